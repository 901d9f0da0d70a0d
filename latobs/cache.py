"""The content-addressed cache of what latobs computes once per input and reuses, shared by every
command (build, validate, replay, campaign, check, demo) and every output folder:

* ``design``: a certified design (``pipeline.solve``: the LMI solve and its certificate, 1-30 s);
* ``build-time-facts``: what only running a runtime decides (paper 001's longest communication
  step: 5-20 s per design);
* ``fmu``: a built FMU with the design file beside it (``pipeline.build``: compilation for every
  platform, the reference experiment), reused by a build into any folder;
* ``compile``: one target's binary (``cbackend.toolchain``: keyed by the compiler command, the
  compilers' versions and every source file's bytes, as ccache does).

An entry's key is the SHA-256 of everything its value is made from (the identities of
``latobs.identity``: design inputs, design-time code, solver versions, runtime and packaging code,
toolchain, platforms); a changed input is another key, so a stale value is never reused. An entry
is checked again where it is used (an FMU's identity is read back; a design is certified again
when packaged), and against its own content when it is read: a value entry holds the SHA-256 of its
value, a files entry the SHA-256 of each file; an entry that does not match (damaged, truncated,
patched by hand) is removed and made again. The folder is :func:`folder` (``$LATOBS_CACHE_DIR``, else the platform's user
cache folder); ``LATOBS_NO_CACHE=1`` (``latobs build --no-cache``) turns it off. Entries are written
atomically (a file, or a folder renamed into place); an unreadable one is made again; the least
recently used entries are removed when the folder grows past ``$LATOBS_CACHE_MAX_MB`` (default
:data:`MAX_MB`)."""
from __future__ import annotations

import hashlib
import json
import os
import shutil
import tempfile
import time
from contextlib import contextmanager
from functools import lru_cache
from pathlib import Path
from typing import Any, Callable, Iterator

from .atomic import atomic_write_text
from .synthesis.identity import sha256_json

ENV_DIR, ENV_OFF, ENV_MAX = "LATOBS_CACHE_DIR", "LATOBS_NO_CACHE", "LATOBS_CACHE_MAX_MB"
VERSION = 2                      # of the entries' layout (2: entries hold their content's hashes)
MAX_MB = 2000.0                  # the folder's default size bound (one full native build: ~60 MB)


def folder() -> Path:
    """The cache folder (not created): ``$LATOBS_CACHE_DIR``, else ``%LOCALAPPDATA%\\latobs`` on
    Windows, ``~/Library/Caches/latobs`` on macOS, ``$XDG_CACHE_HOME/latobs`` (``~/.cache/latobs``)."""
    import sys

    if os.environ.get(ENV_DIR):
        return Path(os.environ[ENV_DIR])
    if sys.platform == "win32" and os.environ.get("LOCALAPPDATA"):
        return Path(os.environ["LOCALAPPDATA"]) / "latobs"
    if sys.platform == "darwin":
        return Path.home() / "Library" / "Caches" / "latobs"
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "latobs"


def enabled() -> bool:
    """Whether the cache is on; CacheSettingError (before anything is made) if its size bound is
    not usable."""
    if os.environ.get(ENV_OFF, "") not in ("", "0"):
        return False
    _max_bytes()
    return True


@contextmanager
def turned_off() -> Iterator[None]:
    """No cache inside the block (``latobs build --no-cache``), for this process and its children."""
    saved = os.environ.get(ENV_OFF)
    os.environ[ENV_OFF] = "1"
    try:
        yield
    finally:
        if saved is None:
            os.environ.pop(ENV_OFF, None)
        else:
            os.environ[ENV_OFF] = saved


def key(kind: str, parts: dict) -> str:
    """The key of a value of ``kind`` computed from ``parts`` (JSON-able, numpy allowed)."""
    return sha256_json({"cache": VERSION, "kind": kind, "parts": parts})


def _value_sha256(value) -> str:
    """The hash a value entry holds of its value (of the text it is stored as)."""
    return hashlib.sha256(json.dumps(value).encode()).hexdigest()


def _read_value(path: Path) -> tuple[bool, Any]:
    """(True, value) of the value entry ``path`` if it is whole (its value matches the hash it
    holds); else (False, None), the entry removed when it exists (damaged: made again)."""
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
        if _value_sha256(doc["value"]) == doc["sha256"]:
            os.utime(path)                             # recently used (pruning goes by age)
            return True, doc["value"]
    except FileNotFoundError:
        return False, None
    except (OSError, ValueError, KeyError, TypeError):
        pass
    _remove(path)
    return False, None


def remember(kind: str, parts: dict, compute: Callable[[], Any]) -> Any:
    """The cached value of ``kind`` for ``parts``, else ``compute()`` stored under its key. The
    value must be JSON (what it round-trips to is what every later call gets: also the first)."""
    if not enabled():
        return compute()
    path = folder() / kind / f"{key(kind, parts)}.json"
    hit, value = _read_value(path)
    if hit:
        return value
    # (the value's key order kept: what is packaged from it is written in that order)
    value = json.loads(json.dumps(compute()))
    text = json.dumps({"kind": kind, "sha256": _value_sha256(value), "value": value})
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        atomic_write_text(path, text)
        prune()
    except OSError:                                    # a read-only or full disk: computed, not kept
        pass
    return value


