"""Paper 000's linear design model, eq. (1)-(2): the bicycle model with roll, re-derived from first
principles (three entries differ from the printed eq. (1), commented where they are computed),
and its coefficients as polynomials in 1/Vx for the runtime (``lpv_coefficients``); and the same
model with its axle forces relaxed as in paper 001's eq. (9) (``relaxed_lpv_coefficients``: two
more states, a term in Vx). The documentation's paper-000 page gives the model."""
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


RELAXED_STATES = STATES + ("front_axle_force", "rear_axle_force")
RELAXED_STATE_UNITS = STATE_UNITS + ("m*g", "m*g")
RELAXED_REQUIRED = REQUIRED + ("sigma",)
RELAXED_C = np.hstack([C, np.zeros((3, 2))])


def relaxed_lpv_coefficients(vehicle: Vehicle, Cf: float | None = None, Cr: float | None = None) -> dict:
    """Paper 000's model (1) with its axle forces Ff, Fr (body y, per unit of the vehicle's weight m g:
    numbers near the angles', so that gains and Lyapunov matrices are not scaled by 1e4 N) as states
    relaxed as in paper 001's eq. (9): sigma / Vx F' + F = C alpha, alpha_f = delta - beta - lf r / Vx, alpha_r = -beta +
    lr r / Vx (the slip angles of eq. 1), sigma the vehicle's relaxation length (m). States
    ``RELAXED_STATES``, measurements ``RELAXED_C`` (those of eq. 1). Not in the paper: its model has
    algebraic tire forces, which lag the slip angles by ~sigma / Vx on a car (CarPlant's too).

    Built from ``lpv_coefficients``, which is linear in Cf and Cr: delta reaches eq. (1) only through
    the front force, so B = Cf g_f with g_f the model's response to 1 N of front force; the rear
    force's response g_r is minus the beta column of dA/dCr (alpha_r = -beta + ...), here
    (A(2 Cr) - A(Cr)) / Cr. The forces taken out of A (A - Cf g_f alpha_f - Cr g_r alpha_r) return
    as the states' columns g_f, g_r; what cancels exactly there (beta's column) is set to 0.

    Returns {"first_power": -1, "A": [...], "B": [...], "F": [...]}: M(Vx) = sum_k M[k] Vx**-(k - 1)
    (a term in Vx: the relaxation rate Vx / sigma). ``evaluate`` takes it.
    """
    p = vehicle.require(RELAXED_REQUIRED, "the paper-000 model with relaxed axle forces")
    sigma, lf, lr = p["sigma"], p["lf"], p["lr"]
    if not (sigma > 0 and np.isfinite(sigma)):
        raise ValueError(f"the relaxed model needs a relaxation length sigma > 0 m, got sigma={sigma}")
    base = lpv_coefficients(vehicle, Cf, Cr)
    Cf = p["Cf"] if Cf is None else float(Cf)
    Cr = p["Cr"] if Cr is None else float(Cr)
    twice_r = lpv_coefficients(vehicle, Cf, 2.0 * Cr)          # (a difference as large as its terms)
    gf = [b[:, 0] / Cf for b in base["B"]]                                      # powers 0, 1 of 1/Vx
    gr = [-(a1[:, 0] - a0[:, 0]) / Cr for a0, a1 in zip(base["A"], twice_r["A"])][:2]   # powers 0, 1
    af = [np.array([-1.0, 0.0, 0.0, 0.0]), np.array([0.0, -lf, 0.0, 0.0])]      # alpha_f's x row, powers 0, 1
    ar = [np.array([-1.0, 0.0, 0.0, 0.0]), np.array([0.0, lr, 0.0, 0.0])]
    body = [M.copy() for M in base["A"]]                                         # A without the tire forces
    size = [np.abs(M) for M in base["A"]]
    for i in range(2):
        for j in range(2):
            tires = Cf * np.outer(gf[i], af[j]) + Cr * np.outer(gr[i], ar[j])
            body[i + j] -= tires
            size[i + j] += np.abs(tires)
    for M, mag in zip(body, size):    # what cancels exactly (beta's column: only the tires see beta) is 0
        M[np.abs(M) <= 1e-12 * mag] = 0.0
    # the 1/Vx^2 term of eq. (1) is the forces' (g ~ 1/Vx times alpha ~ r/Vx): nothing of it is left
    assert np.max(np.abs(body[2])) <= 1e-9 * max(np.max(np.abs(base["A"][2])), 1e-300), body[2]
    A = [np.zeros((6, 6)) for _ in range(3)]                                     # powers -1, 0, 1
    for k in (0, 1):
        A[k + 1][:4, :4] = body[k]
        A[k + 1][:4, 4], A[k + 1][:4, 5] = gf[k], gr[k]
    # F' = (Vx / sigma)(C alpha - F): Vx alpha_f = Vx (delta - beta) - lf r, so powers -1 and 0
    for row, c, a in ((4, Cf, af), (5, Cr, ar)):
        A[0][row, :4] = c / sigma * a[0]
        A[1][row, :4] = c / sigma * a[1]
        A[0][row, row] = -1.0 / sigma
    B = [np.zeros((6, 1))]
    B[0][4, 0] = Cf / sigma
    F = [np.zeros((6, 1))] + [np.vstack([M, np.zeros((2, 1))]) for M in base["F"]]
    # forces in N -> per m g: x_new = D x
    D = np.diag([1.0, 1.0, 1.0, 1.0, 1.0 / (p["m"] * G), 1.0 / (p["m"] * G)])
    Di = np.diag(1.0 / np.diag(D))
    return {"first_power": -1, "A": [D @ M @ Di for M in A], "B": [D @ M for M in B], "F": [D @ M for M in F]}


def evaluate(coeffs: dict, vx: float) -> LinearModel:
    """The model at speed ``vx`` (m/s) from its 1/Vx coefficients: M(Vx) = sum_k M[k] Vx**-(k + p)
    with p = coeffs["first_power"] (0 when absent)."""
    if not vx > 0:
        raise ValueError(f"the design model needs a speed > 0 m/s, got vx={vx}")
    inv, p = 1.0 / vx, int(coeffs.get("first_power", 0))
    A = sum(M * inv**(k + p) for k, M in enumerate(coeffs["A"]))
    B = sum(M * inv**(k + p) for k, M in enumerate(coeffs["B"]))
    F = sum(M * inv**(k + p) for k, M in enumerate(coeffs["F"]))
    out_C = RELAXED_C if A.shape[0] == RELAXED_C.shape[1] else C
    return LinearModel(A=A, B=B, F=F, C=out_C.copy(), vx=float(vx))


def model(vehicle: Vehicle, vx: float, Cf: float | None = None, Cr: float | None = None) -> LinearModel:
    """Paper 000's model (1) at speed ``vx`` (m/s)."""
    return evaluate(lpv_coefficients(vehicle, Cf, Cr), vx)
