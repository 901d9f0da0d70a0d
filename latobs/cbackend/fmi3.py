"""FMI 3.0 FMUs of the native C models (work in progress: not yet reachable from ``latobs build``).

The same model file, data and generated ``fmu_config.h`` as the FMI 2.0 FMU of
:func:`latobs.cbackend.build_c_fmu`, compiled with ``fmu_src/c/fmi3_layer.c`` instead of
``fmi2_layer.c``, and an FMI 3.0 model description made from the FMI 2.0 one's parts
(``latobs.fmu_src.framework``: the variable table, units, bounds and ModelExchange dependencies).

Value references are the FMI 2.0 FMU's (parameters, inputs, Float64 outputs, Int32 outputs, the
states and their derivatives), then the event indicators (FMI 3.0 declares them as variables) and
the independent variable ``time``. Platform folders as FMI 3.0 names them (:data:`PLATFORMS`).
"""
from __future__ import annotations

from pathlib import Path
from xml.etree.ElementTree import Element, SubElement, tostring

from .. import __version__
from ..fmu_src import framework as fw
from ..fmu_src.spec import input_starts, max_step
from . import _build_description, _config_header, native_model, native_sources

LAYER = ("fmi3_layer.c", "model.h", "fp_contract.h", "glibc_compat.h")
FMI_HEADERS = ("fmi3Functions.h", "fmi3FunctionTypes.h", "fmi3PlatformTypes.h")
#: FMI 3.0 platform folder -> the ``toolchain.PLATFORMS`` folder that compiles it (darwin: not yet,
#: FMI 3.0 wants one thin library per architecture where the toolchain makes a universal one)
PLATFORMS = {"x86_64-linux": "linux64", "x86_64-windows": "win64", "aarch64-linux": "aarch64-linux"}


def host_platform() -> str | None:
    """The FMI 3.0 platform folder this machine loads, or None."""
    from .toolchain import host_platform as fmi2_host

    host = fmi2_host()
    return next((p3 for p3, p2 in PLATFORMS.items() if p2 == host), None)


def event_indicator_name(k: int) -> str:
    """The name of the event indicator ``k`` (0-based) in the model description (the layer's too)."""
    return f"event_indicator_{k + 1}"


def model_description(spec, data: dict, model_identifier: str, token: str, *, native: fw.NativeInterfaces,
                      version: str, generation_tool: str, copyright: str, license: str = "MIT",
                      author: str = "latobs") -> bytes:
    """modelDescription.xml (FMI 3.0) of the native FMU of ``spec`` with ``data``: UTF-8, deterministic.
    CoSimulation (no event mode, variable steps, FMU state) and, with states, ModelExchange; the
    variables, units, bounds and structure of the FMI 2.0 description (``framework.model_description``)."""
    states = native.states
    root = Element("fmiModelDescription", {
        "fmiVersion": "3.0", "modelName": model_identifier, "instantiationToken": token,
        "description": fw.model_text(spec, data), "author": author, "version": version, "copyright": copyright,
        "license": license, "generationTool": generation_tool, "variableNamingConvention": "flat"})
    common = {"modelIdentifier": model_identifier, "needsExecutionTool": "false",
              "canBeInstantiatedOnlyOncePerProcess": "false", "canGetAndSetFMUState": "true",
              "canSerializeFMUState": "true", "providesDirectionalDerivatives": "false",
              "providesAdjointDerivatives": "false", "providesPerElementDependencies": "false"}
    if states:
        SubElement(root, "ModelExchange", {**common, "needsCompletedIntegratorStep": "false",
                                           "providesEvaluateDiscreteStates": "false"})
    SubElement(root, "CoSimulation", {**common, "canHandleVariableCommunicationStepSize": "true",
                                      "maxOutputDerivativeOrder": "0", "providesIntermediateUpdate": "false",
                                      "mightReturnEarlyFromDoStep": "false", "canReturnEarlyAfterIntermediateUpdate":
                                      "false", "hasEventMode": "false", "providesEvaluateDiscreteStates": "false"})
    table = fw.full_table(spec, states)
    fw.unit_definitions(root, sorted({*fw.used_units(table), "s"}))   # "s": the independent variable's
    fw.log_categories(root)
    longest = max_step(spec, data)
    SubElement(root, "DefaultExperiment", startTime="0", stopTime=fw._num(spec.stop_time),
               stepSize=repr(min(fw.DEFAULT_STEP, longest)))

    starts, in_starts, bounds = fw.start_values(spec, data), input_starts(spec, data), fw.all_bounds(spec, data)
    mv = SubElement(root, "ModelVariables")
    state_vr = {v.name: vr for vr, _, caus, v in table if caus == "state"}
    for vr, typ, caus, v in table:
        attrs = {"name": v.name, "valueReference": str(vr),
                 "description": f"{v.documentation} [{v.unit}]" if v.unit != "1" else v.documentation,
                 "causality": caus}
        if caus == "parameter":
            attrs.update(variability="fixed", initial="exact")
        elif caus == "input":
            attrs["variability"] = "continuous"
        elif caus in ("state", "derivative"):
            attrs.update(causality="local", variability="continuous", initial="calculated")
            if caus == "derivative":
                attrs.update(name=f"der({v.name})", description=f"time derivative of {v.name}")
        else:
            attrs.update(variability="continuous" if typ == "Real" else "discrete", initial="calculated")
        lo, hi = bounds.get(v.name, (v.min, v.max))
        if caus == "derivative":
            attrs["derivative"] = str(state_vr[v.name])
            if v.unit in fw.DERIVATIVE_UNITS:
                attrs["unit"] = fw.DERIVATIVE_UNITS[v.unit]
        else:
            if typ == "Real" and v.unit in fw.BASE_UNITS:
                attrs["unit"] = v.unit
                if v.unit in fw.DISPLAY_UNITS:
                    attrs["displayUnit"] = fw.DISPLAY_UNITS[v.unit][0]
            if lo is not None:
                attrs["min"] = fw._num(lo) if typ == "Real" else str(int(lo))
            if hi is not None:
                attrs["max"] = fw._num(hi) if typ == "Real" else str(int(hi))
            if caus == "parameter":
                attrs["start"] = repr(starts[v.name])
            elif caus == "input":
                attrs["start"] = fw._num(in_starts[v.name])
        SubElement(mv, "Float64" if typ == "Real" else "Int32", attrs)
    first_indicator = len(table)
    indicators = list(range(first_indicator, first_indicator + (native.event_indicators if states else 0)))
    for k, vr in enumerate(indicators):
        SubElement(mv, "Float64", {"name": event_indicator_name(k), "valueReference": str(vr),
                                   "description": "event indicator: an event when its sign changes",
                                   "causality": "local", "variability": "continuous", "initial": "calculated"})
    SubElement(mv, "Float64", {"name": "time", "valueReference": str(first_indicator + len(indicators)),
                               "description": "simulation time", "causality": "independent",
                               "variability": "continuous", "unit": "s"})

    ms = SubElement(root, "ModelStructure")
    deps = fw.me_dependencies(table, native) if states else {}
    outputs = [vr for vr, _, caus, _ in table if caus == "output"]
    for vr in outputs:
        SubElement(ms, "Output", valueReference=str(vr), dependencies=" ".join(map(str, deps.get(vr, []))))
    for vr, _, caus, _ in table:
        if caus == "derivative":
            SubElement(ms, "ContinuousStateDerivative", valueReference=str(vr),
                       dependencies=" ".join(map(str, deps[vr])))
    for vr in sorted(outputs + [vr for vr, _, caus, _ in table if caus in ("state", "derivative")]):
        SubElement(ms, "InitialUnknown", valueReference=str(vr))
    for vr in indicators:
        SubElement(ms, "EventIndicator", valueReference=str(vr))
    ann = SubElement(SubElement(root, "Annotations"), "Annotation", type="org.latobs")
    SubElement(ann, "CommunicationStep", max=repr(longest), unit="s")   # the longest step the layer accepts
    fw._indent(root)
    return ('<?xml version="1.0" encoding="UTF-8"?>\n' + tostring(root, encoding="unicode") + "\n").encode("utf-8")


