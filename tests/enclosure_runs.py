"""Worker of paper 001's enclosure campaign (tests/test_enclosure_001.py): co-simulations of given
seeds and stiffness scales, in a process of its own (the campaign spreads them over the cores)."""
from __future__ import annotations

SIGNALS = ("vy", "beta", "yaw_rate", "Fyf", "Fyr")


def run_cases(plant: str, observer: str, cases: list[tuple[int, float, float]]) -> list[dict]:
    """One 5 s `random-manoeuvre` co-simulation per (seed, scale_f, scale_r), linear tires."""
    from latobs.validation import get_scenario, harness, metrics

    rows = []
    for k, sf, sr in cases:
        res = harness.run(get_scenario("random-manoeuvre", seed=k, duration=5.0), plant, {"I": observer},
                          plant_parameters={"linear_tires": 1.0, "scale_f": sf, "scale_r": sr})
        m = metrics.compute(res, settle_time=0.0)["observers"]["I"]["intervals"]
        rows.append({"seed": k, "scale_f": sf, "scale_r": sr,
                     **{f"{s}_violations": m[s]["enclosure_violations"] for s in SIGNALS},
                     **{f"{s}_width": m[s]["mean_width"] for s in SIGNALS},
                     "vmin": float(res.bus["vx"].min()), "vmax": float(res.bus["vx"].max()),
                     "modes": sorted(set(int(x) for x in res.observers["I"]["mode"]))})
    return rows
