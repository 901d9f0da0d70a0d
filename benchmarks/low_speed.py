"""Sideslip at low speed: each sideslip observer beside CarPlant (sedan, flat road, no sensor noise)
against the kinematic estimate beta_kin = lr r / vx, which dominates below about 10 m/s.

    python benchmarks/low_speed.py [--out DIR]

Builds (native, this machine) CarPlant and the observers for ``sedan`` in DIR (default a temporary
folder): SideslipBankObserver (paper 000), LateralIntervalObserver (paper 001, the midpoint of its
bounds), SideslipKalmanFilter and SideslipFixedOrderEstimatorScheduled (paper 002 scheduled; sedan
with a +-10 % stiffness box and the shipped scheduled design's 15-63 m/s grid, then the grid
extended down to 2.5 m/s). Two manoeuvres of 20 s at constant speed: a 2 deg road-wheel sine at
0.3 Hz and a 2 deg steady turn; RMS of the error to CarPlant's beta at the CG after 2 s, degrees;
beta_kin from the same (one step earlier) sample the observers see. Ratio < 1: the observer is
better. The documentation's validation page shows the table.
"""
from __future__ import annotations

import argparse
import math
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import tomli_w

from latobs.cli import main as latobs
from latobs.synthesis.params import load_vehicle
from latobs.validation import harness
from latobs.validation.scenario_base import Scenario, _cosine_blend

SPEEDS = (3.0, 5.0, 7.5, 10.0)       # m/s
SETTLE, DURATION, DT = 2.0, 20.0, 0.005
DEG = math.pi / 180.0


@dataclass(frozen=True)
class LowSpeed(Scenario):
    """Constant speed, flat road; steering "sine" (amplitude, 0.3 Hz, 1 s fade-in) or "turn"."""
    name: str = "low-speed"
    description: str = "constant low speed, open-loop road-wheel steering"
    duration: float = DURATION
    settle_time: float = SETTLE
    speed: float = 5.0
    kind: str = "sine"
    amp_deg: float = 2.0

    def signals(self, t, vehicle="sedan"):
        t = np.asarray(t, dtype=float)
        a = self.amp_deg * DEG
        d = (a * _cosine_blend(t) * np.sin(2 * math.pi * 0.3 * t) if self.kind == "sine"
             else a * _cosine_blend((t - 0.5) / 1.5))
        return {"delta": d, "vx": np.full_like(t, self.speed), "bank_angle": np.zeros_like(t)}


def _vehicle(path: Path, lowest: float) -> str:
    """sedan with paper 002's ranges: Cf, Cr +-10 %, speed lowest ... 63 m/s (a vehicle file)."""
    doc = load_vehicle("sedan").as_dict()
    doc["name"] = path.stem
    cf, cr = doc["parameters"]["Cf"]["value"], doc["parameters"]["Cr"]["value"]
    doc["ranges"] = {"speed": {"min": lowest, "max": 63.0, "unit": "m/s"},
                     "Cf": {"min": 0.9 * cf, "max": 1.1 * cf, "unit": "N/rad"},
                     "Cr": {"min": 0.9 * cr, "max": 1.1 * cr, "unit": "N/rad"}}
    path.write_text(tomli_w.dumps(doc))
    return str(path)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=None)
    out = ap.parse_args(argv).out or Path(tempfile.mkdtemp(prefix="low-speed-"))
    out.mkdir(parents=True, exist_ok=True)
    build = ["--platforms", "host", "--out", str(out), "--backend", "c"]
    assert latobs(["build", "CarPlant", "SideslipBankObserver", "LateralIntervalObserver", "SideslipKalmanFilter",
                   "--vehicle", "sedan", *build]) == 0
    observers = {"000 SideslipBankObserver": out / "SideslipBankObserver.fmu",
                 "001 LateralIntervalObserver (midpoint)": out / "LateralIntervalObserver.fmu",
                 "SideslipKalmanFilter": out / "SideslipKalmanFilter_sedan.fmu"}
    for lowest, tag in ((15.0, "grid 15-63 m/s"), (2.5, "grid 2.5-63 m/s")):
        v = _vehicle(out / f"sedan_002_{int(lowest * 10)}.toml", lowest)
        assert latobs(["build", "SideslipFixedOrderEstimatorScheduled", "--vehicle", v, *build]) == 0
        observers[f"002 scheduled, {tag}"] = out / f"SideslipFixedOrderEstimatorScheduled_{Path(v).stem}.fmu"
    lr = load_vehicle("sedan").value("lr")
    print("| observer | manoeuvre | " + " | ".join(f"{v:g} m/s: observer / kinematic (ratio)" for v in SPEEDS) + " |")
    print("|---|---|" + "---|" * len(SPEEDS))
    for label, fmu in observers.items():
        for kind in ("sine", "turn"):
            cells = []
            for v in SPEEDS:
                res = harness.run(LowSpeed(speed=v, kind=kind), out / "CarPlant.fmu", {"o": fmu}, dt=DT,
                                  vehicle="sedan")
                t, bus, o = res.time, res.bus, res.observers["o"]
                est = (np.asarray(o["beta_hat"], float) if "beta_hat" in o
                       else 0.5 * (np.asarray(o["beta_lower"], float) + np.asarray(o["beta_upper"], float)))
                kin_now = lr * bus["yaw_rate"] / bus["vx"]
                kin = np.concatenate([kin_now[:1], kin_now[:-1]])
                m = t >= SETTLE
                e_o = math.sqrt(float(np.mean((est - bus["beta_cg"])[m] ** 2))) / DEG
                e_k = math.sqrt(float(np.mean((kin - bus["beta_cg"])[m] ** 2))) / DEG
                cells.append(f"{e_o:.3f} / {e_k:.3f} ({e_o / e_k:.2f})")
            print(f"| {label} | {kind} | " + " | ".join(cells) + " |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
