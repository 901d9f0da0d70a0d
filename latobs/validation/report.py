"""The Markdown report ``index.md`` of validation runs: a table of contents, each run's metrics
tables with the baselines beside the observers (the lowest RMS marked, a baseline as good as the
observer flagged) and its figures, linked relative to the report; angles in degrees."""
from __future__ import annotations

from ..atomic import atomic_write_text

import json
import math
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


def estimate_label(name: str, entry) -> str:
    """An estimate's name as the tables show it: an output scored one step behind (``X_filtered``,
    ``"lag_steps"``) says so."""
    lag = (entry or {}).get("lag_steps")
    return f"{name} ({lag} step behind)" if lag else name


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
UNITS_NOTE = "angles in deg, angular rates in deg/s, other quantities in SI units"
BASELINE_TITLES = {"zero": "zero", "bicycle": "linear bicycle", "steady_turn": "steady turn",
                   "regression": "fitted regression"}
WARN_MD = "⚠"      # a baseline is as good as or better than the observer (markdown)
WARN_TEXT = "!"    # the same in plain text


def _baseline_title(name: str) -> str:
    return BASELINE_TITLES.get(name, name.replace("_", " "))


def _all_baselines(metrics: Mapping[str, Any]) -> list[str]:
    """Every baseline some observer of ``metrics`` has, in report order."""
    from .metrics import baseline_names

    found: list[str] = []
    for o in metrics.get("observers", {}).values():
        for b in baseline_names(o.get("baselines")):
            if b not in found:
                found.append(b)
    from .baselines import BASELINES

    return [b for b in BASELINES if b in found] + [b for b in found if b not in BASELINES]


def _as_good(summary: Mapping[str, Any] | None) -> list[str]:
    """Every baseline as good as or better than the observer (a metrics file written before the
    summary listed them all: its best baseline, when it was as good)."""
    summary = summary or {}
    if "baselines_as_good" in summary:
        return list(summary["baselines_as_good"] or [])
    return [summary["best_baseline"]] if summary.get("baseline_as_good") and summary.get("best_baseline") else []


def _verdict(summary: Mapping[str, Any] | None, warn: str) -> str | None:
    """Every baseline as good as or better than the observer, after ``warn``; else "observer" when
    every baseline that applies was computed, else no verdict (the baselines not computed named)."""
    if not summary:
        return None
    good = _as_good(summary)
    if good:
        return f"{warn} " + " and ".join(_baseline_title(b) for b in good) + f" baseline{'s' if len(good) > 1 else ''}"
    missing = summary.get("not_computed") or {}
    if missing:
        return "no verdict: " + " and ".join(_baseline_title(b) for b in missing) + " baseline not computed"
    return "observer" if summary.get("best_baseline") is not None else None


def _not_computed_notes(metrics: Mapping[str, Any]) -> list[str]:
    """One line per observer and baseline that could not be computed for some of its estimates:
    which estimates and why (the reason of the metrics' summary)."""
    lines = []
    for lab, o in metrics.get("observers", {}).items():
        per: dict[tuple[str, str], list[str]] = {}
        for name, summ in ((o.get("baselines") or {}).get("summary") or {}).items():
            for b, why in (summ.get("not_computed") or {}).items():
                per.setdefault((b, why), []).append(name)
        lines += [f"{lab}: {_baseline_title(b)} baseline not computed for {', '.join(names)}: {why}; no verdict "
                  "on these estimates" for (b, why), names in per.items()]
    return lines


def _bold(x) -> str:
    return f"**{_fmt(x)}**"


def _baseline_values(o: Mapping[str, Any], name: str, bases: list[str]) -> dict[str, Any]:
    """{baseline: its value of the statistic the summary compares (RMS after settle)} for ``name``."""
    bl = o.get("baselines") or {}
    stat = ((bl.get("summary") or {}).get(name) or {}).get("statistic", "rms_after_settle")
    return {b: ((bl.get(b) or {}).get(name) or {}).get(stat) for b in bases}


def _observer_cell(o: Mapping[str, Any], name: str, value, bases: list[str]):
    """The observer's own value, bold when it is the lowest of its row (ties included)."""
    if value is None or not bases:
        return value
    others = [v for v in _baseline_values(o, name, bases).values() if v is not None]
    return _bold(value) if others and all(value <= v for v in others) else value


