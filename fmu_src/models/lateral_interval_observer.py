"""FMU model file: LateralIntervalObserver (paper 001).

Interface: the documentation's interface page (docs/interface.md); the maths is in ``lateral_interval_observer.py``; the gains, the stiffness
box and the speed modes come from the design file baked into the FMU.
"""
from ..lateral_interval_observer import IntervalObserver
from ..papers import IFQIR_2020
from ..spec import ACCEL, ANGLE, CAR, CAR_BETA, LEFT, RATE, SPEED, ModelSpec, Var, design_speed


def _variant(data: dict) -> str:
    """The stiffness box and the speed modes the design file makes."""
    parts = []
    box = data.get("stiffness_box", {})
    cf, cr = box.get("Cf"), box.get("Cr")
    if cf and cr:
        parts.append(f"cornering stiffness box Cf in [{cf[0]:.4g}, {cf[1]:.4g}], Cr in [{cr[0]:.4g}, {cr[1]:.4g}] "
                     "N/rad (per axle)")
    modes = data.get("modes", [])
    edges = data.get("switching", {}).get("edges", [])
    if modes and len(edges) == len(modes) + 1:
        bands = ", ".join(f"{m['vx']:g} m/s on [{lo:g}, {hi:g})" for m, lo, hi in zip(modes, edges, edges[1:]))
        parts.append(f"{len(modes)} speed modes (eq. 44): {bands}")
    return "; ".join(parts) or "speed modes"


def max_communication_step(data: dict) -> float:
    """The longest communication step (s) of this design: a longer one is refused with an error,
    the state kept (``IntervalObserver.max_communication_step``: the bounds would not contract)."""
    stored = data.get("runtime", {}).get("max_communication_step")
    return float(stored) if stored is not None else IntervalObserver(data).max_communication_step()


SPEC = ModelSpec(
    description="Switched interval observer: guaranteed bounds of lateral velocity, sideslip, yaw rate and "
                "axle lateral forces for cornering stiffnesses in a box "
                "(Ifqir, Ichalal, Ait-Oufroukh, Mammar, ACC 2020)",
    describe=_variant,
    runtime=IntervalObserver,
    inputs=(
        Var("delta", "rad", "road-wheel steering angle", **ANGLE, **CAR["delta"]),
        Var("vx", "m/s", "longitudinal speed", **SPEED, **CAR["vx"]),
        Var("yaw_rate", "rad/s", "measured yaw rate", **RATE, **CAR["yaw_rate"]),
        Var("ay", "m/s2", "measured lateral acceleration", **ACCEL, **CAR["ay"]),
    ),
    outputs=(
        Var("vy_lower", "m/s", "lower bound of the lateral velocity at the CG", sign=LEFT),
        Var("vy_upper", "m/s", "upper bound of the lateral velocity at the CG", sign=LEFT),
        Var("beta_lower", "rad", "lower bound of the sideslip angle atan(vy/vx) at the CG", sign=CAR_BETA),
        Var("beta_upper", "rad", "upper bound of the sideslip angle atan(vy/vx) at the CG", sign=CAR_BETA),
        Var("yaw_rate_lower", "rad/s", "lower bound of the yaw rate", sign=CAR["yaw_rate"]["sign"]),
        Var("yaw_rate_upper", "rad/s", "upper bound of the yaw rate", sign=CAR["yaw_rate"]["sign"]),
        Var("Fyf_lower", "N", "lower bound of the front axle lateral force", sign=LEFT),
        Var("Fyf_upper", "N", "upper bound of the front axle lateral force", sign=LEFT),
        Var("Fyr_lower", "N", "lower bound of the rear axle lateral force", sign=LEFT),
        Var("Fyr_upper", "N", "upper bound of the rear axle lateral force", sign=LEFT),
    ),
    integer_outputs=(
        Var("mode", "1", "active switched mode (speed band), 1-based", start=1, min=1),
        Var("consistent", "1", "1 = the measurement lay inside the bounds, 0 = it did not: the bounds were "
                               "reset to the measurement for the measured components (and widened to the "
                               "initial box for the others)", start=1, min=0, max=1),
    ),
    bounds=lambda data: {"mode": (1, len(data["modes"])), "consistent": (0, 1)},
    parameters=(
        Var("vx_hold", "m/s", "below this speed the observer is frozen and its bounds held",
            start=1.0, min=0.01, max=10.0),
        # not in the paper (its measurements are exact): the bounds of the sensors' errors, start
        # values from the design file (runtime.y_error_bound; `latobs identify` estimates them)
        Var("yaw_rate_error_bound", "rad/s", "bound of |measured - true| yaw rate (sensor noise and bias): "
            "the measurement is known to within +-this", start=0.0, min=0.0, max=1.0),
        Var("ay_error_bound", "m/s2", "bound of |measured - true| lateral acceleration (sensor noise, "
            "vibration and bias): the measurement is known to within +-this", start=0.0, min=0.0, max=50.0),
    ),
    starts=design_speed,   # vx starts inside the design grid: an unconnected run steps with fmi2OK
    # longest communication step (s): the longest at which the design's bounds contract (stored in
    # the design file; see IntervalObserver.max_communication_step)
    max_step=max_communication_step,
    stop_time=20.0,
    paper=IFQIR_2020,
    initialization="the bounds start around the first measurement (the measured yaw rate and ay, the design's "
                   "initial box for the lateral velocity and the yaw acceleration) in the mode of the initial "
                   "speed, consistent = 1",
)
