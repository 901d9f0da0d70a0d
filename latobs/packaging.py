"""Package FMUs. pythonfmu backend (here): the runtime (``fmu_src``), one data file, pythonfmu's
binaries; the native C backend is ``latobs.cbackend`` (``package_design``/``package_plant`` take
the backend).

An FMU is assembled here file by file, not by pythonfmu's ``FmuBuilder``, so that it is

* **isolated**: pythonfmu's native library imports an FMU's entry module by name and Python
  caches modules by name for the life of the process, while importers (fmpy, libcosim) delete an
  FMU's extraction folder when they unload it. Every module an FMU brings therefore has a name
  unique to its content: the runtime package is ``latobs_rt_<h>`` and the entry module
  ``<Class>_<h>``, with ``h`` the hash of everything the FMU runs (runtime sources, model, class
  name, data file, latobs version). Two different FMUs never share a module, so any sequence of
  them can be loaded, unloaded and reloaded in one process; the same FMU loaded again reuses
  identical code. The FMU carries no ``pythonfmu`` Python package (``framework.py`` speaks the
  native protocol itself);
* **identified by its content**: the ``guid`` is derived from the hash of every file of the FMU
  and of its model description, so the same sources and design give the same guid and other
  gains another. On linux64 a native guard (``latobs.native_guard``, built when a C compiler is
  present) refuses an instantiation with another guid and unknown value references with
  fmi2Error; pythonfmu's own library, which ignores the guid, is shipped beside it;
* **reproducible**: the zip has sorted entries, fixed timestamps and permissions, and the model
  description has no generation date: two builds from the same inputs are byte-identical.

* **documented**: ``documentation/index.html``, the FMU's datasheet, and the icon ``model.png``,
  generated from the model's declarations and its data (``latobs.datasheet``; both backends);

* **identified by its inputs**: ``resources/latobs-identity.json`` holds the identity of what the
  FMU is made from (``latobs.identity``: design or plant inputs, backend, code, toolchain), which
  ``latobs build`` and every command that builds a missing FMU compare before reusing one; the
  design copy inside has no wall-clock figures (``design_file.reproducible``).

A design file is re-certified (``latobs.synthesis.certificate``) before packaging; an uncertified
design is never packaged. The FMU is checked with ``fmpy validate`` and then moved into place
atomically, under the output folder's lock, together with the design file beside it when one is
written (:func:`install`). The gains live in the FMU's own resources folder, read per instance, and an instance
refuses to run if that file's hash is not the one its entry script was built with.
"""
from __future__ import annotations

import hashlib
import warnings
import zipfile
from dataclasses import dataclass
from importlib import import_module
from pathlib import Path
from typing import Callable, Mapping

from . import __version__, catalogue, identity
from .atomic import atomic_paths, locked_folder
from .synthesis import design_file, designs
from .synthesis.params import Vehicle, load_vehicle

from . import fmu_src as _fmu_src  # the runtime's sources are copied, not run, here
from .fmu_src import framework as _framework  # model description only (standard library)

FMU_SRC = Path(_fmu_src.__file__).resolve().parent
COPYRIGHT = "Copyright (c) 2026 the latobs authors"
ZIP_DATE = (1980, 1, 1, 0, 0, 0)  # fixed timestamp of every zip entry (reproducible builds)


class PackagingError(RuntimeError):
    pass


@dataclass(frozen=True)
class FmuKind:
    name: str
    model_module: str          # fmu_src/models/<model_module>.py
    data_kind: str             # "design" (observer) or "plant"
    default_vehicle: str


def _kind(name: str) -> FmuKind:
    e = catalogue.get(name)
    return FmuKind(name, e.model_module, "design" if e.kind == "observer" else "plant", e.default_vehicle)


#: the plant and observer FMUs of the catalogue (``latobs.catalogue``)
PLANTS = {name: _kind(name) for name in catalogue.PLANTS}
OBSERVERS = {name: _kind(name) for name in catalogue.OBSERVERS}


