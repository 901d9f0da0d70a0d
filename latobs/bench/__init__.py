"""``latobs bench``: what latobs costs, measured side by side in one run (build, LMI solves, one
FMU step per backend, coupled runs, a 1000-run campaign, the demo, scaling), each figure beside a reference measured in the same
process. :mod:`.measure` and :mod:`.lmi` measure, :mod:`.tables` renders the figures as Markdown;
``latobs bench --markdown`` prints the documentation's speed page.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from ..synthesis import designs  # the catalogue only (no solver stack)
from .lmi import LMI_TIMEOUT, lmi_row, lmi_row_isolated, lmi_section
from .measure import (BACKEND_LABEL, BACKENDS, CAMPAIGN, CAMPAIGN_RUNS, DT, LENGTHS, SCALING_OBSERVERS_DURATION,
                      SCALING_SCENARIO, SOLVER_LABEL, SOLVERS, Pairing, _fmu_pairing, _jsonable, _kind, _numpy_reference,
                      _progress, bus, build_time, campaign_time, coupled, demo_time, coupled_in_fresh_process, coupled_section,
                      ensure_fmus, fmu_data, fmu_names, fmu_section, machine, paper_000_observers, pairings, plant_artefact, runtime_step_time,
                      scaling_section)
from .tables import (_lmi_cell, build_table, campaign_table, coupled_table, demo_table, fmu_table, lmi_table, machine_statement, markdown,
                     scaling_table, table)

__all__ = ["BACKENDS", "BACKEND_LABEL", "DT", "LENGTHS", "LMI_TIMEOUT", "SCALING_OBSERVERS_DURATION",
           "SCALING_SCENARIO", "SOLVERS", "SOLVER_LABEL", "Pairing", "bench", "build_table", "build_time", "bus",
           "campaign_table", "campaign_time", "coupled", "demo_time", "coupled_in_fresh_process", "coupled_section",
           "coupled_table", "demo_table", "ensure_fmus", "fmu_data",
           "fmu_names", "fmu_section", "fmu_table", "lmi_row", "lmi_row_isolated", "lmi_section", "lmi_table",
           "machine", "machine_statement", "main", "markdown", "paper_000_observers", "pairings", "parser",
           "plant_artefact", "runtime_step_time", "scaling_section", "scaling_table", "table",
           "_fmu_pairing", "_jsonable", "_kind", "_lmi_cell"]


def bench(fmu_dir: Path, n: int = 3000, repeats: int = 3, *, backends=BACKENDS, lmi: bool = True,
          build: bool = True, fmus: bool = True, coupled_runs: bool = True, scaling: bool = True,
          campaign: bool = True, demo: bool = True, lmi_designs: list[str] | None = None, solvers=SOLVERS, scs_max_iters: int | None = None,
          lmi_timeout: float | None = LMI_TIMEOUT) -> dict:
    """Every section (the module docstring); returns the figures (``--json`` writes them)."""
    from ..synthesis import lmi as lmi_mod

    fmu_dir = Path(fmu_dir)
    names = fmu_names()
    out: dict = {"date": time.strftime("%Y-%m-%d"), "machine": machine(), "n_steps": n, "repeats": repeats, "dt": DT,
                 "backends": list(backends), "pairings": [dict(p.__dict__, plant_fmu=p.plant_fmu) for p in pairings()],
                 "build": None, "lmi": None, "fmus": None, "coupled": None, "scaling": None, "campaign": None, "demo": None,
                 "unavailable": {}}
    folders = {b: fmu_dir / b for b in backends}
    if build:
        out["build"] = []
        for b in backends:
            _progress(f"latobs build --backend {b} in a fresh process")
            out["build"].append(build_time(b, fill=folders[b]))
    if demo:
        _progress("latobs demo in a fresh process, cold then warm")
        out["demo"] = demo_time()
    if lmi:
        out["lmi"] = {"solvers": list(solvers), "timeout_seconds": lmi_timeout,
                      "settings": {s: {**lmi_mod.SOLVERS[s], **({"max_iters": scs_max_iters}
                                                                if s == "SCS" and scs_max_iters else {})}
                                   for s in solvers},
                      "rows": lmi_section(lmi_designs or list(designs.DESIGNS), solvers, scs_max_iters,
                                          lmi_timeout)}
    if fmus or coupled_runs or scaling:
        for b in backends:
            out["unavailable"][b] = ensure_fmus(folders[b], b, names)
    if fmus:
        out["fmus"] = fmu_section(folders, names, n, repeats, out["unavailable"])
        out["numpy_reference"] = _numpy_reference(n)
    if coupled_runs:
        out["coupled"] = coupled_section(folders, max(1, repeats - 1))
    if campaign:
        if "c" not in folders:
            out["campaign"] = {"error": "the campaign is timed with the native FMUs (--backends c)"}
        else:
            _progress(f"latobs campaign {CAMPAIGN} --runs {CAMPAIGN_RUNS} in a fresh process")
            out["campaign"] = campaign_time(folders["c"])
    if scaling:
        need = ["CarPlant", *paper_000_observers()]
        backend = next((b for b in ("c", "python") if b in folders
                        and all((folders[b] / f"{x}.fmu").is_file() for x in need)), None)
        if backend is None:
            out["scaling"] = {"error": f"no backend folder holds {', '.join(need)}"}
        else:
            out["scaling"] = scaling_section(folders[backend], backend, repeats)
    return out


def parser() -> argparse.ArgumentParser:
    from ..synthesis.lmi import SCS_SETTINGS   # no solver stack: constants only

    p = argparse.ArgumentParser(prog="latobs bench", description=__doc__.split("\n\n")[0].replace("``", "`"))
    p.add_argument("--fmu-dir", default="build/bench",
                   help="FMUs to measure, per backend in FMU_DIR/python and FMU_DIR/c (built there if missing)")
    p.add_argument("--steps", type=int, default=3000, help="communication steps per FMU measurement (at most the "
                   "pairing's scenario; default 3000)")
    p.add_argument("--repeats", type=int, default=3, help="fresh instances / runs per figure, the best is kept "
                   "(default 3)")
    p.add_argument("--json", dest="json_file", help="also write every figure to this JSON file")
    p.add_argument("--markdown", action="store_true",
                   help="print the figures as the documentation's speed page (Markdown: the machine and its load, "
                        "then a heading and a table per section; no date)")
    p.add_argument("--from-json", dest="from_json", metavar="FILE",
                   help="measure nothing: print the figures of an earlier --json FILE")
    p.add_argument("--backends", default=",".join(BACKENDS),
                   help="comma-separated backends to measure (default python,c)")
    p.add_argument("--designs", default=None,
                   help="comma-separated designs of the LMI section (default: every design)")
    p.add_argument("--scs-max-iters", type=int, default=None,
                   help=f"SCS's iteration cap in the LMI section (default {SCS_SETTINGS['max_iters']}, "
                        "latobs.synthesis.lmi.SCS_SETTINGS)")
    p.add_argument("--lmi-timeout", type=float, default=LMI_TIMEOUT,
                   help=f"s, cap of one design x solver in the LMI section (a fresh process, stopped at the cap; "
                        f"default {LMI_TIMEOUT:g})")
    p.add_argument("--skip-build", action="store_true", help="no whole `latobs build` timing")
    p.add_argument("--skip-lmi", action="store_true", help="no LMI solver comparison")
    p.add_argument("--skip-fmus", action="store_true", help="no per-FMU step timing")
    p.add_argument("--skip-coupled", action="store_true", help="no coupled run per pairing")
    p.add_argument("--skip-scaling", action="store_true", help="no scaling with scenario length and observers")
    p.add_argument("--skip-demo", action="store_true", help="no timing of `latobs demo` (cold and warm)")
    p.add_argument("--skip-campaign", action="store_true",
                   help="no timing of a 1000-run campaign (robustness-000 on 2 local workers)")
    return p


def main(argv: list[str] | None = None) -> int:
    a = parser().parse_args(argv)
    if a.from_json:
        try:
            r = json.loads(Path(a.from_json).read_text(encoding="utf-8"))
        except (OSError, ValueError) as exc:
            r = exc
        if not isinstance(r, dict):        # a user error: one line, exit 2
            why = f": {r}" if isinstance(r, Exception) else ""
            print(f"latobs bench: error: --from-json: {a.from_json} is not the JSON of `latobs bench --json`{why}",
                  file=sys.stderr)
            return 2
        print(markdown(r) if a.markdown else table(r))
        return 0
    backends = [b.strip() for b in a.backends.split(",") if b.strip()]
    bad = [b for b in backends if b not in BACKENDS]
    if bad or not backends:
        parser().error(f"--backends: unknown backend(s) {', '.join(bad) or '(none)'}; known: {', '.join(BACKENDS)}")
    lmi_designs = [d.strip() for d in a.designs.split(",") if d.strip()] if a.designs else None
    unknown = [d for d in lmi_designs or [] if d not in designs.DESIGNS]
    if unknown:
        parser().error(f"--designs: unknown design(s) {', '.join(unknown)}; known: {', '.join(designs.DESIGNS)}")
    r = bench(Path(a.fmu_dir), a.steps, a.repeats, backends=backends, lmi=not a.skip_lmi, build=not a.skip_build,
              fmus=not a.skip_fmus, coupled_runs=not a.skip_coupled, scaling=not a.skip_scaling,
              campaign=not a.skip_campaign, demo=not a.skip_demo, lmi_designs=lmi_designs, scs_max_iters=a.scs_max_iters, lmi_timeout=a.lmi_timeout)
    print(markdown(r) if a.markdown else table(r))
    if a.json_file:
        from ..atomic import atomic_write_text

        atomic_write_text(a.json_file, json.dumps(_jsonable(r), indent=2))
    return 0
