"""Emitter of the native C model of the Kalman peer of paper 002, the linear bicycle-model Kalman
filter of the MBDS dataset's authors (``fmu_src/c/sideslip_kalman_filter.c``).

Writes the design file's tables (``synthesis/tables/sideslip_kalman_filter.py``) as C data: KF_A,
KF_B (the model's speed-free coefficients), KF_Q, KF_R, KF_P0, KF_VX_MIN, KF_VX_MAX. No step map:
the model changes with the measured speed, so the C model discretises it per step (a 3x3 expm).
"""
from __future__ import annotations

from .emit import CModel, c_array, c_define

SOURCE = "sideslip_kalman_filter.c"


def emit(data: dict) -> CModel:
    t = data["tables"]
    header = "".join([
        "/* paper 002's baseline: linear bicycle-model Kalman filter, x = [vy, r], y = [ay, r] */\n",
        c_array("KF_A", [float(x) for x in t["a"]]),
        c_array("KF_B", [float(x) for x in t["b"]]),
        c_array("KF_Q", t["Q"]),
        c_array("KF_R", t["R"]),
        c_array("KF_P0", t["P0"]),
        c_define("KF_VX_MIN", float(t["vx_min"])),
        c_define("KF_VX_MAX", float(t["vx_max"])),
    ])
    return CModel(header=header)


def gains(data: dict) -> list:
    """The filter's tuning as the FMI 3.0 FMU's array constants (``latobs.cbackend.fmi3``): Q, R, P0
    (the Kalman gain itself changes with the speed at every step)."""
    t = data["tables"]
    return [("Q", "process noise covariance Q (x = [vy, r], SI)", t["Q"]),
            ("R", "measurement noise covariance R (y = [ay, r], SI)", t["R"]),
            ("P0", "initial error covariance P0 (x = [vy, r], SI)", t["P0"])]