def runtime_sources() -> list[Path]:
    files = sorted(p for p in FMU_SRC.rglob("*.py") if "__pycache__" not in p.parts)
    if not any(p.name == "framework.py" for p in files):
        raise PackagingError(f"FMU runtime sources not found in {FMU_SRC}")
    return files


def plant_data(vehicle: str | Vehicle) -> dict:
    """The data file of a plant FMU: the validated vehicle parameter set (and, for a motorcycle,
    the equations derived from it: ``structure``, see ``motorcycle_data``)."""
    veh = vehicle if isinstance(vehicle, Vehicle) else load_vehicle(vehicle)
    data = {"schema": "latobs.plant/1", "vehicle": veh.as_dict()}
    if veh.kind == "motorcycle":
        data.update(motorcycle_data(veh))
    from .synthesis import tables

    return tables.attach(data)


def motorcycle_data(veh) -> dict:
    """MotorcyclePlant's extra data: the equations of Sharp's motorcycle derived (sympy, at build
    time) for this vehicle, as numbers for the stdlib runtime (fmu_src/motorcycle_plant.py)."""
    from .synthesis.motorcycle_model import plant_structure

    return {"structure": plant_structure(veh)}


def pythonfmu_binaries() -> dict[str, bytes]:
    """pythonfmu's native libraries by platform folder: {"linux64/.so": bytes, "win64/.dll": ...}."""
    from importlib.util import find_spec  # the FMUs carry its binaries, not its Python code: not imported

    spec = find_spec("pythonfmu")
    if spec is None or not spec.submodule_search_locations:
        raise PackagingError("pythonfmu is not installed (its binaries make the pythonfmu backend's FMUs)")
    root = Path(list(spec.submodule_search_locations)[0]).resolve() / "resources" / "binaries"
    out = {}
    for f in sorted(root.rglob("*")):
        if f.is_file() and f.suffix in (".so", ".dll", ".dylib"):
            out[f"{f.parent.name}/{f.suffix}"] = f.read_bytes()
    if not any(k.startswith("linux64/") for k in out):
        raise PackagingError(f"pythonfmu's linux64 binary not found under {root}")
    return out


ENTRY = '''\
# Generated by latobs {version}; do not edit.
# pythonfmu 0.7.0's native loader imports this module by its file name (resources/slavemodule.txt),
# re-executes it at every instantiation and takes the class whose MRO holds a class named
# Fmi2Slave. This module and the runtime package carry the hash of the FMU's content in their
# names: FMUs with other code or data never share a module in one process (see latobs.packaging).
import os as _os
import sys as _sys

_PKG = "{pkg}"


def _rebind_stale_package():
    """If this very FMU was loaded before from a folder the importer has deleted since, point the
    cached package (identical content: same hash) at this folder, so that any submodule not yet
    imported is found here."""
    # this instance's resources folder: pythonfmu has just put it first on sys.path (__file__ may
    # name the folder of an earlier load, since pythonfmu re-executes this file in the cached module)
    here = next((p for p in _sys.path if _os.path.isfile(_os.path.join(p, "{module}.py"))),
                _os.path.dirname(_os.path.abspath(__file__)))
    root = _os.path.join(here, _PKG)
    for name, module in list(_sys.modules.items()):
        if name == _PKG or name.startswith(_PKG + "."):
            path = getattr(module, "__path__", None)
            if path is not None and not all(_os.path.isdir(p) for p in path):
                module.__path__ = [_os.path.join(root, *name.split(".")[1:])]


_rebind_stale_package()
from {pkg}.framework import Fmi2Slave  # noqa: E402
from {pkg}.models.{model} import SPEC  # noqa: E402

# pythonfmu 0.7.0 releases a reference to this module's globals per instantiation that it does
# not own (see _ENTRY_DICT_REFS in the framework, which gives one back per instance); a reserve
# for the first instantiation, before any instance exists.
_GLOBALS_RESERVE = [globals()] * 8

if "{cls}" in globals():
    # pythonfmu re-executes this module (into a scratch namespace) at every instantiation, and
    # instantiates the module's own class: bind that one rather than create a class per instance
    {cls} = globals()["{cls}"]
else:
    class {cls}(Fmi2Slave):
        spec = SPEC
        data_file = "{data_file}"
        data_sha256 = "{data_sha}"
'''


