"""Co-simulation of a plant FMU and observer FMUs with fmpy, wired by variable name.

Only the BUILT FMUs are used, through fmpy's FMI 2.0 co-simulation API (``FMU2Slave``); the FMUs'
Python internals are never imported.

Signal bus
    At each communication point t_k = k*dt (s) the bus holds the scenario's signals (the plant
    inputs, e.g. delta rad, vx m/s, bank_angle rad, and the scenario's ``parameter_signals``,
    e.g. CarPlant's stiffness_scale_f/r) and every output (causality="output") of the plant FMU,
    keyed by variable name. A plant output with the same name as a scenario signal replaces it
    on the bus (the plant is the truth).
Wiring
    Plant inputs come from the scenario signals; each observer input is pulled from the bus by
    name. A missing signal is a :class:`WiringError` naming the FMU and the variable, raised
    before any FMU is instantiated. Exception: a plant input listed in the scenario's
    ``optional_plant_inputs`` (CarPlant's stiffness_scale_f/r) that the scenario does not
    provide is never set: it keeps the start value of the plant's model description (recorded
    in ``SimResult.info["plant_inputs_at_start"]``).
Measurement model
    Observers see the bus through an optional :class:`NoiseSpec` (additive white Gaussian noise
    with a standard deviation and a constant bias per signal, in the signal's SI unit). The noise
    is drawn once per run from ``numpy.random.default_rng(seed)`` and applied only to what the
    observers receive: the recorded truth (``SimResult.bus``) stays clean; what they received is
    in ``SimResult.measured``. Every observer sees the same noisy measurement (one sensor each).
Timing (fixed step, zero-order hold)
    Initialisation: plant parameters and inputs u(t_0) are set, the plant is initialised and its
    outputs read; then each observer gets bus(t_0) and is initialised. Step k: plant inputs
    u(t_k) and observer inputs bus(t_k) are set, every FMU does doStep(t_k, dt), then the plant
    outputs and observer outputs at t_{k+1} are read. So an observer output at t_{k+1} depends on
    the bus at t_k (one step of transport delay, as for a sampled-data observer).
Observer designs
    A latobs observer FMU carries its design file in its resources (``resources/NAME.design.json``).
    :func:`observer_design` reads it out of the archive (the FMU's Python is never imported) and
    ``SimResult.info["observer_designs"][label]`` holds its summary: design name, paper and the
    vehicle parameter set it was designed for (values and units), which the metrics' baselines
    (:mod:`latobs.validation.baselines`) use; None for an FMU without a design file.
"""
from __future__ import annotations

import ctypes
import itertools
import os
import shutil
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from fmpy import calloc, extract, free, read_model_description
from fmpy.fmi2 import (
    FMU2Slave,
    fmi2CallbackAllocateMemoryTYPE,
    fmi2CallbackFreeMemoryTYPE,
    fmi2CallbackFunctions,
    fmi2CallbackLoggerTYPE,
    fmi2Integer,
    fmi2Real,
    fmi2ValueReference,
    fmi2Boolean,
)

from .scenarios import Scenario, get_scenario

PLANT_LABEL = "plant"
_STATUS = ["OK", "WARNING", "DISCARD", "ERROR", "FATAL", "PENDING"]
MAX_LOG_MESSAGES = 10_000  # per FMU; further messages are counted, not stored


class WiringError(ValueError):
    """An FMU input has no signal to connect, or a parameter/noise name is unknown."""


class CoSimulationError(RuntimeError):
    """An FMU failed during the co-simulation (the message names it, the time and its last logs)."""


