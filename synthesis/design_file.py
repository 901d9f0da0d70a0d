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
    """``data`` without its wall-clock figures (:func:`is_wall_time`), at any depth, and without
    its seal (:data:`SEAL_KEY`): what an FMU carries of its design."""
    if isinstance(data, dict):
        data = {k: v for k, v in data.items() if k != SEAL_KEY}
    return _without_wall_time(data)


def _without_wall_time(data):
    if isinstance(data, dict):
        return {k: _without_wall_time(v) for k, v in data.items() if not is_wall_time(str(k))}
    if isinstance(data, (list, tuple)):
        return [_without_wall_time(v) for v in data]
    return data


#: the key of a written design file holding the SHA-256 of the rest of it (canonical JSON,
#: ``synthesis.identity.sha256_json``): a file whose content no longer matches was edited by hand
SEAL_KEY = "content_sha256"


def sealed(data: dict) -> dict:
    """``data`` with its seal (:data:`SEAL_KEY`, last): what :func:`write` writes."""
    from .identity import sha256_json

    body = {k: v for k, v in data.items() if k != SEAL_KEY}
    return {**body, SEAL_KEY: sha256_json(_plain(body))}


def seal_state(data: dict) -> str:
    """"sealed" (the content is what latobs wrote), "broken" (it carries a seal its content does
    not match: edited by hand) or "missing" (no seal: a design in memory, or a file written by
    another version or by hand)."""
    from .identity import sha256_json

    seal = data.get(SEAL_KEY)
    if seal is None:
        return "missing"
    body = {k: v for k, v in data.items() if k != SEAL_KEY}
    return "sealed" if seal == sha256_json(_plain(body)) else "broken"


def edited_message(path: Path) -> str:
    """What to tell a user whose design file does not match its seal."""
    return (f"{path}: edited by hand (its content no longer matches its {SEAL_KEY}): run `latobs design` "
            "to make it again, or remove it; a design is changed through its vehicle file or design options, "
            "then designed and certified again")


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
    """Write ``out_dir/NAME.design.json`` (:func:`path_of`), sealed (:func:`sealed`)."""
    path = path_of(data, out_dir)
    with locked_folder(out_dir, "design"):
        return atomic_write_text(path, dumps(sealed(data)))


def read(path: Path) -> dict:
    path = Path(path)
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError) as exc:
        raise ValueError(f"{path}: not a readable design file: {exc}") from exc
    if data.get("schema") != SCHEMA:
        raise ValueError(f"{path}: schema {data.get('schema')!r} is not {SCHEMA!r}")
    return data
