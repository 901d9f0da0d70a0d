"""The one FMI 2.0 co-simulation glue of every latobs FMU (pythonfmu backend). No maths here.

A generated entry script binds a ``ModelSpec`` (``spec.py``) and a data file to this class:

    from latobs_rt_<hash>.framework import LatobsSlave as Fmi2Slave
    class SideslipBankObserver(Fmi2Slave):
        spec = SPEC; data_file = "SideslipBankObserver.design.json"; data_sha256 = "..."

(pythonfmu's native loader finds the class with the regex ``class NAME(Fmi2Slave):``, hence the
alias). The host never sees a Python exception: every failure is logged and reported as a
status, as documented here:
  * a non-finite input or step size, or doStep before exitInitializationMode: the step is
    refused, the state is kept, an error is logged and doStep returns fmi2Discard (pythonfmu
    maps a refused step to fmi2Discard; any uncaught Python exception would be fmi2Fatal);
  * the data file differs from the one the FMU was built with (sha256), or the runtime rejects
    its data or parameters at exitInitializationMode: logged as an error, every later doStep
    is refused;
  * parameters set after initialisation are ignored with a warning;
  * warnings of the runtime (clamps, e.g. speed outside the design grid) are logged.
The model description gets what pythonfmu omits and ``fmpy validate`` requires (ModelStructure/
InitialUnknowns) plus units.
"""
from __future__ import annotations

import hashlib
import json
import math
import os
import sys
import traceback
from xml.etree.ElementTree import Element, SubElement

from pythonfmu import Fmi2Slave as _PythonFmuSlave
from pythonfmu import DefaultExperiment, Fmi2Causality, Fmi2Initial, Fmi2Variability, Integer, Real
from pythonfmu.enums import Fmi2Status

from .spec import ModelSpec

# FMI 2.0 base-unit exponents of the units used by the model files
BASE_UNITS = {
    "rad": {"rad": "1"}, "rad/s": {"rad": "1", "s": "-1"}, "m": {"m": "1"}, "m/s": {"m": "1", "s": "-1"},
    "m/s2": {"m": "1", "s": "-2"}, "N": {"kg": "1", "m": "1", "s": "-2"}, "N.m": {"kg": "1", "m": "2", "s": "-2"},
    "s": {"s": "1"},
}
DEFAULT_STEP = 0.005  # s, communication step suggested in the model description

# pythonfmu 0.7.0's native findClass() ends with Py_DECREF(PyModule_GetDict(module)): it releases,
# on every instantiation, a reference to the entry module's __dict__ that it never owned, so the
# dict is freed after a few instances and the next instantiation crashes the host (upstream issue
# NTNU-IHB/PythonFMU#228). Each instance hands one reference back (see LatobsSlave.__init__).
_ENTRY_DICT_REFS: list = []


