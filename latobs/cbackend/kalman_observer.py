"""Emitter of the native C model of paper 002's baseline, the linear bicycle-model Kalman filter
of the MBDS dataset's authors (``fmu_src/c/kalman_observer.c``).

Mirrors ``fmu_src/kalman_observer.py``: the data file is checked by that runtime itself (a file
it refuses raises its ValueError here), and the C file gets bit-for-bit the runtime's
coefficients of the model at the speed v (A = [[a00/v, a01/v - v], [a10/v, a11/v]],
B = [b0, b1], ay row C = [a00/v, a01/v], D = [b0, 0]):

    KF_A      (a00, a01, a10, a11) = (-(Cf + Cr)/m, -(lf Cf - lr Cr)/m, -(lf Cf - lr Cr)/Iz,
              -(lf^2 Cf + lr^2 Cr)/Iz)
    KF_B      (b0, b1) = (Cf/m, lf Cf/Iz)
    KF_Q      process-noise intensity on [vy', r'] (per s), KF_R measurement covariance on
              [ay, r], KF_P0 the initial covariance
    KF_VX_MIN, KF_VX_MAX  the speed clamp (m/s)

No step map is precomputed: the model depends on the measured speed at every step, so the C
model discretises it per step as the runtime does (a 3x3 expm). The filter is discrete-time
(the FMU is co-simulation only: see the C file's header).
"""
from __future__ import annotations

from ..fmu_src.kalman_observer import KalmanObserver
from .emit import CModel, c_array, c_define

SOURCE = "kalman_observer.c"


def emit(data: dict) -> CModel:
    rt = KalmanObserver(data)               # the runtime's checks: ValueError naming the culprit
    header = "".join([
        "/* paper 002's baseline: linear bicycle-model Kalman filter, x = [vy, r], y = [ay, r] */\n",
        c_array("KF_A", list(rt._a)),
        c_array("KF_B", list(rt._b)),
        c_array("KF_Q", rt.Q),
        c_array("KF_R", rt.R),
        c_array("KF_P0", rt.P0),
        c_define("KF_VX_MIN", rt.vx_min),
        c_define("KF_VX_MAX", rt.vx_max),
    ])
    return CModel(header=header)
