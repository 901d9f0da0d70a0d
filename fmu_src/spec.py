"""What an FMU model file declares: its variables and the runtime class that does the maths.

Standard library only. The FMI glue (``framework.py``) reads a ``ModelSpec`` and never holds
maths; the runtime classes know nothing of FMI. A runtime class follows this protocol:

    rt = Runtime(data, params)   # data: the FMU's JSON data file (design or plant file),
                                 # params: {parameter name: value} after initialisation
    rt.y                         # dict {output name: value}, valid after construction
    rt.initialize(u)             # optional: the inputs set in initialisation mode (finite), so that
                                 # the outputs at the start time are consistent with them
    rt.step(h, u)                # advance h seconds, inputs u (dict name -> float) held
    rt.events                    # list of (level, message) produced by the last call,
                                 # level in {"warning", "error"}; drained by the framework

``step`` receives only finite inputs (the framework rejects the others) and must not raise for
any finite value: out-of-range inputs are clamped as documented by the runtime, with a warning.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable


@dataclass(frozen=True)
class Var:
    name: str
    unit: str
    description: str
    start: float = 0.0


@dataclass(frozen=True)
class ModelSpec:
    """Interface of one FMU: Real inputs/outputs/parameters, Integer outputs."""

    description: str
    runtime: Callable  # the runtime class, see the module docstring
    inputs: tuple[Var, ...]
    outputs: tuple[Var, ...]
    integer_outputs: tuple[Var, ...] = ()
    parameters: tuple[Var, ...] = field(default_factory=tuple)
