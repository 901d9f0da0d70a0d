"""Every shipped car x every car observer with the catalogue's own options: certified, n/a (the
missing parameter or range named), infeasible (the LMI named) or refused (the failing checks
named), and the seconds of design + certificate. Prints a Markdown table (the README's).

    python benchmarks/vehicle_matrix.py [VEHICLE ...]

The test ``tests/synthesis/test_vehicle_matrix.py`` walks the same matrix (paper 002 on a coarser grid).
"""
from __future__ import annotations

import sys

from latobs.synthesis import designs
from latobs.synthesis.params import load_vehicle, vehicle_names


def main(argv: list[str]) -> int:
    cars = argv or [v for v in vehicle_names() if load_vehicle(v).kind == "car"]
    observers = [n for n, e in designs.DESIGNS.items() if e.plant == "CarPlant"]
    print("| vehicle | observer | result | design + certificate (s) |")
    print("|---|---|---|---|")
    for car in cars:
        for obs in observers:
            out = designs.attempt(obs, car)
            why = f" ({out.detail})" if out.detail else ""
            print(f"| {car} | {obs} | {out.status}{why} | {out.seconds:.1f} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
