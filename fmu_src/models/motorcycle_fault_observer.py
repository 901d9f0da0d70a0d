"""FMU model file: MotorcycleFaultObserver (paper 003).

Interface: the documentation's interface page (docs/interface.md); the maths is in ``motorcycle_fault_observer.py``; the gains come from the
design file baked into the FMU. Signs are those of the design model (``synthesis/motorcycle_model.py``,
Sharp's SAE axes: y to the right, z down): roll, steer, yaw rate, vy, forces and torque > 0 to the right.
"""
from ..motorcycle_fault_observer import MotorcycleFaultObserver
from ..papers import ICHALAL_2017
from ..spec import ANGLE, MOTORCYCLE, RATE, RIGHT, SPEED, ModelSpec, Var, design_speed


def _variant(data: dict) -> str:
    if data.get("method") == "measured_speed":
        bands = ", ".join(f"{m['band'][0]:g}-{m['band'][1]:g}" for m in data.get("modes", []))
        nt = len(data.get("structure", {}).get("faults", []))
        return (f"measured speed: model and gain L(vx) = L0 + vx L1 + L2/vx evaluated at the measured speed "
                f"(bands {bands} m/s, one Lyapunov matrix), roll angle a state, {nt} torque integrator(s)")
    speeds = "/".join(f"{m['vx']:g}" for m in data.get("modes", []))
    return (f"speed modes: one PI gain pair per grid speed {speeds} m/s, switched on vx "
            f"(nearest grid speed, hysteresis {data.get('switching', {}).get('hysteresis', 0):g} m/s)")


SPEC = ModelSpec(
    description="H-infinity observer of a motorcycle's roll angle and rider steering torque (paper 003, "
                "eq. (13): switched PI, or latobs's measured-speed PMI extension) on the reduced Sharp 1971 "
                "lateral model",
    describe=_variant,
    runtime=MotorcycleFaultObserver,
    inputs=(
        Var("vx", "m/s", "longitudinal speed (schedules the mode)", **SPEED, **MOTORCYCLE["vx"]),
        Var("steer_angle", "rad", "measured steering (handlebar) angle", **ANGLE, **MOTORCYCLE["steer_angle"]),
        Var("yaw_rate", "rad/s", "measured yaw rate", **RATE, **MOTORCYCLE["yaw_rate"]),
        Var("roll_rate", "rad/s", "measured roll rate", **RATE, **MOTORCYCLE["roll_rate"]),
    ),
    outputs=(
        Var("roll_angle_hat", "rad", "estimated roll angle (paper design: unknown input f1; measured-speed design: a state)", sign="> 0 leaning right"),
        Var("rider_torque_hat", "N.m", "estimated rider steering torque (an unknown input)",
            sign="> 0 turning the handlebar right"),
        Var("vy_hat", "m/s", "estimated lateral velocity", sign=RIGHT),
        Var("steer_rate_hat", "rad/s", "estimated steering rate", sign="> 0 steering further right"),
        Var("Ff_hat", "N", "estimated front tyre lateral force, linear part H_x x^ + H_phi phi^ (no Gamma)",
            sign=RIGHT),
        Var("Fr_hat", "N", "estimated rear tyre lateral force, linear part H_x x^ + H_phi phi^ (no Gamma)",
            sign=RIGHT),
        Var("residual_norm", "1", "|y - C x^| (eq. 14), Euclidean norm of [rad, rad/s, rad/s] numbers in SI "
                                  "(mixed units)"),
    ),
    integer_outputs=(Var("mode", "1", "active switched mode, 1-based", start=1, min=1),),
    bounds=lambda data: {"mode": (1, len(data["modes"]))},
    parameters=(
        Var("vx_hold", "m/s", "below this |vx| the observer is frozen and its estimates held",
            start=1.0, min=0.01, max=10.0),
    ),
    starts=design_speed,   # vx starts inside the design grid: an unconnected run steps with fmi2OK
    # longest communication step (s), measured against 1 ms runs: exact step maps (matrix exponential):
    # identical to 1 ms runs to 1e-11 (measured-speed design: the speed held over the step)
    max_step=1.0,
    stop_time=16.0,
    paper=ICHALAL_2017,
    initialization="the measured states start at their first measurement (steering angle, yaw rate, roll rate), "
                   "the others and both unknown inputs (roll angle, rider torque) at 0, in the mode of the "
                   "initial speed",
)
