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
from typing import Iterator

import numpy as np

#: The bundled real-vehicle record (MIT, see the README and LICENSE beside it).
MBDS_CSV = Path(os.fspath(resources.files("latobs").joinpath("data", "mbds-250lm", "mbds_250lm_100hz.csv.gz")))


class RecordError(ValueError):
    """A record that cannot be read as a CSV of finite numbers over a strictly increasing ``t``;
    the message names the file, the column and the line."""


def load_csv(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """Read a ``.csv`` or ``.csv.gz`` file with a header row into {column: float array} (new
    arrays on every call; a small file read before in this process, unchanged since (its size and
    modification time), is not parsed again).

    Checks: a regular file (not a device, FIFO or folder: :func:`check_file`), no larger than the
    record limit (:func:`latobs.data.budget.record_limit`, the decompressed text of a ``.gz``
    counted as it is read), a header of distinct non-empty names, a column ``t``, every row with
    as many fields as the header, every value a finite number, ``t`` strictly increasing. Errors
    are :class:`RecordError` naming the file, the column and the line (the header is line 1).
    Blank lines are skipped. The rows are converted to numbers in blocks as they are read: the
    memory held is about the arrays' (8 bytes a value), not the text's.
    """
    path = Path(path)
    st = check_file(path)
    if st.st_size > CACHED_BYTES:
        return _parse(path)
    hit = _parsed(os.path.realpath(path), st.st_size, st.st_mtime_ns)
    return {n: a.copy() for n, a in hit.items()}


#: files up to this size (bytes) are kept parsed (the last few): the tests and the demo read the
#: bundled record many times; a larger one is parsed on each call, held once
CACHED_BYTES = 32 * 1024 * 1024
#: rows converted to numbers at once
BLOCK_ROWS = 65536


def check_file(path: str | os.PathLike) -> os.stat_result:
    """The ``os.stat`` of a record file that may be read: a regular file (a device such as
    /dev/zero, a FIFO, a socket or a folder is refused before it is opened: reading one may never
    end) whose size is within the record limit (a ``.gz`` file's text is counted as it is read);
    else RecordError naming the file, what it is and the limit."""
    import stat

    from . import budget

    path = Path(path)
    try:
        st = path.stat()
    except FileNotFoundError:
        raise RecordError(f"{path}: no such file") from None
    except OSError as exc:
        raise RecordError(f"{path}: cannot read it: {exc.strerror or exc}") from None
    mode = st.st_mode
    if not stat.S_ISREG(mode):
        what = ("a folder" if stat.S_ISDIR(mode) else "a character device" if stat.S_ISCHR(mode)
                else "a block device" if stat.S_ISBLK(mode) else "a FIFO (named pipe)" if stat.S_ISFIFO(mode)
                else "a socket" if stat.S_ISSOCK(mode) else "not a regular file")
        raise RecordError(f"{path}: is {what}, not a record file (a .csv or .csv.gz file)")
    try:
        limit, why = budget.record_limit()
    except budget.ResourceLimitError as exc:
        raise RecordError(str(exc)) from None
    if st.st_size > limit:
        raise RecordError(f"{path}: {budget.size(st.st_size)}, larger than the record limit of "
                          f"{budget.size(limit)} ({why})")
    return st


@lru_cache(maxsize=4)
def _parsed(path: str, size: int, mtime_ns: int) -> dict[str, np.ndarray]:
    """:func:`_parse` of a file by its real path, size and modification time (the few last read)."""
    return _parse(Path(path))


class _Limited:
    """A text stream that raises RecordError once more than ``limit`` characters were read."""

    def __init__(self, fh, limit: int, why: str, path: Path):
        self.fh, self.left, self.limit, self.why, self.path = fh, limit, limit, why, path

    def __iter__(self):
        return self

    def __next__(self) -> str:
        line = next(self.fh)
        self.left -= len(line)
        if self.left < 0:
            from . import budget

            raise RecordError(f"{self.path}: more than {budget.size(self.limit)} of text, the record limit "
                              f"({self.why})")
        return line


def _parse(path: Path) -> dict[str, np.ndarray]:
    blocks: dict[str, list[np.ndarray]] = {}       # {column: its blocks}
    for block in iter_blocks(path):
        for n, a in block.items():
            blocks.setdefault(n, []).append(a)
    return {n: np.concatenate(blocks.pop(n)) for n in list(blocks)}


def iter_blocks(path: str | os.PathLike, rows: int | None = None) -> Iterator[dict[str, np.ndarray]]:
    """The record at ``path`` as consecutive blocks of up to ``rows`` (default :data:`BLOCK_ROWS`)
    rows, each {column: float array}, with every check of :func:`load_csv` (a RecordError when the
    block that holds the culprit is read; at the end, fewer than 2 rows). Memory: one block."""
    from . import budget

    path = Path(path)
    check_file(path)
    limit, why = budget.record_limit()
    block_rows = max(2, rows or BLOCK_ROWS)      # (a whole block: the 2 rows a record needs)
    opener = gzip.open if path.name.lower().endswith(".gz") else open
    names: list[str] = []
    state = {"last": None}               # the previous block's last (t text, t value, line)

    def convert(rows: list[list[str]], lines: list[int]) -> dict[str, np.ndarray]:
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
                        raise RecordError(f"{path}: column {name!r}, line {line}: {cell!r} is not a number") \
                            from None
            raise  # pragma: no cover - numpy rejected something float() accepts
        data = data.reshape(len(rows), len(names))
        bad = ~np.isfinite(data)
        if bad.any():
            i, j = np.argwhere(bad)[0]
            raise RecordError(f"{path}: column {names[j]!r}, line {lines[i]}: value {rows[i][j].strip()!r} is "
                              "not finite")
        jt = names.index("t")
        t = data[:, jt]
        last = state["last"]
        texts = [r[jt] for r in rows]
        tt = t if last is None else np.concatenate([[last[1]], t])
        tx = texts if last is None else [last[0], *texts]
        tl = lines if last is None else [last[2], *lines]
        dt = np.diff(tt)
        if np.any(dt <= 0):
            i = int(np.argmax(dt <= 0))
            raise RecordError(f"{path}: column 't' is not strictly increasing at line {tl[i + 1]} "
                              f"(t = {tx[i + 1].strip()} after {tx[i].strip()})")
        state["last"] = (texts[-1], float(t[-1]), lines[-1])
        return {n: data[:, j].copy() for j, n in enumerate(names)}

    header = None
    n_rows = 0
    block = None
    try:
        with opener(path, "rt", encoding="utf-8-sig", newline="") as fh:
            reader = csv.reader(_Limited(fh, limit, why, path))
            header = next(reader, None)
            if header is not None:
                names = [h.strip() for h in header]
                if any(not n for n in names):
                    raise RecordError(f"{path}: the header (line 1) has an empty column name: {header}")
                dup = sorted({n for n in names if names.count(n) > 1})
                if dup:
                    raise RecordError(f"{path}: column(s) {', '.join(dup)} appear more than once in the header")
                if "t" not in names:
                    raise RecordError(f"{path}: no time column 't' (columns: {', '.join(names)})")
            rows: list[list[str]] = []
            lines: list[int] = []
            for row in reader:
                if not row or all(not c.strip() for c in row):
                    continue
                rows.append(row)
                lines.append(reader.line_num)
                if len(rows) == block_rows:
                    yield convert(rows, lines)
                    n_rows += len(rows)
                    rows, lines = [], []
            if rows:
                block = convert(rows, lines)
                n_rows += len(rows)
    except FileNotFoundError:
        raise RecordError(f"{path}: no such file") from None
    except (OSError, EOFError, UnicodeDecodeError, csv.Error) as exc:
        raise RecordError(f"{path}: cannot read it as a {'gzip-compressed ' if opener is gzip.open else ''}"
                          f"CSV file: {exc}") from None
    if header is None:
        raise RecordError(f"{path}: empty file (a header row of column names is needed)")
    if n_rows < 2:
        raise RecordError(f"{path}: {n_rows} data row(s); at least 2 are needed")
    if block is not None:
        yield block
