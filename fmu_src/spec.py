"""What an FMU model file declares: its variables and the runtime class that does the maths.

Standard library only. The FMI glue (``framework.py``) reads a ``ModelSpec`` and never holds
maths; the runtime classes know nothing of FMI. A runtime class follows this protocol:

    rt = Runtime(data, params)   # data: the FMU's JSON data file (design or plant file),
                                 # params: {parameter name: value} after initialisation
    rt.y                         # dict {output name: value}, valid after construction
    rt.initialize(u)             # optional: the inputs set in initialisation mode (finite), so that
                                 # the outputs at the start time are consistent with them
    rt.step(h, u)                # advance h seconds, inputs u (dict name -> float) held
    rt.events                    # list of (level, message) produced by the last call,
                                 # level in {"warning", "error"}; drained by the framework
    Runtime.parameter_defaults(data)   # optional: data-dependent parameter start values

``step`` receives only inputs inside their declared [min, max] (the FMI layers of both backends
refuse a step with any other input, non-finite ones included, with an error and the state kept)
and a step 0 < h <= the model's ``max_step`` (longer steps are refused likewise); it must not
raise for such values. Within the declared range a runtime may still clamp an input to the range
its maths is meant for, as it documents, with a warning.
Outputs change only in ``initialize`` and ``step``: the model description declares that no
output depends directly on an input (no direct feedthrough), and the tests check it.
"""
from __future__ import annotations

import math

from dataclasses import dataclass, field
from typing import Callable, Optional


DEFAULT_STEP = 0.005  # s: the communication step suggested in the model description (and the step
#                       the runtime tables' step maps are computed for, synthesis.tables)

# Physical bounds of the signals every FMU takes as inputs (SI). Each is a value no road vehicle
# or sensor produces, wide enough for any real record (noise and reversing included) and for the
# runtimes' own documented clamps to stay reachable inside it, narrow enough that no arithmetic
# of a runtime can overflow (a MotorcycleFaultObserver fed 1e155 rad once computed inf - inf and
# stayed NaN for good). A step with an input outside them is refused by both FMI layers.
SPEED_MAX = 250.0                # m/s (900 km/h): above any road vehicle's top speed and the
#                                  runtimes' own speed clamps (the Kalman filter's default 200 m/s);
#                                  >= -SPEED_MAX for reversing (the observers freeze below vx_hold)
ANGLE_MAX = 0.5 * math.pi        # rad: road-wheel and handlebar steering, roll and bank angles; beyond
#                                  90 deg no vehicle is on its wheels (the plants clamp far inside)
RATE_MAX = 35.0                  # rad/s (2000 deg/s): the largest full scale of common MEMS gyroscopes
ACCEL_MAX = 160.0                # m/s2 (16 g): the largest full scale of common MEMS accelerometers
TORQUE_MAX = 1000.0              # N m: rider steering torque, ~5x the strongest rider's
SCALE_MAX = 100.0                # 1: a cornering stiffness scale factor is >= 0 (no grip); the car
#                                  plant clamps it to [0.1, 10] with a warning
# the keyword arguments of Var declaring them
SPEED = {"min": -SPEED_MAX, "max": SPEED_MAX}
ANGLE = {"min": -ANGLE_MAX, "max": ANGLE_MAX}
RATE = {"min": -RATE_MAX, "max": RATE_MAX}
ACCEL = {"min": -ACCEL_MAX, "max": ACCEL_MAX}
TORQUE = {"min": -TORQUE_MAX, "max": TORQUE_MAX}
SCALE = {"min": 0.0, "max": SCALE_MAX}

