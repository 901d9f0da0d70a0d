"""The one FMI 2.0 co-simulation glue of every latobs FMU (pythonfmu backend). No maths here.
Over ~600 lines: the whole layer (the twin of ``c/fmi2_layer.c``) in the one file every FMU carries.

pythonfmu's native library (``binaries/<platform>/<id>.so``, taken unchanged from pythonfmu) embeds
Python, imports the module named in ``resources/slavemodule.txt`` and calls, on an instance of the
class that the regex ``class NAME(Fmi2Slave):`` finds in it, a small set of methods: the
constructor (``instance_name``, ``resources``, ``logger``, ``visible``), ``_get_log_queue``,
``setup_experiment``, ``enter/exit_initialization_mode``, ``do_step``, ``terminate``,
``get/set_real|integer|boolean|string`` and ``_get/_set_fmu_state``. :class:`Fmi2Slave` speaks
that protocol itself (:class:`Fmi2Slave`) instead of subclassing pythonfmu's Python class: an FMU then carries
no ``pythonfmu`` package, so no two FMUs share a module in one process (see ``latobs.packaging``),
every call is as lean as a Python call can be (the per-step cost through fmpy matters), and the
model description is ours to write (:func:`model_description`).

A generated entry script binds a ``ModelSpec`` (``spec.py``) and a data file to this class:

    from latobs_rt_<hash>.framework import Fmi2Slave
    class SideslipBankObserver(Fmi2Slave):
        spec = SPEC; data_file = "SideslipBankObserver.design.json"; data_sha256 = "..."

The host never sees a Python exception (pythonfmu 0.7.0 turns one into fmi2Fatal, and after a
few of them its log buffer handling crashes the host). Every failure is logged and reported as a
status, as documented here:
  * a step size that is not finite and > 0 or exceeds the model's ``max_step``, an input outside
    its declared [min, max] (non-finite ones included; fmi2SetReal stores any value, the step
    checks it), or doStep before exitInitializationMode: the step is refused, the state is kept,
    an error naming the culprit is logged and doStep returns fmi2Discard (pythonfmu maps a
    refused step to fmi2Discard; it has no way to return fmi2Error). The native C layer
    (``c/fmi2_layer.c``) refuses the same steps with the same messages (fmi2Error);
  * an unknown value reference, or one of another type, in a get/set call: an error is logged,
    a set is ignored, a get returns 0 for it. (With the native guard of ``latobs.native_guard``,
    which the linux64 binary has when a C compiler was present at build time, such a call never
    reaches Python: the guard returns a real fmi2Error.) Setting a variable that is not an input
    or a parameter is likewise logged and ignored;
  * the data file differs from the one the FMU was built with (sha256), a parameter is outside
    its declared [min, max], or the runtime rejects its data or parameters at
    exitInitializationMode: logged as an error, every later doStep is refused;
  * parameters set after initialisation are ignored with a warning;
  * warnings of the runtime (clamps, e.g. speed outside the design grid) are logged.
"""
from __future__ import annotations

import hashlib
import json
import math
import os
import pickle
import sys
import traceback
from xml.etree.ElementTree import Element, SubElement, tostring

from .spec import DEFAULT_STEP, ModelSpec, input_starts, max_step, refused_above, var_bounds

#: sha256 of a data file -> its parsed content, pickled: an instance of an FMU whose data file this
#: process has read before gets a fresh copy in ~1/4 of the time of parsing the JSON again (a paper-000
#: tire-mode design file with its tables is 2.7 MB: 19 ms to parse, 4 ms to unpickle). The last
#: _PARSED_KEEP files are kept (a process loading many designs holds a few MB, not one copy each).
_PARSED: dict[str, bytes] = {}
_PARSED_KEEP = 8

# FMI 2.0 status codes (fmi2Status)
OK, WARNING, DISCARD, ERROR, FATAL = 0, 1, 2, 3, 4
_CATEGORY = {WARNING: "logStatusWarning", ERROR: "logStatusError", FATAL: "logStatusFatal"}

