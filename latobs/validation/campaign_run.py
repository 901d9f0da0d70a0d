"""One run of a Monte Carlo campaign on built FMU files (a worker's task) and its metrics, and
the check of a campaign definition against the variables its FMUs declare, before any run.
"""
from __future__ import annotations

import hashlib
import math
import os
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from .scenarios import Scenario

from .campaign import (DEFAULT_DT, Campaign, CampaignError, FmuRef, PerturbedScenario, draw, noise_of, scenario_cases,
                       scenario_of, sha256_file)
from .campaign_stats import headline_columns


# --------------------------------------------------------------------------------------------
# supports against the declared ranges: checked before any run
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Declared:
    """A variable of an FMU's modelDescription: causality and declared range (None: unbounded)."""

    causality: str
    min: float | None
    max: float | None


def declared_variables(path: str | os.PathLike) -> dict[str, Declared]:
    """{name: Declared} of every Real/Integer variable of the FMU at ``path``; its min/max from the
    variable or, when it has none, from its declared type."""
    from fmpy import read_model_description

    from .instance import fmi_type

    def num(x):
        return None if x in (None, "") else float(x)

    out = {}
    for v in read_model_description(str(path)).modelVariables:
        if fmi_type(v) not in ("Real", "Integer"):
            continue
        t = v.declaredType
        lo = v.min if v.min not in (None, "") else getattr(t, "min", None)
        hi = v.max if v.max not in (None, "") else getattr(t, "max", None)
        out[v.name] = Declared(v.causality, num(lo), num(hi))
    return out


def _inside(where: str, what: str, lo: float, hi: float, var: str, decl: Declared, fmu: str) -> None:
    """CampaignError unless [lo, hi] lies within the range ``fmu`` declares for ``var``."""
    rng = f"{'-inf' if decl.min is None else f'{decl.min:g}'} .. {'inf' if decl.max is None else f'{decl.max:g}'}"
    if decl.min is not None and not lo >= decl.min:
        raise CampaignError(f"{where}: {what} reaches {lo:g}, below the minimum {decl.min:g} that {fmu} declares "
                            f"for {var} (range {rng})")
    if decl.max is not None and not hi <= decl.max:
        raise CampaignError(f"{where}: {what} reaches {hi:g}, above the maximum {decl.max:g} that {fmu} declares "
                            f"for {var} (range {rng})")


def check_supports(c: Campaign, fmus: list[FmuRef]) -> None:
    """Before any run of a cosim campaign: every [plant] parameter is one the plant FMU (``fmus[0]``,
    with a local path) has, and its support lies within the range the FMU declares for it; every
    plant input the scenario drives, transformed by [signals], stays within its declared range,
    over the ends of every drawn scenario field and transform (:func:`scenario_cases`; the
    transforms are affine per sample, so the ends bound every draw; a scenario with a seed field
    is checked at its nominal seed). CampaignError naming the file, table and key otherwise."""
    if c.kind != "cosim" or not fmus or fmus[0].path is None:
        return
    import itertools

    where, plant = f"campaign {c.source or c.name}", fmus[0]
    decl = declared_variables(plant.path)
    params = sorted(n for n, d in decl.items() if d.causality == "parameter")
    for k, d in sorted(c.plant.items()):
        if k not in params:
            raise CampaignError(f"{where}: [plant] {k}: {plant.filename} has no such parameter; its parameters: "
                                f"{', '.join(params) or '(none)'}")
        _inside(where, f"[plant] {k} = {d.describe()}", *d.support(), k, decl[k], plant.filename)
    ins = {n: d for n, d in decl.items() if d.causality == "input" and (d.min is not None or d.max is not None)}
    if not ins:
        return
    dt = c.dt or DEFAULT_DT
    drawn = {k: d.extremes() for k, d in sorted(c.signals.items())}
    corners = [dict(zip(drawn, xs)) for xs in itertools.product(*drawn.values())] or [{}]
    for label, base in scenario_cases(where, c.scenario, c.scenario_fields, dt):
        t = base.time_grid(dt)
        for tr in corners:
            sig = PerturbedScenario.of(base, **tr).sampled(t, c.plant_vehicle or "sedan")
            for n in sorted(set(sig) & set(ins)):
                what = (f"input {n} of scenario {c.scenario!r}"
                        + (f" with {label}" if label else "")
                        + (" and [signals] " + ", ".join(f"{k} = {x:g}" for k, x in tr.items()) if tr else ""))
                _inside(where, what, float(np.min(sig[n])), float(np.max(sig[n])), n, ins[n], plant.filename)