def _guid(digest: str) -> str:
    """A UUID-shaped guid from a content hash (version nibble 5: name-based, SHA)."""
    h = digest[:32]
    return f"{{{h[:8]}-{h[8:12]}-5{h[13:16]}-{h[16:20]}-{h[20:32]}}}"


def write_zip(path: Path, files: Mapping[str, bytes], stored: tuple[str, ...] = ()) -> None:
    """A reproducible zip: entries sorted, fixed date and permissions, fixed compression; names
    ending in one of ``stored`` are not recompressed (e.g. FMUs inside an SSP package)."""
    with zipfile.ZipFile(path, "w") as z:
        for name in sorted(files):
            info = zipfile.ZipInfo(name, date_time=ZIP_DATE)
            info.compress_type = zipfile.ZIP_STORED if name.endswith(stored) else zipfile.ZIP_DEFLATED
            info.external_attr = (0o755 if name.startswith("binaries/") else 0o644) << 16
            info.create_system = 3  # unix, whatever the build machine
            z.writestr(info, files[name], compresslevel=6)


def seal_fmu(files: dict[str, bytes], model_identifier: str, model_description: Callable[[str], bytes],
             guard_variables: list[tuple[int, str, bool]], path: Path,
             native: Callable[[str], dict[str, bytes]] | None = None, native_sources: bytes = b"") -> list[str]:
    """Finish an FMU archive and write it to ``path``; returns fmpy validate's problems.

    ``files`` holds everything but the model description (with pythonfmu's library moved to
    ``binaries/linux64/<id>_pythonfmu.so`` when the native guard is to be built);
    ``model_description(guid)`` gives its bytes. The guid is derived from the content (the
    description without guid, the guard's source, every file), the guard is compiled for it with
    ``guard_variables`` [(value reference, type, settable)], and the zip is reproducible.
    ``native(guid)`` (the native C backend) gives the files that hold the guid (the generated
    configuration header and the compiled library); ``native_sources`` (what they are made from)
    stands for them in the hash."""
    from fmpy.validation import validate_fmu

    from . import native_guard

    guarded = f"binaries/linux64/{model_identifier}_pythonfmu.so" in files
    g = hashlib.sha256(model_description(""))
    if guarded:  # the guard's binary holds the guid; its source stands for it in the hash
        g.update(native_guard.GUARD_SOURCE.read_bytes())
    g.update(native_sources)
    for name in sorted(files):
        g.update(name.encode() + b"\0" + hashlib.sha256(files[name]).digest())
    guid = _guid(g.hexdigest())
    files["modelDescription.xml"] = model_description(guid)
    if native is not None:
        files.update(native(guid))
    if guarded:
        guard = path.with_suffix(".guard.so")
        try:
            native_guard.build_guard(model_identifier, guid, f"{model_identifier}_pythonfmu.so", guard_variables,
                                     guard)
            files[f"binaries/linux64/{model_identifier}.so"] = guard.read_bytes()
        finally:
            guard.unlink(missing_ok=True)
    write_zip(path, files)
    return validate_fmu(str(path))


def check_name(class_name: str) -> str:
    """An FMU's name (its modelIdentifier and file name): ArtefactNameError unless it is an FMI
    modelIdentifier (ASCII letters, digits, underscores, not starting with a digit)."""
    if not isinstance(class_name, str) or not designs.MODEL_IDENTIFIER.match(class_name):
        raise designs.ArtefactNameError(f"FMU name {class_name!r} is not an FMI modelIdentifier (ASCII letters, "
                                        "digits and underscores, not starting with a digit)")
    return class_name