# FMI 2.0 base-unit exponents of the units used by the model files; "1" is dimensionless
BASE_UNITS = {
    "1": {}, "rad": {"rad": "1"}, "rad/s": {"rad": "1", "s": "-1"}, "m": {"m": "1"},
    "m/s": {"m": "1", "s": "-1"}, "m/s2": {"m": "1", "s": "-2"}, "N": {"kg": "1", "m": "1", "s": "-2"},
    "N.m": {"kg": "1", "m": "2", "s": "-2"}, "s": {"s": "1"},
    "rad/s2": {"rad": "1", "s": "-2"}, "N/s": {"kg": "1", "m": "1", "s": "-3"}, "m/s3": {"m": "1", "s": "-3"},
    "1/s": {"s": "-1"},
}
# the unit of a state's time derivative (ModelExchange)
DERIVATIVE_UNITS = {"1": "1/s", "rad": "rad/s", "rad/s": "rad/s2", "m": "m/s", "m/s": "m/s2", "m/s2": "m/s3",
                    "N": "N/s"}
# display units offered to tools: (name, factor) with display value = factor * SI value
DISPLAY_UNITS = {"rad": ("deg", 180.0 / math.pi), "rad/s": ("deg/s", 180.0 / math.pi), "m/s": ("km/h", 3.6)}

# pythonfmu 0.7.0's native findClass() ends with Py_DECREF(PyModule_GetDict(module)): it releases,
# on every instantiation, a reference to the entry module's __dict__ that it never owned, so the
# dict is freed after a few instances and the next instantiation crashes the host (upstream issue
# NTNU-IHB/PythonFMU#228). Each instance hands one reference back (see Fmi2Slave.__init__): as a
# bare reference count through the C API (no memory per instance: a host may instantiate millions
# of times), or, where ctypes cannot reach the C API, held in this list.
_ENTRY_DICT_REFS: list = []


def _give_back_entry_dict(module) -> None:
    d = vars(module)
    try:
        import ctypes
        ctypes.pythonapi.Py_IncRef(ctypes.py_object(d))
    except Exception:
        _ENTRY_DICT_REFS.append(d)


class _LogMsg:
    """What pythonfmu's native side reads from the log queue: status, category, msg."""

    __slots__ = ("status", "category", "msg")

    def __init__(self, status: int, category: str, msg: str):
        self.status, self.category, self.msg = status, category, msg


def start_values(spec: ModelSpec, data: dict) -> dict:
    """Parameter start values: the spec's, overridden by the runtime's data-dependent defaults."""
    p = {v.name: float(v.start) for v in spec.parameters}
    defaults = getattr(spec.runtime, "parameter_defaults", None)
    if defaults is not None and data:
        p.update({k: float(x) for k, x in defaults(data).items() if k in p})
    return p


def variable_table(spec: ModelSpec) -> list[tuple[int, str, str, object]]:
    """(value reference, FMI type, causality, Var) in value-reference order: parameters, inputs,
    Real outputs, Integer outputs. The model description and the native guard use this table."""
    rows = [(v, "Real", "parameter") for v in spec.parameters]
    rows += [(v, "Real", "input") for v in spec.inputs]
    rows += [(v, "Real", "output") for v in spec.outputs]
    rows += [(v, "Integer", "output") for v in spec.integer_outputs]
    return [(vr, typ, caus, v) for vr, (v, typ, caus) in enumerate(rows)]


_EXIT_HOOKS: dict = {}          # library path -> finalizePythonInterpreter, see _defuse_pythonfmu_exit


def _defuse_pythonfmu_exit(resources: str) -> None:
    """pythonfmu 0.7.0's exit-time use-after-free, for FMUs without the native guard.

    Its library cannot be unloaded (STB_GNU_UNIQUE symbols); at process exit its static
    destructors run before its ELF destructor ``finalizePythonInterpreter``, which then releases a
    destroyed shared_ptr again (heap corruption; glibc may abort the host at exit). The native
    guard calls that function itself while the library is alive (fmi2_guard.c): nothing to do
    for a guarded FMU (its pythonfmu library is ``<id>_pythonfmu.so``). Without the guard (an FMU
    built without a C compiler, binaries/<platform>/<id>.so is pythonfmu's) and in a PYTHON host
    process (in a C host pythonfmu created the interpreter and finalizes it from that very
    shared_ptr's destructor, where this must not run), a Python ``atexit`` handler calls
    ``finalizePythonInterpreter``; Python's atexit handlers run before the C exit handlers.
    Only a library the host has already loaded is touched (RTLD_NOLOAD). Never raises."""
    try:
        exe = os.path.realpath("/proc/self/exe") if os.path.exists("/proc/self/exe") else sys.executable
        if not os.path.basename(exe or "").startswith("python"):
            return                                   # not a Python host
        folder = os.path.join(os.path.dirname(os.path.abspath(resources)), "binaries")
        libs = [os.path.join(r, f) for r, _d, fs in os.walk(folder) for f in fs if f.endswith(".so")]
        if not libs or any(p.endswith("_pythonfmu.so") for p in libs):
            return                                   # guarded: the guard does it
        import atexit
        import ctypes
        for path in libs:
            if path in _EXIT_HOOKS:
                continue
            try:
                lib = ctypes.CDLL(path, mode=os.RTLD_NOLOAD | os.RTLD_LAZY)
                fn = lib.finalizePythonInterpreter
            except (OSError, AttributeError):
                continue
            fn.restype, fn.argtypes = None, []
            _EXIT_HOOKS[path] = (lib, fn)            # the library is never unloaded anyway
            atexit.register(fn)
    except Exception:                                # best effort, never into the host
        pass


