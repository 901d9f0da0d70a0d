"""``latobs replay``: a recorded CSV drives a built observer FMU through fmpy (inputs wired by column
name, the record checked first) and is scored against the reference columns it holds, on the
whole record and before and after a split time. Format, timing and scoring are on the
documentation's "Results files" page."""
from __future__ import annotations

import math
import os
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping

import numpy as np

from ..atomic import sha256_file  # noqa: F401  (also this module's: the record's identity)
from ..data import checks as _checks
from ..data import records as _records
from . import baselines as _baselines
from . import metrics as _metrics

#: The bundled real-vehicle record (MIT, see the README and LICENSE beside it).
MBDS_CSV = _records.MBDS_CSV
#: The word that stands for :data:`MBDS_CSV` on the command line.
MBDS_ALIAS = "mbds"
#: The vehicle parameter set of the MBDS record.
MBDS_VEHICLE = "mbds_250lm"
#: Default split time (s) per file name: the MBDS record is tuned on t < 425 s, tested on the rest.
DEFAULT_SPLITS = {"mbds_250lm_100hz.csv.gz": 425.0, "mbds_250lm_100hz.csv": 425.0}
UNIFORM_RTOL, UNIFORM_ULPS = _checks.UNIFORM_RTOL, _checks.UNIFORM_ULPS   # the time axis's rule (data.checks)
ZOOM_S = 20.0         # length of the zoomed figure's window, s
FORCE_BOUNDS = ("Fyf_lower", "Fyr_lower", "Fyf_upper", "Fyr_upper")


class ReplayError(ValueError):
    """A user-facing replay failure (file, column, time step, observer); the message names it."""


@dataclass(frozen=True)
class InputSpec:
    """An FMU input as :func:`check_record` sees it: name, unit, declared range (None: none)."""

    name: str
    unit: str | None = None
    min: float | str | None = None
    max: float | str | None = None


# --------------------------------------------------------------------------------------------
# the CSV file
# --------------------------------------------------------------------------------------------
def resolve_csv(csv_file: str | os.PathLike) -> Path:
    """The path of a CSV argument: the word ``mbds`` is the bundled :data:`MBDS_CSV`."""
    if str(csv_file) == MBDS_ALIAS:
        return MBDS_CSV
    return Path(csv_file)


def csv_stem(path: str | os.PathLike) -> str:
    """File name without ``.gz`` and ``.csv``: ``mbds_250lm_100hz.csv.gz`` -> ``mbds_250lm_100hz``."""
    name = Path(path).name
    for suffix in (".gz", ".csv"):
        if name.lower().endswith(suffix):
            name = name[: -len(suffix)]
    return name


def default_split(path: str | os.PathLike) -> float | None:
    """The split time (s) of a known file (:data:`DEFAULT_SPLITS`), else None."""
    return DEFAULT_SPLITS.get(Path(path).name)


