"""The design file ``NAME.design.json``: the one thing that crosses from design time to the FMU.
Written atomically under the folder's lock; the copy inside an FMU is :func:`reproducible`
(without wall-clock figures). Its keys are on the documentation's "public interface" page."""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from ..atomic import atomic_write_text, locked_folder

SCHEMA = "latobs.design/1"

#: the values of optional fields a design file may omit, read by whoever builds or checks from it:
#: the Kalman peer's initial covariance ``initial.P0`` and its speed clamp ``runtime.vx_min``/``vx_max`` (m/s)
KALMAN_P0_DEFAULT = [[1.0, 0.0], [0.0, 0.01]]
KALMAN_VX_RANGE_DEFAULT = (1.0, 200.0)


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


def is_wall_time(key: str) -> bool:
    """A key holding a wall-clock measurement (run-dependent)."""
    return key == "seconds" or key.endswith("_seconds")


def reproducible(data):
    """``data`` without its wall-clock figures (:func:`is_wall_time`), at any depth: what an FMU
    carries of its design."""
    if isinstance(data, dict):
        return {k: reproducible(v) for k, v in data.items() if not is_wall_time(str(k))}
    if isinstance(data, (list, tuple)):
        return [reproducible(v) for v in data]
    return data


def path_of(data: dict, out_dir: Path) -> Path:
    """``out_dir/NAME.design.json``; ArtefactNameError if NAME is not an FMI modelIdentifier
    (a name never makes a path outside ``out_dir``)."""
    from .designs import ArtefactNameError, MODEL_IDENTIFIER

    name = str(data.get("name", ""))
    if not MODEL_IDENTIFIER.match(name):
        raise ArtefactNameError(f"design name {name!r} is not an FMI modelIdentifier (ASCII letters, digits and "
                                "underscores, not starting with a digit)")
    return Path(out_dir) / f"{name}.design.json"


def write(data: dict, out_dir: Path) -> Path:
    path = path_of(data, out_dir)
    with locked_folder(out_dir, "design"):
        return atomic_write_text(path, dumps(data))


def read(path: Path) -> dict:
    path = Path(path)
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError) as exc:
        raise ValueError(f"{path}: not a readable design file: {exc}") from exc
    if data.get("schema") != SCHEMA:
        raise ValueError(f"{path}: schema {data.get('schema')!r} is not {SCHEMA!r}")
    return data
