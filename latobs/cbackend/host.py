"""A plain C FMI 2.0 host (``latobs/native/fmi2_host.c``), compiled on first use: an FMU run or
timed with no Python in the loop (``latobs bench``, and the tests' non-Python host).

pythonfmu FMUs need libpython's symbols in the global scope of a C host: :func:`libpython` finds
this interpreter's shared library, which the host dlopens first.
"""
from __future__ import annotations

import json
import shlex
import subprocess
import sys
import sysconfig
import tempfile
import zipfile
from pathlib import Path

import numpy as np

from ..native_guard import fmi2_headers, find_compiler

HOST_SOURCE = Path(__file__).resolve().parent.parent / "native" / "fmi2_host.c"
_BUILT: dict[str, Path] = {}


class HostError(RuntimeError):
    pass


def compile_host(out_dir: Path | None = None) -> Path:
    """The host executable (compiled once per process into ``out_dir`` or a temporary folder)."""
    key = str(out_dir)
    if key in _BUILT and _BUILT[key].is_file():
        return _BUILT[key]
    cc = find_compiler()
    if cc is None:
        raise HostError("no C compiler found (pip install ziglang, set CC, or install cc/gcc)")
    folder = Path(out_dir) if out_dir else Path(tempfile.mkdtemp(prefix="latobs-host-"))
    folder.mkdir(parents=True, exist_ok=True)
    exe = folder / "fmi2_host"
    cmd = [*shlex.split(cc), "-std=c99", "-O2", "-Wall", "-Wextra", f"-I{fmi2_headers()}", "-o", str(exe),
           str(HOST_SOURCE), "-ldl"]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        raise HostError(f"host build failed ({shlex.join(cmd)}):\n{proc.stderr}")
    _BUILT[key] = exe
    return exe


def libpython() -> Path | None:
    """This interpreter's shared libpython, or None (a static build: pythonfmu FMUs cannot run in
    a C host then)."""
    name = sysconfig.get_config_var("LDLIBRARY") or ""
    for folder in (sysconfig.get_config_var("LIBDIR"), Path(sys.base_prefix) / "lib"):
        if folder and (name.endswith(".so") or ".so." in name):
            path = Path(folder) / name
            if path.is_file():
                return path
    return None


def _vrs(md, causality: str, typ: str) -> tuple[list[str], list[int]]:
    vs = [v for v in md.modelVariables if v.causality == causality and v.type == typ]
    return [v.name for v in vs], [v.valueReference for v in vs]


def _call(mode: str, fmu: Path, inputs: dict[str, np.ndarray], h: float, repeats: int, workdir: Path | None):
    from fmpy import extract, read_model_description

    md = read_model_description(str(fmu))
    out_names, out_vrs = _vrs(md, "output", "Real")
    int_names, int_vrs = _vrs(md, "output", "Integer")
    # inputs without values keep their start values (never set), as in the validation harness
    given = [v for v in md.modelVariables if v.causality == "input" and v.type == "Real" and v.name in inputs]
    missing = [v.name for v in md.modelVariables if v.causality == "input" and v.name not in inputs
               and v.start is None]
    if missing:
        raise HostError(f"{fmu.name}: no values for input(s) {', '.join(missing)}, which declare no start value")
    in_vrs = [v.valueReference for v in given]
    rows = np.column_stack([np.asarray(inputs[v.name], dtype=float) for v in given]) if given else None
    n = len(rows) if rows is not None else len(next(iter(inputs.values())))
    python_fmu = "resources/slavemodule.txt" in zipfile.ZipFile(fmu).namelist()
    lib = libpython() if python_fmu else None
    if python_fmu and lib is None:
        raise HostError(f"{fmu.name} is a pythonfmu FMU and this Python has no shared libpython")
    with tempfile.TemporaryDirectory(prefix="latobs-host-run-", dir=workdir) as tmp:
        unzipped = extract(str(fmu), unzipdir=tmp)
        text = "\n".join(" ".join(repr(float(x)) for x in row) for row in rows) if rows is not None else ""
        cmd = [str(compile_host()), mode, str(lib) if lib else "none", unzipped,
               md.coSimulation.modelIdentifier, md.guid, repr(float(h)), str(n),
               ",".join(map(str, in_vrs)) or "-", ",".join(map(str, out_vrs)) or "-",
               ",".join(map(str, int_vrs)) or "-", str(repeats)]
        proc = subprocess.run(cmd, input=text, capture_output=True, text=True)
    if proc.returncode != 0:
        raise HostError(f"{fmu.name} in the C host: exit {proc.returncode}\n{proc.stderr[-3000:]}")
    return proc.stdout, out_names, int_names


def run(fmu: Path, inputs: dict[str, np.ndarray], h: float, workdir: Path | None = None) -> dict[str, np.ndarray]:
    """Run ``fmu`` in the C host: row k of ``inputs`` (by input name) is set before step k of
    size ``h`` (an input missing from ``inputs`` keeps its start value); returns every output
    after initialisation and after each step (N + 1 values)."""
    out, names, int_names = _call("run", Path(fmu), inputs, h, 1, workdir)
    table = np.array([[float(x) for x in line.split()] for line in out.splitlines()])
    res = {name: table[:, j] for j, name in enumerate(names)}
    res.update({name: table[:, len(names) + j].astype(int) for j, name in enumerate(int_names)})
    return res


def bench(fmu: Path, inputs: dict[str, np.ndarray], h: float, repeats: int = 5,
          workdir: Path | None = None) -> dict:
    """Time ``fmu`` in the C host on ``inputs``: {"ns_per_step_with_io", "ns_per_doStep", "steps",
    "repeats"} (best of ``repeats`` fresh instances)."""
    out, _, _ = _call("bench", Path(fmu), inputs, h, repeats, workdir)
    return json.loads(out)
