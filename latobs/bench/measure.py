"""What ``latobs bench`` measures (the LMI section apart, in :mod:`.lmi`): the whole build, µs per
step of every FMU through fmpy and in a plain C host beside a reference, coupled runs and their
scaling. Not a test: nothing here asserts a time; every figure is measured beside a reference in
the same process, and the tables (``latobs bench --markdown``: the speed page) say how."""
from __future__ import annotations

import contextlib
import io
import json
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .. import catalogue
from ..synthesis import designs  # the catalogue only (no solver stack)

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
    from ..packaging import PLANTS

    return plant if vehicle == PLANTS[plant].default_vehicle else f"{plant}_{vehicle}"


def paper_000_observers() -> tuple[str, ...]:
    """``latobs validate``'s default observers beside CarPlant (the demo's ``PAPER_000``)."""
    return tuple(catalogue.default_observers("CarPlant"))


def pairings() -> list[Pairing]:
    """The co-simulations benchmarked: the first run of each paper in ``latobs.demo.RUNS`` with
    nominal plant parameters (tests/validation/test_bench.py checks they are there), and the replay-only
    observers on a CarPlant bus."""
    return [
        Pairing("000", "bank-braking", "CarPlant", "sedan", paper_000_observers(),
                "demo run bank-braking: paper 000's observers"),
        Pairing("001", "double-lane-change-15", "CarPlant", "sedan", ("LateralIntervalObserver",),
                "demo run double-lane-change-15 [001]"),
        Pairing("002", "w1-steer", "CarPlant", "delibasi",
                ("SideslipFixedOrderEstimator", "SideslipKalmanFilter_delibasi"),
                "demo run w1-steer [002], CarPlant for paper 002's vehicle"),
        Pairing("003", "motorcycle-lane-change", "MotorcyclePlant", "sharp_motorcycle",
                tuple(catalogue.default_observers("MotorcyclePlant")),
                "demo run motorcycle-lane-change [003]: paper 003's observers"),
        Pairing("mbds", "double-lane-change", "CarPlant", "sedan",
                tuple(n for n in catalogue.OBSERVERS if catalogue.get(n).default_vehicle == "mbds_250lm"),
                "not a demo run: the observers designed for the MBDS record's vehicle (mbds_250lm), which the demo "
                "only replays, on a CarPlant sedan bus at 22 m/s (inside their speed range); their inputs "
                "(delta, vx, yaw_rate, ay) are all on it"),
    ]


def fmu_names() -> list[str]:
    """Every FMU ``latobs build`` builds (observers at their default vehicle, plants), then the
    other FMUs the pairings need."""
    from ..packaging import PLANTS

    names = [*designs.DESIGNS, *PLANTS]
    for p in pairings():
        names += [x for x in (p.plant_fmu, *p.observers) if x not in names]
    return names


def _parse_fmu(name: str) -> tuple[str, str | None, bool]:
    """(model, vehicle or None for the default, is_plant) of an FMU name."""
    from ..packaging import PLANTS

    for plant in sorted(PLANTS, key=len, reverse=True):
        if name == plant:
            return plant, None, True
        if name.startswith(plant + "_"):
            return plant, name[len(plant) + 1:], True
    design, vehicle = designs.parse_artefact(name)
    return design, vehicle, False


def _kind(name: str):
    from ..packaging import OBSERVERS, PLANTS

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
def _empty_cache_env(folder: Path) -> dict[str, str]:
    """This environment with latobs's cache in ``folder`` (empty: every design solved, every FMU
    built) and turned on."""
    import os

    env = {**os.environ, "LATOBS_CACHE_DIR": str(folder)}
    env.pop("LATOBS_NO_CACHE", None)
    return env


def _timed(args: list[str], env: dict[str, str] | None = None) -> tuple[float, subprocess.CompletedProcess]:
    """(wall seconds, the finished process) of ``python -P -m latobs ARGS`` in a new process."""
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-P", "-m", "latobs", *args], capture_output=True, text=True, env=env)
    return time.perf_counter() - t0, proc


def _stderr_tail(proc: subprocess.CompletedProcess) -> str | None:
    """None for a process that succeeded, else the last lines of its stderr."""
    return None if proc.returncode == 0 else " | ".join(proc.stderr.strip().splitlines()[-3:])


