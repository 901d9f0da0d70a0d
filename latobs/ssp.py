"""Export a validation scenario as an SSP 1.0 package (``latobs export-ssp``), and run one in fmpy.

The package (a zip, ``.ssp``) is the co-simulation that ``latobs validate SCENARIO`` runs, in the
form other tools read (SSP 1.0, Modelica Association)::

    SystemStructure.ssd             the system: components, connectors, connections, units, the
                                    experiment (start, stop, fixed step)
    resources/ScenarioSignals.fmu   the scenario's input signals (plant inputs), sampled on the
                                    harness's time grid and played back by a small FMU made here
    resources/<plant>.fmu           the plant FMU (CarPlant, MotorcyclePlant, ``_V`` builds)
    resources/<observer>.fmu        each observer FMU, as built
    resources/<component>.ssv       one SSV parameter set per plant and observer: every
                                    parameter of the FMU (the given plant parameters, the
                                    others at their start values), bound with
                                    ``ssd:ParameterBinding source=...``

Wiring (that of :mod:`latobs.validation.harness`): the plant's inputs come from the signal
source's outputs of the same names (an optional plant input the scenario does not drive, such as
CarPlant's ``stiffness_scale_f/r``, is not connected and keeps its start value); each observer
input comes from the plant output of the same name, else from the signal source.

Step: ``ssd:DefaultExperiment`` holds start and stop time, and its ``com.opensimulationplatform``
annotation ``osp:FixedStepAlgorithm baseStepSize`` the communication step that libcosim's SSP
loader reads (SSP 1.0 itself has no step size).

Timing. The harness steps every FMU from t_k with the plant's inputs u(t_k) and the observers'
inputs the plant outputs at t_k (a Jacobi scheme: the observer output at t_(k+1) depends on the
bus at t_k). libcosim's fixed-step algorithm is also Jacobi (every FMU steps, then outputs are
copied to inputs), and the signal source outputs after the step from t_k the sample of t_(k+1), so
the plant steps from t_k with u(t_k) and each observer with the plant outputs at t_k: the same
ordering, step for step. Two differences remain. libcosim steps by the difference of two double
time points (round-off). It also initialises the observers with the plant outputs of
initialisation mode, the FMUs' start values (latobs FMUs compute their outputs at
exitInitializationMode), where the harness uses the plant outputs after initialisation: the same
when the plant starts at rest, as in every shipped scenario. fmpy's ``simulate_ssp`` is Jacobi as
well but starts every connection at 0.0 (see :func:`simulate_fmpy`).

The package is validated before it is written (:func:`check_package`; nothing invalid is ever
written): the SSD and every SSV against the SSP 1.0 XML schemas (fmpy's copy, through lxml, always;
pyssp-standard's validator too when it is installed), and the structure against the FMUs' model
descriptions (every connector a variable of its FMU with the same causality and type, every
connection output -> input of one type, every input connector connected exactly once, every bound
parameter a parameter of its FMU).

This module is on the validation side: it reads the built FMUs (fmpy), never their Python.
"""
from __future__ import annotations

import hashlib
import io
import math
import os
import tempfile
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from .atomic import atomic_path

SSD_NAME = "SystemStructure.ssd"
SOURCE_MODEL = "ScenarioSignals"      # model identifier of the signal-source FMU
SOURCE_LABEL = "signals"              # its component name in the SSD
PLANT_LABEL = "plant"                 # as the harness labels the plant
DEFAULT_DT = 0.005                    # s, the harness's communication step (latobs validate)
NS = {
    "ssd": "http://ssp-standard.org/SSP1/SystemStructureDescription",
    "ssc": "http://ssp-standard.org/SSP1/SystemStructureCommon",
    "ssv": "http://ssp-standard.org/SSP1/SystemStructureParameterValues",
    "osp": "http://opensimulationplatform.com/SSP/OSPAnnotations",
    "latobs": "urn:latobs:ssp:1",
}
OSP_ANNOTATION = "com.opensimulationplatform"
LATOBS_ANNOTATION = "org.latobs.export"
TIMING = ("Jacobi fixed step: every FMU steps from t_k with its inputs at t_k (plant: the scenario "
          "signals u(t_k); observers: the plant outputs at t_k), then outputs are copied to inputs. "
          "The signal source outputs after its step from t_k the sample of t_(k+1).")


class SspError(RuntimeError):
    """A user-facing failure of the export (the message names the culprit)."""


# ------------------------------------------------------------------------------------------------
# what the export needs of an FMU
# ------------------------------------------------------------------------------------------------
@dataclass
class FmuVar:
    name: str
    type: str              # Real, Integer, Boolean, String
    causality: str
    unit: str | None = None
    start: Any = None
    min: float | None = None
    max: float | None = None


@dataclass
class FmuInterface:
    """The variables of a built FMU that the SSD refers to (from its modelDescription.xml)."""

    path: Path
    model_name: str
    inputs: list[FmuVar] = field(default_factory=list)
    outputs: list[FmuVar] = field(default_factory=list)
    parameters: list[FmuVar] = field(default_factory=list)
    units: dict[str, dict[str, float]] = field(default_factory=dict)   # unit -> base-unit exponents

    @classmethod
    def read(cls, path: Path, label: str) -> "FmuInterface":
        from fmpy import read_model_description

        try:
            md = read_model_description(str(path))
        except Exception as exc:
            raise SspError(f"{label} ({path}): cannot read its modelDescription.xml: {exc}") from exc
        if md.coSimulation is None:
            raise SspError(f"{label} ({path.name}) has no co-simulation interface")
        me = cls(Path(path), md.modelName)
        for v in md.modelVariables:
            typ = v.type
            if v.causality not in ("input", "output", "parameter"):
                continue
            if typ == "Enumeration":
                raise SspError(f"{label} ({path.name}): variable {v.name!r} is an Enumeration, which libcosim's "
                               "SSP loader cannot connect")
            unit = getattr(v, "unit", None) or getattr(getattr(v, "declaredType", None), "unit", None)
            lo, hi = (None if b in (None, "") else float(b) for b in (getattr(v, "min", None), getattr(v, "max", None)))
            var = FmuVar(v.name, typ, v.causality, unit or None, v.start, lo, hi)
            {"input": me.inputs, "output": me.outputs, "parameter": me.parameters}[v.causality].append(var)
        for u in md.unitDefinitions:
            b = u.baseUnit
            me.units[u.name] = ({k: getattr(b, k) for k in ("kg", "m", "s", "A", "K", "mol", "cd", "rad",
                                                           "factor", "offset")} if b is not None else {})
        return me

    def var(self, name: str) -> FmuVar | None:
        return next((v for v in (*self.inputs, *self.outputs, *self.parameters) if v.name == name), None)

    def start_values(self) -> dict[str, Any]:
        return {p.name: _typed(p.type, p.start) for p in self.parameters}


