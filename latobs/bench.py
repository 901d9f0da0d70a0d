"""``latobs bench``: how fast the built FMUs step, measured side by side in one run.

Not a test: nothing here asserts a time. Every figure is printed beside a reference measured in
the same process, so that ratios (not absolute microseconds, which depend on the machine) are
what gets compared. Per backend (``python``: pythonfmu, ``c``: the native C backend), with the
FMUs of ``--fmu-dir``/<backend> (built there if missing):

* **per FMU**, µs per communication step through fmpy's ``FMU2Slave`` (the same prebuilt ctypes
  set/doStep/get calls as the validation harness): set the inputs, ``doStep``, get the outputs;
* **the same FMU in a plain C host** (``latobs/native/fmi2_host.c``, no Python in the process; a
  pythonfmu FMU gets libpython preloaded): µs per ``fmi2DoStep`` alone, and per set + doStep + get;
* **the same arithmetic in numpy**, per step, in the same run: for an observer, the affine map
  of one step (``Phi @ s + Gam @ w``, 5 states, 4 inputs) and, for comparison, the classical RK4
  substeps it replaces; for the plant, one call of the FMU's own Python runtime class stepping
  outside any FMU;
* **the coupled run**: ``bank-braking`` (30 s at 5 ms: CarPlant + both paper-000 observers)
  through the validation harness, wall time and real-time factor, per backend.
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

OBSERVERS = ("SideslipBankObserver", "SideslipBankObserverTire")
BACKENDS = ("python", "c")
PLANT = "CarPlant"
SCENARIO = "bank-braking"
DT = 0.005


def _bus_trajectory(fmu_dir: Path) -> dict[str, np.ndarray]:
    """Plant inputs and outputs of the bank-braking scenario (one co-simulation, plant alone)."""
    from .validation.harness import run

    res = run(SCENARIO, fmu_dir / f"{PLANT}.fmu", {}, dt=DT)
    return res.bus


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


def _numpy_reference(n: int, nsub: int = 5) -> dict[str, float]:
    """µs per step of the observer arithmetic in numpy: the one-step affine map, and RK4 substeps."""
    rng = np.random.default_rng(0)
    M = rng.standard_normal((5, 5)) * 0.1
    G = rng.standard_normal((5, 4))
    Phi = np.eye(5) + M * 0.005
    Gam = G * 0.005
    w = rng.standard_normal((n, 4))
    s = np.zeros(5)
    t0 = time.perf_counter()
    for i in range(n):
        s = Phi @ s + Gam @ w[i]
    affine = (time.perf_counter() - t0) / n * 1e6
    hs = 0.005 / nsub
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


def _plant_runtime_time(bus: dict[str, np.ndarray], n: int) -> float:
    """µs per CarPlantModel.step outside any FMU (the FMU's own maths, no FMI)."""
    from .fmu_src.car_plant import CarPlantModel
    from .packaging import plant_data

    rt = CarPlantModel(plant_data("sedan"), {})
    rows = [{"delta": float(bus["delta"][i]), "vx": float(bus["vx"][i]),
             "bank_angle": float(bus["bank_angle"][i])} for i in range(n)]
    t0 = time.perf_counter()
    for u in rows:
        rt.step(DT, u)
    return (time.perf_counter() - t0) / n * 1e6


def _coupled(fmu_dir: Path, repeats: int) -> dict[str, float]:
    from .validation.harness import run
    from .validation.scenarios import get_scenario

    sc = get_scenario(SCENARIO)
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        run(sc, fmu_dir / f"{PLANT}.fmu", {o: fmu_dir / f"{o}.fmu" for o in OBSERVERS}, dt=DT)
        times.append(time.perf_counter() - t0)
    best = min(times)
    steps = round(sc.duration / DT)
    return {"seconds": best, "first_seconds": times[0], "scenario_seconds": sc.duration,
            "real_time_factor": sc.duration / best, "first_real_time_factor": sc.duration / times[0],
            "us_per_step": best / steps * 1e6}


def _c_host_time(path: Path, inputs: dict[str, np.ndarray], n: int, repeats: int) -> dict[str, float] | None:
    """µs per fmi2DoStep alone and per set + doStep + get in the plain C host (None: no C host here:
    no compiler, or a pythonfmu FMU and no shared libpython)."""
    from .cbackend import host

    try:
        r = host.bench(path, {k: v[:n] for k, v in inputs.items()}, DT, repeats=max(repeats, 5))
    except host.HostError:
        return None
    return {"c_host_us_per_doStep": r["ns_per_doStep"] / 1e3, "c_host_us_per_step": r["ns_per_step_with_io"] / 1e3,
            "c_host_median_us_per_doStep": r["median_ns_per_doStep"] / 1e3,
            "c_host_median_us_per_step": r["median_ns_per_step_with_io"] / 1e3}


def _ensure(fmu_dir: Path, backend: str) -> Path | None:
    """``fmu_dir/backend`` with the benchmarked FMUs, built there if missing (None: the backend
    cannot build them on this machine)."""
    from . import packaging
    from .pipeline import build

    folder = fmu_dir / backend
    missing = [x for x in (PLANT, *OBSERVERS) if not (folder / f"{x}.fmu").is_file()]
    if missing:
        if backend == "c" and any(packaging.resolve_backend("auto", packaging.OBSERVERS.get(x) or
                                                            packaging.PLANTS[x])[0] != "c" for x in missing):
            return None
        build(missing, None, folder, backend)
    return folder


def bench(fmu_dir: Path, n: int = 3000, repeats: int = 3) -> dict:
    fmu_dir = Path(fmu_dir)
    folders = {b: f for b in BACKENDS if (f := _ensure(fmu_dir, b)) is not None}
    bus = _bus_trajectory(folders["python"])
    n = min(n, len(bus["vx"]) - 1)
    out: dict = {"n_steps": n, "dt": DT, "backends": list(folders), "fmus": {}, "coupled": {}}
    for backend, folder in folders.items():
        for name in (PLANT, *OBSERVERS):   # first: nothing of this FMU cached in the process yet
            first, best = _fmu_step_time(folder / f"{name}.fmu", bus, n, repeats)
            entry = {"fmpy_us_per_step": best, "fmpy_us_per_step_first": first}
            entry.update(_c_host_time(folder / f"{name}.fmu", bus, n, repeats) or {})
            out["fmus"].setdefault(name, {})[backend] = entry
        out["coupled"][backend] = _coupled(folder, max(1, repeats - 1))
    out["plant_runtime_us_per_step"] = _plant_runtime_time(bus, n)
    out["numpy_reference"] = _numpy_reference(n)
    out["coupled"]["python"]["fresh_process_real_time_factor"] = _coupled_in_fresh_process(folders["python"])
    return out


def _coupled_in_fresh_process(fmu_dir: Path) -> float:
    """Real-time factor of one coupled run in a new Python process (nothing cached)."""
    import subprocess
    import sys

    code = (f"from pathlib import Path; from latobs.bench import _coupled; "
            f"print(_coupled(Path({str(fmu_dir)!r}), 1)['real_time_factor'])")
    out = subprocess.run([sys.executable, "-P", "-c", code], capture_output=True, text=True, check=True).stdout
    return float(out.strip().splitlines()[-1])


def _us(x: float | None) -> str:
    return "—" if x is None else f"{x:.3g}" if x < 1 else f"{x:.1f}"


def table(r: dict) -> str:
    ref = r["numpy_reference"]
    backends = r["backends"]
    lines = [f"µs per communication step, {r['n_steps']} steps of {SCENARIO} signals, dt = {r['dt'] * 1e3:g} ms. "
             "fmpy: set inputs + doStep + get outputs through fmpy's FMU2Slave, best of the fresh instances (first "
             "instance in the process). C host: a plain C program, no Python in the loop (a pythonfmu FMU with "
             "libpython preloaded), best (median) of 5 fresh instances, each timed over about 20 ms of steps: "
             "fmi2DoStep alone / set + doStep + get.",
             "| FMU | backend | µs/step via fmpy | µs/doStep in a C host | µs/step in a C host (with I/O) |",
             "|---|---|---|---|---|"]
    for name in (PLANT, *OBSERVERS):
        for b in backends:
            f = r["fmus"][name][b]
            lines.append(f"| {name} | {'pythonfmu' if b == 'python' else 'native C'} | {_us(f['fmpy_us_per_step'])} "
                         f"({_us(f['fmpy_us_per_step_first'])}) | {_us(f.get('c_host_us_per_doStep'))} "
                         f"({_us(f.get('c_host_median_us_per_doStep'))}) | {_us(f.get('c_host_us_per_step'))} "
                         f"({_us(f.get('c_host_median_us_per_step'))}) |")
    if "c" in backends:
        lines += ["", "| FMU | pythonfmu / native C via fmpy | pythonfmu / native C, doStep in a C host |", "|---|---|---|"]
        for name in (PLANT, *OBSERVERS):
            py, c = r["fmus"][name]["python"], r["fmus"][name]["c"]
            host_ratio = (f"{py['c_host_us_per_doStep'] / c['c_host_us_per_doStep']:.0f}"
                          if "c_host_us_per_doStep" in py and "c_host_us_per_doStep" in c else "—")
            lines.append(f"| {name} | {py['fmpy_us_per_step'] / c['fmpy_us_per_step']:.1f} | {host_ratio} |")
    lines += ["", f"references in the same run: numpy affine map of one observer step {_us(ref['numpy_affine_map_us'])} µs "
              f"(numpy RK4 substeps {_us(ref['numpy_rk4_substeps_us'])} µs); CarPlant's Python runtime outside the FMU "
              f"{_us(r['plant_runtime_us_per_step'])} µs", ""]
    for b in backends:
        c = r["coupled"][b]
        fresh = (f" (one run in a fresh process: {c['fresh_process_real_time_factor']:.1f}x)"
                 if "fresh_process_real_time_factor" in c else "")
        lines.append(f"coupled {SCENARIO} through fmpy, {'pythonfmu' if b == 'python' else 'native C'} FMUs (CarPlant + "
                     f"{' + '.join(OBSERVERS)}), {c['scenario_seconds']:g} s simulated: {c['seconds']:.2f} s wall, "
                     f"{c['us_per_step']:.0f} µs per step, {c['real_time_factor']:.1f}x real time{fresh}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="latobs bench", description=__doc__.split("\n\n")[0])
    p.add_argument("--fmu-dir", default="build/bench",
                   help="FMUs to measure, per backend in FMU_DIR/python and FMU_DIR/c (built there if missing)")
    p.add_argument("--steps", type=int, default=3000)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--json", dest="json_file", help="also write the figures to this JSON file")
    a = p.parse_args(argv)
    r = bench(Path(a.fmu_dir), a.steps, a.repeats)
    print(table(r))
    if a.json_file:
        from .atomic import atomic_write_text

        atomic_write_text(a.json_file, json.dumps(r, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
