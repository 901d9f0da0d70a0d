"""Where paper 000's speed-mode observer (``SideslipBankObserver``, the default design) wins and
loses against the open-loop bicycle on a level road: ``robustness-000-flat``, the fraction of runs
where β beats the best baseline by quartile of each drawn quantity (the stiffness mismatch
|scale - 1|, the steering amplitude, the friction), and the correlation of each estimate's β RMS
(divided by the zero baseline's, the run's excitation) with the drawn quantities.

    python benchmarks/flat_road_000.py [--runs N] [--out DIR] [--fmu-dir DIR]

The FMUs are built into ``--fmu-dir`` (default: the output folder) when missing.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

NAME = "SideslipBankObserver"
CAMPAIGN = "robustness-000-flat"
#: (label, the run's parameter, transform)
DRAWN = [("front stiffness mismatch, abs(scale_f - 1)", "plant.scale_f", lambda x: np.abs(x - 1)),
         ("rear stiffness mismatch, abs(scale_r - 1)", "plant.scale_r", lambda x: np.abs(x - 1)),
         ("steering amplitude, steer_scale", "signals.steer_scale", lambda x: x),
         ("peak friction, mu", "plant.mu", lambda x: x)]


def main(argv=None) -> int:
    from latobs.campaign_runner import run_campaign

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=1000)
    ap.add_argument("--out", type=Path, default=Path("build/flat_road_000"))
    ap.add_argument("--fmu-dir", type=Path, default=None)
    args = ap.parse_args(argv)
    s = run_campaign(CAMPAIGN, observers=[NAME], runs=args.runs, out=args.out, fmu_dir=args.fmu_dir or args.out,
                     plots=False, progress=False, fresh=True)
    rows = [json.loads(line) for line in (Path(s["folder"]) / "runs.jsonl").read_text().splitlines()]
    rows = [r for r in rows if r["status"] == "ok"]
    param = {k: np.array([r["params"][k] for r in rows]) for k in rows[0]["params"]}
    metric = {k: np.array([r["metrics"][k] for r in rows]) for k in rows[0]["metrics"]}
    ratio = metric[f"{NAME}.beta.ratio"]
    print(f"{CAMPAIGN}, {len(rows)} runs: β wins in {100 * np.mean(ratio < 1):.1f} %, ratio p50 "
          f"{np.median(ratio):.3g}\n")
    print("| drawn quantity | β wins by its quartile (lowest first) | ratio p50 by quartile |")
    print("|---|---|---|")
    for label, key, f in DRAWN:
        x = f(param[key])
        edges = np.quantile(x, [0.0, 0.25, 0.5, 0.75, 1.0])
        bins = [(x >= lo) & (x <= hi) for lo, hi in zip(edges[:-1], edges[1:])]
        wins = ", ".join(f"{100 * np.mean(ratio[b] < 1):.0f} %" for b in bins)
        med = ", ".join(f"{np.median(ratio[b]):.2f}" for b in bins)
        print(f"| {label} | {wins} | {med} |")
    zero = metric[f"{NAME}.beta.rms_zero"]
    rel = {"observer": metric[f"{NAME}.beta.rms"] / zero, "bicycle": metric[f"{NAME}.beta.rms_bicycle"] / zero}
    print("\n| β RMS ÷ the zero baseline's | p50 | correlation with scale_f | with scale_r | with mu | with "
          "steer_scale |")
    print("|---|---|---|---|---|---|")
    for who, y in rel.items():
        corr = [np.corrcoef(param[k], y)[0, 1] for k in ("plant.scale_f", "plant.scale_r", "plant.mu",
                                                          "signals.steer_scale")]
        print(f"| {who} | {np.median(y):.2f} | " + " | ".join(f"{c:+.2f}" for c in corr) + " |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
