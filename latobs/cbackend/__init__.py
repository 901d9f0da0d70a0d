"""The native C backend: FMI 2.0 and FMI 3.0 FMUs with no Python inside (``latobs build --backend c``).

For one FMU (an observer's design file or a plant's data file) the generator writes C sources and
compiles them at build time for every platform asked (``latobs.cbackend.toolchain``: zig cc, the
system C compiler for this machine's platform when there is one):

* ``model_data.h``: the data as ``static const`` C data, written by the model's emitter
  (``latobs/cbackend/<runtime>.py``, one per runtime, beside the Python runtime
  ``fmu_src/<runtime>.py`` it mirrors): certified gains, model coefficients, the step maps
  precomputed for the default communication step, tables;
* ``fmu_config.h``: the sizes and index macros of the variable table (the value references of the
  pythonfmu backend, then the ModelExchange states and derivatives), which the model file compiles
  with; ``fmu_tables.h``: identifiers, the guid, the variables' names, start values and ranges,
  which ``layer_config.c`` hands to the layer;
* compiled with the hand-written sources of ``fmu_src/c``: ``fmi2_layer.c`` (the FMI 2.0 layer;
  ``fmi3_layer.c`` with ``--fmi 3``) over ``layer.h`` (what both layers share: instance, state
  machine, variables, logging, checks; CoSimulation and ModelExchange), ``layer_config.c`` (the
  layer's view of ``fmu_config.h`` and ``fmu_tables.h``, read at run time: the layer itself is
  compiled once per platform for every FMU), ``model.h`` (the layers'
  interface to the model files), ``<runtime>.c`` (the maths), shared helpers (``linalg.h``),
  ``fp_contract.h`` (no FMA contraction, stated in the sources for every compiler that rebuilds
  them; included by ``model.h``) and ``glibc_compat.h`` (the old-glibc baseline, below).

The FMU holds ``binaries/<platform>/<id><suffix>`` for each platform (default all of
``toolchain.PLATFORMS``: ``linux64`` and ``aarch64-linux`` with libc and libm only and no symbol
newer than GLIBC_2.17 (on x86-64 ``glibc_compat.h`` binds the few libm functions that glibc 2.29
re-versioned to their old versions), ``win64`` with the system's universal C runtime only,
``darwin64`` one universal x86-64 + arm64 library), ``sources/`` (every file above, the
standard FMI 2.0 headers taken from fmpy, and a ``buildDescription.xml``; the model description
lists the sources too, so a tool can compile the FMU for another platform),
``resources/<name>.<kind>.json`` (the design or plant file it was built from, for the record: the
library does not read it), and the model description (both interfaces when the model has
continuous states). Like the pythonfmu backend it is reproducible (no dates,
no build id, relative source names) and its guid is derived from its content.
"""
from __future__ import annotations

from importlib import import_module
from pathlib import Path
from xml.etree.ElementTree import Element, SubElement, tostring

from .. import __version__, catalogue
from ..fmu_src import framework as _framework
from ..native_guard import fmi2_headers
from ..fmu_src.spec import input_starts, max_step, refused_above, var_bounds
from .emit import CModel, c_array, c_define, c_string

C_SRC = Path(_framework.__file__).resolve().parent / "c"
#: the FMI 2.0 layer's files: the layer itself first, layer_config.c (its view of the FMU) second
LAYER = ("fmi2_layer.c", "layer_config.c", "layer.h", "layer_config.h", "model.h", "fp_contract.h", "glibc_compat.h")
SHARED_HEADERS = ("linalg.h", "model_util.h")
FMI_HEADERS = ("fmi2Functions.h", "fmi2FunctionTypes.h", "fmi2TypesPlatform.h")
#: the FMI versions the native backend builds (``latobs build --fmi``)
FMI_VERSIONS = (2, 3)

