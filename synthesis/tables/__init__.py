"""What each FMU's runtime evaluates, computed once at build time from its design (or plant) file.

``compute(data)`` returns the tables of the runtime that ``data`` is for (step maps at the FMU's
default step, Taylor tables in 1/vx, band tables, discretisations): plain JSON data, stored in the
design (or plant) file under ``"tables"`` by :func:`attach`. The native C model (through its
emitter, which writes them as C data) and the Python reference runtime both evaluate exactly these
numbers; ``synthesis.table_checks`` verifies them independently as part of the certificate.

One module per runtime, named like the runtime: ``tables/<runtime>.py`` with ``compute(data) ->
dict``.
"""
from __future__ import annotations

from importlib import import_module

TABLES_KEY = "tables"


def runtime_of(data: dict) -> str:
    """The runtime a design (or plant) dict is for, by its paper and kind (plants: by vehicle kind)."""
    if data.get("schema", "").startswith("latobs.plant"):
        return "motorcycle_plant" if data["vehicle"].get("kind") == "motorcycle" else "car_plant"
    paper, kind = data.get("paper"), data.get("kind")
    if paper == "000":
        return "sideslip_bank_observer"
    if paper == "001":
        return "lateral_interval_observer"
    if paper == "002":
        return "sideslip_kalman_filter" if kind == "kalman_baseline" else "sideslip_fixed_order_estimator"
    if paper == "003":
        return "motorcycle_fault_observer"
    raise ValueError(f"design {data.get('name')!r}: no runtime for paper {paper!r} (kind {kind!r})")


def _module(package: str, data: dict):
    """The runtime's module in ``package``, or None while it has none (transitional)."""
    name = f"{package}.{runtime_of(data)}"
    try:
        return import_module(name)
    except ModuleNotFoundError as exc:
        if exc.name == name:
            return None
        raise


def compute(data: dict) -> dict:
    """The tables of ``data``'s runtime ({} for a runtime that needs none)."""
    mod = _module(__name__, data)
    return mod.compute(data) if mod is not None else {}


def attach(data: dict) -> dict:
    """``data`` with its tables under ``"tables"`` (computed when absent); returns ``data``."""
    if TABLES_KEY not in data:
        data[TABLES_KEY] = compute(data)
    return data