def _typed(typ: str, value):
    if value is None:
        return None
    if typ == "Real":
        return float(value)
    if typ == "Integer":
        return int(value)
    if typ == "Boolean":
        return value if isinstance(value, bool) else str(value).strip().lower() in ("true", "1")
    return str(value)


# ------------------------------------------------------------------------------------------------
# wiring (the harness's rule)
# ------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Connection:
    start_element: str
    start_connector: str
    end_element: str
    end_connector: str


def scenario_signals(scenario, t: np.ndarray, vehicle) -> dict[str, np.ndarray]:
    """The scenario's signals and parameter signals on the grid t, as the harness samples them."""
    try:
        return scenario.sampled(t, vehicle)
    except ValueError as exc:
        raise SspError(str(exc)) from None


def wiring(scenario, signal_names, plant: FmuInterface, observers: Mapping[str, FmuInterface]) -> list[Connection]:
    """The connections of the harness (:mod:`latobs.validation.harness`, "Wiring"): plant inputs
    from the scenario signals (an optional plant input the scenario does not drive stays
    unconnected, at its start value), each observer input from the plant output of that name,
    else from the scenario signal of that name."""
    signal_names = list(signal_names)
    optional = set(getattr(scenario, "optional_plant_inputs", ()))
    conns = []
    missing = [v.name for v in plant.inputs if v.name not in signal_names and v.name not in optional]
    if missing:
        raise SspError(f"plant {plant.model_name}: input(s) {', '.join(repr(m) for m in missing)} not provided by "
                       f"scenario {scenario.name!r} (it provides {', '.join(sorted(signal_names))})")
    for v in plant.inputs:
        if v.name in signal_names:
            conns.append(Connection(SOURCE_LABEL, v.name, PLANT_LABEL, v.name))
    plant_out = {v.name for v in plant.outputs}
    for label, f in observers.items():
        for v in f.inputs:
            if v.name in plant_out:
                conns.append(Connection(PLANT_LABEL, v.name, label, v.name))
            elif v.name in signal_names:
                conns.append(Connection(SOURCE_LABEL, v.name, label, v.name))
            else:
                raise SspError(f"observer {label} ({f.path.name}): input {v.name!r} has no signal: neither a "
                               f"{plant.model_name} output nor a signal of scenario {scenario.name!r}")
    return conns


