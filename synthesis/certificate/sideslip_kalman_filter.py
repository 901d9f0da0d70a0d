"""Certificate of the sideslip Kalman filter (paper 002's baseline peer, the MBDS authors' linear
bicycle-model filter): the covariances, the stored model against a force-balance derivation, and on
a grid of speeds the discretised model's observability and the steady-state filter's stability.
What is checked and why: ``docs/certificates.md``.
"""
from __future__ import annotations

import math

import numpy as np

from ..params import parse_vehicle
from .checks import Check, _ge, _le, _rel_err

KALMAN_STEP = 0.01      # s, certificate step when the file names none: the MBDS record's 100 Hz
KALMAN_SPEEDS = 50      # speeds of the certificate's grid when the file names no number


def _kalman_force_model(p: dict, v: float):
    """(A, B, C, D) of the single-track model at the speed v (m/s), states [vy, r], input delta,
    outputs [ay, r], derived from the force balance alone (not from any filter code): slip angles
    af = delta - (vy + lf r)/v, ar = -(vy - lr r)/v, axle forces Fy = C alpha, m (vy' + v r) =
    Fyf + Fyr, Iz r' = lf Fyf - lr Fyr, ay = (Fyf + Fyr)/m. The map is linear, so each column is
    the response to a unit state or input."""
    def respond(vy, r, delta):
        fyf = p["Cf"] * (delta - (vy + p["lf"] * r) / v)
        fyr = p["Cr"] * (-(vy - p["lr"] * r) / v)
        ay = (fyf + fyr) / p["m"]
        return np.array([ay - v * r, (p["lf"] * fyf - p["lr"] * fyr) / p["Iz"]]), np.array([ay, r])
    cols = [respond(*e) for e in ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))]
    A = np.column_stack([cols[0][0], cols[1][0]])
    C = np.column_stack([cols[0][1], cols[1][1]])
    return A, cols[2][0], C, cols[2][1]


def certify(d: dict) -> list[Check]:
    """The checks of a Kalman filter design file (``docs/certificates.md``); frozen speed, on a grid."""
    import scipy.linalg
    import scipy.signal

    checks: list[Check] = []
    name = d.get("name")
    vehicle = parse_vehicle(d["vehicle"], f"design file {name}")
    p = vehicle.require(("m", "lf", "lr", "Iz", "Cf", "Cr"), f"the certificate of {name}")
    Q, R, P0 = (np.asarray(x, float) for x in (d["noise"]["q"], d["noise"]["r"], d["initial"]["P0"]))
    checks.append(_le("Q, R, P0 are 2x2 and symmetric: max |M - M'|",
                      max(float(np.max(np.abs(M - M.T))) if M.shape == (2, 2) else math.inf for M in (Q, R, P0)), 0.0))
    if any(M.shape != (2, 2) for M in (Q, R, P0)):
        return checks
    checks.append(_ge("Q positive semidefinite: min eig(Q) (process noise on [vy', r'])",
                      float(np.min(np.linalg.eigvalsh(Q))), 0.0))
    checks.append(_ge("R positive definite: min eig(R) (measurement noise on [ay, r])",
                      float(np.min(np.linalg.eigvalsh(R))), 1e-12))
    checks.append(_ge("P0 positive definite: min eig(P0)", float(np.min(np.linalg.eigvalsh(P0))), 1e-12))
    cert = d.get("certificate", {}) or {}
    h = float(cert.get("step_s", KALMAN_STEP))
    n = int(cert.get("n_speeds", KALMAN_SPEEDS))
    rt = d.get("runtime", {}) or {}
    vx_min, vx_max = float(rt.get("vx_min", 1.0)), float(rt.get("vx_max", 200.0))
    mod = d.get("model", {})
    for mode in d["modes"]:
        lo, hi = (float(x) for x in mode["scheduling"]["range"])
        where = f"mode {mode['index']}, vx in [{lo:g}, {hi:g}] m/s"
        checks.append(_le(f"certified speeds inside the runtime's clamp [vx_min, vx_max] = [{vx_min:g}, {vx_max:g}] "
                          f"m/s: max(vx_min - min, max - vx_max), {where}", max(vx_min - lo, hi - vx_max), 0.0))
        speeds = np.linspace(lo, hi, max(n, 1)) if hi > lo else np.array([lo])
        err_stored = 0.0
        obs, rho_max, res_max = math.inf, 0.0, 0.0
        for v in speeds:
            A, B, C, D = _kalman_force_model(p, float(v))
            if mod:
                As = np.asarray(mod["A_inv_v"], float) / v + np.asarray(mod["A_v"], float) * v
                Cs = np.asarray(mod["C_inv_v"], float) / v + np.asarray(mod["C_0"], float)
                err_stored = max(err_stored, _rel_err(As, A), _rel_err(mod["B"], B), _rel_err(Cs, C),
                                 _rel_err(mod["D"], D))
            Phi, Gam, *_ = scipy.signal.cont2discrete((A, B[:, None], C, D[:, None]), h, method="zoh")
            sv = np.linalg.svd(np.vstack([C, C @ Phi]), compute_uv=False)
            obs = min(obs, float(sv[-1] / sv[0]))
            try:
                P = scipy.linalg.solve_discrete_are(Phi.T, C.T, Q * h, R)
                S = C @ P @ C.T + R
                K = P @ C.T @ np.linalg.inv(S)
                res = Phi @ (P - K @ C @ P) @ Phi.T + Q * h - P         # the Riccati recursion's fixed point
                res_max = max(res_max, float(np.max(np.abs(res)) / max(1e-300, float(np.max(np.abs(P))))))
                rho = float(np.max(np.abs(np.linalg.eigvals(Phi @ (np.eye(2) - K @ C)))))
            except (np.linalg.LinAlgError, ValueError):
                rho, res_max = math.inf, math.inf
            rho_max = max(rho_max, rho if math.isfinite(rho) else math.inf)
        grid = f"{len(speeds)} speeds in [{lo:g}, {hi:g}] m/s"
        if mod:
            checks.append(_le(f"stored model coefficients equal the force-balance model (max rel. error), {grid}",
                              err_stored, 1e-12))
        checks.append(_ge(f"discretised model observable from [ay, r]: min sigma_min/sigma_max of [C; C Phi] "
                          f"at h = {h:g} s, {grid}", obs, 1e-9))
        checks.append(_le(f"discrete algebraic Riccati equation (Q h, R) solved: max relative residual at "
                          f"h = {h:g} s, {grid}", res_max, 1e-8))
        checks.append(Check(f"steady-state Kalman error dynamics Phi (I - K C) Schur stable: max spectral radius "
                            f"at h = {h:g} s, {grid}", float(rho_max), 1.0, bool(rho_max < 1.0), "<"))
        checks.append(_le(f"max spectral radius <= the stored gamma, {grid}", rho_max,
                          float(d["gamma"]) * (1 + 1e-9)))
    return checks


def summary(data: dict) -> dict:
    """Headline figures of a certified design (for notes and reports): no modes to tabulate."""
    return {"gamma": data.get("gamma"), "per_mode": []}
