"""The plain C FMI 2.0 host on this machine's platform (``latobs/native/fmu_runner.c``, through
:mod:`latobs.cbackend.runner`, compiled on first use): an FMU run or timed with no Python in the
loop (``latobs bench``, and the tests' non-Python host), on a fixed communication step.

pythonfmu FMUs need libpython's symbols in the global scope of a C host: :func:`libpython` finds
this interpreter's shared library, which the host loads first.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from . import runner, toolchain
from .runner import libpython  # noqa: F401  (part of this module's interface)


class HostError(RuntimeError):
    pass


def _grid(fmu: Path, inputs: dict[str, np.ndarray], h: float):
    """The host platform, the points t_k = k h (N + 1 of them for N rows) and the inputs (their
    last row repeated for the last point, which no step follows)."""
    platform = toolchain.host_platform()
    why = runner.available(platform) if platform else "this machine is none of the FMU platforms"
    if why:
        raise HostError(f"{Path(fmu).name}: no C host here: {why}")
    columns = {k: np.asarray(v, dtype=float) for k, v in inputs.items()}
    n = len(next(iter(columns.values()))) if columns else 0
    if n < 1:
        raise HostError(f"{Path(fmu).name}: no input rows")
    return platform, np.arange(n + 1) * float(h), {k: np.append(v, v[-1:]) for k, v in columns.items()}


def run(fmu: Path, inputs: dict[str, np.ndarray], h: float, workdir: Path | None = None) -> dict[str, np.ndarray]:
    """Run ``fmu`` in the C host: row k of ``inputs`` (by input name) is set before step k of
    size ``h`` (an input missing from ``inputs`` keeps its start value); returns every output
    after initialisation and after each step (N + 1 values; Integer outputs as int)."""
    from fmpy import read_model_description

    platform, time, cols = _grid(fmu, inputs, h)
    try:
        res = runner.run(fmu, platform, time, cols, step=float(h), workdir=workdir)
    except runner.RunnerError as exc:
        raise HostError(str(exc)) from exc
    if not res.ok:
        raise HostError(f"{Path(fmu).name} in the C host: {res.failure()}")
    types = {v.name: v.type for v in read_model_description(str(fmu)).modelVariables}
    return {k: (v if types[k] == "Real" else v.astype(int)) for k, v in res.outputs.items()}


def bench(fmu: Path, inputs: dict[str, np.ndarray], h: float, repeats: int = 5,
          workdir: Path | None = None) -> dict:
    """Time ``fmu`` in the C host on ``inputs``: {"ns_per_step_with_io", "ns_per_doStep", "steps",
    "repeats"} (best of ``repeats`` fresh instances)."""
    platform, time, cols = _grid(fmu, inputs, h)
    try:
        return runner.bench(fmu, platform, time, cols, step=float(h), repeats=repeats, workdir=workdir)
    except runner.RunnerError as exc:
        raise HostError(str(exc)) from exc