# --------------------------------------------------------------------------------------------
# metrics of one run
# --------------------------------------------------------------------------------------------
def observer_metrics(label: str, outputs: Mapping[str, np.ndarray], truth: Mapping[str, np.ndarray],
                     after: np.ndarray, model_name: str | None) -> dict[str, float]:
    """Flat metrics of one observer in one run, on the samples ``after`` (t >= settle time):
    ``LABEL.X.rms`` and ``LABEL.X.max_abs`` of every estimate ``X_hat`` that has a truth (and
    ``LABEL.X_filtered.rms``, ``.max_abs`` of a filtered estimate ``X_filtered``, scored one step
    behind: its row k + 1 against the truth at row k, :func:`latobs.validation.metrics.one_step_behind`),
    and for every interval ``X_lower``/``X_upper``: ``LABEL.X.violations`` (samples outside, or a bound
    not finite), ``LABEL.X.max_violation`` and ``LABEL.X.mean_width``; ``LABEL.nonfinite``: samples
    of any scored output that are not finite. SI units of the signals. The truth is chosen as in
    :mod:`latobs.validation.metrics` (its REFERENCE_SIGNALS map)."""
    from . import metrics

    row: dict[str, float] = {}
    nonfinite = 0
    for name, y in outputs.items():
        if name.endswith("_hat") or name.endswith(metrics.FILTERED):
            filtered = name.endswith(metrics.FILTERED)
            key = name if filtered else name[:-4]          # X, or X_filtered under its own name
            src = metrics.truth_signal(metrics.quantity_of(name), truth, model_name)
            if src is None:
                continue
            yy, xx, sel = (metrics.one_step_behind(y, truth[src], after) if filtered else
                           (np.asarray(y, dtype=float), np.asarray(truth[src], dtype=float), after))
            e = (yy - xx)[sel]
            nonfinite += int(np.sum(~np.isfinite(e)))
            row[f"{label}.{key}.rms"] = float(np.sqrt(np.mean(e * e))) if e.size else math.nan
            row[f"{label}.{key}.max_abs"] = float(np.max(np.abs(e))) if e.size else math.nan
        elif name.endswith("_lower") and name[:-6] + "_upper" in outputs:
            q = name[:-6]
            src = metrics.truth_signal(q, truth, model_name)
            if src is None:
                continue
            s = metrics.enclosure_stats(np.asarray(y)[after], np.asarray(outputs[q + "_upper"])[after],
                                        np.asarray(truth[src])[after])
            nonfinite += s["nonfinite_samples"]
            row[f"{label}.{q}.violations"] = float(s["enclosure_violations"])
            row[f"{label}.{q}.max_violation"] = float(s["max_violation"] or 0.0)
            row[f"{label}.{q}.mean_width"] = math.nan if s["mean_width"] is None else float(s["mean_width"])
    row[f"{label}.nonfinite"] = float(nonfinite)
    return row


#: integer outputs by which an observer declares a sample valid (nonzero): paper 000's ``valid``
#: (inside its linear domain and speed grid), paper 001's ``consistent`` (the measurement inside the bounds)
VALIDITY_FLAGS = ("valid", "consistent")


