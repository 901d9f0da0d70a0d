"""Paper 001's design model, eq. (9): the bicycle model with first-order tire relaxation, and the
bounds of its stiffness uncertainty over a box (:func:`stiffness_bounds`); the sign of A(3,2)
printed in eq. (12) is corrected where it is computed. The documentation's paper-001 page gives
the model."""
from __future__ import annotations

import itertools

import numpy as np

from .params import Vehicle

STATES = ("vy", "yaw_rate", "ay", "yaw_accel")
STATE_UNITS = ("m/s", "rad/s", "m/s2", "rad/s2")
OUTPUTS = ("yaw_rate", "ay")
C = np.array([[0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]])
PARAMETERS = ("m", "Iz", "lf", "lr", "sigma", "Cf", "Cr")


def coefficients(m: float, Iz: float, lf: float, lr: float, sigma: float, cf: float, cr: float):
    """(A0, A1, B1) of A(vx) = A0 + vx A1, B(vx) = vx B1 for stiffnesses cf, cr (N/rad, per axle)."""
    ms, Is = m * sigma, Iz * sigma
    A0 = np.array([[0.0, 0.0, 1.0, 0.0],
                   [0.0, 0.0, 0.0, 1.0],
                   [-(cf + cr) / ms, (cr * lr - cf * lf) / ms, 0.0, 0.0],
                   [(cr * lr - cf * lf) / Is, -(cf * lf**2 + cr * lr**2) / Is, 0.0, 0.0]])
    A1 = np.array([[0.0, -1.0, 0.0, 0.0],
                   [0.0, 0.0, 0.0, 0.0],
                   [0.0, 0.0, -1.0 / sigma, 0.0],
                   [0.0, 0.0, 0.0, -1.0 / sigma]])
    B1 = np.array([0.0, 0.0, cf / ms, cf * lf / Is])
    return A0, A1, B1


def vehicle_values(vehicle: Vehicle, needed_by: str) -> dict[str, float]:
    """The parameters of the model, or an error naming every missing one."""
    return vehicle.require(PARAMETERS, needed_by)


def stiffness_bounds(v: dict, cf_box: tuple[float, float], cr_box: tuple[float, float]):
    """Elementwise bounds of dA = A0(cf, cr) - A0(Cf, Cr) and dB1 = B1(cf) - B1(Cf) over the box
    (eq. 13): (dA_lower, dA_upper, dB1_lower, dB1_upper). Exact: affine in (cf, cr)."""
    A0n, _, B1n = coefficients(v["m"], v["Iz"], v["lf"], v["lr"], v["sigma"], v["Cf"], v["Cr"])
    dAs, dBs = [], []
    for cf, cr in itertools.product(cf_box, cr_box):
        A0, _, B1 = coefficients(v["m"], v["Iz"], v["lf"], v["lr"], v["sigma"], cf, cr)
        dAs.append(A0 - A0n)
        dBs.append(B1 - B1n)
    return np.min(dAs, axis=0), np.max(dAs, axis=0), np.min(dBs, axis=0), np.max(dBs, axis=0)


def forces_from_state(x3: float, x4: float, v: dict) -> tuple[float, float]:
    """(Fyf, Fyr) in N from x3 = (Fyf + Fyr)/m and x4 = (lf Fyf - lr Fyr)/Iz (inverse of eq. 8)."""
    L = v["lf"] + v["lr"]
    return (v["m"] * v["lr"] * x3 + v["Iz"] * x4) / L, (v["m"] * v["lf"] * x3 - v["Iz"] * x4) / L
