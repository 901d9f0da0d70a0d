"""The content-addressed cache of what latobs computes once per input and reuses: today the
build-time facts of a design (paper 001's longest communication step, which the runtime decides
by probing itself: 5-20 s per design).

An entry's key is the SHA-256 of everything its value is computed from: the design's reproducible
content and the code that decides it (``identity.packaging_code``: the runtimes and the
packaging). A changed design or a changed runtime is another key, so a stale value is never
reused. The folder is ``$LATOBS_CACHE_DIR``, else the user's cache folder (``$XDG_CACHE_HOME`` or
``~/.cache``, then ``latobs``); ``LATOBS_NO_CACHE=1`` (``latobs build --no-cache``) turns it off.
Entries are small JSON files written atomically; an unreadable one is computed again."""
from __future__ import annotations

import json
import os
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Callable, Iterator

from .atomic import atomic_write_text
from .synthesis.identity import sha256_json

ENV_DIR, ENV_OFF = "LATOBS_CACHE_DIR", "LATOBS_NO_CACHE"
VERSION = 1                      # of the entries' layout


def folder() -> Path:
    """The cache folder (not created)."""
    if os.environ.get(ENV_DIR):
        return Path(os.environ[ENV_DIR])
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "latobs"


def enabled() -> bool:
    return os.environ.get(ENV_OFF, "") in ("", "0")


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


def remember(kind: str, parts: dict, compute: Callable[[], Any]) -> Any:
    """The cached value of ``kind`` for ``parts``, else ``compute()`` stored under its key. The
    value must be JSON (what it round-trips to is what every later call gets: also the first)."""
    if not enabled():
        return compute()
    path = folder() / kind / f"{key(kind, parts)}.json"
    try:
        return json.loads(path.read_text(encoding="utf-8"))["value"]
    except (OSError, ValueError, KeyError, TypeError):
        pass                                           # a miss, or an entry that cannot be read
    text = json.dumps({"kind": kind, "value": compute()}, sort_keys=True)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        atomic_write_text(path, text)
    except OSError:                                    # a read-only or full disk: computed, not kept
        pass
    return json.loads(text)["value"]
