"""FMU model file: SideslipFixedOrderEstimator (paper 002).

Interface: the documentation's interface page (docs/interface.md) (input yaw_rate, output beta_hat); the maths is in ``sideslip_fixed_order_estimator.py``;
the estimator's coefficients come from the design file baked into the FMU.
"""
from ..papers import DELIBASI_2014
from ..spec import CAR, CAR_BETA, RATE, ModelSpec, Var
from ..sideslip_fixed_order_estimator import TfEstimator


def describe_estimator(data: dict) -> str:
    """Order, parameter box and certified worst cases the design file makes (model description)."""
    modes = data.get("modes", [])
    if not modes:
        return "transfer-function estimator"
    m = modes[0]
    box = m.get("box", {})
    parts = [f"order {data.get('order', len(m['estimator']['den']) - 1)}"]
    if box:
        v = [lo for lo, _ in (mm["box"]["v"] for mm in modes)] + [modes[-1]["box"]["v"][1]]
        parts.append(f"box Cf in [{box['Cf'][0]:.4g}, {box['Cf'][1]:.4g}], Cr in [{box['Cr'][0]:.4g}, "
                     f"{box['Cr'][1]:.4g}] N/rad per axle, v in [{v[0]:.4g}, {v[-1]:.4g}] m/s")
    if len(modes) > 1:
        parts.append(f"{len(modes)} speed bands")
    if "gamma" in data:
        parts.append(f"certified worst-case weighted H-inf error: {data['gamma']:.4g} over the coefficient "
                     f"polytope vertices, {data.get('gamma_grid', float('nan')):.4g} over a grid of true plants")
    return "; ".join(parts)


#: the estimators' start (sideslip_fixed_order_estimator.TfEstimator.initialize)
INITIALIZATION = ("the estimator starts in steady state for the initial yaw rate (as if that yaw rate had been "
                  "held for ever), so beta_hat at the start time is its DC gain times the initial yaw rate")


SPEC = ModelSpec(
    description="Fixed-order robust H-inf sideslip estimator beta^ = (y(s)/x(s)) r from the yaw rate alone "
                "(Delibasi, fixed-order robust H-inf sideslip estimation, 2014)",
    describe=describe_estimator,
    runtime=TfEstimator,
    inputs=(
        Var("yaw_rate", "rad/s", "measured yaw rate", **RATE, **CAR["yaw_rate"]),
    ),
    outputs=(
        Var("beta_hat", "rad", "estimated sideslip angle at the CG", sign=CAR_BETA),
    ),
    # longest communication step (s), measured against 1 ms runs: exact step maps: identical to 1 ms runs
    # to 1e-14
    max_step=1.0,
    stop_time=20.0,
    paper=DELIBASI_2014,
    initialization=INITIALIZATION,
)
