"""One FMI 2.0 or FMI 3.0 co-simulation FMU loaded through fmpy: extraction, model description,
value references, instantiation and initialisation, typed get/set, logging, unloading.

Both versions are driven alike: a variable's FMI 3.0 type is read as its FMI 2.0 call family
(Float64 as Real, Int32 as Integer; :func:`fmi_type`), the calls are the version's own
(``fmi3SetFloat64`` with its ``nValues``, ``fmi3DoStep`` with its event flags, ...). An FMI 3.0
FMU's array variables and variables of other types are not driven (none is an input or output of
a latobs FMU; an FMU with such an input is refused naming it).

The FMU's Python internals (if any) are never imported: everything goes through the FMI calls of
the binary fmpy loads, so a pythonfmu FMU and a native C FMU are driven the same way. Also reads
the design file an observer FMU carries in its resources.
"""
from __future__ import annotations

import ctypes
import itertools
import os
import shutil
from functools import lru_cache
from pathlib import Path
from typing import Any, Callable, Mapping, NamedTuple

import fmpy
from fmpy import calloc, free, read_model_description
from fmpy.fmi2 import (
    FMU2Slave,
    fmi2Boolean,
    fmi2CallbackAllocateMemoryTYPE,
    fmi2CallbackFreeMemoryTYPE,
    fmi2CallbackFunctions,
    fmi2CallbackLoggerTYPE,
    fmi2Integer,
    fmi2Real,
    fmi2ValueReference,
)

def extract(path: str, unzipdir: str | None = None) -> str:
    """``fmpy.extract`` of what loading and running the FMU here needs: its model description, its
    resources and this platform's binaries (FMI 2.0 ``binaries/linux64``, FMI 3.0
    ``binaries/x86_64-linux``); not its sources, documentation or other platforms' binaries (a
    native latobs FMU carries four platforms' binaries and its C sources: most of its bytes). Returns
    the folder (a temporary one when ``unzipdir`` is None)."""
    mine = (f"binaries/{fmpy.platform}/", f"binaries/{fmpy.platform_tuple}/")

    def needed(name: str) -> bool:
        return not name.startswith(("sources/", "documentation/", "extra/", "binaries/")) or name.startswith(mine)
    return str(fmpy.extract(path, unzipdir=unzipdir, include=needed))


_STATUS = ["OK", "WARNING", "DISCARD", "ERROR", "FATAL", "PENDING"]
MAX_LOG_MESSAGES = 10_000  # per FMU; further messages are counted, not stored
FMI_TYPES = ("Real", "Integer", "Boolean")   # how values cross the FMI 2 boundary (Enumeration as Integer)
#: FMI 3.0 type -> the FMI 2.0 call family it is driven as (the types of the harness's signals)
FMI3_FAMILY = {"Float64": "Real", "Int32": "Integer", "Enumeration": "Integer"}
#: FMI 2.0 call family -> the FMI 3.0 functions' type name
FMI3_CALL = {"Real": "Float64", "Integer": "Int32"}


class WiringError(ValueError):
    """An FMU input has no signal to connect, or a parameter/noise name is unknown."""


class CoSimulationError(RuntimeError):
    """An FMU failed during the co-simulation (the message names it, the time and its last logs)."""


def fmi_type(v) -> str:
    """The FMI 2 call family of a model variable: "Real", "Integer" (also Enumeration) or "Boolean";
    an FMI 3.0 scalar Float64 "Real", Int32 or Enumeration "Integer", anything else its own type."""
    if getattr(v, "dimensions", None):
        return "array"
    return FMI3_FAMILY.get(v.type) or ("Integer" if v.type == "Enumeration" else v.type)


def fmi_version(md) -> int:
    """2 or 3: the major FMI version of a model description read by fmpy."""
    return 3 if str(md.fmiVersion).startswith("3") else 2


def _unit_of(v) -> str | None:
    u = getattr(v, "unit", None)
    if not u and getattr(v, "declaredType", None) is not None:
        u = getattr(v.declaredType, "unit", None)
    return u or None


_INSTANCES: dict[int, "FmuInstance"] = {}   # componentEnvironment id -> live instance
_ENV_IDS = itertools.count(1)


