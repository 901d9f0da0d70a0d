"""Emitter of the native C model of the nonlinear motorcycle plant (``fmu_src/c/motorcycle_plant.c``).

Writes the plant file's derived equations (``data["structure"]``: PL_C0, PL_C1, PL_K_SIN, PL_B_F,
PL_B_TAU; per tyre PL_SLIP, PL_HEADING, PL_CAMBER, PL_TYRE_C1, PL_TYRE_C2, PL_TYRE_FZ), its tables
(``synthesis/tables/motorcycle_plant.py``: PL_MINV, PL_KT) and the runtime's declared numerical
constants (substeps, clamps, floors: its public class constants) as C data.
"""
from __future__ import annotations

from ..fmu_src.motorcycle_plant import MotorcyclePlantModel
from ..fmu_src.spec import Var
from .emit import CModel, c_array, c_define, structure

SOURCE = "motorcycle_plant.c"

#: ModelExchange states: the runtime's STATE_NAMES order
STATES = (
    Var("x_roll_angle", "rad", "state: roll angle"),
    Var("x_steer_angle", "rad", "state: steering angle"),
    Var("x_vy", "m/s", "state: lateral velocity of the rear frame's ground point"),
    Var("x_yaw_rate", "rad/s", "state: yaw rate"),
    Var("x_roll_rate", "rad/s", "state: roll rate"),
    Var("x_steer_rate", "rad/s", "state: steering rate"),
    Var("x_Ff", "N", "state: front tyre side force (relaxation, E4; constant when sigma = 0)"),
    Var("x_Fr", "N", "state: rear tyre side force (relaxation, E4; constant when sigma = 0)"),
)
#: z0 = TAU_MAX - |rider_torque|, z1 = vx, z2 = VX_MAX - vx, z3 = vx - V_WARN, z4 = ROLL_WARN - |roll|
N_EVENT_INDICATORS = 5

#: the runtime's constants carried to C (class attribute -> macro)
CONSTANTS = ("H_MAX", "LAM_DT", "LAM_MECH", "VX_MAX", "V_SLIP_MIN", "V_RELAX_MIN", "V_WARN", "TAU_MAX",
             "SIGMA_MIN", "ROLL_WARN")


def _floats(x):
    return [_floats(v) for v in x] if isinstance(x, list) else float(x)


def emit(data: dict) -> CModel:
    if tuple(MotorcyclePlantModel.STATE_NAMES) != tuple(s.name[2:] for s in STATES):
        raise ValueError(f"MotorcyclePlant: states {MotorcyclePlantModel.STATE_NAMES} are not the C model's")
    st, t = data["structure"], data["tables"]
    tyres = [st["tyres"][key] for key in ("front", "rear")]
    header = "".join([
        "/* Sharp (1971) motorcycle, Magic Formula tyres (paper 003): equations (E1)-(E4) of motorcycle_plant.py */\n",
        *(c_define(f"PL_{name}", float(getattr(MotorcyclePlantModel, name))) for name in CONSTANTS),
        c_array("PL_MINV", _floats(t["Minv"])),
        *(c_array(f"PL_{macro}", _floats(st[key])) for macro, key in
          (("C0", "C0"), ("C1", "C1"), ("K_SIN", "K_sin"), ("B_F", "B_F"), ("B_TAU", "B_tau"))),
        *(c_array(f"PL_{macro}", [_floats(ty[key]) for ty in tyres]) for macro, key in
          (("SLIP", "slip_velocity"), ("HEADING", "heading"), ("CAMBER", "camber"), ("TYRE_C1", "C1"),
           ("TYRE_C2", "C2"), ("TYRE_FZ", "Fz"))),
        c_define("PL_KT", float(t["kt"])),
    ])
    return CModel(header=header, states=STATES, n_event_indicators=N_EVENT_INDICATORS,
                  dependencies=DEPENDENCIES)


_CHASSIS = ("x_roll_angle", "x_steer_angle", "x_yaw_rate", "x_roll_rate", "x_steer_rate", "x_Ff", "x_Fr")
#: ModelExchange structure of motorcycle_plant.c (model_me_derivatives, model_me_outputs), the
#: same for every data file: the kinematic rows; the mass-matrix-solved accelerations (rider
#: torque, speed-scheduled terms, tire forces); each tire force relaxing (E4) towards the Magic
#: Formula at its slip and camber; the slip and camber outputs. With sigma = 0 the force states
#: are constant: their dependencies then are conservative.
DEPENDENCIES = structure({
    **{s[2:]: (s,) for s in ("x_steer_angle", "x_steer_rate", "x_yaw_rate", "x_roll_angle", "x_roll_rate",
                             "x_vy", "x_Ff", "x_Fr")},
    "Gamma_f": ("vx", "x_roll_angle", "x_steer_angle", "x_vy", "x_yaw_rate", "x_steer_rate"),
    "Gamma_r": ("vx", "x_roll_angle", "x_vy", "x_yaw_rate"),
    "alpha_f": ("vx", "x_steer_angle", "x_vy", "x_yaw_rate", "x_steer_rate"),
    "alpha_r": ("vx", "x_vy", "x_yaw_rate"),
    "der(x_roll_angle)": ("x_roll_rate",),
    "der(x_steer_angle)": ("x_steer_rate",),
    **{f"der({s})": ("rider_torque", "vx", *_CHASSIS) for s in ("x_vy", "x_yaw_rate", "x_roll_rate", "x_steer_rate")},
    "der(x_Ff)": ("vx", "x_roll_angle", "x_steer_angle", "x_vy", "x_yaw_rate", "x_steer_rate", "x_Ff"),
    "der(x_Fr)": ("vx", "x_roll_angle", "x_vy", "x_yaw_rate", "x_Fr"),
})