def build_time(backend: str, fill: Path | None = None) -> dict:
    """Wall times of ``python -m latobs build --out TMP --backend BACKEND``, each a new process: cold
    (an empty cache of its own, ``LATOBS_CACHE_DIR``: every design solved, every FMU compiled; zig's
    per-target C runtime already cached), then warm into a new folder (every FMU installed from the
    cache) and warm again into the same folder (every FMU reused in place): {"seconds" (cold),
    "warm_new_folder_seconds", "warm_same_folder_seconds", "returncode", "fmus",
    "lmi_solver_seconds" (sum of the design files' ``solver.seconds`` of the LMI designs), "error"
    (None or the last lines of stderr)}. ``fill``: a folder that then receives the built FMUs and
    design files it lacks."""
    tmp = Path(tempfile.mkdtemp(prefix=f"latobs-bench-build-{backend}-"))
    try:
        env = _empty_cache_env(tmp / "cache")

        def run(out: Path) -> tuple[float, subprocess.CompletedProcess]:
            return _timed(["build", "--out", str(out), "--backend", backend], env)

        cold_dir = tmp / "cold"
        seconds, proc = run(cold_dir)
        warm_new = warm_same = None
        if proc.returncode == 0:
            warm_new, again = run(tmp / "warm")
            warm_same, again2 = run(tmp / "warm")
            if again.returncode or again2.returncode:
                proc = again if again.returncode else again2
        fmus = sorted(cold_dir.glob("*.fmu"))
        lmi_seconds = 0.0
        for f in cold_dir.glob("*.design.json"):
            s = json.loads(f.read_text()).get("solver") or {}
            if s.get("name") in SOLVERS and isinstance(s.get("seconds"), (int, float)):
                lmi_seconds += float(s["seconds"])
        if fill is not None and proc.returncode == 0:
            fill.mkdir(parents=True, exist_ok=True)
            for f in [*fmus, *cold_dir.glob("*.design.json")]:
                if not (fill / f.name).exists():
                    shutil.copy2(f, fill / f.name)
        err = _stderr_tail(proc)
        return {"backend": backend, "seconds": seconds, "warm_new_folder_seconds": warm_new,
                "warm_same_folder_seconds": warm_same, "returncode": proc.returncode, "fmus": len(fmus),
                "lmi_solver_seconds": lmi_seconds,
                "command": f"build --out TMP --backend {backend} (LATOBS_CACHE_DIR: an empty folder)", "error": err}
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def demo_time() -> dict:
    """Wall times of ``latobs demo`` in new processes: cold (an empty cache of its own: every
    design solved, every FMU built for this machine, every run, figure and replay), then warm into
    a new folder (designs and FMUs from the cache; the runs, figures and replays again): {"seconds"
    (cold), "warm_new_folder_seconds", "returncode", "error"}."""
    tmp = Path(tempfile.mkdtemp(prefix="latobs-bench-demo-"))
    try:
        env = _empty_cache_env(tmp / "cache")
        cold, proc = _timed(["demo", "--out", str(tmp / "cold")], env)
        warm = None
        if proc.returncode == 0:
            warm, proc = _timed(["demo", "--out", str(tmp / "warm")], env)
        return {"seconds": cold, "warm_new_folder_seconds": warm, "returncode": proc.returncode,
                "command": "demo --out TMP (LATOBS_CACHE_DIR: an empty folder)", "error": _stderr_tail(proc)}
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


#: the campaign `latobs bench` times: paper 000's robustness campaign (bank-braking, 10 s per run)
CAMPAIGN, CAMPAIGN_RUNS, CAMPAIGN_WORKERS = "robustness-000", 1000, 2


def campaign_time(folder: Path, runs: int = CAMPAIGN_RUNS, workers: int = CAMPAIGN_WORKERS) -> dict:
    """Wall time of ``latobs campaign robustness-000 --runs RUNS --workers WORKERS`` in a new process
    with the native FMUs of ``folder`` (its FMUs reused), into an empty output folder: {"seconds"
    (the whole command), "execution_s" (the runs on the local Dask cluster, as the campaign's
    summary times them), "cluster_start_s", "runs_per_s", "runs", "ok", "workers", "returncode",
    "error"}."""
    tmp = Path(tempfile.mkdtemp(prefix="latobs-bench-campaign-"))
    try:
        seconds, proc = _timed(["campaign", CAMPAIGN, "--runs", str(runs), "--workers", str(workers), "--no-plots",
                                "--no-progress", "--fmu-dir", str(folder), "--out", str(tmp)])
        row = {"campaign": CAMPAIGN, "runs": runs, "workers": workers, "seconds": seconds,
               "returncode": proc.returncode, "command": f"campaign {CAMPAIGN} --runs {runs} --workers {workers} "
                                                         "--no-plots --no-progress", "error": _stderr_tail(proc)}
        summary = tmp / f"campaign_{CAMPAIGN}" / "summary.json"
        if proc.returncode == 0 and summary.is_file():
            s = json.loads(summary.read_text(encoding="utf-8"))
            timing = s.get("timing") or {}
            row.update(ok=s.get("ok"), execution_s=timing.get("execution_s"),
                       cluster_start_s=timing.get("cluster_start_s"), runs_per_s=timing.get("runs_per_s"))
        return row
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


