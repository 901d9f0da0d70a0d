"""FMU model file: SideslipBankObserver and SideslipBankObserverTire (paper 000).

Interface per CONTRACT.md; the maths is in ``pi_observer.py``; the gains come from the design
file baked into the FMU.
"""
from ..pi_observer import SwitchedPIObserver
from ..spec import ModelSpec, Var


def _variant(data: dict) -> str:
    """Which paper-000 variant the design file makes (the two FMUs share this model file)."""
    sw = data.get("switching", {})
    if sw.get("kind") == "speed_bands":
        speeds = "/".join(f"{3.6 * m['model_speed']['value']:.0f}" for m in data["modes"])
        return f"speed modes: one gain pair per design speed {speeds} km/h, switched on vx (eq. 25)"
    star = sw.get("alpha_star")
    at = f" at alpha* = {star * 57.29577951308232:.2g} deg" if isinstance(star, (int, float)) else ""
    return f"tire modes: linear (C1) and reduced (C2) cornering stiffness, switched on the estimated slip angles{at} (eq. 27)"


SPEC = ModelSpec(
    description="Switched H-infinity PI observer of sideslip and road bank angle "
                "(Menhour, Koenig, d'Andrea-Novel, ECC 2014)",
    describe=_variant,
    runtime=SwitchedPIObserver,
    inputs=(
        Var("delta", "rad", "road-wheel steering angle, > 0 steers left"),
        Var("vx", "m/s", "longitudinal speed"),
        Var("yaw_rate", "rad/s", "measured yaw rate"),
        Var("roll_angle", "rad", "measured roll angle"),
        Var("roll_rate", "rad/s", "measured roll rate"),
    ),
    outputs=(
        Var("beta_hat", "rad", "estimated sideslip angle at the roll axis below the CG (the design model's beta; "
                               "the CG's differs by hr*roll_rate/vx)"),
        Var("yaw_rate_hat", "rad/s", "estimated yaw rate"),
        Var("roll_angle_hat", "rad", "estimated roll angle"),
        Var("roll_rate_hat", "rad/s", "estimated roll rate"),
        Var("bank_angle_hat", "rad", "estimated road bank angle (unknown input)"),
    ),
    integer_outputs=(Var("mode", "1", "active switched mode, 1-based", start=1, min=1),),
    bounds=lambda data: {"mode": (1, len(data["modes"]))},
    parameters=(
        Var("vx_hold", "m/s", "below this forward speed (standstill and reversing included) the observer is "
                              "frozen and every estimate held",
            start=1.0, min=0.01, max=10.0),
    ),
    stop_time=30.0,
)