# ------------------------------------------------------------------------------------------------
# the signal-source FMU
# ------------------------------------------------------------------------------------------------
SOURCE_ENTRY = '''\
# Generated by latobs {version} (latobs export-ssp); do not edit. Standard library only.
# Scenario {scenario!r}: its input signals sampled every {dt!r} s from t = {t0!r} s, played back as
# outputs with a zero-order hold: after a step to time t the outputs are the sample at or before t,
# the last sample after the end. pythonfmu 0.7.0's native library imports this module by its name
# (resources/slavemodule.txt, unique to the content) and instantiates the class whose MRO holds a
# class named Fmi2Slave.
import csv as _csv
import hashlib as _hashlib
import math as _math
import os as _os
import sys as _sys

_DATA = {data_file!r}
_DATA_SHA256 = {data_sha!r}
_T0 = {t0!r}
_DT = {dt!r}
_NAMES = {names!r}      # the outputs, value references 0, 1, ...
_OK, _WARNING, _ERROR = 0, 1, 3

# pythonfmu 0.7.0 releases, per instantiation, one reference to this module's __dict__ that it does
# not own (NTNU-IHB/PythonFMU#228): each instance hands one back. pythonfmu re-executes this file in
# the same module at each instantiation: the list survives that, the reserve covers the first one.
_ENTRY_DICT_REFS = globals().get("_ENTRY_DICT_REFS", [])
_GLOBALS_RESERVE = [globals()] * 8
_EXIT_HOOKS = globals().get("_EXIT_HOOKS", {{}})


class _LogMsg:
    __slots__ = ("status", "category", "msg")

    def __init__(self, status, category, msg):
        self.status, self.category, self.msg = status, category, msg


def _defuse_pythonfmu_exit(resources):
    """Without the native guard (no C compiler at export time) and in a Python host, finalize
    pythonfmu's interpreter state from a Python atexit handler, before pythonfmu's static
    destructors have run (its exit-time use-after-free; see latobs.native_guard)."""
    try:
        exe = _os.path.realpath("/proc/self/exe") if _os.path.exists("/proc/self/exe") else _sys.executable
        if not _os.path.basename(exe or "").startswith("python"):
            return
        folder = _os.path.join(_os.path.dirname(_os.path.abspath(resources)), "binaries")
        libs = [_os.path.join(r, f) for r, _d, fs in _os.walk(folder) for f in fs if f.endswith(".so")]
        if not libs or any(p.endswith("_pythonfmu.so") for p in libs):
            return
        import atexit
        import ctypes
        for path in libs:
            if path in _EXIT_HOOKS:
                continue
            try:
                lib = ctypes.CDLL(path, mode=_os.RTLD_NOLOAD | _os.RTLD_LAZY)
                fn = lib.finalizePythonInterpreter
            except (OSError, AttributeError):
                continue
            fn.restype, fn.argtypes = None, []
            _EXIT_HOOKS[path] = (lib, fn)
            atexit.register(fn)
    except Exception:
        pass


class Fmi2Slave:
    def __init__(self, instance_name="", resources=None, logger=None, visible=False, **_):
        _ENTRY_DICT_REFS.append(globals())
        self.instance_name = instance_name
        self.log_queue = []
        if resources:
            _sys.path[:] = [p for p in _sys.path if p != resources]
            _defuse_pythonfmu_exit(resources)
        self._fault = ""
        self._rows = self._load(resources or "")
        self._y = self._rows[0] if self._rows else [0.0] * len(_NAMES)

    def _get_log_queue(self):
        return self.log_queue

    def _log(self, msg, status=_OK):
        cat = {{_WARNING: "logStatusWarning", _ERROR: "logStatusError"}}.get(status, "logAll")
        self.log_queue.append(_LogMsg(status, cat, str(msg)))

    def _load(self, resources):
        path = _os.path.join(resources, _DATA)
        try:
            with open(path, "rb") as fh:
                raw = fh.read()
            if _hashlib.sha256(raw).hexdigest() != _DATA_SHA256:
                self._fault = f"{{_DATA}} is not the table this FMU was built with (sha256)"
                return []
            rows = list(_csv.reader(raw.decode("utf-8").splitlines()))
            if rows[0] != ["t", *_NAMES]:
                self._fault = f"{{_DATA}}: unexpected header {{rows[0]}}"
                return []
            return [[float(x) for x in r[1:]] for r in rows[1:]]
        except Exception as exc:
            self._fault = f"cannot read {{_DATA}} from the FMU resources: {{exc}}"
            return []

    def _seek(self, t):
        k = int(_math.floor((t - _T0) / _DT + 1e-6))
        self._y = self._rows[min(max(k, 0), len(self._rows) - 1)]

    def setup_experiment(self, start_time=0.0, stop_time=None, tolerance=None):
        if self._rows and _math.isfinite(start_time):
            self._seek(start_time)

    def enter_initialization_mode(self):
        pass

    def exit_initialization_mode(self):
        if self._fault:
            self._log(self._fault, _ERROR)

    def do_step(self, current_time, step_size):
        try:
            if self._fault:
                self._log(f"step refused at t = {{current_time}}: {{self._fault}}", _ERROR)
                return False
            t = current_time + step_size
            if not (step_size > 0 and _math.isfinite(t)):
                self._log(f"step refused: communication step {{step_size!r}} must be finite and > 0 s", _ERROR)
                return False
            self._seek(t)
            return True
        except Exception as exc:
            self._log(f"step failed at t = {{current_time}}: {{exc!r}}", _ERROR)
            return False

    def terminate(self):
        pass

    def get_real(self, vrs):
        out = []
        for vr in vrs:
            if isinstance(vr, int) and 0 <= vr < len(_NAMES):
                out.append(float(self._y[vr]))
            else:
                self._log(f"fmi2GetReal: value reference {{vr!r}} is not a variable of this FMU", _ERROR)
                out.append(0.0)
        return out

    def _none(self, what, vrs, value):
        for vr in vrs:
            self._log(f"{{what}}: value reference {{vr!r}}: this FMU has only Real outputs", _ERROR)
        return [value for _ in vrs]

    def get_integer(self, vrs):
        return self._none("fmi2GetInteger", vrs, 0)

    def get_boolean(self, vrs):
        return self._none("fmi2GetBoolean", vrs, False)

    def get_string(self, vrs):
        return self._none("fmi2GetString", vrs, "")

    def set_real(self, vrs, values):
        self._none("fmi2SetReal", vrs, None)

    def set_integer(self, vrs, values):
        self._none("fmi2SetInteger", vrs, None)

    def set_boolean(self, vrs, values):
        self._none("fmi2SetBoolean", vrs, None)

    def set_string(self, vrs, values):
        self._none("fmi2SetString", vrs, None)

    def _get_fmu_state(self):
        self._log("fmi2GetFMUstate is not supported by this FMU", _ERROR)
        return {{}}

    def _set_fmu_state(self, state):
        self._log("fmi2SetFMUstate is not supported by this FMU", _ERROR)


class {cls}(Fmi2Slave):
    pass
'''


def _xml_bytes(root) -> bytes:
    from lxml import etree

    return etree.tostring(root, pretty_print=True, xml_declaration=True, encoding="UTF-8")


def _num(x: float) -> str:
    x = float(x)
    return str(int(x)) if x.is_integer() and abs(x) < 1e15 else repr(x)