def baseline_metrics(label: str, outputs: Mapping[str, np.ndarray], truth: Mapping[str, np.ndarray],
                     drive: Mapping[str, np.ndarray], time: np.ndarray, after: np.ndarray,
                     model_name: str | None, design: Mapping[str, Any] | None, inputs=(),
                     initial: str = "rest") -> dict[str, float]:
    """The observer ``label`` against the baselines of ``validate`` on the same run and samples.

    For every quantity X the observer estimates (``X_hat``, ``X_filtered`` under its own name, scored
    one step behind with the baselines on the same samples, or an interval by its midpoint) that it
    does not read as an input and that has a truth: the baselines of
    :func:`latobs.validation.metrics.baselines_for` (zero, the bicycle or the steady turn, from the
    design's vehicle, driven by ``drive``: the signals the observers received) are scored on the
    samples ``after`` (t >= settle time) beside the observer:
    ``LABEL.X.rms_B`` per baseline B, ``LABEL.X.midpoint_rms`` for an interval, ``LABEL.X.ratio``
    = observer RMS / best baseline RMS (< 1: the observer is better), ``LABEL.X.wins`` = 1 when
    every applicable baseline was computed and is worse than the observer, 0 when one is as good
    (:func:`latobs.validation.metrics.baseline_summary`). With a validity flag
    (:data:`VALIDITY_FLAGS`) the same on the samples after settling where the flag is nonzero:
    ``LABEL.X.valid_rms``, ``LABEL.X.valid_ratio``, ``LABEL.X.valid_wins``, and
    ``LABEL.valid_fraction`` (those samples' share). SI units."""
    from . import metrics

    ins = set(inputs)
    # key (X, or X_filtered) -> (estimate, truth signal, what, X, scored one step behind)
    targets: dict[str, tuple[np.ndarray, str, str, str, bool]] = {}
    for name, y in outputs.items():
        q = key = None
        if name.endswith("_hat"):
            q = key = name[:-4]
            est = np.asarray(y, dtype=float)
        elif name.endswith(metrics.FILTERED):
            q, key, est = metrics.quantity_of(name), name, np.asarray(y, dtype=float)
        elif name.endswith("_lower") and name[:-6] + "_upper" in outputs and name[:-6] + "_hat" not in outputs:
            q = key = name[:-6]
            est = 0.5 * (np.asarray(y, dtype=float) + np.asarray(outputs[q + "_upper"], dtype=float))
        if q is None or q in ins:
            continue
        src = metrics.truth_signal(q, truth, model_name)
        if src is not None:
            what = "midpoint" if name.endswith("_lower") else "estimate"
            targets[key] = (est, src, what, q, name.endswith(metrics.FILTERED))
    if not targets:
        return {}
    quantities = list(dict.fromkeys(t[3] for t in targets.values()))
    b = metrics.baselines_for(time, drive, quantities, dict(design) if design else None, model_name,
                              initial=initial)
    flag = next((f for f in VALIDITY_FLAGS if f in outputs), None)
    sels = {"": after}
    row: dict[str, float] = {}
    if flag is not None:
        sels["valid_"] = after & (np.asarray(outputs[flag]) != 0)
        row[f"{label}.valid_fraction"] = float(np.mean(sels["valid_"][after])) if np.any(after) else math.nan

    def rms(e):
        return float(np.sqrt(np.mean(e * e))) if e.size else None

    for key, (est, src, what, q, lag) in targets.items():
        x = np.asarray(truth[src], dtype=float)
        missing = {base: u[q] for base, u in b["unavailable"].items() if q in u}
        for pre, sel in sels.items():
            series = {base: np.asarray(ser[q], dtype=float) for base, ser in b["series"].items() if q in ser}
            if lag:            # row k + 1 estimates row k: the baselines on rows 0 .. n - 2, as the estimate
                e, xs, sel = metrics.one_step_behind(est, x, sel)
                series = {base: v[:-1] for base, v in series.items()}
            else:
                e, xs = est, x
            obs = rms((e - xs)[sel])
            base_rms = {base: rms((v - xs)[sel]) for base, v in series.items()}
            if not base_rms and not missing:
                continue
            metrics.baseline_row(row, label, key, pre, what, obs, base_rms, missing)
    return row


# --------------------------------------------------------------------------------------------
# one run, on FMU files (a worker's task)
# --------------------------------------------------------------------------------------------
_WORKER_CACHE: dict[str, tuple[str, str]] = {}   # sha256 -> (FMU path, extracted folder)
_CACHE_LOCK = threading.Lock()
_CACHE_DIR: list[str] = []                          # this process's folder, made on first use
_RUN_LOCK = threading.Lock()                        # one run at a time per process (see run_case)


