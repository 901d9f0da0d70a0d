"""PNG figures of a co-simulation (matplotlib, Agg canvas, no pyplot state): estimates beside the
truth and the model baseline, modes, residuals, bank angle, the scenario's inputs; angles in
degrees."""
from __future__ import annotations

from ..atomic import atomic_path

import math
import os
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from .harness import PLANT_LABEL, SimResult

from .units import _LABELS, PREFERRED, display_scale


def _ylabel(name: str, units) -> str:
    _, u = display_scale(name, units)
    return f"{_LABELS.get(name, name)} [{u}]"


MAX_BUCKETS = 800  # a line is drawn from at most 2 samples (its min and max) per bucket


def thin(t: np.ndarray, *ys: np.ndarray) -> np.ndarray:
    """Indices of the samples to draw: per bucket of consecutive samples, the minimum and maximum of
    each series in ``ys`` (so peaks and steps survive), plus the first and last sample. A 30 s run
    at 5 ms (6001 samples) draws at most ~1600 points per line instead of 6001: the figure looks
    the same at the resolution it is saved in and renders several times faster."""
    n = len(t)
    if n <= 2 * MAX_BUCKETS:
        return np.arange(n)
    b = -(-n // MAX_BUCKETS)
    nb = n // b
    idx = [np.array([0, n - 1]), np.arange(nb * b, n)]
    base = np.arange(nb) * b
    for y in ys:
        blocks = np.asarray(y, float)[: nb * b].reshape(nb, b)
        idx += [base + np.argmin(blocks, axis=1), base + np.argmax(blocks, axis=1)]
    return np.unique(np.concatenate(idx))


def _plot(ax, t, y, **kw):
    i = thin(t, y)
    return ax.plot(t[i], np.asarray(y)[i], **kw)


def _save(fig: Figure, path: Path) -> Path:
    FigureCanvasAgg(fig)
    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, format="png", dpi=110)
    return path


def _truths(result: SimResult) -> dict[str, dict[str, str]]:
    """{quantity X: {observer label: truth signal}} for every X an observer estimates (X_hat) or
    bounds (X_lower/X_upper) and that has a truth on the bus, with metrics.REFERENCE_SIGNALS
    applied (the same truth as the metrics)."""
    from .metrics import estimated_quantities, truth_signal

    models = (result.info or {}).get("observer_models", {})
    found: dict[str, dict[str, str]] = {}
    for label, outs in result.observers.items():
        hats, pairs = estimated_quantities(outs)
        for q in dict.fromkeys([*hats, *pairs]):
            truth = truth_signal(q, result.bus, models.get(label))
            if truth is not None:
                found.setdefault(q, {})[label] = truth
    return found


def estimated_signals(result: SimResult) -> list[str]:
    """Quantities X that some observer estimates (X_hat) or bounds (X_lower/upper) and that have a
    truth on the bus (X itself or the observer's metrics.REFERENCE_SIGNALS entry)."""
    found = set(_truths(result))
    return [s for s in PREFERRED if s in found] + sorted(found - set(PREFERRED))


#: style of a model baseline's line (thin, dashed)
BASELINE_STYLE = {"color": "tab:gray", "lw": 0.8, "ls": "--"}


def model_baseline_lines(result: SimResult) -> dict[str, list[tuple[str, np.ndarray]]]:
    """{quantity X: [(legend label, array), ...]}: the model baselines (not ``zero``) of the
    observers' metrics for every estimated X, one line per distinct series (observers designed
    for the same vehicle share one)."""
    from .metrics import simulation_baselines

    truths = _truths(result)
    lines: dict[str, list[tuple[str, np.ndarray]]] = {}
    for label in result.observers:
        qs = [q for q, labs in truths.items() if label in labs]
        if not qs:
            continue
        b = simulation_baselines(result, label, qs)
        for base, ser in b["series"].items():
            if base == "zero":
                continue
            veh = (b["about"].get(base) or {}).get("vehicle")
            name = f"{base.replace('_', ' ')} baseline" + (f" ({veh})" if veh else "")
            for q, y in ser.items():
                have = lines.setdefault(q, [])
                if any(np.array_equal(y, y0) for _, y0 in have):
                    continue
                if any(n == name for n, _ in have):
                    name = f"{name}, {label}"
                have.append((name, np.asarray(y, dtype=float)))
    return lines


