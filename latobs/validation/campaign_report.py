"""The Markdown report of a Monte Carlo campaign (:mod:`latobs.validation.campaign`), with its
histograms and scatter plots (matplotlib, Agg canvas).

``report.md`` in the campaign folder: the declared distributions; runs, failures and timing; the
percentiles of every metric (and the 95 % bootstrap interval of its mean); the enclosure of every
interval; the worst runs of every headline metric with their seeds and the command that re-runs
each alone; every observer against the baselines of ``validate`` (win fraction, ratio percentiles,
the runs of the highest ratio; ``figures/versus_baselines.png``); and per observer
``figures/hist_LABEL.png`` (the distribution of each headline metric over the runs) and per
headline metric ``figures/scatter_LABEL.X.rms.png`` (it against each drawn quantity, one point
per run).
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from ..atomic import atomic_write_text
from .campaign import Campaign
from .campaign_stats import headlines


SCATTER_COLUMNS = 6   # panels per row of a scatter figure


def _g(x: Any) -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "—"
    if isinstance(x, str):
        return x
    return f"{x:.4g}"


def _label_of(column: str) -> str:
    return column.split(".", 1)[0]


def _numeric_params(rows: list[Mapping[str, Any]]) -> list[str]:
    """Drawn quantities that vary over the runs and are numbers (the scatter plots' x axes)."""
    names: dict[str, None] = {}
    for r in rows:
        for k, v in r["params"].items():
            if isinstance(v, (int, float)) and not isinstance(v, bool) and k != "scenario.seed":
                names.setdefault(k, None)
    return [k for k in names if len({r["params"].get(k) for r in rows}) > 1]


#: the metrics (last part of a column's name) in the unit of their quantity; the others are counts
_IN_UNIT = ("rms", "max_abs", "mean_width", "max_violation")


def display(column: str) -> tuple[float, str]:
    """(factor, unit) of a metric column in the report: angles in deg, angular rates in deg/s,
    other quantities in SI (:func:`latobs.validation.units.display_scale`); counts: (1, "samples")."""
    from .metrics import quantity_of
    from .units import display_scale

    parts = column.split(".")
    if len(parts) >= 3 and (parts[-1] in _IN_UNIT or parts[-1].startswith("rms_") or parts[-1].endswith("_rms")):
        return display_scale(quantity_of(parts[-2]))     # X_filtered in the unit of X
    return 1.0, "samples" if parts[-1] in ("violations", "nonfinite") else ""


def _metric_table(stats: Mapping[str, Mapping[str, Any]]) -> list[str]:
    lines = ["| metric | unit | runs | p5 | p50 | p95 | p99 | max | mean [95 % CI] |",
             "|---|---|---|---|---|---|---|---|---|"]
    for col, s in stats.items():
        k, unit = display(col)
        if not s.get("n"):
            lines.append(f"| `{col}` | {unit} | 0 | | | | | | |")
            continue
        ci = s["mean_ci95"]
        lines.append(f"| `{col}` | {unit} | {s['n']} | {_g(k * s['p5'])} | {_g(k * s['p50'])} | {_g(k * s['p95'])} | "
                     f"{_g(k * s['p99'])} | {_g(k * s['max'])} | {_g(k * s['mean'])} [{_g(k * ci[0])}, {_g(k * ci[1])}] |")
    return lines


def markdown(c: Campaign, summary: Mapping[str, Any], figures: list[Path]) -> str:
    t = summary.get("timing", {})
    out = [f"# Campaign `{c.name}`", "", c.description, "",
           f"- kind: {c.kind}; " + (f"scenario `{c.scenario}` on the plant for vehicle `{c.plant_vehicle}`"
                                    if c.kind == "cosim" else f"record `{c.replay['csv']}`, segments of "
                                    f"{c.replay['segment_s']:g} s from "
                                    + ("both parts" if c.replay["part"] == "both" else f"the {c.replay['part']} part")),
           f"- observers: {', '.join(f'`{o}`' for o in c.observers)}",
           f"- runs: {summary['runs']} ({summary['ok']} ok, {summary['failed']} failed); campaign seed {c.seed}; "
           f"run k's seed is SeedSequence([{c.seed}, k]) (`latobs.validation.campaign.run_seed`)",
           f"- definition: `{c.source}`"]
    for t in summary.get("invocations", [t]):
        if t.get("execution_s"):
            out.append(f"- invocation finished {t.get('finished', '')}: {t['runs_this_invocation']} runs, "
                       f"{t['runs_on_dask']} of them in {t['execution_s']:.1f} s on {t['workers']} Dask worker(s) "
                       f"({t['scheduler']} scheduler), {t['runs_per_s']:.2f} runs/s; cluster start "
                       f"{t['cluster_start_s']:.1f} s")
    out += ["", "## Declared distributions", "", "| quantity | distribution |", "|---|---|"]
    for table, dists in (("scenario", c.scenario_fields), ("plant", c.plant), ("signals", c.signals)):
        for k, dist in sorted(dists.items()):
            out.append(f"| `{table}.{k}` | {dist.describe()} |")
    for s, (std, bias) in sorted(c.noise.items()):
        out.append(f"| `noise.{s}` | std {std.describe()}, bias {bias.describe()} |")
    if c.kind == "replay":
        out.append(f"| segment | start uniform in the part, part with probability ∝ its room; "
                   f"{c.replay['segment_s']:g} s |")
    out += ["", "## Metrics over the runs", "",
            "After each run's settle time; angles in deg, angular rates in deg/s, other quantities in SI units "
            "(the definition's distributions above, runs.parquet and summary.json: SI throughout). `X.rms`, "
            "`X.max_abs`: estimate error; `X.violations`: samples where the truth is outside the interval; "
            "`X.mean_width`: its mean width.", ""]
    out += _metric_table(summary["metrics"])
    if c.kind == "replay":
        out += ["", "The segments are drawn from one record and overlap: the bootstrap interval of a mean "
                "reflects the resampling of this drive, not of drives like it (a part of length L holds about "
                f"L / {c.replay['segment_s']:g} s independent segments)."]
    for part, stats in summary.get("by_part", {}).items():
        out += ["", f"### {part} part of the record ({'t < split' if part == 'train' else 't >= split'})", ""]
        out += _metric_table(stats)
    if summary["enclosure"]:
        out += ["", "## Enclosure of the intervals", "", "| interval | runs with a violation | violating samples |",
                "|---|---|---|"]
        for base, e in summary["enclosure"].items():
            out.append(f"| `{base}` | {e['runs_with_violations']} of {e['runs']} | {e['violating_samples']} |")
    out += _versus_markdown(summary.get("versus_baselines") or {}, c)
    out += ["", "## Worst runs", "", f"Re-run one alone (full validation output and plots): "
            f"`{summary.get('rerun_command', 'latobs campaign ' + c.name + ' --rerun SEED')}`", ""]
    drawn_names = c.drawn_names()
    for col, worst in summary["worst"].items():
        if not worst:
            continue
        k, unit = display(col)
        what = "widest runs" if col.endswith(".mean_width") else "worst runs"
        out += [f"**`{col}`** ({what})", "", f"| run | seed | value{f' [{unit}]' if unit else ''} | drawn quantities |",
                "|---|---|---|---|"]
        for w in worst:
            drawn = ", ".join(f"{k} {_g(w['params'][k])}" for k in drawn_names if k in w["params"]
                              and k != "scenario.seed")
            out.append(f"| {w['run']} | `--rerun {w['seed']}` | {_g(k * w['value'])} | {drawn} |")
        out.append("")
    quiet = [col for col, worst in summary["worst"].items() if not worst and col.endswith(".violations")]
    if quiet:
        out += [f"No run violated {', '.join(f'`{c}`' for c in quiet)}: their bounds are judged by their widths "
                "(the widest runs above).", ""]
    if summary["failures"]:
        out += ["## Failed runs", "", "| run | seed | error |", "|---|---|---|"]
        out += [f"| {f['run']} | {f['seed']} | {str(f['error']).splitlines()[0][:200]} |" for f in summary["failures"]]
        out.append("")
    if figures:
        out += ["## Figures", ""]
        out += [f"![{p.stem}](figures/{p.name})" for p in figures]
    return "\n".join(out) + "\n"


def _versus_markdown(vs: Mapping[str, Any], c: Campaign) -> list[str]:
    """The section "Against the baselines" (:func:`latobs.validation.campaign_stats.versus_baselines`)."""
    if not vs:
        return []
    out = ["", "## Against the baselines", "",
           "Each run scores each observer and the baselines of `latobs validate` (the estimate 0; the open-loop "
           "linear bicycle, or a motorcycle's steady turn, with the design's vehicle parameters, driven by the "
           "signals the observers received) on the same drawn car, drive, sensors and samples (after the settle "
           "time). Ratio: the observer's RMS error over the best baseline's in that run (an interval by its "
           "midpoint); below 1 the observer is better. A run counts as won when every baseline is worse. "
           "*Valid samples*: only the samples where the observer declares itself valid (`valid`, `consistent`).",
           "", "| observer | quantity | runs | wins | ratio p5 | p50 | p95 | max | best baseline (runs) "
           "| valid samples | wins on them | ratio p50 on them |", "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for e in vs.values():
        r = e["ratio"]
        wf = e.get("win_fraction")
        best = ", ".join(f"{b} {n}" for b, n in sorted(e["best_baseline_runs"].items(), key=lambda kv: -kv[1]))
        v = e.get("valid") or {}
        vr = v.get("ratio") or {}
        out.append(f"| `{e['observer']}` | {e['quantity']} | {e['runs']} | "
                   f"{'—' if wf is None else f'{100 * wf:.1f} %'} | {_g(r.get('p5'))} | {_g(r.get('p50'))} | "
                   f"{_g(r.get('p95'))} | {_g(r.get('max'))} | {best or '—'} | "
                   + (f"{100 * v['mean_valid_fraction']:.1f} % | " if v.get("mean_valid_fraction") is not None else "— | ")
                   + (f"{100 * v['win_fraction']:.1f} % | " if v.get("win_fraction") is not None else "— | ")
                   + f"{_g(vr.get('p50'))} |")
    drawn_names = c.drawn_names()
    for key, e in vs.items():
        if not e["worst"]:
            continue
        out += ["", f"**`{key}`**: the runs of the highest ratio", "", "| run | seed | ratio | drawn quantities |",
                "|---|---|---|---|"]
        for w in e["worst"]:
            drawn = ", ".join(f"{k} {_g(w['params'][k])}" for k in drawn_names if k in w["params"]
                              and k != "scenario.seed")
            out.append(f"| {w['run']} | `--rerun {w['seed']}` | {_g(w['ratio'])} | {drawn} |")
    return out


def _versus_figure(folder: Path, rows: list[Mapping[str, Any]], canvas, figure, atomic_path) -> list[Path]:
    """``figures/versus_baselines.png``: per observer and quantity, the distribution (empirical CDF)
    of observer RMS / best baseline RMS over the runs on a log axis, the line at 1 marking a win;
    dashed: on the valid samples only."""
    from .campaign_stats import versus_baselines

    ok = [r for r in rows if r["status"] == "ok"]
    vs = versus_baselines(ok)
    if not vs:
        return []
    fig = figure(figsize=(6.4, 4.2))
    ax = fig.add_subplot(1, 1, 1)
    for i, key in enumerate(vs):
        for pre, style in (("", "-"), ("valid_", "--")):
            x = np.array([np.nan if r["metrics"].get(f"{key}.{pre}ratio") is None else r["metrics"][f"{key}.{pre}ratio"]
                          for r in ok], dtype=float)
            x = np.sort(x[np.isfinite(x) & (x > 0)])
            if x.size:
                ax.step(x, np.arange(1, x.size + 1) / x.size, style, where="post", color=f"C{i % 10}",
                        label=key + (" (valid samples)" if pre else ""))
    ax.axvline(1.0, color="k", lw=0.8)
    ax.set_xscale("log")
    ax.set_xlabel("observer RMS / best baseline RMS (< 1: the observer wins)")
    ax.set_ylabel("fraction of runs")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7)
    fig.suptitle(f"Against the baselines: {len(ok)} runs")
    fig.tight_layout()
    return [_save(fig, folder / "figures" / "versus_baselines.png", canvas, atomic_path)]


def figures(folder: Path, rows: list[Mapping[str, Any]]) -> list[Path]:
    """Per observer: histograms of its headline metrics, and scatter plots of them against the
    drawn quantities. Returns the PNG paths."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from ..atomic import atomic_path

    ok = [r for r in rows if r["status"] == "ok"]
    # a violation count that is zero in every run plots nothing: its interval's width says more
    cols = [c for c in headlines(ok) if not (c.endswith(".violations")
                                             and all(not r["metrics"].get(c) for r in ok))]
    params = _numeric_params(ok)
    paths = _versus_figure(folder, rows, FigureCanvasAgg, Figure, atomic_path)
    for label in dict.fromkeys(_label_of(c) for c in cols):
        mine = [c for c in cols if _label_of(c) == label]
        vals = {c: display(c)[0] * np.array([np.nan if r["metrics"].get(c) is None else r["metrics"][c] for r in ok],
                                            dtype=float) for c in mine}
        fig = Figure(figsize=(4.0 * len(mine), 3.2))
        for i, c in enumerate(mine):
            ax = fig.add_subplot(1, len(mine), i + 1)
            x = vals[c][np.isfinite(vals[c])]
            ax.hist(x, bins=min(40, max(5, int(math.sqrt(max(x.size, 1))))), color="tab:blue", alpha=0.8)
            ax.set_xlabel(_axis_label(c))
            ax.set_ylabel("runs")
            ax.grid(alpha=0.3)
        fig.suptitle(f"{label}: {len(ok)} runs")
        fig.tight_layout()
        paths.append(_save(fig, folder / "figures" / f"hist_{label}.png", FigureCanvasAgg, atomic_path))
        for c in mine if params else ():
            ncol = min(SCATTER_COLUMNS, len(params))
            nrow = -(-len(params) // ncol)
            fig = Figure(figsize=(2.7 * ncol, 2.3 * nrow + 0.4))
            for j, p in enumerate(params):
                ax = fig.add_subplot(nrow, ncol, j + 1)
                px = np.array([np.nan if r["params"].get(p) is None else r["params"][p] for r in ok], dtype=float)
                ax.scatter(px, vals[c], s=4, alpha=0.5)
                ax.set_xlabel(p, fontsize=8)
                if j % ncol == 0:
                    ax.set_ylabel(_axis_label(c), fontsize=8)
                ax.locator_params(nbins=4)
                ax.tick_params(labelsize=7)
                ax.grid(alpha=0.3)
            fig.suptitle(f"{c} against each drawn quantity, one point per run")
            fig.tight_layout()
            paths.append(_save(fig, folder / "figures" / f"scatter_{c}.png", FigureCanvasAgg, atomic_path))
    return paths


def _axis_label(column: str) -> str:
    unit = display(column)[1]
    return column.split(".", 1)[1] + (f" [{unit}]" if unit else "")


def _save(fig, path: Path, canvas, atomic_path) -> Path:
    canvas(fig)
    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, format="png", dpi=80)
    return path


def write(folder: Path, c: Campaign, summary: Mapping[str, Any], rows: list[Mapping[str, Any]],
          plots: bool = True) -> Path:
    """Write ``folder/report.md`` (and its figures unless ``plots`` is false); returns its path."""
    figs = figures(Path(folder), rows) if plots else []
    return atomic_write_text(Path(folder) / "report.md", markdown(c, summary, figs))
