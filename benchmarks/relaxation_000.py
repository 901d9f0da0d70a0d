"""How much of paper 000's level-road error is the tires' relaxation, which its eq. (1) lacks: the
default speed-mode observer (``SideslipBankObserver``, whose model now carries the relaxed axle
forces; the study that led there ran it on eq. (1), ``tire_relaxation=False``: 0.77 and 0.37) on
``robustness-000-flat`` with the nominal car (stiffness scale 1, peak friction 1), with CarPlant's
relaxation length as the vehicle has it and with ``sigma = 0`` (static tires, as in eq. 1). Sensors
and manoeuvres as drawn.

    python benchmarks/relaxation_000.py [--runs N] [--out DIR] [--fmu-dir DIR]

Prints β's win fraction and median ratio to the best baseline for both; the campaign files are
written into ``--out``.
"""
from __future__ import annotations

import argparse
import re
from pathlib import Path

NAME = "SideslipBankObserver"
BASE = "robustness-000-flat"


def variant(text: str, name: str, sigma: float | None) -> str:
    """The campaign's definition with the nominal car, and CarPlant's ``sigma`` fixed if given."""
    text = re.sub(r'^name = ".*"$', f'name = "{name}"', text, count=1, flags=re.M)
    text = re.sub(r"^mu = .*$", "mu = 1.0", text, count=1, flags=re.M)
    text = re.sub(r"^scale_f = .*$", "scale_f = 1.0", text, count=1, flags=re.M)
    text = re.sub(r"^scale_r = .*$", "scale_r = 1.0" + ("" if sigma is None else f"\nsigma = {sigma!r}"),
                  text, count=1, flags=re.M)
    return text


def main(argv=None) -> int:
    from latobs.campaign_runner import CAMPAIGN_DIR, run_campaign

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=200)
    ap.add_argument("--out", type=Path, default=Path("build/relaxation_000"))
    ap.add_argument("--fmu-dir", type=Path, default=None, help="default: --out")
    args = ap.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    text = (CAMPAIGN_DIR / f"{BASE}.toml").read_text()
    print("| CarPlant | β wins | ratio p50 |\n|---|---|---|")
    for label, name, sigma in (("nominal car, tire relaxation as the vehicle's", "flat-nominal", None),
                               ("nominal car, sigma = 0 (static tires)", "flat-nominal-static", 0.0)):
        spec = args.out / f"{name}.toml"
        spec.write_text(variant(text, name, sigma))
        s = run_campaign(str(spec), observers=[NAME], runs=args.runs, out=args.out, fmu_dir=args.fmu_dir or args.out,
                         plots=False, progress=False)
        beta = next(e for e in s["versus_baselines"].values() if e["quantity"] == "beta")
        print(f"| {label} | {100 * beta['win_fraction']:.1f} % | {beta['ratio'].get('p50'):.3f} |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