def _baseline_cells(o: Mapping[str, Any], name: str, observer_value, bases: list[str]) -> list[Any]:
    """Cells appended to an estimate's (or interval's) markdown row: per baseline its RMS after
    settle (bold when it is the lowest of the row, the observer's included), observer ÷ best
    baseline, and the verdict."""
    summ = ((o.get("baselines") or {}).get("summary") or {}).get(name)
    vals = _baseline_values(o, name, bases)
    cand = [v for v in (observer_value, *vals.values()) if v is not None]
    best = min(cand) if cand else None
    good, missing = _as_good(summ), (summ or {}).get("not_computed") or {}
    cells: list[Any] = [
        "not computed" if b in missing else
        ((_bold(v) if (v is not None and v == best) else _fmt(v)) + (f" {WARN_MD}" if b in good else ""))
        for b, v in vals.items()]
    return cells + [(summ or {}).get("ratio"), _verdict(summ, WARN_MD)]


def _segment_headers(metrics: Mapping[str, Any]) -> list[str]:
    split = metrics.get("split_s")
    if split is None:
        return ["whole record"]
    return ["whole record", f"t < {split:g} s", f"t ≥ {split:g} s"]


def replay_rows(metrics: Mapping[str, Any], mark: str | None = None) -> tuple[list[str], list[list[Any]]]:
    """(header, rows) of a replay's metrics (``metrics["kind"] == "replay"``): per scored output
    its truth column, the metric, and the value on the whole record and each side of the split;
    after an estimate's rows (an interval's: after the RMS error of its midpoint), the RMS error
    of each baseline. ``mark``: None (raw values), "md" or "text": the lowest RMS error of each
    output and segment is then written bold (md) or with a trailing ``*`` (text), and the
    baseline rows' metric names end with a warning when the baseline is as good as or better
    than the observer on the summary's segment."""
    segs = [s for s in SEGMENTS if s in metrics.get("segments", {"all": None})]
    header = ["observer", "output", "truth", "metric", *_segment_headers(metrics)]
    rows: list[list[Any]] = []
    warn = WARN_MD if mark == "md" else WARN_TEXT

    def baseline_rows(lab, shown, o, name, e, first_rms_row):
        from .metrics import baseline_names

        bl = o.get("baselines") or {}
        summ = (bl.get("summary") or {}).get(name) or {}
        for b in baseline_names(bl):
            be = (bl.get(b) or {}).get(name)
            if not be:
                continue
            flag = f" {warn}" if (mark and b in _as_good(summ)) else ""
            rows.append([lab, shown, e.get("truth"), f"RMS error, {_baseline_title(b)} baseline "
                         f"[{e.get('unit') or 'SI'}]{flag}", *[(be.get(s) or {}).get("rms") for s in segs]])
        for b in summ.get("not_computed") or {}:
            rows.append([lab, shown, e.get("truth"), f"RMS error, {_baseline_title(b)} baseline: not computed",
                         *[None for _ in segs]])
        if mark:
            group = [r for r in rows[first_rms_row:] if str(r[3]).startswith("RMS error")]
            for j in range(4, 4 + len(segs)):
                vals = [r[j] for r in group if isinstance(r[j], (int, float))]
                if len(vals) > 1:
                    best = min(vals)
                    for r in group:
                        if isinstance(r[j], (int, float)) and r[j] == best:
                            r[j] = _bold(best) if mark == "md" else f"{_fmt(best)}*"

    for lab, o in metrics.get("observers", {}).items():
        for name, e in o.get("estimates", {}).items():
            first = len(rows)
            for key, what in (("rms", "RMS error"), ("max_abs", "max abs error"), ("mean_error", "mean error")):
                rows.append([lab, estimate_label(name, e), e.get("truth"), f"{what} [{e.get('unit') or 'SI'}]",
                             *[(e.get(s) or {}).get(key) for s in segs]])
            baseline_rows(lab, estimate_label(name, e), o, name, e, first)
        for name, e in o.get("intervals", {}).items():
            shown = f"[{e.get('lower')}, {e.get('upper')}]"
            for key, what in (("violation_rate", "violation rate"), ("enclosure_violations", "violations"),
                              ("mean_width", f"mean width [{e.get('unit') or 'SI'}]")):
                rows.append([lab, shown, e.get("truth"), what, *[(e.get(s) or {}).get(key) for s in segs]])
            if e.get("midpoint"):
                first = len(rows)
                rows.append([lab, shown, e.get("truth"), f"RMS error of the midpoint [{e.get('unit') or 'SI'}]",
                             *[(e["midpoint"].get(s) or {}).get("rms") for s in segs]])
                baseline_rows(lab, shown, o, name, e, first)
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
             f"{metrics.get('t_start_s'):.12g} … {metrics.get('t_end_s'):.12g} s"]   # Unix times too
    if metrics.get("split_s") is not None:
        parts.append(f"split at {metrics['split_s']:g} s ({(seg.get('before_split') or {}).get('n_samples')} + "
                     f"{(seg.get('after_split') or {}).get('n_samples')} samples)")
    return "; ".join(parts)


