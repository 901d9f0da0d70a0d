"""Independent certificate of a design file: numpy/scipy only, never the LMI solver, never the
design module that produced the file.

A certificate re-evaluates the numbers that will be packaged (the design file's model
coefficients and gains), not the solver's internal state; a design whose certificate fails is never
packaged. One module per FMU family (named like it) with ``certify(data) -> list[Check]`` and
``summary(data) -> dict``, over the shared helpers of :mod:`.checks`; :func:`certify` adds the
checks of the runtime's tables (``synthesis.table_checks``). Method per paper: ``docs/certificates.md``.
"""
from __future__ import annotations

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


def certify(data: dict) -> tuple[bool, list[Check]]:
    """Certify a design dict. Returns (certified, checks)."""
    checks = _family(data).certify(data)
    from ..table_checks import checks as table_checks
    checks = checks + table_checks(data)      # the runtime's tables, checked independently
    return all(c.passed for c in checks) and bool(checks), checks


def as_dicts(checks: list[Check]) -> list[dict]:
    return [asdict(c) for c in checks]


def summary(data: dict) -> dict:
    """Headline figures of a certified design (for notes and reports)."""
    return _family(data).summary(data)