class Fmi2Slave:
    """The slave of every latobs FMU. pythonfmu 0.7.0's native ``findClass`` picks, in the entry
    module, the class whose MRO holds a class named ``Fmi2Slave``: hence this class's name."""

    spec: ModelSpec = None        # set by the entry script
    data_file: str = ""           # resource file holding the design or plant data
    data_sha256: str = ""         # hash of that file at build time

    def __init__(self, instance_name="", resources=None, logger=None, visible=False, **_):
        module = sys.modules.get(type(self).__module__)
        if module is not None:
            _give_back_entry_dict(module)           # see _ENTRY_DICT_REFS
        self.instance_name = instance_name
        self.resources = resources
        self.log_queue: list = []
        # pythonfmu put this FMU's resources folder at the front of sys.path to import the entry
        # module; everything is imported by now: keep the host's sys.path as it was
        if resources:
            sys.path[:] = [p for p in sys.path if p != resources]
            _defuse_pythonfmu_exit(resources)
        spec = self.spec
        self._phase = "instantiated"
        self._fault = ""
        self._rt = None
        self._data = self._load_data()
        data = self._data if not self._fault else {}
        self._u = input_starts(spec, data)
        self._p = start_values(spec, data)
        self._y = {v.name: float(v.start) for v in spec.outputs}
        self._y.update({v.name: int(v.start) for v in spec.integer_outputs})
        self._bounds = var_bounds(spec, data, spec.parameters)
        # (name, min, max) of every input, None -> +-inf: checked at every doStep (a NaN fails too)
        self._in_range = tuple((n, -math.inf if lo is None else float(lo), math.inf if hi is None else float(hi))
                               for n, (lo, hi) in var_bounds(spec, data, spec.inputs).items())
        known = data or not callable(spec.max_step)
        self._max_step = max_step(spec, data) if known else math.inf
        self._refused_above = refused_above(spec, data) if known else math.inf
        # value reference -> (store, name) per type; settable Real references -> store
        self._get = {"Real": {}, "Integer": {}}
        self._set_in, self._set_par = {}, {}
        for vr, typ, caus, v in variable_table(spec):
            store = {"parameter": self._p, "input": self._u, "output": self._y}[caus]
            self._get[typ][vr] = (store, v.name)
            if caus == "input":
                self._set_in[vr] = v.name
            elif caus == "parameter":
                self._set_par[vr] = v.name
        self._inputs = tuple(v.name for v in spec.inputs)

    # -- logging -------------------------------------------------------------------------------
    def _get_log_queue(self):
        return self.log_queue

    def log(self, msg: str, status: int = OK) -> None:
        self.log_queue.append(_LogMsg(int(status), _CATEGORY.get(status, "logAll"), str(msg)))

    def _drain(self):
        rt = self._rt
        if rt is None or not rt.events:
            return
        for level, msg in rt.events:
            self.log(msg, ERROR if level == "error" else WARNING)
        rt.events.clear()

    # -- data ----------------------------------------------------------------------------------
    def _load_data(self):
        """The FMU's data file, checked against the hash the entry script was built with."""
        if not self.data_file:
            return {}
        path = os.path.join(self.resources or "", self.data_file)
        try:
            with open(path, "rb") as fh:
                raw = fh.read()
        except OSError as exc:
            self._fault = f"cannot read data file {self.data_file!r} from the FMU resources: {exc}"
            return {}
        digest = hashlib.sha256(raw).hexdigest()
        if self.data_sha256 and digest != self.data_sha256:
            self._fault = (f"data file {self.data_file!r} (sha256 {digest[:12]}) is not the one this FMU "
                           f"was built with ({self.data_sha256[:12]}): refusing to run other gains")
            return {}
        kept = _PARSED.get(digest)
        if kept is not None:
            return pickle.loads(kept)          # a copy of its own: no instance sees another's changes
        try:
            data = json.loads(raw.decode("utf-8"))
        except ValueError as exc:
            self._fault = f"data file {self.data_file!r} is not valid JSON: {exc}"
            return {}
        _PARSED[digest] = pickle.dumps(data, protocol=pickle.HIGHEST_PROTOCOL)
        while len(_PARSED) > _PARSED_KEEP:
            del _PARSED[next(iter(_PARSED))]   # the oldest first
        return data

    # -- variables (never raise: see the module docstring) -------------------------------------
    def _bad_ref(self, what: str, vr, typ: str) -> None:
        kind = next((t for t, table in self._get.items() if vr in table), None)
        why = f"is a {kind} variable" if kind else "is not a variable of this FMU"
        self.log(f"{what}: value reference {vr!r} {why}; {typ} value references are "
                 f"{sorted(self._get.get(typ, {})) or 'none'}", ERROR)

    def _getter(self, typ: str, vrs, conv):
        table = self._get[typ]
        try:
            return [conv(s[n]) for s, n in map(table.__getitem__, vrs)]
        except Exception:  # an unknown reference: answer what is known, 0 for the rest
            out = []
            for vr in vrs:
                entry = table.get(vr)
                if entry is None:
                    self._bad_ref(f"fmi2Get{typ}", vr, typ)
                    out.append(conv(0))
                else:
                    out.append(conv(entry[0][entry[1]]))
            return out

    def get_real(self, vrs):
        return self._getter("Real", vrs, float)

    def get_integer(self, vrs):
        return self._getter("Integer", vrs, int)

    def get_boolean(self, vrs):
        for vr in vrs:
            self._bad_ref("fmi2GetBoolean", vr, "Boolean")
        return [False for _ in vrs]

    def get_string(self, vrs):
        for vr in vrs:
            self._bad_ref("fmi2GetString", vr, "String")
        return ["" for _ in vrs]

    def set_real(self, vrs, values):
        u, names = self._u, self._set_in
        try:
            for vr, x in zip(vrs, values):
                u[names[vr]] = x          # checked (finite) at doStep
        except Exception:
            for vr, x in zip(vrs, values):
                if vr in names:
                    u[names[vr]] = float(x)
                elif vr in self._set_par:
                    self._set_parameter(self._set_par[vr], x)
                elif vr in self._get["Real"]:
                    self.log(f"fmi2SetReal: value reference {vr} ({self._get['Real'][vr][1]}) is an output; "
                             "ignored", ERROR)
                else:
                    self._bad_ref("fmi2SetReal", vr, "Real")

    def _set_parameter(self, name, value):
        if self._phase not in ("instantiated", "initialization"):
            self.log(f"parameter {name!r} set after initialisation: ignored", WARNING)
            return
        self._p[name] = float(value)

    def _refuse_set(self, typ, vrs):
        for vr in vrs:
            if vr in self._get.get(typ, {}):
                self.log(f"fmi2Set{typ}: value reference {vr} ({self._get[typ][vr][1]}) is an output; ignored",
                         ERROR)
            else:
                self._bad_ref(f"fmi2Set{typ}", vr, typ)

    def set_integer(self, vrs, values):
        self._refuse_set("Integer", vrs)

    def set_boolean(self, vrs, values):
        self._refuse_set("Boolean", vrs)

    def set_string(self, vrs, values):
        self._refuse_set("String", vrs)

    # The FMU state (canGetAndSetFMUstate="false", canSerializeFMUstate="false"). With the native
    # guard these calls never get here: it answers all six with a logged fmi2Error. Without it
    # (an FMU built without a C compiler) pythonfmu 0.7.0 answers fmi2OK whatever happens here
    # (an exception would be fmi2Fatal and destroy the instance), so: the refusal is logged as an
    # error, and after a refused fmi2SetFMUstate the instance is in the error state (every later
    # doStep refused, fmi2Discard), since the host believes it has restored a state it has not.
    # Whatever state is handed in (pythonfmu passes its pointer on as a Python object: another
    # FMU's state cannot be told apart here, only the guard can refuse it unread), nothing of it
    # is read or kept: every state is refused alike (docs/using-fmus.md, "Unusual calls").
    def _get_fmu_state(self):
        self.log("fmi2GetFMUstate: this FMU cannot get or set its state (canGetAndSetFMUstate=\"false\"); "
                 "the state returned is empty and cannot be restored", ERROR)
        return None

    def _set_fmu_state(self, state):
        self._fault = ("fmi2SetFMUstate: this FMU cannot restore a state (canGetAndSetFMUstate=\"false\"); "
                       "the instance keeps its own state and refuses every further step")
        self._phase = "error"
        self.log(self._fault, ERROR)

    @staticmethod
    def _fmu_state_to_bytes(state):      # fmi2Serialize[d]FMUstate[Size] without the guard: nothing
        return b""

    @staticmethod
    def _fmu_state_from_bytes(raw):      # fmi2DeSerializeFMUstate without the guard: an empty state
        return None

    # -- FMI calls -----------------------------------------------------------------------------
    def setup_experiment(self, start_time=0.0, stop_time=None, tolerance=None):
        pass

    def enter_initialization_mode(self):
        self._phase = "initialization"

    def exit_initialization_mode(self):
        try:
            if not self._fault:
                for name, (lo, hi) in self._bounds.items():
                    x = self._p[name]
                    if not math.isfinite(x) or (lo is not None and x < lo) or (hi is not None and x > hi):
                        self._fault = (f"parameter {name!r} = {x!r} is outside its declared range "
                                       f"[{lo}, {hi}]")
                        break
            if self._fault:
                self.log(self._fault, ERROR)
                self._phase = "error"
                return
            self._rt = self.spec.runtime(self._data, dict(self._p))
            if hasattr(self._rt, "initialize"):
                bad = self._bad_inputs()
                if not bad:
                    self._rt.initialize(dict(self._u))
                elif bad[0]:
                    self.log("non-finite inputs at initialisation: the runtime starts from the first step",
                             WARNING)
                else:
                    self.log(f"input(s) outside the declared range at initialisation: {bad[1]}; the runtime "
                             "starts from the first step", WARNING)
            self._y.update(self._rt.y)
            self._drain()
            self._phase = "stepping"
        except Exception as exc:  # the runtime rejected its data or parameters
            self._fault = f"initialisation failed: {exc}"
            self.log(self._fault, ERROR)
            self._phase = "error"

    def do_step(self, current_time, step_size):
        try:
            if self._phase != "stepping":
                why = self._fault or f"doStep called in phase {self._phase!r} (call exitInitializationMode first)"
                self.log(f"step refused at t = {current_time}: {why}", ERROR)
                return False
            if not math.isfinite(current_time):
                self.log(f"step refused: communication point {current_time!r} is not finite; state held", ERROR)
                return False
            if not (step_size > 0 and math.isfinite(step_size)):
                self.log(f"step refused: communication step {step_size!r} must be finite and > 0 s", ERROR)
                return False
            if step_size > self._refused_above:
                self.log(f"step refused at t = {float(current_time)!r}: communication step {float(step_size)!r} s "
                         f"exceeds this FMU's longest step {self._max_step!r} s (declared in its model "
                         "description); state held", ERROR)
                return False
            u = self._u
            for name, lo, hi in self._in_range:
                if not lo <= u[name] <= hi:       # a NaN fails too
                    self._refuse_inputs(current_time)
                    return False
            rt = self._rt
            rt.step(step_size, u)
            if rt.events:
                self._drain()
            self._y.update(rt.y)
            return True
        except Exception as exc:  # never let the host see an exception
            self.log(f"step failed at t = {current_time}: {exc!r}\n{traceback.format_exc(limit=3)}", ERROR)
            try:
                self._drain()
            except Exception:
                pass
            return False

    def _bad_inputs(self):
        """None if every input is inside its declared range; else (any non-finite, "name = value, ..."
        listing the non-finite inputs if any, else those outside their range)."""
        u = self._u
        out = [(n, float(u[n]), lo, hi) for n, lo, hi in self._in_range if not lo <= u[n] <= hi]
        if not out:
            return None
        nonfinite = [f"{n} = {x!r}" for n, x, _, _ in out if not math.isfinite(x)]
        if nonfinite:
            return True, ", ".join(nonfinite)
        return False, ", ".join(f"{n} = {x!r} (declared range [{lo!r}, {hi!r}])" for n, x, lo, hi in out)

    def _refuse_inputs(self, current_time):
        nonfinite, text = self._bad_inputs()
        if nonfinite:
            self.log(f"step refused at t = {current_time}: non-finite input(s) {text}; state held", ERROR)
        else:
            self.log(f"step refused at t = {float(current_time)!r}: input(s) outside the declared range: {text}; "
                     "state held", ERROR)

    def terminate(self):
        self._phase = "terminated"