def build_source_fmu(scenario_name: str, t: np.ndarray, signals: Mapping[str, np.ndarray],
                     units: Mapping[str, str | None], unit_defs: Mapping[str, dict], out: Path) -> Path:
    """Write the signal-source FMU ``out`` (model ``ScenarioSignals``): one Real output per signal,
    the sample at or before the current time (zero-order hold on the grid ``t``, uniform), made
    like latobs' own FMUs (pythonfmu's binaries behind the native guard when a C compiler is
    present, module names unique to the content, no pythonfmu Python package), checked by
    ``fmpy validate``."""
    from lxml import etree

    from . import __version__, native_guard
    from .packaging import COPYRIGHT, pythonfmu_binaries, seal_fmu

    names = list(signals)
    dt = float(t[1] - t[0]) if len(t) > 1 else DEFAULT_DT
    t0 = float(t[0])
    buf = io.StringIO()
    buf.write(",".join(["t", *names]) + "\n")
    for k in range(len(t)):
        buf.write(",".join([repr(float(t[k])), *(repr(float(signals[n][k])) for n in names)]) + "\n")
    data = buf.getvalue().encode("utf-8")
    data_file = "ScenarioSignals.csv"
    data_sha = hashlib.sha256(data).hexdigest()
    h = hashlib.sha256()
    for part in (__version__, SOURCE_ENTRY, data_sha, repr(names), repr(dt), repr(t0)):
        h.update(part.encode() + b"\0")
    tag = h.hexdigest()[:16]
    module = f"{SOURCE_MODEL}_{tag}"
    entry = SOURCE_ENTRY.format(version=__version__, scenario=scenario_name, dt=dt, t0=t0, data_file=data_file,
                                data_sha=data_sha, names=tuple(names), cls=SOURCE_MODEL)
    files: dict[str, bytes] = {f"resources/{module}.py": entry.encode("utf-8"), f"resources/{data_file}": data,
                               "resources/slavemodule.txt": module.encode("utf-8")}
    for key, raw in pythonfmu_binaries().items():
        platform, suffix = key.split("/")
        files[f"binaries/{platform}/{SOURCE_MODEL}{suffix}"] = raw
    guarded = native_guard.find_compiler() is not None
    if guarded:
        files[f"binaries/linux64/{SOURCE_MODEL}_pythonfmu.so"] = files.pop(f"binaries/linux64/{SOURCE_MODEL}.so")

    def model_description(guid: str) -> bytes:
        root = etree.Element("fmiModelDescription", {
            "fmiVersion": "2.0", "modelName": SOURCE_MODEL, "guid": guid,
            "description": f"latobs scenario {scenario_name!r}: its input signals sampled every {dt:g} s, "
                           "played back with a zero-order hold",
            "author": "latobs", "version": __version__, "copyright": COPYRIGHT, "license": "MIT",
            "generationTool": f"latobs {__version__} export-ssp", "variableNamingConvention": "flat",
            "numberOfEventIndicators": "0"})
        etree.SubElement(root, "CoSimulation", {
            "modelIdentifier": SOURCE_MODEL, "needsExecutionTool": "true",
            "canHandleVariableCommunicationStepSize": "true", "canInterpolateInputs": "false",
            "canBeInstantiatedOnlyOncePerProcess": "false", "canNotUseMemoryManagementFunctions": "true",
            "canGetAndSetFMUstate": "false", "canSerializeFMUstate": "false"})
        used = sorted({u for u in (units.get(n) for n in names) if u and u in unit_defs})
        if used:
            ud = etree.SubElement(root, "UnitDefinitions")
            for u in used:
                el = etree.SubElement(ud, "Unit", name=u)
                etree.SubElement(el, "BaseUnit", _base_unit_attrs(unit_defs[u]))
        etree.SubElement(root, "DefaultExperiment", startTime=_num(t0), stopTime=_num(t[-1]), stepSize=repr(dt))
        mv = etree.SubElement(root, "ModelVariables")
        for vr, n in enumerate(names):
            sv = etree.SubElement(mv, "ScalarVariable", name=n, valueReference=str(vr),
                                  description=f"scenario signal {n}", causality="output",
                                  variability="continuous", initial="calculated")
            etree.SubElement(sv, "Real", {"unit": units[n]} if units.get(n) in used else {})
        ms = etree.SubElement(root, "ModelStructure")
        outs = etree.SubElement(ms, "Outputs")
        for vr in range(len(names)):
            etree.SubElement(outs, "Unknown", index=str(vr + 1), dependencies="")
        ini = etree.SubElement(ms, "InitialUnknowns")
        for vr in range(len(names)):
            etree.SubElement(ini, "Unknown", index=str(vr + 1))
        return _xml_bytes(root)

    problems = seal_fmu(files, SOURCE_MODEL, model_description, [(vr, "Real", False) for vr in range(len(names))],
                        Path(out))
    if problems:
        raise SspError(f"the signal-source FMU fails fmpy validate: {problems}")
    return Path(out)


def _base_unit_attrs(exps: Mapping[str, float]) -> dict[str, str]:
    out = {}
    for k, v in exps.items():
        if k in ("factor", "offset"):
            if float(v) != (1.0 if k == "factor" else 0.0):
                out[k] = repr(float(v))
        elif v:
            out[k] = str(int(v))
    return out


# ------------------------------------------------------------------------------------------------
# SSD and SSV
# ------------------------------------------------------------------------------------------------
def _q(prefix: str, tag: str) -> str:
    return f"{{{NS[prefix]}}}{tag}"


def _type_element(parent, prefix: str, typ: str, attrs: Mapping[str, str] | None = None):
    from lxml import etree

    return etree.SubElement(parent, _q(prefix, typ), dict(attrs or {}))


def _units_element(parent, prefix: str, units: Mapping[str, dict]):
    from lxml import etree

    if not units:
        return
    el = etree.SubElement(parent, _q(prefix, "Units"))
    for name in sorted(units):
        u = etree.SubElement(el, _q("ssc", "Unit"), name=name)
        etree.SubElement(u, _q("ssc", "BaseUnit"), _base_unit_attrs(units[name]))


def ssv_bytes(name: str, params: list[tuple[FmuVar, Any]], unit_defs: Mapping[str, dict]) -> bytes:
    """An SSV 1.0 parameter set: one ``ssv:Parameter`` per (variable, value), units declared."""
    from lxml import etree

    root = etree.Element(_q("ssv", "ParameterSet"), nsmap={k: NS[k] for k in ("ssv", "ssc")},
                         version="1.0", name=name)
    ps = etree.SubElement(root, _q("ssv", "Parameters"))
    used = {}
    for var, value in params:
        p = etree.SubElement(ps, _q("ssv", "Parameter"), name=var.name)
        if var.type == "Real":
            attrs = {"value": repr(float(value))}
            if var.unit and var.unit in unit_defs:
                attrs["unit"] = var.unit
                used[var.unit] = unit_defs[var.unit]
        elif var.type == "Integer":
            attrs = {"value": str(int(value))}
        elif var.type == "Boolean":
            attrs = {"value": "true" if value else "false"}
        else:
            attrs = {"value": str(value)}
        _type_element(p, "ssv", var.type, attrs)
    _units_element(root, "ssv", used)
    return _xml_bytes(root)


@dataclass
class Component:
    label: str
    source: str                        # archive path of the FMU
    fmu: FmuInterface
    inputs: list[str]                  # connected input connectors
    ssv: str | None = None             # archive path of its parameter set