def _local(ref: FmuRef, blob: bytes | None = None) -> tuple[str, str]:
    """(FMU path, extracted folder) of ``ref`` in this process, copied (or written) and extracted
    once per process into a temporary folder removed at exit, so that it stays valid whatever
    happens to the file it came from. ``blob``: the FMU's bytes when the caller received them
    separately (a scattered Dask object); checked against the sha256, as the copy is."""
    import atexit
    import shutil
    import tempfile

    from .instance import extract

    with _CACHE_LOCK:
        hit = _WORKER_CACHE.get(ref.sha256)
        if hit is not None:
            return hit
        if not _CACHE_DIR:
            _CACHE_DIR.append(tempfile.mkdtemp(prefix="latobs_campaign_"))
            atexit.register(shutil.rmtree, _CACHE_DIR[0], True)
        folder = Path(_CACHE_DIR[0]) / ref.sha256[:16]
        folder.mkdir(parents=True, exist_ok=True)
        if blob is not None:
            if hashlib.sha256(blob).hexdigest() != ref.sha256:
                raise CampaignError(f"FMU {ref.filename}: the bytes received do not match its sha256")
            path = folder / ref.filename
            path.write_bytes(blob)
        elif ref.path is not None:
            # a copy of its own: the cache entry outlives the folder it came from (a campaign run
            # before, in this process, on the same FMU bytes in a folder since deleted)
            path = folder / ref.filename
            shutil.copyfile(ref.path, path)
            if sha256_file(path) != ref.sha256:
                raise CampaignError(f"FMU {ref.filename}: {ref.path} changed since the campaign started")
        else:
            raise CampaignError(f"FMU {ref.filename}: neither its bytes nor its path were given")
        hit = (str(path), extract(str(path), unzipdir=str(folder / "unzipped")))
        _WORKER_CACHE[ref.sha256] = hit
        return hit


#: metrics of a replay run start this long (s) after the segment's start unless the definition
#: says otherwise: the observer starts from its initial state in the middle of a drive
REPLAY_SETTLE_S = 5.0


def settle_time(c: Campaign, scenario: Scenario | None = None) -> float:
    if c.settle_time is not None:
        return c.settle_time
    return float(scenario.settle_time) if scenario is not None else REPLAY_SETTLE_S


def cosim_setup(c: Campaign, params: Mapping[str, Any], seed: int) -> tuple[PerturbedScenario, dict[str, Any]]:
    """The run's scenario and the keyword arguments of :func:`latobs.validation.harness.run`
    (dt, noise with the run's seed, plant parameters, vehicle): what a campaign run and its
    ``--rerun`` both use."""
    from .harness import NoiseSpec

    sc = scenario_of(c, params)
    noise = noise_of(params)
    kwargs = {"dt": c.dt or DEFAULT_DT, "seed": int(seed), "vehicle": c.plant_vehicle or "sedan",
              "noise": NoiseSpec(signals=noise, seed=int(seed)) if noise else None,
              "plant_parameters": {k.split(".", 1)[1]: float(v) for k, v in params.items() if k.startswith("plant.")}}
    return sc, kwargs


def replay_segment(c: Campaign, params: Mapping[str, Any], record: Mapping[str, np.ndarray],
                   seed: int) -> dict[str, np.ndarray]:
    """The run's slice of the record ([t_start, t_start + segment_s) from the record's start),
    with the run's sensor noise and bias added to the noisy columns (NoiseSpec with the run's seed)."""
    from .harness import NoiseSpec

    t = np.asarray(record["t"], dtype=float)
    t0 = float(params["segment.t_start_s"])
    sel = (t >= t0 - 1e-9) & (t < t0 + float(c.replay["segment_s"]) - 1e-9)
    data = {k: np.asarray(v, dtype=float)[sel] for k, v in record.items()}
    noise = noise_of(params)
    if noise:
        missing = sorted(set(noise) - set(data))
        if missing:
            raise CampaignError(f"[noise] {', '.join(missing)}: no such column in the record")
        for s, e in NoiseSpec(signals=noise, seed=int(seed)).draw(int(sel.sum())).items():
            data[s] = data[s] + e
    return data


