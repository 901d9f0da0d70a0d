"""Independent checks of the tables a design (or plant) file carries (``synthesis.tables``).

A check recomputes what a table stands for by another route (numpy/scipy, not the code that built
the table) and bounds the difference; the certificate (``synthesis.certificate``) includes these
checks, so a design whose tables are wrong is never packaged. One module per runtime, named like
the runtime: ``table_checks/<runtime>.py`` with ``checks(data) -> list[Check]``.
"""
from __future__ import annotations

from ..tables import _module


def checks(data: dict) -> list:
    """The table checks of ``data``'s runtime ([] for a runtime without tables)."""
    mod = _module(__name__, data)
    return mod.checks(data) if mod is not None else []