def _dispatch_log(env, instance_name, status, category, message):
    """The one logger of every FmuInstance (see FmuInstance.instantiate): to the instance whose id
    is ``env``; a message of an instance already closed is dropped."""
    f = _INSTANCES.get(env or 0)
    if f is not None:
        f._log(env, instance_name, status, category, message)


_DISPATCH_LOG = fmi2CallbackLoggerTYPE(_dispatch_log)   # module-level: lives as long as the process


#: fmpy's function table per slave class (and model identifier: FMI 1.0's symbols carry it)
_FUNCTIONS: dict[tuple, list[tuple[str, str, Any, Any, Any]]] = {}


def _fast_loading(base):
    """``base`` (fmpy's FMU2Slave or FMU3Slave) loading its FMI functions as fmpy does, but reading
    their Python signatures once per process: fmpy inspects every method of every new instance
    (~0.7 ms per FMU and instance; a campaign run makes three). The first instance runs fmpy's own
    ``_loadFunctions``; later ones take each function of their own library with the argument
    names, argument types and result type it gave (the same table: tested). A base without that
    method (another fmpy) is used as it is."""
    if not hasattr(base, "_loadFunctions"):
        return base

    class Slave(base):
        def _loadFunctions(self) -> None:
            key = (base, getattr(self, "modelIdentifier", None))
            table = _FUNCTIONS.get(key)
            if table is None:
                super()._loadFunctions()
                _FUNCTIONS[key] = [(name, f.__name__, getattr(f, "argnames", None), f.argtypes, f.restype)
                                   for name, f in self._functions.items()]
                return
            for name, symbol, argnames, argtypes, restype in table:
                f = getattr(self.dll, symbol)
                f.argnames, f.argtypes, f.restype = argnames, argtypes, restype
                self._functions[name] = f

    Slave.__name__ = Slave.__qualname__ = base.__name__    # fmpy reads the FMI version from it
    return Slave


_Slave2 = _fast_loading(FMU2Slave)


@lru_cache(maxsize=1)
def _slave3():
    from fmpy.fmi3 import FMU3Slave     # (only when an FMI 3.0 FMU is driven)

    return _fast_loading(FMU3Slave)


def _file_version(path: str | os.PathLike) -> tuple[str, int, int, int]:
    """(path, inode, size, modification time in ns): what the per-file caches below are keyed on
    (a campaign reads the same FMUs thousands of times); a file replaced or rewritten at the same
    path is another version. OSError if there is no such file."""
    st = os.stat(path)
    return str(path), st.st_ino, st.st_size, st.st_mtime_ns


def _model_description(path: str):
    """fmpy's model description of the FMU at ``path``, parsed once per file version; shared, read-only."""
    return _parsed_model_description(*_file_version(path))


@lru_cache(maxsize=64)
def _parsed_model_description(path: str, inode: int, size: int, mtime_ns: int):
    return read_model_description(path)