def _nothing_scored(metrics: Mapping[str, Any]) -> str:
    outs = sorted({x for o in metrics.get("observers", {}).values() for x in o.get("unscored_outputs", [])})
    return (f"nothing was scored: no reference column for any output (outputs {', '.join(outs) or '(none)'}; "
            f"columns {', '.join(metrics.get('columns', []))})")


def replay_markdown(metrics: Mapping[str, Any]) -> str:
    """Markdown of a replay's metrics: the header line and the per-segment table (angles in deg)."""
    metrics = display_units(metrics)
    parts = [_replay_head(metrics) + ".\n"]
    if metrics.get("nothing_scored"):
        parts.append(_nothing_scored(metrics) + "\n")
    else:
        header, rows = replay_rows(metrics, mark="md")
        parts.append(f"Scores (estimate − recorded truth, {UNITS_NOTE}; baselines on the same recorded signals, the "
                     f"lowest RMS error in bold, {WARN_MD} where a baseline is as good as or better than the "
                     "observer):\n\n" + _table(header, rows))
        parts += [f"- {line}" for line in _not_computed_notes(metrics)]
    return "\n".join(parts)


def metrics_markdown(metrics: Mapping[str, Any]) -> str:
    """Tables of one scenario's metrics (estimates, intervals, per-observer summary); a replay's
    metrics (``kind == "replay"``) as :func:`replay_markdown`."""
    if metrics.get("kind") == "replay":
        return replay_markdown(metrics)
    metrics = display_units(metrics)
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
    bases = _all_baselines(metrics)
    for lab, o in obs.items():
        summ = (o.get("baselines") or {}).get("summary") or {}
        for name, e in o.get("estimates", {}).items():
            row = [lab, estimate_label(name, e), e.get("truth"), e.get("unit"), e.get("rms"), e.get("max_abs"),
                   _observer_cell(o, name, e.get("rms_after_settle"), bases), e.get("max_abs_after_settle")]
            if bases:
                row += _baseline_cells(o, name, (summ.get(name) or {}).get("observer_rms"), bases)
            est_rows.append(row)
        for name, e in o.get("intervals", {}).items():
            row = [lab, name, e.get("unit"), e.get("enclosure_violations"),
                   e.get("enclosure_violations_after_settle"), e.get("mean_width"), e.get("max_violation")]
            if bases:
                mid = (summ.get(name) or {}).get("observer_rms")
                row += [_observer_cell(o, name, mid, bases), *_baseline_cells(o, name, mid, bases)]
            int_rows.append(row)
        occ = o.get("mode_occupancy")
        occ_s = ", ".join(f"{m}: {v:.0%}" for m, v in occ.items()) if occ else None
        sum_rows.append([lab, o.get("beta_error_to_bank_l2_ratio"), o.get("beta_error_to_bank_l2_ratio_after_settle"),
                         occ_s, o.get("mode_switches"), o.get("log_messages")])
    bcols = [f"{_baseline_title(b)} baseline: RMS after settle" for b in bases]
    if bases:
        bcols += ["observer ÷ best baseline", "best"]
    note = (f" Baselines on the same signals (zero estimate; {', '.join(_baseline_title(b) for b in bases[1:]) or '—'}"
            f" model): the lowest RMS after settle in bold, {WARN_MD} where a baseline is as good as or better "
            "than the observer." if bases else "")
    if est_rows:
        parts.append(f"Estimation errors (estimate − truth, {UNITS_NOTE})." + note + "\n\n" + _table(
            ["observer", "estimate", "truth", "unit", "RMS", "max abs", "RMS after settle", "max abs after settle",
             *bcols], est_rows))
    if int_rows:
        parts.append("Interval outputs" + (" (the midpoint of the bounds beside the baselines)" if bases else "")
                     + ":\n\n" + _table(
            ["observer", "signal", "unit", "enclosure violations", "violations after settle", "mean width",
             "max violation", *(["midpoint: RMS after settle", *bcols] if bases else [])], int_rows))
    notes = _not_computed_notes(metrics)
    if notes:
        parts.append("\n".join(f"- {line}" for line in notes) + "\n")
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
    """The link to file ``path`` (absolute or relative to the working directory, as every path)
    from a markdown file in ``report_dir``; ValueError when there is no such file."""
    p = Path(os.path.abspath(path))
    if not p.is_file():
        raise ValueError(f"report image {path}: no such file")
    return Path(os.path.relpath(p, os.path.abspath(report_dir))).as_posix()


