"""FMU model file: SideslipFixedOrderEstimatorScheduled (paper 002, speed-scheduled extension).

One paper-002 estimator per speed band, switched on vx (the state is kept across a switch). The
maths is in ``sideslip_fixed_order_estimator.py``; the estimators come from the design file baked into the FMU.
"""
from ..papers import DELIBASI_2014
from ..spec import CAR, CAR_BETA, RATE, SPEED, ModelSpec, Var, design_speed
from ..sideslip_fixed_order_estimator import TfEstimator
from .sideslip_fixed_order_estimator import INITIALIZATION, describe_estimator

SPEC = ModelSpec(
    description="Speed-scheduled fixed-order robust H-inf sideslip estimator: one Delibasi (2014) estimator "
                "beta^ = (y(s)/x(s)) r per speed band, switched on the speed",
    describe=describe_estimator,
    runtime=TfEstimator,
    inputs=(
        Var("yaw_rate", "rad/s", "measured yaw rate", **RATE, **CAR["yaw_rate"]),
        Var("vx", "m/s", "longitudinal speed (selects the band; outside the grid the nearest band, with a "
                         "warning)", **SPEED, **CAR["vx"]),
    ),
    outputs=(
        Var("beta_hat", "rad", "estimated sideslip angle at the CG", sign=CAR_BETA),
    ),
    integer_outputs=(
        Var("mode", "1", "active speed band, 1-based", start=1, min=1),
    ),
    bounds=lambda data: {"mode": (1, len(data.get("estimators", [1])))},
    starts=design_speed,   # vx starts inside the design grid: an unconnected run steps with fmi2OK
    # longest communication step (s), measured against 1 ms runs: exact step maps: identical to 1 ms runs
    # to 1e-14
    max_step=1.0,
    stop_time=20.0,
    paper=DELIBASI_2014,
    initialization=INITIALIZATION + ", in the band of the initial speed",
)