# ------------------------------------------------------------------------------------------------
# FMUs: building the missing ones, their data, the bus of their pairing
# ------------------------------------------------------------------------------------------------
def ensure_fmus(folder: Path, backend: str, names: list[str]) -> dict[str, str]:
    """Build the FMUs of ``names`` missing in ``folder`` with ``backend`` (Clarabel designs);
    returns {name: reason} of those that could not be built (the build's output is kept quiet)."""
    from ..pipeline import build, current

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
    from ..validation.harness import run

    return run(pairing.scenario, folder / f"{pairing.plant_fmu}.fmu", {}, dt=DT, vehicle=pairing.vehicle).bus


def _fmu_step_time(path: Path, inputs: dict[str, np.ndarray], n: int, repeats: int) -> tuple[float, float]:
    """µs per (set inputs + doStep + get outputs) over ``n`` steps: (first instance in the process,
    best of ``repeats`` fresh instances). They differ when a runtime builds and caches per-process
    data on its first steps (the paper-000 observers' step maps)."""
    from ..validation.harness import FmuInstance

    times = []
    for _ in range(repeats):
        fmu = FmuInstance(path.stem, path)
        names = [v.name for v in fmu.inputs if v.name in inputs]   # optional inputs (CarPlant's
        # stiffness_scale_f/r) stay at their start values, as in the harness
        rows = [{k: float(inputs[k][i]) for k in names} for i in range(n)]
        fmu.start(rows[0])
        do_step = fmu.do_step
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

    from ..fmu_src.framework import start_values

    spec = import_module(f"{__package__.rpartition('.')[0]}.fmu_src.models.{_kind(name).model_module}").SPEC
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
    from fmpy import read_model_description

    from ..cbackend import host

    try:
        # the bus carries every signal of the pairing; the host sets the FMU's own inputs only
        names = {v.name for v in read_model_description(str(path)).modelVariables if v.causality == "input"}
        r = host.bench(path, {k: v[:n] for k, v in inputs.items() if k in names}, DT, repeats=max(repeats, 5))
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
    """Best and first wall time of ``repeats`` coupled runs (``harness.run``, direct FMI calls)."""
    from ..validation.harness import run

    times, stepping = [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        res = run(scenario, plant, observers, dt=DT, vehicle=vehicle, unzipped=unzipped)
        times.append(time.perf_counter() - t0)
        stepping.append(res.info["stepping_seconds"])
    best, duration = min(times), res.duration
    steps = len(res.time) - 1
    return {"seconds": best, "first_seconds": times[0], "scenario_seconds": duration, "steps": steps,
            "real_time_factor": duration / best, "first_real_time_factor": duration / times[0],
            "us_per_step": best / steps * 1e6,
            # the stepping loop alone (set + doStep + get of every FMU, the routes): which one ran
            "master_loop": res.info["master_loop"], "loop_us_per_step": min(stepping) / steps * 1e6}


def coupled(folder: Path, pairing: Pairing, repeats: int) -> dict:
    """The pairing's co-simulation with the FMUs of ``folder``: see :func:`_time_runs`."""
    return _time_runs(pairing.scenario, folder / f"{pairing.plant_fmu}.fmu",
                      {o: folder / f"{o}.fmu" for o in pairing.observers}, pairing.vehicle, repeats)


def coupled_in_fresh_process(folder: Path, key: str) -> float:
    """Real-time factor of one coupled run of pairing ``key`` in a new Python process (nothing cached)."""
    code = (f"from pathlib import Path; from latobs.bench.measure import coupled, pairings; "
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
    from ..validation.instance import extract

    from ..validation.scenarios import get_scenario

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


def machine() -> dict:
    """What the figures were measured on: CPU model, logical cores, OS, Python, and the load
    average (1, 5, 15 min) at the start (other processes share the machine)."""
    import os
    import platform

    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as f:
            cpu = next((line.split(":", 1)[1].strip() for line in f if line.startswith("model name")), cpu)
    except OSError:
        pass
    try:
        load = [round(x, 2) for x in os.getloadavg()]
    except (OSError, AttributeError):
        load = None
    return {"cpu": cpu, "logical_cores": os.cpu_count(), "system": f"{platform.system()} {platform.release()}",
            "python": platform.python_version(), "numpy": np.__version__, "load_average": load}


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