def identity_file(data: dict, backend: str, base: identity.Identity | None = None,
                  platforms: list[str] | None = None) -> dict[str, bytes]:
    """The FMU member holding the identity of the FMU of ``backend`` made from ``data``, whose
    own identity is ``base`` (default: the one ``data`` carries, else its content); a native
    FMU's for ``platforms`` (None: all)."""
    ident = identity.of_fmu(base or identity.of_data(data), backend, platforms)
    return {identity.FMU_MEMBER: identity.fmu_bytes(ident)}


def install(out_dir: Path, class_name: str, seal: Callable[[Path], list[str]],
            beside: Mapping[str, bytes] | None = None, finish: Finish | None = None) -> Path:
    """Write ``out_dir/<class_name>.fmu`` and the files ``beside`` it ({file name: bytes}, e.g. its
    design file) as one unit, under the folder's lock: all to temporaries, then renamed, the FMU
    last. ``seal(tmp)`` writes the FMU to ``tmp`` and returns fmpy validate's problems (any:
    PackagingError, nothing is written). ``finish(tmp)``, if given, runs the sealed FMU and returns
    members to add to it ({archive name: bytes}, e.g. its reference results): they are added
    before the FMU takes its name (they do not enter its guid: they are made from it)."""
    out_dir = Path(out_dir)
    final = out_dir / f"{check_name(class_name)}.fmu"
    beside = dict(beside or {})
    with locked_folder(out_dir, "build"), atomic_paths([*(out_dir / n for n in beside), final]) as tmps:
        for tmp, raw in zip(tmps, beside.values()):
            tmp.write_bytes(raw)
        problems = seal(tmps[-1])
        if problems:
            raise PackagingError(f"{class_name}: fmpy validate found {len(problems)} problem(s): {problems}")
        if finish is not None:
            add_members(tmps[-1], finish(tmps[-1]))
    return final


#: ``finish(sealed FMU) -> {archive name: bytes}`` of :func:`install`
Finish = Callable[[Path], Mapping[str, bytes]]


def add_members(path: Path, extra: Mapping[str, bytes]) -> None:
    """Rewrite the reproducible zip ``path`` (:func:`write_zip`) with the members ``extra`` added
    (none may exist already)."""
    if not extra:
        return
    with zipfile.ZipFile(path) as z:
        files = {n: z.read(n) for n in z.namelist()}
    clash = sorted(set(files) & set(extra))
    if clash:
        raise PackagingError(f"{path.name}: already holds {', '.join(clash)}")
    write_zip(path, {**files, **extra})


