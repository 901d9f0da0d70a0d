"""Scores of a co-simulation: estimation errors, interval enclosure, paper 000's bank-angle L2
ratio, modes, residuals, and every estimate beside the baselines on the same samples
(:func:`compute`). The structure of ``metrics.json`` is on the documentation's "Results files"
page."""
from __future__ import annotations

from .. import catalogue
from ..atomic import atomic_write_text

import json
import math
import os
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from . import baselines as _bl
from .harness import SimResult

ENCLOSURE_TOL = 1e-9  # absolute tolerance of the enclosure test, in the signal's unit
#: A sample is in a tire's saturation zone when the nonlinear part of its force (the plant's
#: Gamma_f / Gamma_r output, paper 003 eq. 5-6) exceeds this fraction of the force.
SATURATION_FRACTION = 0.05

#: Truth signal of an estimated quantity, per observer FMU model (the model name, or its prefix
#: before ``_<vehicle>`` for a build of another vehicle): {model: {quantity X: bus signal}}. Used
#: only when the mapped signal is on the bus (else the signal ``X`` itself). CarPlant's ``vy`` and
#: ``beta`` are at the roll-axis point below the centre of gravity, ``vy_cg``/``beta_cg`` at it.
REFERENCE_SIGNALS: dict[str, dict[str, str]] = {e.name: dict(e.truth) for e in catalogue.ENTRIES if e.truth}


def reference_map(model_name: str | None) -> dict[str, str]:
    """The :data:`REFERENCE_SIGNALS` entry of an FMU model name: an exact key, else the longest
    key ``K`` with ``model_name`` starting ``K_`` (``LateralIntervalObserver_mbds_250lm``)."""
    if not model_name:
        return {}
    if model_name in REFERENCE_SIGNALS:
        return REFERENCE_SIGNALS[model_name]
    keys = [k for k in REFERENCE_SIGNALS if model_name.startswith(k + "_")]
    return REFERENCE_SIGNALS[max(keys, key=len)] if keys else {}


def truth_signal(quantity: str, available, model_name: str | None = None) -> str | None:
    """The signal an observer of FMU model ``model_name`` estimating ``quantity`` is scored
    against, among ``available`` signal names (a mapping or a set); None when there is none."""
    mapped = reference_map(model_name).get(quantity)
    if mapped is not None and mapped in available:
        return mapped
    return quantity if quantity in available else None


FILTERED = "_filtered"


def filtered_outputs(outputs) -> list[str]:
    """Every ``X_filtered`` output: a filter's estimate x(k|k) of X at the previous communication
    point, published one step behind (a filtered estimate of the current time would make the
    outputs depend on the current inputs: a direct feedthrough). Its value at row k + 1 is scored
    against the truth at row k (:func:`one_step_behind`)."""
    return [n for n in outputs if n.endswith(FILTERED)]


def one_step_behind(y, truth, mask):
    """(y[1:], truth[:-1], mask[:-1]): the samples of a ``X_filtered`` output (row k + 1) beside
    the truth and the sample selection of the time they estimate (row k)."""
    return np.asarray(y, dtype=float)[1:], np.asarray(truth, dtype=float)[:-1], np.asarray(mask)[:-1]


def same_samples(series, truth, mask, entry: Mapping[str, Any]):
    """(series, truth, mask) on the samples the estimate ``entry`` was scored on, for a baseline
    beside it: all of them, or, for one scored one step behind (``"lag_steps"``: its rows k + 1
    estimate rows k), rows 0 .. n - 2, the times it estimates."""
    if entry.get("lag_steps"):
        return np.asarray(series, dtype=float)[:-1], np.asarray(truth, dtype=float)[:-1], np.asarray(mask)[:-1]
    return series, truth, mask


def quantity_of(name: str) -> str:
    """X of an estimate ``X_hat`` or ``X_filtered`` (the name itself otherwise)."""
    for suffix in ("_hat", FILTERED):
        if name.endswith(suffix):
            return name[:-len(suffix)]
    return name


def estimated_quantities(outputs) -> tuple[list[str], list[str]]:
    """(X of every ``X_hat`` output, X of every ``X_lower``/``X_upper`` pair) of an observer."""
    hats = [n[:-4] for n in outputs if n.endswith("_hat")]
    pairs = [n[:-6] for n in outputs if n.endswith("_lower") and n[:-6] + "_upper" in outputs]
    return hats, pairs


def error_stats(estimate, truth) -> dict[str, Any]:
    """Statistics of estimate - truth over the given samples (SI unit of the signal)."""
    e = np.asarray(estimate, dtype=float) - np.asarray(truth, dtype=float)
    return {"n_samples": int(e.size), "rms": _rms(e), "max_abs": _maxabs(e),
            "mean_error": _f(np.mean(e)) if e.size else None,
            "nonfinite_samples": int(np.sum(~np.isfinite(e)))}


def enclosure_stats(lower, upper, truth, tol: float = ENCLOSURE_TOL) -> dict[str, Any]:
    """Enclosure of ``truth`` in [lower, upper] over the given samples: a sample violates when
    the truth is outside by more than ``tol`` or a bound is not finite."""
    lo = np.asarray(lower, dtype=float)
    hi = np.asarray(upper, dtype=float)
    x = np.asarray(truth, dtype=float)
    n = int(x.size)
    viol = (x < lo - tol) | (x > hi + tol) | ~np.isfinite(lo) | ~np.isfinite(hi)
    nv = int(np.sum(viol))
    width = hi - lo
    over = np.maximum(lo - x, x - hi)
    return {"n_samples": n, "enclosure_violations": nv,
            "violation_rate": nv / n if n else None,
            "enclosure_rate": 1.0 - nv / n if n else None,
            "max_violation": _f(max(0.0, float(np.nanmax(over)))) if n and np.any(np.isfinite(over)) else None,
            "mean_width": _f(np.mean(width)) if n else None,
            "nonfinite_samples": int(np.sum(~np.isfinite(width)))}


def _f(x) -> float | None:
    x = float(x)
    return x if math.isfinite(x) else None