#: unit of an angle (rate) in the report, and the factor from the SI unit
DISPLAY_UNITS = {"rad": ("deg", 180.0 / math.pi), "rad/s": ("deg/s", 180.0 / math.pi),
                 "rad/s2": ("deg/s2", 180.0 / math.pi)}
#: metric keys (at any depth of an estimate's or interval's entry) that carry the signal's unit;
#: the others (counts, rates, ratios, fractions) are dimensionless
UNIT_KEYS = frozenset({"rms", "max_abs", "rms_after_settle", "max_abs_after_settle", "mean_error",
                       "mean_error_after_settle", "mean_width", "mean_width_after_settle", "max_violation",
                       "observer_rms", "best_baseline_rms", "truth_rms_after_settle"})


def _scaled(x: Any, k: float, key: str | None = None) -> Any:
    if isinstance(x, Mapping):
        return {kk: (_scaled(v, k, kk) if isinstance(v, Mapping) or kk in UNIT_KEYS else v) for kk, v in x.items()}
    if key in UNIT_KEYS and isinstance(x, (int, float)) and not isinstance(x, bool):
        return x * k
    return x


def display_units(metrics: Mapping[str, Any]) -> dict[str, Any]:
    """A copy of ``metrics`` (validate's or replay's) with every angle in degrees and every angular
    rate in deg/s (:data:`DISPLAY_UNITS`): the values under :data:`UNIT_KEYS` of each estimate and
    interval whose unit is one of them, of its baselines and of its baseline summary, and its
    ``unit``. Idempotent (a converted entry's unit is no longer rad)."""
    out = dict(metrics)
    obs = {}
    for lab, o in metrics.get("observers", {}).items():
        o = dict(o)
        factors = {}
        for group in ("estimates", "intervals"):
            entries = {}
            for name, e in (o.get(group) or {}).items():
                du = DISPLAY_UNITS.get(e.get("unit")) if isinstance(e, Mapping) else None
                if du:
                    factors[name] = du[1]
                    e = {**_scaled(e, du[1]), "unit": du[0]}
                entries[name] = e
            if group in o:
                o[group] = entries
        bl = o.get("baselines")
        if isinstance(bl, Mapping) and factors:
            bl = dict(bl)
            for b, per in bl.items():
                if b == "summary" or not isinstance(per, Mapping):
                    continue
                bl[b] = {n: (_scaled(v, factors[n]) if n in factors and isinstance(v, Mapping) else v)
                         for n, v in per.items()}
            summ = bl.get("summary")
            if isinstance(summ, Mapping):
                bl["summary"] = {n: ({**_scaled(v, factors[n]),
                                      "baselines": {b: (None if x is None else x * factors[n])
                                                    for b, x in (v.get("baselines") or {}).items()}}
                                     if n in factors and isinstance(v, Mapping) else v) for n, v in summ.items()}
            o["baselines"] = bl
        obs[lab] = o
    out["observers"] = obs
    return out


def worst_bound(o: Mapping[str, Any], key=lambda e: e.get("enclosure_violations")) -> tuple[int, list[str]] | None:
    """(samples, [bounds]) of an observer's most violated interval(s): a violation count that never
    adds up bounds of one quantity seen through another (beta = atan(vy / vx) is violated exactly
    when vy is: 234 + 234 is one event, not 468). None when it has no interval."""
    counts = {n: key(e) or 0 for n, e in (o.get("intervals") or {}).items()}
    if not counts:
        return None
    n = max(counts.values())
    return n, [k for k, v in counts.items() if v == n]


def anchor(title: str, taken: dict[str, int] | None = None) -> str:
    """The anchor of a markdown heading (GitHub's rule: lower case, punctuation dropped, spaces to
    hyphens; the second heading of one anchor gets "-1", the next "-2"). ``taken`` counts the
    anchors seen so far and is updated."""
    import re

    a = re.sub(r"[^\w\- ]", "", title.strip().lower(), flags=re.UNICODE).replace(" ", "-")
    if taken is None:
        return a
    n = taken.get(a, 0)
    taken[a] = n + 1
    return a if n == 0 else f"{a}-{n}"


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


