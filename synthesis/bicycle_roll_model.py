"""Paper 000's linear design model, eq. (1)-(2): the bicycle model with roll, re-derived from first
principles (three entries differ from the printed eq. (1), commented where they are computed),
and its coefficients as polynomials in 1/Vx for the runtime (``lpv_coefficients``). The
documentation's paper-000 page gives the model."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .params import G, Vehicle

STATES = ("beta", "yaw_rate", "roll_angle", "roll_rate")
STATE_UNITS = ("rad", "rad/s", "rad", "rad/s")
INPUTS = ("delta",)
UNKNOWN_INPUTS = ("bank_angle",)
OUTPUTS = ("yaw_rate", "roll_angle", "roll_rate")
REQUIRED = ("m", "Iz", "Ix", "lf", "lr", "hr", "Kr", "br", "Cf", "Cr")

C = np.array([[0.0, 1.0, 0.0, 0.0],
              [0.0, 0.0, 1.0, 0.0],
              [0.0, 0.0, 0.0, 1.0]])


@dataclass(frozen=True)
class LinearModel:
    """x' = A x + B u + F w, y = C x at one speed."""

    A: np.ndarray
    B: np.ndarray
    F: np.ndarray
    C: np.ndarray
    vx: float


def lpv_coefficients(vehicle: Vehicle, Cf: float | None = None, Cr: float | None = None) -> dict[str, list[np.ndarray]]:
    """Coefficient matrices M_k with M(Vx) = sum_k M_k Vx**-k, for M in A (k<=2), B, F (k<=1).

    ``Cf``/``Cr`` (N/rad, per axle) override the vehicle's stiffnesses (tire modes).
    """
    p = vehicle.require(REQUIRED, "the paper-000 design model (bicycle + roll)")
    m, Iz, Ix, lf, lr, hr, Kr, br = (p[k] for k in ("m", "Iz", "Ix", "lf", "lr", "hr", "Kr", "br"))
    Cf = p["Cf"] if Cf is None else float(Cf)
    Cr = p["Cr"] if Cr is None else float(Cr)
    if not (Cf > 0 and Cr > 0):
        raise ValueError(f"cornering stiffnesses must be > 0 N/rad, got Cf={Cf}, Cr={Cr}")
    Ieq = Ix + m * hr**2                       # paper: I_eq = I_x + m h_r^2
    Ca0 = Cf + Cr                              # C_alpha,0
    Ca1 = lf * Cf - lr * Cr                    # C_alpha,1
    Ca2 = lf**2 * Cf + lr**2 * Cr              # C_alpha,2
    Ca3 = hr * (m * G * hr - Kr)               # C_alpha,3

    A0 = np.array([[0.0, -1.0, 0.0, 0.0],
                   [-Ca1 / Iz, 0.0, 0.0, 0.0],
                   [0.0, 0.0, 0.0, 1.0],
                   [-Ca0 * hr / Ix, 0.0, (m * G * hr - Kr) / Ix, -br / Ix]])
    A1 = np.array([[-Ieq * Ca0 / (Ix * m), 0.0, Ca3 / Ix, -hr * br / Ix],   # A(1,4): misprint corrected, printed hr*Lr
                   [0.0, -Ca2 / Iz, 0.0, 0.0],                              # A(2,2): misprint corrected, printed Ix
                   [0.0, 0.0, 0.0, 0.0],
                   [0.0, -Ca1 * hr / Ix, 0.0, 0.0]])
    A2 = np.zeros((4, 4))
    A2[0, 1] = -Ieq * Ca1 / (Ix * m)
    B0 = np.array([[0.0], [lf * Cf / Iz], [0.0], [hr * Cf / Ix]])         # B(4): re-derived, printed Cf/Ix
    B1 = np.array([[Ieq * Cf / (Ix * m)], [0.0], [0.0], [0.0]])
    F0 = np.zeros((4, 1))
    F1 = np.array([[-G], [0.0], [0.0], [0.0]])                            # F = [-g/Vx, 0, 0, 0]^T
    return {"A": [A0, A1, A2], "B": [B0, B1], "F": [F0, F1]}


MODEL_ERRORS = ("lateral_force", "yaw_moment", "roll_moment")
MODEL_ERROR_UNITS = ("m*g", "m*g*L", "m*g*hr")


def model_error_coefficients(vehicle: Vehicle) -> list[np.ndarray]:
    """E_k (4x3) with E(Vx) = E_0 + E_1 / Vx: how model errors enter eq. (1), x' = ... + E d.

    d = [dFy / (m g), dMz / (m g L), dMx / (m g hr)] (dimensionless): a lateral-force residual
    (N) at the CG, a yaw-moment residual (N m) and a roll-moment residual (N m) about the roll
    axis, each divided by its natural scale (weight, weight x wheelbase, weight x roll lever),
    so that d = 0.01 is "1 % of the vehicle's weight" whatever the car. They enter exactly like
    the model's own forces (the columns of eq. (1) that the tire forces and the roll moment
    Kr phi + br phi' use): a lateral force F acts on beta' as I_eq F / (I_x m V_x) and on the
    roll acceleration as h_r F / I_x; a roll moment M_x on beta' as h_r M_x / (I_x V_x) and on
    the roll acceleration as M_x / I_x; a yaw moment on r' as M_z / I_z. The tire-model errors
    of the nonlinear vehicle (saturation, load transfer, stiffness error) are such residuals.
    """
    p = vehicle.require(REQUIRED, "the paper-000 model-error input matrix")
    m, Iz, Ix, lf, lr, hr = (p[k] for k in ("m", "Iz", "Ix", "lf", "lr", "hr"))
    Ieq = Ix + m * hr**2
    scale = np.diag([m * G, m * G * (lf + lr), m * G * hr])
    E0 = np.array([[0.0, 0.0, 0.0], [0.0, 1.0 / Iz, 0.0], [0.0, 0.0, 0.0], [hr / Ix, 0.0, 1.0 / Ix]]) @ scale
    E1 = np.array([[Ieq / (Ix * m), 0.0, hr / Ix], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]]) @ scale
    return [E0, E1]


def evaluate(coeffs: dict[str, list[np.ndarray]], vx: float) -> LinearModel:
    """The model at speed ``vx`` (m/s) from its 1/Vx coefficients."""
    if not vx > 0:
        raise ValueError(f"the design model needs a speed > 0 m/s, got vx={vx}")
    inv = 1.0 / vx
    A = sum(M * inv**k for k, M in enumerate(coeffs["A"]))
    B = sum(M * inv**k for k, M in enumerate(coeffs["B"]))
    F = sum(M * inv**k for k, M in enumerate(coeffs["F"]))
    return LinearModel(A=A, B=B, F=F, C=C.copy(), vx=float(vx))


def model(vehicle: Vehicle, vx: float, Cf: float | None = None, Cr: float | None = None) -> LinearModel:
    """Paper 000's model (1) at speed ``vx`` (m/s)."""
    return evaluate(lpv_coefficients(vehicle, Cf, Cr), vx)
