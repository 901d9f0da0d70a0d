"""``latobs bench``: what latobs costs, measured side by side in one run.

Not a test: nothing here asserts a time. Every figure is printed beside a reference measured in
the same process, so that ratios (not absolute microseconds, which depend on the machine and
vary by tens of percent between runs) are what gets compared. Sections (each can be skipped):

* **build** (``--skip-build``): wall time of a whole ``latobs build`` (every observer at its
  default vehicle and every plant) per backend, in a fresh process (``python -m latobs build
  --out TMP --backend B``: nothing cached), and the LMI solver time inside it (from the design
  files). Missing FMUs of ``--fmu-dir`` are then copied from that build.
* **LMI** (``--skip-lmi``): every design of :data:`latobs.synthesis.designs.DESIGNS` at its
  default vehicle solved with Clarabel and with SCS (:func:`latobs.synthesis.lmi.using`; SCS at
  eps 1e-9, ``--scs-max-iters``), each result through the pipeline's independent certificate
  (:func:`latobs.synthesis.certificate.certify`, as ``designs.run``): wall time of the design
  function, of its LMI solves (every ``lmi.solve`` call, counted) and of the certificate, the
  result (certified / certificate failed / no solution / error / stopped, with the reason) and
  gamma. Each design x solver runs in a fresh process, stopped after ``--lmi-timeout`` s
  (:data:`LMI_TIMEOUT`).
* **FMUs** (``--skip-fmus``): µs per communication step of every FMU ``latobs build`` builds,
  plus the plant and observer FMUs for other vehicles that the pairings need (``CarPlant_delibasi``,
  ``SideslipKalmanFilter_delibasi``), per backend (``python``: pythonfmu, ``c``: native C), with
  the FMUs of ``--fmu-dir``/<backend> (built there if missing), driven by the signal bus of its
  pairing (:func:`pairings`, the demo's runs): through fmpy's ``FMU2Slave`` (set inputs, doStep,
  get outputs, as the validation harness's plain loop); in a plain C host
  (``latobs/native/fmu_runner.c``, no Python in the loop; a pythonfmu FMU gets libpython
  preloaded); and the reference: for a pythonfmu FMU its runtime class of ``fmu_src/`` stepped
  directly in Python (the same arithmetic outside FMI), for a native FMU the C host's doStep.
* **coupled** (``--skip-coupled``): each pairing's co-simulation by the validation harness
  (``latobs.validation.harness.run``, fast master), wall time, µs per step and real-time factor.
* **scaling** (``--skip-scaling``): cost of one coupled run against scenario length
  (:data:`LENGTHS` s of ``bank-braking``, paper 000's observers) and against the number of
  observers (0..4 of paper 000's beside CarPlant, 10 s), native C FMUs, with the FMUs extracted
  for every run (``harness.run`` alone) and extracted once (``unzipped=``, as a campaign worker
  does), and the straight line fitted through each.
"""
from __future__ import annotations

import argparse
import contextlib
import io
import json
import math
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from . import catalogue
from .synthesis import designs  # the catalogue only (no solver stack)

BACKENDS = ("python", "c")
BACKEND_LABEL = {"python": "pythonfmu", "c": "native C"}
SOLVERS = ("CLARABEL", "SCS")
SOLVER_LABEL = {"CLARABEL": "Clarabel", "SCS": "SCS"}
DT = 0.005                                    # s, communication step of every measurement
LENGTHS = (2.5, 5.0, 10.0, 20.0, 40.0)        # s of bank-braking, the scaling with length
SCALING_SCENARIO = "bank-braking"
SCALING_OBSERVERS_DURATION = 10.0             # s, the scaling with the number of observers


@dataclass(frozen=True)
class Pairing:
    """A plant FMU, the observer FMUs beside it and the scenario that drives them.

    key        short name ("000" .. "003": the demo's runs of that paper, "mbds": see note)
    scenario   registered scenario name
    plant      plant model (``packaging.PLANTS`` key); vehicle: the plant FMU's vehicle set (also
               the vehicle the scenario is sampled for)
    observers  observer FMU names (NAME, or NAME_V for a design built for vehicle V)
    """

    key: str
    scenario: str
    plant: str
    vehicle: str
    observers: tuple[str, ...]
    note: str = ""

    @property
    def plant_fmu(self) -> str:
        """The plant FMU's name: PLANT for its default vehicle, PLANT_V otherwise."""
        return plant_artefact(self.plant, self.vehicle)


def plant_artefact(plant: str, vehicle: str) -> str:
    from .packaging import PLANTS

    return plant if vehicle == PLANTS[plant].default_vehicle else f"{plant}_{vehicle}"


def paper_000_observers() -> tuple[str, ...]:
    """``latobs validate``'s default observers beside CarPlant (the demo's ``PAPER_000``)."""
    return tuple(catalogue.default_observers("CarPlant"))


def pairings() -> list[Pairing]:
    """The co-simulations benchmarked: the first run of each paper in ``latobs.demo.RUNS`` with
    nominal plant parameters (tests/test_bench.py checks they are there), and the replay-only
    observers on a CarPlant bus."""
    return [
        Pairing("000", "bank-braking", "CarPlant", "sedan", paper_000_observers(),
                "demo run bank-braking: paper 000's observers"),
        Pairing("001", "double-lane-change-15", "CarPlant", "sedan", ("LateralIntervalObserver",),
                "demo run double-lane-change-15 [001]"),
        Pairing("002", "w1-steer", "CarPlant", "delibasi",
                ("SideslipFixedOrderEstimator", "SideslipKalmanFilter_delibasi"),
                "demo run w1-steer [002], CarPlant for paper 002's vehicle"),
        Pairing("003", "motorcycle-lane-change", "MotorcyclePlant", "sharp_motorcycle", ("MotorcycleFaultObserver",),
                "demo run motorcycle-lane-change [003]"),
        Pairing("mbds", "double-lane-change", "CarPlant", "sedan",
                tuple(n for n in catalogue.OBSERVERS if catalogue.get(n).default_vehicle == "mbds_250lm"),
                "not a demo run: the observers designed for the MBDS record's vehicle (mbds_250lm), which the demo "
                "only replays, on a CarPlant sedan bus at 22 m/s (inside their speed range); their inputs "
                "(delta, vx, yaw_rate, ay) are all on it"),
    ]


