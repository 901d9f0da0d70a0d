"""What an FMI 3.0 FMU of a native C model adds to the FMI 2.0 one (``latobs build --fmi 3``).

The same model file, data and ``fmu_config.h`` as the FMI 2.0 FMU (:func:`latobs.cbackend.build_c_fmu`
builds both), compiled with ``fmu_src/c/fmi3_layer.c`` instead of ``fmi2_layer.c``; here:

* the FMI 3.0 model description, made from the FMI 2.0 one's parts (``latobs.fmu_src.framework``:
  the variable table, units and display units, bounds, ModelExchange dependencies);
* the platform folders as FMI 3.0 names them (:data:`FOLDERS`; darwin: the universal library the
  toolchain makes, split into its two thin files);
* the gain matrices as array constants (each emitter's ``gains(data)``), readable with
  ``fmi3GetFloat64``, each declared with its dimensions;
* ``terminalsAndIcons/``: the inputs grouped by sensor (observers) or source (plants), the outputs
  by estimate (:data:`TERMINALS`), and the FMU's icon.

Value references are the FMI 2.0 FMU's (parameters, inputs, Float64 outputs, Int32 outputs, the
states and their derivatives), then the event indicators (FMI 3.0 declares them as variables), the
independent variable ``time`` and the gain arrays.
"""
from __future__ import annotations

from typing import NamedTuple
from xml.etree.ElementTree import Element, SubElement, tostring

from ..fmu_src import framework as fw
from ..fmu_src.spec import input_starts, max_step
from .emit import c_array, c_define, c_string

LAYER = ("fmi3_layer.c", "layer_config.c", "layer.h", "layer_config.h", "model.h", "fp_contract.h", "glibc_compat.h")
FMI_HEADERS = ("fmi3Functions.h", "fmi3FunctionTypes.h", "fmi3PlatformTypes.h")
#: ``toolchain.PLATFORMS`` folder -> the FMI 3.0 platform folders made of its library (darwin64's
#: universal Mach-O holds both macOS architectures: each gets its own thin file)
FOLDERS = {"linux64": ("x86_64-linux",), "win64": ("x86_64-windows",),
           "darwin64": ("x86_64-darwin", "aarch64-darwin"), "aarch64-linux": ("aarch64-linux",)}
#: Mach-O cputype of each darwin folder (CPU_TYPE_X86_64, CPU_TYPE_ARM64)
_MACHO_CPU = {"x86_64-darwin": 0x01000007, "aarch64-darwin": 0x0100000C}
TERMINALS_FILE = "terminalsAndIcons/terminalsAndIcons.xml"
ICON_FILE = "terminalsAndIcons/icon.png"

#: Terminals: (name, kind, description, the variables it groups). Observer inputs by sensor, plant
#: inputs by source, outputs by estimate (an estimate's bounds and its status beside it). Every
#: input and output of every FMU belongs to exactly one terminal of its kind (a build refuses one
#: that does not: NativeBuildError naming it).
TERMINALS = {
    "observer-inputs": (
        ("IMU", "sensor", "inertial measurement unit: rates, lateral acceleration, roll angle",
         ("yaw_rate", "roll_rate", "ay", "roll_angle")),
        ("Steering", "sensor", "steering angle sensor", ("delta", "steer_angle")),
        ("WheelSpeeds", "sensor", "longitudinal speed from the wheel speeds", ("vx",)),
    ),
    "plant-inputs": (
        ("Driver", "source", "the driver's (rider's) commands: steering, speed, rider torque",
         ("delta", "vx", "rider_torque")),
        ("Road", "source", "the road: bank angle, grip (tire stiffness scales)",
         ("bank_angle", "stiffness_scale_f", "stiffness_scale_r")),
    ),
    "outputs": (
        ("Sideslip", "estimate", "sideslip angle and lateral velocity",
         ("beta", "vy", "beta_cg", "vy_cg")),
        ("YawRate", "estimate", "yaw rate", ("yaw_rate",)),
        ("LateralAcceleration", "estimate", "lateral acceleration", ("ay",)),
        ("Roll", "estimate", "roll angle and roll rate", ("roll_angle", "roll_rate")),
        ("BankAngle", "estimate", "road bank angle", ("bank_angle",)),
        ("Steering", "estimate", "steering angle and rate", ("steer_angle", "steer_rate")),
        ("RiderTorque", "estimate", "rider steering torque", ("rider_torque",)),
        ("Tires", "estimate", "tire lateral forces, slip angles and camber",
         ("Fyf", "Fyr", "Ff", "Fr", "alpha_f", "alpha_r", "Gamma_f", "Gamma_r")),
        ("Status", "status", "active mode, validity, consistency, residual",
         ("mode", "valid", "consistent", "residual_norm")),
    ),
}
#: suffixes of an estimate's name (beta_hat, vy_lower, beta_filtered, ...): the terminal is the quantity's
_SUFFIXES = ("_hat", "_lower", "_upper", "_filtered")


