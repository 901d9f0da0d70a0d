"""Paper 001's design model: bicycle model with first-order tire relaxation (Ifqir et al., ACC 2020).

Eq. (7) in the coordinates of eq. (8), written as eq. (9) with ERRATA 001's corrections:

    x = [vy, r, x3, x4],  x3 = (Fyf + Fyr)/m = ay (m/s^2),  x4 = (lf Fyf - lr Fyr)/Iz (rad/s^2)
    u = delta (road-wheel angle, rad),  y = [r, ay] = C x,  C = [[0, 1, 0, 0], [0, 0, 1, 0]]

    A(vx) = [[0, -vx, 1, 0],
             [0, 0, 0, 1],
             [-(cf + cr)/(m s), +(cr lr - cf lf)/(m s), -vx/s, 0],
             [(cr lr - cf lf)/(Iz s), -(cf lf^2 + cr lr^2)/(Iz s), 0, -vx/s]]
    B(vx) = [0, 0, cf vx/(m s), cf lf vx/(Iz s)]

with s the relaxation length sigma (m) and cf, cr the AXLE cornering stiffnesses (N/rad).
Departures from the printed paper, per ERRATA 001 and re-derived here:
  * A(3,2) = +(cr lr - cf lf)/(m s): eq. (12) prints it with the opposite sign (eq. (9) has it
    right). From x3' = (vx/s)(-x3 + (cf alpha_f + cr alpha_r)/m) with the slip angles of eq. (4),
    the r coefficient is (vx/s)(cr lr - cf lf)/(m vx).
  * The paper names x2 "psi"; it is the yaw RATE r (its derivative is x4 = r').
  * The paper writes one relaxation length r for both axles; here sigma, one per vehicle.
vx cancels only in the vy and r columns, so A(vx) = A0 + vx A1 with the stiffnesses only in A0,
and B(vx) = vx B1. The uncertainty of eqs. (10)-(13) is the stiffness part: dA(dc) (vx-free) and
dB(vx, dc) = vx dB1(dc), both affine in (dcf, dcr): their elementwise bounds over a box are
attained at its vertices (:func:`stiffness_bounds`).
``tests/test_car_plant_001.py`` holds this model against CarPlant's numerical linearisation.
"""
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