# Sign conventions and sources of the measured signals (keyword arguments of Var). Cars: ISO 8855
# axes, x forward, y left, z up (CarPlant's); motorcycles: SAE axes, x forward, y right, z down
# (Sharp's, MotorcyclePlant's). Observer inputs and plant outputs share names: wiring is by name.
LEFT = "> 0 to the left"
RIGHT = "> 0 to the right"
CAR = {
    "delta": {"sign": "> 0 steers left",
              "sensor": "steering-wheel angle sensor divided by the steering ratio (CarPlant input delta)"},
    "vx": {"sign": "> 0 forward", "sensor": "wheel-speed sensors or GNSS (CarPlant input vx)"},
    "yaw_rate": {"sign": "> 0 turning left (counter-clockwise seen from above)",
                 "sensor": "IMU yaw-rate gyroscope (CarPlant output yaw_rate)"},
    "roll_angle": {"sign": "> 0 leaning right", "sensor": "IMU roll angle estimate (CarPlant output roll_angle)"},
    "roll_rate": {"sign": "> 0 rolling to the right", "sensor": "IMU roll-rate gyroscope (CarPlant output roll_rate)"},
    "ay": {"sign": LEFT, "sensor": "IMU lateral accelerometer at the centre of gravity (CarPlant output ay)"},
}
CAR_BETA = "> 0 when the velocity points left of the heading (vy > 0)"
MOTORCYCLE = {
    "vx": {"sign": "> 0 forward", "sensor": "wheel-speed sensor (MotorcyclePlant input vx)"},
    "steer_angle": {"sign": "> 0 steers right",
                    "sensor": "steering-head angle encoder (MotorcyclePlant output steer_angle)"},
    "yaw_rate": {"sign": "> 0 turning right", "sensor": "IMU yaw-rate gyroscope (MotorcyclePlant output yaw_rate)"},
    "roll_rate": {"sign": "> 0 leaning further right",
                  "sensor": "IMU roll-rate gyroscope (MotorcyclePlant output roll_rate)"},
}


@dataclass(frozen=True)
class Var:
    """One variable. ``unit`` is an FMI unit name ("1" for dimensionless); ``min``/``max`` are the
    physical bounds declared in the model description: a parameter outside them is refused at
    initialisation, a step with an input outside them is refused (error, state kept). Every input
    declares both (the tests check it): values no sensor or vehicle can produce, so that no finite
    input can overflow a runtime's arithmetic."""

    name: str
    unit: str
    description: str
    start: float = 0.0
    min: Optional[float] = None
    max: Optional[float] = None
    sign: str = ""       # sign convention (e.g. "> 0 steers left"), "" where a sign means nothing
    sensor: str = ""     # an input's source: the sensor that measures it, or the plant output it comes from

    @property
    def documentation(self) -> str:
        """The description with the sign convention and the sensor: the model description's
        ``description`` and the datasheet's (``latobs.datasheet``) are this one text."""
        return "; ".join([self.description] + ([self.sign] if self.sign else [])
                         + ([f"from: {self.sensor}"] if self.sensor else []))


@dataclass(frozen=True)
class Paper:
    """A publication a model implements (its datasheet cites it)."""

    authors: tuple[str, ...]
    title: str
    venue: str
    year: int
    doi: str = ""

    @property
    def citation(self) -> str:
        doi = f", doi:{self.doi}" if self.doi else ""
        return f"{', '.join(self.authors)}: {self.title}. {self.venue}, {self.year}{doi}"


@dataclass(frozen=True)
class ModelSpec:
    """Interface of one FMU: Real inputs/outputs/parameters, Integer outputs.

    description   what the model is; ``describe(data)``, if given, says which variant the data
                  file makes of it (e.g. speed or tire switching), appended to the description
    bounds        optional ``bounds(data) -> {variable name: (min, max)}`` for bounds that depend
                  on the data file (e.g. the number of modes)
    starts        optional ``starts(data) -> {input name: start value}`` for input start values that
                  depend on the data file (e.g. a speed inside the design's grid), so that the FMU
                  run unconnected from its start values steps with fmi2OK
    stop_time     s, the DefaultExperiment's stop time (a sensible first run)
    paper         the publication the model implements (None: latobs's own model)
    initialization what the outputs are at the start time and where the state starts (datasheet)
    max_step      s, the longest communication step the model keeps its accuracy at (measured:
                  outputs bounded and close to small-step results); a number, or
                  ``max_step(data) -> s``. Both FMI layers refuse a longer step (error, state kept),
                  and the model description declares it (see ``framework.model_description``)
    """

    description: str
    runtime: Callable  # the runtime class, see the module docstring
    inputs: tuple[Var, ...]
    outputs: tuple[Var, ...]
    integer_outputs: tuple[Var, ...] = ()
    parameters: tuple[Var, ...] = field(default_factory=tuple)
    describe: Optional[Callable[[dict], str]] = None
    bounds: Optional[Callable[[dict], dict]] = None
    starts: Optional[Callable[[dict], dict]] = None
    stop_time: float = 10.0
    max_step: "float | Callable[[dict], float]" = 1.0
    paper: Optional[Paper] = None
    initialization: str = ""


