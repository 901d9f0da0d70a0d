"""FMU model file: ScenarioSignals, the signal source of an SSP package (``latobs export-ssp``).

A validation scenario's input signals, sampled on a uniform time grid when the package is made,
played back as Real outputs with a zero-order hold (``fmu_src/c/signal_source.c``; native C
backend only). Its outputs are the scenario's signals, so the interface depends on the data
file: :func:`spec_of` gives the ``ModelSpec`` of a data file, and :class:`SignalTable` checks it.

Data file (``latobs.ssp.source.signal_data``)::

    {"scenario": name, "t0": s, "dt": s, "stop_time": s,
     "signals": [{"name": ..., "unit": ...}, ...],      # the outputs, in value-reference order
     "rows": [[value of each signal at t0 + k dt], ...]}
"""
from __future__ import annotations

import math
import sys

from ..spec import ModelSpec, Var

#: any finite communication step: a zero-order hold of samples has no accuracy limit
MAX_STEP = sys.float_info.max


class SignalTable:
    """The data check of a signal-source data file and its outputs at the first sample (the
    runtime protocol of ``fmu_src/spec.py``). The playback itself is the C model's: it needs the
    host's communication points, which the Python runtime protocol does not pass to ``step``."""

    def __init__(self, data: dict, params: dict):
        self.names, self.rows = _checked(data)
        if params:
            raise ValueError(f"ScenarioSignals has no parameters, got {', '.join(map(str, params))}")
        self.y = dict(zip(self.names, self.rows[0]))
        self.events: list = []

    def step(self, h: float, u: dict) -> None:
        raise NotImplementedError("ScenarioSignals is played back by its native C model (signal_source.c) only")


def _checked(data: dict) -> tuple[list[str], list[list[float]]]:
    """(signal names, rows) of a data file; ValueError naming what is wrong."""
    names = [str(s.get("name", "")) for s in data.get("signals", [])]
    rows = data.get("rows") or []
    if not names or any(not n.isidentifier() for n in names) or len(set(names)) != len(names):
        raise ValueError(f"signal source: signal names must be distinct identifiers, got {names}")
    for key in ("t0", "dt", "stop_time"):
        x = data.get(key)
        if isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x):
            raise ValueError(f"signal source: {key} must be a finite number, got {x!r}")
    if not data["dt"] > 0:
        raise ValueError(f"signal source: dt = {data['dt']!r} s must be > 0")
    if not rows:
        raise ValueError("signal source: no samples")
    for k, row in enumerate(rows):
        if len(row) != len(names) or not all(isinstance(x, (int, float)) and math.isfinite(x) for x in row):
            raise ValueError(f"signal source: row {k} must hold {len(names)} finite values, got {row!r}")
    return names, [[float(x) for x in row] for row in rows]


def spec_of(data: dict) -> ModelSpec:
    """The interface of the signal source made from ``data``: one Real output per signal, its
    start value the first sample (the outputs in initialisation mode, before the model knows the
    start time)."""
    names, rows = _checked(data)
    units = [s.get("unit") or "1" for s in data["signals"]]
    return ModelSpec(
        description=f"latobs scenario {data.get('scenario', '?')!r}: its input signals sampled every "
                    f"{float(data['dt']):g} s, played back with a zero-order hold",
        runtime=SignalTable,
        inputs=(),
        outputs=tuple(Var(n, u, f"scenario signal {n}", start=x) for n, u, x in zip(names, units, rows[0])),
        max_step=MAX_STEP,
        stop_time=float(data["stop_time"]),
        initialization="in initialisation mode the outputs hold the first sample; from "
                       "fmi2ExitInitializationMode on, the sample at or before the start time",
    )