def build_fmu(kind: FmuKind, class_name: str, data: dict, out_dir: Path, *,
              base: identity.Identity | None = None, beside: Mapping[str, bytes] | None = None,
              finish: Finish | None = None) -> Path:
    """Build ``out_dir/<class_name>.fmu`` from the runtime and ``data``; returns its path.
    ``base``: the identity of ``data`` (:func:`identity_file`); ``beside``, ``finish``: files
    written with the FMU as one unit, members added to it (:func:`install`)."""
    check_name(class_name)
    data = design_file.reproducible(data)       # no wall-clock figure enters an FMU
    out_dir = Path(out_dir)
    # the runtime must accept its data now, not when a user initialises the FMU
    spec = import_module(f"{_fmu_src.__name__}.models.{kind.model_module}").SPEC
    try:
        spec.runtime(data, {})
    except (ValueError, KeyError, TypeError) as exc:
        raise PackagingError(f"{class_name}: the {kind.name} runtime rejects its data: {exc}") from exc
    data_name = f"{class_name}.{kind.data_kind}.json"
    data_bytes = design_file.dumps(data).encode("utf-8")
    data_sha = hashlib.sha256(data_bytes).hexdigest()

    # content hash of everything the FMU runs -> unique module names
    h = hashlib.sha256()
    for part in (__version__, kind.model_module, class_name, data_sha):
        h.update(part.encode() + b"\0")
    sources = {p.relative_to(FMU_SRC).as_posix(): p.read_bytes() for p in runtime_sources()}
    for rel, raw in sources.items():
        h.update(rel.encode() + b"\0" + hashlib.sha256(raw).digest())
    tag = h.hexdigest()[:16]
    pkg, module = f"latobs_rt_{tag}", f"{class_name}_{tag}"
    entry = ENTRY.format(version=__version__, pkg=pkg, module=module, model=kind.model_module, cls=class_name,
                         data_file=data_name, data_sha=data_sha)

    files: dict[str, bytes] = {f"resources/{pkg}/{rel}": raw for rel, raw in sources.items()}
    files[f"resources/{module}.py"] = entry.encode("utf-8")
    files[f"resources/{data_name}"] = data_bytes
    files["resources/slavemodule.txt"] = module.encode("utf-8")
    files.update(identity_file(data, "python", base))
    binaries = pythonfmu_binaries()
    for key, raw in binaries.items():
        platform, suffix = key.split("/")
        files[f"binaries/{platform}/{class_name}{suffix}"] = raw

    from . import native_guard

    cc = native_guard.find_compiler()
    guarded = cc is not None
    if guarded:  # pythonfmu's library moves aside; the guard takes its name
        files[f"binaries/linux64/{class_name}_pythonfmu.so"] = files.pop(f"binaries/linux64/{class_name}.so")
    else:
        warnings.warn(f"{class_name}: no C compiler found; the FMU has no native guard, so its guid and "
                      "value references are not checked natively (see latobs.native_guard)", stacklevel=2)

    import pythonfmu

    tool = f"latobs {__version__} (pythonfmu {pythonfmu.__version__} binaries)"
    md = lambda guid: _framework.model_description(  # noqa: E731
        spec, data, class_name, guid, version=__version__, generation_tool=tool, copyright=COPYRIGHT)
    guard_variables = [(vr, typ, caus in ("input", "parameter"))
                       for vr, typ, caus, _ in _framework.variable_table(spec)]
    from . import datasheet   # documentation/index.html and model.png

    platforms = sorted({name.split("/")[1] for name in files if name.startswith("binaries/")})
    files.update(datasheet.files(spec, data, class_name, data_kind=kind.data_kind, backend="python",
                                 platforms=platforms, generation_tool=tool, copyright=COPYRIGHT))

    return install(out_dir, class_name, lambda tmp: seal_fmu(files, class_name, md, guard_variables, tmp), beside,
                   finish)


BACKENDS = ("c", "python")


def resolve_backend(requested: str, kind: FmuKind, platforms: list[str] | None = None) -> tuple[str, str | None]:
    """(backend, why) for building ``kind``: ``requested`` "python" or "c" is taken as is (the C
    build then fails with the reason if it cannot be done); "auto" is "c" where the C compilers
    for ``platforms`` (None: all) are present and the runtime has a C model, else "python" with
    ``why`` it fell back."""
    if requested not in (*BACKENDS, "auto"):
        raise PackagingError(f"unknown backend {requested!r}; known: auto, {', '.join(BACKENDS)}")
    if requested != "auto":
        return requested, None
    from . import cbackend

    why = cbackend.unavailable_reason(kind.model_module, platforms)
    return ("python", why) if why else ("c", None)


def _build(kind: FmuKind, class_name: str, data: dict, out_dir: Path, backend: str,
           base: identity.Identity | None = None, beside: Mapping[str, bytes] | None = None,
           platforms: list[str] | None = None, finish: Finish | None = None) -> Path:
    if backend == "c":
        from . import cbackend

        try:
            return cbackend.build_c_fmu(kind, class_name, data, out_dir, base=base, beside=beside,
                                        platforms=platforms, finish=finish)
        except cbackend.NativeBuildError as exc:
            raise PackagingError(str(exc)) from exc
    if platforms is not None:   # pythonfmu's binaries are pythonfmu's platforms
        raise PackagingError(f"{class_name}: the pythonfmu backend ships pythonfmu's binaries; platforms "
                             f"({', '.join(platforms)}) are chosen for native FMUs only")
    return build_fmu(kind, class_name, data, out_dir, base=base, beside=beside, finish=finish)