def _headline_estimate(o: Mapping[str, Any]) -> str | None:
    """The estimate an overview line shows: beta_hat, else an interval beta, else the first scored."""
    summ, est = (o.get("baselines") or {}).get("summary") or {}, o.get("estimates") or {}
    for n in ("beta_hat", "beta"):
        if n in summ or n in est:
            return n
    return next(iter([*est, *summ]), None)


def overview_rows(sections: Iterable) -> tuple[list[str], list[list[Any]]]:
    """(header, rows) of the overview: per section with metrics and per observer, its headline
    estimate (:func:`_headline_estimate`), the observer's RMS error and the best baseline's on the
    same statistic (the summary's: after settle, a replay's held-out part), the most violated
    bound (:func:`worst_bound`) and paper 000's eq. (26) ratio. Angles in degrees."""
    header = ["run", "observer", "estimate", "observer RMS", "best baseline RMS", "violations (bound)",
              "‖β−β̂‖₂/‖φr‖₂"]
    rows = []
    for s in (_as_section(x) for x in sections):
        if not (isinstance(s, ReportSection) and s.metrics):
            continue
        m = display_units(s.metrics)
        replay = m.get("kind") == "replay"
        for lab, o in m.get("observers", {}).items():
            name = _headline_estimate(o)
            entry = (o.get("estimates") or {}).get(name) or (o.get("intervals") or {}).get(name) or {}
            unit = entry.get("unit") or ""
            summ = ((o.get("baselines") or {}).get("summary") or {}).get(name) or {}
            own = summ.get("observer_rms")
            if own is None:          # no baseline summary: the estimate's own figure
                own = ((entry.get("after_split") or entry.get("all") or {}).get("rms") if replay
                       else entry.get("rms_after_settle"))
            best = None
            if summ.get("best_baseline") is not None:
                best = (f"{WARN_MD + ' ' if _as_good(summ) else ''}"
                        f"{_baseline_title(summ['best_baseline'])}: {_fmt(summ.get('best_baseline_rms'))} {unit}")
            if summ.get("not_computed") and not _as_good(summ):   # no verdict when a baseline is missing
                best = (f"{best}; " if best else "") + _verdict(summ, WARN_MD)
            worst = worst_bound(o, (lambda e: (e.get("all") or {}).get("enclosure_violations")) if replay
                                else (lambda e: e.get("enclosure_violations")))
            rows.append([s.title, lab, (name or "—") + (" (midpoint)" if name in (o.get("intervals") or {}) else ""),
                         None if own is None else f"{_fmt(own)} {unit}".strip(), best,
                         None if worst is None else (f"{worst[0]} ({', '.join(worst[1])})" if worst[0] else 0),
                         o.get("beta_error_to_bank_l2_ratio")])
    return header, rows


def render(report_dir: str | os.PathLike, sections: Iterable, title: str = "latobs validation report",
           intro: str = "") -> str:
    """The report's markdown: title, intro, a table of contents, the overview (one row per section
    with metrics and observer), then each section (its markdown, tables, figures). Plain-string
    sections are copied as they are (their headings enter the contents)."""
    import re

    report_dir = Path(report_dir)
    secs = [_as_section(s) for s in sections]
    header, rows = overview_rows(secs)
    body = []
    if rows:
        body.append("## Overview\n\nOne row per run and observer: its headline estimate (β when it estimates β, "
                    "else its first) beside the best baseline on the same signals, after the settle time (a replay: "
                    f"its held-out part when split); {WARN_MD}: a baseline as good as the observer or better. "
                    "Violations: samples outside the most violated bound (β = atan(vy/vx) is violated exactly when "
                    "vy is: one event, counted once).\n\n" + _table(header, rows))
    for s in secs:
        if isinstance(s, str):
            body.append(s.rstrip() + "\n")
            continue
        body.append(f"## {s.title}\n")
        if s.markdown:
            body.append(s.markdown.rstrip() + "\n")
        if s.metrics:
            body.append(metrics_markdown(s.metrics))
        for img in s.images:
            body.append(f"![{Path(img).stem}]({_rel(img, report_dir)})\n")
    taken: dict[str, int] = {anchor(title): 1, "contents": 1}   # the headings above the sections
    toc = []
    for block in body:
        for line in block.splitlines():
            h = re.match(r"(#{2,3}) (.+)$", line)
            if h:
                toc.append(f"{'  ' * (len(h.group(1)) - 2)}- [{h.group(2)}](#{anchor(h.group(2), taken)})")
    out = [f"# {title}\n"]
    if intro:
        out.append(intro.rstrip() + "\n")
    if toc:
        out.append("## Contents\n\n" + "\n".join(toc) + "\n")
    return "\n".join(out + body)


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
    header, rows = replay_rows(metrics, mark="text")
    header, rows = header[1:], [r[1:] for r in rows]    # one observer per replay
    shown, last = [], None
    for r in rows:
        key = (r[0], r[1])
        shown.append([*(["", ""] if key == last else [str(r[0]), str(r[1])]), str(r[2]), *(_fmt(c) for c in r[3:])])
        last = key
    notes = _not_computed_notes(metrics)
    return head + "\n" + _columns([header, *shown]) + "".join(f"\n{line}" for line in notes)


