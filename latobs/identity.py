"""The identity of a design, of a plant's data and of an FMU: a hash of everything it is made from
(catalogue design, vehicle content, options, code, toolchain, version, platforms). An artefact is
reused only when its identity equals that of what would be built now; otherwise it is rebuilt,
saying what changed. Every part is run-independent, so an identity can live inside a
reproducible FMU."""
from __future__ import annotations

import hashlib
import json
import zipfile
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

from . import __version__

SCHEMA = "latobs.identity/1"
#: the member of an FMU that holds its identity
FMU_MEMBER = "resources/latobs-identity.json"
_ROOT = Path(__file__).resolve().parent

#: what each part is, for the messages ("rebuilding X.fmu: the vehicle parameters changed")
LABELS = {"kind": "the kind of artefact", "model": "the catalogue model", "artefact": "the artefact name",
          "vehicle": "the vehicle parameters", "options": "the design options", "design_code": "the design code",
          "latobs": "the latobs version", "data": "the design (made outside the catalogue)",
          "backend": "the backend", "packaging_code": "the runtime or packaging code",
          "toolchain": "the toolchain (C compiler, FMI headers, pythonfmu binaries)",
          "platforms": "the platforms"}
#: parts shown with their values when they differ (short plain values, not hashes)
_PLAIN = ("kind", "model", "artefact", "latobs", "backend", "platforms")


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
    from . import synthesis

    return _tree_hash(_sources(Path(synthesis.__file__).resolve().parent, ("*.py",), "synthesis"))


@lru_cache(maxsize=None)
def packaging_code() -> str:
    """Hash of the code an FMU is assembled from: the runtime (Python and C), the packaging, the
    native backend and guard, and this module."""
    from . import fmu_src

    files = _sources(Path(fmu_src.__file__).resolve().parent, ("*.py", "*.c", "*.h"), "fmu_src")
    files += _sources(_ROOT / "cbackend", ("*.py",), "cbackend") + _sources(_ROOT / "native", ("*.c",), "native")
    files += [(name, _ROOT / name)
              for name in ("packaging.py", "native_guard.py", "atomic.py", "identity.py", "datasheet.py")]
    return _tree_hash(files)


@lru_cache(maxsize=None)
def compiler_version(cc: str) -> bytes:
    """What ``cc --version`` says (the compiler's identity; once per process)."""
    import shlex
    import subprocess

    try:
        return subprocess.run([*shlex.split(cc), "--version"], capture_output=True, timeout=60).stdout
    except (OSError, subprocess.SubprocessError) as exc:
        return f"{cc}: {exc}".encode()


def toolchain(backend: str) -> str:
    """Hash of the tools whose output an FMU of ``backend`` holds: the C compilers (native
    backend: ``latobs.cbackend.toolchain.describe``, the system compiler's and zig's versions and
    the flags; pythonfmu backend: the compiler of its native guard and the guard's flags), the FMI
    headers, and for the pythonfmu backend pythonfmu's binaries. Which compilers are found is
    looked up at every call (cheap); what they are, once per process and compiler."""
    if backend == "c":
        from .cbackend import toolchain as c_toolchain

        return _toolchain_c(c_toolchain.describe())
    from .native_guard import find_compiler

    return _toolchain_python(find_compiler())


@lru_cache(maxsize=None)
def _toolchain_c(compilers: bytes) -> str:
    from .cbackend import FMI_HEADERS
    from .native_guard import fmi2_headers

    h = hashlib.sha256(compilers)
    for name in FMI_HEADERS:
        h.update((fmi2_headers() / name).read_bytes())
    return h.hexdigest()


@lru_cache(maxsize=None)
def _toolchain_python(cc: str | None) -> str:
    from .native_guard import CFLAGS as GUARD_FLAGS
    from .packaging import pythonfmu_binaries

    h = hashlib.sha256(b"no C compiler" if cc is None else compiler_version(cc))
    h.update(" ".join(GUARD_FLAGS).encode())
    for key, raw in sorted(pythonfmu_binaries().items()):
        h.update(key.encode() + b"\0" + hashlib.sha256(raw).digest())
    return h.hexdigest()


def vehicle_hash(vehicle) -> str:
    """The content of a vehicle parameter set (a ``params.Vehicle``), wherever it was read from."""
    return sha256_json(vehicle.as_dict())


def of_design(name: str, vehicle=None, overrides: dict | None = None) -> Identity:
    """The identity of the design ``designs.run(name, vehicle, **overrides)`` would make (known
    before solving): ``vehicle`` a shipped set's name, a TOML file, a loaded ``params.Vehicle``
    or None (the design's default vehicle)."""
    from .synthesis import designs
    from .synthesis.params import Vehicle, load_vehicle

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
    :func:`of_design`), else its content (a design made or edited outside the catalogue)."""
    carried = data.get("identity")
    if isinstance(carried, dict) and isinstance(carried.get("parts"), dict):
        return Identity(dict(carried["parts"]))
    from .synthesis import design_file

    content = design_file.dumps(design_file.reproducible(data)).encode()
    return Identity({"kind": "data", "data": hashlib.sha256(content).hexdigest(), "latobs": __version__})


def of_fmu(base: Identity, backend: str, platforms: list[str] | None = None) -> Identity:
    """The identity of the FMU of ``backend`` ("c" or "python") built from the data of ``base``;
    a native FMU's for ``platforms`` (FMI platform folders; None: all), a pythonfmu FMU's holds
    pythonfmu's binaries (the toolchain)."""
    parts = {**base.parts, "backend": backend, "packaging_code": packaging_code(), "toolchain": toolchain(backend)}
    if backend == "c":
        from .cbackend import platforms_of

        parts["platforms"] = ",".join(platforms_of(platforms))
    return Identity(parts)


def fmu_bytes(ident: Identity) -> bytes:
    """The content of :data:`FMU_MEMBER`."""
    return (json.dumps(ident.as_dict(), indent=1, sort_keys=True) + "\n").encode()


def read_fmu(path: Path) -> Identity | None:
    """The identity an FMU carries; None if it has none or cannot be read."""
    try:
        with zipfile.ZipFile(path) as z:
            doc = json.loads(z.read(FMU_MEMBER))
    except (OSError, KeyError, ValueError, zipfile.BadZipFile):
        return None
    parts = doc.get("parts") if isinstance(doc, dict) else None
    return Identity(parts) if isinstance(parts, dict) else None


def fmu_backend(path: Path) -> str | None:
    """"python" (pythonfmu) or "c" (native) for an existing FMU, None if it cannot be read."""
    ident = read_fmu(path)
    if ident is not None and ident.parts.get("backend") in ("c", "python"):
        return ident.parts["backend"]
    try:
        with zipfile.ZipFile(path) as z:
            return "python" if "resources/slavemodule.txt" in z.namelist() else "c"
    except (OSError, zipfile.BadZipFile):
        return None
