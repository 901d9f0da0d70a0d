"""Run a native observer FMU through ModelExchange with fmpy's CVode, beside the CarPlant FMU (no latobs import).

What it shows: a native latobs FMU (``latobs build``'s default where a C compiler is present) has
both FMI 2.0 interfaces. This script co-simulates CarPlant with the driver of
``simulate_with_fmpy.py`` (a 1 degree sine steer at 80 km/h on a road that banks by 3 degrees after
2 s), samples the observer's inputs at every communication point, and runs the observer on those
samples twice: as a co-simulation FMU, and as a ModelExchange FMU integrated by fmpy's CVode
solver. It prints, per estimate, the largest difference between the two and the final values
beside the truth.

The samples are given to fmpy held from one to the next (each time twice: the value before, then
the value after). fmpy's ModelExchange driver sets an FMU's inputs only at input events, not
before each derivative evaluation, and CVode takes long internal steps between events: with
interpolated inputs the integration would lag them. Held, every sample is an event, and both
interfaces solve nearly the same problem. What differs: the default observers' co-simulation has
a first-order hold (it integrates the samples as ramps, ModelExchange as the held steps it is
given: O(h), about 1e-3 of the peak at 1 ms), CVode's tolerance, and the one step by which a
co-simulation decides a mode switch late.

Run it, with the native FMUs built first (`latobs build SideslipBankObserver CarPlant`, into build/):

    python examples/model_exchange_with_fmpy.py --fmu-dir build
    python examples/model_exchange_with_fmpy.py --fmu-dir build --observer SideslipBankObserverTire --dt 0.002
"""
from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np
from fmpy import read_model_description, simulate_fmu

from simulate_with_fmpy import Fmu, driver   # the same folder: its FMU wrapper and its driver

DRIVE = argparse.Namespace(steer_deg=1.0, steer_hz=0.5, speed_kmh=80.0, bank_deg=3.0)


def plant_run(path: Path, duration: float, dt: float) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """CarPlant co-simulated on the driver's inputs: the time grid and, on it, every driver input
    and plant output (the bus the observer reads from)."""
    plant = Fmu(path, "plant")
    n = int(round(duration / dt))
    t = np.arange(n + 1) * dt
    rows = []
    try:
        u = driver(0.0, DRIVE)
        plant.slave.enterInitializationMode()
        plant.set(u)
        plant.slave.exitInitializationMode()
        rows.append({**u, **plant.get()})
        for k in range(n):
            plant.set(driver(t[k], DRIVE))
            plant.slave.doStep(currentCommunicationPoint=t[k], communicationStepSize=dt)
            rows.append({**driver(t[k + 1], DRIVE), **plant.get()})
    finally:
        plant.close()
    return t, {name: np.array([r[name] for r in rows]) for name in rows[0]}


def held(t: np.ndarray, signals: dict[str, np.ndarray]) -> np.ndarray:
    """fmpy input rows holding sample k over [t_k, t_k+1): every time after the first twice."""
    rows = np.zeros(2 * len(t) - 1, dtype=[("time", float)] + [(k, float) for k in signals])
    rows["time"] = np.repeat(t, 2)[1:]
    for k, v in signals.items():
        rows[k] = np.repeat(v, 2)[:-1]
    return rows


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--fmu-dir", default="build", help="folder with OBSERVER.fmu and CarPlant.fmu (default build)")
    p.add_argument("--observer", default="SideslipBankObserver", help="observer FMU name (a paper-000 observer)")
    p.add_argument("--duration", type=float, default=10.0, help="simulated time, s (default 10)")
    p.add_argument("--dt", type=float, default=0.001, help="communication step, s (default 0.001)")
    p.add_argument("--rtol", type=float, default=1e-8, help="CVode's relative tolerance (default 1e-8)")
    args = p.parse_args(argv)

    fmu_dir = Path(args.fmu_dir)
    obs_path = fmu_dir / f"{args.observer}.fmu"
    for path in (fmu_dir / "CarPlant.fmu", obs_path):
        if not path.is_file():
            p.error(f"{path} not found: build it first (latobs build {args.observer} CarPlant --out {fmu_dir})")
    md = read_model_description(str(obs_path))
    if md.modelExchange is None:
        p.error(f"{obs_path} has no ModelExchange interface: build it with the native C backend "
                f"(latobs build {args.observer} --backend c --out {fmu_dir})")
    t, bus = plant_run(fmu_dir / "CarPlant.fmu", args.duration, args.dt)
    inputs = held(t, {v.name: bus[v.name] for v in md.modelVariables if v.causality == "input"})
    estimates = ["beta_hat", "bank_angle_hat", "yaw_rate_hat"]
    common = dict(input=inputs, start_time=0.0, stop_time=float(t[-1]), output_interval=args.dt, output=estimates)
    cs = simulate_fmu(str(obs_path), fmi_type="CoSimulation", **common)
    me = simulate_fmu(str(obs_path), fmi_type="ModelExchange", solver="CVode", relative_tolerance=args.rtol,
                      record_events=False, **common)
    print(f"{args.observer}: CoSimulation and ModelExchange (CVode, rtol {args.rtol:g}) on CarPlant's samples, "
          f"dt = {args.dt:g} s, {len(t) - 1} steps")
    for name in estimates:
        a, b = cs[name], np.interp(cs["time"], me["time"], me[name])
        print(f"  {name}: max |ME - CS| = {np.max(np.abs(b - a)):.3g} (peak {np.max(np.abs(a)):.3g})")
    deg = math.degrees
    print(f"final beta: ModelExchange {deg(me['beta_hat'][-1]):+.3f} deg, CoSimulation {deg(cs['beta_hat'][-1]):+.3f} "
          f"deg, truth {deg(bus['beta'][-1]):+.3f} deg")
    print(f"final bank: ModelExchange {deg(me['bank_angle_hat'][-1]):+.3f} deg, CoSimulation "
          f"{deg(cs['bank_angle_hat'][-1]):+.3f} deg, truth {deg(bus['bank_angle'][-1]):+.3f} deg")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
