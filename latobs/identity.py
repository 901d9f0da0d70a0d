"""The identity of a design, of a plant's data and of an FMU: a hash of everything it is made from
(catalogue design, vehicle content, options, code, toolchain, version, platforms). An artefact is
reused only when its identity equals that of what would be built now; otherwise it is rebuilt,
saying what changed. Every part is run-independent, so an identity can live inside a
reproducible FMU."""
from __future__ import annotations

import hashlib
import json
import zipfile
from functools import lru_cache
from pathlib import Path

# the design-side identity (design time), re-exported: an FMU's identity extends a design's
from .synthesis.identity import (LABELS, SCHEMA, Identity, _sources, _tree_hash, design_code,  # noqa: F401
                                 of_data, of_design, of_plant, sha256_json, vehicle_hash)

#: the member of an FMU that holds its identity
FMU_MEMBER = "resources/latobs-identity.json"
_ROOT = Path(__file__).resolve().parent

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
    from .cbackend.fmi3 import FMI_HEADERS as FMI3_HEADERS
    from .native_guard import fmi2_headers

    h = hashlib.sha256(compilers)
    for name in (*FMI_HEADERS, *FMI3_HEADERS):
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


def of_fmu(base: Identity, backend: str, platforms: list[str] | None = None, fmi: int = 2) -> Identity:
    """The identity of the FMU of ``backend`` ("c" or "python") built from the data of ``base``;
    a native FMU's for ``platforms`` (``toolchain.PLATFORMS`` folders; None: all) and FMI version
    ``fmi`` (2 or 3; an FMI 2.0 FMU's identity does not name it), a pythonfmu FMU's holds
    pythonfmu's binaries (the toolchain)."""
    parts = {**base.parts, "backend": backend, "packaging_code": packaging_code(), "toolchain": toolchain(backend)}
    if backend == "c":
        from .cbackend import platforms_of

        parts["platforms"] = ",".join(platforms_of(platforms))
    if fmi != 2:
        parts["fmi"] = str(fmi)
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


def fmu_fmi_version(path: Path) -> int | None:
    """2 or 3: the FMI version of an existing FMU (its identity, else its model description's
    ``fmiVersion``); None if it cannot be read."""
    ident = read_fmu(path)
    if ident is not None:
        return int(ident.parts.get("fmi", 2))
    try:
        with zipfile.ZipFile(path) as z:
            return 3 if b'fmiVersion="3.' in z.read("modelDescription.xml")[:2000] else 2
    except (OSError, KeyError, zipfile.BadZipFile):
        return None
