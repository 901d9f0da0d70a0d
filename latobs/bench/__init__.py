"""``latobs bench``: what latobs costs, measured side by side in one run (build, LMI solves, one
FMU step per backend, coupled runs, scaling), each figure beside a reference measured in the same
process. :mod:`.measure` measures, :mod:`.tables` renders the figures as Markdown;
``latobs bench --markdown`` prints the documentation's speed page.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

from ..synthesis import designs  # the catalogue only (no solver stack)
from .measure import (BACKEND_LABEL, BACKENDS, DT, LENGTHS, LMI_TIMEOUT, SCALING_OBSERVERS_DURATION,
                      SCALING_SCENARIO, SOLVER_LABEL, SOLVERS, Pairing, _fmu_pairing, _jsonable, _kind, bench, bus,
                      build_time, coupled, coupled_in_fresh_process, coupled_section, ensure_fmus, fmu_data, fmu_names,
                      fmu_section, lmi_row, lmi_row_isolated, lmi_section, machine, paper_000_observers, pairings,
                      plant_artefact, runtime_step_time, scaling_section)
from .tables import (_lmi_cell, build_table, coupled_table, fmu_table, lmi_table, machine_statement, markdown,
                     scaling_table, table)

__all__ = ["BACKENDS", "BACKEND_LABEL", "DT", "LENGTHS", "LMI_TIMEOUT", "SCALING_OBSERVERS_DURATION",
           "SCALING_SCENARIO", "SOLVERS", "SOLVER_LABEL", "Pairing", "bench", "build_table", "build_time", "bus",
           "coupled", "coupled_in_fresh_process", "coupled_section", "coupled_table", "ensure_fmus", "fmu_data",
           "fmu_names", "fmu_section", "fmu_table", "lmi_row", "lmi_row_isolated", "lmi_section", "lmi_table",
           "machine", "machine_statement", "main", "markdown", "paper_000_observers", "pairings", "parser",
           "plant_artefact", "runtime_step_time", "scaling_section", "scaling_table", "table",
           "_fmu_pairing", "_jsonable", "_kind", "_lmi_cell"]


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
    return p


def main(argv: list[str] | None = None) -> int:
    a = parser().parse_args(argv)
    if a.from_json:
        try:
            r = json.loads(Path(a.from_json).read_text(encoding="utf-8"))
        except (OSError, ValueError) as exc:
            parser().error(f"--from-json: cannot read {a.from_json}: {exc}")
        if not isinstance(r, dict):
            parser().error(f"--from-json: {a.from_json} is not the JSON of `latobs bench --json`")
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
              lmi_designs=lmi_designs, scs_max_iters=a.scs_max_iters, lmi_timeout=a.lmi_timeout)
    print(markdown(r) if a.markdown else table(r))
    if a.json_file:
        from ..atomic import atomic_write_text

        atomic_write_text(a.json_file, json.dumps(_jsonable(r), indent=2))
    return 0
