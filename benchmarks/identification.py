"""``latobs identify`` on synthetic truth: CarPlant drives (paper 002's band-limited random steering
at 30 km/h, 40 s at 100 Hz, Magic Formula tires), each with its stiffnesses scaled by factors drawn
in 0.8 ... 1.2 of ``sedan``'s and the sensors of ``latobs validate --noise`` (plus 0.05 m/s^2 on
ay), identified on their first 60 % with ``sedan`` as the base vehicle. Prints one line per drive
and the counts: Cf and Cr within 5 % of the truth, the truth inside the reported interval, the yaw
inertia (sedan's) identified and its error.

    python benchmarks/identification.py [RUNS] [CARPLANT.fmu]

(default 50 runs; the CarPlant FMU of ``latobs build CarPlant``, ``build/CarPlant.fmu``). The test
``tests/synthesis/test_identification.py`` runs one such drive.
"""
from __future__ import annotations

import sys

import numpy as np

from latobs import pipeline
from latobs.synthesis import identification as ident
from latobs.synthesis.params import load_vehicle
from latobs.validation import get_scenario
from latobs.validation.harness import run


def main(argv: list[str]) -> int:
    runs = int(argv[0]) if argv else 50
    plant = argv[1] if len(argv) > 1 else "build/CarPlant.fmu"
    base = load_vehicle("sedan")
    noise = {**pipeline.DEFAULT_NOISE, "ay": (0.05, 0.0)}
    rng = np.random.default_rng(1)
    within = inside = 0
    iz_errors: list = []
    for k in range(runs):
        sf, sr = rng.uniform(0.8, 1.2, 2)
        r = run(get_scenario("w1-steer", seed=k, duration=40.0), plant, {}, dt=0.01, vehicle="sedan",
                plant_parameters={"scale_f": sf, "scale_r": sr})
        g = np.random.default_rng(100 + k)
        cols = {"t": r.time, "beta": r.bus["beta_cg"]}
        for s in ("delta", "vx", "yaw_rate", "ay"):
            std, bias = noise.get(s, (0.0, 0.0))
            cols[s] = r.bus[s] + bias + std * g.standard_normal(len(r.time))
        res = ident.identify(cols, base, float(r.time[0] + 0.6 * (r.time[-1] - r.time[0])))
        tf, tr = sf * base.value("Cf"), sr * base.value("Cr")
        ef, er = res.Cf / tf - 1, res.Cr / tr - 1
        ok = abs(ef) < 0.05 and abs(er) < 0.05
        ins = res.Cf_interval[0] <= tf <= res.Cf_interval[1] and res.Cr_interval[0] <= tr <= res.Cr_interval[1]
        within += ok
        inside += ins
        iz = (f"Iz {100 * (res.Iz / base.value('Iz') - 1):+.2f} %" if res.Iz is not None
              else "Iz not identified")
        iz_errors.append(None if res.Iz is None else res.Iz / base.value("Iz") - 1)
        print(f"{k:3d}: scales {sf:.3f} {sr:.3f}: Cf {100 * ef:+.2f} %, Cr {100 * er:+.2f} %, truth "
              f"{'inside' if ins else 'outside'} the interval; {iz}", flush=True)
    print(f"Cf and Cr within 5 %: {within}/{runs}; the truth inside the interval: {inside}/{runs}")
    got = [e for e in iz_errors if e is not None]
    print(f"Iz identified in {len(got)}/{runs}" + (f", error {100 * min(got):+.2f} ... {100 * max(got):+.2f} %"
                                                    if got else ""))
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