# ------------------------------------------------------------------------------------------------
# model description (build time; deterministic: no dates, the guid is given)
# ------------------------------------------------------------------------------------------------
def _num(x: float) -> str:
    x = float(x)
    return str(int(x)) if x.is_integer() and abs(x) < 1e15 else repr(x)


def model_text(spec: ModelSpec, data: dict) -> str:
    """The model description's ``description``: what the model is, the variant ``data`` makes of it,
    its longest communication step (the datasheet, ``latobs.datasheet``, shows the same text)."""
    text = spec.description + (f" -- {spec.describe(data)}" if spec.describe else "")
    return text + (f" -- communication steps up to {_num(max_step(spec, data))} s (longer ones are refused: the "
                   "accuracy is measured up to there); inputs outside their declared min/max are refused")


def model_description(spec: ModelSpec, data: dict, model_identifier: str, guid: str, *, version: str,
                      generation_tool: str, copyright: str, license: str = "MIT",
                      author: str = "latobs", native: "NativeInterfaces | None" = None) -> bytes:
    """modelDescription.xml of an FMU of ``spec`` with ``data``: UTF-8 bytes, deterministic.

    Beyond what pythonfmu writes: units with base units and display units (deg, deg/s, km/h),
    ``unit="1"`` on dimensionless variables, min/max where physics bounds a value, the output
    ``dependencies`` (empty: outputs change only in doStep, so no direct feedthrough and no false
    algebraic loop for a tool that closes one), InitialUnknowns (outputs after initialisation may
    depend on every known, as the observers start from their initial inputs) and a
    DefaultExperiment with a stop time.

    ``native`` (the native C backend, ``latobs.cbackend``): a self-contained binary with its
    sources; CoSimulation without an execution tool and with the FMU state, and ModelExchange
    when ``native.states`` is not empty: the states (local, after the other variables) and their
    derivatives ``der(name)``, the event indicators, and the ModelExchange structure
    ``native.dependencies``: which inputs and states each Real output and each derivative depends
    on directly (in ModelExchange an estimate such as z + N y feeds the measurement through; FMI 2.0
    shares one ModelStructure between the interfaces, and a dependency that is direct in
    ModelExchange is merely conservative in co-simulation, where outputs change in doStep only).
    Integer outputs (mode, flags) change at events only: empty dependencies. InitialUnknowns list
    no dependencies: after initialisation they may depend on every input and parameter.
    """
    description = model_text(spec, data)
    longest = max_step(spec, data)
    root = Element("fmiModelDescription", {
        "fmiVersion": "2.0", "modelName": model_identifier, "guid": guid, "description": description,
        "author": author, "version": version, "copyright": copyright, "license": license,
        "generationTool": generation_tool, "variableNamingConvention": "flat",
        "numberOfEventIndicators": str(native.event_indicators if native else 0)})
    states = native.states if native else ()
    if states:
        me = SubElement(root, "ModelExchange", {
            "modelIdentifier": model_identifier, "needsExecutionTool": "false",
            "completedIntegratorStepNotNeeded": "true", "canBeInstantiatedOnlyOncePerProcess": "false",
            "canNotUseMemoryManagementFunctions": "true", "canGetAndSetFMUstate": "true",
            "canSerializeFMUstate": "true"})
        _source_files(me, native.source_files)
    cs = SubElement(root, "CoSimulation", {
        "modelIdentifier": model_identifier, "needsExecutionTool": "false" if native else "true",
        "canHandleVariableCommunicationStepSize": "true", "canInterpolateInputs": "false",
        "canBeInstantiatedOnlyOncePerProcess": "false", "canNotUseMemoryManagementFunctions": "true",
        "canGetAndSetFMUstate": "true" if native else "false", "canSerializeFMUstate": "true" if native else "false"})
    if native:
        _source_files(cs, native.source_files)
    table = full_table(spec, states)
    unit_definitions(root, used_units(table))
    log_categories(root)
    SubElement(root, "DefaultExperiment", startTime="0", stopTime=_num(spec.stop_time),
               stepSize=repr(min(DEFAULT_STEP, longest)))
    # the longest communication step both FMI layers accept (FMI 2.0 has no attribute for it)
    va = SubElement(SubElement(root, "VendorAnnotations"), "Tool", name="latobs")
    SubElement(va, "CommunicationStep", max=repr(longest), unit="s")
    starts = start_values(spec, data)
    in_starts = input_starts(spec, data)
    bounds = all_bounds(spec, data)
    mv = SubElement(root, "ModelVariables")
    for vr, typ, caus, v in table:
        sv = SubElement(mv, "ScalarVariable", variable_attributes(typ, caus, v, vr))
        # a derivative names its state by its 1-based index in ModelVariables
        SubElement(sv, typ, value_attributes(typ, caus, v, bounds, starts, in_starts, str(vr - len(states) + 1)))
    ms = SubElement(root, "ModelStructure")
    outputs = [vr for vr, _, caus, _ in table if caus == "output"]
    derivatives = [vr for vr, _, caus, _ in table if caus == "derivative"]
    deps = {vr: " ".join(str(k + 1) for k in knowns)
            for vr, knowns in me_dependencies(table, native).items()} if states else {}
    if outputs:
        out_el = SubElement(ms, "Outputs")
        for vr in outputs:
            SubElement(out_el, "Unknown", {"index": str(vr + 1), "dependencies": deps.get(vr, "")})
    if derivatives:
        der_el = SubElement(ms, "Derivatives")
        for vr in derivatives:
            SubElement(der_el, "Unknown", {"index": str(vr + 1), "dependencies": deps[vr]})
    initial = outputs + [vr for vr, _, caus, _ in table if caus in ("state", "derivative")]
    if initial:
        init_el = SubElement(ms, "InitialUnknowns")
        for vr in sorted(initial):
            SubElement(init_el, "Unknown", index=str(vr + 1))
    _indent(root)
    return ('<?xml version="1.0" encoding="UTF-8"?>\n' + tostring(root, encoding="unicode") + "\n").encode("utf-8")



