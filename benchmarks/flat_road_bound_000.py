"""How well one fixed estimator built on paper 000's measurements can beat the baselines on banked
and level roads: a bound for the campaigns ``robustness-000`` and ``robustness-000-flat``.

A ridge regression of the true sideslip is fitted on the runs of each campaign. Each run draws a car
with its cornering stiffnesses within ±20 % of the design's, a manoeuvre and sensors. The features are
causally filtered signals that the observer receives: the steering angle, speed, yaw rate, roll angle
and roll rate, their products and quotients from the bicycle's steady relations, and each low-passed at
0.05 to 2 s (the filter bank of ``latobs.validation.baselines.regression_features``, with the roll
signals added). It is fitted on the TRUE sideslip of the first half of the runs (of the level-road
campaign alone, then of both) and scored on the other half against each run's best baseline, as the
campaigns score the observer. It is one fixed estimator tuned with the truth over the distribution it is
scored on: a bound on what the signals allow, not a rival. The script prints it with ``ay`` among the
features as well; paper 000's observer does not read that sensor.

    python benchmarks/flat_road_bound_000.py [--runs N] [--out DIR] [--fmu-dir DIR]
"""
from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np

NAME = "SideslipBankObserver"
CAMPAIGNS = ("robustness-000", "robustness-000-flat")
OBSERVER_SIGNALS = ("delta", "vx", "yaw_rate", "roll_angle", "roll_rate")
TAUS_S = (0.0, 0.05, 0.2, 0.5, 2.0)


def features(s: dict[str, np.ndarray], dt: float, with_ay: bool) -> np.ndarray:
    """Causal features of the measured signals (past and present samples only)."""
    from scipy.signal import lfilter

    d, v, r, phi, p = (np.asarray(s[k], float) for k in OBSERVER_SIGNALS)
    ve = np.maximum(v, 1.0)
    base = [d, r, phi, p, v, r * v, r / ve, d * v, d / ve, phi / ve, phi * v, p / ve, 1.0 / ve]
    if with_ay:
        ay = np.asarray(s["ay"], float)
        base += [ay, ay / ve, ay - r * v]
    cols = []
    for tau in TAUS_S:
        a = 1.0 if tau == 0.0 else -math.expm1(-dt / tau)
        for x in base:
            cols.append(x if tau == 0.0 else lfilter([a], [1.0, a - 1.0], x, zi=[(1.0 - a) * x[0]])[0])
    return np.column_stack(cols)


def simulate(campaign: str, runs: int, out: Path, fmu_dir: Path) -> list[dict]:
    """The campaign's runs again, each with the signals the observer received and the truth."""
    from latobs.campaign_runner import fmu_refs, resolve, run_campaign
    from latobs.validation import campaign_run as cr
    from latobs.validation import harness

    s = run_campaign(campaign, observers=[NAME], runs=runs, out=out, fmu_dir=fmu_dir, plots=False,
                     progress=False, fresh=True)
    rows = [json.loads(line) for line in (Path(s["folder"]) / "runs.jsonl").read_text().splitlines()]
    c = resolve(campaign, [NAME])
    paths = {ref.role: ref.path for ref in fmu_refs(c, fmu_dir)}
    runs_out = []
    for row in (r for r in rows if r["status"] == "ok"):
        sc, kwargs = cr.cosim_setup(c, row["params"], row["seed"])
        res = harness.run(sc, paths["plant"], {NAME: paths[NAME]}, **kwargs)
        t = np.asarray(res.time, float)
        m = row["metrics"]
        runs_out.append({"drive": {**res.bus, **(res.measured or {})}, "dt": float(np.median(np.diff(t))),
                         "beta": np.asarray(res.bus["beta"], float), "after": t >= cr.settle_time(c, sc) - 1e-12,
                         # the run's best baseline's β RMS, and the observer's ratio to it
                         "best": m[f"{NAME}.beta.rms"] / m[f"{NAME}.beta.ratio"], "obs_ratio": m[f"{NAME}.beta.ratio"]})
    return runs_out


def score(test: list[dict], w, b, with_ay: bool) -> np.ndarray:
    ratios = []
    for r in test:
        est = features(r["drive"], r["dt"], with_ay) @ w + b
        ratios.append(float(np.sqrt(np.mean((est - r["beta"])[r["after"]] ** 2))) / r["best"])
    return np.array(ratios)


def main(argv=None) -> int:
    from latobs.validation.baselines import ridge_fit

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=400)
    ap.add_argument("--out", type=Path, default=Path("build/flat_road_bound_000"))
    ap.add_argument("--fmu-dir", type=Path, default=None)
    args = ap.parse_args(argv)
    fmu_dir = args.fmu_dir or args.out
    runs = {c: simulate(c, args.runs, args.out, fmu_dir) for c in CAMPAIGNS}
    fit = {c: r[: len(r) // 2] for c, r in runs.items()}
    test = {c: r[len(r) // 2:] for c, r in runs.items()}
    print(f"{args.runs} runs of each campaign; the regressions fitted on the true β of the first half, scored on "
          f"the other half (the observer's ratios on that half)\n")
    print("| estimator | fitted on | features | " + " | ".join(f"{c}: β wins, ratio p50" for c in CAMPAIGNS) + " |")
    print("|---|---|---|" + "---|" * len(CAMPAIGNS))
    obs = {c: np.array([r["obs_ratio"] for r in test[c]]) for c in CAMPAIGNS}
    print(f"| `{NAME}` (the default design) | — | — | "
          + " | ".join(f"{100 * np.mean(obs[c] < 1):.1f} %, {np.median(obs[c]):.3g}" for c in CAMPAIGNS) + " |")
    for fitted_on in (("robustness-000-flat",), CAMPAIGNS):
        for with_ay in (False, True):
            X = np.vstack([features(r["drive"], r["dt"], with_ay)[r["after"]] for c in fitted_on for r in fit[c]])
            y = np.concatenate([r["beta"][r["after"]] for c in fitted_on for r in fit[c]])
            w, b, alpha, _ = ridge_fit(X, y)
            res = {c: score(test[c], w, b, with_ay) for c in CAMPAIGNS}
            label = "the observer's signals" + (" and ay" if with_ay else "")
            print(f"| pooled ridge regression on the truth (α = {alpha:.3g}) | {' and '.join(fitted_on)} | {label}, "
                  f"{X.shape[1]} | " + " | ".join(f"{100 * np.mean(res[c] < 1):.1f} %, {np.median(res[c]):.3g}"
                                                   for c in CAMPAIGNS) + " |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