class FmuInstance:
    """An extracted FMU: model description, slave, prebuilt value-reference arrays, logger.

    ``unzipdir``: where the FMU is extracted; if None, it is extracted into a temporary folder
    that :meth:`close` deletes after unloading the FMU.
    """

    def __init__(self, label: str, path: Path, unzipdir: str | None = None):
        self.label = label
        self.path = Path(path)
        self._owned_dir = unzipdir is None
        self.unzipdir = extract(str(path)) if unzipdir is None else unzipdir
        try:
            self.md = _model_description(str(path))
        except Exception as exc:
            raise WiringError(f"FMU {label!r} ({path}): cannot read its modelDescription.xml: {exc}") from exc
        if self.md.coSimulation is None:
            raise WiringError(f"FMU {label!r} ({path.name}) has no co-simulation interface")
        self.fmi = fmi_version(self.md)
        driven = FMI_TYPES if self.fmi == 2 else tuple(FMI3_CALL)
        self.vars = {v.name: v for v in self.md.modelVariables}
        self.inputs = [v for v in self.md.modelVariables if v.causality == "input"]
        self.outputs = [v for v in self.md.modelVariables if v.causality == "output" and fmi_type(v) in driven]
        for v in self.inputs:
            if fmi_type(v) not in driven:
                raise WiringError(f"FMU {label!r} ({path.name}): input {v.name!r} has type {v.type}"
                                  f"{' (an array)' if fmi_type(v) == 'array' else ''}, which the harness cannot "
                                  f"drive ({'Real, Integer, Boolean' if self.fmi == 2 else 'scalar Float64, Int32'}"
                                  " only)")
        self.logs: list[str] = []
        self.dropped_logs = 0
        self.slave = None   # fmpy's FMU2Slave or FMU3Slave
        self.instantiated = False
        self.initialized = False

    @property
    def model_name(self) -> str:
        return self.md.modelName

    def describe(self) -> str:
        return f"FMU {self.label!r} ({self.path.name}, model {self.model_name})"

    # logger --------------------------------------------------------------------------------
    def _log(self, component, instance_name, status, category, message):
        try:
            if len(self.logs) >= MAX_LOG_MESSAGES:
                self.dropped_logs += 1
                return
            st = _STATUS[status] if 0 <= status < len(_STATUS) else str(status)
            cat = category.decode("utf-8", "replace") if category else ""
            msg = message.decode("utf-8", "replace") if message else ""
            self.logs.append(f"[{st}] {cat}: {msg}" if cat else f"[{st}] {msg}")
        except Exception:  # never let an exception cross the C boundary
            pass

    def instantiate(self):
        if self.fmi == 3:
            return self._instantiate3()
        self.callbacks = fmi2CallbackFunctions()
        # fmpy's native logger proxy (it formats the printf-style variadic messages) keeps ONE
        # process-wide pointer to the last logger registered: every FMU's messages reach the
        # logger of the last instance, and a freed one crashes the host at the next message. So
        # the logger is one process-wide dispatcher, never freed, that routes each message to its
        # instance by componentEnvironment, an id per instance.
        self._env = next(_ENV_IDS)
        _INSTANCES[self._env] = self
        self.callbacks.componentEnvironment = self._env
        self.callbacks.logger = _DISPATCH_LOG
        self.callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        self.callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        try:
            from fmpy.logging import addLoggerProxy

            addLoggerProxy(ctypes.byref(self.callbacks))
        except Exception:  # pragma: no cover - the proxy library is optional
            pass
        self.slave = _Slave2(guid=self.md.guid, unzipDirectory=self.unzipdir,
                               modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName=self.label)
        self.slave.instantiate(callbacks=self.callbacks, loggingOn=True)
        self.instantiated = True

    def _instantiate3(self):
        """FMI 3.0: fmpy's FMU3Slave with a logger of this instance (FMI 3.0's logger takes no
        variadic arguments: fmpy keeps one callback per instance, no process-wide proxy needed)."""

        def log(env, status, category, message):
            self._log(env, None, status, category, message)

        self.slave = _slave3()(guid=self.md.guid, unzipDirectory=self.unzipdir,
                               modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName=self.label)
        self.slave.instantiate(loggingOn=True, logMessage=log)
        self.instantiated = True

    def do_step(self, t: float, h: float) -> None:
        """One communication step from ``t`` of ``h`` seconds (fmi2DoStep or fmi3DoStep); fmpy
        raises for an error status. An FMI 3.0 FMU that asks to terminate is an error here."""
        if self.fmi == 2:
            self.slave.doStep(t, h)
            return
        _, terminate, _, _ = self.slave.doStep(t, h)
        if terminate:
            raise RuntimeError(f"{self.describe()}: fmi3DoStep at t = {t:.6g} s asked to terminate the simulation")

    def start(self, inputs: Mapping[str, float] | None = None, parameters: Mapping[str, Any] | None = None,
              start_time: float = 0.0, stop_time: float | None = None) -> dict[str, float]:
        """Instantiate and initialise, as every latobs host does: prebuilt I/O for all inputs,
        setupExperiment, parameters, initialisation mode with the initial ``inputs`` (so the FMU
        starts consistent with them), exit. Returns the outputs at the start time. A failure is
        raised naming the FMI call that failed."""
        stage = "instantiate"
        try:
            self.instantiate()
            self.prepare_io([v.name for v in self.inputs])
            if self.fmi == 2:
                stage = "setupExperiment"
                self.slave.setupExperiment(startTime=start_time, stopTime=stop_time)
            stage = "setting parameters"
            self.set_parameters(parameters or {})
            stage = "enterInitializationMode"
            if self.fmi == 2:
                self.slave.enterInitializationMode()
            else:
                self.slave.enterInitializationMode(startTime=start_time, stopTime=stop_time)
            self.initialized = True
            stage = "setting inputs"
            if inputs:
                self.set_inputs(inputs)
            stage = "exitInitializationMode"
            self.slave.exitInitializationMode()
            stage = "getting outputs"
            return self.get_outputs()
        except Exception as exc:
            raise RuntimeError(f"{stage}: {exc}") from exc

    # prebuilt get/set ------------------------------------------------------------------------
    def prepare_io(self, input_names: list[str]):
        """Group inputs and outputs by type with ctypes arrays built once."""
        self.in_groups = _groups([self.vars[n] for n in input_names])
        self.out_groups = _groups(self.outputs)
        s = self.slave
        if self.fmi == 2:
            self._setter = {t: getattr(s, "fmi2Set" + t) for t in FMI_TYPES}
            self._getter = {t: getattr(s, "fmi2Get" + t) for t in FMI_TYPES}
        else:   # (component, vr, n, values, nValues = n): every driven variable is a scalar
            self._setter = {t: _with_n(getattr(s, "fmi3Set" + c)) for t, c in FMI3_CALL.items()}
            self._getter = {t: _with_n(getattr(s, "fmi3Get" + c)) for t, c in FMI3_CALL.items()}

    def set_inputs(self, values: Mapping[str, float]):
        """Set the prepared inputs from ``values`` {name: value}. A prepared input absent from
        ``values`` is not set: it keeps its current value (its start value if never set), e.g. an
        optional plant input such as CarPlant's stiffness_scale_f."""
        s = self.slave
        for typ, (names, vr, buf) in self.in_groups.items():
            try:
                for i, n in enumerate(names):
                    buf[i] = values[n] if typ == "Real" else int(round(values[n]))
            except KeyError:
                names, vr, buf = self._subset(typ, names, vr, values)
                if not names:
                    continue
            self._setter[typ](s.component, vr, len(names), buf)

    @staticmethod
    def _subset(typ, names, vr, values):
        """(names, value references, filled buffer) of the prepared inputs present in ``values``."""
        keep = [i for i, n in enumerate(names) if n in values]
        ctype = _CTYPE[typ]
        sub = [names[i] for i in keep]
        buf = (ctype * len(keep))(*[values[n] if typ == "Real" else int(round(values[n])) for n in sub])
        return sub, (fmi2ValueReference * len(keep))(*[vr[i] for i in keep]), buf

    def get_outputs(self) -> dict[str, float]:
        s = self.slave
        out = {}
        for typ, (names, vr, buf) in self.out_groups.items():
            self._getter[typ](s.component, vr, len(names), buf)
            out.update(zip(names, buf))
        return out

    def check_parameters(self, params: Mapping[str, Any]):
        """Raise WiringError naming any name in ``params`` that is not a parameter of this FMU."""
        known = sorted(x.name for x in self.md.modelVariables if x.causality == "parameter")
        for name in params:
            if name not in known:
                raise WiringError(f"{self.describe()} has no parameter {name!r}; its parameters: "
                                  f"{', '.join(known) or '(none)'}")

    def set_parameters(self, params: Mapping[str, Any]):
        self.check_parameters(params)
        for name, value in params.items():
            v = self.vars[name]
            if self.fmi == 3:
                typ = fmi_type(v)
                if typ not in FMI3_CALL:
                    raise WiringError(f"{self.describe()}: parameter {name!r} has type {v.type}, which the "
                                      "harness does not set (scalar Float64, Int32 only)")
                getattr(self.slave, "set" + FMI3_CALL[typ])([v.valueReference],
                                                           [float(value) if typ == "Real" else int(value)])
            elif v.type == "Real":
                self.slave.setReal([v.valueReference], [float(value)])
            elif v.type in ("Integer", "Enumeration"):
                self.slave.setInteger([v.valueReference], [int(value)])
            elif v.type == "Boolean":
                self.slave.setBoolean([v.valueReference], [bool(value)])
            elif v.type == "String":
                self.slave.setString([v.valueReference], [str(value)])

    def close(self):
        if self.slave is None:
            if self._owned_dir:
                shutil.rmtree(self.unzipdir, ignore_errors=True)
            return
        if self.instantiated:
            if self.initialized:
                try:
                    self.slave.terminate()
                except Exception:
                    pass
            try:
                self.slave.freeInstance()
            except Exception:
                pass
        else:
            try:
                self.slave.freeLibrary()
            except Exception:
                pass
        self.slave = None
        _INSTANCES.pop(getattr(self, "_env", None), None)
        if self._owned_dir:
            shutil.rmtree(self.unzipdir, ignore_errors=True)

    def log_tail(self, n: int = 5) -> str:
        return "; ".join(self.logs[-n:]) if self.logs else "(no log messages)"

    def row_calls(self, checked: bool = False) -> "RowCalls":
        """The instantiated FMU's get/set/doStep calls on raw addresses (see :class:`RowCalls`):
        the functions of the library fmpy loaded, called directly, or with ``checked`` through
        fmpy's ``FMU2Slave`` wrappers (argument conversion, status check), the reference of the
        direct calls. Either way a call returns its fmi2Status."""
        s = self.slave
        if self.fmi == 3:
            return self._row_calls3(checked)
        if not checked:
            dll = s.dll
            return RowCalls(s.component, {t: _ROW(("fmi2Set" + t, dll)) for t in FMI_TYPES},
                            {t: _ROW(("fmi2Get" + t, dll)) for t in FMI_TYPES}, _DOSTEP(("fmi2DoStep", dll)))
        return RowCalls(s.component, {t: _checked(getattr(s, "fmi2Set" + t), _CTYPE[t]) for t in FMI_TYPES},
                        {t: _checked(getattr(s, "fmi2Get" + t), _CTYPE[t]) for t in FMI_TYPES},
                        _checked_step(s.fmi2DoStep))


    def _row_calls3(self, checked: bool) -> "RowCalls":
        """:meth:`row_calls` of an FMI 3.0 FMU: the same signatures, nValues = n added and
        fmi3DoStep's event flags taken (a request to terminate is an error status)."""
        s = self.slave
        if checked:
            sets = {t: _checked(_with_n(getattr(s, "fmi3Set" + c)), _CTYPE[t]) for t, c in FMI3_CALL.items()}
            gets = {t: _checked(_with_n(getattr(s, "fmi3Get" + c)), _CTYPE[t]) for t, c in FMI3_CALL.items()}

            def step(c, t, h, no_prior):
                try:
                    self.do_step(t, h)
                    return 0
                except Exception as exc:
                    return _status(exc)
            return RowCalls(s.component, sets, gets, step)
        dll = s.dll
        raw_set = {t: _ROW3(("fmi3Set" + c, dll)) for t, c in FMI3_CALL.items()}
        raw_get = {t: _ROW3(("fmi3Get" + c, dll)) for t, c in FMI3_CALL.items()}
        raw_step = _DOSTEP3(("fmi3DoStep", dll))
        flags = [ctypes.c_bool(), ctypes.c_bool(), ctypes.c_bool(), ctypes.c_double()]
        refs = [ctypes.byref(x) for x in flags]

        def step_fast(c, t, h, no_prior):
            status = raw_step(c, t, h, no_prior, *refs)
            return status if status > 1 or not flags[1].value else 3   # terminateSimulation: an error here
        return RowCalls(s.component, {t: (lambda f: lambda c, vr, n, v: f(c, vr, n, v, n))(f) for t, f in raw_set.items()},
                        {t: (lambda f: lambda c, vr, n, v: f(c, vr, n, v, n))(f) for t, f in raw_get.items()},
                        step_fast)