# --------------------------------------------------------------------------------------------
# measurement model
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class NoiseSpec:
    """Measurement model of what observers receive.

    signals  {bus signal name: (std, bias)} in the signal's SI unit (e.g. rad, rad/s, m/s^2);
             measured = truth + bias + std * N(0, 1), white, independent per signal and sample
    seed     seed of numpy.random.default_rng; None = use the ``seed`` argument of :func:`run`

    Draws are made per signal in sorted name order, a full-length array each, so a given
    (seed, signal set, grid) always gives the same noise.
    """

    signals: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    seed: int | None = None

    def __post_init__(self):
        for name, sb in self.signals.items():
            try:
                std, bias = (float(x) for x in sb)
            except (TypeError, ValueError):
                raise ValueError(f"noise for {name!r} must be (std, bias), got {sb!r}") from None
            if not (np.isfinite(std) and std >= 0 and np.isfinite(bias)):
                raise ValueError(f"noise for {name!r}: std must be finite and >= 0 and bias finite, got {sb!r}")

    def rng(self, default_seed: int = 0) -> np.random.Generator:
        return np.random.default_rng(self.seed if self.seed is not None else default_seed)

    def draw(self, n: int, default_seed: int = 0) -> dict[str, np.ndarray]:
        """Additive error arrays (bias + std*N(0,1)), length n, per signal name."""
        g = self.rng(default_seed)
        out = {}
        for name in sorted(self.signals):
            std, bias = (float(x) for x in self.signals[name])
            out[name] = bias + std * g.standard_normal(n)
        return out

    def as_dict(self) -> dict:
        return {"signals": {k: {"std": float(v[0]), "bias": float(v[1])} for k, v in self.signals.items()},
                "seed": self.seed}


# --------------------------------------------------------------------------------------------
# result
# --------------------------------------------------------------------------------------------
@dataclass
class SimResult:
    """Time series of one co-simulation.

    time       communication points t_k, s, shape (n+1,)
    bus        truth: {signal: array}, the scenario signals and every plant output (SI units)
    measured   {signal: array} what the observers received for each bus signal wired to one
    observers  {label: {output name: array}} every Real/Integer/Boolean output of each observer
               (Integer outputs such as ``mode`` as int arrays)
    logs       {label: [message, ...]} FMU log messages ("[STATUS] category: text"), plant
               under "plant"
    scenario   scenario name; dt communication step, s; settle_time, s (from the scenario)
    units      {variable name: unit} where the modelDescriptions declare one
    inputs     {label: [input names]} the wiring actually used
    info       scenario info (derived amplitudes), noise spec, FMU paths, vehicle name,
               observer_models {label: modelName}, observer_designs {label: design summary or
               None} (see "Observer designs" above)
    """

    time: np.ndarray
    bus: dict[str, np.ndarray]
    observers: dict[str, dict[str, np.ndarray]]
    logs: dict[str, list[str]]
    scenario: str
    dt: float
    settle_time: float = 0.0
    measured: dict[str, np.ndarray] = field(default_factory=dict)
    units: dict[str, str] = field(default_factory=dict)
    inputs: dict[str, list[str]] = field(default_factory=dict)
    info: dict[str, Any] = field(default_factory=dict)

    @property
    def duration(self) -> float:
        return float(self.time[-1] - self.time[0])


