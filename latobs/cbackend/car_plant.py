"""Emitter of the native CarPlant (``fmu_src/c/car_plant.c``): the vehicle as static const data.

The plant data file's vehicle parameters (SI; the Python runtime has validated them before the
emitter runs), the gravity constant and the runtime's declared limits (its public class constants:
clamps, substep bound) become ``model_data.h``. CarPlant needs no precomputed tables: every derived
constant depends on the FMU parameters (mu, scale_f, scale_r, sigma, linear_tires), so
``car_plant.c`` derives them in ``model_setup`` as ``CarPlantModel.__init__`` does.
ModelExchange adds ``x_vx_lag`` (the lag state through which vx is differentiated) and one event
indicator per warning condition.
"""
from __future__ import annotations

from ..fmu_src.car_plant import G, CarPlantModel
from ..fmu_src.spec import Var
from .emit import CModel, c_define, c_double, structure

SOURCE = "car_plant.c"

#: the vehicle parameters car_plant.c reads (mu and sigma are FMU parameters: their defaults, the
#: vehicle's values, are the parameters' start values), with their units
VEHICLE_FIELDS = {"m": "kg", "Iz": "kg m^2", "Ix": "kg m^2", "lf": "m", "lr": "m", "hr": "m", "Kr": "N m/rad",
                  "br": "N m s/rad", "Cf": "N/rad", "Cr": "N/rad", "track": "m", "h_rc": "m", "roll_share_f": "1",
                  "mf_C": "1", "mf_E": "1"}

#: CarPlantModel's limits (class constants), as CP_<NAME> macros
LIMITS = ("H_MAX", "VX_MAX", "V_SLIP_MIN", "V_RELAX_MIN", "AX_MAX", "DELTA_MAX", "BANK_MAX", "ALPHA_SPIN",
          "SCALE_IN_MIN", "SCALE_IN_MAX")

STATES = (
    Var("x_vy", "m/s", "lateral velocity at the roll axis below the CG (state of output vy)"),
    Var("x_yaw_rate", "rad/s", "yaw rate (state of output yaw_rate)"),
    Var("x_roll_angle", "rad", "roll angle, > 0 leaning right (state of output roll_angle)"),
    Var("x_roll_rate", "rad/s", "roll rate (state of output roll_rate)"),
    Var("x_Fy_fl", "N", "front left tire lateral force, wheel frame (relaxation, E7; constant and unused "
        "with algebraic tires, sigma <= 0)"),
    Var("x_Fy_fr", "N", "front right tire lateral force, wheel frame (relaxation, E7; constant and unused "
        "with algebraic tires, sigma <= 0)"),
    Var("x_Fy_rl", "N", "rear left tire lateral force, wheel frame (relaxation, E7; constant and unused "
        "with algebraic tires, sigma <= 0)"),
    Var("x_Fy_rr", "N", "rear right tire lateral force, wheel frame (relaxation, E7; constant and unused "
        "with algebraic tires, sigma <= 0)"),
    Var("x_vx_lag", "m/s", "vx through a first-order lag of 5 ms: ax = (vx - x_vx_lag) / 5 ms is the "
        "longitudinal acceleration of the load transfer (E5) in model exchange"),
)

#: car_plant.c's event indicators: vx < 0, vx > VX_MAX, vx < V_SLIP_MIN, |delta| > DELTA_MAX,
#: |bank_angle| > BANK_MAX, each stiffness input outside its range, |ax| > AX_MAX, |alpha_r| > ALPHA_SPIN
N_EVENT_INDICATORS = 9


def emit(data: dict) -> CModel:
    """``model_data.h`` of the CarPlant FMU for the plant data file ``data`` (validated by the
    runtime first: ``cbackend.build_c_fmu``)."""
    params = data["vehicle"]["parameters"]
    values = {k: float(params[k]["value"] if isinstance(params[k], dict) else params[k]) for k in VEHICLE_FIELDS}
    name = str(data["vehicle"].get("name", "?"))
    label = repr(name).replace("*/", "* /")   # inside a C comment
    lines = [f"/* CarPlant of vehicle {label}: its parameters (SI) and the runtime's constants, "
             "from fmu_src/car_plant.py */\n",
             c_define("CP_G", float(G)).rstrip("\n") + " /* m/s^2 */\n"]
    lines += [c_define(f"CP_{k}", float(getattr(CarPlantModel, k))) for k in LIMITS]
    lines.append("\ntypedef struct {\n")
    lines += [f"    double {k}; /* {unit} */\n" for k, unit in VEHICLE_FIELDS.items()]
    lines.append("} CarVehicle;\n\n")
    lines.append("static const CarVehicle CP_VEHICLE = {\n")
    lines += [f"    .{k} = {c_double(values[k])},\n" for k in VEHICLE_FIELDS]
    lines.append("};\n")
    return CModel(header="".join(lines), states=STATES, n_event_indicators=N_EVENT_INDICATORS,
                  dependencies=DEPENDENCIES)


_BODY = ("x_vy", "x_yaw_rate", "x_roll_angle", "x_roll_rate")
_FORCES = ("x_Fy_fl", "x_Fy_fr", "x_Fy_rl", "x_Fy_rr")
#: ModelExchange structure of car_plant.c (model_me_derivatives, model_me_outputs), the same for
#: every data file: the body (E1-E3) driven by the four wheel-frame forces projected by delta, the
#: bank and, for vy' (vx r), the speed; each force relaxing (E7, rate vx / sigma) towards the tire
#: model at its slip (delta, vx, vy, r, the roll terms of the wheel velocities) and load (bank,
#: load transfer from the lateral forces and from ax = (vx - x_vx_lag) / 5 ms, E5), scaled by its
#: axle's stiffness input. With algebraic tires (sigma <= 0) the forces are constant: their
#: dependencies then are conservative.
DEPENDENCIES = structure({
    "beta": ("vx", "x_vy"), "vy": ("x_vy",), "yaw_rate": ("x_yaw_rate",), "roll_angle": ("x_roll_angle",),
    "roll_rate": ("x_roll_rate",), "ay": ("delta", *_FORCES), "Fyf": ("delta", "x_Fy_fl", "x_Fy_fr"),
    "Fyr": ("x_Fy_rl", "x_Fy_rr"), "alpha_f": ("delta", "vx", "x_vy", "x_yaw_rate"),
    "alpha_r": ("vx", "x_vy", "x_yaw_rate"), "vy_cg": ("x_vy", "x_roll_angle", "x_roll_rate"),
    "beta_cg": ("vx", "x_vy", "x_roll_angle", "x_roll_rate"),
    "der(x_vy)": ("delta", "vx", "bank_angle", "x_yaw_rate", "x_roll_angle", "x_roll_rate", *_FORCES),
    "der(x_yaw_rate)": ("delta", *_FORCES),
    "der(x_roll_angle)": ("x_roll_rate",),
    "der(x_roll_rate)": ("delta", "bank_angle", "x_roll_angle", "x_roll_rate", *_FORCES),
    **{f"der({f})": ("delta", "vx", "bank_angle", "stiffness_scale_f" if f[-2] == "f" else "stiffness_scale_r",
                     *_BODY, *_FORCES, "x_vx_lag") for f in _FORCES},
    "der(x_vx_lag)": ("vx", "x_vx_lag"),
})