def _with_n(fn):
    """An FMI 3.0 get/set function called as its FMI 2.0 form: (c, vr, n, values) -> fn(..., n)."""
    return lambda c, vr, n, values: fn(c, vr, n, values, n)


_CTYPE = {"Real": fmi2Real, "Integer": fmi2Integer, "Boolean": fmi2Boolean}
_ROW = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_size_t, ctypes.c_void_p)
_DOSTEP = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_double, ctypes.c_double, ctypes.c_int)
_ROW3 = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_size_t, ctypes.c_void_p,
                         ctypes.c_size_t)
_DOSTEP3 = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_double, ctypes.c_double, ctypes.c_bool,
                            ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p)


class RowCalls(NamedTuple):
    """An FMU's FMI calls with raw addresses: ``set[typ](component, vr, n, values)`` and
    ``get[typ](...)`` for typ in :data:`FMI_TYPES` (``vr``, ``values``: addresses of n value
    references and n values), ``do_step(component, t, h, 1)``; each returns the fmi2Status."""
    component: Any
    set: dict[str, Callable[..., int]]
    get: dict[str, Callable[..., int]]
    do_step: Callable[..., int]


def _status(exc: Exception) -> int:
    """The fmi2Status of a failed fmpy call (fmpy raises for status > fmi2Warning)."""
    return int(getattr(exc, "status", 3))