#: relative slack on the longest step: a host computing its step as a difference of communication
#: points (t_next - t) exceeds the nominal step by a few ulps
STEP_SLACK = 1e-9


def max_step(spec: ModelSpec, data: dict) -> float:
    """The model's longest communication step (s) for this data file, as declared."""
    m = spec.max_step(data) if callable(spec.max_step) else spec.max_step
    return float(m)


def refused_above(spec: ModelSpec, data: dict) -> float:
    """The step (s) above which both FMI layers refuse a step: ``max_step`` plus ``STEP_SLACK``."""
    return max_step(spec, data) * (1.0 + STEP_SLACK)


def input_starts(spec: ModelSpec, data: dict) -> dict[str, float]:
    """Input start values: the spec's, overridden by the data-dependent ones (``starts``)."""
    u = {v.name: float(v.start) for v in spec.inputs}
    if spec.starts is not None and data:
        u.update({k: float(x) for k, x in spec.starts(data).items() if k in u})
    return u


def design_speed(data: dict) -> dict:
    """``{"vx": speed}`` with a speed (m/s) in the middle of the design's speed grid (the middle of
    its central band: switching edges, or scheduled estimators' bands, or the central mode's model
    speed range), or {} if the data file has none: the start value of the observers' vx input, so
    that an FMU run unconnected runs inside its grid (above vx_hold) without a warning."""
    bands = data.get("switching", {}).get("edges")
    if not bands and data.get("estimators"):
        bands = [e["vx_band"][0] for e in data["estimators"]] + [data["estimators"][-1]["vx_band"][1]]
    if not bands and data.get("modes"):
        bands = data["modes"][(len(data["modes"]) - 1) // 2].get("model_speed", {}).get("range")
    if not bands or len(bands) < 2:
        return {}
    k = (len(bands) - 2) // 2
    return {"vx": 0.5 * (float(bands[k]) + float(bands[k + 1]))}


def var_bounds(spec: ModelSpec, data: dict, variables) -> dict[str, tuple]:
    """{name: (min, max)} of ``variables``: declared, or data-dependent (``bounds``); None = none."""
    extra = spec.bounds(data) if (spec.bounds and data) else {}
    return {v.name: tuple(extra.get(v.name, (v.min, v.max))) for v in variables}


def runtime_parameters(model: str, known, defaults: dict, params: dict | None) -> dict[str, float]:
    """The runtime's parameter values: ``defaults`` overridden by ``params`` (None = default).
    Unknown names and values that are not finite numbers raise a ValueError naming the model and
    the parameter (the framework has already checked each declared [min, max])."""
    params = dict(params or {})
    unknown = sorted(set(params) - set(known))
    if unknown:
        raise ValueError(f"{model}: unknown parameter(s) {', '.join(unknown)}; known: {', '.join(known)}")
    out = {}
    for k, d in defaults.items():
        val = params.get(k)
        val = d if val is None else val
        if isinstance(val, bool) or not isinstance(val, (int, float)) or not math.isfinite(val):
            raise ValueError(f"{model}: parameter {k!r} must be a finite number, got {val!r}")
        out[k] = float(val)
    return out


def tables_of(data: dict, runtime: str) -> dict:
    """``data["tables"]``: what the runtime evaluates, computed when the design (or plant) file was
    built; a ValueError naming ``runtime`` when they are missing."""
    t = data.get("tables") if isinstance(data, dict) else None
    if not isinstance(t, dict) or not t:
        raise ValueError(f"data file lacks the 'tables' of the {runtime} runtime (computed when the design "
                         "or plant file is built)")
    return t
