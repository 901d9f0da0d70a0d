"""Every latobs sideslip estimator on the real MBDS record against baselines tuned on the same data:
the car identified on the tuning part (t < 425 s; with the record's beta and with it withheld), every
car observer designed and built for it, each replayed over the whole record and scored on the
held-out part (t >= 425 s) beside the zero estimate, the open-loop bicycle with the identified
parameters, and the ridge regression fitted on the tuning part (``latobs.validation.baselines``).
The Kalman filter designed for the identified car is latobs's SideslipKalmanFilter, scored by its
prediction x(k|k-1) and its filtered estimate x(k|k). The table of the docs page "Which observer for
which job".

    python benchmarks/mbds_table.py [--out DIR]

Builds native FMUs for this machine in DIR (default a temporary folder); about 5 minutes.
"""
from __future__ import annotations

import argparse
import math
from pathlib import Path

import tomli_w

from latobs import __version__, packaging
from latobs.cbackend.toolchain import host_platform
from latobs.synthesis import design_file, designs
from latobs.synthesis import identification as ident
from latobs.validation import replay as rp

from _mbds import SPLIT, setup

OBSERVERS = ("SideslipFixedOrderEstimatorScheduled", "SideslipFixedOrderEstimator", "SideslipKalmanFilter",
             "LateralIntervalObserver")
BASELINES = ("zero", "bicycle", "regression")


def _deg(x) -> str:
    return "—" if x is None else f"{math.degrees(x):.3f}°"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args(argv)
    out, cols, base = setup(args.out, "mbds-table-")
    rows, base_rms = [], {}
    for use_beta in (True, False):
        tag = "with beta" if use_beta else "beta withheld"
        res = ident.identify(cols, base, SPLIT, use_beta=use_beta)
        name = "mycar" if use_beta else "mycar_nobeta"
        car = out / f"{name}.toml"
        car.write_text(tomli_w.dumps(ident.vehicle_document(res, base, name, "mbds", f"t < {SPLIT:g} s", __version__)))
        for obs in OBSERVERS:
            data = packaging.complete_runtime_data(designs.run(obs, str(car)))
            fmu = packaging.package_design(design_file.write(data, out), out, backend="c", platforms=[host_platform()])
            run = rp.drive(fmu, cols, label=obs)
            m = rp.score(run, split=SPLIT)["observers"][obs]
            est = m["estimates"].get("beta_hat")
            key = "beta_hat" if est else "beta"
            rms = est["after_split"]["rms"] if est else m["intervals"]["beta"]["midpoint"]["after_split"]["rms"]
            rows.append((tag, obs + ("" if est else " (interval midpoint)"), rms))
            filt = m["estimates"].get("beta_filtered")       # the Kalman filter's x(k|k)
            if filt is not None:
                rows.append((tag, obs + " (filtered, x(k|k))", filt["after_split"]["rms"]))
            for bl in BASELINES:
                e = m["baselines"].get(bl, {}).get(key)
                if e is not None:
                    base_rms.setdefault((tag, bl), e["after_split"]["rms"])
        print(f"identified ({tag}): Cf {res.Cf:.0f}, Cr {res.Cr:.0f} N/rad", flush=True)
    print(f"\nMBDS, held-out part (t >= {SPLIT:g} s), beta RMS; everything tuned on t < {SPLIT:g} s\n")
    print("| identified | estimator | held-out β RMS |\n|---|---|---|")
    for tag, obs, rms in rows:
        print(f"| {tag} | `{obs}` | {_deg(rms)} |")
    titles = {"zero": "baseline: β̂ = 0", "bicycle": "baseline: open-loop bicycle, identified parameters",
              "regression": "baseline: ridge regression fitted on t < 425 s"}
    for (tag, bl), rms in base_rms.items():
        print(f"| {tag} | {titles[bl]} | {_deg(rms)} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