def _rms(e: np.ndarray) -> float | None:
    return _f(np.sqrt(np.mean(e**2))) if e.size else None


def _maxabs(e: np.ndarray) -> float | None:
    return _f(np.max(np.abs(e))) if e.size else None


def l2_norm(x: np.ndarray, dt: float) -> float:
    """Discrete L2 norm sqrt(sum x_k^2 * dt) (unit of x times sqrt(s))."""
    return float(np.sqrt(np.sum(np.asarray(x, dtype=float) ** 2) * dt))


def mode_occupancy(time: np.ndarray, mode: np.ndarray) -> dict[str, float]:
    """Fraction of the run's time spent in each mode, zero-order hold (sample k holds over
    [t_k, t_{k+1})); keys are the mode numbers as strings."""
    time = np.asarray(time, dtype=float)
    mode = np.asarray(mode)
    if time.size < 2:
        return {str(int(m)): 1.0 for m in np.unique(mode)}
    w = np.diff(time)
    total = float(time[-1] - time[0])
    occ = {}
    for m in np.unique(mode[:-1]):
        occ[str(int(m))] = float(np.sum(w[mode[:-1] == m]) / total)
    return dict(sorted(occ.items(), key=lambda kv: int(kv[0])))


def compute(result: SimResult, settle_time: float | None = None) -> dict[str, Any]:
    """Metrics of ``result`` (see the module docstring); settle_time (s) defaults to the scenario's."""
    t = np.asarray(result.time, dtype=float)
    ts = result.settle_time if settle_time is None else float(settle_time)
    after = t >= ts - 1e-12
    dt = float(result.dt)
    bus = result.bus
    out: dict[str, Any] = {
        "scenario": result.scenario,
        "dt_s": dt,
        "duration_s": float(t[-1] - t[0]),
        "settle_time_s": ts,
        "n_samples": int(t.size),
        "info": result.info,
        "observers": {},
    }
    models = (result.info or {}).get("observer_models", {})
    for label, outs in result.observers.items():
        o: dict[str, Any] = {"estimates": {}, "intervals": {}}
        scored: set[str] = set()
        model = models.get(label)
        for name, y in outs.items():
            truth = truth_signal(name[:-4], bus, model) if name.endswith("_hat") else None
            if truth is not None:
                o["estimates"][name] = estimate_entry(y, bus[truth], after, truth,
                                                      result.units.get(name) or result.units.get(truth))
                scored.add(name)
        for name in filtered_outputs(outs):
            truth = truth_signal(quantity_of(name), bus, model)
            if truth is not None and t.size > 1:
                o["estimates"][name] = {**estimate_entry(*one_step_behind(outs[name], bus[truth], after), truth,
                                                         result.units.get(name) or result.units.get(truth)),
                                        "lag_steps": 1}
                scored.add(name)
        for name in outs:
            if name.endswith("_lower"):
                base = name[:-6]
                up = base + "_upper"
                truth = truth_signal(base, bus, model)
                if up in outs and truth is not None:
                    lo = np.asarray(outs[name], dtype=float)
                    hi = np.asarray(outs[up], dtype=float)
                    x = bus[truth]
                    below = lo - x  # > 0 when violated
                    above = x - hi
                    viol = (x < lo - ENCLOSURE_TOL) | (x > hi + ENCLOSURE_TOL) | ~np.isfinite(lo) | ~np.isfinite(hi)
                    width = hi - lo
                    o["intervals"][base] = {
                        "truth": truth,
                        "lower": name,
                        "upper": up,
                        "unit": result.units.get(name) or result.units.get(truth),
                        "enclosure_violations": int(np.sum(viol)),
                        "enclosure_violations_after_settle": int(np.sum(viol[after])),
                        "max_violation": _f(max(0.0, float(np.nanmax(np.maximum(below, above))))) if x.size else None,
                        "mean_width": _f(np.mean(width)),
                        "mean_width_after_settle": _f(np.mean(width[after])) if np.any(after) else None,
                        "nonfinite_samples": int(np.sum(~np.isfinite(width))),
                    }
                    scored.update((name, up))
        beta_truth = truth_signal("beta", bus, model)
        if "beta_hat" in outs and beta_truth is not None and "bank_angle" in bus:
            e = np.asarray(outs["beta_hat"], dtype=float) - bus[beta_truth]
            phi = bus["bank_angle"]
            for key, sel in (("beta_error_to_bank_l2_ratio", slice(None)),
                             ("beta_error_to_bank_l2_ratio_after_settle", after)):
                den = l2_norm(phi[sel], dt)
                o[key] = _f(l2_norm(e[sel], dt) / den) if den > 0 else None
        sat = {ax: g for ax, g in (("Ff", "Gamma_f"), ("Fr", "Gamma_r"))
               if f"{ax}_hat" in outs and ax in bus and g in bus}
        if sat:                              # paper 003: force estimates inside the saturation zone
            o["saturation_zone"] = {}
            for ax, g in sat.items():
                F, G = bus[ax], bus[g]
                zone = np.abs(G) > SATURATION_FRACTION * np.maximum(np.abs(F), 1e-9)
                e = np.asarray(outs[f"{ax}_hat"], dtype=float) - F
                o["saturation_zone"][ax] = {
                    "samples": int(np.sum(zone)), "fraction": _f(np.mean(zone)),
                    "rms": _rms(e[zone]) if np.any(zone) else None,
                    "max_abs": _maxabs(e[zone]) if np.any(zone) else None,
                    "rms_outside": _rms(e[~zone]) if np.any(~zone) else None,
                    "peak_gamma_over_force": _f(np.max(np.abs(G) / np.maximum(np.abs(F), 1e-9))) if F.size else None}
        if "residual_norm" in outs:          # paper 003: |y - y^|, no truth to compare with
            rn = np.asarray(outs["residual_norm"], dtype=float)
            o["residual_norm"] = {"rms": _rms(rn), "max": _maxabs(rn),
                                  "rms_after_settle": _rms(rn[after]) if np.any(after) else None,
                                  "max_after_settle": _maxabs(rn[after]) if np.any(after) else None}
            scored.add("residual_norm")
        if "mode" in outs:
            m = np.asarray(outs["mode"])
            o["mode_occupancy"] = mode_occupancy(t, m)
            o["mode_switches"] = int(np.sum(m[1:] != m[:-1]))
            scored.add("mode")
        if "valid" in outs:                  # paper 000: the linear-domain flag (integral frozen at 0)
            v = np.asarray(outs["valid"])
            o["valid"] = {"fraction_invalid": _f(np.mean(v == 0)) if v.size else None,
                          "invalid_episodes": int(np.sum((v[1:] == 0) & (v[:-1] != 0)) + (1 if v.size and v[0] == 0 else 0)),
                          "time_invalid_s": _f(np.sum(v[:-1] == 0) * dt) if v.size else None}
            scored.add("valid")
        o["unscored_outputs"] = sorted(set(outs) - scored)
        o["log_messages"] = len(result.logs.get(label, []))
        o["baselines"] = _simulation_baselines(result, label, o, after)
        out["observers"][label] = o
    return out


