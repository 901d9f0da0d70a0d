"""Markdown report: ``index.md`` with the metrics tables and figures of each validation run.

A section is one of

* a :class:`ReportSection` (title, metrics dict as from :func:`latobs.validation.metrics.compute`,
  image paths, extra markdown),
* a mapping with the same keys,
* a plain string: markdown copied as is (e.g. a design certificate written by the caller).

Image links are made relative to the report directory. Metric values are in the SI unit of the
signal (rad, rad/s, m/s, N); the unit column repeats it when the FMU declares it.
"""
from __future__ import annotations

from ..atomic import atomic_write_text

import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, Mapping

IMAGE_ORDER = ("estimates.png", "bank_angle.png", "modes.png", "inputs.png", "replay.png", "replay_zoom.png")


@dataclass
class ReportSection:
    title: str
    metrics: Mapping[str, Any] | None = None
    images: list[str | os.PathLike] = field(default_factory=list)
    markdown: str = ""


def _fmt(x) -> str:
    if x is None:
        return "—"
    if isinstance(x, bool):
        return "yes" if x else "no"
    if isinstance(x, int):
        return str(x)
    if isinstance(x, float):
        return f"{x:.4g}"
    return str(x)


def _table(header: list[str], rows: list[list[Any]]) -> str:
    if not rows:
        return ""
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(_fmt(c) for c in r) + " |" for r in rows]
    return "\n".join(lines) + "\n"


SEGMENTS = ("all", "before_split", "after_split")


def _segment_headers(metrics: Mapping[str, Any]) -> list[str]:
    split = metrics.get("split_s")
    if split is None:
        return ["whole record"]
    return ["whole record", f"t < {split:g} s", f"t ≥ {split:g} s"]


def replay_rows(metrics: Mapping[str, Any]) -> tuple[list[str], list[list[Any]]]:
    """(header, rows) of a replay's metrics (``metrics["kind"] == "replay"``): per scored output
    its truth column, the metric, and the value on the whole record and each side of the split."""
    segs = [s for s in SEGMENTS if s in metrics.get("segments", {"all": None})]
    header = ["observer", "output", "truth", "metric", *_segment_headers(metrics)]
    rows: list[list[Any]] = []
    for lab, o in metrics.get("observers", {}).items():
        for name, e in o.get("estimates", {}).items():
            for key, what in (("rms", "RMS error"), ("max_abs", "max abs error"), ("mean_error", "mean error")):
                rows.append([lab, name, e.get("truth"), f"{what} [{e.get('unit') or 'SI'}]",
                             *[(e.get(s) or {}).get(key) for s in segs]])
        for name, e in o.get("intervals", {}).items():
            for key, what in (("violation_rate", "violation rate"), ("enclosure_violations", "violations"),
                              ("mean_width", f"mean width [{e.get('unit') or 'SI'}]")):
                rows.append([lab, f"[{e.get('lower')}, {e.get('upper')}]", e.get("truth"), what,
                             *[(e.get(s) or {}).get(key) for s in segs]])
        f = o.get("may_in_force_sum")
        if f and "skipped" not in f:
            for key, what in (("enclosure_rate", "enclosure rate (eq. 47)"), ("enclosure_violations", "violations"),
                              ("mean_width", "mean width [N]")):
                rows.append([lab, f"[{f['lower']}, {f['upper']}]", f"m*ay (m = {f['mass_kg']:g} kg)", what,
                             *[(f.get(s) or {}).get(key) for s in segs]])
    return header, rows


def _replay_head(metrics: Mapping[str, Any]) -> str:
    seg = metrics.get("segments", {})
    parts = [f"{metrics.get('scenario', 'replay')} through {metrics.get('label')} (vehicle {metrics.get('vehicle')})",
             f"{metrics.get('n_samples')} samples at {metrics.get('dt_s'):.6g} s, t = "
             f"{metrics.get('t_start_s'):.6g} … {metrics.get('t_end_s'):.6g} s"]
    if metrics.get("split_s") is not None:
        parts.append(f"split at {metrics['split_s']:g} s ({(seg.get('before_split') or {}).get('n_samples')} + "
                     f"{(seg.get('after_split') or {}).get('n_samples')} samples)")
    return "; ".join(parts)


def _nothing_scored(metrics: Mapping[str, Any]) -> str:
    outs = sorted({x for o in metrics.get("observers", {}).values() for x in o.get("unscored_outputs", [])})
    return (f"nothing was scored: no reference column for any output (outputs {', '.join(outs) or '(none)'}; "
            f"columns {', '.join(metrics.get('columns', []))})")


