"""Worker of paper 001's enclosure campaign (tests/runtime/test_lateral_interval_observer_enclosure.py): co-simulations of given
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


def run_steps(plant: str, observer: str, cases: list[tuple[int, float, float]], steps: list[float],
              duration: float, settle: float = 5.0) -> list[dict]:
    """One `random-manoeuvre` co-simulation of ``duration`` s per case and communication step h:
    the violations of every bound, the vy width after ``settle`` s (mean, max, the means over the
    middle and the last third of the run: no growth), or the error of a refused step."""
    import numpy as np

    from latobs.validation import get_scenario, harness, metrics

    rows = []
    for k, sf, sr in cases:
        for h in steps:
            row = {"seed": k, "scale_f": sf, "scale_r": sr, "h": h}
            try:
                res = harness.run(get_scenario("random-manoeuvre", seed=k, duration=duration), plant,
                                  {"I": observer}, dt=h,
                                  plant_parameters={"linear_tires": 1.0, "scale_f": sf, "scale_r": sr})
            except harness.CoSimulationError as exc:
                rows.append({**row, "refused": str(exc)})
                continue
            m = metrics.compute(res, settle_time=0.0)["observers"]["I"]["intervals"]
            ob = res.observers["I"]
            t = np.asarray(res.time, float)
            w = np.asarray(ob["vy_upper"], float) - np.asarray(ob["vy_lower"], float)
            after = t >= settle
            mid = (t >= duration / 3) & (t < 2 * duration / 3)
            last = t >= 2 * duration / 3
            rows.append({**row, "refused": None, "violations": sum(m[s]["enclosure_violations"] for s in SIGNALS),
                         "vy_width_mean": float(np.mean(w[after])), "vy_width_max": float(np.max(w[after])),
                         "vy_width_mid": float(np.mean(w[mid])), "vy_width_last": float(np.mean(w[last])),
                         "vy_width_max_before": float(np.max(w[after & ~last])),
                         "vy_width_max_last": float(np.max(w[last]))})
    return rows


def step_table(plant: str, observer: str, runs: int, box: tuple[float, float], steps: list[float],
               duration: float, workers: int = 2) -> tuple[dict, list[dict]]:
    """The campaign's plants (seed k, stiffness scales drawn in the box as in test_enclosure_001's
    ``campaign``) at every step: {h: summary} and the rows. A summary: runs, refused, violations,
    the mean vy width after settling, its largest value, and growth: the largest ratio of a run's
    largest vy width over the last third of the run to its largest before (after settling), and
    the median ratio of its mean widths over the last and the middle third (the manoeuvre changes
    over a run, so a ratio near 1, not exactly 1, is what a stable observer gives)."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    import numpy as np

    rng = np.random.default_rng(2026)
    cases = [(k, *(1.0 + rng.uniform(-b, b) for b in box)) for k in range(runs)]
    chunks = [cases[i::workers] for i in range(workers)]
    with ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn")) as pool:
        parts = list(pool.map(run_steps, [plant] * workers, [observer] * workers, chunks, [steps] * workers,
                              [duration] * workers))
    rows = [r for part in parts for r in part]
    table = {}
    for h in steps:
        ok = [r for r in rows if r["h"] == h and r["refused"] is None]
        table[h] = {"runs": sum(r["h"] == h for r in rows), "refused": sum(r["h"] == h and r["refused"] is not None
                                                                          for r in rows)}
        if ok:
            table[h].update(violations=sum(r["violations"] for r in ok),
                            vy_width_mean=float(np.mean([r["vy_width_mean"] for r in ok])),
                            vy_width_max=max(r["vy_width_max"] for r in ok),
                            growth=max(r["vy_width_max_last"] / r["vy_width_max_before"] for r in ok),
                            growth_median=float(np.median([r["vy_width_last"] / r["vy_width_mid"] for r in ok])))
    return table, rows


if __name__ == "__main__":     # python tests/enclosure_runs.py PLANT.fmu OBSERVER.fmu RUNS DURATION
    import json
    import sys

    table, _ = step_table(sys.argv[1], sys.argv[2], int(sys.argv[3]), (0.2, 0.2),
                          [0.005, 0.02, 0.05, 0.1, 0.2], float(sys.argv[4]))
    print("| h (ms) | runs | refused | violations | mean vy width (m/s) | max vy width after 5 s (m/s) | "
          "growth: max (largest width, last third / before) | growth: median (mean width, last / middle third) |")
    print("|---|---|---|---|---|---|---|---|")
    for h, s in table.items():
        print(f"| {h * 1e3:g} | {s['runs']} | {s['refused']} | {s.get('violations', '-')} | "
              + " | ".join(f"{s[k]:.4f}" if k in s else "-"
                           for k in ("vy_width_mean", "vy_width_max", "growth", "growth_median")) + " |")
    print(json.dumps({str(h): s for h, s in table.items()}))