def estimate_entry(estimate, truth, after, truth_name: str, unit: str | None) -> dict[str, Any]:
    """The metrics entry of one estimate against ``truth`` (arrays over the run; ``after`` the
    samples with t >= settle time): truth, unit, rms, max_abs, the same after settle, the bias
    after settle, the truth's RMS after settle, nonfinite_samples (SI unit of the signal)."""
    x = np.asarray(truth, dtype=float)
    e = np.asarray(estimate, dtype=float) - x
    return {
        "truth": truth_name,
        "unit": unit,
        "rms": _rms(e),
        "max_abs": _maxabs(e),
        "rms_after_settle": _rms(e[after]),
        "max_abs_after_settle": _maxabs(e[after]),
        "mean_error_after_settle": _f(np.mean(e[after])) if np.any(after) else None,   # bias
        "truth_rms_after_settle": _rms(x[after]) if np.any(after) else None,
        "nonfinite_samples": int(np.sum(~np.isfinite(e))),
    }


# --------------------------------------------------------------------------------------------
# baselines
# --------------------------------------------------------------------------------------------
#: The model baseline of each kind of vehicle (the zero baseline applies to all).
MODEL_BASELINE = {"car": "bicycle", "motorcycle": "steady_turn"}
#: Keys of a ``baselines`` entry that are not baselines.
BASELINE_META_KEYS = ("summary", "skipped", "about")


def baseline_names(entry: dict[str, Any] | None) -> list[str]:
    """The baselines present in an observer's ``baselines`` entry, in report order."""
    entry = entry or {}
    return [b for b in _bl.BASELINES if b in entry] + sorted(
        k for k in entry if k not in _bl.BASELINES and k not in BASELINE_META_KEYS)


def design_vehicle(design: dict[str, Any] | None) -> dict[str, Any] | None:
    """The vehicle dict of a design summary (``harness.design_summary``) or design file; a plain
    vehicle dict (with ``parameters``) as it is; None for None."""
    if isinstance(design, dict) and isinstance(design.get("vehicle"), dict):
        return design["vehicle"]
    return design if isinstance(design, dict) else None


def observer_kind(design: dict[str, Any] | None, model: str | None = None) -> str:
    """"motorcycle" or "car": the kind of the design's vehicle, else guessed from the FMU model
    name (a model named Motorcycle... is a motorcycle's)."""
    kind = (design_vehicle(design) or {}).get("kind")
    if kind in MODEL_BASELINE:
        return kind
    return "motorcycle" if (model or "").startswith("Motorcycle") else "car"