def build_c_fmu3(kind, class_name: str, data: dict, out_dir: Path, *, platforms: list[str] | None = None) -> Path:
    """Build ``out_dir/<class_name>.fmu``, an FMI 3.0 FMU of the native C model of ``kind`` made
    from ``data``, for ``platforms`` (FMI 3.0 folders of :data:`PLATFORMS`; None: this machine's);
    returns its path. Errors as ``build_c_fmu``'s (NativeBuildError, PackagingError).

    Not yet in it (see FMI3_WIP.md): the datasheet, the identity record and the reference
    experiment of the FMI 2.0 FMU, darwin binaries."""
    from ..packaging import COPYRIGHT, check_name, install, seal_fmu
    from ..synthesis import design_file
    from . import NativeBuildError, toolchain

    check_name(class_name)
    data = design_file.reproducible(data)
    if platforms is None:
        host = host_platform()
        if host is None:
            raise NativeBuildError(f"{class_name}: this machine is none of the FMI 3.0 platforms {', '.join(PLATFORMS)}")
        platforms = [host]
    unknown = [p for p in platforms if p not in PLATFORMS]
    if unknown or not platforms:
        raise NativeBuildError(f"{class_name}: unknown FMI 3.0 platform {unknown[0]!r}" if unknown else
                               f"{class_name}: no platform given (known: {', '.join(PLATFORMS)})")
    platforms = [p for p in PLATFORMS if p in platforms]
    spec, em, cm = native_model(kind, class_name, data, [PLATFORMS[p] for p in platforms])
    sources, model_c = native_sources(kind, class_name, em, cm, LAYER, FMI_HEADERS)
    c_files = ["fmi3_layer.c", model_c]
    sources["buildDescription.xml"] = _build_description(class_name, c_files)
    files = {f"sources/{name}": raw for name, raw in sources.items()}
    files[f"resources/{class_name}.{kind.data_kind}.json"] = design_file.dumps(data).encode("utf-8")
    native = fw.NativeInterfaces(cm.states, cm.n_event_indicators, c_files, cm.dependencies)
    tool = f"latobs {__version__} (native C backend, FMI 3.0)"
    md = lambda token: model_description(  # noqa: E731
        spec, data, class_name, token, native=native, version=__version__, generation_tool=tool,
        copyright=COPYRIGHT)

    def compiled(token: str) -> dict[str, bytes]:
        config = _config_header(spec, data, class_name, token, cm).encode()
        suffix = {p: toolchain.SUFFIX[PLATFORMS[p]] for p in platforms}
        try:
            libraries = toolchain.compile_platforms({PLATFORMS[p]: class_name + suffix[p] for p in platforms},
                                                    {**sources, "fmu_config.h": config}, c_files)
        except toolchain.ToolchainError as exc:
            raise NativeBuildError(f"{class_name}: {exc}") from exc
        return {"sources/fmu_config.h": config,
                **{f"binaries/{p}/{class_name}{suffix[p]}": libraries[PLATFORMS[p]] for p in platforms}}

    stamp = toolchain.describe() + b"\0fmi3\0" + ",".join(platforms).encode()
    return install(Path(out_dir), class_name, lambda tmp: seal_fmu(
        files, class_name, md, [], tmp, native=compiled, native_sources=stamp))
