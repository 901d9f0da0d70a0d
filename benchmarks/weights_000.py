"""Paper 000's speed-mode design (``SideslipBankObserver``) with other weights of its model-error
channel, against the baselines on banked and level roads: for each variant, β's win fraction and
median ratio to the best baseline and the bank angle's median RMS over ``robustness-000`` and
``robustness-000-flat`` (the campaigns' ``versus_baselines``).

    python benchmarks/weights_000.py [--runs N] [--seed S] [--out DIR] VARIANT=JSON ...

``VARIANT=JSON``: a name and the design options that differ from the catalogue's, e.g.
``w4='{"model_error_weights": [4, 1, 1], "gamma_ref": 0.15}'``; ``base={}`` is the default design.
A campaign builds the catalogue's FMUs: this script gives the catalogue entry the variant's options
in its own process (builds in this process, ``LATOBS_JOBS=1``, and no cache: a variant's design has
the default's identity). ``--seed``: the campaigns' seed (default: theirs); choose weights on one
seed and report them on another.
"""
from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

NAME = "SideslipBankObserver"
CAMPAIGNS = ("robustness-000", "robustness-000-flat")


def use_options(overrides: dict) -> None:
    """The catalogue's entry for NAME (and the design registry built from it) with ``overrides``."""
    from latobs import catalogue
    from latobs.synthesis import designs

    entry = catalogue.get(NAME)
    base = use_options.__dict__.setdefault("base", dict(entry.option_args))
    object.__setattr__(entry, "option_args", tuple({**base, **overrides}.items()))   # frozen dataclass
    designs.DESIGNS[NAME] = designs._entry(entry)


def scores(overrides: dict, runs: int, seed: int | None, folder: Path) -> dict:
    from latobs.campaign_runner import run_campaign

    use_options(overrides)
    out = {}
    for camp in CAMPAIGNS:
        s = run_campaign(camp, observers=[NAME], runs=runs, out=folder, fmu_dir=folder, plots=False,
                         progress=False, fresh=True, seed=seed)
        beta = next(e for e in s["versus_baselines"].values() if e["quantity"] == "beta")
        bank = s["metrics"].get(f"{NAME}.bank_angle.rms", {}).get("p50")
        out[camp] = (beta["win_fraction"], beta["ratio"].get("p50"), bank)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("variants", nargs="+", help="NAME=JSON design options")
    ap.add_argument("--runs", type=int, default=200)
    ap.add_argument("--seed", type=int, default=None)
    ap.add_argument("--out", type=Path, default=Path("build/weights_000"))
    args = ap.parse_args(argv)
    os.environ["LATOBS_JOBS"] = "1"
    os.environ["LATOBS_NO_CACHE"] = "1"
    print("| variant | options | " + " | ".join(f"{c}: β wins, ratio p50, bank RMS p50 (rad)" for c in CAMPAIGNS) + " |")
    print("|---|---|" + "---|" * len(CAMPAIGNS))
    for spec in args.variants:
        tag, _, text = spec.partition("=")
        overrides = {k: tuple(v) if isinstance(v, list) else v for k, v in json.loads(text or "{}").items()}
        folder = args.out / tag
        folder.mkdir(parents=True, exist_ok=True)
        s = scores(overrides, args.runs, args.seed, folder)
        cells = [f"{w:.1%}, {r:.3f}, {b:.4f}" for w, r, b in (s[c] for c in CAMPAIGNS)]
        print(f"| {tag} | `{json.dumps(json.loads(text or '{}'))}` | " + " | ".join(cells) + " |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