class GainArray(NamedTuple):
    """A gain matrix (or a stack of them, one per mode) as an FMI 3.0 array constant."""
    name: str
    description: str
    shape: tuple[int, ...]
    values: tuple[float, ...]        # row-major (C order), len = product of shape


def folders(platforms: list[str]) -> list[str]:
    """The FMI 3.0 platform folders of an FMU built for ``platforms`` (``toolchain.PLATFORMS`` folders)."""
    return [f for p in platforms for f in FOLDERS[p]]


def host_folder() -> str | None:
    """The FMI 3.0 platform folder of this machine (None: none of :data:`FOLDERS`)."""
    import platform as _platform

    from .toolchain import host_platform

    host = host_platform()
    if host == "darwin64":
        return "aarch64-darwin" if _platform.machine() in ("arm64", "aarch64") else "x86_64-darwin"
    return FOLDERS[host][0] if host in FOLDERS else None


def binaries(libraries: dict[str, bytes]) -> dict[str, tuple[str, bytes]]:
    """{FMI 3.0 folder: (suffix, library)} from {``toolchain.PLATFORMS`` folder: library}."""
    from .toolchain import SUFFIX, macho_slices

    out = {}
    for platform, raw in libraries.items():
        if platform == "darwin64":
            thin = {cpu: part for cpu, _, part in macho_slices(raw)}
            for folder in FOLDERS[platform]:
                out[folder] = (SUFFIX[platform], thin[_MACHO_CPU[folder]])
        else:
            out[FOLDERS[platform][0]] = (SUFFIX[platform], raw)
    return out


def gain_arrays(emitter, data: dict) -> list[GainArray]:
    """The gain arrays of the FMU of ``data`` (its emitter's ``gains(data)``: (name, description,
    nested list), rectangular); [] when the emitter declares none (the plants)."""
    import numpy as np

    out = []
    for name, description, nested in (emitter.gains(data) if hasattr(emitter, "gains") else ()):
        a = np.asarray(nested, dtype=float)
        if a.ndim == 0 or a.size == 0 or not np.all(np.isfinite(a)):
            raise ValueError(f"gain array {name}: empty, scalar or not finite")
        out.append(GainArray(name, description, tuple(int(n) for n in a.shape), tuple(float(x) for x in a.ravel())))
    return out


def config_tables(gains: list[GainArray]) -> str:
    """The gain arrays' tables of ``fmu_tables.h`` for the FMI 3.0 layer (through layer_config.c)."""
    out = [c_define("N_ARRAYS", len(gains))]
    offsets, pos = [], 0
    for g in gains:
        offsets.append(pos)
        pos += len(g.values)
    out.append("static const char *const ARR_NAMES[] = {" + ", ".join([c_string(g.name) for g in gains] + ["0"])
               + "};\n")
    out.append(c_array("ARR_OFFSET", offsets + [pos], "int"))
    out.append(c_array("ARR_SIZE", [len(g.values) for g in gains] + [0], "int"))
    out.append(c_array("ARR_VALUES", [x for g in gains for x in g.values] + [0.0]))
    return "".join(out)