#: the model file (fmu_src/models/<m>.py) -> its emitter module latobs.cbackend.<emitter> (``latobs.catalogue``)
EMITTERS = {**{e.model_module: e.emitter_module for e in catalogue.ENTRIES},
            **{model: dotted.rsplit(".", 1)[-1] for model, dotted in catalogue.PART_EMITTERS.items()}}


class NativeBuildError(RuntimeError):
    pass


def emitter(model_module: str):
    """The emitter module of a model file, or None if that runtime has no C model yet."""
    name = EMITTERS.get(model_module)
    if name is None:
        return None
    try:
        return import_module(f"{__name__}.{name}")
    except ModuleNotFoundError as exc:
        if exc.name == f"{__name__}.{name}":
            return None
        raise


def platforms_of(platforms: list[str] | None) -> list[str]:
    """The platform folders to build: ``platforms`` (each a folder of ``toolchain.PLATFORMS``, in
    that order, once) or, for None, all of them. NativeBuildError naming an unknown one."""
    from . import toolchain   # (imported when used: `python -m latobs.cbackend.toolchain` runs it as __main__)

    if platforms is None:
        return list(toolchain.PLATFORMS)
    unknown = [p for p in platforms if p not in toolchain.PLATFORMS]
    if unknown or not platforms:
        raise NativeBuildError(f"unknown platform {unknown[0]!r}" if unknown else "no platform given"
                               f" (known: {', '.join(toolchain.PLATFORMS)})")
    return [p for p in toolchain.PLATFORMS if p in platforms]


def unavailable_reason(model_module: str, platforms: list[str] | None = None) -> str | None:
    """Why the C backend cannot build this model here for ``platforms`` (None: all) (None: it can)."""
    from . import toolchain

    why = toolchain.missing(platforms_of(platforms))
    if why:
        return why
    if emitter(model_module) is None:
        return f"the {model_module} model has no C implementation"
    return None


def _config_header(spec, data: dict, model_identifier: str, cm: CModel) -> str:
    """fmu_config.h: the sizes, index macros and longest step the model file compiles with (the
    same for both FMI versions: no identifier or token, so a model's object serves both)."""
    groups = (("PAR", spec.parameters), ("IN", spec.inputs), ("OUT", spec.outputs), ("INT", spec.integer_outputs))
    out = ["/* Generated by latobs; do not edit. */\n", "#ifndef FMU_CONFIG_H\n#define FMU_CONFIG_H\n\n"]
    for name, count in (("N_PARAMETERS", len(spec.parameters)), ("N_INPUTS", len(spec.inputs)),
                        ("N_OUTPUTS", len(spec.outputs)), ("N_INT_OUTPUTS", len(spec.integer_outputs)),
                        ("N_STATES", len(cm.states)), ("N_EVENT_INDICATORS", cm.n_event_indicators)):
        out.append(c_define(name, count))
    out.append(c_define("MAX_STEP", max_step(spec, data)))   # s, the longest step, as declared
    out.append(c_define("MAX_STEP_REFUSED_ABOVE", refused_above(spec, data)))   # with its slack
    for prefix, variables in groups:
        for k, v in enumerate(variables):
            if not v.name.isidentifier():
                raise NativeBuildError(f"{model_identifier}: variable name {v.name!r} is not a C identifier")
            out.append(c_define(f"{prefix}_{v.name}", k))
    out.append("\n#endif\n")
    return "".join(out)