#: a panel's y-limits reach at most CLIP_SPANS times the reference span beyond the truth's range:
#: the reference span is the truth's range or, if larger, CLIP_ERROR_FACTOR times the largest error
#: of the best observer's estimate (so a flat truth still gets a scale); a curve beyond is clipped
#: there and marked (a diverging design cannot flatten the others)
CLIP_SPANS = 1.0
CLIP_ERROR_FACTOR = 10.0
#: shading of the spans where an observer's flag output is 0: (output, colour, legend text)
FLAGS = (("valid", "tab:orange", "valid = 0 (outside the linear domain, bank frozen)"),
         ("consistent", "tab:red", "consistent = 0 (measurement outside the bounds)"))


def _flag_spans(t: np.ndarray, flag: np.ndarray) -> list[tuple[float, float]]:
    """[(t_start, t_end)] of the runs of samples where ``flag`` is 0 (each sample holds over its step)."""
    off = np.asarray(flag, dtype=float) == 0
    if not off.any():
        return []
    d = np.diff(np.concatenate([[0], off.astype(int), [0]]))
    starts, ends = np.flatnonzero(d == 1), np.flatnonzero(d == -1)
    t_end = np.append(t[1:], t[-1] + (t[-1] - t[-2] if len(t) > 1 else 0.0))
    return [(float(t[a]), float(t_end[b - 1])) for a, b in zip(starts, ends)]


def shade_flags(axes, result: SimResult, labels: list[str]) -> list:
    """Shade, on every axis of ``axes``, where some observer of ``labels`` outputs ``valid`` = 0 or
    ``consistent`` = 0 (:data:`FLAGS`); returns one legend handle per flag drawn."""
    from matplotlib.patches import Patch

    handles = []
    for name, colour, text in FLAGS:
        who = [lab for lab in labels if name in result.observers.get(lab, {})]
        off = np.zeros(len(result.time), dtype=bool)     # the union: some observer's flag is 0
        for lab in who:
            off |= np.asarray(result.observers[lab][name], dtype=float) == 0
        spans = _flag_spans(result.time, ~off)
        if not spans:
            continue
        for ax in axes:
            for a, b in spans:
                ax.axvspan(a, b, color=colour, alpha=0.12, lw=0)
        handles.append(Patch(color=colour, alpha=0.3, label=text + (f" ({who[0]})" if len(who) == 1
                                                                    else f" (any of {len(who)} observers)")))
    return handles


def clip_limits(truths: list[np.ndarray], others: list[np.ndarray], ref_span: float | None = None) -> tuple[float, float]:
    """y-limits of a panel: every truth inside; the other curves too, as far as :data:`CLIP_SPANS`
    times ``ref_span`` (default: the truths' range) beyond the truths' range. Non-finite samples
    are ignored."""
    def finite(ys):
        v = np.concatenate([np.asarray(y, dtype=float).ravel() for y in ys]) if ys else np.zeros(0)
        return v[np.isfinite(v)]

    tv, ov = finite(truths), finite(others)
    lo, hi = (float(tv.min()), float(tv.max())) if tv.size else (0.0, 0.0)
    span = (hi - lo) if ref_span is None else ref_span
    allow = (lo - CLIP_SPANS * span, hi + CLIP_SPANS * span) if span > 0 else (-math.inf, math.inf)
    if ov.size:
        lo, hi = max(allow[0], min(lo, float(ov.min()))), min(allow[1], max(hi, float(ov.max())))
    pad = 0.05 * (hi - lo) if hi > lo else max(abs(hi), 1.0) * 0.05
    return lo - pad, hi + pad


