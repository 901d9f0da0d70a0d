"""FMU model file: MotorcyclePlant, the nonlinear truth model of paper 003's motorcycle observer.

Sharp's (1971) two-frame lateral motorcycle model (derived at build time by
``latobs.synthesis.motorcycle_model``; the numbers arrive in the plant data file) with Magic
Formula tyres on slip and camber, relaxation and sin() gravity terms; the maths is in
``motorcycle_plant.py``. Interface: the documentation's interface page (docs/interface.md) (inputs rider_torque, vx; outputs steer_angle,
steer_rate, yaw_rate, roll_angle, roll_rate, vy, Ff, Fr) extended by Gamma_f, Gamma_r (the
nonlinear parts of the tyre forces that paper 003's observer estimates) and alpha_f, alpha_r.
Axes are Sharp's (SAE): x forward, y RIGHT, z down.
"""
from ..motorcycle_plant import MotorcyclePlantModel
from ..papers import SHARP_1971
from ..spec import RIGHT, SPEED, TORQUE, ModelSpec, Var

SPEC = ModelSpec(
    description="Nonlinear Sharp (1971) motorcycle: rear frame with rider, steered front frame, wheel "
                "gyroscopics, Magic Formula tyres on slip and camber with relaxation (latobs truth model "
                "of paper 003; SAE axes: y right, z down)",
    runtime=MotorcyclePlantModel,
    inputs=(
        Var("rider_torque", "N.m", "rider steering torque about the steering axis; clamped to +-200 N m with a "
            "warning", **TORQUE, sign="> 0 turns the handlebar to the right"),
        Var("vx", "m/s", "prescribed forward speed (model meant for >= 5 m/s; < 1 m/s regularised, "
            "clamped to [0, 60] with a warning)", start=15.0, **SPEED, sign="> 0 forward"),
    ),
    outputs=(
        Var("steer_angle", "rad", "steering angle about the steering axis", sign="> 0 steers right"),
        Var("steer_rate", "rad/s", "steering rate", sign="> 0 steering further right"),
        Var("yaw_rate", "rad/s", "yaw rate", sign="> 0 turns right"),
        Var("roll_angle", "rad", "roll (lean) angle", sign="> 0 leans right"),
        Var("roll_rate", "rad/s", "roll rate", sign="> 0 leaning further right"),
        Var("vy", "m/s", "lateral velocity of the ground point below the rear-frame mass centre", sign=RIGHT),
        Var("Ff", "N", "front tyre side force", sign=RIGHT),
        Var("Fr", "N", "rear tyre side force", sign=RIGHT),
        Var("Gamma_f", "N", "nonlinear part of the front static tyre force: Fs_f - (Cf1 alpha_f + Cf2 gamma_f)"),
        Var("Gamma_r", "N", "nonlinear part of the rear static tyre force: Fs_r - (Cr1 alpha_r + Cr2 gamma_r)"),
        Var("alpha_f", "rad", "front slip angle"),
        Var("alpha_r", "rad", "rear slip angle"),
    ),
    parameters=(
        Var("mu", "1", "peak tyre-road friction coefficient (Magic Formula peak mu * static load)", start=1.0,
            min=0.01, max=2.0),
        Var("sigma", "m", "tyre relaxation length, both tyres (default: the vehicle's); 0: algebraic tyres "
            "(paper 003's reduced model); 0 < sigma < 0.01 is refused", start=0.2438, min=0.0, max=5.0),
        Var("linear_tires", "1", "1: linear tyres C1 alpha + C2 gamma (no saturation, Gamma = 0); 0: Magic "
            "Formula", start=0.0, min=0.0, max=1.0),
        Var("mf_C", "1", "Magic Formula shape factor C (0 < C < 2)", start=1.3, min=0.01, max=1.99),
        Var("mf_E", "1", "Magic Formula curvature factor E (<= 1)", start=0.0, min=-5.0, max=1.0),
    ),
    # longest communication step (s), measured against 1 ms runs: <= 1 ms RK4 substeps inside any step:
    # identical to 1 ms runs
    max_step=1.0,
    stop_time=16.0,
    paper=SHARP_1971,
    initialization="the motorcycle starts upright in straight running at the initial speed (every state 0); "
                   "the outputs at the start time use the inputs set during initialisation",
)