def variable_attributes(typ: str, caus: str, v, vr: int) -> dict:
    """The attributes of a variable of :func:`full_table` (``typ`` "Real"/"Integer", ``caus`` its
    causality there) that both FMI versions declare on the variable element itself: name, value
    reference, description, causality, variability, initial."""
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
    return attrs


def value_attributes(typ: str, caus: str, v, bounds: dict, starts: dict, in_starts: dict, state_ref: str) -> dict:
    """The attributes of a variable's values (FMI 2.0: on its type element; FMI 3.0: on the
    variable): unit and display unit, min, max, start; a derivative's ``derivative`` (``state_ref``:
    its state as the version refers to it) and unit. ``bounds``, ``starts``, ``in_starts``: of
    :func:`all_bounds`, :func:`start_values`, ``spec.input_starts``."""
    if caus == "derivative":
        attrs = {"derivative": state_ref}
        if v.unit in DERIVATIVE_UNITS:
            attrs["unit"] = DERIVATIVE_UNITS[v.unit]
        return attrs
    attrs = {}
    lo, hi = bounds.get(v.name, (v.min, v.max))
    if typ == "Real" and v.unit in BASE_UNITS:
        attrs["unit"] = v.unit
        if v.unit in DISPLAY_UNITS:
            attrs["displayUnit"] = DISPLAY_UNITS[v.unit][0]
    if lo is not None:
        attrs["min"] = _num(lo) if typ == "Real" else str(int(lo))
    if hi is not None:
        attrs["max"] = _num(hi) if typ == "Real" else str(int(hi))
    if caus == "parameter":
        attrs["start"] = repr(starts[v.name])
    elif caus == "input":
        attrs["start"] = _num(in_starts[v.name])
    return attrs