def mark_clipped(ax, t: np.ndarray, y: np.ndarray, colour) -> float | None:
    """Mark on ``ax`` (its y-limits set) where ``y`` leaves them: a triangle at the edge at the
    start of each excursion. Returns the most extreme value beyond the limits, None if none."""
    lo, hi = ax.get_ylim()
    y = np.asarray(y, dtype=float)
    out = (y < lo) | (y > hi) | ~np.isfinite(y)
    if not out.any():
        return None
    starts = np.flatnonzero(np.diff(np.concatenate([[0], out.astype(int)])) == 1)
    for k in starts[:50]:
        up = not (y[k] < lo)
        ax.plot([t[k]], [hi if up else lo], marker="^" if up else "v", color=colour, ms=7, clip_on=False,
                markeredgecolor="black", mew=0.5, ls="none")
    bad = y[out]
    fin = bad[np.isfinite(bad)]
    return float(fin[np.argmax(np.abs(fin))]) if fin.size else float("nan")


def _clip_note(v: float | None, unit: str) -> str:
    return "" if v is None else f" (clipped: reaches {v:.3g} {unit})"


def plot_estimates(result: SimResult, out_dir: str | os.PathLike, only: str | None = None,
                   name: str = "estimates.png") -> Path | None:
    """estimates.png: one row per estimated quantity (``only``: that one alone, if estimated): left,
    the truth, every observer's estimate or bounds and the model baseline; right, the error
    (estimate − truth; bounds − truth, which must straddle 0). Spans where an observer's ``valid``
    or ``consistent`` output is 0 are shaded; y-limits follow the truth (:func:`clip_limits`), a
    curve that leaves them is marked at the edge and its legend entry says how far it went;
    legends beside the panels, outside the data. None when nothing is estimated."""
    truths = _truths(result)
    sigs = [s for s in estimated_signals(result) if only in (None, s)]
    if not sigs:
        return None
    base_lines = model_baseline_lines(result)
    colours = {lab: f"C{i % 10}" for i, lab in enumerate(result.observers)}
    fig = Figure(figsize=(14, 2.5 * len(sigs) + 0.9), layout="constrained")
    grid = fig.subplots(len(sigs), 2, sharex=True, squeeze=False, gridspec_kw={"width_ratios": [3, 2]})
    handles: dict[str, Any] = {}
    for (ax, ex), s in zip(grid, sigs):
        for h in _quantity_row(ax, ex, result, s, truths[s], base_lines.get(s, []), colours):
            handles.setdefault(h.get_label(), h)
    grid[0][0].set_title("estimate vs truth" + (f"; {grid[0][0].get_title()}" if grid[0][0].get_title() else ""),
                         fontsize=8)
    grid[0][1].set_title("error: estimate − truth (bounds − truth must straddle 0)"
                         + (f"\n{grid[0][1].get_title()}" if grid[0][1].get_title() else ""), fontsize=8)
    grid[-1][0].set_xlabel("time [s]")
    grid[-1][1].set_xlabel("time [s]")
    fig.legend(handles=list(handles.values()), loc="outside lower center", ncol=min(4, len(handles)), fontsize=8)
    fig.suptitle(f"{result.scenario}: " + ("estimates vs truth" if only is None else f"{_LABELS.get(only, only)}"))
    return _save(fig, Path(out_dir) / name)


