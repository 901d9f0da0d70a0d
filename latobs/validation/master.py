"""The co-simulation master: a plant FMU and observer FMUs stepped together on a scenario's fixed
grid, wired by variable name through a signal bus, observers seeing it through a measurement model
(:class:`NoiseSpec`). The wiring, measurement and timing rules are in docs/validation.md.

Every FMU's inputs and outputs live in typed matrices, one row per communication point, handed to
the FMI calls by address; one stepping loop runs the same calls for every FMU kind.
"""
from __future__ import annotations

import os
import shutil
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np


from .instance import (FMI_TYPES, CoSimulationError, FmuInstance, WiringError, _unit_of, extract, fmi_type,
                       observer_design)
from .scenarios import Scenario, get_scenario

PLANT_LABEL = "plant"
_DTYPE = {"Real": np.float64, "Integer": np.int32, "Boolean": np.int32}   # fmi2Real, fmi2Integer, fmi2Boolean


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

    def blocks(self, n: int, default_seed: int = 0) -> "NoiseBlocks":
        """The draws of :meth:`draw` taken a block at a time (:class:`NoiseBlocks`): the same
        numbers for the same (seed, signals, n), without holding n of them."""
        return NoiseBlocks(self, n, default_seed)

    def as_dict(self) -> dict:
        return {"signals": {k: {"std": float(v[0]), "bias": float(v[1])} for k, v in self.signals.items()},
                "seed": self.seed}


class NoiseBlocks:
    """:meth:`NoiseSpec.draw` (n samples per signal, in sorted name order from one generator)
    taken block by block: ``take(m)`` gives each signal's next m errors. Signal i's numbers start
    where signal i - 1's n numbers end in the one generator, so its generator's state there is
    found once by drawing (and dropping) those n numbers a block at a time; numpy's normal draws
    split into blocks are the same numbers as one draw of their total (the ziggurat keeps no
    state between calls), so every error equals the whole-run draw's bit for bit."""

    CHUNK = 1 << 16

    def __init__(self, spec: NoiseSpec, n: int, default_seed: int = 0):
        g = spec.rng(default_seed)
        self.gens: dict[str, tuple[np.random.Generator, float, float]] = {}
        names = sorted(spec.signals)
        for i, name in enumerate(names):
            h = np.random.Generator(type(g.bit_generator)())
            h.bit_generator.state = g.bit_generator.state
            std, bias = (float(x) for x in spec.signals[name])
            self.gens[name] = (h, std, bias)
            if i + 1 < len(names):          # the next signal's numbers start after this one's n
                for k in range(0, n, self.CHUNK):
                    g.standard_normal(min(self.CHUNK, n - k))

    def take(self, m: int) -> dict[str, np.ndarray]:
        return {name: bias + std * h.standard_normal(m) for name, (h, std, bias) in self.gens.items()}


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
               None} (:func:`~latobs.validation.instance.observer_design`)
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
# one FMU in the master
# --------------------------------------------------------------------------------------------
class Port:
    """One FMU's inputs and outputs as matrices, one per FMI type (float64 for Real, int32 for
    Integer/Enumeration/Boolean, as FMI 2 passes them), one row per communication point, and its
    calls that set or get a row: ``sets``/``gets`` are (call, component, vr address, count, row 0
    address, row stride, port) with an empty type skipped, in the order Real, Integer, Boolean."""

    def __init__(self, f: FmuInstance, input_names: list[str], n: int, checked: bool):
        self.f, self.checked = f, checked
        calls = f.row_calls(checked)
        self.component, self.do_step = calls.component, calls.do_step
        self.inputs = _matrices(f, [f.vars[x] for x in input_names], n)
        self.outputs = _matrices(f, f.outputs, n)
        self.sets = [(calls.set[typ], calls.component, vr.ctypes.data, len(names), m.ctypes.data, m.strides[0], self)
                     for typ, (names, vr, m) in self.inputs.items()]
        self.gets = [(calls.get[typ], calls.component, vr.ctypes.data, len(names), m.ctypes.data, m.strides[0], self)
                     for typ, (names, vr, m) in self.outputs.items()]

    @staticmethod
    def columns(groups) -> dict[str, tuple[str, int]]:
        """{variable name: (FMI type, column)} of ``self.inputs`` or ``self.outputs``."""
        return {x: (typ, j) for typ, (names, _, _) in groups.items() for j, x in enumerate(names)}

    def fail(self, what: str, tk: float, status: int):
        raise CoSimulationError(f"{self.f.describe()} failed in {what} at t = {tk:.6g} s (status {status}). "
                                f"Last log messages: {self.f.log_tail()}")


