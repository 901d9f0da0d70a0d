"""The design file ``NAME.design.json``: the one thing that crosses from design time to the FMU.

Keys (CONTRACT.md): name, paper, vehicle (name and every parameter), modes (scheduling value or
range, gain matrices), gamma, certified, checks [{name, value, limit, passed}], solver {name,
status, seconds}; plus what the runtime needs (``runtime``) and the certificate's inputs.
Writes are atomic (temporary file in the same folder, then ``os.replace``).
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from ..atomic import atomic_write_text

SCHEMA = "latobs.design/1"


def _plain(obj):
    if isinstance(obj, np.ndarray):
        return _plain(obj.tolist())
    if isinstance(obj, (np.floating, np.integer)):
        return obj.item()
    if isinstance(obj, dict):
        return {str(k): _plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_plain(v) for v in obj]
    if isinstance(obj, float) and not math.isfinite(obj):
        raise ValueError(f"refusing to write a non-finite number ({obj}) to a design file")
    return obj


def dumps(data: dict) -> str:
    return json.dumps(_plain(data), indent=1, sort_keys=False) + "\n"


def write(data: dict, out_dir: Path) -> Path:
    return atomic_write_text(Path(out_dir) / f"{data['name']}.design.json", dumps(data))


def read(path: Path) -> dict:
    path = Path(path)
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError) as exc:
        raise ValueError(f"{path}: not a readable design file: {exc}") from exc
    if data.get("schema") != SCHEMA:
        raise ValueError(f"{path}: schema {data.get('schema')!r} is not {SCHEMA!r}")
    return data