def fmu_names() -> list[str]:
    """Every FMU ``latobs build`` builds (observers at their default vehicle, plants), then the
    other FMUs the pairings need."""
    from .packaging import PLANTS

    names = [*designs.DESIGNS, *PLANTS]
    for p in pairings():
        names += [x for x in (p.plant_fmu, *p.observers) if x not in names]
    return names


def _parse_fmu(name: str) -> tuple[str, str | None, bool]:
    """(model, vehicle or None for the default, is_plant) of an FMU name."""
    from .packaging import PLANTS

    for plant in sorted(PLANTS, key=len, reverse=True):
        if name == plant:
            return plant, None, True
        if name.startswith(plant + "_"):
            return plant, name[len(plant) + 1:], True
    design, vehicle = designs.parse_artefact(name)
    return design, vehicle, False


def _kind(name: str):
    from .packaging import OBSERVERS, PLANTS

    model, _, is_plant = _parse_fmu(name)
    return PLANTS[model] if is_plant else OBSERVERS[model]


def _fmu_pairing(name: str) -> Pairing:
    """The pairing whose bus drives FMU ``name`` (the first that holds it)."""
    for p in pairings():
        if name == p.plant_fmu or name in p.observers:
            return p
    raise KeyError(f"no pairing holds FMU {name!r}")


def _progress(msg: str) -> None:
    print(f"bench: {msg}", file=sys.stderr, flush=True)