def _checked(fn, ctype) -> Callable[..., int]:
    vr_p, val_p = ctypes.POINTER(fmi2ValueReference), ctypes.POINTER(ctype)

    def call(c, vr, n, values):
        try:
            return fn(c, ctypes.cast(vr, vr_p), n, ctypes.cast(values, val_p))
        except Exception as exc:
            return _status(exc)
    return call


def _checked_step(fn) -> Callable[..., int]:
    def call(c, t, h, no_prior_state):
        try:
            return fn(c, t, h, no_prior_state)
        except Exception as exc:
            return _status(exc)
    return call


def _groups(variables) -> dict[str, tuple[list[str], Any, Any]]:
    by: dict[str, list] = {}
    for v in variables:
        by.setdefault(fmi_type(v), []).append(v)
    out = {}
    for typ, vs in by.items():
        n = len(vs)
        vr = (fmi2ValueReference * n)(*[v.valueReference for v in vs])
        out[typ] = ([v.name for v in vs], vr, (_CTYPE[typ] * n)())
    return out


# --------------------------------------------------------------------------------------------
# the design file baked into an observer FMU
# --------------------------------------------------------------------------------------------
def read_fmu_design(fmu_path: str | os.PathLike) -> tuple[dict, str] | None:
    """(design dict, archive member name) of the design file in an observer FMU's resources
    (``resources/*.design.json``), None when the FMU has none (or is not a readable zip)."""
    import json
    import zipfile

    try:
        with zipfile.ZipFile(fmu_path) as z:
            names = sorted(n for n in z.namelist()
                           if n.startswith("resources/") and n.count("/") == 1 and n.endswith(".design.json"))
            if not names:
                return None
            return json.loads(z.read(names[0]).decode("utf-8")), names[0]
    except (OSError, zipfile.BadZipFile, ValueError, KeyError):
        return None


