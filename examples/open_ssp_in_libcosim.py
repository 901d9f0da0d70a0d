"""Run a latobs SSP package in libcosim, with libcosimpy only.

Run it from the repository root:

    python examples/open_ssp_in_libcosim.py [SYSTEM.ssp] [--csv RESULTS.csv]

SYSTEM.ssp is what ``latobs export-ssp SCENARIO`` writes; without it, this first runs
``latobs export-ssp bank-braking --out build/bank-braking.ssp`` (the only use of latobs here).
libcosim reads everything from the package: the FMUs, the connections, the parameter sets and the
fixed step (the ``osp:FixedStepAlgorithm`` annotation of ``ssd:DefaultExperiment``). This script
steps it to the stop time, records every output of every component after each step (libcosim
has no sample at the start time) and prints the final values; ``--csv`` writes them all
(columns ``time`` and ``<component>.<variable>``).
"""
from __future__ import annotations

import argparse
import csv
import subprocess
import sys
import zipfile
from pathlib import Path
from xml.etree import ElementTree

from libcosimpy.CosimEnums import CosimVariableCausality, CosimVariableType
from libcosimpy.CosimExecution import CosimExecution
from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
from libcosimpy.CosimObserver import CosimObserver

NS = {"ssd": "http://ssp-standard.org/SSP1/SystemStructureDescription",
      "ssc": "http://ssp-standard.org/SSP1/SystemStructureCommon",
      "osp": "http://opensimulationplatform.com/SSP/OSPAnnotations"}


def experiment(ssp: Path) -> tuple[float, float, float]:
    """(start, stop, step) in s from the package's SystemStructure.ssd."""
    with zipfile.ZipFile(ssp) as z:
        root = ElementTree.fromstring(z.read("SystemStructure.ssd"))
    de = root.find("ssd:DefaultExperiment", NS)
    alg = de.find("ssd:Annotations/ssc:Annotation/osp:Algorithm/osp:FixedStepAlgorithm", NS)
    return float(de.get("startTime", 0.0)), float(de.get("stopTime")), float(alg.get("baseStepSize"))


def run(ssp: Path) -> dict[str, list[float]]:
    """Every output of every component after each step: {"time": [...], "<component>.<name>": [...]}."""
    start, stop, step = experiment(ssp)
    ex = CosimExecution.from_ssp_file(str(ssp))        # fixed step from the package's annotation
    obs = CosimObserver.create_last_value()
    ex.add_observer(obs)
    outputs = []                                       # (slave index, name, reference, type)
    for info in ex.slave_infos():
        for v in ex.slave_variables(info.index):
            if v.causality == CosimVariableCausality.OUTPUT.value and v.type in (
                    CosimVariableType.REAL.value, CosimVariableType.INTEGER.value):
                outputs.append((info.index, f"{info.name.decode()}.{v.name.decode()}", v.reference, v.type))
    rows: dict[str, list[float]] = {"time": [], **{name: [] for _, name, _, _ in outputs}}
    for _ in range(round((stop - start) / step)):
        if not ex.step():
            raise RuntimeError(f"libcosim failed a step at t = {ex.status().current_time * 1e-9} s")
        rows["time"].append(ex.status().current_time * 1e-9)
        for index, name, ref, typ in outputs:
            get = obs.last_real_values if typ == CosimVariableType.REAL.value else obs.last_integer_values
            rows[name].append(float(get(index, [ref])[0]))
    return rows


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("ssp", nargs="?", help="the .ssp package (default: export bank-braking first)")
    ap.add_argument("--csv", help="write every output at every step to this CSV file")
    args = ap.parse_args(argv)
    ssp = Path(args.ssp) if args.ssp else Path("build/bank-braking.ssp")
    if not args.ssp:
        subprocess.run([sys.executable, "-m", "latobs", "export-ssp", "bank-braking", "--out", str(ssp)], check=True)
    log_output_level(CosimLogLevel.ERROR)
    rows = run(ssp)
    if args.csv:
        with open(args.csv, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(list(rows))
            w.writerows(zip(*[[repr(x) for x in col] for col in rows.values()]))
    n = len(rows["time"])
    print(f"{ssp}: {n} steps of libcosim to t = {rows['time'][-1]:g} s; final values:")
    for name, values in rows.items():
        if name != "time":
            print(f"  {name:44s} {values[-1]: .6g}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
