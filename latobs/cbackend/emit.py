"""C text for the native backend's generated headers (build time; standard library only).

A model's emitter (``latobs/cbackend/<runtime>.py``) turns the FMU's data file into a
:class:`CModel`: the ``model_data.h`` its C model file reads (static const data: the certified
gains, the discretisation, the tables), and what the model description needs beyond the
``ModelSpec`` (the ModelExchange states and event indicators). Numbers are written with 17
significant digits (``repr``), so the C doubles are bit-for-bit the Python floats.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from ..fmu_src.spec import Var


@dataclass(frozen=True)
class CModel:
    """What an emitter gives the generator.

    header              C text of ``model_data.h`` (include guards are added by the generator)
    states              the ModelExchange continuous states, in the order of
                        ``model_me_get_states`` (name, unit, description; names must be unique and
                        not clash with the ModelSpec's variables); empty: co-simulation only
    n_event_indicators  ``model_me_event_indicators``'s count (the C model reports the states'
                        nominal values itself: ``model_me_nominals``)
    dependencies        ModelExchange's structure, as the C model computes it: {unknown: knowns},
                        the unknowns being every Real output (by name) and every state's derivative
                        (``der(<state>)``), the knowns the inputs and states each depends on
                        directly within a mode (a speed that only selects the mode at events is not
                        one; Integer outputs change at events only: no dependency). Written into the
                        model description's ``ModelStructure`` (Outputs, Derivatives);
                        ``tests/cbackend/test_model_structure.py`` checks it against finite differences of
                        the FMU. Required when ``states`` is not empty.
    """

    header: str
    states: tuple[Var, ...] = ()
    n_event_indicators: int = 0
    dependencies: "dict[str, tuple[str, ...]] | None" = None


def nonzero(names, *rows) -> set:
    """The ``names[j]`` whose coefficient is nonzero in any of ``rows`` (equal-length sequences of
    numbers): the knowns a linear combination with these coefficients (e.g. one row of a matrix, in
    each mode) depends on."""
    return {name for j, name in enumerate(names) if any(float(row[j]) != 0.0 for row in rows)}


def structure(deps: dict) -> dict[str, tuple[str, ...]]:
    """``CModel.dependencies`` from {unknown: iterable of knowns}, each tuple sorted and unique (the
    model description lists them in value-reference order anyway)."""
    return {k: tuple(sorted(set(v))) for k, v in deps.items()}


def c_double(x) -> str:
    """A C double literal equal to the Python float ``x`` (inf and nan as expressions of math.h)."""
    x = float(x)
    if math.isnan(x):
        return "NAN"
    if math.isinf(x):
        return "INFINITY" if x > 0 else "(-INFINITY)"
    text = repr(x)
    if "e" not in text and "." not in text and "inf" not in text:
        text += ".0"
    return text


def _nested(values, conv) -> str:
    if isinstance(values, (list, tuple)):
        return "{" + ", ".join(_nested(v, conv) for v in values) + "}"
    return conv(values)


def _shape(values) -> list[int]:
    shape = []
    while isinstance(values, (list, tuple)):
        shape.append(len(values))
        if not values:
            break
        values = values[0]
    return shape


def c_array(name: str, values, ctype: str = "double") -> str:
    """``static const <ctype> NAME[a][b]... = {...};`` for a (nested, rectangular) list.
    ctype "double" writes exact double literals, "int" integers."""
    shape = _shape(values)
    if not shape or 0 in shape:
        raise ValueError(f"c_array {name}: empty or scalar value {values!r}")
    conv = c_double if ctype == "double" else (lambda v: str(int(v)))
    dims = "".join(f"[{n}]" for n in shape)
    return f"static const {ctype} {name}{dims} = {_nested(values, conv)};\n"


def c_define(name: str, value) -> str:
    """``#define NAME value`` (an int, a float as an exact double literal, or a C string)."""
    if isinstance(value, bool):
        text = "1" if value else "0"
    elif isinstance(value, int):
        text = str(value)
    elif isinstance(value, float):
        text = c_double(value)
        text = f"({text})" if text.startswith("-") else text
    elif isinstance(value, str):
        text = c_string(value)
    else:
        raise TypeError(f"c_define {name}: unsupported value {value!r}")
    return f"#define {name} {text}\n"


def c_string(s: str) -> str:
    """A C string literal of ``s`` (UTF-8, every non-printable byte and '"', '\\', '?' escaped)."""
    out = []
    for b in s.encode("utf-8"):
        c = chr(b)
        if c in '"\\?' or not 0x20 <= b < 0x7F:
            out.append(f"\\{b:03o}")
        else:
            out.append(c)
    return '"' + "".join(out) + '"'
