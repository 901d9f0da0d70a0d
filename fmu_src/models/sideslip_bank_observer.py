"""FMU model file: SideslipBankObserver and SideslipBankObserverTire (paper 000).

Interface per CONTRACT.md; the maths is in ``pi_observer.py``; the gains come from the design
file baked into the FMU.
"""
from ..pi_observer import SwitchedPIObserver
from ..spec import ModelSpec, Var

SPEC = ModelSpec(
    description="Switched H-infinity PI observer of sideslip and road bank angle "
                "(Menhour, Koenig, d'Andrea-Novel, ECC 2014)",
    runtime=SwitchedPIObserver,
    inputs=(
        Var("delta", "rad", "road-wheel steering angle, > 0 steers left"),
        Var("vx", "m/s", "longitudinal speed"),
        Var("yaw_rate", "rad/s", "measured yaw rate"),
        Var("roll_angle", "rad", "measured roll angle"),
        Var("roll_rate", "rad/s", "measured roll rate"),
    ),
    outputs=(
        Var("beta_hat", "rad", "estimated sideslip angle at the CG"),
        Var("yaw_rate_hat", "rad/s", "estimated yaw rate"),
        Var("roll_angle_hat", "rad", "estimated roll angle"),
        Var("roll_rate_hat", "rad/s", "estimated roll rate"),
        Var("bank_angle_hat", "rad", "estimated road bank angle (unknown input)"),
    ),
    integer_outputs=(Var("mode", "1", "active switched mode, 1-based", start=1),),
    parameters=(
        Var("vx_hold", "m/s", "below this speed the observer is frozen and its estimates held", start=1.0),
    ),
)