def _tables_header(spec, data: dict, model_identifier: str, guid: str, cm: CModel, extra: str = "") -> str:
    """fmu_tables.h, read by layer_config.c only: identifiers, the guid, the variable names, start
    values and declared ranges; ``extra``: more of the layer's tables (the FMI 3.0 gain arrays)."""
    table = _framework.variable_table(spec)
    starts = _framework.start_values(spec, data)
    bounds = {**var_bounds(spec, data, spec.parameters), **var_bounds(spec, data, spec.inputs)}
    out = ["/* Generated by latobs; do not edit. */\n", "#ifndef FMU_TABLES_H\n#define FMU_TABLES_H\n\n",
           "#include <math.h>\n\n", c_define("MODEL_IDENTIFIER", model_identifier),
           c_define("INSTANTIATION_TOKEN", guid)]
    names = [v.name for _, _, _, v in table] + [s.name for s in cm.states] + [f"der({s.name})" for s in cm.states]
    out.append("static const char *const VAR_NAMES[] = {" + ", ".join(map(c_string, names)) + "};\n")

    def lo_hi(v):
        lo, hi = bounds.get(v.name, (v.min, v.max))
        return (-float("inf") if lo is None else lo), (float("inf") if hi is None else hi)

    pars = spec.parameters
    out.append(c_array("PAR_START", [starts[v.name] for v in pars] + [0.0]))
    out.append(c_array("PAR_MIN", [lo_hi(v)[0] for v in pars] + [0.0]))
    out.append(c_array("PAR_MAX", [lo_hi(v)[1] for v in pars] + [0.0]))
    out.append(c_array("IN_START", [input_starts(spec, data)[v.name] for v in spec.inputs] + [0.0]))
    out.append(c_array("IN_MIN", [lo_hi(v)[0] for v in spec.inputs] + [0.0]))
    out.append(c_array("IN_MAX", [lo_hi(v)[1] for v in spec.inputs] + [0.0]))
    out.append(c_array("OUT_START", [v.start for v in spec.outputs] + [0.0]))
    out.append(c_array("INT_START", [int(v.start) for v in spec.integer_outputs] + [0], "int"))
    out.append(extra)
    out.append("\n#endif\n")
    return "".join(out)


def layer_limits() -> dict[str, int]:
    """The sizes the FMI layers' buffers hold (``LAYER_MAX_*`` of ``fmu_src/c/layer_config.h``,
    read from it): {"VARS": per group of variables, "STATES": ..., "EVENT_INDICATORS": ...}."""
    import re

    text = (C_SRC / "layer_config.h").read_text()
    return {k: int(v) for k, v in re.findall(r"#define LAYER_MAX_(\w+) (\d+)", text)}


def check_layer_limits(class_name: str, spec, cm: CModel) -> None:
    """NativeBuildError naming what of this FMU exceeds the layers' buffers (``layer_limits``)."""
    limits = layer_limits()
    counts = {"parameters": (len(spec.parameters), "VARS"), "inputs": (len(spec.inputs), "VARS"),
              "Real outputs": (len(spec.outputs), "VARS"), "Integer outputs": (len(spec.integer_outputs), "VARS"),
              "continuous states": (len(cm.states), "STATES"),
              "event indicators": (cm.n_event_indicators, "EVENT_INDICATORS")}
    for what, (n, key) in counts.items():
        if n > limits[key]:
            raise NativeBuildError(f"{class_name}: {n} {what}, more than the FMI layers hold ({limits[key]}: "
                                   f"LAYER_MAX_{key} of fmu_src/c/layer_config.h)")


def _build_description(model_identifier: str, sources: list[str]) -> bytes:
    """sources/buildDescription.xml (the FMI 3.0 build description, which FMI 2.0 tools read too)."""
    root = Element("fmiBuildDescription", fmiVersion="3.0")
    bc = SubElement(root, "BuildConfiguration", modelIdentifier=model_identifier,
                    description="C99 sources; compile every SourceFile into one shared library <modelIdentifier> "
                                "and link libm")
    sfs = SubElement(bc, "SourceFileSet", language="C99", compilerOptions="-ffp-contract=off")
    for name in sources:
        SubElement(sfs, "SourceFile", name=name)
    SubElement(sfs, "IncludeDirectory", name=".")
    SubElement(bc, "Library", name="m", description="the C maths library (libm)")
    _framework._indent(root)
    return ('<?xml version="1.0" encoding="UTF-8"?>\n' + tostring(root, encoding="unicode") + "\n").encode()