class LatobsSlave(_PythonFmuSlave):
    spec: ModelSpec = None        # set by the entry script
    data_file: str = ""           # resource file holding the design or plant data
    data_sha256: str = ""         # hash of that file at build time

    def __init__(self, **kwargs):
        module = sys.modules.get(type(self).__module__)
        if module is not None:
            _ENTRY_DICT_REFS.append(vars(module))   # see _ENTRY_DICT_REFS
        super().__init__(**kwargs)
        spec = self.spec
        self.description = spec.description
        self.author = "latobs"
        self.default_experiment = DefaultExperiment(start_time=0.0, step_size=DEFAULT_STEP)
        self._phase = "instantiated"
        self._fault = ""
        self._rt = None
        self._u = {v.name: float(v.start) for v in spec.inputs}
        self._p = {v.name: float(v.start) for v in spec.parameters}
        self._y = {v.name: float(v.start) for v in spec.outputs}
        self._y.update({v.name: int(v.start) for v in spec.integer_outputs})
        self._data = self._load_data()
        defaults = getattr(spec.runtime, "parameter_defaults", None)   # data-dependent start values
        if defaults is not None and self._data:
            self._p.update({k: float(x) for k, x in defaults(self._data).items() if k in self._p})
        for v in spec.parameters:
            self.register_variable(Real(v.name, start=self._p[v.name], description=f"{v.description} [{v.unit}]",
                                        causality=Fmi2Causality.parameter, variability=Fmi2Variability.fixed,
                                        initial=Fmi2Initial.exact,
                                        getter=self._getter(self._p, v.name), setter=self._param_setter(v.name)))
        for v in spec.inputs:
            self.register_variable(Real(v.name, start=v.start, description=f"{v.description} [{v.unit}]",
                                        causality=Fmi2Causality.input, variability=Fmi2Variability.continuous,
                                        getter=self._getter(self._u, v.name), setter=self._input_setter(v.name)))
        for v in spec.outputs:
            self.register_variable(Real(v.name, description=f"{v.description} [{v.unit}]",
                                        causality=Fmi2Causality.output, variability=Fmi2Variability.continuous,
                                        getter=self._getter(self._y, v.name)))
        for v in spec.integer_outputs:
            self.register_variable(Integer(v.name, description=v.description,
                                           causality=Fmi2Causality.output, variability=Fmi2Variability.discrete,
                                           getter=self._getter(self._y, v.name)))

    # -- variables ---------------------------------------------------------------------------
    @staticmethod
    def _getter(store, name):
        return lambda: store[name]

    def _input_setter(self, name):
        def setter(value):
            self._u[name] = float(value)   # checked (finite) at doStep
        return setter

    def _param_setter(self, name):
        def setter(value):
            if self._phase not in ("instantiated", "initialization"):
                self.log(f"parameter {name!r} set after initialisation: ignored", Fmi2Status.warning)
                return
            self._p[name] = float(value)
        return setter

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
        return json.loads(raw.decode("utf-8"))

    # -- FMI calls -----------------------------------------------------------------------------
    def enter_initialization_mode(self):
        self._phase = "initialization"

    def exit_initialization_mode(self):
        if self._fault:
            self.log(self._fault, Fmi2Status.error)
            self._phase = "error"
            return
        try:
            self._rt = self.spec.runtime(self._data, dict(self._p))
            if hasattr(self._rt, "initialize"):
                if all(math.isfinite(v) for v in self._u.values()):
                    self._rt.initialize(dict(self._u))
                else:
                    self.log("non-finite inputs at initialisation: the runtime starts from the first step",
                             Fmi2Status.warning)
            self._y.update(self._rt.y)
            self._drain()
            self._phase = "stepping"
        except Exception as exc:  # the runtime rejected its data or parameters
            self._fault = f"initialisation failed: {exc}"
            self.log(self._fault, Fmi2Status.error)
            self._phase = "error"

    def do_step(self, current_time, step_size):
        if self._phase != "stepping":
            why = self._fault or f"doStep called in phase {self._phase!r} (call exitInitializationMode first)"
            self.log(f"step refused at t = {current_time}: {why}", Fmi2Status.error)
            return False
        if not (isinstance(step_size, float) and math.isfinite(step_size) and step_size > 0):
            self.log(f"step refused: communication step {step_size!r} must be finite and > 0 s", Fmi2Status.error)
            return False
        bad = [f"{k} = {v!r}" for k, v in self._u.items() if not math.isfinite(v)]
        if bad:
            self.log(f"step refused at t = {current_time}: non-finite input(s) {', '.join(bad)}; state held",
                     Fmi2Status.error)
            return False
        try:
            self._rt.step(step_size, self._u)
        except Exception as exc:  # never let the host see an exception
            self.log(f"step failed at t = {current_time}: {exc!r}\n{traceback.format_exc(limit=3)}",
                     Fmi2Status.error)
            self._drain()
            return False
        self._drain()
        self._y.update(self._rt.y)
        return True

    def terminate(self):
        self._phase = "terminated"

    def _drain(self):
        rt = self._rt
        if rt is None:
            return
        for level, msg in rt.events:
            self.log(msg, Fmi2Status.error if level == "error" else Fmi2Status.warning)
        rt.events.clear()

    # -- model description -------------------------------------------------------------------
    def to_xml(self, model_options=dict()) -> Element:
        root = super().to_xml(model_options)
        units = {v.name: v.unit for v in (*self.spec.inputs, *self.spec.outputs, *self.spec.parameters)}
        used = sorted({u for u in units.values() if u in BASE_UNITS})
        if used:
            ud = Element("UnitDefinitions")
            for u in used:
                SubElement(SubElement(ud, "Unit", name=u), "BaseUnit", BASE_UNITS[u])
            cs_index = list(root).index(root.find("CoSimulation"))
            root.insert(cs_index + 1, ud)
        for sv in root.find("ModelVariables"):
            real = sv.find("Real")
            if real is not None and units.get(sv.get("name")) in BASE_UNITS:
                real.set("unit", units[sv.get("name")])
        structure = root.find("ModelStructure")
        outputs = structure.find("Outputs")
        if outputs is not None:
            initial = SubElement(structure, "InitialUnknowns")
            for unknown in outputs:
                SubElement(initial, "Unknown", index=unknown.get("index"))
        return root