def ssd_bytes(system_name: str, description: str, components: list[Component], connections: list[Connection],
              start: float, stop: float, dt: float, info: Mapping[str, str]) -> bytes:
    from lxml import etree

    from . import __version__

    root = etree.Element(_q("ssd", "SystemStructureDescription"),
                         nsmap={k: NS[k] for k in ("ssd", "ssc", "osp", "latobs")},
                         version="1.0", name=system_name, description=description,
                         generationTool=f"latobs {__version__} export-ssp", author="latobs", license="MIT")
    system = etree.SubElement(root, _q("ssd", "System"), name=system_name)
    elements = etree.SubElement(system, _q("ssd", "Elements"))
    units: dict[str, dict] = {}
    for c in components:
        comp = etree.SubElement(elements, _q("ssd", "Component"), name=c.label, source=c.source,
                                type="application/x-fmu-sharedlibrary", implementation="CoSimulation")
        conns = etree.SubElement(comp, _q("ssd", "Connectors"))
        for var in [*(c.fmu.var(n) for n in c.inputs), *c.fmu.outputs]:
            el = etree.SubElement(conns, _q("ssd", "Connector"), name=var.name, kind=var.causality)
            attrs = {}
            if var.type == "Real" and var.unit and var.unit in c.fmu.units:
                attrs["unit"] = var.unit
                units[var.unit] = c.fmu.units[var.unit]
            _type_element(el, "ssc", var.type, attrs)
        if c.ssv:
            pb = etree.SubElement(comp, _q("ssd", "ParameterBindings"))
            etree.SubElement(pb, _q("ssd", "ParameterBinding"), source=c.ssv)
    cs = etree.SubElement(system, _q("ssd", "Connections"))
    for c in connections:
        etree.SubElement(cs, _q("ssd", "Connection"), startElement=c.start_element,
                         startConnector=c.start_connector, endElement=c.end_element, endConnector=c.end_connector)
    _units_element(root, "ssd", units)
    de = etree.SubElement(root, _q("ssd", "DefaultExperiment"), startTime=_num(start), stopTime=_num(stop))
    an = etree.SubElement(etree.SubElement(de, _q("ssd", "Annotations")), _q("ssc", "Annotation"),
                          type=OSP_ANNOTATION)
    alg = etree.SubElement(an, _q("osp", "Algorithm"))
    etree.SubElement(alg, _q("osp", "FixedStepAlgorithm"), baseStepSize=repr(float(dt)))
    an = etree.SubElement(etree.SubElement(root, _q("ssd", "Annotations")), _q("ssc", "Annotation"),
                          type=LATOBS_ANNOTATION)
    etree.SubElement(an, _q("latobs", "Export"), dict(info))
    return _xml_bytes(root)


# ------------------------------------------------------------------------------------------------
# checks
# ------------------------------------------------------------------------------------------------
def _schema_problems(xml: bytes, schema: str, what: str) -> list[str]:
    """Validate against the SSP 1.0 XSD ``schema`` (file name): fmpy's copy through lxml, and
    pyssp-standard's (xmlschema, XSD 1.0; for the SSD also its XSD 1.1 variant with assertions)
    when pyssp-standard is installed."""
    from lxml import etree

    import fmpy

    problems = []
    xsd = etree.XMLSchema(etree.parse(str(Path(fmpy.__file__).parent / "ssp" / "schema" / schema)))
    try:
        doc = etree.fromstring(xml)
    except etree.XMLSyntaxError as exc:
        return [f"{what}: not well-formed XML: {exc}"]
    if not xsd.validate(doc):
        problems += [f"{what}: line {e.line}: {e.message}" for e in xsd.error_log]
    for key in _pyssp_schemas(schema):
        s = _xmlschema(key)
        problems += [f"{what} (pyssp-standard {key}): {e.reason or e.message}" for e in s.iter_errors(xml.decode())]
    return problems


def _pyssp_schemas(schema: str) -> tuple[str, ...]:
    """The pyssp-standard schema keys for ``schema``; none when pyssp-standard is not installed
    (it is a test extra; fmpy's copy of the same XSDs is always used)."""
    from importlib.util import find_spec

    if find_spec("pyssp_standard") is None:
        return ()
    return {"SystemStructureDescription.xsd": ("ssd", "ssd11"),
            "SystemStructureParameterValues.xsd": ("ssv",)}.get(schema, ())


_SCHEMAS: dict[str, Any] = {}


def _xmlschema(key: str):
    if key not in _SCHEMAS:
        import xmlschema
        from pyssp_standard.standard import ModelicaStandard

        path = str(ModelicaStandard.schemas[key])
        _SCHEMAS[key] = (xmlschema.XMLSchema11 if "11" in key else xmlschema.XMLSchema10)(path)
    return _SCHEMAS[key]


def pyssp_compliance(ssd_path: Path) -> None:
    """pyssp-standard's own compliance check of an SSD file (raises on a violation)."""
    from pyssp_standard.ssd import SSD

    SSD(ssd_path, "r").__check_compliance__()


def read_ssd_tree(ssp: Path):
    from lxml import etree

    with zipfile.ZipFile(ssp) as z:
        return etree.fromstring(z.read(SSD_NAME))


def connections_of(ssp: Path) -> list[Connection]:
    root = read_ssd_tree(ssp)
    return [Connection(c.get("startElement"), c.get("startConnector"), c.get("endElement"), c.get("endConnector"))
            for c in root.iterfind("ssd:System/ssd:Connections/ssd:Connection", NS)]


def experiment_of(ssp: Path) -> tuple[float, float, float]:
    """(start, stop, step) in s: ssd:DefaultExperiment and its osp:FixedStepAlgorithm baseStepSize."""
    root = read_ssd_tree(ssp)
    de = root.find("ssd:DefaultExperiment", NS)
    alg = root.find("ssd:DefaultExperiment/ssd:Annotations/ssc:Annotation/osp:Algorithm/osp:FixedStepAlgorithm", NS)
    if de is None or alg is None or de.get("stopTime") is None:
        raise SspError(f"{ssp}: no ssd:DefaultExperiment with a stopTime and an osp:FixedStepAlgorithm")
    return float(de.get("startTime", 0.0)), float(de.get("stopTime")), float(alg.get("baseStepSize"))