def replay_markdown(metrics: Mapping[str, Any]) -> str:
    """Markdown of a replay's metrics: the header line and the per-segment table."""
    parts = [_replay_head(metrics) + ".\n"]
    if metrics.get("nothing_scored"):
        parts.append(_nothing_scored(metrics) + "\n")
    else:
        header, rows = replay_rows(metrics)
        parts.append("Scores (estimate − recorded truth, SI units):\n\n" + _table(header, rows))
    return "\n".join(parts)


def metrics_markdown(metrics: Mapping[str, Any]) -> str:
    """Tables of one scenario's metrics (estimates, intervals, per-observer summary); a replay's
    metrics (``kind == "replay"``) as :func:`replay_markdown`."""
    if metrics.get("kind") == "replay":
        return replay_markdown(metrics)
    obs = metrics.get("observers", {})
    parts = []
    head = []
    for key, lab in (("scenario", "scenario"), ("duration_s", "duration [s]"), ("dt_s", "step [s]"),
                     ("settle_time_s", "settle time [s]")):
        if key in metrics:
            head.append(f"{lab}: {_fmt(metrics[key])}")
    if head:
        parts.append("; ".join(head) + "\n")
    est_rows, int_rows, sum_rows = [], [], []
    for lab, o in obs.items():
        for name, e in o.get("estimates", {}).items():
            est_rows.append([lab, name, e.get("truth"), e.get("unit"), e.get("rms"), e.get("max_abs"),
                             e.get("rms_after_settle"), e.get("max_abs_after_settle")])
        for name, e in o.get("intervals", {}).items():
            int_rows.append([lab, name, e.get("unit"), e.get("enclosure_violations"),
                             e.get("enclosure_violations_after_settle"), e.get("mean_width"),
                             e.get("max_violation")])
        occ = o.get("mode_occupancy")
        occ_s = ", ".join(f"{m}: {v:.0%}" for m, v in occ.items()) if occ else None
        sum_rows.append([lab, o.get("beta_error_to_bank_l2_ratio"), o.get("beta_error_to_bank_l2_ratio_after_settle"),
                         occ_s, o.get("mode_switches"), o.get("log_messages")])
    if est_rows:
        parts.append("Estimation errors (estimate − truth, SI units):\n\n" + _table(
            ["observer", "estimate", "truth", "unit", "RMS", "max abs", "RMS after settle", "max abs after settle"],
            est_rows))
    if int_rows:
        parts.append("Interval outputs:\n\n" + _table(
            ["observer", "signal", "unit", "enclosure violations", "violations after settle", "mean width",
             "max violation"], int_rows))
    if sum_rows:
        parts.append("Per observer (‖β − β̂‖₂ / ‖φr‖₂ is paper 000 eq. (26)):\n\n" + _table(
            ["observer", "‖β−β̂‖₂/‖φr‖₂", "same after settle", "mode occupancy", "mode switches", "log messages"],
            sum_rows))
    return "\n".join(parts)


def _as_section(s) -> ReportSection | str:
    if isinstance(s, (ReportSection, str)):
        return s
    if isinstance(s, Mapping):
        return ReportSection(title=str(s.get("title", "")), metrics=s.get("metrics"),
                             images=list(s.get("images", [])), markdown=str(s.get("markdown", "")))
    raise TypeError(f"report section must be a ReportSection, a mapping or a markdown string, got {type(s).__name__}")


def _rel(path, report_dir: Path) -> str:
    p = Path(path)
    if not p.is_absolute():
        p = report_dir / p
    return Path(os.path.relpath(p, report_dir)).as_posix()


def section_from_dir(scenario_dir: str | os.PathLike, title: str | None = None, markdown: str = "") -> ReportSection:
    """A section from a ``validate`` output directory: its metrics.json and its PNGs."""
    d = Path(scenario_dir)
    metrics = None
    mf = d / "metrics.json"
    if mf.is_file():
        metrics = json.loads(mf.read_text(encoding="utf-8"))
    pngs = sorted(d.glob("*.png"), key=lambda p: (IMAGE_ORDER.index(p.name) if p.name in IMAGE_ORDER else 99, p.name))
    return ReportSection(title=title or (metrics or {}).get("scenario", d.name), metrics=metrics,
                         images=pngs, markdown=markdown)


