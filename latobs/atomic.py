"""Atomic file writes and output-folder locks: nothing half-written is ever visible under the
final name, and one writer at a time builds into a folder.

* :func:`atomic_paths` writes several files as one unit: each to a temporary in its folder, then
  all renamed in the order given (the last one is the commit point: a build renames the design
  file first and its FMU last, so an FMU on disk always has its design file beside it, and the FMU
  carries a copy of its design to check the pair by);
* :func:`locked_folder` holds an exclusive lock (``fcntl.flock`` on ``FOLDER/.latobs.lock``)
  while a build writes a folder. A second build waits for it, saying so on stderr, up to
  ``LATOBS_LOCK_TIMEOUT`` seconds (default :data:`LOCK_TIMEOUT`), then gives up with
  :class:`FolderBusy` (a user error: exit 2). The lock is the kernel's: it is released when its
  holder exits, however it exits (SIGKILL included). Whoever takes it first removes the
  temporaries that an interrupted writer left (``.NAME.fmu.XXXXXXXX*``, ``.NAME.design.json.*``).
"""
from __future__ import annotations

import fcntl
import os
import re
import sys
import tempfile
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator, Sequence

LOCK_NAME = ".latobs.lock"
LOCK_TIMEOUT = 1800.0                   # s a build waits for another one writing the same folder
LOCK_TIMEOUT_ENV = "LATOBS_LOCK_TIMEOUT"
#: the files whose stale temporaries a locked writer removes (what builds write)
LOCKED_SUFFIXES = (".fmu", ".design.json")

_held: dict[str, list] = {}             # real path of a locked folder -> [fd, depth] (this process)


class FolderBusy(RuntimeError):
    """Another process has been writing the output folder for longer than the lock timeout."""


@contextmanager
def atomic_paths(paths: Sequence[str | os.PathLike], suffixes: Sequence[str] | None = None,
                 mode: int = 0o644) -> Iterator[list[Path]]:
    """Yield one temporary path per target, each in its target's folder; when the block succeeds
    they replace the targets in the order given (with permissions ``mode``). On failure no target
    is touched and the temporaries are removed. ``suffixes``: of the temporaries (default: each
    target's suffix)."""
    targets = [Path(p) for p in paths]
    suffixes = list(suffixes) if suffixes is not None else [p.suffix for p in targets]
    tmps: list[Path] = []
    try:
        for path, suffix in zip(targets, suffixes):
            path.parent.mkdir(parents=True, exist_ok=True)
            fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=suffix, dir=path.parent)
            os.close(fd)
            tmps.append(Path(tmp))
        yield list(tmps)
        for tmp, path in zip(tmps, targets):
            os.chmod(tmp, mode)   # mkstemp makes 0600; outputs are meant to be shared
            os.replace(tmp, path)
    finally:
        for tmp in tmps:
            if os.path.exists(tmp):
                os.unlink(tmp)


@contextmanager
def atomic_path(path: str | os.PathLike, suffix: str = ".tmp") -> Iterator[Path]:
    """Yield a temporary path in the target's folder; on success it replaces ``path`` (0644)."""
    with atomic_paths([path], [suffix]) as (tmp,):
        yield tmp


def sha256_file(path: str | os.PathLike) -> str:
    """The sha256 (hex) of a file's bytes, read in blocks."""
    import hashlib

    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def atomic_write_bytes(path: str | os.PathLike, raw: bytes, mode: int = 0o644) -> Path:
    """``raw`` into ``path`` atomically (the folder made if missing), with permissions ``mode``
    (0o755: a program or library latobs compiled for this machine)."""
    with atomic_paths([path], mode=mode) as (tmp,):
        tmp.write_bytes(raw)
    return Path(path)


def atomic_write_text(path: str | os.PathLike, text: str) -> Path:
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return Path(path)


def _timeout() -> float:
    text = os.environ.get(LOCK_TIMEOUT_ENV, "").strip()
    try:
        value = float(text) if text else LOCK_TIMEOUT
    except ValueError:
        raise FolderBusy(f"{LOCK_TIMEOUT_ENV}={text!r} is not a number of seconds") from None
    return max(value, 0.0)


def stale_temporaries(folder: Path, suffixes: Sequence[str] = LOCKED_SUFFIXES) -> list[Path]:
    """The temporaries :func:`atomic_paths` leaves in ``folder`` when its writer is killed, for
    targets ending in ``suffixes`` (``.NAME.fmu.XXXXXXXX.fmu``, ``...guard.so``, ...)."""
    pattern = re.compile(r"\.(.+(?:" + "|".join(map(re.escape, suffixes)) + r"))\.[a-z0-9_]{8}(?:\..*)?\Z")
    try:
        return sorted(p for p in Path(folder).iterdir() if pattern.match(p.name) and p.is_file())
    except FileNotFoundError:
        return []


@contextmanager
def locked_folder(folder: str | os.PathLike, purpose: str = "build",
                  stale: Sequence[str] = LOCKED_SUFFIXES) -> Iterator[Path]:
    """Hold ``folder``'s lock (created with the folder if missing) for the block; re-entrant in
    one process. See the module docstring for waiting, the timeout and the temporaries removed."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    key = os.path.realpath(folder)
    if key in _held:
        _held[key][1] += 1
        try:
            yield folder
        finally:
            _held[key][1] -= 1
        return
    lock = folder / LOCK_NAME
    fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            timeout = _timeout()
            holder = _holder(fd)
            print(f"latobs: waiting for {holder} to finish writing {folder} (up to {timeout:g} s; "
                  f"{LOCK_TIMEOUT_ENV} sets it)", file=sys.stderr, flush=True)
            deadline = time.monotonic() + timeout
            while True:
                time.sleep(0.2)
                try:
                    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                    break
                except BlockingIOError:
                    if time.monotonic() >= deadline:
                        raise FolderBusy(f"{folder} is being written by {holder} for more than {timeout:g} s "
                                         f"(lock {lock}); wait for it to finish, or set {LOCK_TIMEOUT_ENV}") \
                            from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"pid {os.getpid()}: latobs {purpose}\n".encode(), 0)
        removed = stale_temporaries(folder, stale)
        for p in removed:
            p.unlink(missing_ok=True)
        if removed:
            print(f"latobs: removed {len(removed)} temporary file(s) an interrupted build left in {folder}: "
                  f"{', '.join(p.name for p in removed)}", file=sys.stderr)
        _held[key] = [fd, 1]
        try:
            yield folder
        finally:
            del _held[key]
    finally:
        os.close(fd)                    # releases the lock


def _holder(fd: int) -> str:
    """Who holds a lock, from what it wrote in the lock file ("another latobs" if unknown)."""
    try:
        text = os.pread(fd, 200, 0).decode("utf-8", "replace").strip()
    except OSError:
        text = ""
    return f"another latobs ({text})" if text else "another latobs"