def load_csv(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """:func:`latobs.data.records.load_csv` (a ``.csv`` or ``.csv.gz`` file with a header row into
    {column: float array}), its errors as :class:`ReplayError`."""
    try:
        return _records.load_csv(path)
    except _records.RecordError as exc:
        raise ReplayError(str(exc)) from None


#: bytes a replay holds per sample and value (the record's columns and the FMU's outputs): the
#: column itself, the master's matrices, the outputs' copies and the scoring's selections (a
#: lower estimate)
BYTES_PER_VALUE = 24


def check_resources(data: Mapping[str, np.ndarray], n_outputs: int, source: Any = "the record") -> None:
    """Refuse (ResourceLimitError, naming the estimate and the limit) a replay of ``data`` through
    an FMU with ``n_outputs`` outputs that would not fit in memory, before the FMU is built or run."""
    from ..data import budget

    n = len(data["t"]) if "t" in data else 0
    budget.check(f"replaying {source} ({n} samples of {len(data)} columns, {n_outputs} outputs)",
                 memory=n * (len(data) + n_outputs) * BYTES_PER_VALUE)


def uniform_step(t: np.ndarray, source: Any = "the record") -> float:
    """The time step of ``t`` (s): the mean step, when the record is uniform, by the rule
    ``latobs identify`` shares (:func:`latobs.data.checks.uniform_step`: time relative to the first
    sample, every step within UNIFORM_RTOL of the mean step plus UNIFORM_ULPS ulps of max|t|);
    otherwise a ReplayError names the step that departs most from the usual (median) step, where
    it is (data rows and times) and by how much."""
    return _checks.uniform_step(t, source, ReplayError)


def check_record(data: Mapping[str, np.ndarray], inputs, source: Any = "the record",
                 who: str = "the observer", first_row: int = 0) -> None:
    """Check that the record ``data`` ({column: array}) can drive an FMU whose inputs are
    ``inputs`` (objects with ``name``, ``unit`` and optional ``min``/``max``, SI: an FMU's
    model-description variables or a model file's declared variables), before anything is built or
    run: every input has its column; an angle input (unit rad) stays within +-pi, else the record is
    most likely in degrees; every value lies in the input's declared range. A ReplayError names
    ``who``, the signals it needs, the missing ones, or the column, row and value out of range
    (``data`` a block of a record: its first row is the record's data row ``first_row + 1``)."""
    names = [v.name for v in inputs]
    missing = [x for x in names if x not in data]
    if missing:
        raise ReplayError(
            f"{who} cannot run on {source}: it needs the signals {', '.join(names)} (one column each), and the "
            f"record lacks {', '.join(repr(m) for m in missing)} (its columns: {', '.join(data)})")
    for v in inputs:
        x = np.asarray(data[v.name], dtype=float)
        unit = getattr(v, "unit", None)
        if unit == "rad" and x.size and np.max(np.abs(x)) > math.pi:
            i = int(np.argmax(np.abs(x)))
            raise ReplayError(f"{source}: column {v.name!r} is an angle in rad, but reaches {x[i]:.6g} at data row "
                              f"{first_row + i + 1} (beyond +-pi): the record looks like degrees; give it in SI units "
                              "(rad)")
        lo, hi = getattr(v, "min", None), getattr(v, "max", None)
        lo = None if lo is None else float(lo)
        hi = None if hi is None else float(hi)
        out = np.zeros(x.shape, dtype=bool)
        if lo is not None:
            out |= x < lo
        if hi is not None:
            out |= x > hi
        if out.any():
            i = int(np.argmax(out))
            shown = f"{x[i]:.6g}" + (f" {unit}" if unit and unit != "1" else "")
            raise ReplayError(f"{source}: column {v.name!r} = {shown} at data row {first_row + i + 1} is outside "
                              f"the range [{'-inf' if lo is None else f'{lo:g}'}, {'inf' if hi is None else f'{hi:g}'}]"
                              f" that {who} declares for input {v.name!r} ({int(out.sum())} row(s) outside)")


def unit_warnings(data: Mapping[str, np.ndarray], source: Any = "the record",
                  design: Mapping[str, Any] | None = None) -> list[str]:
    """What in the record looks like another unit than SI (degrees, km/h, g, milliseconds: the rule
    ``latobs identify`` refuses by, :func:`latobs.data.checks.unit_findings`, with the wheelbase of
    the FMU's design vehicle when it has one), each printed as a warning on stderr; returned."""
    try:
        geo = _baselines.parameter_values(_metrics.design_vehicle(design), ["lf", "lr"])
        wheelbase = geo["lf"] + geo["lr"]
    except _baselines.BaselineUnavailable:      # no design file, or no such geometry: without it
        wheelbase = None
    found = [f"{source}: {msg}" for msg in _checks.unit_findings(data, wheelbase)]
    for msg in found:
        print(f"warning: {msg}", file=sys.stderr)
    return found


# --------------------------------------------------------------------------------------------
# driving the FMU
# --------------------------------------------------------------------------------------------
@dataclass
class ReplayRun:
    """The recorded columns and the FMU's outputs on the same time grid.

    time      t (s) of the CSV, shape (n,)
    columns   {column: array} every CSV column but t (SI units)
    outputs   {output: array} every Real/Integer/Boolean output of the FMU (outputs at t_k)
    inputs    FMU input names (each wired to the column of the same name)
    units     {variable: unit} as the modelDescription declares them
    design    summary of the design file baked into the FMU (harness.design_summary), None if none
    """

    time: np.ndarray
    columns: dict[str, np.ndarray]
    outputs: dict[str, np.ndarray]
    inputs: list[str]
    dt: float
    fmu: Path
    model_name: str
    label: str
    units: dict[str, str] = field(default_factory=dict)
    logs: list[str] = field(default_factory=list)
    design: dict[str, Any] | None = None


def start(f, row0: Mapping[str, float], parameters, t0: float, t_end: float) -> dict[str, Any]:
    """The FMU instance ``f`` initialised with the inputs ``row0`` at ``t0``: its outputs there
    (a failure is a ReplayError with its last log messages)."""
    try:
        return f.start(row0, parameters, t0, t_end)
    except Exception as exc:
        raise ReplayError(f"{f.describe()} failed in initialisation at t = {t0:.6g} s: "
                          f"{str(exc).rstrip('.')}. Last log messages: {f.log_tail()}") from None


def step_rows(f, in_names: list[str], t: np.ndarray, dt: float, cols: Mapping[str, np.ndarray],
              first: Mapping[str, Any]) -> dict[str, np.ndarray]:
    """The started FMU instance ``f`` stepped over the times ``t`` with the master's matrices and
    stepping loop (compiled where it can run): at t_k the row k of ``cols`` ({input: values}) in,
    one step, the outputs at t_k+1 out. ``first``: the outputs at t[0]. Returns {output: values at
    t} (float for Real, int64 for the others)."""
    from .instance import CoSimulationError, fmi_type
    from .master import Port, step_ports, store_input

    port = Port(f, in_names, t.size, checked=False)
    try:
        for x, (typ, j) in port.columns(port.inputs).items():
            store_input(port, typ, j, slice(None), cols[x], x, t)
        oc = port.columns(port.outputs)
        for x, (typ, j) in oc.items():
            port.outputs[typ][2][0, j] = first[x]
        step_ports(t, dt, [port])
    except CoSimulationError as exc:
        raise ReplayError(str(exc)) from None
    return {v.name: port.outputs[oc[v.name][0]][2][:, oc[v.name][1]].astype(
        float if fmi_type(v) == "Real" else np.int64) for v in f.outputs}


def drive(fmu_path: str | os.PathLike, data: Mapping[str, np.ndarray], label: str | None = None,
          source: Any = "the record", unzipdir: str | None = None,
          parameters: Mapping[str, Any] | None = None) -> ReplayRun:
    """Drive the FMU at ``fmu_path`` with the columns of ``data`` (``t`` and one column per FMU
    input; see the module docstring for the timing). ``source`` names the data in errors.
    ``unzipdir``: the folder the FMU is already extracted to (kept), else a temporary one.
    ``parameters``: FMU parameters set before initialisation (name: value)."""
    from .harness import FmuInstance, WiringError, _unit_of, observer_design

    fmu_path = Path(fmu_path)
    if not fmu_path.is_file():
        raise ReplayError(f"no FMU {fmu_path}")
    if "t" not in data:
        raise ReplayError(f"{source}: no time column 't'")
    t = np.asarray(data["t"], dtype=float)
    dt = uniform_step(t, source)
    cols = {k: np.asarray(v, dtype=float) for k, v in data.items() if k != "t"}
    label = label or fmu_path.stem
    try:
        f = FmuInstance(label, fmu_path, unzipdir)
    except WiringError as exc:
        raise ReplayError(str(exc)) from None
    except Exception as exc:  # not a zip, not an FMU
        raise ReplayError(f"cannot open FMU {fmu_path}: {exc}") from None
    try:
        in_names = [v.name for v in f.inputs]
        check_record(data, [InputSpec(v.name, _unit_of(v), v.min, v.max) for v in f.inputs], source, f.describe())
        units = {v.name: u for v in f.md.modelVariables if (u := _unit_of(v)) and v.causality in ("input", "output")}
        y0 = start(f, {x: float(cols[x][0]) for x in in_names}, parameters, float(t[0]), float(t[-1]))
        rec = step_rows(f, in_names, t, dt, cols, y0)
        logs = list(f.logs)
        if f.dropped_logs:
            logs.append(f"[INFO] replay: {f.dropped_logs} further log messages dropped")
        return ReplayRun(time=t, columns=cols, outputs=rec, inputs=in_names, dt=dt, fmu=fmu_path,
                         model_name=f.model_name, label=label, units=units, logs=logs,
                         design=observer_design(fmu_path))
    finally:
        f.close()


# --------------------------------------------------------------------------------------------
# scoring
# --------------------------------------------------------------------------------------------
def segments(t: np.ndarray, split: float | None) -> dict[str, np.ndarray]:
    """{"all": mask} and, with a split time, "before_split" (t < split), "after_split" (t >= split)."""
    t = np.asarray(t, dtype=float)
    segs = {"all": np.ones(t.size, dtype=bool)}
    if split is not None:
        segs["before_split"] = t < split
        segs["after_split"] = t >= split
    return segs


def score(run: ReplayRun, split: float | None = None, mass: float | None = None,
          vehicle: str | None = None, info: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """Metrics of a replay (SI units; non-finite values become null in the file)::

        {"kind": "replay", "scenario": "replay <csv stem>", "csv": path, "csv_sha256": hex,
         "observer": NAME, "label": FMU name, "fmu": path, "fmu_model": modelName, "vehicle": V,
         "dt_s", "n_samples", "t_start_s", "t_end_s", "duration_s", "split_s": T | null,
         "segments": {"all" | "before_split" | "after_split": {"t_from_s", "t_to_s", "n_samples"}},
         "inputs": [FMU inputs = CSV columns used], "columns": [CSV columns],
         "scored": [scored outputs], "nothing_scored": bool,
         "observers": {label: {
             "estimates": {"X_hat": {"truth": column, "unit", SEG: {"n_samples", "rms", "max_abs",
                                                                    "mean_error", "nonfinite_samples"}},
                           "X_filtered": {as X_hat, "lag_steps": 1: row k + 1 against the truth at row k}},
             "intervals": {"X": {"truth": column, "lower", "upper", "unit",
                                 SEG: {"n_samples", "enclosure_violations", "violation_rate",
                                       "enclosure_rate", "max_violation", "mean_width",
                                       "nonfinite_samples"},
                                 "midpoint": {SEG: {as an estimate: the bounds' midpoint}}}},
             "may_in_force_sum": {"quantity": "m*ay", "lower": ..., "upper": ..., "mass_kg",
                                  "vehicle", "unit": "N", SEG: {as an interval}},   # if applicable
             "modes": {SEG: {"occupancy": {"1": fraction, ...}, "switches": int}},   # if `mode`
             "baselines": {"zero" | "bicycle" | "steady_turn": {name: {"truth", "unit", SEG: {as an
                                                                estimate}}},
                           "summary": {name: {"segment": SEG, "statistic": "rms", "observer", "observer_rms",
                                              "baselines", "best_baseline", "best_baseline_rms", "ratio",
                                              "baseline_as_good", "baselines_as_good", "not_computed",
                                              "observer_best"}},   # metrics.baseline_summary
                           "skipped": {baseline: reason}, "about": {baseline: {...}}},
             "unscored_outputs": [...], "log_messages": int, "log_excerpt": [first messages]}}}

    SEG is each key of "segments" (``all``; with a split also ``before_split``/``after_split``).
    Baselines (:func:`latobs.validation.metrics.baselines_for`): every scored estimate (and
    interval, by its midpoint) is also scored for the zero estimate and the model baseline
    driven by the record's own columns (the car's linear bicycle needs ``delta`` and ``vx``,
    started from the steady state of the first row; the motorcycle's steady turn ``vx`` and
    ``yaw_rate``), with the parameters of the design file baked into the FMU (``run.design``);
    the summary compares RMS errors on the held-out part (``after_split``) when there is a split,
    else on the whole record. A baseline without its columns or parameters is in ``skipped`` and,
    beside each estimate it would have given, in the summary's ``not_computed`` (no verdict then).
    """
    t = run.time
    cols = run.columns
    segs = segments(t, split)
    outs = run.outputs
    o: dict[str, Any] = {"estimates": {}, "intervals": {}}
    scored: set[str] = set()
    hats, pairs = _metrics.estimated_quantities(outs)
    for q in hats:
        truth = _metrics.truth_signal(q, cols, run.model_name)
        if truth is None:
            continue
        name = q + "_hat"
        y, x = np.asarray(outs[name], dtype=float), cols[truth]
        o["estimates"][name] = {"truth": truth, "unit": run.units.get(name) or run.units.get(truth),
                                **{s: _metrics.error_stats(y[m], x[m]) for s, m in segs.items()}}
        scored.add(name)
    for name in _metrics.filtered_outputs(outs):       # x(k|k), published one step behind
        truth = _metrics.truth_signal(_metrics.quantity_of(name), cols, run.model_name)
        if truth is None or t.size < 2:
            continue
        stats = {s: _metrics.error_stats(*_selected(*_metrics.one_step_behind(outs[name], cols[truth], m)))
                 for s, m in segs.items()}
        o["estimates"][name] = {"truth": truth, "unit": run.units.get(name) or run.units.get(truth), "lag_steps": 1,
                                **stats}
        scored.add(name)
    for q in pairs:
        truth = _metrics.truth_signal(q, cols, run.model_name)
        if truth is None:
            continue
        lo, hi = np.asarray(outs[q + "_lower"], dtype=float), np.asarray(outs[q + "_upper"], dtype=float)
        x = cols[truth]
        mid = 0.5 * (lo + hi)
        o["intervals"][q] = {"truth": truth, "lower": q + "_lower", "upper": q + "_upper",
                             "unit": run.units.get(q + "_lower") or run.units.get(truth),
                             **{s: _metrics.enclosure_stats(lo[m], hi[m], x[m]) for s, m in segs.items()},
                             # the interval's midpoint as a point estimate (compared with the baselines)
                             "midpoint": {s: _metrics.error_stats(mid[m], x[m]) for s, m in segs.items()}}
        scored.update((q + "_lower", q + "_upper"))
    if all(b in outs for b in FORCE_BOUNDS) and "ay" in cols:
        entry = force_sum_entry(mass, vehicle)
        if mass is not None:
            lo = np.asarray(outs["Fyf_lower"], float) + np.asarray(outs["Fyr_lower"], float)
            hi = np.asarray(outs["Fyf_upper"], float) + np.asarray(outs["Fyr_upper"], float)
            x = float(mass) * cols["ay"]
            entry.update({s: _metrics.enclosure_stats(lo[m], hi[m], x[m]) for s, m in segs.items()})
            scored.add("may_in_force_sum")
        o["may_in_force_sum"] = entry
    if "mode" in outs:
        mo = np.asarray(outs["mode"])
        o["modes"] = {s: ({"occupancy": _metrics.mode_occupancy(t[m], mo[m]),
                           "switches": int(np.sum(mo[m][1:] != mo[m][:-1]))} if m.any() else None)
                      for s, m in segs.items()}
    o["baselines"] = _replay_baselines(run, o, segs, "after_split" if split is not None else "all")
    o["unscored_outputs"] = sorted(set(outs) - scored - {"mode"})
    o["log_messages"] = len(run.logs)
    o["log_excerpt"] = run.logs[:10]
    meta = dict(info or {})
    csv_path = meta.pop("csv", None)
    out: dict[str, Any] = {
        "kind": "replay",
        "scenario": f"replay {csv_stem(csv_path) if csv_path else 'record'}",
        "csv": str(csv_path) if csv_path else None,
        **meta,
        "label": run.label,
        "fmu": str(run.fmu),
        "fmu_model": run.model_name,
        "vehicle": vehicle,
        "dt_s": run.dt,
        "n_samples": int(t.size),
        "t_start_s": float(t[0]),
        "t_end_s": float(t[-1]),
        "duration_s": float(t[-1] - t[0]),
        "split_s": split,
        "segments": {s: {"t_from_s": float(t[m][0]) if m.any() else None,
                         "t_to_s": float(t[m][-1]) if m.any() else None,
                         "n_samples": int(np.sum(m))} for s, m in segs.items()},
        "inputs": list(run.inputs),
        "columns": ["t", *run.columns],
        "scored": sorted(scored),
        "nothing_scored": not scored,
        "observers": {run.label: o},
    }
    return out


def force_sum_entry(mass: float | None, vehicle: str | None) -> dict[str, Any]:
    """The head of the ``may_in_force_sum`` entry of :func:`score` (its statistics added beside)."""
    entry: dict[str, Any] = {"quantity": "m*ay", "lower": "Fyf_lower + Fyr_lower", "upper": "Fyf_upper + Fyr_upper",
                             "reference": "paper 001 eq. (47)", "mass_kg": mass, "vehicle": vehicle, "unit": "N"}
    if mass is None:
        entry["skipped"] = f"vehicle {vehicle!r} has no mass parameter m"
    return entry


def _selected(y, x, mask):
    """(y[mask], x[mask])."""
    return np.asarray(y)[mask], np.asarray(x)[mask]


def _replay_baselines(run: ReplayRun, o: Mapping[str, Any], segs: Mapping[str, np.ndarray],
                      seg: str) -> dict[str, Any]:
    """The ``baselines`` entry of a replay (see :func:`score`)."""
    cols = run.columns
    targets = {name: (_metrics.quantity_of(name), e) for name, e in o["estimates"].items()}
    targets.update({name: (name, e) for name, e in o["intervals"].items()})
    # with a split, the regression baseline is fitted on the tuning part (before it) only
    fit = ((segs["before_split"], {q: cols[e["truth"]] for q, e in targets.values()})
           if "before_split" in segs and segs["before_split"].any() else None)
    b = _metrics.baselines_for(run.time, cols, [q for q, _ in targets.values()], run.design, run.model_name,
                               sources={k: "recorded column" for k in cols}, initial="steady", fit=fit)
    out: dict[str, Any] = {}
    for base, ser in b["series"].items():
        out[base] = {name: {"truth": e["truth"], "unit": e.get("unit"),
                            **{s: _metrics.error_stats(*_selected(*_metrics.same_samples(ser[q], cols[e["truth"]],
                                                                                         m, e)))
                               for s, m in segs.items()}}
                     for name, (q, e) in targets.items() if q in ser}
    summary = {}
    for name, (q, e) in targets.items():
        if name in o["estimates"]:
            obs_rms, what = (e.get(seg) or {}).get("rms"), "estimate"
        else:
            obs_rms, what = ((e.get("midpoint") or {}).get(seg) or {}).get("rms"), "interval midpoint"
        rms = {base: out[base][name][seg]["rms"] for base in out if name in out[base]}
        missing = {base: u[q] for base, u in b["unavailable"].items() if q in u}
        if rms or missing:
            summary[name] = {"segment": seg, **_metrics.baseline_summary(obs_rms, rms, "rms", what, missing)}
    out["summary"] = summary
    out["skipped"] = b["skipped"]
    out["about"] = b["about"]
    return out


# --------------------------------------------------------------------------------------------
# figures
# --------------------------------------------------------------------------------------------
def _panels(run: ReplayRun, mass: float | None) -> list[dict[str, Any]]:
    """What to draw: per estimated quantity its truth (if any), estimate and/or band; m*ay and the
    force-sum band last."""
    from .units import PREFERRED

    outs = run.outputs
    hats, pairs = _metrics.estimated_quantities(outs)
    qs = list(dict.fromkeys([*hats, *pairs]))
    qs = [q for q in PREFERRED if q in qs] + sorted(set(qs) - set(PREFERRED))
    # the model baseline of the metrics (not zero), drawn thin and dashed
    b = _metrics.baselines_for(run.time, run.columns, qs, run.design, run.model_name, initial="steady")
    base = {q: (f"{n.replace('_', ' ')} baseline", y) for n, ser in b["series"].items() if n != "zero"
            for q, y in ser.items()}
    panels = []
    for q in qs:
        truth = _metrics.truth_signal(q, run.columns, run.model_name)
        p = {"name": q, "truth": truth, "truth_y": run.columns[truth] if truth else None,
             "hat": outs.get(q + "_hat"), "band": None, "baseline": base.get(q)}
        if q in pairs:
            p["band"] = (outs[q + "_lower"], outs[q + "_upper"])
        panels.append(p)
    if all(b in outs for b in FORCE_BOUNDS):
        lo = np.asarray(outs["Fyf_lower"], float) + np.asarray(outs["Fyr_lower"], float)
        hi = np.asarray(outs["Fyf_upper"], float) + np.asarray(outs["Fyr_upper"], float)
        have = mass is not None and "ay" in run.columns
        panels.append({"name": "force_sum", "truth": "m*ay" if have else None,
                       "truth_y": float(mass) * run.columns["ay"] if have else None, "hat": None,
                       "band": (lo, hi), "label": "Fyf + Fyr", "unit": "N"})
    return panels


def activity_window(run: ReplayRun, panels: list[dict[str, Any]], length: float = ZOOM_S,
                    before: float | None = None) -> tuple[int, int]:
    """Index range [i0, i1) of the ``length``-second window with the most activity: the largest
    sum over the panels' truths (else estimates) of the squared deviation from the median, each
    signal normalised by its standard deviation. With ``before`` (the split time), the window is
    taken from t < before when that part is long enough: the held-out part is not inspected."""
    n = run.time.size
    w = int(round(length / run.dt)) + 1
    if w >= n:
        return 0, n
    if before is not None:
        n_before = int(np.sum(run.time < before))
        if n_before >= w:
            n = n_before
    a = np.zeros(n)
    for p in panels:
        y = p["truth_y"] if p["truth_y"] is not None else p["hat"]
        if y is None and p["band"] is not None:
            y = 0.5 * (np.asarray(p["band"][0], float) + np.asarray(p["band"][1], float))
        if y is None:
            continue
        y = np.asarray(y, float)[:n]
        y = np.where(np.isfinite(y), y, np.nanmedian(y) if np.isfinite(y).any() else 0.0)
        s = float(np.std(y))
        if s > 0:
            a += ((y - np.median(y)) / s) ** 2
    c = np.concatenate([[0.0], np.cumsum(a)])
    i0 = int(np.argmax(c[w:] - c[:-w]))
    return i0, i0 + w


def _figure(run: ReplayRun, panels, sl: slice, title: str, split: float | None, path: Path) -> Path:
    from matplotlib.figure import Figure

    from .plots import BASELINE_STYLE, _save, _ylabel, display_scale, thin

    t = run.time[sl]
    fig = Figure(figsize=(13, 2.3 * len(panels) + 0.8), layout="constrained")   # legends beside the data
    axes = fig.subplots(len(panels), 1, sharex=True, squeeze=False)[:, 0]
    lab = run.label
    for ax, p in zip(axes, panels):
        if p["name"] == "force_sum":
            k, ylabel = 1.0, "lateral force [N]"
        else:
            k, _ = display_scale(p["name"], run.units)
            ylabel = _ylabel(p["name"], run.units)
        if p["band"] is not None:
            lo, hi = (k * np.asarray(b, float)[sl] for b in p["band"])
            i = thin(t, lo, hi)
            name = p.get("label") or p["name"]
            blabel = f"{lab}: {name} bounds" if p["name"] == "force_sum" else \
                f"{lab}: [{name}_lower, {name}_upper]"
            ax.fill_between(t[i], lo[i], hi[i], alpha=0.3, color="tab:blue", lw=0, label=blabel)
        if p["truth_y"] is not None:
            y = k * np.asarray(p["truth_y"], float)[sl]
            i = thin(t, y)
            ax.plot(t[i], y[i], color="black", lw=1.0, label=f"{p['truth']} (recorded)")
        if p.get("baseline") is not None:
            y = k * np.asarray(p["baseline"][1], float)[sl]
            i = thin(t, y)
            ax.plot(t[i], y[i], label=p["baseline"][0], **BASELINE_STYLE)
        if p["hat"] is not None:
            y = k * np.asarray(p["hat"], float)[sl]
            i = thin(t, y)
            ax.plot(t[i], y[i], color="tab:red", lw=0.9, label=f"{lab}: {p['name']}_hat")
        if split is not None and t[0] < split <= t[-1]:
            ax.axvspan(split, t[-1], color="0.85", alpha=0.5, lw=0, zorder=0,
                       label=f"held-out test (t ≥ {split:g} s)" if ax is axes[0] else None)
        ax.set_ylabel(ylabel, fontsize=8)
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)
    axes[-1].set_xlabel("time [s]")
    axes[-1].set_xlim(float(t[0]), float(t[-1]))
    fig.suptitle(title, fontsize=10)
    return _save(fig, path)


def write_plots(run: ReplayRun, metrics: Mapping[str, Any], out_dir: str | os.PathLike,
                mass: float | None = None) -> list[Path]:
    """``replay.png`` (whole record) and ``replay_zoom.png`` (the 20 s window of most activity, in
    t < split when there is a split; only for a record longer than 20 s); returns the paths
    written (none when the observer has no estimate or interval output)."""
    panels = _panels(run, mass)
    if not panels:
        return []
    out_dir = Path(out_dir)
    split = metrics.get("split_s")
    head = f"{metrics.get('scenario', 'replay')} through {run.label}"
    paths = [_figure(run, panels, slice(None), f"{head}: whole record", split, out_dir / "replay.png")]
    i0, i1 = activity_window(run, panels, before=split)
    if i1 - i0 < run.time.size:
        t0, t1 = run.time[i0], run.time[i1 - 1]
        where = "" if split is None else (" (held-out part)" if t0 >= split else
                                          " (tuning part)" if t1 < split else " (across the split)")
        paths.append(_figure(run, panels, slice(i0, i1),
                             f"{head}: {t0:.2f}–{t1:.2f} s, the {ZOOM_S:g} s of most activity{where}",
                             split, out_dir / "replay_zoom.png"))
    return paths


# --------------------------------------------------------------------------------------------
# all of it
# --------------------------------------------------------------------------------------------
def run(csv_file: str | os.PathLike, fmu_path: str | os.PathLike, out_dir: str | os.PathLike,
        split: float | None | str = "auto", observer: str | None = None, vehicle: str | None = None,
        mass: float | None = None, plots: bool | Callable = True,
        data: Mapping[str, np.ndarray] | None = None) -> tuple[dict[str, Any], list[Path]]:
    """Replay ``csv_file`` (a path or ``mbds``) through the FMU at ``fmu_path``; write
    ``out_dir/metrics.json`` and (with ``plots``) the PNGs (a callable ``plots(run, metrics,
    out_dir, mass)`` draws them instead, e.g. :func:`write_plots` in another process). ``split``: a time (s), None for none,
    or ``"auto"`` (:func:`default_split`). ``data``: the already loaded columns of ``csv_file``.
    Returns (metrics, [metrics.json, PNGs...])."""
    path = resolve_csv(csv_file)
    cols = load_csv(path) if data is None else data
    if isinstance(split, str):
        if split != "auto":
            raise ReplayError(f"split must be a time in s, None or 'auto', got {split!r}")
        split = default_split(path)
    split = None if split is None else float(split)
    if split is not None and not np.isfinite(split):
        raise ReplayError(f"split time must be finite, got {split}")
    rr = drive(fmu_path, cols, label=Path(fmu_path).stem, source=path)
    warned = unit_warnings(cols, path, rr.design)
    try:   # the mass the FMU was designed with, when its design file carries it
        mass = _baselines.parameter_values(_metrics.design_vehicle(rr.design), ["m"])["m"]
    except _baselines.BaselineUnavailable:
        pass
    info = {"csv": str(path), "csv_sha256": sha256_file(path) if path.is_file() else None,
            "observer": observer or rr.label}
    m = score(rr, split=split, mass=mass, vehicle=vehicle, info=info)
    if warned:
        m["warnings"] = warned
    out_dir = Path(out_dir)
    paths = [_metrics.write(m, out_dir)]
    if callable(plots):                  # drawn elsewhere (the demo's worker processes)
        plots(rr, m, out_dir, mass)
    elif plots:
        paths += write_plots(rr, m, out_dir, mass=mass)
    return m, paths
