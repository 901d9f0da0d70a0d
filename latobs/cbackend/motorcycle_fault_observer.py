"""Emitter of the native C model of paper 003's switched PI observer (``fmu_src/c/motorcycle_fault_observer.c``).

Writes the design file's tables (``synthesis/tables/motorcycle_fault_observer.py``) as C data: per
mode OBS_M, OBS_G (s' = M s + G y, s = [x^; f^]), OBS_C, OBS_F and OBS_MAP_H0 (the exact step map
at OBS_H0, the default step); OBS_EDGES and OBS_HYST (the speed bands and the hysteresis, m/s).
"""
from __future__ import annotations

from ..fmu_src.spec import Var
from .emit import CModel, c_array, c_define, nonzero, structure

SOURCE = "motorcycle_fault_observer.c"

#: ModelExchange states: s = [x^ (5); f^ (2)] (eq. 13), the order of the runtime's state vector
STATES = (
    Var("xhat_vy", "m/s", "observer state x^: lateral velocity"),
    Var("xhat_yaw_rate", "rad/s", "observer state x^: yaw rate"),
    Var("xhat_roll_rate", "rad/s", "observer state x^: roll rate"),
    Var("xhat_steer_angle", "rad", "observer state x^: steering angle"),
    Var("xhat_steer_rate", "rad/s", "observer state x^: steering rate"),
    Var("fhat_roll_angle", "rad", "observer state f^: roll angle (unknown input f1)"),
    Var("fhat_rider_torque", "N.m", "observer state f^: rider steering torque (unknown input f2)"),
)
#: z0, z1: the active mode's band widened by the hysteresis (lower, upper edge); z2: |vx| - vx_hold;
#: z3, z4: the design grid's ends (the out-of-grid warning)
N_EVENT_INDICATORS = 5


def emit(data: dict) -> CModel:
    t = data["tables"]
    modes, measurements = t["modes"], t["measurements"]
    n, nf, ny = len(modes[0]["C"][0]), len(modes[0]["M"]) - len(modes[0]["C"][0]), len(modes[0]["C"])
    if (n, nf, ny) != (5, 2, 3) or len(measurements) != ny or len(STATES) != n + nf:
        raise ValueError(f"paper-003 observer: unexpected sizes n = {n}, nf = {nf}, ny = {ny}")
    header = "".join([
        "/* paper 003, eq. (13): s' = M_s s + G_s y, s = [x^; f^], y = [steer angle, yaw rate, roll rate] */\n",
        c_define("OBS_N_MODES", len(modes)),
        c_define("OBS_NX", n), c_define("OBS_NF", nf), c_define("OBS_NY", ny), c_define("OBS_NS", n + nf),
        c_define("OBS_HYST", float(t["hysteresis"])),
        c_define("OBS_H0", float(t["h0"])),
        c_array("OBS_EDGES", [float(e) for e in t["edges"]]),
        *(c_array(f"OBS_{key.upper()}", [m[key] for m in modes]) for key in ("M", "G", "C", "F")),
        c_array("OBS_MAP_H0", [m["map_h0"] for m in modes]),
    ])
    return CModel(header=header, states=STATES, n_event_indicators=N_EVENT_INDICATORS,
                  dependencies=_dependencies(modes, measurements))


#: the outputs that are one state each (outputs_of in motorcycle_fault_observer.c)
STATE_OUTPUTS = {"roll_angle_hat": "fhat_roll_angle", "rider_torque_hat": "fhat_rider_torque",
                 "vy_hat": "xhat_vy", "steer_rate_hat": "xhat_steer_rate"}


def _dependencies(modes: list, measurements: list) -> dict:
    """ModelExchange (model_me_derivatives, outputs_of), in every mode: s' = M s + G y; the force
    estimates F s; the residual norm |y - C x^| (every measurement, the states C reads)."""
    names = [s.name for s in STATES]
    deps = {f"der({name})": nonzero(names, *(m["M"][i] for m in modes))
            | nonzero(measurements, *(m["G"][i] for m in modes)) for i, name in enumerate(names)}
    deps.update({out: {state} for out, state in STATE_OUTPUTS.items()})
    for k, out in enumerate(("Ff_hat", "Fr_hat")):
        deps[out] = nonzero(names, *(m["F"][k] for m in modes))
    n = len(modes[0]["C"][0])
    deps["residual_norm"] = set(measurements) | nonzero(names[:n], *(row for m in modes for row in m["C"]))
    return structure(deps)


def gains(data: dict) -> list:
    """The certified gains as the FMI 3.0 FMU's array constants (``latobs.cbackend.fmi3``): per mode
    the proportional L_P and integral L_I gains of the PI observer (the design file's ``modes[i].gains``)."""
    modes = data["modes"]
    return [("L_P", "proportional gain L_P of each mode (modes x states x measurements, SI)",
             [m["gains"]["L_P"] for m in modes]),
            ("L_I", "integral gain L_I of each mode (modes x unknown inputs x measurements, SI)",
             [m["gains"]["L_I"] for m in modes])]
