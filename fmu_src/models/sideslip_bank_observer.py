"""FMU model file of the paper-000 observers (SideslipBankObserver, SideslipBankObserverTire and variants).

Interface: the documentation's interface page (docs/interface.md); the maths is in ``sideslip_bank_observer.py``; the gains come from the design
file baked into the FMU.
"""
from ..sideslip_bank_observer import SwitchedPIObserver
from ..papers import MENHOUR_2014
from ..spec import ANGLE, CAR, CAR_BETA, RATE, SPEED, ModelSpec, Var, design_speed


def _grid_speed(mode: dict):
    """A speed mode's design speed (m/s): its fixed model speed, else its scheduling value."""
    ms = mode.get("model_speed", {})
    if ms.get("kind") == "fixed":
        return ms.get("value")
    speeds = mode.get("design_speeds") or [None]
    return mode.get("scheduling", {}).get("value", speeds[0])


def _variant(data: dict) -> str:
    """Which paper-000 variant the design file makes (the two FMUs share this model file)."""
    sw = data.get("switching", {})
    modes = data.get("modes", [])
    measured = [m["model_speed"].get("range") for m in modes if m.get("model_speed", {}).get("kind") == "measured"]
    if sw.get("kind") == "speed_bands":
        speeds = "/".join(f"{3.6 * v:.0f}" if isinstance(v, (int, float)) else "?" for v in map(_grid_speed, modes))
        text = f"speed modes: one gain pair per design speed {speeds} km/h, switched on vx (eq. 25)"
        if measured:
            text += "; each mode's model at the measured speed clamped to its band (LPV)"
        if data.get("structure", {}).get("first_power") == -1:
            text += "; the axle forces relaxed as the tires' (two more states)"
    else:
        star = sw.get("alpha_star")
        at = f" at alpha* = {star * 57.29577951308232:.2g} deg" if isinstance(star, (int, float)) else ""
        text = ("tire modes: linear (C1) and reduced (C2) cornering stiffness, switched on the estimated slip "
                f"angles{at} (eq. 27)")
        if measured and measured[0]:
            lo, hi = measured[0]
            text += f"; model at the measured speed clamped to {3.6 * lo:.4g}-{3.6 * hi:.4g} km/h"
    if data.get("runtime", {}).get("input_hold") == "first_order":
        text += "; first-order hold of the measurements over a step"
    if data.get("validity"):
        frozen = " (bank estimate frozen while 0)" if data["validity"].get("freeze_integral") else ""
        text += f"; valid flag{frozen}"
    return text


SPEC = ModelSpec(
    description="Switched H-infinity PI observer of sideslip and road bank angle "
                "(Menhour, Koenig, d'Andrea-Novel, ECC 2014)",
    describe=_variant,
    runtime=SwitchedPIObserver,
    inputs=(
        Var("delta", "rad", "road-wheel steering angle", **ANGLE, **CAR["delta"]),
        Var("vx", "m/s", "longitudinal speed", **SPEED, **CAR["vx"]),
        Var("yaw_rate", "rad/s", "measured yaw rate", **RATE, **CAR["yaw_rate"]),
        Var("roll_angle", "rad", "measured roll angle", **ANGLE, **CAR["roll_angle"]),
        Var("roll_rate", "rad/s", "measured roll rate", **RATE, **CAR["roll_rate"]),
    ),
    outputs=(
        Var("beta_hat", "rad", "estimated sideslip angle at the roll axis below the CG (the design model's beta; "
                               "the CG's differs by hr*roll_rate/vx), at the end of the step", sign=CAR_BETA),
        Var("yaw_rate_hat", "rad/s", "estimated yaw rate, at the end of the step (z + N y with the input hold's y "
                                     "there: the measurement, or its first-order extrapolation)", sign=CAR["yaw_rate"]["sign"]),
        Var("roll_angle_hat", "rad", "estimated roll angle, at the end of the step (as yaw_rate_hat)",
            sign=CAR["roll_angle"]["sign"]),
        Var("roll_rate_hat", "rad/s", "estimated roll rate, at the end of the step (as yaw_rate_hat)",
            sign=CAR["roll_rate"]["sign"]),
        Var("bank_angle_hat", "rad", "estimated road bank angle (unknown input; the integral action, held while "
                                     "valid = 0 if the design freezes it)", sign="> 0 when gravity pulls towards the right (as CarPlant's "
                                     "bank_angle)"),
    ),
    integer_outputs=(
        Var("mode", "1", "active switched mode, 1-based", start=1, min=1),
        Var("valid", "1", "1 while the estimated slip angles and |vx*yaw_rate| are within the design's validity "
                          "limits, 0 once either exceeds them until both fall below the release fraction "
                          "(hysteresis); always 1 if the design has no validity limits; held while frozen "
                          "below vx_hold", start=1, min=0, max=1),
    ),
    bounds=lambda data: {"mode": (1, len(data["modes"])), "valid": (0, 1)},
    parameters=(
        Var("vx_hold", "m/s", "below this forward speed (standstill and reversing included) the observer is "
                              "frozen and every estimate held",
            start=1.0, min=0.01, max=10.0),
    ),
    starts=design_speed,   # vx starts inside the design grid: an unconnected run steps with fmi2OK
    # longest communication step (s), measured against 1 ms runs on consistent steering staircases
    # (outputs within 10 % of their peak): 0.1 s for the tire-switched design (2.1 % at 0.1 s; the
    # first-order input hold extrapolates over longer steps); 0.025 s for the speed-switched robust-H2
    # gains (its roll_rate_hat, near 0 on the staircase, moves by its whole peak at 0.1 s and by 23 % at
    # 0.05 s: the extrapolated input steps excite its slow, lightly damped roll poles); the paper-faithful
    # tire-switched design chatters between its tire modes: 8.5 % at 5 ms, 17 % at 10 ms
    max_step=lambda data: (0.005 if (data.get("options", {}).get("faithful")
                                     and data.get("switching", {}).get("kind") == "tire_slip")
                           else 0.025 if "robust_h2" in data else 0.1),
    stop_time=30.0,
    paper=MENHOUR_2014,
    initialization="the state starts from the first measurement (estimated sideslip 0, the measured yaw rate, "
                   "roll angle and roll rate; bank estimate 0) in the mode of the initial speed (tire modes: "
                   "mode 1); the outputs at the start time are these values",
)