def _matrices(f: FmuInstance, variables, n: int) -> dict[str, tuple[list[str], np.ndarray, np.ndarray]]:
    """{FMI type: (names, value references, n-row matrix)} of ``variables``, types in FMI_TYPES order."""
    out = {}
    for typ in FMI_TYPES:
        vs = [v for v in variables if fmi_type(v) == typ]
        if vs:
            out[typ] = ([v.name for v in vs], np.array([v.valueReference for v in vs], dtype=np.uint32),
                        np.zeros((n, len(vs)), dtype=_DTYPE[typ]))
    return out


def store_input(port: Port, typ: str, j: int, rows, values, name: str, t: np.ndarray):
    """Write float ``values`` into input column j of ``port`` at ``rows``; an Integer or Boolean input
    takes the nearest integer, and a value that is not finite or beyond 32 bits there is a
    CoSimulationError (never a silently wrapped value)."""
    m = port.inputs[typ][2]
    if typ == "Real":
        m[rows, j] = values
        return
    v = np.atleast_1d(np.asarray(values, dtype=float))
    bad = ~np.isfinite(v) | (np.abs(v) > 2**31 - 1)
    if bad.any():
        k = np.atleast_1d(np.arange(len(t))[rows])[int(np.argmax(bad))]
        raise CoSimulationError(f"{port.f.describe()}: {typ} input {name!r} gets {float(v[bad][0])!r} at "
                                f"t = {t[k]:.6g} s, not representable as fmi2{typ} (a 32-bit int)")
    m[rows, j] = np.rint(v) if np.ndim(values) else np.rint(v[0])