def native_model(kind, class_name: str, data: dict, platforms: list[str]):
    """(spec, emitter module, CModel) of the FMU of ``kind`` made from ``data`` (reproducible) for
    ``platforms`` (folders of ``toolchain.PLATFORMS``): NativeBuildError when this machine cannot
    build it, PackagingError when the runtime rejects the data. Shared by both FMI layers."""
    from ..packaging import PackagingError

    why = unavailable_reason(kind.model_module, platforms)
    if why:
        raise NativeBuildError(f"{class_name}: {why}")
    model = import_module(f"{_framework.__package__}.models.{kind.model_module}")
    spec = model.spec_of(data) if hasattr(model, "spec_of") else model.SPEC   # spec_of: data-dependent variables
    try:
        spec.runtime(data, {})
        em = emitter(kind.model_module)
        cm = em.emit(data)
    except (ValueError, KeyError, TypeError) as exc:
        raise PackagingError(f"{class_name}: the {kind.name} runtime rejects its data: {exc}") from exc
    return spec, em, cm


def native_sources(kind, class_name: str, em, cm: CModel, layer, fmi_headers) -> tuple[dict[str, bytes], str]:
    """({file name: bytes} of ``sources/`` but fmu_config.h, fmu_tables.h and buildDescription.xml, the model's C
    file name): the ``layer`` files and shared headers of ``fmu_src/c``, the model file, the
    ``fmi_headers`` from fmpy and the emitted ``model_data.h``."""
    headers = fmi2_headers()
    model_c = Path(em.SOURCE).name
    sources = {name: (C_SRC / name).read_bytes() for name in (*layer, *SHARED_HEADERS)}
    sources[model_c] = (C_SRC / em.SOURCE).read_bytes()
    sources.update({name: (headers / name).read_bytes() for name in fmi_headers})
    sources["model_data.h"] = (f"/* Generated by latobs {__version__} from {class_name}'s {kind.data_kind} file; "
                               f"do not edit. */\n#ifndef MODEL_DATA_H\n#define MODEL_DATA_H\n\n{cm.header}\n"
                               "#endif\n").encode()
    return sources, model_c