def full_table(spec: ModelSpec, states=()) -> list[tuple[int, str, str, object]]:
    """:func:`variable_table` with the ModelExchange ``states`` (causality "state") and their
    derivatives ("derivative") after it, in value-reference order (both FMI layers' numbering)."""
    table = variable_table(spec)
    first_state = len(table)
    table += [(first_state + k, "Real", "state", v) for k, v in enumerate(states)]
    table += [(first_state + len(states) + k, "Real", "derivative", v) for k, v in enumerate(states)]
    return table


def used_units(table) -> list[str]:
    """The units of :data:`BASE_UNITS` the variables of ``table`` (:func:`full_table`) use, sorted."""
    return sorted({v.unit for _, typ, caus, v in table if typ == "Real" and caus != "derivative"
                   and v.unit in BASE_UNITS}
                  | {DERIVATIVE_UNITS[v.unit] for _, _, caus, v in table if caus == "derivative"
                     and v.unit in DERIVATIVE_UNITS})


def unit_definitions(root: Element, used) -> None:
    """The ``UnitDefinitions`` of the units ``used`` (the same element in FMI 2.0 and 3.0)."""
    if used:
        ud = SubElement(root, "UnitDefinitions")
        for u in used:
            unit = SubElement(ud, "Unit", name=u)
            SubElement(unit, "BaseUnit", BASE_UNITS[u])
            if u in DISPLAY_UNITS:
                name, factor = DISPLAY_UNITS[u]
                SubElement(unit, "DisplayUnit", name=name, factor=repr(factor))