def _reason(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return f"{type(exc).__name__}: {text[:400]}"


# ------------------------------------------------------------------------------------------------
# (d) a whole `latobs build`, per backend, in a fresh process
# ------------------------------------------------------------------------------------------------
def build_time(backend: str, fill: Path | None = None) -> dict:
    """Wall time of ``python -m latobs build --out TMP --backend BACKEND`` (a new process, so
    nothing is cached): {"seconds", "returncode", "fmus", "lmi_solver_seconds" (sum of the design
    files' ``solver.seconds`` of the LMI designs), "error" (None or the last lines of stderr)}.
    ``fill``: a folder that then receives the built FMUs and design files it lacks."""
    tmp = Path(tempfile.mkdtemp(prefix=f"latobs-bench-build-{backend}-"))
    try:
        cmd = [sys.executable, "-P", "-m", "latobs", "build", "--out", str(tmp), "--backend", backend]
        t0 = time.perf_counter()
        proc = subprocess.run(cmd, capture_output=True, text=True)
        seconds = time.perf_counter() - t0
        fmus = sorted(tmp.glob("*.fmu"))
        lmi_seconds = 0.0
        for f in tmp.glob("*.design.json"):
            s = json.loads(f.read_text()).get("solver") or {}
            if s.get("name") in SOLVERS and isinstance(s.get("seconds"), (int, float)):
                lmi_seconds += float(s["seconds"])
        if fill is not None and proc.returncode == 0:
            fill.mkdir(parents=True, exist_ok=True)
            for f in [*fmus, *tmp.glob("*.design.json")]:
                if not (fill / f.name).exists():
                    shutil.copy2(f, fill / f.name)
        err = None if proc.returncode == 0 else " | ".join(proc.stderr.strip().splitlines()[-3:])
        return {"backend": backend, "seconds": seconds, "returncode": proc.returncode, "fmus": len(fmus),
                "lmi_solver_seconds": lmi_seconds, "command": " ".join(cmd[2:]).replace(str(tmp), "TMP"),
                "error": err}
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


# ------------------------------------------------------------------------------------------------
# (a) LMI solve time per design and solver, each result certified
# ------------------------------------------------------------------------------------------------
def lmi_row(name: str, solver: str, scs_max_iters: int | None = None) -> dict:
    """Design ``name`` (default vehicle) with ``solver`` and certify it as the pipeline does
    (``designs.run``: ``entry.solve`` then ``certificate.certify``), timing each part. Never raises:
    a failure is ``result`` ("no solution", "certificate failed", "error") with ``reason``."""
    from .synthesis import certificate, lmi
    from .synthesis.params import load_vehicle

    entry = designs.get(name)
    row: dict = {"design": name, "paper": entry.paper, "vehicle": entry.default_vehicle, "solver": solver,
                 "result": None, "reason": None, "gamma": None, "design_seconds": None, "lmi_seconds": 0.0,
                 "lmi_solves": 0, "lmi_statuses": [], "certificate_seconds": None, "recorded_solver": None,
                 "checks_passed": None, "checks_total": None}
    settings = {"max_iters": scs_max_iters} if solver == "SCS" and scs_max_iters else {}
    with lmi.using(solver, **settings) as usage:
        row["settings"] = dict(usage.settings)
        t0 = time.perf_counter()
        try:
            veh = load_vehicle(entry.default_vehicle)
            data = entry.solve(veh, entry.options(designs.artefact_name(name, veh.name)))
        except Exception as exc:           # a row, not a crash
            data = None
            row["result"] = "no solution" if type(exc).__name__ in ("DesignError", "ConditionError") else "error"
            row["reason"] = _reason(exc)
        row["design_seconds"] = time.perf_counter() - t0
    row["lmi_seconds"] = usage.seconds
    row["lmi_solves"] = len(usage.calls)
    row["lmi_statuses"] = sorted({s for s, _ in usage.calls})
    row["uses_lmi"] = bool(usage.calls)
    if data is None:
        return row
    rec = data.get("solver") or {}
    row["recorded_solver"] = rec.get("name")
    row["recorded_solver_seconds"] = rec.get("seconds")
    row["recorded_status"] = rec.get("status")
    row["gamma"] = data.get("gamma")
    data["design"] = name
    t1 = time.perf_counter()
    try:
        ok, checks = certificate.certify(data)
    except Exception as exc:
        row["certificate_seconds"] = time.perf_counter() - t1
        row["result"], row["reason"] = "error", "certificate raised " + _reason(exc)
        return row
    row["certificate_seconds"] = time.perf_counter() - t1
    row["checks_passed"] = sum(bool(c.passed) for c in checks)
    row["checks_total"] = len(checks)
    row["certified"] = bool(ok)
    if ok:
        row["result"] = "certified"
    else:
        failed = [c for c in checks if not c.passed]
        row["result"] = "certificate failed"
        row["reason"] = "; ".join(f"{c.name}: {c.value:.6g} > {c.limit:.6g}" for c in failed[:3]) + (
            f" (+{len(failed) - 3} more)" if len(failed) > 3 else "")
    if row["uses_lmi"] and row["recorded_solver"] != solver:
        row["result"] = "error"
        row["reason"] = f"the design dict records solver {row['recorded_solver']!r}, not {solver!r}"
    return row


#: s, wall-time cap of one design in the LMI section (a fresh process, killed at the cap): SCS at
#: eps 1e-9 takes about 70 s per Lemma 5 solve of paper 002, whose designs make 4 to ~100 solves
LMI_TIMEOUT = 180.0


def lmi_row_isolated(name: str, solver: str, scs_max_iters: int | None = None,
                     timeout: float | None = LMI_TIMEOUT) -> dict:
    """:func:`lmi_row` in a fresh Python process (nothing cached from another design or solver),
    stopped after ``timeout`` s: then a row with result "stopped" and the cap as the reason."""
    entry = designs.get(name)
    # the solver stack and the design modules imported first: the design time is not an import time
    code = ("import json, cvxpy, scipy.linalg; from latobs.bench import lmi_row, _jsonable; "
            "from latobs.synthesis import certificate, fixed_order_002, interval_001, kalman_baseline, "
            "pi_hinf_000, pi_switched_003; "
            f"print('LMI-ROW ' + json.dumps(_jsonable(lmi_row({name!r}, {solver!r}, {scs_max_iters!r}))))")
    base = {"design": name, "paper": entry.paper, "vehicle": entry.default_vehicle, "solver": solver,
            "gamma": None, "design_seconds": None, "lmi_seconds": 0.0, "lmi_solves": 0, "lmi_statuses": [],
            "certificate_seconds": None, "recorded_solver": None, "checks_passed": None, "checks_total": None}
    t0 = time.perf_counter()
    try:
        proc = subprocess.run([sys.executable, "-P", "-c", code], capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return {**base, "result": "stopped", "design_seconds": time.perf_counter() - t0, "timed_out": True,
                "reason": f"not finished within the {timeout:g} s cap (process stopped)"}
    line = next((x for x in reversed(proc.stdout.splitlines()) if x.startswith("LMI-ROW ")), None)
    if proc.returncode != 0 or line is None:
        tail = " | ".join(proc.stderr.strip().splitlines()[-2:])
        return {**base, "result": "error", "reason": f"design process exit {proc.returncode}: {tail[:400]}"}
    row = json.loads(line[len("LMI-ROW "):])
    row["process_seconds"] = time.perf_counter() - t0
    return row


def lmi_section(names: list[str], solvers=SOLVERS, scs_max_iters: int | None = None,
                timeout: float | None = LMI_TIMEOUT) -> list[dict]:
    """Every design x solver (:func:`lmi_row_isolated`)."""
    rows = []
    for name in names:
        for solver in solvers:
            _progress(f"LMI design {name} with {SOLVER_LABEL.get(solver, solver)}")
            rows.append(lmi_row_isolated(name, solver, scs_max_iters, timeout))
    return rows


# ------------------------------------------------------------------------------------------------
# FMUs: building the missing ones, their data, the bus of their pairing
# ------------------------------------------------------------------------------------------------
def ensure_fmus(folder: Path, backend: str, names: list[str]) -> dict[str, str]:
    """Build the FMUs of ``names`` missing in ``folder`` with ``backend`` (Clarabel designs);
    returns {name: reason} of those that could not be built (the build's output is kept quiet)."""
    from .pipeline import build, current

    failed = {}
    for name in names:
        model, vehicle, _ = _parse_fmu(name)
        try:
            if (folder / f"{name}.fmu").is_file() and current(model, vehicle, folder, backend):
                continue                                    # built from identical inputs: reused
        except Exception as exc:
            failed[name] = _reason(exc)
            continue
        _progress(f"building {name} ({BACKEND_LABEL[backend]}) in {folder}")
        log = io.StringIO()
        try:
            with contextlib.redirect_stdout(log):
                build([model], vehicle, folder, backend)
        except Exception as exc:
            failed[name] = _reason(exc)
    return failed


def fmu_data(path: Path) -> dict:
    """The data file an FMU carries (``resources/NAME.design.json`` or ``NAME.plant.json``)."""
    import zipfile

    with zipfile.ZipFile(path) as z:
        for member in (f"resources/{path.stem}.design.json", f"resources/{path.stem}.plant.json"):
            if member in z.namelist():
                return json.loads(z.read(member))
    raise ValueError(f"{path} carries no resources/{path.stem}.design.json or .plant.json")


def bus(pairing: Pairing, folder: Path) -> dict[str, np.ndarray]:
    """The truth bus of the pairing's scenario: its signals and the plant FMU's outputs (one
    co-simulation of the plant alone)."""
    from .validation.harness import run

    return run(pairing.scenario, folder / f"{pairing.plant_fmu}.fmu", {}, dt=DT, vehicle=pairing.vehicle).bus


def _fmu_step_time(path: Path, inputs: dict[str, np.ndarray], n: int, repeats: int) -> tuple[float, float]:
    """µs per (set inputs + doStep + get outputs) over ``n`` steps: (first instance in the process,
    best of ``repeats`` fresh instances). They differ when a runtime builds and caches per-process
    data on its first steps (the paper-000 observers' step maps)."""
    from .validation.harness import FmuInstance

    times = []
    for _ in range(repeats):
        fmu = FmuInstance(path.stem, path)
        names = [v.name for v in fmu.inputs if v.name in inputs]   # optional inputs (CarPlant's
        # stiffness_scale_f/r) stay at their start values, as in the harness
        rows = [{k: float(inputs[k][i]) for k in names} for i in range(n)]
        fmu.start(rows[0])
        do_step = fmu.slave.doStep
        set_inputs, get_outputs = fmu.set_inputs, fmu.get_outputs
        t0 = time.perf_counter()
        for i in range(n):
            set_inputs(rows[i])
            do_step(i * DT, DT)
            get_outputs()
        times.append((time.perf_counter() - t0) / n * 1e6)
        fmu.close()
    return times[0], min(times)


def runtime_step_time(name: str, data: dict, inputs: dict[str, np.ndarray], n: int,
                      repeats: int) -> tuple[float, float]:
    """µs per ``step`` of FMU ``name``'s runtime class (``fmu_src``), stepped directly in Python
    with the FMU's own data file and parameter start values, outside FMI (the pythonfmu FMU's
    arithmetic without the FMI layer): (first instance, best of ``repeats`` fresh instances).
    Inputs missing from ``inputs`` keep their start values, as in the FMU."""
    from importlib import import_module

    from .fmu_src.framework import start_values

    spec = import_module(f"{__package__}.fmu_src.models.{_kind(name).model_module}").SPEC
    base = {v.name: float(v.start) for v in spec.inputs}
    given = [v.name for v in spec.inputs if v.name in inputs]
    rows = [{**base, **{k: float(inputs[k][i]) for k in given}} for i in range(n)]
    times = []
    for _ in range(repeats):
        rt = spec.runtime(data, start_values(spec, data))
        if hasattr(rt, "initialize"):
            rt.initialize(dict(rows[0]))
        step = rt.step
        t0 = time.perf_counter()
        for u in rows:
            step(DT, u)
        times.append((time.perf_counter() - t0) / n * 1e6)
    return times[0], min(times)


def _c_host_time(path: Path, inputs: dict[str, np.ndarray], n: int, repeats: int) -> dict:
    """µs per fmi2DoStep alone and per set + doStep + get in the plain C host ({"c_host_error"}:
    no C host here: no compiler, or a pythonfmu FMU and no shared libpython)."""
    from .cbackend import host

    try:
        r = host.bench(path, {k: v[:n] for k, v in inputs.items()}, DT, repeats=max(repeats, 5))
    except Exception as exc:
        return {"c_host_error": _reason(exc)}
    return {"c_host_us_per_doStep": r["ns_per_doStep"] / 1e3, "c_host_us_per_step": r["ns_per_step_with_io"] / 1e3,
            "c_host_median_us_per_doStep": r["median_ns_per_doStep"] / 1e3,
            "c_host_median_us_per_step": r["median_ns_per_step_with_io"] / 1e3}


def fmu_section(folders: dict[str, Path], names: list[str], n: int, repeats: int,
                unavailable: dict[str, dict[str, str]]) -> dict:
    """Per FMU: {"pairing", "scenario", "kind", "n_steps", "python_runtime_us_per_step"[_first],
    "backends": {backend: {"fmpy_us_per_step"[_first], "c_host_...", "reference_us_per_step",
    "reference", "fmpy_over_reference"} or {"error"}}}."""
    out: dict = {}
    buses: dict[str, dict] = {}
    for name in names:
        p = _fmu_pairing(name)
        _, _, is_plant = _parse_fmu(name)
        entry: dict = {"pairing": p.key, "scenario": p.scenario, "kind": "plant" if is_plant else "observer",
                       "backends": {}}
        out[name] = entry
        if p.key not in buses:
            src = next((f for b, f in folders.items() if (f / f"{p.plant_fmu}.fmu").is_file()), None)
            try:
                if src is None:
                    raise FileNotFoundError(f"no {p.plant_fmu}.fmu in any backend's folder")
                buses[p.key] = bus(p, src)
            except Exception as exc:
                buses[p.key] = {"error": _reason(exc)}
        b = buses[p.key]
        if "error" in b:
            entry["error"] = f"bus of {p.scenario}: {b['error']}"
            continue
        steps = min(n, len(b["vx"]) - 1)
        entry["n_steps"] = steps
        data = None
        for backend, folder in folders.items():
            path = folder / f"{name}.fmu"
            if name in unavailable.get(backend, {}) or not path.is_file():
                entry["backends"][backend] = {"error": unavailable.get(backend, {}).get(name, f"no {path}")}
                continue
            _progress(f"FMU {name} ({BACKEND_LABEL[backend]}), {steps} steps of {p.scenario}")
            try:
                first, best = _fmu_step_time(path, b, steps, repeats)
            except Exception as exc:
                entry["backends"][backend] = {"error": "fmpy: " + _reason(exc)}
                continue
            e = {"fmpy_us_per_step": best, "fmpy_us_per_step_first": first}
            e.update(_c_host_time(path, b, steps, repeats))
            entry["backends"][backend] = e
            if data is None:
                data = fmu_data(path)
        if data is not None:
            try:
                first, best = runtime_step_time(name, data, b, steps, repeats)
                entry["python_runtime_us_per_step"], entry["python_runtime_us_per_step_first"] = best, first
            except Exception as exc:
                entry["python_runtime_error"] = _reason(exc)
        for backend, e in entry["backends"].items():     # each figure beside its reference
            if "fmpy_us_per_step" not in e:
                continue
            if backend == "c":
                ref, what = e.get("c_host_us_per_doStep"), "C host fmi2DoStep"
            else:
                ref, what = entry.get("python_runtime_us_per_step"), "runtime class in Python, no FMI"
            e["reference"], e["reference_us_per_step"] = what, ref
            e["fmpy_over_reference"] = e["fmpy_us_per_step"] / ref if ref else None
    return out


# ------------------------------------------------------------------------------------------------
# (c) coupled runs per pairing, (e) scaling
# ------------------------------------------------------------------------------------------------
def _time_runs(scenario, plant: Path, observers: dict[str, Path], vehicle: str, repeats: int,
               unzipped: dict | None = None) -> dict:
    """Best and first wall time of ``repeats`` coupled runs (``harness.run``, fast master)."""
    from .validation.harness import run

    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        res = run(scenario, plant, observers, dt=DT, vehicle=vehicle, unzipped=unzipped)
        times.append(time.perf_counter() - t0)
    best, duration = min(times), res.duration
    steps = len(res.time) - 1
    return {"seconds": best, "first_seconds": times[0], "scenario_seconds": duration, "steps": steps,
            "real_time_factor": duration / best, "first_real_time_factor": duration / times[0],
            "us_per_step": best / steps * 1e6}


def coupled(folder: Path, pairing: Pairing, repeats: int) -> dict:
    """The pairing's co-simulation with the FMUs of ``folder``: see :func:`_time_runs`."""
    return _time_runs(pairing.scenario, folder / f"{pairing.plant_fmu}.fmu",
                      {o: folder / f"{o}.fmu" for o in pairing.observers}, pairing.vehicle, repeats)


def coupled_in_fresh_process(folder: Path, key: str) -> float:
    """Real-time factor of one coupled run of pairing ``key`` in a new Python process (nothing cached)."""
    code = (f"from pathlib import Path; from latobs.bench import coupled, pairings; "
            f"p = next(x for x in pairings() if x.key == {key!r}); "
            f"print(coupled(Path({str(folder)!r}), p, 1)['real_time_factor'])")
    out = subprocess.run([sys.executable, "-P", "-c", code], capture_output=True, text=True, check=True).stdout
    return float(out.strip().splitlines()[-1])


def coupled_section(folders: dict[str, Path], repeats: int) -> list[dict]:
    rows = []
    for p in pairings():
        for backend, folder in folders.items():
            row = {"pairing": p.key, "scenario": p.scenario, "plant": p.plant_fmu, "observers": list(p.observers),
                   "backend": backend, "note": p.note}
            missing = [x for x in (p.plant_fmu, *p.observers) if not (folder / f"{x}.fmu").is_file()]
            if missing:
                row["error"] = f"missing FMU(s) {', '.join(missing)}"
                rows.append(row)
                continue
            _progress(f"coupled {p.scenario} ({BACKEND_LABEL[backend]})")
            try:
                row.update(coupled(folder, p, repeats))
                if p.key == "000":
                    row["fresh_process_real_time_factor"] = coupled_in_fresh_process(folder, p.key)
            except Exception as exc:
                row["error"] = _reason(exc)
            rows.append(row)
    return rows


def _fit(xs, ys) -> dict:
    """Least-squares straight line ys = intercept + slope xs."""
    slope, intercept = np.polyfit(np.asarray(xs, float), np.asarray(ys, float), 1)
    return {"intercept": float(intercept), "slope": float(slope)}


def scaling_section(folder: Path, backend: str, repeats: int) -> dict:
    """Wall seconds per coupled run against scenario length and number of observers (see the
    module docstring), FMUs extracted per run and extracted once."""
    from fmpy import extract

    from .validation.scenarios import get_scenario

    obs = paper_000_observers()
    plant = folder / "CarPlant.fmu"
    paths = {o: folder / f"{o}.fmu" for o in obs}
    out: dict = {"backend": backend, "scenario": SCALING_SCENARIO, "observers": list(obs), "lengths": [],
                 "n_observers": [], "observers_duration": SCALING_OBSERVERS_DURATION}
    tmp = Path(tempfile.mkdtemp(prefix="latobs-bench-unzipped-"))
    try:
        unzipped = {p: extract(str(p), unzipdir=str(tmp / p.stem)) for p in [plant, *paths.values()]}

        def measure(duration: float, observers: dict) -> dict:
            sc = get_scenario(SCALING_SCENARIO, duration=duration)
            per_run = _time_runs(sc, plant, observers, "sedan", repeats)
            once = _time_runs(sc, plant, observers, "sedan", repeats,
                              unzipped={p: unzipped[p] for p in [plant, *observers.values()]})
            return {"duration": duration, "steps": per_run["steps"], "n_observers": len(observers),
                    "seconds_extract_per_run": per_run["seconds"], "seconds_extracted_once": once["seconds"],
                    "us_per_step_extract_per_run": per_run["us_per_step"],
                    "us_per_step_extracted_once": once["us_per_step"],
                    "real_time_factor_extracted_once": once["real_time_factor"]}

        for T in LENGTHS:
            _progress(f"scaling: {T:g} s of {SCALING_SCENARIO}, {len(obs)} observers ({BACKEND_LABEL[backend]})")
            out["lengths"].append(measure(T, paths))
        for k in range(len(obs) + 1):
            _progress(f"scaling: {k} observer(s), {SCALING_OBSERVERS_DURATION:g} s ({BACKEND_LABEL[backend]})")
            out["n_observers"].append(measure(SCALING_OBSERVERS_DURATION, {o: paths[o] for o in obs[:k]}))
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    for key, x in (("lengths", "duration"), ("n_observers", "n_observers")):
        rows = out[key]
        out[f"fit_{key}"] = {col: _fit([r[x] for r in rows], [r[col] for r in rows])
                             for col in ("seconds_extract_per_run", "seconds_extracted_once")}
    return out


# ------------------------------------------------------------------------------------------------
# the whole benchmark
# ------------------------------------------------------------------------------------------------
def bench(fmu_dir: Path, n: int = 3000, repeats: int = 3, *, backends=BACKENDS, lmi: bool = True,
          build: bool = True, fmus: bool = True, coupled_runs: bool = True, scaling: bool = True,
          lmi_designs: list[str] | None = None, solvers=SOLVERS, scs_max_iters: int | None = None,
          lmi_timeout: float | None = LMI_TIMEOUT) -> dict:
    """Every section (see the module docstring); returns the figures (``--json`` writes them)."""
    from .synthesis import lmi as lmi_mod

    fmu_dir = Path(fmu_dir)
    names = fmu_names()
    out: dict = {"date": time.strftime("%Y-%m-%d"), "n_steps": n, "repeats": repeats, "dt": DT,
                 "backends": list(backends), "pairings": [dict(p.__dict__, plant_fmu=p.plant_fmu) for p in pairings()],
                 "build": None, "lmi": None, "fmus": None, "coupled": None, "scaling": None,
                 "unavailable": {}}
    folders = {b: fmu_dir / b for b in backends}
    if build:
        out["build"] = []
        for b in backends:
            _progress(f"latobs build --backend {b} in a fresh process")
            out["build"].append(build_time(b, fill=folders[b]))
    if lmi:
        out["lmi"] = {"solvers": list(solvers), "timeout_seconds": lmi_timeout,
                      "settings": {s: {**lmi_mod.SOLVERS[s], **({"max_iters": scs_max_iters}
                                                                if s == "SCS" and scs_max_iters else {})}
                                   for s in solvers},
                      "rows": lmi_section(lmi_designs or list(designs.DESIGNS), solvers, scs_max_iters,
                                          lmi_timeout)}
    if fmus or coupled_runs or scaling:
        for b in backends:
            out["unavailable"][b] = ensure_fmus(folders[b], b, names)
    if fmus:
        out["fmus"] = fmu_section(folders, names, n, repeats, out["unavailable"])
        out["numpy_reference"] = _numpy_reference(n)
    if coupled_runs:
        out["coupled"] = coupled_section(folders, max(1, repeats - 1))
    if scaling:
        need = ["CarPlant", *paper_000_observers()]
        backend = next((b for b in ("c", "python") if b in folders
                        and all((folders[b] / f"{x}.fmu").is_file() for x in need)), None)
        if backend is None:
            out["scaling"] = {"error": f"no backend folder holds {', '.join(need)}"}
        else:
            out["scaling"] = scaling_section(folders[backend], backend, repeats)
    return out


def _numpy_reference(n: int, nsub: int = 5) -> dict[str, float]:
    """µs per step of a paper-000 observer's arithmetic in numpy: the one-step affine map (5
    states, 4 inputs), and the classical RK4 substeps it replaces."""
    rng = np.random.default_rng(0)
    M = rng.standard_normal((5, 5)) * 0.1
    G = rng.standard_normal((5, 4))
    Phi = np.eye(5) + M * DT
    Gam = G * DT
    w = rng.standard_normal((n, 4))
    s = np.zeros(5)
    t0 = time.perf_counter()
    for i in range(n):
        s = Phi @ s + Gam @ w[i]
    affine = (time.perf_counter() - t0) / n * 1e6
    hs = DT / nsub
    s = np.zeros(5)
    t0 = time.perf_counter()
    for i in range(n):
        b = G @ w[i]
        for _ in range(nsub):
            k1 = M @ s + b
            k2 = M @ (s + 0.5 * hs * k1) + b
            k3 = M @ (s + 0.5 * hs * k2) + b
            k4 = M @ (s + hs * k3) + b
            s = s + hs / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
    rk4 = (time.perf_counter() - t0) / n * 1e6
    return {"numpy_affine_map_us": affine, "numpy_rk4_substeps_us": rk4}


# ------------------------------------------------------------------------------------------------
# Markdown tables
# ------------------------------------------------------------------------------------------------
def _us(x) -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "—"
    return f"{x:.3g}" if x < 1 else f"{x:.1f}" if x < 1000 else f"{x:.0f}"


def _s(x, digits: int = 2) -> str:
    return "—" if x is None else f"{x:.{digits}f}"


def _g(x) -> str:
    return "—" if x is None else f"{x:.4g}"


def _cell(text: str) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def build_table(rows: list[dict]) -> str:
    lines = ["Whole `latobs build` (every observer at its default vehicle and every plant), one fresh process per "
             "backend (`python -m latobs build --out TMP --backend B`):", "",
             "| backend | wall time (s) | FMUs built | LMI solver time inside (s) | result |", "|---|---|---|---|---|"]
    for r in rows:
        result = "ok" if r["returncode"] == 0 else _cell(f"exit {r['returncode']}: {r['error']}")
        lines.append(f"| {BACKEND_LABEL.get(r['backend'], r['backend'])} | {_s(r['seconds'], 1)} | {r['fmus']} | "
                     f"{_s(r.get('lmi_solver_seconds'), 1)} | {result} |")
    return "\n".join(lines)


def _lmi_cell(r: dict | None) -> tuple[str, str]:
    """(time cell, result cell) of one design x solver row."""
    if r is None:
        return "—", "not run"
    if r.get("uses_lmi") is False and r["result"] == "certified":
        timing = f"{_s(r['design_seconds'])} (no LMI)"
    else:
        timing = f"{_s(r['design_seconds'])} ({_s(r['lmi_seconds'])}, {r['lmi_solves']})"
    if r.get("timed_out"):
        timing = f"> {r['design_seconds']:.0f} (stopped)"
    result = r["result"] or "?"
    statuses = [s for s in r.get("lmi_statuses", []) if s != "optimal"]
    if r["result"] == "certified":
        result += f" {r['checks_passed']}/{r['checks_total']}, γ = {_g(r['gamma'])}"
    else:
        if r.get("checks_total"):
            result += f" ({r['checks_total'] - r['checks_passed']} of {r['checks_total']} checks)"
        result += (f", γ = {_g(r['gamma'])}" if r.get("gamma") is not None else "") + f": {r['reason']}"
    if statuses:
        result += f" [solver: {', '.join(statuses)}]"
    return timing, _cell(result)


def lmi_table(section: dict) -> str:
    rows = section["rows"]
    solvers = section["solvers"]
    settings = section.get("settings", {})
    scs = settings.get("SCS")
    lines = ["LMI designs at their default vehicle, each solver's result through the independent certificate "
             "(`certificate.certify`, as `latobs design`/`build`). Time: wall time of the design function in s "
             "(of it, its LMI solves in s, and their number, fallbacks and infeasibility diagnostics included); "
             "certificate time separate. Clarabel: its defaults (numerical-failure fallback of ERRATA 002)"
             + (f"; SCS: eps_abs = {scs.get('eps_abs'):g}, eps_rel = {scs.get('eps_rel'):g}, "
                f"max_iters = {scs.get('max_iters')}" if scs else "")
             + (f". Each design x solver in a fresh process, stopped after {section['timeout_seconds']:g} s"
                if section.get("timeout_seconds") else "") + ".", ""]
    head = "| design (paper, vehicle) |"
    sep = "|---|"
    for s in solvers:
        head += f" {SOLVER_LABEL.get(s, s)}: design s (LMI s, solves) | {SOLVER_LABEL.get(s, s)}: result |"
        sep += "---|---|"
    if len(solvers) == 2:
        a, b = (SOLVER_LABEL.get(x, x) for x in solvers)
        head += f" LMI time {b} ÷ {a} | γ relative difference |"
        sep += "---|---|"
    head += " certificate s |"
    sep += "---|"
    lines += [head, sep]
    by = {(r["design"], r["solver"]): r for r in rows}
    for name in dict.fromkeys(r["design"] for r in rows):
        first = next(r for r in rows if r["design"] == name)
        line = f"| {name} ({first['paper']}, {first['vehicle']}) |"
        for s in solvers:
            timing, result = _lmi_cell(by.get((name, s)))
            line += f" {timing} | {result} |"
        if len(solvers) == 2:
            a, b = by.get((name, solvers[0])), by.get((name, solvers[1]))
            ratio = (f"{b['lmi_seconds'] / a['lmi_seconds']:.1f}" if a and b and a.get("lmi_solves")
                     and b.get("lmi_solves") and a["lmi_seconds"] > 0 else "—")
            diff = (f"{abs(b['gamma'] - a['gamma']) / abs(a['gamma']):.1e}"
                    if a and b and a.get("uses_lmi") and a.get("gamma") and b.get("gamma") is not None else "—")
            line += f" {ratio} | {diff} |"
        certs = [_s(by[(name, s)].get("certificate_seconds")) for s in solvers if (name, s) in by]
        line += f" {' / '.join(certs)} |"
        lines.append(line)
    totals = []
    for s in solvers:
        sel = [r for r in rows if r["solver"] == s]
        ok = sum(r["result"] == "certified" for r in sel)
        stopped = sum(bool(r.get("timed_out")) for r in sel)
        totals.append(f"{SOLVER_LABEL.get(s, s)}: {ok}/{len(sel)} certified"
                      + (f", {stopped} stopped at the cap" if stopped else "") + ", LMI solves "
                      f"{sum(r['lmi_seconds'] for r in sel):.1f} s, design functions "
                      f"{sum(r['design_seconds'] or 0 for r in sel):.1f} s" + (" (the stopped ones at the cap)"
                                                                                if stopped else ""))
    lines += ["", "Totals: " + "; ".join(totals) + "."]
    return "\n".join(lines)


def fmu_table(r: dict) -> str:
    fm = r["fmus"]
    backends = r["backends"]
    lines = [f"µs per communication step (dt = {r['dt'] * 1e3:g} ms), each FMU driven by the bus of its pairing "
             f"(up to {r['n_steps']} steps). fmpy: set inputs + doStep + get outputs through fmpy's FMU2Slave, best of "
             f"{r['repeats']} fresh instances (first instance in the process). C host: a plain C program, no Python in "
             "the loop (a pythonfmu FMU with libpython preloaded), best (median) of 5 fresh instances: fmi2DoStep alone "
             "/ set + doStep + get. Reference: for pythonfmu the FMU's runtime class of `fmu_src/` stepped directly in "
             "Python (same arithmetic, no FMI; first instance in parentheses), for native C the C host's fmi2DoStep.",
             "", "| FMU | driven by | backend | µs/step via fmpy | µs/doStep in a C host | µs/step in a C host (with I/O) "
             "| reference µs/step | fmpy ÷ reference |", "|---|---|---|---|---|---|---|---|"]
    for name, f in fm.items():
        where = f"{f['scenario']} ({f.get('n_steps', '—')} steps)"
        if "error" in f:
            lines.append(f"| {name} | {where} | — | {_cell(f['error'])} | | | | |")
            continue
        for b in backends:
            e = f["backends"].get(b)
            if e is None:
                continue
            if "error" in e:
                lines.append(f"| {name} | {where} | {BACKEND_LABEL[b]} | {_cell(e['error'])} | — | — | — | — |")
                continue
            if b == "c":
                ref = f"{_us(e.get('reference_us_per_step'))} (C host doStep)"
            else:
                ref = (f"{_us(f.get('python_runtime_us_per_step'))} ({_us(f.get('python_runtime_us_per_step_first'))}) "
                       "(Python runtime)")
            ratio = "—" if e.get("fmpy_over_reference") is None else f"{e['fmpy_over_reference']:.1f}"
            host = ("—" if "c_host_error" in e else
                    f"{_us(e.get('c_host_us_per_doStep'))} ({_us(e.get('c_host_median_us_per_doStep'))})")
            host_io = ("—" if "c_host_error" in e else
                       f"{_us(e.get('c_host_us_per_step'))} ({_us(e.get('c_host_median_us_per_step'))})")
            lines.append(f"| {name} | {where} | {BACKEND_LABEL[b]} | {_us(e['fmpy_us_per_step'])} "
                         f"({_us(e['fmpy_us_per_step_first'])}) | {host} | {host_io} | {ref} | {ratio} |")
    if "python" in backends and "c" in backends:
        lines += ["", "| FMU | pythonfmu ÷ native C via fmpy | pythonfmu ÷ native C, doStep in a C host |",
                  "|---|---|---|"]
        for name, f in fm.items():
            py, c = f.get("backends", {}).get("python", {}), f.get("backends", {}).get("c", {})
            if "fmpy_us_per_step" not in py or "fmpy_us_per_step" not in c:
                continue
            host = (f"{py['c_host_us_per_doStep'] / c['c_host_us_per_doStep']:.0f}"
                    if py.get("c_host_us_per_doStep") and c.get("c_host_us_per_doStep") else "—")
            lines.append(f"| {name} | {py['fmpy_us_per_step'] / c['fmpy_us_per_step']:.1f} | {host} |")
    ref = r.get("numpy_reference")
    if ref:
        lines += ["", f"numpy in the same run: the affine map of one paper-000 observer step (5 states, 4 inputs) "
                      f"{_us(ref['numpy_affine_map_us'])} µs, the RK4 substeps it replaces "
                      f"{_us(ref['numpy_rk4_substeps_us'])} µs."]
    return "\n".join(lines)


def coupled_table(rows: list[dict]) -> str:
    lines = ["Coupled runs through the validation harness (`harness.run`, fast master), best of the repeats "
             "(first run in parentheses):", "",
             "| pairing | scenario (s simulated) | plant + observers | backend | wall time (s) | µs per step | "
             "real time |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        fmus = f"{r['plant']} + {', '.join(r['observers'])}"
        if "error" in r:
            lines.append(f"| {r['pairing']} | {r['scenario']} | {fmus} | {BACKEND_LABEL.get(r['backend'], r['backend'])} "
                         f"| {_cell(r['error'])} | — | — |")
            continue
        fresh = (f" (fresh process: {r['fresh_process_real_time_factor']:.0f}×)"
                 if "fresh_process_real_time_factor" in r else "")
        lines.append(f"| {r['pairing']} | {r['scenario']} ({r['scenario_seconds']:g}) | {fmus} | "
                     f"{BACKEND_LABEL.get(r['backend'], r['backend'])} | {r['seconds']:.2f} ({r['first_seconds']:.2f}) | "
                     f"{r['us_per_step']:.0f} | {r['real_time_factor']:.0f}×{fresh} |")
    return "\n".join(lines)


def scaling_table(s: dict) -> str:
    if "error" in s:
        return f"Scaling: not measured ({s['error']})."
    b = BACKEND_LABEL.get(s["backend"], s["backend"])
    lines = [f"Cost of one coupled run, {b} FMUs, best of the repeats: wall seconds per run with the FMUs extracted "
             "for every run (`harness.run` alone) and extracted once (`unzipped=`, as a campaign worker), and µs per "
             "step (extracted once).", "",
             f"| {s['scenario']} length (s) | steps | observers | s per run (extract per run) | s per run (extracted once) "
             "| µs per step | real time |", "|---|---|---|---|---|---|---|"]
    for r in s["lengths"]:
        lines.append(f"| {r['duration']:g} | {r['steps']} | {r['n_observers']} | {r['seconds_extract_per_run']:.3f} | "
                     f"{r['seconds_extracted_once']:.3f} | {r['us_per_step_extracted_once']:.1f} | "
                     f"{r['real_time_factor_extracted_once']:.0f}× |")
    lines += ["", f"| observers beside CarPlant ({s['observers_duration']:g} s) | s per run (extract per run) | "
                  "s per run (extracted once) | µs per step |", "|---|---|---|---|"]
    for r in s["n_observers"]:
        lines.append(f"| {r['n_observers']} | {r['seconds_extract_per_run']:.3f} | {r['seconds_extracted_once']:.3f} | "
                     f"{r['us_per_step_extracted_once']:.1f} |")
    fl, fo = s["fit_lengths"], s["fit_n_observers"]
    lines += ["", f"Straight lines (least squares): per run {fl['seconds_extract_per_run']['intercept']:.3f} s + "
                  f"{fl['seconds_extract_per_run']['slope'] * 1e3:.2f} ms per simulated second (extract per run), "
                  f"{fl['seconds_extracted_once']['intercept']:.3f} s + {fl['seconds_extracted_once']['slope'] * 1e3:.2f} "
                  f"ms per simulated second (extracted once); per observer added "
                  f"{fo['seconds_extracted_once']['slope'] * 1e3:.1f} ms per {s['observers_duration']:g} s run "
                  f"(extracted once; CarPlant alone {s['n_observers'][0]['seconds_extracted_once']:.3f} s)."]
    return "\n".join(lines)


def table(r: dict) -> str:
    """Every measured section as Markdown."""
    parts = []
    if r.get("build"):
        parts.append(build_table(r["build"]))
    if r.get("lmi"):
        parts.append(lmi_table(r["lmi"]))
    if r.get("fmus"):
        parts.append(fmu_table(r))
    if r.get("coupled"):
        parts.append(coupled_table(r["coupled"]))
    if r.get("scaling"):
        parts.append(scaling_table(r["scaling"]))
    return "\n\n".join(parts)


def _jsonable(x):
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, (np.floating, np.integer)):
        return x.item()
    if isinstance(x, Path):
        return str(x)
    return x


def parser() -> argparse.ArgumentParser:
    from .synthesis.lmi import SCS_SETTINGS   # no solver stack: constants only

    p = argparse.ArgumentParser(prog="latobs bench", description=__doc__.split("\n\n")[0])
    p.add_argument("--fmu-dir", default="build/bench",
                   help="FMUs to measure, per backend in FMU_DIR/python and FMU_DIR/c (built there if missing)")
    p.add_argument("--steps", type=int, default=3000, help="communication steps per FMU measurement (at most the "
                   "pairing's scenario; default 3000)")
    p.add_argument("--repeats", type=int, default=3, help="fresh instances / runs per figure, the best is kept "
                   "(default 3)")
    p.add_argument("--json", dest="json_file", help="also write every figure to this JSON file")
    p.add_argument("--backends", default=",".join(BACKENDS),
                   help="comma-separated backends to measure (default python,c)")
    p.add_argument("--designs", default=None,
                   help="comma-separated designs of the LMI section (default: every design)")
    p.add_argument("--scs-max-iters", type=int, default=None,
                   help=f"SCS's iteration cap in the LMI section (default {SCS_SETTINGS['max_iters']}, "
                        "latobs.synthesis.lmi.SCS_SETTINGS)")
    p.add_argument("--lmi-timeout", type=float, default=LMI_TIMEOUT,
                   help=f"s, cap of one design x solver in the LMI section (a fresh process, stopped at the cap; "
                        f"default {LMI_TIMEOUT:g})")
    p.add_argument("--skip-build", action="store_true", help="no whole `latobs build` timing")
    p.add_argument("--skip-lmi", action="store_true", help="no LMI solver comparison")
    p.add_argument("--skip-fmus", action="store_true", help="no per-FMU step timing")
    p.add_argument("--skip-coupled", action="store_true", help="no coupled run per pairing")
    p.add_argument("--skip-scaling", action="store_true", help="no scaling with scenario length and observers")
    return p


def main(argv: list[str] | None = None) -> int:
    a = parser().parse_args(argv)
    backends = [b.strip() for b in a.backends.split(",") if b.strip()]
    bad = [b for b in backends if b not in BACKENDS]
    if bad or not backends:
        parser().error(f"--backends: unknown backend(s) {', '.join(bad) or '(none)'}; known: {', '.join(BACKENDS)}")
    lmi_designs = [d.strip() for d in a.designs.split(",") if d.strip()] if a.designs else None
    unknown = [d for d in lmi_designs or [] if d not in designs.DESIGNS]
    if unknown:
        parser().error(f"--designs: unknown design(s) {', '.join(unknown)}; known: {', '.join(designs.DESIGNS)}")
    r = bench(Path(a.fmu_dir), a.steps, a.repeats, backends=backends, lmi=not a.skip_lmi, build=not a.skip_build,
              fmus=not a.skip_fmus, coupled_runs=not a.skip_coupled, scaling=not a.skip_scaling,
              lmi_designs=lmi_designs, scs_max_iters=a.scs_max_iters, lmi_timeout=a.lmi_timeout)
    print(table(r))
    if a.json_file:
        from .atomic import atomic_write_text

        atomic_write_text(a.json_file, json.dumps(_jsonable(r), indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