def package_design(design_path: Path, out_dir: Path, backend: str = "python",
                   platforms: list[str] | None = None, finish: Finish | None = None) -> Path:
    """Re-certify a design file and package its observer FMU (never an uncertified one) with
    ``backend`` "python" (pythonfmu) or "c" (native, ``latobs.cbackend``, for ``platforms``:
    FMI platform folders, None: all of ``latobs.cbackend.toolchain.PLATFORMS``); ``finish``: see
    :func:`install`."""
    return package_design_data(design_file.read(design_path), out_dir, backend, origin=str(design_path),
                               platforms=platforms, finish=finish)


def package_design_data(data: dict, out_dir: Path, backend: str = "python", write_design: bool = False,
                        origin: str | None = None, platforms: list[str] | None = None,
                        finish: Finish | None = None) -> Path:
    """:func:`package_design` of a design dict; with ``write_design`` its design file
    ``out_dir/NAME.design.json`` is written with the FMU, as one unit (:func:`install`)."""
    from .synthesis import certificate, tables  # scipy: only when packaging a design

    origin = origin or f"design {data.get('name')!r}"
    tables.attach(data)   # a design file written without its runtime's tables gets them here
    ok, checks = certificate.certify(data)
    if not ok or not data.get("certified"):
        failed = [c.name for c in checks if not c.passed]
        raise PackagingError(f"{origin}: design is not certified ({', '.join(failed) or 'flag false'}); "
                             "refusing to package it")
    kind = OBSERVERS.get(data.get("design", ""))
    if kind is None:
        raise PackagingError(f"{origin}: no FMU model for design {data.get('design')!r} "
                             f"(known: {', '.join(OBSERVERS)})")
    beside = {design_file.path_of(data, out_dir).name: design_file.dumps(data).encode("utf-8")} if write_design \
        else None
    return _build(kind, data["name"], data, out_dir, backend, beside=beside, platforms=platforms, finish=finish)


def plant_artefact(name: str, vehicle: str | Vehicle | None) -> tuple[FmuKind, Vehicle, str, identity.Identity]:
    """(kind, vehicle, FMU name, identity of its data) of the plant ``name`` for ``vehicle`` (a
    set's name, a TOML file, a Vehicle, or None: the plant's default vehicle); known before the
    data is derived. The FMU is ``PLANT`` for the default vehicle, ``PLANT_V`` otherwise (V the
    set's ``name``, whatever file it came from)."""
    kind = PLANTS.get(name)
    if kind is None:
        raise PackagingError(f"unknown plant {name!r}; known: {', '.join(PLANTS)}")
    veh = vehicle if isinstance(vehicle, Vehicle) else load_vehicle(vehicle or kind.default_vehicle)
    class_name = designs.fmu_name(name, veh.name, kind.default_vehicle)
    return kind, veh, class_name, identity.of_plant(name, class_name, veh)


def package_plant(name: str, vehicle: str | Vehicle | None, out_dir: Path, backend: str = "python",
                  platforms: list[str] | None = None, finish: Finish | None = None) -> Path:
    """Package the plant ``name``'s FMU for ``vehicle`` (:func:`plant_artefact`) with ``backend``
    (native: for ``platforms``, as :func:`package_design`; ``finish``: see :func:`install`)."""
    kind, veh, class_name, base = plant_artefact(name, vehicle)
    return _build(kind, class_name, plant_data(veh), out_dir, backend, base=base, platforms=platforms,
                  finish=finish)
