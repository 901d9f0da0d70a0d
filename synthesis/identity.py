"""The identity of a design (or a plant's data): a hash of everything it is made from.

An identity is a small dict of named *parts* (each a plain value or the SHA-256 of some content)
and the SHA-256 of that dict. A design's is known before anything is solved (the catalogue design,
its artefact name, the vehicle's content, the options, the design-time code, the latobs version),
so a design is solved again only when one of these changes. An FMU's identity adds the backend,
the packaging code and the toolchain to these parts (``latobs.identity``).
"""
from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

from .. import __version__

SCHEMA = "latobs.identity/1"

#: what each part is, for the messages ("rebuilding X.fmu: the vehicle parameters changed")
LABELS = {"kind": "the kind of artefact", "model": "the catalogue model", "artefact": "the artefact name",
          "vehicle": "the vehicle parameters", "options": "the design options", "design_code": "the design code",
          "latobs": "the latobs version", "data": "the design (made outside the catalogue)",
          "backend": "the backend", "packaging_code": "the runtime or packaging code",
          "toolchain": "the toolchain (C compiler, FMI headers, pythonfmu binaries)",
          "platforms": "the platforms", "fmi": "the FMI version"}
#: parts shown with their values when they differ (short plain values, not hashes)
_PLAIN = ("kind", "model", "artefact", "latobs", "backend", "platforms", "fmi")


@dataclass(frozen=True)
class Identity:
    parts: dict

    @property
    def sha256(self) -> str:
        return sha256_json(self.parts)

    def as_dict(self) -> dict:
        return {"schema": SCHEMA, "sha256": self.sha256, "parts": dict(self.parts)}

    def changes(self, old: "Identity | None") -> str:
        """What differs from ``old`` (the identity an existing artefact carries), in words."""
        if old is None:
            return "it carries no build identity (another tool or an older latobs made it)"
        diff = [k for k in sorted(set(self.parts) | set(old.parts)) if self.parts.get(k) != old.parts.get(k)]
        words = [f"{LABELS.get(k, k)} ({old.parts.get(k)} -> {self.parts.get(k)})" if k in _PLAIN
                 else LABELS.get(k, k) for k in diff]
        return ", ".join(words) + " changed" if words else "nothing changed"


def sha256_json(obj) -> str:
    """SHA-256 of ``obj`` as canonical JSON (sorted keys, no spaces)."""
    return hashlib.sha256(json.dumps(obj, sort_keys=True, separators=(",", ":"), default=_plain).encode()).hexdigest()


def _plain(obj):
    """numpy values and tuples of design options as JSON."""
    if hasattr(obj, "tolist"):
        return obj.tolist()
    if hasattr(obj, "__dataclass_fields__"):
        from dataclasses import asdict

        return asdict(obj)
    raise TypeError(f"{type(obj).__name__} in an identity")


def _tree_hash(files) -> str:
    h = hashlib.sha256()
    for rel, path in sorted(files):
        h.update(rel.encode() + b"\0" + hashlib.sha256(Path(path).read_bytes()).digest())
    return h.hexdigest()


def _sources(root: Path, patterns: tuple[str, ...], label: str) -> list[tuple[str, Path]]:
    return [(f"{label}/{p.relative_to(root).as_posix()}", p) for pattern in patterns for p in root.rglob(pattern)
            if "__pycache__" not in p.parts]


@lru_cache(maxsize=None)
def design_code() -> str:
    """Hash of the design-time code (``latobs.synthesis``): designs and plant data come from it."""
    return _tree_hash(_sources(Path(__file__).resolve().parent, ("*.py",), "synthesis"))


def vehicle_hash(vehicle) -> str:
    """The content of a vehicle parameter set (a ``params.Vehicle``), wherever it was read from."""
    return sha256_json(vehicle.as_dict())


def of_design(name: str, vehicle=None, overrides: dict | None = None) -> Identity:
    """The identity of the design ``designs.run(name, vehicle, **overrides)`` would make (known
    before solving): ``vehicle`` a shipped set's name, a TOML file, a loaded ``params.Vehicle``
    or None (the design's default vehicle)."""
    from . import designs
    from .params import Vehicle, load_vehicle

    if not isinstance(vehicle, Vehicle):
        vehicle = load_vehicle(vehicle or designs.get(name).default_vehicle)
    artefact = designs.artefact_name(name, vehicle.name)
    return Identity({"kind": "design", "model": name, "artefact": artefact, "vehicle": vehicle_hash(vehicle),
                     "options": sha256_json(overrides or {}), "design_code": design_code(), "latobs": __version__})


def of_plant(plant: str, artefact: str, vehicle) -> Identity:
    """The identity of a plant FMU's data (``packaging.plant_data``)."""
    return Identity({"kind": "plant", "model": plant, "artefact": artefact, "vehicle": vehicle_hash(vehicle),
                     "design_code": design_code(), "latobs": __version__})


def of_data(data: dict) -> Identity:
    """The identity of a design or plant data dict: the identity it carries (``identity``, see
    :func:`of_design`), else its content (a design made or edited outside the catalogue: also one
    whose seal its content does not match, ``design_file.seal_state``: the inputs it names are not
    what it was made from)."""
    from . import design_file

    carried = data.get("identity")
    if (isinstance(carried, dict) and isinstance(carried.get("parts"), dict)
            and design_file.seal_state(data) != "broken"):
        return Identity(dict(carried["parts"]))

    content = design_file.dumps(design_file.reproducible(data)).encode()
    return Identity({"kind": "data", "data": hashlib.sha256(content).hexdigest(), "latobs": __version__})
