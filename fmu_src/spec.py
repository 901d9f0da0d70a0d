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
    Runtime.parameter_defaults(data)   # optional: data-dependent parameter start values

``step`` receives only finite inputs (the framework rejects the others) and must not raise for
any finite value: out-of-range inputs are clamped as documented by the runtime, with a warning.
Outputs change only in ``initialize`` and ``step``: the model description declares that no
output depends directly on an input (no direct feedthrough), and the tests check it.
"""
from __future__ import annotations

import math

from dataclasses import dataclass, field
from typing import Callable, Optional


@dataclass(frozen=True)
class Var:
    """One variable. ``unit`` is an FMI unit name ("1" for dimensionless); ``min``/``max`` are the
    physical bounds declared in the model description (a parameter outside them is refused at
    initialisation, an input outside them is the runtime's business)."""

    name: str
    unit: str
    description: str
    start: float = 0.0
    min: Optional[float] = None
    max: Optional[float] = None


@dataclass(frozen=True)
class ModelSpec:
    """Interface of one FMU: Real inputs/outputs/parameters, Integer outputs.

    description   what the model is; ``describe(data)``, if given, says which variant the data
                  file makes of it (e.g. speed or tire switching), appended to the description
    bounds        optional ``bounds(data) -> {variable name: (min, max)}`` for bounds that depend
                  on the data file (e.g. the number of modes)
    stop_time     s, the DefaultExperiment's stop time (a sensible first run)
    """

    description: str
    runtime: Callable  # the runtime class, see the module docstring
    inputs: tuple[Var, ...]
    outputs: tuple[Var, ...]
    integer_outputs: tuple[Var, ...] = ()
    parameters: tuple[Var, ...] = field(default_factory=tuple)
    describe: Optional[Callable[[dict], str]] = None
    bounds: Optional[Callable[[dict], dict]] = None
    stop_time: float = 10.0


def runtime_parameters(model: str, known, defaults: dict, params: dict | None) -> dict[str, float]:
    """The runtime's parameter values: ``defaults`` overridden by ``params`` (None = default).
    Unknown names and values that are not finite numbers raise a ValueError naming the model and
    the parameter (the framework has already checked each declared [min, max])."""
    params = dict(params or {})
    unknown = sorted(set(params) - set(known))
    if unknown:
        raise ValueError(f"{model}: unknown parameter(s) {', '.join(unknown)}; known: {', '.join(known)}")
    out = {}
    for k, d in defaults.items():
        val = params.get(k)
        val = d if val is None else val
        if isinstance(val, bool) or not isinstance(val, (int, float)) or not math.isfinite(val):
            raise ValueError(f"{model}: parameter {k!r} must be a finite number, got {val!r}")
        out[k] = float(val)
    return out