def build_c_fmu(kind, class_name: str, data: dict, out_dir: Path, *, base=None, beside=None,
                platforms: list[str] | None = None, finish=None, fmi: int = 2) -> Path:
    """Build ``out_dir/<class_name>.fmu`` with the native C backend for ``platforms`` (platform
    folders of ``toolchain.PLATFORMS``; None: all), compiled in parallel; returns its path.

    ``fmi``: 2 (FMI 2.0, ``fmi2_layer.c``) or 3 (FMI 3.0, ``fmi3_layer.c`` and the description,
    platform folders, terminals and gain arrays of :mod:`latobs.cbackend.fmi3`): the same model
    file, data and ``fmu_config.h`` either way (so the same model object). ``kind``: a ``latobs.packaging.FmuKind``. The
    Python runtime must accept ``data`` (the same checks as the pythonfmu backend), then the
    model's emitter writes its C data. Raises NativeBuildError when there is no C compiler or no C
    model for this runtime (see :func:`unavailable_reason`) or the compiler fails, PackagingError
    when ``fmpy validate`` does. ``base``, ``beside``, ``finish``: as in
    ``latobs.packaging.build_fmu``."""
    from ..packaging import COPYRIGHT, check_name, identity_file, install, seal_fmu
    from ..synthesis import design_file
    from . import fmi3, toolchain

    if fmi not in FMI_VERSIONS:
        raise NativeBuildError(f"{class_name}: unknown FMI version {fmi!r} (known: {', '.join(map(str, FMI_VERSIONS))})")
    check_name(class_name)
    data = design_file.reproducible(data)       # no wall-clock figure enters an FMU
    platforms = platforms_of(platforms)
    spec, em, cm = native_model(kind, class_name, data, platforms)
    check_layer_limits(class_name, spec, cm)
    layer, headers = (LAYER, FMI_HEADERS) if fmi == 2 else (fmi3.LAYER, fmi3.FMI_HEADERS)
    sources, model_c = native_sources(kind, class_name, em, cm, layer, headers)
    c_files = [layer[0], layer[1], model_c]
    # compiled into objects of their own, each cached by the sources it reads: the layer reads no
    # file of this FMU (layer_config.h), so one object per target serves every FMU; the model file
    # reads its data and sizes but no identifier or token, so its object serves both FMI versions
    common = {layer[0]: (*layer[2:], *headers, *SHARED_HEADERS),
              model_c: ("model.h", "fp_contract.h", "glibc_compat.h", "fmu_config.h", "model_data.h",
                        *SHARED_HEADERS)}
    sources["buildDescription.xml"] = _build_description(class_name, c_files)
    data_name = f"{class_name}.{kind.data_kind}.json"
    files = {f"sources/{name}": raw for name, raw in sources.items()}
    files[f"resources/{data_name}"] = design_file.dumps(data).encode("utf-8")
    files.update(identity_file(data, "c", base, platforms, fmi))

    native = _framework.NativeInterfaces(cm.states, cm.n_event_indicators, c_files, cm.dependencies)
    tool = f"latobs {__version__} (native C backend{', FMI 3.0' if fmi == 3 else ''})"
    folders = platforms if fmi == 2 else fmi3.folders(platforms)
    from ..datasheet import files as datasheet_files   # documentation/index.html and model.png

    files.update(datasheet_files(spec, data, class_name, data_kind=kind.data_kind, backend="c", platforms=folders,
                                 generation_tool=tool, copyright=COPYRIGHT, states=cm.states, fmi=fmi))
    try:
        gains = fmi3.gain_arrays(em, data) if fmi == 3 else []
        if fmi == 3:
            files.update(fmi3.terminals_and_icons(spec, files["model.png"], plant=kind.data_kind == "plant"))
    except ValueError as exc:
        raise NativeBuildError(f"{class_name}: {exc}") from exc
    if fmi == 2:
        md = lambda guid: _framework.model_description(  # noqa: E731
            spec, data, class_name, guid, version=__version__, generation_tool=tool, copyright=COPYRIGHT,
            native=native)
    else:
        md = lambda token: fmi3.model_description(  # noqa: E731
            spec, data, class_name, token, native=native, gains=gains, version=__version__, generation_tool=tool,
            copyright=COPYRIGHT)

    def compiled(guid: str) -> dict[str, bytes]:
        generated = {"fmu_config.h": _config_header(spec, data, class_name, cm).encode(),
                     "fmu_tables.h": _tables_header(spec, data, class_name, guid, cm,
                                                    fmi3.config_tables(gains) if fmi == 3 else "").encode()}
        try:
            libraries = toolchain.compile_platforms({p: class_name + toolchain.SUFFIX[p] for p in platforms},
                                                    {**sources, **generated}, c_files, common=common)
        except toolchain.ToolchainError as exc:
            raise NativeBuildError(f"{class_name}: {exc}") from exc
        held = ({p: (toolchain.SUFFIX[p], raw) for p, raw in libraries.items()} if fmi == 2
                else fmi3.binaries(libraries))
        return {**{f"sources/{name}": raw for name, raw in generated.items()},
                **{f"binaries/{p}/{class_name}{suffix}": raw for p, (suffix, raw) in held.items()}}

    # the compilers' identity, the FMI version and the platforms are part of what the binaries are made from
    stamp = toolchain.describe() + (b"\0fmi3" if fmi == 3 else b"") + b"\0" + ",".join(platforms).encode()
    return install(Path(out_dir), class_name, lambda tmp: seal_fmu(
        files, class_name, md, [], tmp, native=compiled, native_sources=stamp), beside, finish)
