"""FMU model file: SideslipKalmanFilter (paper 002's baseline peer).

The linear bicycle-model Kalman filter of the MBDS dataset's authors (Leanza, Reina,
Blanco-Claraco, Sensors 2021), measuring ay and the yaw rate. Interface as the CarPlant outputs
and the MBDS record's columns (wiring by name); the maths is in ``sideslip_kalman_filter.py``; the
vehicle, the noise covariances and the speed clamp come from the design file baked into the FMU
(``sideslip_kalman_filter.design``). The runtime has no tunable parameter: the covariances are part of
the certified design.
"""
from ..sideslip_kalman_filter import KalmanObserver
from ..papers import LEANZA_2021
from ..spec import ACCEL, ANGLE, CAR, CAR_BETA, LEFT, RATE, SPEED, ModelSpec, Var


def _diag(M) -> str:
    return ", ".join(f"{float(M[i][i]):.3g}" for i in range(len(M)))


def _variant(data: dict) -> str:
    """The vehicle, the covariances and the certified speed range the design file makes."""
    parts = []
    veh = data.get("vehicle", {})
    if veh.get("name"):
        parts.append(f"vehicle {veh['name']}")
    noise = data.get("noise", {})
    if noise.get("q") and noise.get("r"):
        parts.append(f"Q = diag({_diag(noise['q'])}) on [vy', r'] per s, R = diag({_diag(noise['r'])}) on [ay, r]")
    modes = data.get("modes", [])
    rng = modes[0].get("scheduling", {}).get("range") if modes else None
    if rng:
        parts.append(f"certified (frozen-speed steady state) for vx in [{rng[0]:g}, {rng[1]:g}] m/s")
    return "; ".join(parts) or "linear bicycle model"


SPEC = ModelSpec(
    description="Baseline peer of paper 002: linear bicycle-model Kalman filter of sideslip, lateral velocity and "
                "yaw rate from the lateral acceleration and the yaw rate, the estimator of the MBDS dataset's "
                "authors (Leanza, Reina, Blanco-Claraco, Sensors 2021); outputs the one-step prediction x(k+1|k) and, one "
                "step behind, the filtered estimate x(k|k)",
    describe=_variant,
    runtime=KalmanObserver,
    inputs=(
        Var("delta", "rad", "road-wheel steering angle", **ANGLE, **CAR["delta"]),
        Var("vx", "m/s", "longitudinal speed (the model is evaluated at vx clamped to [vx_min, vx_max])",
            start=20.0, **SPEED, **CAR["vx"]),
        Var("yaw_rate", "rad/s", "measured yaw rate", **RATE, **CAR["yaw_rate"]),
        Var("ay", "m/s2", "measured lateral acceleration at the centre of gravity", **ACCEL, **CAR["ay"]),
    ),
    outputs=(
        Var("beta_hat", "rad", "estimated sideslip angle atan(vy_hat/vx) at the centre of gravity", sign=CAR_BETA),
        Var("vy_hat", "m/s", "estimated lateral velocity at the centre of gravity", sign=LEFT),
        Var("yaw_rate_hat", "rad/s", "estimated yaw rate", sign=CAR["yaw_rate"]["sign"]),
        Var("beta_filtered", "rad", "filtered sideslip estimate atan(vy_filtered/vx) of the previous communication "
            "point (one step behind: x(k|k), updated with that point's measurements)", sign=CAR_BETA),
        Var("vy_filtered", "m/s", "filtered lateral velocity estimate of the previous communication point (one "
            "step behind)", sign=LEFT),
        Var("yaw_rate_filtered", "rad/s", "filtered yaw rate estimate of the previous communication point (one "
            "step behind)", sign=CAR["yaw_rate"]["sign"]),
    ),
    # longest communication step (s), measured against 1 ms runs: a discrete filter over the communication
    # step (its gain depends on the step, its error does not grow with it): bounded at every step to 1 s
    max_step=1.0,
    stop_time=20.0,
    paper=LEANZA_2021,
    initialization="the filter starts from lateral velocity 0 and the initial measured yaw rate, with the "
                   "design's initial covariance P0; the outputs at the start time are these values at the initial "
                   "speed (clamped to the filter's speed range)",
)
