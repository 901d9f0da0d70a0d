"""Emitter of the native C model of paper 003's switched PI observer (``fmu_src/c/motorcycle_observer.c``).

Mirrors ``fmu_src/motorcycle_observer.py``: the design file is checked and preprocessed by that
runtime itself (a design it refuses raises its ValueError here), so the C file gets bit-for-bit the
Python runtime's matrices of eq. (13) in the form s' = M_s s + G_s y, s = [x^; f^]:

    OBS_M[mode]      M_s = [[A - L_P C, E_f], [-L_I C, 0]]   (7 x 7)
    OBS_G[mode]      G_s = [L_P; L_I]                         (7 x 3)
    OBS_C[mode]      C                                        (3 x 5), residual (eq. 14) and x^(0) = C' y(0)
    OBS_F[mode]      [H_x | H_phi | 0]                        (2 x 7), the forces [Ff^, Fr^] = OBS_F s
    OBS_MAP_H0[mode] [Phi | Gam] = the exact zero-order-hold map over the FMU's default step
                     OBS_H0 = 0.005 s (``framework.DEFAULT_STEP``), computed by the runtime's own
                     ``step_map`` (Van Loan, ``linalg.expm``): at the default step the C model
                     steps with exactly the Python FMU's maps
    OBS_EDGES, OBS_HYST  the speed bands (m/s) and the switching hysteresis (m/s)
"""
from __future__ import annotations

from ..fmu_src.framework import DEFAULT_STEP
from ..fmu_src.motorcycle_observer import MEASUREMENTS, MotorcycleFaultObserver, step_map
from ..fmu_src.spec import Var
from .emit import CModel, c_array, c_define, nonzero, structure

SOURCE = "motorcycle_observer.c"

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
    rt = MotorcycleFaultObserver(data)       # the runtime's checks: ValueError naming the culprit
    n, nf, ny = rt.N, rt.NF, rt.NY
    if (n, nf, ny) != (5, 2, 3) or len(MEASUREMENTS) != ny or len(STATES) != n + nf:
        raise ValueError(f"paper-003 observer: unexpected sizes n = {n}, nf = {nf}, ny = {ny}")
    maps = [[list(row) for row in step_map(M, G, DEFAULT_STEP)] for M, G in zip(rt._M, rt._G)]
    header = "".join([
        "/* paper 003, eq. (13): s' = M_s s + G_s y, s = [x^; f^], y = [steer angle, yaw rate, roll rate] */\n",
        c_define("OBS_N_MODES", rt.n_modes),
        c_define("OBS_NX", n), c_define("OBS_NF", nf), c_define("OBS_NY", ny), c_define("OBS_NS", n + nf),
        c_define("OBS_HYST", rt._hyst),
        c_define("OBS_H0", float(DEFAULT_STEP)),
        c_array("OBS_EDGES", rt._edges),
        c_array("OBS_M", rt._M),
        c_array("OBS_G", rt._G),
        c_array("OBS_C", rt._C),
        c_array("OBS_F", rt._F),
        c_array("OBS_MAP_H0", maps),
    ])
    return CModel(header=header, states=STATES, n_event_indicators=N_EVENT_INDICATORS,
                  dependencies=_dependencies(rt))


#: the outputs that are one state each (outputs_of in motorcycle_observer.c)
STATE_OUTPUTS = {"roll_angle_hat": "fhat_roll_angle", "rider_torque_hat": "fhat_rider_torque",
                 "vy_hat": "xhat_vy", "steer_rate_hat": "xhat_steer_rate"}


def _dependencies(rt: MotorcycleFaultObserver) -> dict:
    """ModelExchange (model_me_derivatives, outputs_of), in every mode: s' = M s + G y; the force
    estimates F s; the residual norm |y - C x^| (every measurement, the states C reads)."""
    names = [s.name for s in STATES]
    deps = {f"der({name})": nonzero(names, *(M[i] for M in rt._M)) | nonzero(MEASUREMENTS, *(G[i] for G in rt._G))
            for i, name in enumerate(names)}
    deps.update({out: {state} for out, state in STATE_OUTPUTS.items()})
    for k, out in enumerate(("Ff_hat", "Fr_hat")):
        deps[out] = nonzero(names, *(F[k] for F in rt._F))
    deps["residual_norm"] = set(MEASUREMENTS) | nonzero(names[:rt.N], *(row for C in rt._C for row in C))
    return structure(deps)