def check_package(ssp: Path) -> list[str]:
    """Every problem of the package ``ssp`` (empty list: valid). See the module docstring."""
    problems: list[str] = []
    try:
        z = zipfile.ZipFile(ssp)
    except (OSError, zipfile.BadZipFile) as exc:
        return [f"{ssp}: not a zip archive: {exc}"]
    with z, tempfile.TemporaryDirectory(prefix="latobs_ssp_check_") as tmp:
        names = set(z.namelist())
        if SSD_NAME not in names:
            return [f"{ssp}: no {SSD_NAME}"]
        ssd = z.read(SSD_NAME)
        problems += _schema_problems(ssd, "SystemStructureDescription.xsd", SSD_NAME)
        if _pyssp_schemas("SystemStructureDescription.xsd"):
            (Path(tmp) / SSD_NAME).write_bytes(ssd)
            try:
                pyssp_compliance(Path(tmp) / SSD_NAME)
            except Exception as exc:
                problems.append(f"{SSD_NAME}: pyssp-standard compliance: {exc}")
        if problems:
            return problems
        from lxml import etree

        root = etree.fromstring(ssd)
        fmus: dict[str, FmuInterface] = {}
        kinds: dict[tuple[str, str], tuple[str, str]] = {}       # (element, connector) -> (kind, type)
        for comp in root.iterfind("ssd:System/ssd:Elements/ssd:Component", NS):
            label, src = comp.get("name"), comp.get("source")
            if src not in names:
                problems.append(f"component {label}: source {src!r} is not in the archive")
                continue
            target = Path(tmp) / f"{len(fmus)}.fmu"
            target.write_bytes(z.read(src))
            try:
                f = fmus[label] = FmuInterface.read(target, label)
            except SspError as exc:
                problems.append(str(exc))
                continue
            for con in comp.iterfind("ssd:Connectors/ssd:Connector", NS):
                var = f.var(con.get("name"))
                typ = next((etree.QName(ch).localname for ch in con
                            if etree.QName(ch).namespace == NS["ssc"]), None)
                if var is None or var.causality != con.get("kind") or var.type != typ:
                    problems.append(f"component {label}: connector {con.get('name')!r} ({con.get('kind')}, {typ}) "
                                    f"is not a variable of {src} with that causality and type")
                    continue
                kinds[(label, var.name)] = (var.causality, var.type)
            for pb in comp.iterfind("ssd:ParameterBindings/ssd:ParameterBinding", NS):
                ssv_src = pb.get("source")
                if ssv_src not in names:
                    problems.append(f"component {label}: parameter set {ssv_src!r} is not in the archive")
                    continue
                ssv = z.read(ssv_src)
                found = _schema_problems(ssv, "SystemStructureParameterValues.xsd", ssv_src)
                problems += found
                if found:
                    continue
                for p in etree.fromstring(ssv).iterfind("ssv:Parameters/ssv:Parameter", NS):
                    var = f.var(p.get("name"))
                    typ = etree.QName(p[0]).localname if len(p) else None
                    if var is None or var.causality != "parameter" or var.type != typ:
                        problems.append(f"{ssv_src}: {p.get('name')!r} ({typ}) is not a {typ} parameter of {src}")
        ends: dict[tuple[str, str], int] = {}
        for c in root.iterfind("ssd:System/ssd:Connections/ssd:Connection", NS):
            a = (c.get("startElement"), c.get("startConnector"))
            b = (c.get("endElement"), c.get("endConnector"))
            ka, kb = kinds.get(a), kinds.get(b)
            if ka is None or kb is None or ka[0] != "output" or kb[0] != "input" or ka[1] != kb[1]:
                problems.append(f"connection {'.'.join(map(str, a))} -> {'.'.join(map(str, b))}: not an output -> "
                                f"input connection of one type between declared connectors")
            ends[b] = ends.get(b, 0) + 1
        for key, (kind, _) in kinds.items():
            if kind == "input" and ends.get(key, 0) != 1:
                problems.append(f"input connector {'.'.join(key)} is connected {ends.get(key, 0)} times (must be 1)")
        try:
            start, stop, dt = experiment_of(ssp)
            if not (math.isfinite(stop) and stop > start and dt > 0):
                problems.append(f"experiment: start {start}, stop {stop}, step {dt} are not a run")
        except (SspError, TypeError, ValueError) as exc:
            problems.append(str(exc))
    return problems


# ------------------------------------------------------------------------------------------------
# export
# ------------------------------------------------------------------------------------------------
def default_observers(scenario) -> list[str]:
    """The observers ``latobs validate`` runs by default (as :func:`latobs.pipeline.run_validation`)."""
    from . import catalogue

    return catalogue.default_observers(scenario.plant)


def _check_out(out: Path) -> None:
    """Fail before any work if ``out`` cannot be written: it is a folder, or its nearest existing
    ancestor is not a writable folder (nothing is created here)."""
    if out.is_dir():
        raise SspError(f"--out {out}: is a folder; give the .ssp file to write")
    anc = out.absolute().parent
    while not anc.exists() and anc != anc.parent:
        anc = anc.parent
    if not anc.is_dir():
        raise SspError(f"--out {out}: {anc} is a file, not a folder")
    try:
        fd, probe = tempfile.mkstemp(prefix=".latobs-export.", suffix=".probe", dir=anc)
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        raise SspError(f"--out {out}: cannot write in {anc} ({exc.strerror or exc})") from None


