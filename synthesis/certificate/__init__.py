"""Independent certificate of a design file: numpy/scipy only, never the LMI solver, never the
design module that produced the file.

A certificate re-evaluates the numbers that will be packaged (the design file's model
coefficients and gains), not the solver's internal state; a design whose certificate fails is never
packaged. One module per FMU family (named like it) with ``certify(data) -> list[Check]`` and
``summary(data) -> dict``, over the shared helpers of :mod:`.checks`; :func:`certify` adds the
checks of the runtime's tables (``synthesis.table_checks``). Method per paper: ``docs/certificates.md``.
"""
from __future__ import annotations

import hashlib
import json
from dataclasses import asdict
from importlib import import_module

from .checks import REL_TOL, Check, _ge, _le  # noqa: F401  (_ge, _le: the table checks' helpers)
from .sideslip_bank_observer import closed_loop_000
from .sideslip_fixed_order_estimator import _bicycle_coefficients_002  # noqa: F401  (its tests)

__all__ = ["REL_TOL", "Check", "as_dicts", "certify", "closed_loop_000", "summary"]


def _family(data: dict):
    """The certificate module of ``data``'s FMU family (the runtime it is packaged with)."""
    from ..tables import runtime_of

    try:
        name = runtime_of(data)
    except ValueError:
        raise ValueError(f"design {data.get('name')!r}: no certificate for paper {data.get('paper')!r}") from None
    return import_module(f"{__name__}.{name}")


#: certificates made in this process, by the content of what they certified (:func:`certify`)
_MADE: dict[str, tuple[bool, tuple[Check, ...]]] = {}
_MADE_SIZE = 32
_OWN_KEYS = ("certified", "checks")     # what a certificate writes into a design dict


def _content_key(obj) -> str:
    """SHA-256 of ``obj`` as canonical JSON (numpy values as lists)."""
    def plain(o):
        if hasattr(o, "tolist"):
            return o.tolist()
        if hasattr(o, "__dataclass_fields__"):
            return asdict(o)
        raise TypeError(f"{type(o).__name__} in a design dict")
    return hashlib.sha256(json.dumps(obj, sort_keys=True, separators=(",", ":"), default=plain).encode()).hexdigest()


def certify(data: dict) -> tuple[bool, list[Check]]:
    """Certify a design dict. Returns (certified, checks).

    A certificate is a pure function of the design's content: one made before in this process of
    identical content (the design's every number, its tables included; not the ``certified`` and
    ``checks`` a certificate wrote) is returned again rather than re-evaluated (a build certifies a
    design when it is solved and again before it is packaged)."""
    key = _content_key({k: v for k, v in data.items() if k not in _OWN_KEYS})
    made = _MADE.get(key)
    if made is None:
        checks = _family(data).certify(data)
        from ..table_checks import checks as table_checks
        checks = checks + table_checks(data)      # the runtime's tables, checked independently
        made = (all(c.passed for c in checks) and bool(checks), tuple(checks))
        if len(_MADE) >= _MADE_SIZE:
            _MADE.pop(next(iter(_MADE)))
        _MADE[key] = made
    return made[0], list(made[1])


def as_dicts(checks: list[Check]) -> list[dict]:
    return [asdict(c) for c in checks]


def summary(data: dict) -> dict:
    """Headline figures of a certified design (for notes and reports)."""
    return _family(data).summary(data)
