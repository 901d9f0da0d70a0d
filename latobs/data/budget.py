"""Resource limits: what a record, a validation run or a campaign may take of this machine.

Each command estimates what it will need (memory, time) from its inputs before it starts, and
refuses (:class:`ResourceLimitError`, exit 2) what would not fit, naming the estimate and the limit,
instead of being killed by the kernel half-way. The limits (documented on the CLI reference and
docs/validation.md):

- memory: ``--max-memory MB`` / ``$LATOBS_MAX_MEMORY_MB``, else :data:`MEMORY_SHARE` of the memory
  the machine has available now (``MemAvailable`` of /proc/meminfo);
- time: ``--max-hours H`` / ``$LATOBS_MAX_HOURS``, else :data:`DEFAULT_MAX_HOURS`;
- a record file: ``--max-record-mb MB`` / ``$LATOBS_MAX_RECORD_MB``, else :data:`DEFAULT_MAX_RECORD_MB`
  of CSV text (the decompressed text of a ``.gz``); device files and FIFOs are never records.

Standard library only (design time reads records too).
"""
from __future__ import annotations

import math
import os

MEMORY_ENV = "LATOBS_MAX_MEMORY_MB"
HOURS_ENV = "LATOBS_MAX_HOURS"
RECORD_ENV = "LATOBS_MAX_RECORD_MB"
#: the share of the available memory a command plans to use when no limit is given
MEMORY_SHARE = 0.8
#: the longest a command plans to run when no limit is given, h
DEFAULT_MAX_HOURS = 24.0
#: the largest record (CSV text, MB) read when no limit is given: 1 h at 1 ms of a dozen columns
DEFAULT_MAX_RECORD_MB = 1024.0
MB = 1024 * 1024


class ResourceLimitError(ValueError):
    """What a command would need exceeds a limit (the message gives the estimate, the limit and
    how to raise it). A user error: exit 2."""


def _env_number(name: str) -> float | None:
    text = os.environ.get(name, "").strip()
    if not text:
        return None
    try:
        value = float(text)
    except ValueError:
        raise ResourceLimitError(f"${name} must be a positive number, got {text!r}") from None
    if not (math.isfinite(value) and value > 0):
        raise ResourceLimitError(f"${name} must be a positive number, got {text!r}")
    return value


def available_memory() -> int:
    """Bytes of memory available to start new work without swapping (MemAvailable), else the
    physical memory; 4 GiB when neither can be read."""
    try:
        with open("/proc/meminfo", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return int(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):
        return 4 * 1024 * MB


def memory_limit() -> tuple[int, str]:
    """(bytes, where the limit comes from)."""
    mb = _env_number(MEMORY_ENV)
    if mb is not None:
        return int(mb * MB), f"--max-memory / ${MEMORY_ENV} = {mb:g} MB"
    avail = available_memory()
    return int(MEMORY_SHARE * avail), (f"{100 * MEMORY_SHARE:g} % of the {avail / MB:.0f} MB available; "
                                       f"--max-memory MB or ${MEMORY_ENV} sets it")


def time_limit() -> tuple[float, str]:
    """(seconds, where the limit comes from)."""
    h = _env_number(HOURS_ENV)
    if h is not None:
        return h * 3600.0, f"--max-hours / ${HOURS_ENV} = {h:g} h"
    return DEFAULT_MAX_HOURS * 3600.0, f"{DEFAULT_MAX_HOURS:g} h; --max-hours H or ${HOURS_ENV} sets it"


def record_limit() -> tuple[int, str]:
    """(bytes of CSV text, where the limit comes from)."""
    mb = _env_number(RECORD_ENV)
    if mb is not None:
        return int(mb * MB), f"--max-record-mb / ${RECORD_ENV} = {mb:g} MB"
    return int(DEFAULT_MAX_RECORD_MB * MB), (f"{DEFAULT_MAX_RECORD_MB:g} MB; --max-record-mb MB or "
                                              f"${RECORD_ENV} reads larger ones")


def size(n: float) -> str:
    """Bytes, readable: '2.4 GB', '310 MB'."""
    if n >= 1024 * MB:
        return f"{n / (1024 * MB):.3g} GB"
    return f"{n / MB:.3g} MB"


def duration(s: float) -> str:
    if s >= 86400 * 365:
        return f"{s / (86400 * 365):.3g} years"
    if s >= 86400:
        return f"{s / 86400:.3g} days"
    if s >= 3600:
        return f"{s / 3600:.3g} h"
    return f"{s:.3g} s"


def check(what: str, memory: float | None = None, seconds: float | None = None) -> None:
    """Refuse (ResourceLimitError) ``what`` when its estimated ``memory`` (bytes) or time
    (``seconds``) exceeds the limit."""
    if memory is not None:
        limit, why = memory_limit()
        if not memory <= limit:
            raise ResourceLimitError(f"{what} would need about {size(memory)} of memory, more than the limit of "
                                     f"{size(limit)} ({why})")
    if seconds is not None:
        limit_s, why = time_limit()
        if not seconds <= limit_s:
            raise ResourceLimitError(f"{what} would take about {duration(seconds)}, longer than the limit of "
                                     f"{duration(limit_s)} ({why})")