def _quantity_row(ax, ex, result: SimResult, s: str, truth_of: dict[str, str], base_lines, colours) -> list:
    """One quantity ``s`` of :func:`plot_estimates`: values on ``ax``, errors on ``ex``; returns the
    legend handles (the figure's legend, below the panels). The truths' names and what was
    clipped go in the panels' titles, above the data."""
    t = result.time
    k, unit = display_scale(s, result.units)
    labs = [lab for lab in result.observers if lab in truth_of]
    tr = {name: k * np.asarray(result.bus[name], float) for name in dict.fromkeys(truth_of.values())}
    for j, (name, y) in enumerate(tr.items()):
        _plot(ax, t, y, color="black", lw=1.6 if j == 0 else 1.2, ls="-" if j == 0 else "--",
              label="truth" if j == 0 else "second truth (dashed)")
    if len(tr) > 1:
        ax.set_title("truth: " + ", ".join(f"{n} ({'solid' if j == 0 else 'dashed'})" for j, n in enumerate(tr)),
                     fontsize=8)
    curves, errors = [], []   # (label, colour, array or (lower, upper)), drawn once the limits are known
    for lab in labs:
        outs, y_true, c = result.observers[lab], tr[truth_of[lab]], colours[lab]
        if s + "_hat" in outs:
            y = k * np.asarray(outs[s + "_hat"], float)
            curves.append((lab, c, y))
            errors.append((lab, c, y - y_true))
        if s + "_lower" in outs and s + "_upper" in outs:
            lo, hi = k * np.asarray(outs[s + "_lower"], float), k * np.asarray(outs[s + "_upper"], float)
            curves.append((f"{lab} bounds", c, (lo, hi)))
            errors.append((f"{lab} bounds", c, (lo - y_true, hi - y_true)))
    first_truth = next(iter(tr.values()))
    baselines = {name for name, _ in base_lines}
    for name, y in base_lines:
        curves.append((name, "gray", k * y))
        errors.append((name, "gray", k * y - first_truth))

    def parts(v):
        return list(v) if isinstance(v, tuple) else [v]

    # the reference span: the truth's range or, if larger, CLIP_ERROR_FACTOR times the largest error
    # of the best observer's estimate (a flat truth still gets a scale); the error panel: that scale
    best = min((float(np.max(np.abs(v[np.isfinite(v)]))) for n, _, v in errors
                if n not in baselines and not isinstance(v, tuple) and np.isfinite(v).any()), default=None)
    t_span = float(np.ptp(np.concatenate(list(tr.values()))))
    scale = None if best is None else CLIP_ERROR_FACTOR * best
    ax.set_ylim(*clip_limits(list(tr.values()), [p for _, _, v in curves for p in parts(v)],
                             ref_span=max(t_span, scale or 0.0)))
    ex.set_ylim(*clip_limits([np.zeros(1)], [p for _, _, v in errors for p in parts(v)],
                             ref_span=t_span if scale is None else scale))
    clipped = []
    for target, group in ((ax, curves), (ex, errors)):
        for name, c, v in group:
            if isinstance(v, tuple):
                i = thin(t, *v)
                h = target.fill_between(t[i], v[0][i], v[1][i], color=c, alpha=0.25, label=name)
            else:
                h = _plot(target, t, v, label=name, **(BASELINE_STYLE if name in baselines else {"color": c, "lw": 1.0}))[0]
            far = max((f for f in (mark_clipped(target, t, p, c) for p in parts(v)) if f is not None),
                      key=abs, default=None)
            if far is not None and target is ax:
                clipped.append(f"{name}{_clip_note(far, unit).replace(' (clipped: reaches', ' to').rstrip(')')}")
    flags = shade_flags([ax, ex], result, labs)
    ex.axhline(0.0, color="black", lw=0.8)
    ax.set_ylabel(_ylabel(s, result.units))
    ex.set_ylabel(f"error [{unit}]")
    for a in (ax, ex):
        a.grid(True, alpha=0.3)
    if clipped:
        ex.set_title("▲▼ clipped: " + "; ".join(clipped), fontsize=7, color="darkred")
    handles, _ = ax.get_legend_handles_labels()
    return handles + flags