# --------------------------------------------------------------------------------------------
# one FMU
# --------------------------------------------------------------------------------------------
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
            self.md = read_model_description(str(path))
        except Exception as exc:
            raise WiringError(f"FMU {label!r} ({path}): cannot read its modelDescription.xml: {exc}") from exc
        if self.md.coSimulation is None:
            raise WiringError(f"FMU {label!r} ({path.name}) has no co-simulation interface")
        self.vars = {v.name: v for v in self.md.modelVariables}
        self.inputs = [v for v in self.md.modelVariables if v.causality == "input"]
        self.outputs = [v for v in self.md.modelVariables
                        if v.causality == "output" and v.type in ("Real", "Integer", "Boolean", "Enumeration")]
        for v in self.inputs:
            if v.type not in ("Real", "Integer", "Boolean", "Enumeration"):
                raise WiringError(f"FMU {label!r} ({path.name}): input {v.name!r} has type {v.type}, "
                                  "which the harness cannot drive (Real, Integer, Boolean only)")
        self.logs: list[str] = []
        self.dropped_logs = 0
        self.slave: FMU2Slave | None = None
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
        self.slave = FMU2Slave(guid=self.md.guid, unzipDirectory=self.unzipdir,
                               modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName=self.label)
        self.slave.instantiate(callbacks=self.callbacks, loggingOn=True)
        self.instantiated = True

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
            stage = "setupExperiment"
            self.slave.setupExperiment(startTime=start_time, stopTime=stop_time)
            stage = "setting parameters"
            self.set_parameters(parameters or {})
            stage = "enterInitializationMode"
            self.slave.enterInitializationMode()
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
            if typ == "Real":
                s.fmi2SetReal(s.component, vr, len(names), buf)
            elif typ == "Boolean":
                s.fmi2SetBoolean(s.component, vr, len(names), buf)
            else:
                s.fmi2SetInteger(s.component, vr, len(names), buf)

    @staticmethod
    def _subset(typ, names, vr, values):
        """(names, value references, filled buffer) of the prepared inputs present in ``values``."""
        keep = [i for i, n in enumerate(names) if n in values]
        ctype = {"Real": fmi2Real, "Integer": fmi2Integer, "Boolean": fmi2Boolean}[typ]
        sub = [names[i] for i in keep]
        buf = (ctype * len(keep))(*[values[n] if typ == "Real" else int(round(values[n])) for n in sub])
        return sub, (fmi2ValueReference * len(keep))(*[vr[i] for i in keep]), buf

    def get_outputs(self) -> dict[str, float]:
        s = self.slave
        out = {}
        for typ, (names, vr, buf) in self.out_groups.items():
            if typ == "Real":
                s.fmi2GetReal(s.component, vr, len(names), buf)
            elif typ == "Boolean":
                s.fmi2GetBoolean(s.component, vr, len(names), buf)
            else:
                s.fmi2GetInteger(s.component, vr, len(names), buf)
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
            if v.type == "Real":
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


