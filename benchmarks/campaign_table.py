"""Every observer against the baselines over the shipped robustness campaigns: per campaign, observer
and estimated quantity, the fraction of runs it beats every baseline and the distribution of its
RMS error over the best baseline's (the campaigns' ``versus_baselines``), the paper-faithful designs
beside latobs's defaults where both exist; the tables of the docs page "Which observer for which job".

    python benchmarks/campaign_table.py [--runs N] [--workers N] [--fmu-dir DIR] [--out DIR] [--campaign NAME ...]

Runs each campaign (``latobs.campaign_runner.run_campaign``, without figures; the FMUs are built
into ``--fmu-dir`` when missing) and prints Markdown. A campaign folder already in ``--out`` with the
same definition and FMUs is resumed, not run again.
"""
from __future__ import annotations

import argparse
import math
from pathlib import Path

from latobs.campaign_runner import run_campaign
from latobs.validation.metrics import quantity_of

P000 = ["SideslipBankObserver", "SideslipBankObserverTire", "SideslipBankObserverPaper",
        "SideslipBankObserverTirePaper"]
#: (campaign, observers: None for the campaign's own)
CAMPAIGNS = (("robustness-000", P000), ("robustness-000-flat", P000), ("robustness-001", None),
             ("robustness-002", None),
             ("robustness-003", None))
#: the error statistics given beside the ratio (headline RMS of these quantities, SI: rad)
RMS_DEG = ("beta", "bank_angle", "roll_angle")


def _pct(x) -> str:
    return "—" if x is None else f"{100 * x:.1f} %"


def _g(x) -> str:
    return "—" if x is None or (isinstance(x, float) and not math.isfinite(x)) else f"{x:.3g}"


def table(summary: dict) -> list[str]:
    """The Markdown rows of one campaign's ``versus_baselines`` (and each quantity's median RMS)."""
    out = [f"**`{summary['campaign']}`**: {summary['ok']} runs", "",
           "| observer | quantity | wins | ratio p50 | p95 | best baseline | median RMS | wins, valid samples |",
           "|---|---|---|---|---|---|---|---|"]
    for key, e in summary["versus_baselines"].items():
        q = e["quantity"]
        rms = (summary["metrics"].get(f"{key}.rms") or summary["metrics"].get(f"{key}.midpoint_rms") or {}).get("p50")
        unit = "°" if quantity_of(q) in RMS_DEG else ""
        rms_s = "—" if rms is None else (f"{math.degrees(rms):.3g}°" if unit else f"{rms:.3g}")
        best = max(e["best_baseline_runs"], key=e["best_baseline_runs"].get) if e["best_baseline_runs"] else "—"
        valid = (e.get("valid") or {}).get("win_fraction")
        out.append(f"| `{e['observer']}` | {q} | {_pct(e['win_fraction'])} | {_g(e['ratio'].get('p50'))} | "
                   f"{_g(e['ratio'].get('p95'))} | {best} | {rms_s} | {_pct(valid)} |")
    return out + [""]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=1000)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--fmu-dir", type=Path, default=Path("build"))
    ap.add_argument("--out", type=Path, default=Path("build"))
    ap.add_argument("--campaign", action="append", choices=[c for c, _ in CAMPAIGNS],
                    help="only this campaign (repeatable; default: all)")
    args = ap.parse_args(argv)
    lines = []
    for name, observers in CAMPAIGNS:
        if args.campaign and name not in args.campaign:
            continue
        s = run_campaign(name, observers=observers, runs=args.runs, out=args.out, fmu_dir=args.fmu_dir,
                         workers=args.workers, plots=False, progress=False)
        lines += table(s)
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
