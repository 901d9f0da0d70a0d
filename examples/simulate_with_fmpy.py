"""Simulate a latobs observer FMU beside the CarPlant FMU with plain fmpy (no latobs import).

What it shows: the FMUs are ordinary FMI 2.0 co-simulation FMUs. This script drives CarPlant
with a steering and speed input it generates itself (a sine steer at 80 km/h on a road that
banks by 3 degrees after 2 s), wires each observer input from the plant output (or the driver
input) of the same name, steps both with ``fmpy.fmi2.FMU2Slave`` and prints the observer's final
sideslip and bank estimates next to the truth, and their RMS errors. Nothing of latobs is
imported: only fmpy and the standard library (the FMUs carry their own runtime).

Run it, with the FMUs built first (`latobs build SideslipBankObserver CarPlant`, into build/):

    python examples/simulate_with_fmpy.py --fmu-dir build
    python examples/simulate_with_fmpy.py --fmu-dir build --observer SideslipBankObserverTire --duration 30

Timing is the one of `latobs validate`: inputs at t_k, doStep(t_k, dt) for every FMU, outputs
read at t_k + dt; the observer sees the plant's outputs of t_k (one step of delay).
"""
from __future__ import annotations

import argparse
import math
import shutil
import sys
from pathlib import Path

from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave


class Fmu:
    """One extracted, instantiated FMU, with its variables by name."""

    def __init__(self, path: Path, instance_name: str):
        self.md = read_model_description(str(path))
        self.unzipdir = extract(str(path))
        self.vars = {v.name: v for v in self.md.modelVariables}
        self.inputs = [v.name for v in self.md.modelVariables if v.causality == "input"]
        self.outputs = [v.name for v in self.md.modelVariables if v.causality == "output"]
        self.slave = FMU2Slave(guid=self.md.guid, unzipDirectory=self.unzipdir,
                               modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName=instance_name)
        self.slave.instantiate()
        self.slave.setupExperiment(startTime=0.0)

    def set(self, values: dict[str, float]) -> None:
        reals = [(self.vars[n].valueReference, v) for n, v in values.items() if self.vars[n].type == "Real"]
        if reals:
            self.slave.setReal([r for r, _ in reals], [v for _, v in reals])

    def get(self) -> dict[str, float]:
        out = {}
        for typ, getter in (("Real", self.slave.getReal), ("Integer", self.slave.getInteger)):
            names = [n for n in self.outputs if self.vars[n].type == typ]
            if names:
                out.update(zip(names, getter([self.vars[n].valueReference for n in names])))
        return out

    def close(self) -> None:
        self.slave.terminate()
        self.slave.freeInstance()
        shutil.rmtree(self.unzipdir, ignore_errors=True)