def baselines_for(time, signals, quantities, design: dict[str, Any] | None = None, model: str | None = None,
                  sources: dict[str, str] | None = None, initial: str = "rest",
                  fit: tuple[np.ndarray, dict[str, np.ndarray]] | None = None) -> dict[str, Any]:
    """Baseline estimates of ``quantities`` (names X of what an observer estimates) computed from
    ``signals`` ({name: array on ``time``}: delta, vx for the bicycle; vx, yaw_rate for the steady
    turn; SI units). ``design``: the observer's design summary (``harness.design_summary``: its
    ``vehicle`` gives the parameters) or a vehicle dict; ``model`` its FMU model name;
    ``sources``: {signal: where it comes from} for the record; ``initial``: the bicycle's
    initial state ("rest" or "steady" at the first sample, :func:`baselines.bicycle`). Returns
    {"series": {baseline: {X: array}}, "skipped": {baseline: reason}, "about": {baseline: {...}},
    "unavailable": {baseline: {X: reason}}}: ``unavailable`` lists each quantity a baseline gives
    (the bicycle's vy, beta ...; the steady turn's forces) that it could not compute here, and why.
    ``fit``: (tuning-sample mask, {X: reference array}) of a record with a tuning part: then also
    the ridge regression of each such X on the causally filtered sensor columns, fitted on those
    samples only (:func:`baselines.regression`).

    The parameters are those of the design file only (``design``: the vehicle the observer was
    designed for, as the user gave it); nothing is looked up elsewhere by the vehicle's name."""
    quantities = list(dict.fromkeys(quantities))
    t = np.asarray(time, dtype=float)
    sources = sources or {}
    vehicle = design_vehicle(design)
    vname = (vehicle or {}).get("name")
    source = design.get("source") if isinstance(design, dict) and isinstance(design.get("vehicle"), dict) else None
    series: dict[str, dict[str, np.ndarray]] = {}
    skipped: dict[str, str] = {}
    about: dict[str, Any] = {}
    unavailable: dict[str, dict[str, str]] = {}
    if quantities:
        series["zero"] = _bl.zero(t.size, quantities)
        about["zero"] = {"what": "every estimate 0 (beta, vy, bank angle, forces, roll angle, torque ...)"}
    kind = observer_kind(design, model)
    name = MODEL_BASELINE[kind]

    def need(*names):
        miss = [n for n in names if n not in signals]
        if miss:
            raise _bl.BaselineUnavailable(f"no signal {', '.join(repr(m) for m in miss)} to drive it")
        return [np.asarray(signals[n], dtype=float) for n in names]

    qs = [q for q in quantities if q in (_bl.BICYCLE_OUTPUTS if kind == "car" else
                                         (*_bl.STEADY_TURN_OUTPUTS, *_bl.STEADY_TURN_MODEL_OUTPUTS))]
    try:
        if kind == "car":
            if not qs:
                raise _bl.BaselineUnavailable(f"the linear bicycle gives none of {', '.join(quantities) or '(none)'}")
            params = _bl.parameter_values(vehicle, _bl.BICYCLE_PARAMETERS, "the linear bicycle baseline", source)
            delta, vx = need("delta", "vx")
            y = _bl.bicycle(t, delta, vx, params, initial=initial)
            series[name] = {q: y[q] for q in qs}
            start = "from rest" if initial == "rest" else "from the steady state of the first sample"
            about[name] = {"what": "open-loop linear single-track model (Rajamani eq. 2.31) driven by delta and vx, "
                                   f"exact zero-order hold, {start}, state held below "
                                   f"{_bl.VX_MIN:g} m/s; quantities at the centre of gravity",
                           "inputs": {n: sources.get(n, "signal") for n in ("delta", "vx")},
                           "vehicle": vname, "parameters": params}
        else:
            if not qs:
                raise _bl.BaselineUnavailable(f"the steady turn gives none of {', '.join(quantities) or '(none)'}")
            vx, r = need("vx", "yaw_rate")
            params, note = None, None
            try:
                params = _bl.parameter_values(vehicle, _bl.STEADY_TURN_PARAMETERS, "the steady-turn forces", source)
            except _bl.BaselineUnavailable as exc:
                note = f"{exc}: roll angle, rider torque and steering rate only"
                unavailable[name] = {q: str(exc) for q in qs if q in _bl.STEADY_TURN_MODEL_OUTPUTS}
            y = _bl.steady_turn(vx, r, params)
            series[name] = {q: y[q] for q in qs if q in y}
            about[name] = {"what": "steady turn at the measured vx and yaw rate: roll angle atan(vx r / g), "
                                   "rider torque 0, steering rate 0; tyre forces and vy of the linear model's "
                                   "steady turn",
                           "inputs": {n: sources.get(n, "signal") for n in ("vx", "yaw_rate")},
                           "vehicle": vname, **({"parameters": params} if params else {}),
                           **({"note": note} if note else {})}
    except _bl.BaselineUnavailable as exc:
        skipped[name] = str(exc)
        unavailable[name] = {q: str(exc) for q in qs}
    if fit is not None:
        mask, refs = fit
        reg: dict[str, np.ndarray] = {}
        try:
            for q in quantities:
                if q in refs:
                    reg[q], info = _bl.regression(t, signals, refs[q], mask)
                    about.setdefault("regression", {"what": "ridge regression of the reference on the sensor "
                                                            f"columns {', '.join(_bl.REGRESSION_SIGNALS)}, their "
                                                            "products and quotients of the bicycle's relations, "
                                                            "raw and causally low-passed, fitted on the tuning "
                                                            "part only (penalty by blocked cross-validation)",
                                                    "inputs": {n: sources.get(n, "signal")
                                                               for n in _bl.REGRESSION_SIGNALS}, "fits": {}})
                    about["regression"]["fits"][q] = info
            if reg:
                series["regression"] = reg
        except _bl.BaselineUnavailable as exc:
            skipped["regression"] = str(exc)
            unavailable["regression"] = {q: str(exc) for q in quantities if q in refs}
    return {"series": series, "skipped": skipped, "about": about,
            "unavailable": {b: u for b, u in unavailable.items() if u}}


def baseline_summary(observer_rms: float | None, baseline_rms: dict[str, float | None], statistic: str,
                     observer: str = "estimate", not_computed: dict[str, str] | None = None) -> dict[str, Any]:
    """The verdict on one estimate: the observer's error statistic beside every baseline's, all on
    the same samples. ``ratio`` = observer / best baseline (< 1: the observer is better);
    ``baselines_as_good``: EVERY baseline as good as or better than the observer (its statistic
    <= the observer's; a finite baseline beats an observer whose statistic is not finite, null);
    ``baseline_as_good``: any such baseline; ``not_computed`` {baseline: reason}: baselines that
    apply to the estimate but could not be computed; ``observer_best``: True only when every
    applicable baseline was computed and each is worse than the observer, False when one is as
    good or better, None (no verdict) otherwise."""
    valid = {b: v for b, v in baseline_rms.items() if v is not None}
    best = min(valid, key=valid.get) if valid else None
    y = valid.get(best) if best else None
    ratio = _f(observer_rms / y) if (observer_rms is not None and y) else None
    as_good = [b for b, v in valid.items() if observer_rms is None or v <= observer_rms]
    missing = dict(not_computed or {})
    verdict = False if as_good else (True if (valid and not missing) else None)
    return {"statistic": statistic, "observer": observer, "observer_rms": observer_rms,
            "baselines": dict(baseline_rms), "best_baseline": best, "best_baseline_rms": y, "ratio": ratio,
            "baselines_as_good": as_good, "baseline_as_good": bool(as_good) if valid else None,
            "not_computed": missing, "observer_best": verdict}


def simulation_baselines(result: SimResult, label: str, quantities) -> dict[str, Any]:
    """:func:`baselines_for` of observer ``label`` of a co-simulation: driven by what the observers
    received (``result.measured``, noise included) where the signal was measured, else by the bus
    (truth), with the design summary ``result.info["observer_designs"][label]``."""
    info = result.info or {}
    design = (info.get("observer_designs") or {}).get(label)
    model = (info.get("observer_models") or {}).get(label)
    bus, meas = result.bus, result.measured or {}
    signals = {**bus, **meas}
    sources = {k: ("measured (as the observers received it)" if k in meas else "bus (truth)") for k in signals}
    return baselines_for(result.time, signals, quantities, design, model, sources)