def render(report_dir: str | os.PathLike, sections: Iterable, title: str = "latobs validation report",
           intro: str = "") -> str:
    report_dir = Path(report_dir)
    out = [f"# {title}\n"]
    if intro:
        out.append(intro.rstrip() + "\n")
    secs = [_as_section(s) for s in sections]
    # overview: one row per (scenario, observer)
    rows = []
    for s in secs:
        if isinstance(s, ReportSection) and s.metrics:
            replay = s.metrics.get("kind") == "replay"
            for lab, o in s.metrics.get("observers", {}).items():
                est = o.get("estimates", {})
                beta = est.get("beta_hat", {})
                if replay:  # the held-out part when there is one, else the whole record
                    seg = "after_split" if s.metrics.get("split_s") is not None else "all"
                    viol = sum((v.get("all") or {}).get("enclosure_violations") or 0
                               for v in o.get("intervals", {}).values()) if o.get("intervals") else None
                    rows.append([s.title, lab, (beta.get(seg) or {}).get("rms"), None, viol, len(est)])
                    continue
                viol = sum(v.get("enclosure_violations") or 0 for v in o.get("intervals", {}).values()) \
                    if o.get("intervals") else None
                rows.append([s.title, lab, beta.get("rms_after_settle"), o.get("beta_error_to_bank_l2_ratio"), viol,
                             len(est)])
    if rows:
        out.append("## Overview\n\n" + _table(
            ["scenario", "observer", "β̂ RMS after settle (replay: held-out part) [rad]", "‖β−β̂‖₂/‖φr‖₂", "enclosure violations",
             "scored estimates"], rows))
    for s in secs:
        if isinstance(s, str):
            out.append(s.rstrip() + "\n")
            continue
        out.append(f"## {s.title}\n")
        if s.markdown:
            out.append(s.markdown.rstrip() + "\n")
        if s.metrics:
            out.append(metrics_markdown(s.metrics))
        for img in s.images:
            rel = _rel(img, report_dir)
            out.append(f"![{Path(img).stem}]({rel})\n")
    return "\n".join(out)


def write_index(report_dir: str | os.PathLike, sections: Iterable, title: str = "latobs validation report",
                intro: str = "") -> Path:
    """Write ``report_dir/index.md`` atomically (temp file + os.replace); returns its path."""
    report_dir = Path(report_dir)
    report_dir.mkdir(parents=True, exist_ok=True)
    text = render(report_dir, sections, title=title, intro=intro)
    return atomic_write_text(report_dir / "index.md", text)


def _columns(rows: list[list[str]]) -> str:
    widths = [max(len(str(r[i])) for r in rows) for i in range(len(rows[0]))]
    lines = ["  ".join(str(c).ljust(w) for c, w in zip(r, widths)).rstrip() for r in rows]
    lines.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join(lines)


def replay_text_table(metrics: Mapping[str, Any]) -> str:
    """Plain-text table of a replay's metrics for a terminal (SI units)."""
    head = _replay_head(metrics)
    if metrics.get("nothing_scored"):
        return head + "\n" + _nothing_scored(metrics)
    header, rows = replay_rows(metrics)
    header, rows = header[1:], [r[1:] for r in rows]    # one observer per replay
    shown, last = [], None
    for r in rows:
        key = (r[0], r[1])
        shown.append([*(["", ""] if key == last else [str(r[0]), str(r[1])]), str(r[2]), *(_fmt(c) for c in r[3:])])
        last = key
    return head + "\n" + _columns([header, *shown])


def text_table(metrics: Mapping[str, Any]) -> str:
    """Plain-text table of one scenario's metrics for a terminal (SI units); a replay's metrics as
    :func:`replay_text_table`."""
    if metrics.get("kind") == "replay":
        return replay_text_table(metrics)
    rows = [("observer", "output", "RMS", "max abs", "RMS settled", "max settled")]
    for lab, o in metrics.get("observers", {}).items():
        for name, e in o.get("estimates", {}).items():
            rows.append((lab, name, _fmt(e.get("rms")), _fmt(e.get("max_abs")), _fmt(e.get("rms_after_settle")),
                         _fmt(e.get("max_abs_after_settle"))))
        for name, e in o.get("intervals", {}).items():
            rows.append((lab, f"[{name}] violations/width", _fmt(e.get("enclosure_violations")),
                         _fmt(e.get("mean_width")), _fmt(e.get("enclosure_violations_after_settle")),
                         _fmt(e.get("mean_width_after_settle"))))
        if o.get("beta_error_to_bank_l2_ratio") is not None:
            rows.append((lab, "|beta err|/|bank| L2", _fmt(o["beta_error_to_bank_l2_ratio"]), "",
                         _fmt(o.get("beta_error_to_bank_l2_ratio_after_settle")), ""))
    widths = [max(len(str(r[i])) for r in rows) for i in range(len(rows[0]))]
    lines = ["  ".join(str(c).ljust(w) for c, w in zip(r, widths)).rstrip() for r in rows]
    lines.insert(1, "  ".join("-" * w for w in widths))
    return f"scenario {metrics.get('scenario', '?')} (SI units: rad, rad/s, m/s, N)\n" + "\n".join(lines)