def _terminal_groups(spec, variables, groups) -> list[tuple[tuple, list[str]]]:
    members: dict[str, list[str]] = {}
    for v in variables:
        stem = next((v.name[: -len(s)] for s in _SUFFIXES if v.name.endswith(s)), v.name)
        group = next((g for g in groups if stem in g[3]), None)
        if group is None:
            raise ValueError(f"variable {v.name!r} belongs to no terminal (latobs.cbackend.fmi3.TERMINALS)")
        members.setdefault(group[0], []).append(v.name)
    return [(g, members[g[0]]) for g in groups if g[0] in members]


def terminals_and_icons(spec, icon_png: bytes, plant: bool) -> dict[str, bytes]:
    """``terminalsAndIcons/terminalsAndIcons.xml`` and the icon: the inputs grouped by sensor (a
    plant's by source), the outputs by estimate, each member a signal named as its variable."""
    root = Element("fmiTerminalsAndIcons", fmiVersion="3.0")
    gr = SubElement(root, "GraphicalRepresentation")
    SubElement(gr, "CoordinateSystem", x1="-100", y1="-100", x2="100", y2="100", suggestedScalingFactorTo_mm="0.1")
    SubElement(gr, "Icon", x1="-100", y1="-100", x2="100", y2="100")
    terms = SubElement(root, "Terminals")
    inputs = TERMINALS["plant-inputs" if plant else "observer-inputs"]
    for variables, groups in ((spec.inputs, inputs), ((*spec.outputs, *spec.integer_outputs), TERMINALS["outputs"])):
        for (name, kind, description, _), members in _terminal_groups(spec, variables, groups):
            is_input = variables is spec.inputs
            t = SubElement(terms, "Terminal", name=f"{name}{'In' if is_input else 'Out'}", matchingRule="bus",
                           terminalKind=f"org.latobs.{kind}", description=description)
            for m in members:
                SubElement(t, "TerminalMemberVariable", variableName=m, memberName=m, variableKind="signal")
    fw._indent(root)
    xml = ('<?xml version="1.0" encoding="UTF-8"?>\n' + tostring(root, encoding="unicode") + "\n").encode("utf-8")
    return {TERMINALS_FILE: xml, ICON_FILE: icon_png}


def event_indicator_name(k: int) -> str:
    """The name of the event indicator ``k`` (0-based) in the model description (the layer's too)."""
    return f"event_indicator_{k + 1}"


def model_description(spec, data: dict, model_identifier: str, token: str, *, native: fw.NativeInterfaces,
                      gains: list[GainArray], version: str, generation_tool: str, copyright: str,
                      license: str = "MIT", author: str = "latobs") -> bytes:
    """modelDescription.xml (FMI 3.0) of the native FMU of ``spec`` with ``data``: UTF-8, deterministic.
    CoSimulation (no event mode, variable steps, FMU state) and, with states, ModelExchange; the
    variables, units, bounds and structure of the FMI 2.0 description (``framework.model_description``),
    then the event indicators, ``time`` and the ``gains`` arrays."""
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
    for vr, typ, caus, v in table:      # a derivative names its state by its value reference
        SubElement(mv, "Float64" if typ == "Real" else "Int32", {
            **fw.variable_attributes(typ, caus, v, vr),
            **fw.value_attributes(typ, caus, v, bounds, starts, in_starts, str(state_vr.get(v.name, "")))})
    first_indicator = len(table)
    indicators = list(range(first_indicator, first_indicator + (native.event_indicators if states else 0)))
    for k, vr in enumerate(indicators):
        SubElement(mv, "Float64", {"name": event_indicator_name(k), "valueReference": str(vr),
                                   "description": "event indicator: an event when its sign changes",
                                   "causality": "local", "variability": "continuous", "initial": "calculated"})
    time_vr = first_indicator + len(indicators)
    SubElement(mv, "Float64", {"name": "time", "valueReference": str(time_vr), "description": "simulation time",
                               "causality": "independent", "variability": "continuous", "unit": "s"})
    for k, g in enumerate(gains):
        el = SubElement(mv, "Float64", {"name": g.name, "valueReference": str(time_vr + 1 + k),
                                        "description": g.description, "causality": "local",
                                        "variability": "constant", "start": " ".join(map(repr, g.values))})
        for n in g.shape:
            SubElement(el, "Dimension", start=str(n))

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