def _simulation_baselines(result: SimResult, label: str, o: dict[str, Any], after: np.ndarray) -> dict[str, Any]:
    """The ``baselines`` entry of observer ``label`` (its estimates and intervals already scored in ``o``)."""
    bus = result.bus
    targets = {name: (quantity_of(name), e) for name, e in o["estimates"].items()}
    targets.update({name: (name, e) for name, e in o["intervals"].items()})
    b = simulation_baselines(result, label, [q for q, _ in targets.values()])
    out: dict[str, Any] = {}
    for base, ser in b["series"].items():
        out[base] = {name: estimate_entry(*same_samples(ser[q], bus[e["truth"]], after, e), e["truth"],
                                          e.get("unit"))
                     for name, (q, e) in targets.items() if q in ser}
    summary = {}
    outs = result.observers[label]
    for name, (q, e) in targets.items():
        if name in o["estimates"]:
            obs_entry, what = e, "estimate"
        else:
            mid = 0.5 * (np.asarray(outs[e["lower"]], dtype=float) + np.asarray(outs[e["upper"]], dtype=float))
            obs_entry, what = estimate_entry(mid, bus[e["truth"]], after, e["truth"], e.get("unit")), \
                "interval midpoint"
        # the same samples for the observer and every baseline: after settling when there are any
        stat = "rms_after_settle" if np.any(after) else "rms"
        rms = {base: out[base][name][stat] for base in out if name in out[base]}
        missing = {base: u[q] for base, u in b["unavailable"].items() if q in u}
        if rms or missing:
            summary[name] = baseline_summary(obs_entry.get(stat), rms, stat, what, missing)
    out["summary"] = summary
    out["skipped"] = b["skipped"]
    out["about"] = b["about"]
    return out


def write_json_atomic(data: Any, path: str | os.PathLike) -> Path:
    """Write strict JSON (no NaN) to ``path`` via a temporary file and os.replace."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    text = json.dumps(_sanitize(data), indent=2, allow_nan=False)
    return atomic_write_text(path, text + "\n")


def _sanitize(x):
    """JSON-ready copy: numpy scalars/arrays to Python, non-finite floats to None, paths to str."""
    if isinstance(x, dict):
        return {str(k): _sanitize(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_sanitize(v) for v in x]
    if isinstance(x, np.ndarray):
        return _sanitize(x.tolist())
    if isinstance(x, np.generic):
        x = x.item()
    if isinstance(x, float) and not math.isfinite(x):
        return None
    if isinstance(x, os.PathLike):
        return os.fspath(x)
    if x is None or isinstance(x, (str, int, float, bool)):
        return x
    raise TypeError(f"not JSON serialisable: {type(x).__name__}")


def write(metrics: dict, out_dir: str | os.PathLike, filename: str = "metrics.json") -> Path:
    """Write ``metrics`` to ``out_dir/metrics.json`` atomically; returns the path."""
    return write_json_atomic(metrics, Path(out_dir) / filename)


# --------------------------------------------------------------------------------------------
# a streamed co-simulation: the metrics summed block by block
# --------------------------------------------------------------------------------------------
class _Sum:
    """Count, sum, sum of squares, max |x| (a NaN kept, as np.max keeps it) and non-finite count
    of samples given block by block."""

    __slots__ = ("n", "s1", "s2", "mx", "nonfinite")

    def __init__(self):
        self.n, self.s1, self.s2, self.mx, self.nonfinite = 0, 0.0, 0.0, None, 0

    def add(self, e) -> None:
        e = np.asarray(e, dtype=float)
        if not e.size:
            return
        self.n += int(e.size)
        self.s1 += float(np.sum(e))
        self.s2 += float(np.sum(e ** 2))
        m = float(np.max(np.abs(e)))
        self.mx = m if self.mx is None else float(np.maximum(self.mx, m))
        self.nonfinite += int(np.sum(~np.isfinite(e)))

    def rms(self) -> float | None:
        """_rms of the samples (None without samples or when not finite)."""
        return _f(math.sqrt(self.s2 / self.n)) if self.n else None

    def maxabs(self) -> float | None:
        return _f(self.mx) if self.n else None

    def mean(self) -> float | None:
        return _f(self.s1 / self.n) if self.n else None

    def raw_rms(self) -> float:
        """The campaign's RMS (NaN without samples, a non-finite value kept)."""
        return math.sqrt(self.s2 / self.n) if self.n else math.nan


class _Max:
    """np.nanmax of samples given block by block (None: none finite or NaN-free seen)."""

    __slots__ = ("v", "finite")

    def __init__(self):
        self.v, self.finite = None, False

    def add(self, x) -> None:
        x = np.asarray(x, dtype=float)
        ok = ~np.isnan(x)
        if ok.any():
            m = float(np.max(x[ok]))
            self.v = m if self.v is None else max(self.v, m)
        self.finite = self.finite or bool(np.any(np.isfinite(x)))