def _int_route(o: Port, typ: str, cols, src, src_cols, nz, t):
    """The route into Integer/Boolean inputs of ``o``: each value stored by :func:`store_input`."""
    def route(k: int):
        v = src[k, src_cols] if nz is None else src[k, src_cols] + nz[k]
        for (j, x), val in zip(cols, v):
            store_input(o, typ, j, k, float(val), x, t)
    return route


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
    fast               the FMI calls made directly into the libraries fmpy loaded (default), or
                       False: through fmpy's checked ``FMU2Slave`` wrappers, the same calls in the
                       same loop (identical results, the reference of the direct calls)
    unzipped           {FMU path: folder it is already extracted to}: those FMUs are not extracted
                       again (a campaign's worker extracts each FMU once, not once per run); the
                       caller owns the folders
    sink               None (every sample returned in memory), or what receives a long run's rows
                       block by block (more than :func:`stream_steps` steps): ``sink.block(k0,
                       part)`` for each block, ``sink.finish(result)`` makes the result returned
                       (:meth:`_simulate_blocks`; :class:`latobs.validation.stream.CosimSink`)
    """

    def __init__(self, scenario: Scenario | str, plant_fmu: str | os.PathLike,
                 observer_fmus: Mapping[str, str | os.PathLike] | None = None, dt: float = 0.005,
                 noise: NoiseSpec | Mapping | None = None, seed: int = 0,
                 plant_parameters: Mapping[str, Any] | None = None, vehicle: Any = "sedan",
                 progress: bool = False, observer_parameters: Mapping[str, Mapping[str, Any]] | None = None,
                 fast: bool = True, unzipped: Mapping[str | os.PathLike, str] | None = None, sink: Any = None):
        self.fast = bool(fast)
        self.sink = sink
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
        from .campaign import check_run_resources

        steps = sc.duration / dt
        if self.sink is not None and np.isfinite(steps) and round(steps) > stream_steps():
            # a long run: stepped block by block, its rows handed to the sink (constant memory)
            check_run_resources(f"scenario {sc.name!r}", sc.duration, dt, block_steps=BLOCK_STEPS)
            return self._simulate_blocks(plant, observers, int(round(steps)))
        check_run_resources(f"scenario {sc.name!r}", sc.duration, dt)    # before its grid is made
        t = sc.time_grid(dt)
        n = len(t)
        scen = sc.sampled(t, self.vehicle)
        w = self._wiring(plant, observers, scen)
        held, plant_in, bus_names, obs_in, measured_names, units = (
            w["held"], w["plant_in"], w["bus_names"], w["obs_in"], w["measured_names"], w["units"])
        noise: dict[str, np.ndarray] = {}
        if self.noise is not None:
            noise = self.noise.draw(n, self.seed)

        # ---- initialisation: plant first (its outputs at t0 feed the observers)
        sig = {x: np.empty(n) for x in scen}
        for x, v in scen.items():
            sig[x][:] = v
        y0, obs_y0 = self._start(plant, observers, w, sig, noise, float(t[0]), float(t[-1]))

        # ---- the buffers: a plant input column is the scenario's signal; an observer input column
        # is its measured signal, computed once for a scenario signal, after each step for a plant
        # output (a route)
        p = Port(plant, plant_in, n, not self.fast)
        for x, (typ, j) in p.columns(p.inputs).items():
            store_input(p, typ, j, slice(None), sig[x], x, t)
        p_out = p.columns(p.outputs)
        for x, (typ, j) in p_out.items():
            p.outputs[typ][2][0, j] = y0[x]
        ports = [p]
        routes = []   # (destination matrix, its columns, source matrix, its columns, noise or None, int store)
        for lab, f in observers.items():
            o = Port(f, obs_in[lab], n, not self.fast)
            ports.append(o)
            for x, (typ, j) in o.columns(o.outputs).items():
                o.outputs[typ][2][0, j] = obs_y0[lab][x]
            for x, (typ, j) in o.columns(o.inputs).items():
                if x not in p_out:
                    store_input(o, typ, j, slice(None), sig[x] + noise[x] if x in noise else sig[x], x, t)
            routes += _routes(o, p, p_out, noise, t)

        _route_row(routes, 0)

        # ---- the stepping loop: at t_k set every FMU's inputs, step every FMU, get the outputs at t_k+1
        stepping_started = time.perf_counter()
        loop = step_ports(t, dt, ports, routes, progress=sc.name if self.progress else None)

        stepping_seconds = time.perf_counter() - stepping_started

        # ---- results
        bus, measured, obs_rec = _rows(observers, ports, sig, noise, bus_names, measured_names, slice(None))
        return SimResult(time=t, bus=bus, observers=obs_rec, logs=self._logs(plant, observers), scenario=sc.name,
                         dt=dt, settle_time=float(sc.settle_time), measured=measured, units=units,
                         inputs={PLANT_LABEL: plant_in, **obs_in},
                         info=self._info(plant, observers, held, loop, stepping_seconds))

    def _wiring(self, plant: FmuInstance, observers: dict[str, FmuInstance], scen) -> dict[str, Any]:
        """The wiring of the scenario signals ``scen`` (names), the plant and the observers, checked
        before anything is instantiated: {"held", "plant_in", "bus_names", "obs_in",
        "measured_names", "units"}."""
        sc = self.scenario
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
        if self.noise is not None:
            bad = sorted(set(self.noise.signals) - set(bus_names))
            if bad:
                raise WiringError(f"noise given for signal(s) {', '.join(repr(b) for b in bad)} not on the bus "
                                  f"(bus signals: {', '.join(bus_names)})")
        measured_names = list(dict.fromkeys(x for names in obs_in.values() for x in names))

        units: dict[str, str] = {}
        for f in [plant, *observers.values()]:
            for v in f.md.modelVariables:
                u = _unit_of(v)
                if u and v.causality in ("input", "output"):
                    units.setdefault(v.name, u)
        return {"held": held, "plant_in": plant_in, "bus_names": bus_names, "obs_in": obs_in,
                "measured_names": measured_names, "units": units}

    def _start(self, plant: FmuInstance, observers: dict[str, FmuInstance], w: dict[str, Any], sig, noise,
               t0: float, stop: float) -> tuple[dict, dict]:
        """Initialise the plant (inputs at row 0 of ``sig``) and then the observers (the plant's
        outputs at t0, plus row 0 of ``noise``); returns (plant outputs, {label: outputs}) at t0."""
        def call(f: FmuInstance, fn, *args):
            try:
                return fn(*args)
            except Exception as exc:
                raise CoSimulationError(
                    f"{f.describe()} failed in initialisation at t = {t0:.6g} s: {str(exc).rstrip('.')}. "
                    f"Last log messages: {f.log_tail()}") from exc

        y0 = call(plant, plant.start, {x: sig[x][0] for x in w["plant_in"]}, self.plant_parameters, t0, stop)
        bus0 = {x: float(y0[x]) if x in y0 else sig[x][0] for x in w["measured_names"]}
        at_start = getattr(self.scenario, "initialise_at_start_values", False)   # as fmpy's simulate_ssp (ssp.py)
        obs_y0 = {}
        for lab, f in observers.items():
            m0 = ({v.name: float(v.start) for v in f.inputs} if at_start else
                  {x: bus0[x] + noise[x][0] if x in noise else bus0[x] for x in w["obs_in"][lab]})
            obs_y0[lab] = call(f, f.start, m0, self.observer_parameters.get(lab, {}), t0, stop)
        return y0, obs_y0

    @staticmethod
    def _logs(plant: FmuInstance, observers: dict[str, FmuInstance]) -> dict[str, list[str]]:
        logs = {}
        for f in [plant, *observers.values()]:
            logs[f.label] = list(f.logs)
            if f.dropped_logs:
                logs[f.label].append(f"[INFO] harness: {f.dropped_logs} further log messages dropped")
        return logs

    def _info(self, plant: FmuInstance, observers: dict[str, FmuInstance], held, loop: str,
              stepping_seconds: float) -> dict[str, Any]:
        sc = self.scenario
        veh = self.vehicle if isinstance(self.vehicle, str) else getattr(self.vehicle, "name", str(self.vehicle))
        return {
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
            # which stepping loop ran ("compiled": compiled_loop; "python": the Python loop) and its
            # wall time (s, the steps alone: no extraction, instantiation or initialisation)
            "master_loop": loop,
            "stepping_seconds": stepping_seconds,
        }

    def _simulate_blocks(self, plant: FmuInstance, observers: dict[str, FmuInstance], steps: int) -> SimResult:
        """The co-simulation of a long run (more than :func:`stream_steps` steps) in blocks of
        :data:`BLOCK_STEPS` steps: per block the scenario's signals on its rows of the grid, the
        noise's next draws (:class:`NoiseBlocks`: the whole run's numbers), the stepping
        (:func:`step_ports` on rows 0 .. m of matrices of BLOCK_STEPS + 1 rows: row 0 the previous
        block's last row), then ``self.sink.block(k0, part)`` with the block's rows k0 .. k0 + m
        (a SimResult: row 0 is the previous block's last row, already handed over, for the first
        block the initial row). The same calls on the same values as the whole-run path: every
        row is bit for bit the same. Returns a SimResult without samples (``time`` and the series
        empty; ``info["streamed"]`` says how it ran); ``self.sink.finish(result)`` makes the
        caller's result of it."""
        sc, dt, sink = self.scenario, self.dt, self.sink
        block = max(1, int(BLOCK_STEPS))

        def grid(k0: int, k1: int) -> np.ndarray:      # rows k0 .. k1 of Scenario.time_grid(dt)
            return np.arange(k0, k1 + 1) * dt

        t = grid(0, min(block, steps))
        scen = {x: np.array(v) for x, v in sc.sampled(t, self.vehicle).items()}
        w = self._wiring(plant, observers, scen)
        plant_in, bus_names, obs_in, measured_names = w["plant_in"], w["bus_names"], w["obs_in"], w["measured_names"]
        draws = self.noise.blocks(steps + 1, self.seed) if self.noise is not None else None
        noise = draws.take(len(t)) if draws is not None else {}
        y0, obs_y0 = self._start(plant, observers, w, scen, noise, 0.0, float(grid(steps, steps)[0]))
        rows = block + 1
        p = Port(plant, plant_in, rows, not self.fast)
        p_out = p.columns(p.outputs)
        for x, (typ, j) in p_out.items():
            p.outputs[typ][2][0, j] = y0[x]
        ports = [p]
        for lab, f in observers.items():
            o = Port(f, obs_in[lab], rows, not self.fast)
            ports.append(o)
            for x, (typ, j) in o.columns(o.outputs).items():
                o.outputs[typ][2][0, j] = obs_y0[lab][x]
        bar = None
        if self.progress or _interactive():
            from tqdm import tqdm

            bar = tqdm(total=steps, desc=sc.name if self.progress else "stepping", unit="step", leave=False)
        loop, stepping_seconds, k0, nblocks = "", 0.0, 0, 0
        units, inputs = w["units"], {PLANT_LABEL: plant_in, **obs_in}
        part_info = {"steps": steps, "observer_models": {lab: f.model_name for lab, f in observers.items()}}
        try:
            while k0 < steps:
                k1 = min(steps, k0 + block)
                m = k1 - k0
                if k0:
                    t = grid(k0, k1)
                    scen = {x: np.array(v) for x, v in sc.sampled(t, self.vehicle).items()}
                    # row 0: the previous block's last row (its noise drawn then, its outputs got then)
                    fresh = draws.take(m) if draws is not None else {}
                    noise = {x: np.concatenate([[last_noise[x]], fresh[x]]) for x in fresh}
                    for port in ports:
                        for _, _, mat in port.outputs.values():
                            mat[0] = mat[last]
                rs = slice(0, m + 1)
                for x, (typ, j) in p.columns(p.inputs).items():
                    store_input(p, typ, j, rs, scen[x], x, t)
                routes = []
                for o in ports[1:]:
                    for x, (typ, j) in o.columns(o.inputs).items():
                        if x not in p_out:
                            store_input(o, typ, j, rs, scen[x] + noise[x] if x in noise else scen[x], x, t)
                    routes += _routes(o, p, p_out, noise, t)
                _route_row(routes, 0)
                started = time.perf_counter()
                loop = step_ports(t, dt, ports, routes)
                stepping_seconds += time.perf_counter() - started
                bus, measured, obs_rec = _rows(observers, ports, scen, noise, bus_names, measured_names, rs)
                sink.block(k0, SimResult(time=t, bus=bus, observers=obs_rec, logs={}, scenario=sc.name, dt=dt,
                                         settle_time=float(sc.settle_time), measured=measured, units=units,
                                         inputs=inputs, info=part_info))
                last, last_noise = m, {x: v[m] for x, v in noise.items()}
                k0, nblocks = k1, nblocks + 1
                if bar is not None:
                    bar.update(m)
        finally:
            if bar is not None:
                bar.close()
        info = self._info(plant, observers, w["held"], loop, stepping_seconds)
        info["streamed"] = {"steps": steps, "samples": steps + 1, "block_steps": block, "blocks": nblocks}
        return sink.finish(SimResult(time=np.empty(0), bus={}, observers={}, logs=self._logs(plant, observers),
                                     scenario=sc.name, dt=dt, settle_time=float(sc.settle_time), units=units,
                                     inputs=inputs, info=info))


STREAM_ENV = "LATOBS_STREAM_ABOVE_STEPS"
#: a co-simulation of more steps than this is stepped in blocks when its caller streams it (a
#: sink: ``latobs validate``, campaign runs); $LATOBS_STREAM_ABOVE_STEPS sets it. Every registered
#: scenario and campaign run at its usual step is far below (a 60 s run at 1 ms: 6e4 steps)
STREAM_ABOVE_STEPS = 1_000_000
#: steps of a block of a streamed co-simulation
BLOCK_STEPS = 100_000


def stream_steps() -> int:
    """The number of steps above which a co-simulation with a sink is streamed (STREAM_ABOVE_STEPS)."""
    text = os.environ.get(STREAM_ENV, "").strip()
    try:
        return int(float(text)) if text else STREAM_ABOVE_STEPS
    except ValueError:
        raise ValueError(f"${STREAM_ENV} must be a number of steps, got {text!r}") from None


#: a run of this many steps or more shows a progress bar on a terminal (a few seconds of stepping)
PROGRESS_STEPS = 1_000_000


def _interactive() -> bool:
    """Whether this is the command's own process (not a worker: a campaign's runs stay quiet) and
    its stderr a terminal."""
    import multiprocessing
    import sys

    return multiprocessing.parent_process() is None and getattr(sys.stderr, "isatty", lambda: False)()


def step_ports(t: np.ndarray, dt: float, ports: list[Port], routes=(), progress: str | None = None) -> str:
    """The stepping loop over ``ports`` (their input matrices filled, row 0 of their outputs set):
    at each t_k every port's inputs set from row k, every FMU stepped by dt, every port's outputs
    got into row k + 1, then ``routes`` (destination matrix, its columns, source matrix, its
    columns, noise or None, Integer/Boolean route or None) fill row k + 1 of routed inputs. In C
    (:mod:`.compiled_loop`) when it can run here: FMI 2.0 FMUs called directly (ports not
    ``checked``), Real routes; else the same calls in Python. ``progress``: a bar's label (None: no bar,
    but for a run of :data:`PROGRESS_STEPS` or more on a terminal). A failed
    call is :meth:`Port.fail` (CoSimulationError naming the FMU, the call and the time). Returns
    which loop ran: "compiled" or "python"."""
    n = len(t)
    if progress is None and n - 1 >= PROGRESS_STEPS and _interactive():
        progress = "stepping"        # a long run shows a bar of its own on a terminal
    sets = [s for port in ports for s in port.sets]
    stepping = [(port.do_step, port.component, port) for port in ports]
    gets = [g for port in ports for g in port.gets]
    compiled = _compiled(t, dt, ports, sets, stepping, gets, routes)
    if compiled is not None:
        # the same calls in C (compiled_loop), in chunks when a progress bar is shown
        chunk = n - 1 if not progress else max(1, (n - 1) // 100)
        bar = None
        if progress:
            from tqdm import tqdm

            bar = tqdm(total=n - 1, desc=progress, unit="step", leave=False)
        try:
            for k0 in range(0, n - 1, chunk):
                k1 = min(n - 1, k0 + chunk)
                failed = compiled.run(k0, k1)
                if failed is not None:
                    k, what, port, st = failed
                    port.fail(what, float(t[k + 1] if what == "getting outputs" else t[k]), st)
                if bar is not None:
                    bar.update(k1 - k0)
        finally:
            if bar is not None:
                bar.close()
        return "compiled"

    steps = range(n - 1)
    if progress:
        from tqdm import tqdm

        steps = tqdm(steps, desc=progress, unit="step", leave=False)
    for k in steps:
        tk = float(t[k])
        k1 = k + 1
        for fn, c, vr, m, a, stride, port in sets:
            st = fn(c, vr, m, a + k * stride)
            if st > 1:
                port.fail("setting inputs", tk, st)
        for fn, c, port in stepping:
            st = fn(c, tk, dt, 1)
            if st > 1:
                port.fail("doStep", tk, st)
        for fn, c, vr, m, a, stride, port in gets:
            st = fn(c, vr, m, a + k1 * stride)
            if st > 1:
                port.fail("getting outputs", t[k1], st)
        if routes:
            _route_row(routes, k1)
    return "python"


def _routes(o: Port, p: Port, p_out, noise, t) -> list[tuple]:
    """The routes into observer port ``o``'s inputs that are plant outputs (of ``p``, columns
    ``p_out``): (destination matrix, its columns, source matrix, its columns, noise matrix or None,
    Integer/Boolean route or None), one per (input type, output type, noisy) group."""
    from_plant: dict[tuple, list] = {}
    for x, (typ, j) in o.columns(o.inputs).items():
        if x in p_out:
            from_plant.setdefault((typ, p_out[x][0], x in noise), []).append((j, x))
    routes = []
    for (typ, src_typ, noisy), cols in from_plant.items():
        names = [x for _, x in cols]
        src, src_cols = p.outputs[src_typ][2], np.array([p_out[x][1] for x in names], dtype=np.intp)
        nz = np.column_stack([noise[x] for x in names]) if noisy else None
        routes.append((o.inputs[typ][2], np.array([j for j, _ in cols], dtype=np.intp), src, src_cols, nz,
                       None if typ == "Real" else _int_route(o, typ, cols, src, src_cols, nz, t)))
    return routes


def _rows(observers: dict[str, FmuInstance], ports: list[Port], sig, noise, bus_names, measured_names, rs):
    """(bus, measured, {label: outputs}) of rows ``rs`` of the ports' matrices (``ports[0]`` the
    plant's), beside the scenario signals ``sig`` and the noise on those rows; a plant output
    overwrites a scenario signal of its name in ``sig``."""
    p = ports[0]
    n = len(next(iter(p.outputs.values()))[2][rs]) if p.outputs else len(next(iter(sig.values())))
    bus = {x: sig[x] if x in sig else np.empty(n) for x in bus_names}
    for x, (typ, j) in p.columns(p.outputs).items():
        bus[x][:] = p.outputs[typ][2][rs, j]
    measured = {x: bus[x] + noise[x] if x in noise else bus[x].copy() for x in measured_names}
    obs_rec: dict[str, dict[str, np.ndarray]] = {}
    for (lab, f), o in zip(observers.items(), ports[1:]):
        cols = o.columns(o.outputs)
        obs_rec[lab] = {v.name: o.outputs[cols[v.name][0]][2][rs, cols[v.name][1]].astype(
            float if fmi_type(v) == "Real" else np.int64) for v in f.outputs}
    return bus, measured, obs_rec


def _route_row(routes, k: int) -> None:
    """Routed inputs at row k from their sources at row k (an observer's from the plant's
    outputs, plus their noise)."""
    for dst, cols, src, src_cols, nz, int_route in routes:
        if int_route is not None:
            int_route(k)
        else:
            dst[k, cols] = src[k, src_cols] if nz is None else src[k, src_cols] + nz[k]


def _compiled(t, dt, ports, sets, stepping, gets, routes):
    """The compiled loop (:mod:`.compiled_loop`) over these calls, or None: the Python loop
    (fmpy's checked calls, an FMI 3.0 FMU, an Integer or Boolean route, no compiled loop here)."""
    if any(p.checked or p.f.fmi != 2 for p in ports) or any(r[5] is not None for r in routes):
        return None
    from . import compiled_loop

    lib = compiled_loop.library()
    if lib is None:
        return None
    return compiled_loop.Loop(lib, t, dt, sets, stepping, gets, [r[:5] for r in routes])


def run(scenario: Scenario | str, plant_fmu: str | os.PathLike,
        observer_fmus: Mapping[str, str | os.PathLike] | None = None, dt: float = 0.005,
        noise: NoiseSpec | Mapping | None = None, seed: int = 0,
        plant_parameters: Mapping[str, Any] | None = None, vehicle: Any = "sedan",
        progress: bool = False, observer_parameters: Mapping[str, Mapping[str, Any]] | None = None,
        fast: bool = True, unzipped: Mapping[str | os.PathLike, str] | None = None, sink: Any = None) -> SimResult:
    """Co-simulate ``plant_fmu`` and ``observer_fmus`` on ``scenario``; see :class:`CoSimulation`."""
    return CoSimulation(scenario, plant_fmu, observer_fmus, dt=dt, noise=noise, seed=seed,
                        plant_parameters=plant_parameters, vehicle=vehicle, progress=progress,
                        observer_parameters=observer_parameters, fast=fast, unzipped=unzipped, sink=sink).run()
