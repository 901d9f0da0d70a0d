"""Replay a recorded CSV through an observer FMU and score it against the reference columns.

What it shows: `latobs replay` from Python (``latobs.pipeline.replay``). A CSV with a header row,
a uniformly sampled time column ``t`` (s) and columns named like the FMU's inputs (SI units,
angles in rad) drives the observer FMU (built into --fmu-dir if missing); every output ``X_hat``
is scored against a column ``X`` when the file has one, beside the zero estimate and the open-loop
bicycle-model baseline. The default CSV is the bundled MBDS real-vehicle record (``mbds``,
columns t, delta, vx, vy, yaw_rate, ay, ax, beta, 100 Hz, 550 s; MIT licensed).

Run it (the first run builds the FMU, a few seconds):

    python examples/replay_csv.py                                   # the whole MBDS record
    python examples/replay_csv.py --seconds 30                      # only its first 30 s
    python examples/replay_csv.py my_drive.csv --observer SideslipFixedOrderEstimatorScheduled

--seconds N writes the first N seconds of the CSV to OUT/<stem>_first<N>s.csv and replays that.
Results: OUT/replay_<csv stem>_<FMU name>/metrics.json (and PNG plots with --plots).
"""
from __future__ import annotations

import argparse
import csv
import gzip
import math
import sys
from pathlib import Path

from latobs.pipeline import replay
from latobs.validation.replay import csv_stem, resolve_csv


def first_seconds(src: Path, seconds: float, out_dir: Path) -> Path:
    """A copy of the CSV ``src`` (.csv or .csv.gz) with the rows of its first ``seconds`` s."""
    opener = gzip.open if src.suffix == ".gz" else open
    stem = src.name.removesuffix(".gz").removesuffix(".csv")
    dst = out_dir / f"{stem}_first{seconds:g}s.csv"
    out_dir.mkdir(parents=True, exist_ok=True)
    with opener(src, "rt", newline="") as f, open(dst, "w", newline="") as g:
        rows = csv.reader(f)
        header = next(rows)
        w = csv.writer(g)
        w.writerow(header)
        it = header.index("t")
        t0 = None
        for row in rows:
            t0 = float(row[it]) if t0 is None else t0
            if float(row[it]) - t0 > seconds:
                break
            w.writerow(row)
    return dst


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("csv", nargs="?", default="mbds",
                   help="a .csv/.csv.gz file, or 'mbds' (default): the bundled record")
    p.add_argument("--observer", default="SideslipKalmanFilter",
                   help="observer FMU name (default SideslipKalmanFilter: inputs delta, vx, yaw_rate, ay)")
    p.add_argument("--vehicle", default=None, help="vehicle set of the FMU (default: the design's own)")
    p.add_argument("--fmu-dir", default="build", help="where the FMU is, built if missing (default build)")
    p.add_argument("--out", default="build", help="where the results go (default build)")
    p.add_argument("--seconds", type=float, default=None, help="replay only the first SECONDS s of the CSV")
    p.add_argument("--plots", action="store_true", help="also write the PNG plots")
    args = p.parse_args(argv)

    path = resolve_csv(args.csv)
    if args.seconds is not None:
        path = first_seconds(path, args.seconds, Path(args.out))
        print(f"replaying the first {args.seconds:g} s: {path}")
    m = replay(path, args.observer, vehicle=args.vehicle, out=Path(args.out), fmu_dir=Path(args.fmu_dir),
               plots=args.plots, quiet=True)
    print(f"{m['label']} on {Path(m['csv']).name}: {m['n_samples']} samples, {m['duration_s']:.1f} s, "
          f"dt {m['dt_s']:g} s, inputs {', '.join(m['inputs'])}")
    obs = m["observers"][m["label"]]
    if m["nothing_scored"]:
        print("nothing scored: the CSV has no reference column for the observer's outputs")
    for name, e in obs["estimates"].items():
        deg = " ({:.3g} deg)" if e["unit"] == "rad" else ""       # angles are in rad: also in deg
        segs = ", ".join(f"{seg} {e[seg]['rms']:.4g}" + deg.format(math.degrees(e[seg]["rms"]))
                         for seg in m["segments"] if e.get(seg))
        print(f"{name} vs {e['truth']}: RMS error ({e['unit']}) {segs}")
        s = obs["baselines"]["summary"].get(name)
        if s and s["best_baseline"] is not None:
            good = s.get("baselines_as_good") or []
            print(f"  best baseline ({s['segment']}): {s['best_baseline']} {s['best_baseline_rms']:.4g}"
                  f"{'  (as good as the observer or better: ' + ', '.join(good) + ')' if good else ''}")
        for base, why in ((s or {}).get("not_computed") or {}).items():
            print(f"  {base} baseline not computed: {why}")
    for name, e in obs["intervals"].items():
        print(f"{name} within [{e['lower']}, {e['upper']}]: {100 * e['all']['enclosure_rate']:.1f} % of samples")
    metrics = Path(args.out) / f"replay_{csv_stem(path)}_{m['label']}" / "metrics.json"
    print(f"metrics: {metrics}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