class StreamedMetrics:
    """The metrics of a co-simulation streamed in blocks
    (:meth:`latobs.validation.master.CoSimulation._simulate_blocks`), summed over the blocks: :meth:`add` each block (its rows k0 .. k0 + m, row 0 the previous
    block's last row), then :meth:`compute` (the dict of :func:`compute`) or :meth:`flat` (the
    campaign's flat metrics, :func:`latobs.validation.campaign_run.result_metrics`). The same values
    as the whole-array functions up to the rounding of the sums (~1e-15 relative): sums of squares,
    maxima and counts over every sample (or every pair of consecutive samples for what is scored
    one step behind, mode switches and occupancy). The model baselines (the bicycle, the steady turn),
    which simulate a model over the whole run, are not computed: ``baselines`` has the zero baseline,
    and ``not_computed`` names the model baseline in each verdict (so no verdict that the observer
    is best)."""

    def __init__(self, settle_time: float | None = None):
        self.settle = settle_time
        self.obs: dict[str, dict[str, Any]] = {}
        self.acc: dict[tuple, Any] = {}
        self.t_first = self.t_last = None
        self.n = self.n_after = 0
        self.dt = None

    def _a(self, *key, cls=_Sum):
        a = self.acc.get(key)
        if a is None:
            a = self.acc[key] = cls()
        return a

    def _setup(self, part: SimResult) -> None:
        models = (part.info or {}).get("observer_models", {})
        for label, outs in part.observers.items():
            model = models.get(label)
            hats = {n: truth_signal(n[:-4], part.bus, model) for n in outs if n.endswith("_hat")}
            filt = {n: truth_signal(quantity_of(n), part.bus, model) for n in filtered_outputs(outs)}
            pairs = {n[:-6]: truth_signal(n[:-6], part.bus, model) for n in outs
                     if n.endswith("_lower") and n[:-6] + "_upper" in outs}
            self.obs[label] = {"model": model, "outputs": list(outs),
                               "hats": {n: x for n, x in hats.items() if x is not None},
                               "filtered": {n: x for n, x in filt.items() if x is not None},
                               "pairs": {q: x for q, x in pairs.items() if x is not None},
                               "flag": next((f for f in ("valid", "consistent") if f in outs), None),
                               "inputs": list(part.inputs.get(label, ()))}

    def add(self, k0: int, part: SimResult) -> None:
        t = np.asarray(part.time, dtype=float)
        if not self.obs and not self.n:
            self._setup(part)
            self.dt = float(part.dt)
            if self.settle is None:
                self.settle = float(part.settle_time)
        s0 = 0 if k0 == 0 else 1                        # rows new in this block (row 0: the previous last)
        new = slice(s0, None)
        after_all = t >= self.settle - 1e-12
        after = after_all[new]
        if self.t_first is None:
            self.t_first = float(t[0])
        self.t_last = float(t[-1])
        self.n += t.size - s0
        self.n_after += int(np.sum(after))
        bus = part.bus
        for label, meta in self.obs.items():
            outs = part.observers[label]
            flag = meta["flag"]
            valid_all = after_all & (np.asarray(outs[flag]) != 0) if flag else None
            a = self._a

            def est(key, e, x, sel, vsel):
                a(label, key, "all").add(e)
                a(label, key, "after").add(e[sel])
                a(label, key, "truth_after").add(x[sel])
                if vsel is not None:
                    a(label, key, "valid").add(e[vsel])

            for name, tr in meta["hats"].items():
                x = np.asarray(bus[tr], dtype=float)[new]
                e = np.asarray(outs[name], dtype=float)[new] - x
                v = valid_all[new] if flag else None
                est(("est", name), e, x, after, v)
                est(("zero", name), -x, x, after, v)
            for name, tr in meta["filtered"].items():
                if t.size < 2:
                    continue
                y, x, sel = one_step_behind(outs[name], bus[tr], after_all)
                v = valid_all[:-1] if flag else None
                est(("est", name), y - x, x, sel, v)
                est(("zero", name), -x, x, sel, v)
            for q, tr in meta["pairs"].items():
                lo = np.asarray(outs[q + "_lower"], dtype=float)[new]
                hi = np.asarray(outs[q + "_upper"], dtype=float)[new]
                x = np.asarray(bus[tr], dtype=float)[new]
                viol = (x < lo - ENCLOSURE_TOL) | (x > hi + ENCLOSURE_TOL) | ~np.isfinite(lo) | ~np.isfinite(hi)
                width = hi - lo
                over = np.maximum(lo - x, x - hi)
                a(label, "viol", q, "all", cls=list).append(int(np.sum(viol)))
                a(label, "viol", q, "after", cls=list).append(int(np.sum(viol[after])))
                a(label, "over", q, "all", cls=_Max).add(over)
                a(label, "over", q, "after", cls=_Max).add(over[after])
                a(label, "width", q, "all").add(width)
                a(label, "width", q, "after").add(width[after])
                v = valid_all[new] if flag else None
                mid = 0.5 * (lo + hi)
                est(("mid", q), mid - x, x, after, v)
                est(("zero", q), -x, x, after, v)
            beta = meta["hats"].get("beta_hat")
            if beta is not None and "bank_angle" in bus:
                e = np.asarray(outs["beta_hat"], dtype=float)[new] - np.asarray(bus[beta], dtype=float)[new]
                phi = np.asarray(bus["bank_angle"], dtype=float)[new]
                a(label, "l2e", "all").add(e)
                a(label, "l2e", "after").add(e[after])
                a(label, "l2phi", "all").add(phi)
                a(label, "l2phi", "after").add(phi[after])
            for ax, g in (("Ff", "Gamma_f"), ("Fr", "Gamma_r")):
                if f"{ax}_hat" in outs and ax in bus and g in bus:
                    F, G = np.asarray(bus[ax], dtype=float)[new], np.asarray(bus[g], dtype=float)[new]
                    zone = np.abs(G) > SATURATION_FRACTION * np.maximum(np.abs(F), 1e-9)
                    e = np.asarray(outs[f"{ax}_hat"], dtype=float)[new] - F
                    a(label, "sat", ax, "zone").add(e[zone])
                    a(label, "sat", ax, "out").add(e[~zone])
                    a(label, "sat", ax, "peak").add(np.abs(G) / np.maximum(np.abs(F), 1e-9))
            if "residual_norm" in outs:
                rn = np.asarray(outs["residual_norm"], dtype=float)[new]
                a(label, "rn", "all").add(rn)
                a(label, "rn", "after").add(rn[after])
            if "mode" in outs:
                m = np.asarray(outs["mode"])
                occ = a(label, "occ", cls=dict)
                w = np.diff(t)
                for mm in np.unique(m[:-1]):
                    occ[int(mm)] = occ.get(int(mm), 0.0) + float(np.sum(w[m[:-1] == mm]))
                a(label, "modes", cls=set).update(int(mm) for mm in np.unique(m[new]))
                a(label, "switches", cls=list).append(int(np.sum(m[1:] != m[:-1])))
            if "valid" in outs:
                v = np.asarray(outs["valid"])
                a(label, "invalid", cls=list).append(int(np.sum(v[new] == 0)))
                a(label, "episodes", cls=list).append(int(np.sum((v[1:] == 0) & (v[:-1] != 0)))
                                                      + (1 if k0 == 0 and v.size and v[0] == 0 else 0))
                a(label, "invalid_pairs", cls=list).append(int(np.sum(v[:-1] == 0)))
            if flag:
                a(label, "valid_after", cls=list).append(int(np.sum(valid_all[new])))
                a(label, "after_n", cls=list).append(int(np.sum(after)))

    def _get(self, *key, cls=_Sum):
        return self.acc.get(key) or cls()

    def _entry(self, label: str, key, truth: str, unit: str | None) -> dict[str, Any]:
        """estimate_entry's dict of the sums under ``key``."""
        al, af, tr = (self._get(label, key, s) for s in ("all", "after", "truth_after"))
        return {"truth": truth, "unit": unit, "rms": al.rms(), "max_abs": al.maxabs(),
                "rms_after_settle": af.rms(), "max_abs_after_settle": af.maxabs(),
                "mean_error_after_settle": af.mean(), "truth_rms_after_settle": tr.rms(),
                "nonfinite_samples": al.nonfinite}

    def _model_baseline(self, label: str, result: SimResult) -> tuple[str, tuple[str, ...], str]:
        info = result.info or {}
        design = (info.get("observer_designs") or {}).get(label)
        kind = observer_kind(design, self.obs[label]["model"])
        gives = _bl.BICYCLE_OUTPUTS if kind == "car" else (*_bl.STEADY_TURN_OUTPUTS, *_bl.STEADY_TURN_MODEL_OUTPUTS)
        why = (f"not computed for a streamed co-simulation ({self.n} samples, stepped block by block): it "
               "simulates a model over the whole run")
        return MODEL_BASELINE[kind], gives, why

    def compute(self, result: SimResult) -> dict[str, Any]:
        """:func:`compute`'s dict of the whole run (``result``: the streamed run's SimResult, its
        info, logs and units)."""
        dt, units = self.dt, result.units
        out: dict[str, Any] = {"scenario": result.scenario, "dt_s": dt, "duration_s": self.t_last - self.t_first,
                               "settle_time_s": self.settle, "n_samples": self.n, "info": result.info,
                               "observers": {}}
        for label, meta in self.obs.items():
            o: dict[str, Any] = {"estimates": {}, "intervals": {}}
            scored: set[str] = set()
            outs = meta["outputs"]
            for name, tr in meta["hats"].items():
                o["estimates"][name] = self._entry(label, ("est", name), tr, units.get(name) or units.get(tr))
                scored.add(name)
            for name, tr in meta["filtered"].items():
                if self.n > 1:
                    o["estimates"][name] = {**self._entry(label, ("est", name), tr, units.get(name) or units.get(tr)),
                                            "lag_steps": 1}
                    scored.add(name)
            for q, tr in meta["pairs"].items():
                lo, up = q + "_lower", q + "_upper"
                over = self._get(label, "over", q, "all", cls=_Max)
                wa, wf = self._get(label, "width", q, "all"), self._get(label, "width", q, "after")
                o["intervals"][q] = {
                    "truth": tr, "lower": lo, "upper": up, "unit": units.get(lo) or units.get(tr),
                    "enclosure_violations": sum(self._get(label, "viol", q, "all", cls=list)),
                    "enclosure_violations_after_settle": sum(self._get(label, "viol", q, "after", cls=list)),
                    "max_violation": _f(max(0.0, over.v if over.v is not None else math.nan)) if self.n else None,
                    "mean_width": wa.mean(), "mean_width_after_settle": wf.mean(),
                    "nonfinite_samples": wa.nonfinite}
                scored.update((lo, up))
            if "beta_hat" in meta["hats"] and self._get(label, "l2phi", "all").n:
                for key, s in (("beta_error_to_bank_l2_ratio", "all"),
                               ("beta_error_to_bank_l2_ratio_after_settle", "after")):
                    den = math.sqrt(self._get(label, "l2phi", s).s2 * dt)
                    o[key] = _f(math.sqrt(self._get(label, "l2e", s).s2 * dt) / den) if den > 0 else None
            sat = [ax for ax in ("Ff", "Fr") if (label, "sat", ax, "peak") in self.acc]
            if sat:
                o["saturation_zone"] = {}
                for ax in sat:
                    z, w, pk = (self._get(label, "sat", ax, s) for s in ("zone", "out", "peak"))
                    o["saturation_zone"][ax] = {
                        "samples": z.n, "fraction": _f(z.n / pk.n) if pk.n else None,
                        "rms": z.rms(), "max_abs": z.maxabs(), "rms_outside": w.rms(),
                        "peak_gamma_over_force": pk.maxabs()}
            if "residual_norm" in outs:
                ra, rf = self._get(label, "rn", "all"), self._get(label, "rn", "after")
                o["residual_norm"] = {"rms": ra.rms(), "max": ra.maxabs(), "rms_after_settle": rf.rms(),
                                      "max_after_settle": rf.maxabs()}
                scored.add("residual_norm")
            if "mode" in outs:
                occ = self._get(label, "occ", cls=dict)
                if self.n < 2:
                    o["mode_occupancy"] = {str(m): 1.0 for m in sorted(self._get(label, "modes", cls=set))}
                else:
                    total = self.t_last - self.t_first
                    o["mode_occupancy"] = {str(m): float(w / total) for m, w in sorted(occ.items())}
                o["mode_switches"] = sum(self._get(label, "switches", cls=list))
                scored.add("mode")
            if "valid" in outs:
                inv = sum(self._get(label, "invalid", cls=list))
                o["valid"] = {"fraction_invalid": _f(inv / self.n) if self.n else None,
                              "invalid_episodes": sum(self._get(label, "episodes", cls=list)),
                              "time_invalid_s": _f(sum(self._get(label, "invalid_pairs", cls=list)) * dt)
                              if self.n else None}
                scored.add("valid")
            o["unscored_outputs"] = sorted(set(outs) - scored)
            o["log_messages"] = len(result.logs.get(label, []))
            o["baselines"] = self._baselines(label, o, result)
            out["observers"][label] = o
        return out

    def _baselines(self, label: str, o: dict[str, Any], result: SimResult) -> dict[str, Any]:
        model, gives, why = self._model_baseline(label, result)
        targets = {name: (quantity_of(name), e, "estimate") for name, e in o["estimates"].items()}
        targets.update({name: (name, e, "interval midpoint") for name, e in o["intervals"].items()})
        out: dict[str, Any] = {}
        if targets:
            out["zero"] = {name: self._entry(label, ("zero", name), e["truth"], e.get("unit"))
                           for name, (q, e, _) in targets.items()}
        summary = {}
        for name, (q, e, what) in targets.items():
            obs = e if what == "estimate" else self._entry(label, ("mid", name), e["truth"], e.get("unit"))
            stat = "rms_after_settle" if self.n_after else "rms"    # as compute: after settling when any
            missing = {model: why} if q in gives else {}
            summary[name] = baseline_summary(obs.get(stat), {"zero": out["zero"][name][stat]}, stat, what, missing)
        out["summary"] = summary
        out["skipped"] = {model: why}
        out["about"] = {"zero": {"what": "every estimate 0 (beta, vy, bank angle, forces, roll angle, torque ...), "
                                         "summed over the blocks"}} if targets else {}
        return out

    def flat(self, result: SimResult) -> dict[str, float]:
        """The campaign's flat metrics of every observer (``observer_metrics`` and, of
        ``baseline_metrics``, the zero baseline: the model baseline is not computed, so no ``wins``
        verdict but 0 when the zero baseline is as good), on the samples after the settle time."""
        out: dict[str, float] = {}
        for label, meta in self.obs.items():
            model, gives, why = self._model_baseline(label, result)
            nonfinite = 0
            outs = meta["outputs"]
            for name in outs:
                if name in meta["hats"] or name in meta["filtered"]:
                    if name in meta["filtered"] and self.n < 2:
                        continue
                    key = name if name in meta["filtered"] else name[:-4]
                    s = self._get(label, ("est", name), "after")
                    nonfinite += s.nonfinite
                    out[f"{label}.{key}.rms"] = s.raw_rms()
                    out[f"{label}.{key}.max_abs"] = s.mx if s.n else math.nan
                elif name.endswith("_lower") and name[:-6] in meta["pairs"]:
                    q = name[:-6]
                    over = self._get(label, "over", q, "after", cls=_Max)
                    w = self._get(label, "width", q, "after")
                    nonfinite += w.nonfinite
                    out[f"{label}.{q}.violations"] = float(sum(self._get(label, "viol", q, "after", cls=list)))
                    mv = _f(max(0.0, over.v)) if w.n and over.finite and over.v is not None else None
                    out[f"{label}.{q}.max_violation"] = float(mv or 0.0)
                    out[f"{label}.{q}.mean_width"] = math.nan if w.mean() is None else float(w.mean())
            out[f"{label}.nonfinite"] = float(nonfinite)
            # the baselines: X_hat, X_filtered, or an interval's midpoint (when no X_hat), not an input
            ins = set(meta["inputs"])
            targets = {}
            for name in outs:
                if name in meta["hats"] and name[:-4] not in ins:
                    targets[name[:-4]] = (("est", name), name[:-4], "estimate")
                elif name in meta["filtered"] and quantity_of(name) not in ins and self.n > 1:
                    targets[name] = (("est", name), quantity_of(name), "estimate")
                elif (name.endswith("_lower") and name[:-6] in meta["pairs"] and name[:-6] + "_hat" not in outs
                      and name[:-6] not in ins):
                    targets[name[:-6]] = (("mid", name[:-6]), name[:-6], "midpoint")
            if not targets:
                continue
            flag = meta["flag"]
            sels = {"": "after"}
            if flag is not None:
                sels["valid_"] = "valid"
                na = sum(self._get(label, "after_n", cls=list))
                out[f"{label}.valid_fraction"] = sum(self._get(label, "valid_after", cls=list)) / na if na else math.nan
            for key, (acc_key, q, what) in targets.items():
                zkey = ("zero", acc_key[1])
                missing = {model: why} if q in gives else {}
                for pre, s in sels.items():
                    obs_s, zero_s = self._get(label, acc_key, s), self._get(label, zkey, s)
                    obs = math.sqrt(obs_s.s2 / obs_s.n) if obs_s.n else None
                    zero = math.sqrt(zero_s.s2 / zero_s.n) if zero_s.n else None
                    baseline_row(out, label, key, pre, what, obs, {"zero": zero}, missing)
        return out