def run_case(c: Campaign, k: int, seed: int, fmus: list[FmuRef], blobs: list[bytes | None] | None = None,
             record: Mapping[str, np.ndarray] | None = None, split: float | None = None) -> dict[str, Any]:
    """Run ``k`` (seed ``seed``) of campaign ``c`` on the FMUs ``fmus`` (the plant first for a
    cosim campaign; ``blobs[i]``: the bytes of ``fmus[i]`` when shipped separately) and, for a
    replay campaign, the ``record`` ({column: array}, ``t`` in s) and its ``split`` time. Returns
    the journal row: run, seed, status ("ok", or "failed" with the error: an FMU or model failure
    is a result of the campaign, not a crash of it), seconds, worker, params, metrics. One run at
    a time per process: the FMU instances of a run are not shared with a concurrent one."""
    import socket

    t_start = time.perf_counter()
    row: dict[str, Any] = {"run": int(k), "seed": int(seed), "status": "ok", "error": None,
                           "worker": f"{socket.gethostname()}:{os.getpid()}", "params": {}, "metrics": {},
                           "headline": []}
    with _RUN_LOCK:
        try:
            blobs = blobs or [None] * len(fmus)
            local = {ref.role: _local(ref, b) for ref, b in zip(fmus, blobs)}
            if c.kind == "cosim":
                row["params"] = params = draw(c, seed)
                row["metrics"], inputs = _cosim_metrics(c, params, seed, fmus, local)
            else:
                t = np.asarray(record["t"], dtype=float)
                row["params"] = params = draw(c, seed, record_span=(float(t[0]), float(t[-1])), split=split)
                row["metrics"], inputs = _replay_metrics(c, params, seed, fmus, local, record)
            row["headline"] = headline_columns(row["metrics"], inputs)
        except Exception as exc:    # noqa: BLE001 - recorded in the journal, named in the report
            row["status"] = "failed"
            row["error"] = f"{type(exc).__name__}: {exc}"[:2000]
    row["seconds"] = time.perf_counter() - t_start
    row["metrics"] = {k: (None if isinstance(v, float) and not math.isfinite(v) else v)
                      for k, v in row["metrics"].items()}
    return row


def run_cases(c: Campaign, ks: list[int], seeds: list[int], fmus: list[FmuRef],
              blobs: list[bytes | None] | None = None, record: Mapping[str, np.ndarray] | None = None,
              split: float | None = None) -> list[dict[str, Any]]:
    """:func:`run_case` for each run index of ``ks`` with its seed of ``seeds`` (one Dask task)."""
    return [run_case(c, k, s, fmus, blobs, record, split) for k, s in zip(ks, seeds)]


def _cosim_metrics(c, params, seed, fmus, local) -> tuple[dict[str, float], dict[str, list[str]]]:
    from . import harness, stream

    sc, kwargs = cosim_setup(c, params, seed)
    plant = local[fmus[0].role]
    observers = {ref.role: local[ref.role] for ref in fmus[1:]}
    # a long run is stepped in blocks, its flat metrics summed over them (stream.CosimSink)
    with stream.CosimSink(None, keep=False, settle_time=settle_time(c, sc)) as sink:
        res = harness.run(sc, plant[0], {lab: p for lab, (p, _) in observers.items()},
                          unzipped={p: d for p, d in [plant, *observers.values()]}, sink=sink, **kwargs)
    return (sink.flat(res) if sink.used else result_metrics(res, settle_time(c, sc))), res.inputs


def result_metrics(res, settle: float) -> dict[str, float]:
    """Flat metrics (:func:`observer_metrics`) of every observer of a co-simulation result."""
    after = np.asarray(res.time) >= settle - 1e-12
    models = res.info.get("observer_models", {})
    out: dict[str, float] = {}
    designs = res.info.get("observer_designs", {})
    drive = {**res.bus, **(res.measured or {})}       # what the observers received, else the truth
    for label, outs in res.observers.items():
        out.update(observer_metrics(label, outs, res.bus, after, models.get(label)))
        out.update(baseline_metrics(label, outs, res.bus, drive, np.asarray(res.time, dtype=float), after,
                                    models.get(label), designs.get(label), res.inputs.get(label, ())))
    return out


def _replay_metrics(c, params, seed, fmus, local, record) -> tuple[dict[str, float], dict[str, list[str]]]:
    from . import replay as rp

    data = replay_segment(c, params, record, seed)
    out: dict[str, float] = {}
    inputs: dict[str, list[str]] = {}
    for ref in fmus:
        path, unzipped = local[ref.role]
        run = rp.drive(path, data, label=ref.role, unzipdir=unzipped)
        out.update(replay_metrics(run, c))
        inputs[ref.role] = list(run.inputs)
    return out, inputs


def replay_metrics(run, c: Campaign) -> dict[str, float]:
    """Flat metrics of a replay run (:class:`latobs.validation.replay.ReplayRun`) after the settle time."""
    after = run.time >= run.time[0] + settle_time(c) - 1e-9
    out = observer_metrics(run.label, run.outputs, run.columns, after, run.model_name)
    # the bicycle starts from the steady state of the segment's first sample, as replay's does
    out.update(baseline_metrics(run.label, run.outputs, run.columns, run.columns, run.time, after, run.model_name,
                                run.design, run.inputs, initial="steady"))
    return out