def plot_modes(result: SimResult, out_dir: str | os.PathLike) -> Path | None:
    labs = [lab for lab, outs in result.observers.items() if "mode" in outs]
    if not labs:
        return None
    fig = Figure(figsize=(10, 1.6 * len(labs) + 1.0))
    axes = fig.subplots(len(labs), 1, sharex=True, squeeze=False)[:, 0]
    for ax, lab in zip(axes, labs):
        m = np.asarray(result.observers[lab]["mode"])
        ax.step(result.time, m, where="post", lw=1.2)
        ax.set_ylabel(f"{lab}\nmode [-]", fontsize=8)
        lo, hi = int(m.min()), int(m.max())
        ax.set_yticks(range(lo, hi + 1))
        ax.set_ylim(lo - 0.5, hi + 0.5)
        ax.grid(True, alpha=0.3)
    axes[-1].set_xlabel("time [s]")
    fig.suptitle(f"{result.scenario}: active mode (1-based)")
    fig.tight_layout()
    return _save(fig, Path(out_dir) / "modes.png")


def plot_residual(result: SimResult, out_dir: str | os.PathLike) -> Path | None:
    """residual.png: each observer's ``residual_norm`` output (paper 003's figure 6)."""
    labs = [lab for lab, outs in result.observers.items() if "residual_norm" in outs]
    if not labs:
        return None
    fig = Figure(figsize=(10, 1.8 * len(labs) + 1.0))
    axes = fig.subplots(len(labs), 1, sharex=True, squeeze=False)[:, 0]
    for ax, lab in zip(axes, labs):
        y = np.asarray(result.observers[lab]["residual_norm"], dtype=float)
        _plot(ax, result.time, y, lw=1.0)
        unit = result.units.get("residual_norm")
        ax.set_ylabel(f"{lab}\n|y - y^|" + (f" [{unit}]" if unit else ""), fontsize=8)
        ax.grid(True, alpha=0.3)
    axes[-1].set_xlabel("time [s]")
    fig.suptitle(f"{result.scenario}: residual norm")
    fig.tight_layout()
    return _save(fig, Path(out_dir) / "residual.png")


def plot_bank(result: SimResult, out_dir: str | os.PathLike) -> Path | None:
    """bank_angle.png: the road bank angle row of :func:`plot_estimates` alone, larger; None when no
    observer estimates it (no empty figure)."""
    return plot_estimates(result, out_dir, only="bank_angle", name="bank_angle.png")


def plot_inputs(result: SimResult, out_dir: str | os.PathLike) -> Path | None:
    names = [n for n in result.inputs.get(PLANT_LABEL, []) if n in result.bus]
    if not names:
        names = [n for n in ("delta", "vx", "bank_angle") if n in result.bus]
    if not names:
        return None
    fig = Figure(figsize=(10, 2.2 * len(names) + 0.8))
    axes = fig.subplots(len(names), 1, sharex=True, squeeze=False)[:, 0]
    for ax, n in zip(axes, names):
        k, _ = display_scale(n, result.units)
        _plot(ax, result.time, k * result.bus[n], lw=1.2)
        ax.set_ylabel(_ylabel(n, result.units))
        ax.grid(True, alpha=0.3)
        if n == "vx":
            sec = ax.secondary_yaxis("right", functions=(lambda v: v * 3.6, lambda v: v / 3.6))
            sec.set_ylabel("[km/h]")
    axes[-1].set_xlabel("time [s]")
    fig.suptitle(f"{result.scenario}: plant inputs")
    fig.tight_layout()
    return _save(fig, Path(out_dir) / "inputs.png")


def plot_all(result: SimResult, out_dir: str | os.PathLike) -> list[Path]:
    """Write every applicable figure into ``out_dir``; returns the paths written."""
    paths = [plot_estimates(result, out_dir), plot_modes(result, out_dir), plot_residual(result, out_dir),
             plot_bank(result, out_dir), plot_inputs(result, out_dir)]
    return [p for p in paths if p is not None]