def peek(kind: str, parts: dict) -> Any:
    """The cached value of ``kind`` for ``parts`` (:func:`remember`), None on a miss: nothing is
    computed or written (a damaged entry is removed)."""
    if not enabled():
        return None
    return _read_value(folder() / kind / f"{key(kind, parts)}.json")[1]


def files(kind: str, parts: dict) -> dict[str, bytes] | None:
    """The files stored under ``kind`` for ``parts`` ({file name: bytes}), None on a miss (or with
    the cache off). Every file is checked against the hash its entry holds: an entry that does not
    match (a file damaged, truncated, patched or missing) is removed, a miss. A hit marks the entry
    as recently used."""
    if not enabled():
        return None
    entry = folder() / kind / key(kind, parts)
    if not entry.is_dir():
        return None
    try:
        index = json.loads((entry / _INDEX).read_text(encoding="utf-8"))
        found = {str(n): (entry / str(n)).read_bytes() for n in index}
        whole = isinstance(index, dict) and all(hashlib.sha256(raw).hexdigest() == index[n] for n, raw in found.items())
    except (OSError, ValueError, TypeError, AttributeError):
        whole = False
    if not whole:
        _remove(entry)                                 # made again by the caller, stored anew
        return None
    os.utime(entry)
    return found


_INDEX = ".files.json"


def store_files(kind: str, parts: dict, content: dict[str, bytes]) -> None:
    """Store ``content`` ({plain file name: bytes}) under ``kind`` for ``parts``, with the hash of
    each file: written into a temporary folder, then renamed into place (a reader sees all of it
    or nothing); a whole entry already there is kept, a damaged one replaced. Then the folder is
    pruned to its size bound. A full or read-only disk is not an error: nothing is kept."""
    if not enabled():
        return
    for name in content:
        if not name or "/" in name or "\\" in name or name.startswith(".") or name in (".", ".."):
            raise ValueError(f"cache entry {kind}: {name!r} is not a plain file name")
    if files(kind, parts) is not None:                 # (a damaged entry is removed by the check)
        return
    entry = folder() / kind / key(kind, parts)
    try:
        entry.parent.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(prefix=f".{entry.name}.", dir=entry.parent))
        try:
            for name, raw in content.items():
                (tmp / name).write_bytes(raw)
            index = {name: hashlib.sha256(raw).hexdigest() for name, raw in sorted(content.items())}
            (tmp / _INDEX).write_text(json.dumps(index), encoding="utf-8")
            os.chmod(tmp, 0o755)
            os.rename(tmp, entry)                     # atomic; fails if another writer was first
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
    except OSError:
        return
    prune()


class CacheSettingError(ValueError):
    """A cache setting of the environment that is not a value latobs can use."""


def _max_bytes() -> float:
    text = os.environ.get(ENV_MAX, "").strip()
    try:
        mb = float(text) if text else MAX_MB
    except ValueError:
        mb = float("nan")
    if not mb >= 0 or mb == float("inf"):
        raise CacheSettingError(f"{ENV_MAX}={text!r}: the cache folder's size bound must be a number of "
                                "megabytes >= 0")
    return mb * 1e6


def prune(max_bytes: float | None = None) -> int:
    """Remove the least recently used entries until the folder holds at most ``max_bytes`` (default
    ``$LATOBS_CACHE_MAX_MB``); returns how many were removed. Temporaries older than an hour
    (an interrupted writer's) go too."""
    limit = _max_bytes() if max_bytes is None else max_bytes
    root = folder()
    if not root.is_dir():
        return 0
    entries, total, now = [], 0, time.time()
    for kind_dir in root.iterdir():
        if not kind_dir.is_dir():
            continue
        for entry in kind_dir.iterdir():
            try:
                st = entry.stat()
                size = (sum(f.stat().st_size for f in entry.iterdir()) if entry.is_dir() else st.st_size)
            except OSError:
                continue
            if entry.name.startswith(".") and now - st.st_mtime > 3600:
                _remove(entry)
                continue
            entries.append((st.st_mtime, size, entry))
            total += size
    removed = 0
    for _, size, entry in sorted(entries, key=lambda e: e[0]):
        if total <= limit:
            break
        _remove(entry)
        total -= size
        removed += 1
    return removed


def _remove(entry: Path) -> None:
    if entry.is_dir():
        shutil.rmtree(entry, ignore_errors=True)
    else:
        try:
            entry.unlink()
        except OSError:
            pass


@lru_cache(maxsize=None)
def _versions() -> tuple:
    from importlib.metadata import PackageNotFoundError, version

    found = []
    for name in ("cvxpy", "clarabel", "numpy", "scipy", "sympy"):
        try:
            found.append((name, version(name)))
        except PackageNotFoundError:
            found.append((name, ""))
    return tuple(found)


def solver_versions() -> dict[str, str]:
    """The versions of the packages a design's numbers come from (part of a design's cache key)."""
    return dict(_versions())
