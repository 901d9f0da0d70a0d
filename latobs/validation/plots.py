"""PNG figures of a co-simulation (matplotlib, Agg canvas; pyplot's global state is not used).

Angles are drawn in degrees and angular rates in deg/s (axis labels say so); other signals in
their SI unit. Files written by :func:`plot_all` into ``out_dir``:

    estimates.png   truth vs every observer's estimate (and interval band) per estimated signal;
                    the truth of an observer is the one its metrics use (metrics.REFERENCE_SIGNALS);
                    the model baseline of the metrics (a car's open-loop linear bicycle, a
                    motorcycle's steady turn; latobs.validation.baselines) as a thin dashed line
    modes.png       active mode of each observer over time (observers with a `mode` output)
    residual.png    each observer's `residual_norm` output (paper 003)
    bank_angle.png  road bank angle: truth vs each observer's bank_angle_hat
    inputs.png      the scenario's plant inputs (delta, vx, bank_angle)
"""
from __future__ import annotations

from ..atomic import atomic_path

import math
import os
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from .harness import PLANT_LABEL, SimResult

RAD2DEG = 180.0 / math.pi

#: preferred order of the estimated signals; others follow alphabetically
PREFERRED = ("beta", "yaw_rate", "roll_angle", "roll_rate", "bank_angle")

_ANGLES = {"beta", "roll_angle", "bank_angle", "delta", "alpha_f", "alpha_r", "steer_angle"}
_RATES = {"yaw_rate", "roll_rate", "steer_rate"}
_SI = {"vx": "m/s", "vy": "m/s", "ay": "m/s^2", "Fyf": "N", "Fyr": "N", "Ff": "N", "Fr": "N",
       "rider_torque": "N*m"}
_LABELS = {"beta": "sideslip beta", "yaw_rate": "yaw rate", "roll_angle": "roll angle",
           "roll_rate": "roll rate", "bank_angle": "bank angle", "delta": "road-wheel angle delta",
           "vx": "speed vx", "vy": "lateral speed vy", "ay": "lateral acceleration ay"}


def display_scale(name: str, units: dict[str, str] | None = None) -> tuple[float, str]:
    """(factor, unit label) to draw signal ``name``: rad -> deg, rad/s -> deg/s, else SI."""
    u = (units or {}).get(name) or (units or {}).get(name + "_hat")
    if u in ("rad",) or (u is None and name in _ANGLES):
        return RAD2DEG, "deg"
    if u in ("rad/s",) or (u is None and name in _RATES):
        return RAD2DEG, "deg/s"
    return 1.0, u or _SI.get(name, "SI")


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


def plot_estimates(result: SimResult, out_dir: str | os.PathLike) -> Path | None:
    truths = _truths(result)
    sigs = estimated_signals(result)
    if not sigs:
        return None
    base_lines = model_baseline_lines(result)
    t = result.time
    fig = Figure(figsize=(10, 2.3 * len(sigs) + 0.8))
    axes = fig.subplots(len(sigs), 1, sharex=True, squeeze=False)[:, 0]
    for ax, s in zip(axes, sigs):
        k, _ = display_scale(s, result.units)
        # one truth line per truth signal used for this quantity (e.g. beta and beta_cg)
        for j, truth in enumerate(dict.fromkeys(truths[s].values())):
            _plot(ax, t, k * result.bus[truth], color="black", lw=1.6 if j == 0 else 1.2,
                  ls="-" if j == 0 else "--", label=f"{truth} (truth)")
        for label, outs in result.observers.items():
            if label not in truths[s]:
                continue
            if s + "_hat" in outs:
                _plot(ax, t, k * np.asarray(outs[s + "_hat"], float), lw=1.0, label=f"{label}: {s}_hat")
            if s + "_lower" in outs and s + "_upper" in outs:
                lo, hi = k * np.asarray(outs[s + "_lower"], float), k * np.asarray(outs[s + "_upper"], float)
                i = thin(t, lo, hi)
                ax.fill_between(t[i], lo[i], hi[i], alpha=0.25, label=f"{label}: [{s}_lower, {s}_upper]")
        for name, y in base_lines.get(s, []):
            _plot(ax, t, k * y, label=name, **BASELINE_STYLE)
        ax.set_ylabel(_ylabel(s, result.units))
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7, loc="best")
    axes[-1].set_xlabel("time [s]")
    fig.suptitle(f"{result.scenario}: estimates vs truth")
    fig.tight_layout()
    return _save(fig, Path(out_dir) / "estimates.png")


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
    if "bank_angle" not in result.bus:
        return None
    k, u = display_scale("bank_angle", result.units)
    fig = Figure(figsize=(10, 3.5))
    ax = fig.subplots()
    _plot(ax, result.time, k * result.bus["bank_angle"], color="black", lw=1.6, label="bank_angle (truth)")
    for lab, outs in result.observers.items():
        if "bank_angle_hat" in outs:
            _plot(ax, result.time, k * np.asarray(outs["bank_angle_hat"], float), lw=1.0, label=f"{lab}: bank_angle_hat")
    ax.set_xlabel("time [s]")
    ax.set_ylabel(f"bank angle [{u}]")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    fig.suptitle(f"{result.scenario}: road bank angle")
    fig.tight_layout()
    return _save(fig, Path(out_dir) / "bank_angle.png")


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