def design_summary(design: Mapping[str, Any], source: str = "") -> dict[str, Any]:
    """What the validation needs of a design file: ``{"design", "name", "paper", "source",
    "vehicle": {"name", "kind", "parameters": {p: {"value", "unit"}}}}``. The vehicle is the
    design's own ``vehicle`` entry (values as written, SI), the vehicle the user designed for, and
    nothing else: a parameter it does not carry is missing (the baseline that needs it says so),
    never taken from a shipped vehicle set that happens to have the same name."""
    veh = design.get("vehicle") or {}
    params: dict[str, dict[str, Any]] = {}
    for k, v in (veh.get("parameters") or {}).items():
        if isinstance(v, Mapping):
            params[k] = {"value": v.get("value"), "unit": v.get("unit")}
        else:
            params[k] = {"value": v, "unit": None}
    return {"design": design.get("design"), "name": design.get("name"), "paper": design.get("paper"),
            "source": source,
            "vehicle": {"name": veh.get("name"), "kind": veh.get("kind"), "parameters": params}}


def observer_design(fmu_path: str | os.PathLike) -> dict[str, Any] | None:
    """:func:`design_summary` of the design file baked into the observer FMU at ``fmu_path``;
    None when the FMU carries no design file. Read once per file version (:func:`_file_version`:
    a design file with the runtime's tables takes ~25 ms to parse); a copy each call."""
    import copy

    try:
        version = _file_version(fmu_path)
    except OSError:
        return None
    return copy.deepcopy(_observer_design(*version))


@lru_cache(maxsize=64)
def _observer_design(fmu_path: str, inode: int, size: int, mtime_ns: int) -> dict[str, Any] | None:
    found = read_fmu_design(fmu_path)
    if found is None:
        return None
    design, member = found
    return design_summary(design, f"{Path(fmu_path).name}:{member}")