def export_ssp(scenario, observers: list[str] | None = None, out: Path | None = None,
               fmu_dir: Path = Path("build"), plant_parameters: Mapping[str, Any] | None = None,
               plant_vehicle: str | None = None, dt: float = DEFAULT_DT, quiet: bool = False) -> Path:
    """Write the SSP 1.0 package of ``latobs validate SCENARIO`` (same defaults: the default
    observers, FMUs built into ``fmu_dir`` if missing, the plant's default vehicle) to ``out``
    (default ``build/SCENARIO.ssp``), atomically, after :func:`check_package` passed.
    ``scenario`` is a registered name or a :class:`~latobs.validation.scenarios.Scenario` (e.g.
    ``get_scenario("bank-braking", duration=3.0)``). Returns the path written."""
    from . import packaging
    from .pipeline import ensure_fmus, ensure_plant
    from .synthesis import designs
    from .validation import get_scenario

    sc = get_scenario(scenario)                       # unknown: UnknownScenarioError (a KeyError)
    fmu_dir = Path(fmu_dir)
    observers = list(observers or default_observers(sc))
    for n in observers:
        if n in (PLANT_LABEL, SOURCE_LABEL):
            raise SspError(f"observer name {n!r} is reserved for a component of the system")
        if not (fmu_dir / f"{n}.fmu").is_file():
            try:
                designs.parse_artefact(n)
            except KeyError as exc:
                raise SspError(f"--observer {n}: {exc.args[0] if exc.args else exc}") from None
    if len(set(observers)) != len(observers):
        raise SspError(f"--observer: each observer once, got {', '.join(observers)}")
    kind = packaging.PLANTS.get(sc.plant)
    if kind is None:
        raise SspError(f"scenario {sc.name!r} drives plant {sc.plant!r}, which latobs does not build")
    plant_vehicle = plant_vehicle or kind.default_vehicle
    vehicle_name = plant_vehicle
    if str(plant_vehicle).endswith(".toml"):     # a TOML file: its FMU is named after the set's `name`
        from .synthesis.params import load_vehicle

        vehicle_name = load_vehicle(plant_vehicle).name
    out = Path(out) if out is not None else Path("build") / f"{sc.name}.ssp"
    if out.suffix.lower() != ".ssp":
        raise SspError(f"--out {out}: an SSP package is a .ssp file")
    _check_out(out)
    if not dt > 0:
        raise SspError(f"step {dt} s must be > 0")

    fmus = ensure_fmus(observers, fmu_dir)
    plant_path = ensure_plant(sc.plant, plant_vehicle, fmu_dir)     # reused if current, else built
    plant = FmuInterface.read(plant_path, PLANT_LABEL)
    obs = {n: FmuInterface.read(fmus[n], n) for n in observers}

    params = dict(plant_parameters or {})
    known = {p.name: p for p in plant.parameters}
    for k, value in params.items():
        if k not in known:
            raise SspError(f"--plant-param {k}: {plant.model_name} has no parameter {k!r}; its parameters: "
                           f"{', '.join(known) or '(none)'}")
        lo, hi = known[k].min, known[k].max
        if (lo is not None and value < lo) or (hi is not None and value > hi):
            raise SspError(f"--plant-param {k}={value:g}: outside {plant.model_name}'s declared range "
                           f"[{'-inf' if lo is None else f'{lo:g}'}, {'inf' if hi is None else f'{hi:g}'}]")
    t = sc.time_grid(dt)
    try:
        signals = scenario_signals(sc, t, plant_vehicle)
    except (ValueError, KeyError) as exc:
        raise SspError(f"scenario {sc.name!r} for vehicle {plant_vehicle!r}: {exc}") from exc
    conns = wiring(sc, signals, plant, obs)

    units = {v.name: v.unit for v in plant.inputs}
    with tempfile.TemporaryDirectory(prefix="latobs_ssp_") as tmp:
        source = build_source_fmu(sc.name, t, signals, units, plant.units, Path(tmp) / f"{SOURCE_MODEL}.fmu")
        src_fmu = FmuInterface.read(source, SOURCE_LABEL)
        files: dict[str, bytes] = {f"resources/{SOURCE_MODEL}.fmu": source.read_bytes()}
        components = [Component(SOURCE_LABEL, f"resources/{SOURCE_MODEL}.fmu", src_fmu, [])]
        driven = [c.end_connector for c in conns if c.end_element == PLANT_LABEL]
        start = plant.start_values()
        start.update({k: _typed(known[k].type, v) for k, v in params.items()})
        entries = [(PLANT_LABEL, plant_path, plant, driven, start)]
        entries += [(n, fmus[n], obs[n], [v.name for v in obs[n].inputs], obs[n].start_values()) for n in observers]
        for label, path, f, inputs, values in entries:
            src = f"resources/{path.name}"
            if src in files:
                raise SspError(f"two components would share {src}")
            files[src] = path.read_bytes()
            ssv = None
            if f.parameters:
                ssv = f"resources/{label}.ssv"
                files[ssv] = ssv_bytes(label, [(p, values[p.name]) for p in f.parameters], f.units)
            components.append(Component(label, src, f, inputs, ssv))
        info = {"scenario": sc.name, "vehicle": str(vehicle_name), "step": repr(float(dt)),
                "plantParameters": ", ".join(f"{k}={v!r}" for k, v in params.items()) or "nominal",
                "timing": TIMING}
        desc = (f"latobs validate {sc.name}: {plant.model_name} ({vehicle_name}) beside "
                f"{', '.join(observers) or 'no observer'}; {sc.description}")
        files[SSD_NAME] = ssd_bytes(sc.name, desc, components, conns, float(t[0]), float(t[-1]), dt, info)
        try:
            with atomic_path(out, suffix=".ssp") as tmp_ssp:
                packaging.write_zip(tmp_ssp, files, stored=(".fmu",))
                problems = check_package(tmp_ssp)
                if problems:
                    raise SspError(f"the package would not be valid SSP 1.0, nothing written: {'; '.join(problems)}")
        except OSError as exc:
            raise SspError(f"--out {out}: cannot write ({exc.strerror or exc})") from None
    if not quiet:
        print(f"wrote {out}: {len(components)} components ({SOURCE_LABEL}, {PLANT_LABEL}: {plant_path.name}, "
              f"{', '.join(observers)}), {len(conns)} connections, step {dt:g} s, stop {float(t[-1]):g} s; "
              "SSP 1.0 schema-valid")
    return out


