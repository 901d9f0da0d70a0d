"""Recorded signals: reading a CSV record and the bundled real-vehicle record (:data:`MBDS_CSV`).

Shared by design time (tuning and identification on the record's tuning half) and validation
(``latobs replay``); standard library and numpy only.
"""
from __future__ import annotations

import csv
import gzip
import os
from functools import lru_cache
from importlib import resources
from pathlib import Path

import numpy as np

#: The bundled real-vehicle record (MIT, see the README and LICENSE beside it).
MBDS_CSV = Path(os.fspath(resources.files("latobs").joinpath("data", "mbds-250lm", "mbds_250lm_100hz.csv.gz")))


class RecordError(ValueError):
    """A record that cannot be read as a CSV of finite numbers over a strictly increasing ``t``;
    the message names the file, the column and the line."""


def load_csv(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """Read a ``.csv`` or ``.csv.gz`` file with a header row into {column: float array} (new
    arrays on every call; a file read before in this process, unchanged since (its size and
    modification time), is not parsed again).

    Checks: readable, a header of distinct non-empty names, a column ``t``, every row with as
    many fields as the header, every value a finite number, ``t`` strictly increasing. Errors
    are :class:`RecordError` naming the file, the column and the line (the header is line 1).
    Blank lines are skipped.
    """
    path = Path(path)
    try:
        st = path.stat()
    except OSError:
        hit = _parse(path)                       # (raises the RecordError naming the file)
    else:
        hit = _parsed(os.path.realpath(path), st.st_size, st.st_mtime_ns)
    return {n: a.copy() for n, a in hit.items()}


@lru_cache(maxsize=4)
def _parsed(path: str, size: int, mtime_ns: int) -> dict[str, np.ndarray]:
    """:func:`_parse` of a file by its real path, size and modification time (the few last read)."""
    return _parse(Path(path))


def _parse(path: Path) -> dict[str, np.ndarray]:
    opener = gzip.open if path.name.lower().endswith(".gz") else open
    try:
        with opener(path, "rt", encoding="utf-8-sig", newline="") as fh:
            reader = csv.reader(fh)
            header = next(reader, None)
            rows: list[list[str]] = []
            lines: list[int] = []
            for row in reader:
                if not row or all(not c.strip() for c in row):
                    continue
                rows.append(row)
                lines.append(reader.line_num)
    except FileNotFoundError:
        raise RecordError(f"{path}: no such file") from None
    except (OSError, EOFError, UnicodeDecodeError, csv.Error) as exc:
        raise RecordError(f"{path}: cannot read it as a {'gzip-compressed ' if opener is gzip.open else ''}"
                          f"CSV file: {exc}") from None
    if header is None:
        raise RecordError(f"{path}: empty file (a header row of column names is needed)")
    names = [h.strip() for h in header]
    if any(not n for n in names):
        raise RecordError(f"{path}: the header (line 1) has an empty column name: {header}")
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise RecordError(f"{path}: column(s) {', '.join(dup)} appear more than once in the header")
    if "t" not in names:
        raise RecordError(f"{path}: no time column 't' (columns: {', '.join(names)})")
    if len(rows) < 2:
        raise RecordError(f"{path}: {len(rows)} data row(s); at least 2 are needed")
    for row, line in zip(rows, lines):
        if len(row) != len(names):
            raise RecordError(f"{path}: line {line} has {len(row)} field(s), the header {len(names)}")
    try:
        data = np.array(rows, dtype=float)
    except ValueError:
        for row, line in zip(rows, lines):
            for name, cell in zip(names, row):
                try:
                    float(cell)
                except ValueError:
                    raise RecordError(f"{path}: column {name!r}, line {line}: {cell!r} is not a number") from None
        raise  # pragma: no cover - numpy rejected something float() accepts
    bad = ~np.isfinite(data)
    if bad.any():
        i, j = np.argwhere(bad)[0]
        raise RecordError(f"{path}: column {names[j]!r}, line {lines[i]}: value {rows[i][j].strip()!r} is not finite")
    cols = {n: data[:, j].copy() for j, n in enumerate(names)}
    dt = np.diff(cols["t"])
    if np.any(dt <= 0):
        i = int(np.argmax(dt <= 0))
        raise RecordError(f"{path}: column 't' is not strictly increasing at line {lines[i + 1]} "
                          f"(t = {rows[i + 1][names.index('t')].strip()} after {rows[i][names.index('t')].strip()})")
    return cols