def log_categories(root: Element) -> None:
    """The ``LogCategories`` the FMI layers log under (the same element in FMI 2.0 and 3.0)."""
    cats = SubElement(root, "LogCategories")
    for name, desc in (("logStatusWarning", "warnings: clamps, speed outside the design grid, ignored calls"),
                       ("logStatusError", "errors: refused steps, bad value references, bad parameters"),
                       ("logAll", "all other messages")):
        SubElement(cats, "Category", name=name, description=desc)


def all_bounds(spec: ModelSpec, data: dict) -> dict:
    """{name: (min, max)} of the parameters, inputs and outputs, as declared for ``data``."""
    bounds = {}
    for group in (spec.parameters, spec.inputs, spec.outputs, spec.integer_outputs):
        bounds.update(var_bounds(spec, data, group))
    return bounds


def me_dependencies(table, native: "NativeInterfaces") -> dict[int, list[int]]:
    """{value reference of a Real output or a derivative: the value references it depends on, sorted}
    from ``native.dependencies`` ({name or ``der(state)``: names of inputs and states}); ValueError
    naming the unknown or known when the declaration does not fit the variables."""
    declared = native.dependencies
    if declared is None:
        raise ValueError("a model with continuous states must declare its ModelExchange dependencies")
    knowns = {v.name: vr for vr, _, caus, v in table if caus in ("input", "state")}
    unknowns = {(f"der({v.name})" if caus == "derivative" else v.name): vr for vr, typ, caus, v in table
                if caus == "derivative" or (caus == "output" and typ == "Real")}
    if set(declared) != set(unknowns):
        raise ValueError(f"ModelExchange dependencies: declared for {sorted(declared)}, the model's Real outputs "
                         f"and derivatives are {sorted(unknowns)}")
    out = {}
    for name, names in declared.items():
        bad = sorted(set(names) - set(knowns))
        if bad:
            raise ValueError(f"ModelExchange dependencies of {name}: {bad} are not inputs or states")
        out[unknowns[name]] = sorted(knowns[k] for k in set(names))
    return out


class NativeInterfaces:
    """What a native (C) FMU adds to its model description (see ``model_description``):
    ``states`` (``Var``s, ModelExchange's continuous states; empty: co-simulation only),
    ``event_indicators`` (their number), ``source_files`` (the C files to compile, in
    ``sources/``) and ``dependencies`` (ModelExchange's structure, ``latobs.cbackend.emit.CModel``)."""

    def __init__(self, states=(), event_indicators: int = 0, source_files=(), dependencies=None):
        self.states, self.event_indicators, self.source_files = tuple(states), int(event_indicators), tuple(source_files)
        self.dependencies = dependencies


def _source_files(interface: Element, names) -> None:
    if names:
        sf = SubElement(interface, "SourceFiles")
        for name in names:
            SubElement(sf, "File", name=name)


def _indent(el: Element, level: int = 0) -> None:
    pad = "\n" + "  " * (level + 1)
    if len(el):
        el.text = pad
        for child in el:
            _indent(child, level + 1)
            child.tail = pad
        el[-1].tail = "\n" + "  " * level
