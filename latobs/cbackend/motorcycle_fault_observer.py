"""Emitter of the native C model of paper 003's switched PI observer (``fmu_src/c/motorcycle_fault_observer.c``).

Writes the design file's tables (``synthesis/tables/motorcycle_fault_observer.py``) as C data: per
mode OBS_M, OBS_G (s' = M s + G y, s = [x^; f^]), OBS_C, OBS_F and OBS_MAP_H0 (the exact step map
at OBS_H0, the default step); OBS_EDGES and OBS_HYST (the speed bands and the hysteresis, m/s).
A measured-speed design (OBS_MEASURED 1) has OBS_M_VX, OBS_M_IVX, OBS_G_VX, ... (the coefficients of
vx and 1/vx) and OBS_VX_RANGE (the model speed's clamp per band) instead of OBS_MAP_H0.
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
#: the measured-speed design: x^ with the roll angle, f^ the torque and its derivatives (PMI)
STATES_MEASURED = STATES[:5] + (
    Var("xhat_roll_angle", "rad", "observer state x^: roll angle"),
    Var("fhat_rider_torque", "N.m", "observer state: rider steering torque"),
    Var("fhat_rider_torque_d1", "N.m/s", "observer state: rate of the rider steering torque (PMI)"),
    Var("fhat_rider_torque_d2", "N.m/s2", "observer state: second derivative of the rider steering torque (PMI)"),
)
#: z0, z1: the active mode's band widened by the hysteresis (lower, upper edge); z2: |vx| - vx_hold;
#: z3, z4: the design grid's ends (the out-of-grid warning)
N_EVENT_INDICATORS = 5


def emit(data: dict) -> CModel:
    t = data["tables"]
    modes, measurements = t["modes"], t["measurements"]
    n, nf, ny = len(modes[0]["C"][0]), len(modes[0]["M"]) - len(modes[0]["C"][0]), len(modes[0]["C"])
    measured = bool(t.get("measured"))
    states = STATES_MEASURED[:n + nf] if measured else STATES
    if (n, ny) != ((6, 3) if measured else (5, 3)) or not 1 <= nf <= (3 if measured else 2) or len(measurements) != ny \
            or len(states) != n + nf:
        raise ValueError(f"paper-003 observer: unexpected sizes n = {n}, nf = {nf}, ny = {ny}")
    if measured:
        maps = [c_array(f"OBS_{key.upper()}{sfx.upper()}", [m[key + sfx] for m in modes])
                for key in ("M", "G", "F") for sfx in ("_vx", "_ivx")]
        maps.append(c_array("OBS_VX_RANGE", [m["vx_range"] for m in modes]))
    else:
        maps = [c_array("OBS_MAP_H0", [m["map_h0"] for m in modes])]
    header = "".join([
        "/* paper 003, eq. (13): s' = M_s s + G_s y, s = [x^; f^], y = [steer angle, yaw rate, roll rate] */\n",
        c_define("OBS_N_MODES", len(modes)), c_define("OBS_MEASURED", int(measured)),
        c_define("OBS_NX", n), c_define("OBS_NF", nf), c_define("OBS_NY", ny), c_define("OBS_NS", n + nf),
        c_define("OBS_HYST", float(t["hysteresis"])),
        c_define("OBS_H0", float(t["h0"])),
        c_array("OBS_EDGES", [float(e) for e in t["edges"]]),
        *(c_array(f"OBS_{key.upper()}", [m[key] for m in modes]) for key in ("M", "G", "C", "F")),
        *maps,
    ])
    return CModel(header=header, states=states, n_event_indicators=N_EVENT_INDICATORS,
                  dependencies=_dependencies(modes, measurements, states, measured))


#: the outputs that are one state each (outputs_of in motorcycle_fault_observer.c)
STATE_OUTPUTS = {"roll_angle_hat": 5, "rider_torque_hat": 6, "vy_hat": 0, "steer_rate_hat": 4}


def _dependencies(modes: list, measurements: list, states=STATES, measured: bool = False) -> dict:
    """ModelExchange (model_me_derivatives, outputs_of), in every mode: s' = M s + G y; the force
    estimates F s; the residual norm |y - C x^| (every measurement, the states C reads). A
    measured-speed design's derivatives and forces also depend on vx."""
    names = [s.name for s in states]
    sfx = ("", "_vx", "_ivx") if measured else ("",)
    speed = {"vx"} if measured else set()
    deps = {f"der({name})": nonzero(names, *(m["M" + x][i] for m in modes for x in sfx))
            | nonzero(measurements, *(m["G" + x][i] for m in modes for x in sfx)) | speed
            for i, name in enumerate(names)}
    deps.update({out: {names[i]} for out, i in STATE_OUTPUTS.items()})
    for k, out in enumerate(("Ff_hat", "Fr_hat")):
        deps[out] = nonzero(names, *(m["F" + x][k] for m in modes for x in sfx)) | speed
    n = len(modes[0]["C"][0])
    deps["residual_norm"] = set(measurements) | nonzero(names[:n], *(row for m in modes for row in m["C"]))
    return structure(deps)


def gains(data: dict) -> list:
    """The certified gains as the FMI 3.0 FMU's array constants (``latobs.cbackend.fmi3``): per mode
    the proportional L_P and integral L_I gains of the PI observer (the design file's ``modes[i].gains``)."""
    modes = data["modes"]
    if data.get("method") == "measured_speed":
        return [("L", "gain L of each band per basis function (1, vx, 1/vx): L(vx) = L_0 + vx L_1 + L_2/vx "
                      "(bands x 3 x states x measurements, SI)", [m["gains"]["L"] for m in modes])]
    return [("L_P", "proportional gain L_P of each mode (modes x states x measurements, SI)",
             [m["gains"]["L_P"] for m in modes]),
            ("L_I", "integral gain L_I of each mode (modes x unknown inputs x measurements, SI)",
             [m["gains"]["L_I"] for m in modes])]