def baseline_row(row: dict[str, float], label: str, key: str, pre: str, what: str, obs: float | None,
                 base_rms: dict[str, float | None], missing: dict[str, str]) -> None:
    """The campaign's flat columns of one verdict (``baseline_metrics``), into ``row``: the
    observer's RMS ``obs`` beside each baseline's ``base_rms`` on the samples after settling
    (``pre`` "") or, ``pre`` "valid_", those where its validity flag is set; ``missing``: the
    baselines not computed. ``LABEL.KEY.[valid_]ratio`` and ``[valid_]wins``, ``valid_rms``, and
    for ``pre`` "": ``rms_B`` per baseline, ``midpoint_rms`` for an interval's midpoint."""
    v = baseline_summary(obs if obs is None or math.isfinite(obs) else None, base_rms, "rms", what, missing)
    if pre:
        row[f"{label}.{key}.valid_rms"] = math.nan if obs is None else obs
    else:
        if what == "midpoint":
            row[f"{label}.{key}.midpoint_rms"] = math.nan if obs is None else obs
        for base, r in base_rms.items():
            row[f"{label}.{key}.rms_{base}"] = math.nan if r is None else r
    row[f"{label}.{key}.{pre}ratio"] = math.nan if v["ratio"] is None else v["ratio"]
    row[f"{label}.{key}.{pre}wins"] = math.nan if v["observer_best"] is None else float(v["observer_best"])