# ------------------------------------------------------------------------------------------------
# running a package
# ------------------------------------------------------------------------------------------------
def simulate_fmpy(ssp: Path) -> dict[str, np.ndarray]:
    """Run the package with fmpy's SSP support (``fmpy.ssp.simulation.simulate_ssp``); returns
    {"time": t_1..t_n, "<component>.<output connector>": values at those times}.

    What ``simulate_ssp`` (fmpy 0.3) does and does not, and what is done about it here:

    * it takes stop time and step from its arguments, not from the SSD: they are read from
      ``ssd:DefaultExperiment`` and the ``osp:FixedStepAlgorithm`` annotation (:func:`experiment_of`).
      It advances time by repeated addition while ``time < stop``, so it is given
      ``stop - step/2`` to take exactly n steps;
    * it reads the SSD's ``ssd:ParameterBinding``s but does not apply them; it applies only its
      ``parameter_set`` argument, matching ``<component>.<name>`` to a component by a bare
      prefix (component ``A`` would take ``AB.x`` as a variable ``B.x`` of its own and fail). The
      bound values that differ from the FMUs' start values are passed in it (setting a start value
      again changes nothing); a prefix clash among those is refused with SspError;
    * it does not initialise inputs from connections: at initialisation every input keeps its
      start value, and in the first step every input is 0.0 (the harness and libcosim give the
      first step u(t_0) and the plant outputs at t_0); :func:`fmpy_equivalent` is the scenario
      that the harness runs the same way. The results therefore differ from the harness's from t_1 on by what one step
      with zero inputs does (see the README, "SSP export");
    * each row holds the connector values after the step from its time: the output at t_(k+1).
    """
    from fmpy.ssp.simulation import simulate_ssp
    from fmpy.ssp.ssd import Parameter, ParameterSet, read_ssd

    ssp = Path(ssp)
    start, stop, dt = experiment_of(ssp)
    desc = read_ssd(str(ssp))                        # validates against fmpy's SSP 1.0 schema
    pset = ParameterSet(name="bindings")
    with tempfile.TemporaryDirectory(prefix="latobs_ssp_fmpy_") as tmp, zipfile.ZipFile(ssp) as z:
        comps = [e for e in desc.system.elements if getattr(e, "source", None)]
        for i, comp in enumerate(comps):
            fmu = Path(tmp) / f"{i}.fmu"
            fmu.write_bytes(z.read(comp.source))
            f = FmuInterface.read(fmu, comp.name)
            start_values = f.start_values()
            for binding in comp.parameterBindings:
                for ps in binding.parameterValues:
                    for p in ps.parameters:
                        var = f.var(p.name)
                        if var is None:
                            continue
                        if _typed(var.type, p.value) != start_values.get(p.name):
                            pset.parameters.append(Parameter(name=f"{comp.name}.{p.name}", type=p.type,
                                                             value=p.value, unit=getattr(p, "unit", None)))
    names = [c.name for c in comps]
    for p in pset.parameters:
        owner = p.name.split(".", 1)[0]
        clash = [n for n in names if n != owner and owner.startswith(n)]
        if clash:
            raise SspError(f"fmpy's simulate_ssp would apply parameter {p.name} to component {clash[0]} (bare "
                           "prefix match): rename the components")
    n = int(round((stop - start) / dt))
    res = simulate_ssp(str(ssp), start_time=start, stop_time=start + (n - 0.5) * dt, step_size=dt,
                       parameter_set=pset)
    if len(res) != n:
        raise SspError(f"fmpy's simulate_ssp took {len(res)} steps, expected {n}")
    outputs = {f"{c.name}.{k.name}" for c in comps for k in c.connectors if k.kind == "output"}
    out = {"time": start + dt * np.arange(1, n + 1)}
    for name in res.dtype.names:
        if name in outputs:
            out[name] = np.asarray(res[name])
    return out


def fmpy_equivalent(scenario):
    """The scenario as fmpy's ``simulate_ssp`` runs its package: every signal 0.0 at the start
    time t_0, the scenario's values from t_1 on. The harness on this scenario takes the steps
    ``simulate_ssp`` takes: the plant and the observers initialised with their inputs at their
    start values (``initialise_at_start_values``; the plant's initial state does not depend on
    them) and stepped from t_0 with 0.0, and every later step as in the harness."""
    from .validation.scenarios import Scenario, get_scenario

    base = get_scenario(scenario)

    def zero_first(sig: Mapping[str, np.ndarray], t) -> dict[str, np.ndarray]:
        t = np.asarray(t, dtype=float)
        out = {}
        for k, v in sig.items():
            v = np.array(v, dtype=float, copy=True)
            v[t == 0.0] = 0.0                 # the scenarios' time grids start at 0
            out[k] = v
        return out

    class ZeroAtStart(Scenario):
        def signals(self, t, vehicle="sedan"):
            return zero_first(base.signals(t, vehicle), t)

        def parameter_signals(self, t, vehicle="sedan"):
            return zero_first(base.parameter_signals(t, vehicle), t)

        def info(self, vehicle="sedan"):
            return {**base.info(vehicle), "fmpy_equivalent": "every signal 0.0 at t_0"}

    sc = ZeroAtStart(name=base.name, description=base.description, duration=base.duration, plant=base.plant,
                     settle_time=base.settle_time, signal_names=base.signal_names)
    object.__setattr__(sc, "optional_plant_inputs", tuple(getattr(base, "optional_plant_inputs", ())))
    object.__setattr__(sc, "initialise_at_start_values", True)
    return sc


def harness_trace(result, start: int = 1) -> dict[str, np.ndarray]:
    """A :class:`~latobs.validation.harness.SimResult` as {"time", "<component>.<name>"} from
    sample ``start`` on (1: t_1..t_n, what libcosim and fmpy record): the plant outputs under
    ``plant.``, the other bus signals (the scenario's) under ``signals.``, each observer's outputs
    under its label."""
    plant = FmuInterface.read(Path(result.info["plant_fmu"]), PLANT_LABEL)
    plant_out = {v.name for v in plant.outputs}
    out = {"time": np.asarray(result.time[start:])}
    for k, v in result.bus.items():
        out[f"{PLANT_LABEL if k in plant_out else SOURCE_LABEL}.{k}"] = np.asarray(v[start:])
    for label, outs in result.observers.items():
        for k, v in outs.items():
            out[f"{label}.{k}"] = np.asarray(v[start:])
    return out


def compare(run: Mapping[str, np.ndarray], reference: Mapping[str, np.ndarray]) -> dict[str, float]:
    """Max |run - reference| per signal present in both (same length and times required)."""
    rt, ft = np.asarray(run["time"]), np.asarray(reference["time"])
    if rt.shape != ft.shape or np.max(np.abs(rt - ft), initial=0.0) > 1e-9:
        raise SspError(f"the two runs are not on one time grid ({len(rt)} and {len(ft)} samples)")
    return {k: float(np.max(np.abs(np.asarray(run[k], dtype=float) - np.asarray(reference[k], dtype=float)),
                            initial=0.0))
            for k in reference if k != "time" and k in run}