def driver(t: float, args) -> dict[str, float]:
    """The plant's inputs at time t: road-wheel steer (rad, > 0 steers left), speed (m/s) and the
    road's bank angle (rad: 0, then a 1 s ramp to --bank-deg from t = 2 s)."""
    steer = math.radians(args.steer_deg) * math.sin(2 * math.pi * args.steer_hz * t)
    ramp = min(max(t - 2.0, 0.0), 1.0)
    return {"delta": steer, "vx": args.speed_kmh / 3.6, "bank_angle": math.radians(args.bank_deg) * ramp}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--fmu-dir", default="build", help="folder with OBSERVER.fmu and CarPlant.fmu (default build)")
    p.add_argument("--observer", default="SideslipBankObserver", help="observer FMU name (a paper-000 observer)")
    p.add_argument("--duration", type=float, default=20.0, help="simulated time, s (default 20)")
    p.add_argument("--dt", type=float, default=0.005, help="communication step, s (default 0.005)")
    p.add_argument("--speed-kmh", type=float, default=80.0, help="constant speed, km/h (default 80)")
    p.add_argument("--steer-deg", type=float, default=1.0, help="road-wheel steer amplitude, deg (default 1)")
    p.add_argument("--steer-hz", type=float, default=0.5, help="steer frequency, Hz (default 0.5)")
    p.add_argument("--bank-deg", type=float, default=3.0, help="road bank, ramped in over 2..3 s, deg (default 3)")
    p.add_argument("--settle", type=float, default=5.0, help="RMS errors over t >= SETTLE s (default 5)")
    p.add_argument("--check-no-latobs", action="store_true",
                   help="fail (exit 3) if the latobs package was imported in this process")
    args = p.parse_args(argv)

    fmu_dir = Path(args.fmu_dir)
    for name in ("CarPlant", args.observer):
        if not (fmu_dir / f"{name}.fmu").is_file():
            p.error(f"{fmu_dir / name}.fmu not found: build it first (latobs build {args.observer} CarPlant "
                    f"--out {fmu_dir})")
    plant = Fmu(fmu_dir / "CarPlant.fmu", "plant")
    observer = Fmu(fmu_dir / f"{args.observer}.fmu", "observer")
    try:
        if not {"beta_hat", "bank_angle_hat"} <= set(observer.outputs):
            p.error(f"{args.observer} has no beta_hat and bank_angle_hat outputs: use a paper-000 observer")
        # wiring by name: each observer input is a plant output, else a driver input
        sources = {n: ("plant" if n in plant.outputs else "driver") for n in observer.inputs}
        missing = [n for n in observer.inputs if n not in plant.outputs and n not in driver(0.0, args)]
        if missing:
            p.error(f"observer inputs without a source: {', '.join(missing)}")
        print(f"wiring: {', '.join(f'{n} <- {s}' for n, s in sources.items())}")

        def bus(u: dict, y: dict) -> dict:
            return {n: (y[n] if sources[n] == "plant" else u[n]) for n in observer.inputs}

        u = driver(0.0, args)
        plant.slave.enterInitializationMode()
        plant.set(u)
        plant.slave.exitInitializationMode()
        y = plant.get()
        observer.slave.enterInitializationMode()
        observer.set(bus(u, y))
        observer.slave.exitInitializationMode()
        est = observer.get()
        truth_bank = u["bank_angle"]

        n = int(round(args.duration / args.dt))
        sq_beta = sq_bank = 0.0
        count = 0
        for k in range(n):
            t = k * args.dt
            u = driver(t, args)
            plant.set(u)
            observer.set(bus(u, y))
            for f in (plant, observer):
                status = f.slave.doStep(currentCommunicationPoint=t, communicationStepSize=args.dt)
                if status is not None and status > 1:      # fmi2OK 0, fmi2Warning 1, fmi2Discard 2
                    raise RuntimeError(f"doStep at t = {t:g} s returned status {status}")
            y, est = plant.get(), observer.get()
            truth_bank = driver(t + args.dt, args)["bank_angle"]
            if t + args.dt >= args.settle:         # beta_hat and CarPlant's beta: both at the roll axis
                sq_beta += (est["beta_hat"] - y["beta"]) ** 2
                sq_bank += (est["bank_angle_hat"] - truth_bank) ** 2
                count += 1
    finally:
        observer.close()
        plant.close()

    deg = math.degrees
    print(f"t = {n * args.dt:g} s, {args.observer} beside CarPlant at {args.speed_kmh:g} km/h")
    print(f"beta: estimate {deg(est['beta_hat']):+.4f} deg, truth {deg(y['beta']):+.4f} deg")
    print(f"bank: estimate {deg(est['bank_angle_hat']):+.4f} deg, truth {deg(truth_bank):+.4f} deg")
    if count:
        print(f"RMS error over t >= {args.settle:g} s: beta {deg(math.sqrt(sq_beta / count)):.4f} deg, "
              f"bank {deg(math.sqrt(sq_bank / count)):.4f} deg (mode {est.get('mode')}, valid {est.get('valid')})")
    if args.check_no_latobs:
        loaded = sorted(m for m in sys.modules if m == "latobs" or m.startswith("latobs."))
        print(f"latobs modules loaded: {loaded or 'none'}")
        if loaded:
            return 3
    return 0


if __name__ == "__main__":
    sys.exit(main())