def text_table(metrics: Mapping[str, Any]) -> str:
    """Plain-text table of one scenario's metrics for a terminal (SI units); a replay's metrics as
    :func:`replay_text_table`."""
    if metrics.get("kind") == "replay":
        return replay_text_table(metrics)
    from .metrics import baseline_names

    rows = [("observer", "output", "RMS", "max abs", "RMS settled", "max settled")]
    marked = False

    def with_baselines(lab, o, name, own: tuple | None, what: str):
        """The observer's row ``own`` (None: none) then one row per baseline, the lowest RMS settled
        starred, a ``!`` on the name of a baseline as good as or better than the observer."""
        nonlocal marked
        bl = o.get("baselines") or {}
        summ = (bl.get("summary") or {}).get(name) or {}
        group = []
        if own is not None:
            group.append([lab, what, *own])
        for b in baseline_names(bl):
            be = (bl.get(b) or {}).get(name)
            if not be:
                continue
            flag = f" {WARN_TEXT}" if b in _as_good(summ) else ""
            group.append(["", f"  {_baseline_title(b)} baseline{flag}", be.get("rms"), be.get("max_abs"),
                          be.get("rms_after_settle"), be.get("max_abs_after_settle")])
        for b in summ.get("not_computed") or {}:
            group.append(["", f"  {_baseline_title(b)} baseline: not computed (below)", None, None, None, None])
        vals = [g[4] for g in group if g[4] is not None]
        best = min(vals) if len(group) > 1 and vals else None
        for g in group:
            star = best is not None and g[4] == best
            marked = marked or star
            rows.append((*g[:2], *(_fmt(c) for c in g[2:4]), _fmt(g[4]) + ("*" if star else ""), _fmt(g[5])))

    for lab, o in metrics.get("observers", {}).items():
        summ = (o.get("baselines") or {}).get("summary") or {}
        for name, e in o.get("estimates", {}).items():
            with_baselines(lab, o, name, (e.get("rms"), e.get("max_abs"), e.get("rms_after_settle"),
                                          e.get("max_abs_after_settle")), estimate_label(name, e))
        for name, e in o.get("intervals", {}).items():
            rows.append((lab, f"[{name}] violations/width", _fmt(e.get("enclosure_violations")),
                         _fmt(e.get("mean_width")), _fmt(e.get("enclosure_violations_after_settle")),
                         _fmt(e.get("mean_width_after_settle"))))
            s = summ.get(name)
            if s:
                own = (None, None, s.get("observer_rms"), None) if s.get("statistic") == "rms_after_settle" \
                    else (s.get("observer_rms"), None, None, None)
                with_baselines(lab, o, name, own, f"[{name}] midpoint")
        if o.get("beta_error_to_bank_l2_ratio") is not None:
            rows.append((lab, "|beta err|/|bank| L2", _fmt(o["beta_error_to_bank_l2_ratio"]), "",
                         _fmt(o.get("beta_error_to_bank_l2_ratio_after_settle")), ""))
    widths = [max(len(str(r[i])) for r in rows) for i in range(len(rows[0]))]
    lines = ["  ".join(str(c).ljust(w) for c, w in zip(r, widths)).rstrip() for r in rows]
    lines.insert(1, "  ".join("-" * w for w in widths))
    foot = (f"\n* lowest RMS settled of an output (observer or baseline); {WARN_TEXT}: a baseline as good as or "
            "better than the observer") if marked else ""
    foot += "".join(f"\n{line}" for line in _not_computed_notes(metrics))
    return f"scenario {metrics.get('scenario', '?')} (SI units: rad, rad/s, m/s, N)\n" + "\n".join(lines) + foot
