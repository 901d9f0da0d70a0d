"""FMU model file: CarPlant, the nonlinear two-track truth model of every car observer.

Interface: the documentation's interface page (docs/interface.md); the maths is in ``car_plant.py``; the vehicle parameters come from
the plant data file baked into the FMU. The inputs stiffness_scale_f/r extend the contract's
inputs (delta, vx, bank_angle): hosts that do not drive them leave them at their start value 1.0.
"""
from ..car_plant import CarPlantModel
from ..spec import ANGLE, CAR, CAR_BETA, LEFT, SCALE, SPEED, ModelSpec, Var

SPEC = ModelSpec(
    description="Nonlinear two-track lateral/yaw/roll car model with Magic Formula (optionally linear) tires, "
                "load transfer and tire relaxation (latobs truth model)",
    runtime=CarPlantModel,
    inputs=(
        Var("delta", "rad", "road-wheel steering angle", **ANGLE, sign=CAR["delta"]["sign"]),
        Var("vx", "m/s", "prescribed longitudinal speed", start=20.0, **SPEED, sign=CAR["vx"]["sign"]),
        Var("bank_angle", "rad", "road bank angle", **ANGLE, sign="> 0: gravity pulls towards -y (the right)"),
        # optional inputs (added for paper 002's validation; start 1.0 = the plant without them)
        Var("stiffness_scale_f", "1", "multiplies the front cornering stiffness on top of the parameter "
            "scale_f (Magic Formula B; peak force unchanged); sampled and held per communication step; "
            "clamped to [0.1, 10] with a warning (0 included); a value outside [0, 100], or non-finite, "
            "refuses the step (error logged, state held)", start=1.0, **SCALE),
        Var("stiffness_scale_r", "1", "multiplies the rear cornering stiffness on top of the parameter "
            "scale_r (Magic Formula B; peak force unchanged); sampled and held per communication step; "
            "clamped to [0.1, 10] with a warning (0 included); a value outside [0, 100], or non-finite, "
            "refuses the step (error logged, state held)", start=1.0, **SCALE),
    ),
    outputs=(
        Var("beta", "rad", "sideslip angle atan(vy/vx) at the roll axis below the CG", sign=CAR_BETA),
        Var("vy", "m/s", "lateral velocity at the roll axis below the CG", sign=LEFT),
        Var("yaw_rate", "rad/s", "yaw rate", sign=CAR["yaw_rate"]["sign"]),
        Var("ay", "m/s2", "lateral acceleration sensed at the CG (tire forces / m)", sign=LEFT),
        Var("roll_angle", "rad", "roll angle", sign=CAR["roll_angle"]["sign"]),
        Var("roll_rate", "rad/s", "roll rate", sign=CAR["roll_rate"]["sign"]),
        Var("Fyf", "N", "front axle lateral force (body y)", sign=LEFT),
        Var("Fyr", "N", "rear axle lateral force (body y)", sign=LEFT),
        Var("alpha_f", "rad", "front slip angle (mean of the two wheels)", sign="> 0 makes a force to the left"),
        Var("alpha_r", "rad", "rear slip angle (mean of the two wheels)", sign="> 0 makes a force to the left"),
        Var("vy_cg", "m/s", "lateral velocity of the CG: vy - hr roll_rate cos(roll_angle)", sign=LEFT),
        Var("beta_cg", "rad", "sideslip angle at the CG atan(vy_cg/vx)", sign=CAR_BETA),
    ),
    parameters=(
        Var("mu", "1", "peak friction coefficient (dry 1.0, wet 0.8, snow 0.3, ice 0.1)", start=1.0,
            min=0.01, max=2.0),
        Var("scale_f", "1", "front cornering stiffness scale factor", start=1.0, min=0.1, max=10.0),
        Var("scale_r", "1", "rear cornering stiffness scale factor", start=1.0, min=0.1, max=10.0),
        Var("sigma", "m", "tire relaxation length (0: no relaxation, algebraic tires)", start=0.5,
            min=0.0, max=5.0),
        Var("linear_tires", "1", "1: linear tires mu Fz B C alpha (Magic Formula slope at zero slip, "
            "no saturation); 0: Magic Formula", start=0.0, min=0.0, max=1.0),
    ),
    # longest communication step (s), measured against 1 ms runs: <= 1 ms Heun substeps inside any step:
    # identical to 1 ms runs
    max_step=1.0,
    stop_time=10.0,
    initialization="the car starts in straight running at the initial speed: lateral velocity, yaw rate, roll "
                   "angle and rate and the tire forces 0 (the road's bank acts from the first step)",
)