def _groups(variables) -> dict[str, tuple[list[str], Any, Any]]:
    by: dict[str, list] = {}
    for v in variables:
        typ = "Integer" if v.type == "Enumeration" else v.type
        by.setdefault(typ, []).append(v)
    ctype = {"Real": fmi2Real, "Integer": fmi2Integer, "Boolean": fmi2Boolean}
    out = {}
    for typ, vs in by.items():
        n = len(vs)
        vr = (fmi2ValueReference * n)(*[v.valueReference for v in vs])
        out[typ] = ([v.name for v in vs], vr, (ctype[typ] * n)())
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
    None when the FMU carries no design file."""
    found = read_fmu_design(fmu_path)
    if found is None:
        return None
    design, member = found
    return design_summary(design, f"{Path(fmu_path).name}:{member}")


# --------------------------------------------------------------------------------------------
# the co-simulation
# --------------------------------------------------------------------------------------------
class CoSimulation:
    """A plant FMU plus observer FMUs on a scenario. Use :meth:`run` (or the function :func:`run`).

    scenario           a Scenario or a registered scenario name
    plant_fmu          path of the plant FMU (its inputs must all be scenario signals, except
                       the scenario's optional_plant_inputs, left at their start values)
    observer_fmus      {label: path}; each observer's inputs are pulled from the bus by name
    dt                 communication step, s (default 5 ms)
    noise              NoiseSpec (or {signal: (std, bias)}) applied to what observers receive
    seed               default seed of the noise generator
    plant_parameters   {parameter name: value} set on the plant before initialisation (e.g. mu)
    observer_parameters {label: {parameter name: value}} likewise for observers
    vehicle            vehicle name or Vehicle, used by the scenario for its amplitudes
    progress           show a tqdm progress bar
    fast               the step loop on preallocated buffers (:func:`_fast_loop`, default), or False:
                       the plain loop through fmpy's ``FMU2Slave`` wrappers (identical results, the
                       reference of the fast one)
    unzipped           {FMU path: folder it is already extracted to}: those FMUs are not extracted
                       again (a campaign's worker extracts each FMU once, not once per run); the
                       caller owns the folders
    """

    def __init__(self, scenario: Scenario | str, plant_fmu: str | os.PathLike,
                 observer_fmus: Mapping[str, str | os.PathLike] | None = None, dt: float = 0.005,
                 noise: NoiseSpec | Mapping | None = None, seed: int = 0,
                 plant_parameters: Mapping[str, Any] | None = None, vehicle: Any = "sedan",
                 progress: bool = False, observer_parameters: Mapping[str, Mapping[str, Any]] | None = None,
                 fast: bool = True, unzipped: Mapping[str | os.PathLike, str] | None = None):
        self.fast = bool(fast)
        self.unzipped = {Path(k).resolve(): str(v) for k, v in (unzipped or {}).items()}
        self.scenario = get_scenario(scenario)
        self.plant_path = Path(plant_fmu)
        self.observer_paths = {str(k): Path(v) for k, v in (observer_fmus or {}).items()}
        if PLANT_LABEL in self.observer_paths:
            raise WiringError(f"observer label {PLANT_LABEL!r} is reserved for the plant")
        for label, p in [(PLANT_LABEL, self.plant_path), *self.observer_paths.items()]:
            if not p.is_file():
                raise FileNotFoundError(f"FMU {label!r}: no such file {p}")
        if not dt > 0:
            raise ValueError(f"dt must be > 0 s, got {dt}")
        self.dt = float(dt)
        if noise is not None and not isinstance(noise, NoiseSpec):
            noise = NoiseSpec(dict(noise))
        self.noise = noise
        self.seed = seed
        self.plant_parameters = dict(plant_parameters or {})
        self.observer_parameters = {k: dict(v) for k, v in (observer_parameters or {}).items()}
        unknown = sorted(set(self.observer_parameters) - set(self.observer_paths))
        if unknown:
            raise WiringError(f"observer_parameters for unknown observer label(s) {', '.join(unknown)}")
        self.vehicle = vehicle
        self.progress = progress

    def run(self) -> SimResult:
        tmp = tempfile.mkdtemp(prefix="latobs_cosim_")
        fmus: list[FmuInstance] = []
        try:
            # extract each distinct FMU file once
            unzipped: dict[Path, str] = dict(self.unzipped)
            for p in [self.plant_path, *self.observer_paths.values()]:
                key = p.resolve()
                if key not in unzipped:
                    try:
                        unzipped[key] = extract(str(p), unzipdir=os.path.join(tmp, f"fmu{len(unzipped)}"))
                    except OSError:
                        raise
                    except Exception as exc:    # not a zip, truncated, corrupted: the file, not a bug
                        raise WiringError(f"FMU file {p}: not a readable FMU (zip archive): {exc}") from exc
            plant = FmuInstance(PLANT_LABEL, self.plant_path, unzipped[self.plant_path.resolve()])
            fmus.append(plant)
            observers = {lab: FmuInstance(lab, p, unzipped[p.resolve()]) for lab, p in self.observer_paths.items()}
            fmus.extend(observers.values())
            return self._simulate(plant, observers)
        finally:
            for f in reversed(fmus):
                f.close()
            shutil.rmtree(tmp, ignore_errors=True)

    # ----------------------------------------------------------------------------------------
    def _simulate(self, plant: FmuInstance, observers: dict[str, FmuInstance]) -> SimResult:
        sc, dt = self.scenario, self.dt
        t = sc.time_grid(dt)
        n = len(t)
        scen = sc.sampled(t, self.vehicle)

        # ---- wiring, checked before anything is instantiated
        optional = set(getattr(sc, "optional_plant_inputs", ()))
        missing = [v.name for v in plant.inputs if v.name not in scen and v.name not in optional]
        if missing:
            raise WiringError(
                f"plant {plant.describe()}: input(s) {', '.join(repr(m) for m in missing)} not provided by "
                f"scenario {sc.name!r} (it provides {', '.join(sorted(scen))})")
        held: dict[str, float] = {}   # optional plant inputs left at their declared start value
        for v in plant.inputs:
            if v.name not in scen:
                try:
                    held[v.name] = float(v.start)
                except (TypeError, ValueError):
                    held[v.name] = float("nan")
                if not np.isfinite(held[v.name]):
                    raise WiringError(f"plant {plant.describe()}: optional input {v.name!r} is not provided by "
                                      f"scenario {sc.name!r} and declares no finite start value")
        plant_in = [v.name for v in plant.inputs if v.name in scen]
        plant_out = [v.name for v in plant.outputs]
        bus_names = list(dict.fromkeys([*scen, *plant_out]))
        obs_in: dict[str, list[str]] = {}
        for lab, f in observers.items():
            names = [v.name for v in f.inputs]
            for x in names:
                if x not in bus_names:
                    raise WiringError(
                        f"observer {f.describe()}: input {x!r} has no signal on the bus "
                        f"(bus signals: {', '.join(bus_names)})")
            obs_in[lab] = names
        plant.check_parameters(self.plant_parameters)
        for lab, f in observers.items():
            f.check_parameters(self.observer_parameters.get(lab, {}))
        noise_arr: dict[str, np.ndarray] = {}
        if self.noise is not None:
            bad = sorted(set(self.noise.signals) - set(bus_names))
            if bad:
                raise WiringError(f"noise given for signal(s) {', '.join(repr(b) for b in bad)} not on the bus "
                                  f"(bus signals: {', '.join(bus_names)})")
            noise_arr = self.noise.draw(n, self.seed)
        measured_names = list(dict.fromkeys(x for names in obs_in.values() for x in names))

        units: dict[str, str] = {}
        for f in [plant, *observers.values()]:
            for v in f.md.modelVariables:
                u = _unit_of(v)
                if u and v.causality in ("input", "output"):
                    units.setdefault(v.name, u)

        # ---- storage
        bus = {k: np.empty(n) for k in bus_names}
        for k, v in scen.items():
            bus[k][:] = v
        measured = {k: np.empty(n) for k in measured_names}
        obs_rec: dict[str, dict[str, np.ndarray]] = {}
        for lab, f in observers.items():
            obs_rec[lab] = {v.name: np.zeros(n, dtype=float if v.type == "Real" else np.int64) for v in f.outputs}

        def fill_bus(k: int, plant_values: Mapping[str, float]):
            for name, val in plant_values.items():
                bus[name][k] = val
            for name in measured_names:
                val = bus[name][k]
                if name in noise_arr:
                    val = val + noise_arr[name][k]
                measured[name][k] = val

        def meas(k: int, names: list[str]) -> dict[str, float]:
            return {x: measured[x][k] for x in names}

        def call(f: FmuInstance, what: str, k: int, fn, *args):
            try:
                return fn(*args)
            except Exception as exc:
                raise CoSimulationError(
                    f"{f.describe()} failed in {what} at t = {t[k]:.6g} s: {str(exc).rstrip('.')}. Last log messages: "
                    f"{f.log_tail()}") from exc

        # ---- initialisation: plant first (its outputs at t0 feed the observers)
        t0, stop = float(t[0]), float(t[-1])
        u0 = {x: scen[x][0] for x in plant_in}
        fill_bus(0, call(plant, "initialisation", 0, plant.start, u0, self.plant_parameters, t0, stop))
        if held:
            plant.prepare_io(plant_in)   # only the driven inputs are set from now on
        at_start = getattr(sc, "initialise_at_start_values", False)   # as fmpy's simulate_ssp (ssp.py)
        for lab, f in observers.items():
            m0 = {v.name: float(v.start) for v in f.inputs} if at_start else meas(0, obs_in[lab])
            y0 = call(f, "initialisation", 0, f.start, m0, self.observer_parameters.get(lab, {}), t0, stop)
            for name, val in y0.items():
                obs_rec[lab][name][0] = val

        # ---- fixed-step loop
        steps = range(n - 1)
        if self.progress:
            from tqdm import tqdm

            steps = tqdm(steps, desc=f"{sc.name}", unit="step", leave=False)
        fast = self.fast and _fast_loop(steps, t, dt, plant, plant_in, scen, observers, obs_in, noise_arr, bus,
                                        measured, obs_rec)
        for k in (() if fast else steps):
            tk = float(t[k])
            call(plant, "setting inputs", k, plant.set_inputs, {x: scen[x][k] for x in plant_in})
            for lab, f in observers.items():
                call(f, "setting inputs", k, f.set_inputs, meas(k, obs_in[lab]))
            call(plant, "doStep", k, plant.slave.doStep, tk, dt)
            for f in observers.values():
                call(f, "doStep", k, f.slave.doStep, tk, dt)
            fill_bus(k + 1, call(plant, "getting outputs", k + 1, plant.get_outputs))
            for lab, f in observers.items():
                for name, val in call(f, "getting outputs", k + 1, f.get_outputs).items():
                    obs_rec[lab][name][k + 1] = val

        logs = {}
        for f in [plant, *observers.values()]:
            logs[f.label] = list(f.logs)
            if f.dropped_logs:
                logs[f.label].append(f"[INFO] harness: {f.dropped_logs} further log messages dropped")
        veh = self.vehicle if isinstance(self.vehicle, str) else getattr(self.vehicle, "name", str(self.vehicle))
        info = {
            "scenario": sc.info(self.vehicle),
            "vehicle": veh,
            "plant_fmu": str(self.plant_path),
            "plant_model": plant.model_name,
            "observer_fmus": {lab: str(p) for lab, p in self.observer_paths.items()},
            "observer_models": {lab: f.model_name for lab, f in observers.items()},
            "observer_designs": {lab: observer_design(p) for lab, p in self.observer_paths.items()},
            "plant_parameters": {k: (v if isinstance(v, (int, float, str, bool)) else str(v))
                                 for k, v in self.plant_parameters.items()},
            "plant_inputs_at_start": held,
            "noise": self.noise.as_dict() if self.noise is not None else None,
            "seed": self.seed,
        }
        return SimResult(time=t, bus=bus, observers=obs_rec, logs=logs, scenario=sc.name, dt=dt,
                         settle_time=float(sc.settle_time), measured=measured, units=units,
                         inputs={PLANT_LABEL: plant_in, **obs_in}, info=info)


def run(scenario: Scenario | str, plant_fmu: str | os.PathLike,
        observer_fmus: Mapping[str, str | os.PathLike] | None = None, dt: float = 0.005,
        noise: NoiseSpec | Mapping | None = None, seed: int = 0,
        plant_parameters: Mapping[str, Any] | None = None, vehicle: Any = "sedan",
        progress: bool = False, observer_parameters: Mapping[str, Mapping[str, Any]] | None = None,
        fast: bool = True, unzipped: Mapping[str | os.PathLike, str] | None = None) -> SimResult:
    """Co-simulate ``plant_fmu`` and ``observer_fmus`` on ``scenario``; see :class:`CoSimulation`."""
    return CoSimulation(scenario, plant_fmu, observer_fmus, dt=dt, noise=noise, seed=seed,
                        plant_parameters=plant_parameters, vehicle=vehicle, progress=progress,
                        observer_parameters=observer_parameters, fast=fast, unzipped=unzipped).run()


# ------------------------------------------------------------------------------------------------
# the fast master: fmpy's loaded libraries, called on preallocated buffers
# ------------------------------------------------------------------------------------------------
_GETSET = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_size_t, ctypes.c_void_p)
_DOSTEP = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_double, ctypes.c_double, ctypes.c_int)


class _FastIO:
    """One FMU's fmi2SetReal/DoStep/GetReal/GetInteger of the library fmpy loaded, called with
    raw addresses (rows of numpy arrays) instead of fmpy's checked wrappers: the same calls, without
    the per-call Python conversions, which dominate a step of a native FMU."""

    def __init__(self, f: FmuInstance):
        dll = f.slave.dll
        self.f = f
        self.c = f.slave.component
        self.set_real = _GETSET(("fmi2SetReal", dll))
        self.get_real = _GETSET(("fmi2GetReal", dll))
        self.get_integer = _GETSET(("fmi2GetInteger", dll))
        self.do_step = _DOSTEP(("fmi2DoStep", dll))
        reals = [v for v in f.outputs if v.type == "Real"]
        ints = [v for v in f.outputs if v.type in ("Integer", "Enumeration")]
        self.out_names, self.int_names = [v.name for v in reals], [v.name for v in ints]
        self.out_vr = np.array([v.valueReference for v in reals], dtype=np.uint32)
        self.int_vr = np.array([v.valueReference for v in ints], dtype=np.uint32)

    @staticmethod
    def usable(plant: FmuInstance, observers: Mapping[str, FmuInstance], obs_in) -> bool:
        """Real inputs, Real/Integer outputs, observers wired to Real plant outputs or scenario
        signals only (what latobs' FMUs have); else the plain loop."""
        fmus = (plant, *observers.values())
        plant_ints = {v.name for v in plant.outputs if v.type != "Real"}
        return (all(v.type == "Real" for f in fmus for v in f.inputs)
                and not any(v.type == "Boolean" for f in fmus for v in f.outputs)
                and not any(x in plant_ints for names in obs_in.values() for x in names))

    def fail(self, what: str, tk: float):
        """A call returned more than fmi2Warning: the plain loop's error (fmpy's status is in the log)."""
        raise CoSimulationError(f"{self.f.describe()} failed in {what} at t = {tk:.6g} s. Last log messages: "
                                f"{self.f.log_tail()}")


def _rows(a: np.ndarray) -> tuple[int, int]:
    """(address of row 0, bytes per row) of a C-contiguous 2-D array."""
    return a.ctypes.data, a.strides[0]


def _fast_loop(steps, t, dt, plant, plant_in, scen, observers, obs_in, noise_arr, bus, measured, obs_rec) -> bool:
    """The loop of ``CoSimulation._simulate`` on preallocated buffers, with the same calls in the
    same order and the same arithmetic (a measured value is the bus value plus its noise sample),
    so bit-identical results (``tests/test_validation.py`` checks it): every FMU's inputs and
    outputs live in float64 (Integer outputs: int32) matrices, one row per communication point,
    passed to the FMU by address; the plant's inputs are the scenario's matrix, an observer's input
    columns are its scenario signals (measured, computed once) and, filled after each step from
    the plant's output row, its plant outputs. Returns False, having called nothing, where it does
    not apply (:meth:`_FastIO.usable`)."""
    if not _FastIO.usable(plant, observers, obs_in):
        return False
    n = len(t)
    p = _FastIO(plant)
    p_in = np.ascontiguousarray(np.column_stack([np.asarray(scen[x], dtype=float) for x in plant_in]))
    p_out = np.zeros((n, len(p.out_names)))
    p_int = np.zeros((n, max(1, len(p.int_names))), dtype=np.int32)
    p_in_vr = np.array([plant.vars[x].valueReference for x in plant_in], dtype=np.uint32)
    p_out[0] = [bus[x][0] for x in p.out_names]
    p_int[0, :len(p.int_names)] = [bus[x][0] for x in p.int_names]
    col = {x: j for j, x in enumerate(p.out_names)}
    obs = []
    for lab, f in observers.items():
        o = _FastIO(f)
        names = obs_in[lab]
        o_in = np.zeros((n, len(names)))
        from_plant = [(c, col[x]) for c, x in enumerate(names) if x in col]
        for c, x in enumerate(names):
            if x not in col:                                   # a scenario signal: measured once
                o_in[:, c] = bus[x] + noise_arr[x] if x in noise_arr else bus[x]
            o_in[0, c] = measured[x][0]
        cols = np.array([c for c, _ in from_plant], dtype=np.intp)
        src = np.array([j for _, j in from_plant], dtype=np.intp)
        noise = (np.column_stack([noise_arr[names[c]] if names[c] in noise_arr else np.zeros(n) for c in cols])
                 if len(cols) else np.zeros((n, 0)))
        o_out = np.zeros((n, len(o.out_names)))
        o_int = np.zeros((n, max(1, len(o.int_names))), dtype=np.int32)
        for j, x in enumerate(o.out_names):
            o_out[0, j] = obs_rec[lab][x][0]
        for j, x in enumerate(o.int_names):
            o_int[0, j] = obs_rec[lab][x][0]
        in_vr = np.array([f.vars[x].valueReference for x in names], dtype=np.uint32)
        obs.append((lab, o, names, o_in, cols, src, noise, o_out, o_int, in_vr))

    pc, p_set, p_step, p_get, p_geti = p.c, p.set_real, p.do_step, p.get_real, p.get_integer
    pin_a, pin_s = _rows(p_in)
    pout_a, pout_s = _rows(p_out)
    pint_a, pint_s = _rows(p_int)
    npin, npout, npint = len(plant_in), len(p.out_names), len(p.int_names)
    pin_vr, pout_vr, pint_vr = p_in_vr.ctypes.data, p.out_vr.ctypes.data, p.int_vr.ctypes.data
    fast_obs = [(o.c, o.set_real, o.do_step, o.get_real, o.get_integer, *_rows(o_in), len(names), in_vr.ctypes.data,
                 *_rows(o_out), len(o.out_names), o.out_vr.ctypes.data, *_rows(o_int), len(o.int_names),
                 o.int_vr.ctypes.data, o_in, cols, src, noise, o)
                for lab, o, names, o_in, cols, src, noise, o_out, o_int, in_vr in obs]
    for k in steps:
        tk = float(t[k])
        k1 = k + 1
        if p_set(pc, pin_vr, npin, pin_a + k * pin_s) > 1:
            p.fail("setting inputs", tk)
        for (c, set_, _s, _g, _gi, ia, is_, ni, ivr, *_rest, o) in fast_obs:
            if set_(c, ivr, ni, ia + k * is_) > 1:
                o.fail("setting inputs", tk)
        if p_step(pc, tk, dt, 1) > 1:
            p.fail("doStep", tk)
        for (c, _set, step, *_rest, o) in fast_obs:
            if step(c, tk, dt, 1) > 1:
                o.fail("doStep", tk)
        if p_get(pc, pout_vr, npout, pout_a + k1 * pout_s) > 1 or (
                npint and p_geti(pc, pint_vr, npint, pint_a + k1 * pint_s) > 1):
            p.fail("getting outputs", t[k1])
        for (c, _set, _step, get, geti, _ia, _is, _ni, _ivr, oa, os_, no, ovr, ia2, is2, nint, ivr2,
             o_in, cols, src, noise, o) in fast_obs:
            if len(cols):
                o_in[k1, cols] = p_out[k1, src] + noise[k1] if noise.shape[1] else p_out[k1, src]
            if get(c, ovr, no, oa + k1 * os_) > 1 or (nint and geti(c, ivr2, nint, ia2 + k1 * is2) > 1):
                o.fail("getting outputs", t[k1])
    for j, x in enumerate(p.out_names):
        bus[x][:] = p_out[:, j]
    for j, x in enumerate(p.int_names):
        bus[x][:] = p_int[:, j]
    for x in measured:
        measured[x][:] = bus[x] + noise_arr[x] if x in noise_arr else bus[x]
    for lab, o, names, o_in, cols, src, noise, o_out, o_int, in_vr in obs:
        for j, x in enumerate(o.out_names):
            obs_rec[lab][x][:] = o_out[:, j]
        for j, x in enumerate(o.int_names):
            obs_rec[lab][x][:] = o_int[:, j]
    return True
