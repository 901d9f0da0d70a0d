"""Independent certificate of a design file: numpy/scipy only, never the LMI solver.

A certificate re-evaluates the numbers that will be packaged (the design file's model
coefficients and gains), not the solver's internal state:
  * the stored model equals the model re-derived from the stored vehicle parameters;
  * per mode and design speed: closed-loop eigenvalues inside the pole region, the H-infinity
    norm from bank angle to sideslip error by Hamiltonian bisection (``hinf.py``, no P) <= gamma,
    cross-checked by a dense frequency sweep; the slowest pole seen by the bank estimate;
  * the common Lyapunov matrix P of the file decreases along every mode (switching proof);
  * largest gain, cond(P), and the runtime's RK4 step (stable, accurate on every closed loop).
A design whose certificate fails is never packaged (``latobs.packaging`` re-runs it).

Paper 001 (``_certify_001``, interval observer): the stored model against its re-derivation; the
structure of eq. (23)/(30)/(33) (P = I - E C, N = P A - K C, J = K + N E, H = P B); every N_i
Metzler, Hurwitz and with N_i + eta I >= 0 (36); LMI (35) re-evaluated on the stored Q and gamma;
the width dynamics N_i + 2|P_i dA| Hurwitz over the stiffness box (the small-gain check Theorem 1
omits, ERRATA 001) and, for the runtime (measured states intersected with the measurement, speed
mismatch inside a band bounded exactly), the same on the unmeasured states with the band's speed
mismatch; the ISS gain sqrt(gamma/(alpha eps)) of eq. (37); the largest gain.
"""
from __future__ import annotations

import itertools
import math
from dataclasses import asdict, dataclass

import numpy as np

from . import bicycle_roll_model as brm
from . import hinf
from . import relaxation_model as rm
from .params import parse_vehicle
from .pi_hinf_000 import closed_loop

REL_TOL = 1e-6


@dataclass(frozen=True)
class Check:
    name: str
    value: float
    limit: float
    passed: bool
    sense: str = "<="          # value <= limit, or ">=" for a lower bound
    detail: str = ""


def _le(name, value, limit, detail=""):
    return Check(name, float(value), float(limit), bool(value <= limit), "<=", detail)


def _ge(name, value, limit, detail=""):
    return Check(name, float(value), float(limit), bool(value >= limit), ">=", detail)


def _rk4_factor(z: np.ndarray) -> np.ndarray:
    return 1 + z + z**2 / 2 + z**3 / 6 + z**4 / 24


def certify(data: dict) -> tuple[bool, list[Check]]:
    """Certify a design dict. Returns (certified, checks)."""
    paper = data.get("paper")
    if paper == "000":
        checks = _certify_000(data)
    elif paper == "001":
        checks = _certify_001(data)
    elif paper == "002" and data.get("kind") == "kalman_baseline":
        checks = _certify_kalman(data)
    elif paper == "002":
        checks = _certify_002(data)
    elif paper == "003": checks = _certify_003(data)
    else:
        raise ValueError(f"design {data.get('name')!r}: no certificate for paper {paper!r}")
    return all(c.passed for c in checks) and bool(checks), checks


def _certify_000(d: dict) -> list[Check]:
    checks: list[Check] = []
    T, N, C = (np.asarray(d["structure"][k]) for k in ("T", "N", "C"))
    P = np.asarray(d["P"])
    gamma = float(d["gamma"])
    a, R = d["region"]["alpha"], d["region"]["radius"]
    opts = d["options"]
    checks.append(_le("T + N C = I (eq. 6)", np.max(np.abs(T + N @ C - np.eye(T.shape[0]))), 1e-12))

    vehicle = parse_vehicle(d["vehicle"], f"design file {d['name']}")
    model_err = 0.0
    for mode in d["modes"]:
        kf, kr = (float(k) for k in mode["stiffness_scale"])
        ref = brm.lpv_coefficients(vehicle, kf * vehicle.Cf, kr * vehicle.Cr)
        for key, mats in ref.items():
            for k, M in enumerate(mats):
                stored = np.asarray(mode["model"][key][k])
                model_err = max(model_err, float(np.max(np.abs(stored - M)) / max(1.0, np.max(np.abs(M)))))
    checks.append(_le("model equals the model re-derived from the vehicle parameters", model_err, 1e-12))

    max_step = float(d["runtime"]["max_step"])
    worst = {"hinf": 0.0, "sweep_gap": 0.0, "alpha": -math.inf, "radius": 0.0, "lyap": -math.inf,
             "bank": -math.inf, "rk4_amp": 0.0, "rk4_err": 0.0}
    for mode in d["modes"]:
        K_P, K_I = np.asarray(mode["gains"]["K_P"]), np.asarray(mode["gains"]["K_I"])
        for v in mode["design_speeds"]:
            where = f"mode {mode['index']} at {v * 3.6:.1f} km/h"
            Acl, Fa, La = closed_loop(mode["model"], K_P, K_I, T, C, v)
            reg = hinf.pole_region(Acl, a, R)
            checks.append(_le(f"max Re(eig) < -alpha, {where}", reg["max_real_part"], -a))
            checks.append(_le(f"max |eig| < radius, {where}", reg["max_modulus"], R))
            if reg["max_real_part"] < 0:
                hn = hinf.hinf_norm(Acl, Fa, La).norm
                sweep, _ = hinf.frequency_sweep_peak(Acl, Fa, La)
                gap = abs(hn - sweep) / max(hn, 1e-300)
            else:  # unstable: the norm is infinite, both checks fail
                hn = gap = math.inf
            checks.append(_le(f"H-inf bank->beta error (Hamiltonian) <= gamma, {where}", hn, gamma * (1 + REL_TOL)))
            checks.append(_le(f"Hamiltonian and frequency sweep agree, {where}", gap, 1e-3))
            lyap = float(np.max(np.linalg.eigvalsh(Acl.T @ P + P @ Acl)))
            checks.append(_le(f"common P decreases (max eig of Acl'P + P Acl), {where}", lyap, 0.0))
            n = Acl.shape[0]
            e_w = np.zeros((1, n)); e_w[0, -1] = 1.0
            pole, _w = hinf.slowest_pole_seen_by(Acl, Fa, e_w)
            checks.append(_le(f"slowest pole of the bank estimate, {where}", pole.real, -a))
            lam = np.linalg.eigvals(Acl) * max_step
            amp = float(np.max(np.abs(_rk4_factor(lam))))
            err = float(np.max(np.abs(_rk4_factor(lam) - np.exp(lam))))
            checks.append(_le(f"runtime RK4 step {max_step * 1e3:.3g} ms stable (max |R(h lambda)|), {where}", amp, 1.0 - 1e-9))
            checks.append(_le(f"runtime RK4 one-step error |R(h lambda) - exp(h lambda)|, {where}", err, 1e-6))
    if opts.get("switching") == "tire":
        # the runtime evaluates the tire modes' models at the measured speed: check between grid speeds
        lo, hi = d["modes"][0]["model_speed"]["range"]
        worst_re = -math.inf
        for mode in d["modes"]:
            K_P, K_I = np.asarray(mode["gains"]["K_P"]), np.asarray(mode["gains"]["K_I"])
            for v in np.linspace(lo, hi, 61):
                Acl, _, _ = closed_loop(mode["model"], K_P, K_I, T, C, float(v))
                worst_re = max(worst_re, float(np.max(np.linalg.eigvals(Acl).real)))
        checks.append(_le("max Re(eig) on a 61-point speed grid between the design speeds (frozen speed)", worst_re, 0.0))
    gains = max(max(np.max(np.abs(m["gains"]["K_P"])), np.max(np.abs(m["gains"]["K_I"]))) for m in d["modes"])
    checks.append(_le("largest gain entry", gains, opts.get("gain_limit", 1e4)))
    checks.append(_le("cond(P)", np.linalg.cond(P), opts.get("cond_limit", 1e7)))
    checks.append(_le("P symmetric: max |P - P'|", float(np.max(np.abs(P - P.T))), 0.0))
    checks.append(_ge("P positive definite: min eig(P)", float(np.min(np.linalg.eigvalsh(P))), 1e-12))
    return checks


def _rel_err(a, b) -> float:
    a, b = np.asarray(a, float), np.asarray(b, float)
    return float(np.max(np.abs(a - b)) / max(1.0, float(np.max(np.abs(b)))))


def _certify_001(d: dict) -> list[Check]:
    checks: list[Check] = []
    mod, box = d["model"], d["stiffness_box"]
    vehicle = parse_vehicle(d["vehicle"], f"design file {d['name']}")
    v = rm.vehicle_values(vehicle, f"certificate of {d['name']}")
    A0, A1, B1 = rm.coefficients(*(v[k] for k in ("m", "Iz", "lf", "lr", "sigma", "Cf", "Cr")))
    rel = d["options"]["box"]
    cf_box = (v["Cf"] * (1 - rel[0]), v["Cf"] * (1 + rel[0]))
    cr_box = (v["Cr"] * (1 - rel[1]), v["Cr"] * (1 + rel[1]))
    bounds = rm.stiffness_bounds(v, cf_box, cr_box)
    err = max(_rel_err(mod["A0"], A0), _rel_err(mod["A1"], A1), _rel_err(mod["B1"], B1),
              _rel_err(box["Cf"], cf_box), _rel_err(box["Cr"], cr_box),
              *(_rel_err(mod[k], b) for k, b in zip(("dA_lower", "dA_upper", "dB1_lower", "dB1_upper"), bounds)))
    checks.append(_le("model and stiffness box equal their re-derivation from the vehicle parameters", err, 1e-12))
    C = np.asarray(mod["C"], float)
    checks.append(_le("C measures [r, ay] (eq. 9)", _rel_err(C, rm.C), 0.0))
    Q = np.asarray(d["Q"], float)
    gamma, eps, eta, alpha = float(d["gamma"]), float(d["epsilon"]), float(d["eta"]), float(d["alpha"])
    checks.append(_ge("Q diagonal >= alpha I (34)", float(np.min(Q)), alpha))
    # every vertex of the stiffness box, for |P dA| (dA affine in the stiffnesses: extremal at vertices)
    dAs = []
    for cf in cf_box:
        for cr in cr_box:
            dAs.append(rm.coefficients(*(v[k] for k in ("m", "Iz", "lf", "lr", "sigma")), cf, cr)[0] - A0)
    edges = d["switching"]["edges"]
    unmeasured = [i for i in range(4) if not np.any(C[:, i])]
    n = 4
    for mode in d["modes"]:
        i = mode["index"]
        where = f"mode {i} ({mode['vx']:g} m/s)"
        A, B = (np.asarray(mode[k], float) for k in ("A", "B"))
        N, E, J, H, P, K = (np.asarray(mode[k], float) for k in ("N", "E", "J", "H", "P", "K"))
        vx = float(mode["vx"])
        lo, hi = edges[i - 1], edges[i]
        checks.append(_le(f"model speed inside its band, {where}", max(lo - vx, vx - hi), 0.0))
        checks.append(_le(f"A_i, B_i = the model at the mode's speed, {where}",
                          max(_rel_err(A, A0 + vx * A1), _rel_err(B, vx * B1)), 1e-12))
        struct = max(_rel_err(P, np.eye(n) - E @ C), _rel_err(N, P @ A - K @ C), _rel_err(J, K + N @ E),
                     _rel_err(H, P @ B))
        checks.append(_le(f"P = I - E C, N = P A - K C (33), J = K + N E (30a), H = P B (30b), {where}", struct, 1e-9))
        off = N[~np.eye(n, dtype=bool)]
        checks.append(_ge(f"N Metzler: min off-diagonal entry, {where}", float(np.min(off)), 0.0))
        checks.append(_ge(f"N + eta I >= 0 elementwise (36), {where}", float(np.min(N + eta * np.eye(n))), 0.0))
        checks.append(_le(f"N Hurwitz: max Re(eig), {where}", float(np.max(np.linalg.eigvals(N).real)), -1e-9))
        Qm = np.diag(Q)
        lam = np.block([[N.T @ Qm + Qm @ N + eps * Qm, Qm], [Qm, -gamma * np.eye(n)]])
        checks.append(_le(f"LMI (35) on the stored Q, gamma: max eig, {where}",
                          float(np.max(np.linalg.eigvalsh((lam + lam.T) / 2))), 0.0))
        W = np.max([np.abs(P @ dA) for dA in dAs], axis=0)
        width = N + 2.0 * W
        checks.append(_le(f"width dynamics N + 2|P dA| Hurwitz over the stiffness box (small gain), {where}",
                          float(np.max(np.linalg.eigvals(width).real)), -1e-9))
        # the runtime: measured states are intersected with the measurement at every step (zero
        # width), the known speed mismatch (vx - vx_i) A1 inside the band is bounded exactly (Lemma 3
        # part 1: width gain |P (vx - vx_i) A1|), the stiffness part as above
        dv = max(vx - lo, hi - vx)
        rt = (N + 2.0 * W + dv * np.abs(P) @ np.abs(A1))[np.ix_(unmeasured, unmeasured)]
        checks.append(_le(f"runtime width dynamics on the unmeasured states {[rm.STATES[k] for k in unmeasured]} "
                          f"with the band's speed mismatch +-{dv:g} m/s Hurwitz, {where}",
                          float(np.max(np.linalg.eigvals(rt).real)), -1e-9))
    iss = math.sqrt(gamma / (alpha * eps))
    checks.append(_le("ISS gain sqrt(gamma/(alpha eps)) of eq. (37) equals the stored one (relative error)",
                      abs(iss - float(d["iss_gain"])) / iss, 1e-9))
    gains = max(float(np.max(np.abs(np.asarray(m[k], float)))) for m in d["modes"] for k in ("E", "K", "J"))
    checks.append(_le("largest gain entry of E, K, J", gains, float(d["options"].get("gain_limit", 1e4))))
    checks.append(_ge("runtime Metzler shift eta >= max(-diag N)", float(d["runtime"]["eta"]),
                      max(float(-np.min(np.diag(np.asarray(m["N"], float)))) for m in d["modes"])))
    return checks


# -- paper 002's baseline peer: the MBDS authors' linear bicycle-model Kalman filter -----------------
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


def _certify_kalman(d: dict) -> list[Check]:
    """Certificate of the Kalman baseline's design file (``kalman_baseline.design``), numpy/scipy
    only: the covariances (Q PSD, R and P0 positive definite, symmetric); the model the filter
    runs (``kalman_baseline.model``, the stored coefficients, the FMU runtime's ``model``) against
    the force-balance derivation ``_kalman_force_model``; the runtime's zero-order hold against
    scipy's; and, on a grid of speeds over each mode's range at the step h of the file's
    ``certificate`` section (default 0.01 s, the MBDS rate), the discretised model observable
    from [ay, r] and the steady-state Kalman filter of the discrete algebraic Riccati equation
    (Q h, R) Schur stable, its worst spectral radius <= the stored gamma. Frozen speed: the
    time-varying filter is not covered between grid speeds or under fast speed changes."""
    import scipy.linalg
    import scipy.signal

    from ..fmu_src.kalman_observer import KalmanObserver, _expm3
    from . import kalman_baseline as kb

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
    try:
        runtime = KalmanObserver(d, {})
        runtime_error = ""
    except ValueError as exc:
        runtime, runtime_error = None, str(exc)
    checks.append(_le("the FMU runtime accepts the design file (0 = yes)", 0.0 if runtime else 1.0, 0.0, runtime_error))
    mod = d.get("model", {})
    for mode in d["modes"]:
        lo, hi = (float(x) for x in mode["scheduling"]["range"])
        where = f"mode {mode['index']}, vx in [{lo:g}, {hi:g}] m/s"
        checks.append(_le(f"certified speeds inside the runtime's clamp [vx_min, vx_max] = [{vx_min:g}, {vx_max:g}] "
                          f"m/s: max(vx_min - min, max - vx_max), {where}", max(vx_min - lo, hi - vx_max), 0.0))
        speeds = np.linspace(lo, hi, max(n, 1)) if hi > lo else np.array([lo])
        err_kb = err_stored = err_rt = err_zoh = 0.0
        obs, rho_max, res_max = math.inf, 0.0, 0.0
        for v in speeds:
            A, B, C, D = _kalman_force_model(p, float(v))
            A1, B1, C1, D1 = kb.model(p, v)
            err_kb = max(err_kb, _rel_err(A1[0], A), _rel_err(B1[0], B), _rel_err(C1[0], C), _rel_err(D1[0], D))
            if mod:
                As = np.asarray(mod["A_inv_v"], float) / v + np.asarray(mod["A_v"], float) * v
                Cs = np.asarray(mod["C_inv_v"], float) / v + np.asarray(mod["C_0"], float)
                err_stored = max(err_stored, _rel_err(As, A), _rel_err(mod["B"], B), _rel_err(Cs, C),
                                 _rel_err(mod["D"], D))
            Phi, Gam, *_ = scipy.signal.cont2discrete((A, B[:, None], C, D[:, None]), h, method="zoh")
            if runtime is not None:
                Ar, Br, Cr_, Dr = runtime.model(float(v))
                err_rt = max(err_rt, _rel_err(Ar, A), _rel_err(Br, B), _rel_err(Cr_, C), _rel_err(Dr, D))
                E = np.asarray(_expm3([[*(a * h for a in Ar[0]), Br[0] * h], [*(a * h for a in Ar[1]), Br[1] * h],
                                       [0.0, 0.0, 0.0]]))
                err_zoh = max(err_zoh, _rel_err(E[:2, :2], Phi), _rel_err(E[:2, 2], Gam[:, 0]))
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
        checks.append(_le(f"kalman_baseline.model equals the force-balance model (A, B, C, D; max rel. error), {grid}",
                          err_kb, 1e-12))
        if mod:
            checks.append(_le(f"stored model coefficients equal the force-balance model (max rel. error), {grid}",
                              err_stored, 1e-12))
        checks.append(_le(f"FMU runtime's model(v) equals the force-balance model (max rel. error), {grid}",
                          err_rt if runtime is not None else math.inf, 1e-12))
        checks.append(_le(f"FMU runtime's zero-order hold (Taylor expm) equals scipy's at h = {h:g} s "
                          f"(max rel. error), {grid}", err_zoh if runtime is not None else math.inf, 1e-12))
        checks.append(_ge(f"discretised model observable from [ay, r]: min sigma_min/sigma_max of [C; C Phi] "
                          f"at h = {h:g} s, {grid}", obs, 1e-9))
        checks.append(_le(f"discrete algebraic Riccati equation (Q h, R) solved: max relative residual at "
                          f"h = {h:g} s, {grid}", res_max, 1e-8))
        checks.append(Check(f"steady-state Kalman error dynamics Phi (I - K C) Schur stable: max spectral radius "
                            f"at h = {h:g} s, {grid}", float(rho_max), 1.0, bool(rho_max < 1.0), "<"))
        checks.append(_le(f"max spectral radius <= the stored gamma, {grid}", rho_max,
                          float(d["gamma"]) * (1 + 1e-9)))
    return checks


def _bicycle_coefficients_002(m, Iz, lf, lr, Cf, Cr, v):
    """(b1, b2, a) ascending, a monic, of beta/delta and r/delta, derived here from the state-space
    force equations in (vy, r) and ``scipy.signal.ss2tf`` (independent of the design module's
    closed form): m (vy' + v r) = Fyf + Fyr, Iz r' = lf Fyf - lr Fyr, Fyf = Cf (delta - (vy + lf r)/v),
    Fyr = Cr (lr r - vy)/v, beta = vy / v."""
    import scipy.signal
    A = np.array([[-(Cf + Cr) / (m * v), (lr * Cr - lf * Cf) / (m * v) - v],
                  [(lr * Cr - lf * Cf) / (Iz * v), -(lf ** 2 * Cf + lr ** 2 * Cr) / (Iz * v)]])
    B = np.array([[Cf / m], [lf * Cf / Iz]])
    C = np.array([[1.0 / v, 0.0], [0.0, 1.0]])
    num, den = scipy.signal.ss2tf(A, B, C, np.zeros((2, 1)))
    den = np.asarray(den, float)
    num = np.asarray(num, float) / den[0]
    den = den / den[0]
    # descending (s^2, s, 1) -> ascending; the s^2 terms of num are 0 (strictly proper)
    return num[0][::-1][:2], num[1][::-1][:2], den[::-1]


def _weighted_error_002(b1, b2, a, y, x, W1, W2, w):
    """|W1 W2 (b1 - b2 y/x)/a| (jw) for plant rows (N, .) and frequencies w: (N, W)."""
    s = 1j * np.asarray(w, float)
    pv = lambda c: np.polyval(np.asarray(c, float)[::-1], s)
    Wt = pv(W1["num"]) / pv(W1["den"]) * pv(W2["num"]) / pv(W2["den"])
    k = pv(y) / pv(x)
    rows = lambda M: np.array([np.polyval(np.asarray(c, float)[::-1], s) for c in M])
    return np.abs(Wt * (rows(b1) - rows(b2) * k) / rows(a))


def _peak_002(b1, b2, a, y, x, W1, W2, wmin=1e-5, wmax=1e3, n=4000):
    """Worst |G(jw)| over the plants: a dense log sweep plus w = 0, then a 400-point linear
    re-sweep between the neighbours of the largest sample (a plain sweep, no optimiser)."""
    w = np.concatenate([[0.0], np.logspace(math.log10(wmin), math.log10(wmax), n)])
    M = _weighted_error_002(b1, b2, a, y, x, W1, W2, w)
    i, j = np.unravel_index(int(np.argmax(M)), M.shape)
    lo, hi = w[max(j - 1, 0)], w[min(j + 1, len(w) - 1)]
    fine = _weighted_error_002(b1[i:i + 1], b2[i:i + 1], a[i:i + 1], y, x, W1, W2, np.linspace(lo, hi, 400))
    return float(max(M.max(), fine.max()))


def _certify_002(d: dict) -> list[Check]:
    """Paper 002 (fixed-order estimator y/x, per speed band), independent of Lemma 5 and of the
    design module: the plant coefficients are re-derived from the state-space model
    (``_bicycle_coefficients_002``), the coefficient polytope from its box corners, and every
    worst case by a plain frequency sweep.

    Per mode: x Hurwitz; every vertex plant and every grid plant stable; the polytope contains a
    5^3 grid of true plants (the multi-affine over-bound holds); the worst weighted error over the
    64 vertices <= the file's ``gamma_vertex`` and over the (k_Cf, k_Cr, k_v) grid of true plants
    <= ``gamma_grid`` (each also within 1 % of the claim, so that a claim is not vacuous); the
    file's overall ``gamma`` / ``gamma_grid`` are the modes' maxima. Scheduled: the bands are
    contiguous, cover the vehicle's speed range and match the runtime's ``estimators``."""
    checks: list[Check] = []
    par = d["vehicle"]["parameters"]
    m, Iz, lf, lr = (float(par[k]) for k in ("m", "Iz", "lf", "lr"))
    W1, W2 = d["weights"]["W1"], d["weights"]["W2"]
    grid = tuple(int(k) for k in d.get("certificate_grid", (9, 9, 9)))
    ests = d["estimators"] if d.get("scheduled") else [d["estimator"]]
    if len(ests) != len(d["modes"]):
        checks.append(_le("runtime estimators match the modes (count difference)",
                          abs(len(ests) - len(d["modes"])), 0))
        return checks
    for mode, est in zip(d["modes"], ests):
        where = f"mode {mode['index']} (v in [{mode['box']['v'][0]:.4g}, {mode['box']['v'][1]:.4g}] m/s)"
        y, x = np.asarray(est["num"], float), np.asarray(est["den"], float)
        same = max(float(np.max(np.abs(np.asarray(mode["estimator"][k], float) - np.asarray(est[k], float))))
                   for k in ("num", "den")) if all(len(mode["estimator"][k]) == len(est[k]) for k in ("num", "den")) \
            else math.inf
        checks.append(_le(f"runtime estimator = the mode's estimator (max coefficient difference), {where}", same, 0.0))
        xr = float(np.max(np.roots(x[::-1]).real)) if len(x) > 1 else -math.inf
        checks.append(_le(f"estimator denominator x(s) Hurwitz (max Re root), {where}", xr, -1e-9))
        cf, cr, vv = mode["box"]["Cf"], mode["box"]["Cr"], mode["box"]["v"]
        corners = [_bicycle_coefficients_002(m, Iz, lf, lr, a_, b_, c_) for a_ in cf for b_ in cr for c_ in vv]
        flat = lambda t: np.concatenate([t[0], t[1], t[2][:2]])        # b1_0 b1_1 b2_0 b2_1 a_0 a_1
        C = np.array([flat(t) for t in corners])
        lo, hi = C.min(axis=0), C.max(axis=0)
        verts = np.array([[(lo, hi)[p][k] for k, p in enumerate(pick)] for pick in itertools.product((0, 1), repeat=6)])
        vb1, vb2 = verts[:, 0:2], verts[:, 2:4]
        va = np.column_stack([verts[:, 4:6], np.ones(len(verts))])
        axes = [np.linspace(lo_, hi_, k) for (lo_, hi_), k in zip((cf, cr, vv), grid)]
        pts = list(itertools.product(*axes))
        gt = [_bicycle_coefficients_002(m, Iz, lf, lr, *p) for p in pts]
        gb1, gb2, ga = (np.array([t[i] for t in gt]) for i in range(3))
        G = np.array([flat(t) for t in gt])
        tol = 1e-9 * np.maximum(np.abs(lo), np.abs(hi))
        outside = float(np.max(np.maximum(lo - tol - G, G - hi - tol).clip(min=0)))
        checks.append(_le(f"coefficient polytope contains the grid's true plants (max excess), {where}", outside, 0.0))
        for tag, (b1, b2, a), claim in (("64 polytope vertices", (vb1, vb2, va), mode["gamma_vertex"]),
                                        (f"{len(pts)} true plants on the grid", (gb1, gb2, ga), mode["gamma_grid"])):
            # a monic quadratic is Hurwitz iff its two lower coefficients are > 0
            worst_plant = float(-np.min(a[:, :2]))
            checks.append(_le(f"plants stable ({tag}): -min(a_0, a_1), {where}", worst_plant, 0.0))
            g = _peak_002(b1, b2, a, y, x, W1, W2) if worst_plant < 0 and xr < 0 else math.inf
            checks.append(_le(f"worst weighted H-inf error over the {tag} <= claimed, {where}", g,
                              float(claim) * (1 + REL_TOL)))
            checks.append(_le(f"claimed worst case over the {tag} is tight (relative gap), {where}",
                              abs(float(claim) - g) / max(g, 1e-300) if math.isfinite(g) else math.inf, 1e-2))
    checks.append(_le("gamma = max over the modes of the vertex worst case (difference)",
                      abs(d["gamma"] - max(mm["gamma_vertex"] for mm in d["modes"])), 0.0))
    checks.append(_le("gamma_grid = max over the modes of the grid worst case (difference)",
                      abs(d["gamma_grid"] - max(mm["gamma_grid"] for mm in d["modes"])), 0.0))
    if d.get("scheduled"):
        bands = [e["vx_band"] for e in ests]
        gap = max([abs(b1_[0] - b0[1]) for b0, b1_ in zip(bands, bands[1:])] + [0.0])
        checks.append(_le("speed bands contiguous (max gap or overlap, m/s)", gap, 0.0))
        rv = d["vehicle"].get("ranges", {}).get("speed")
        if rv:
            k = {"m/s": 1.0, "km/h": 1 / 3.6}.get(rv.get("unit", "m/s"), 1.0)
            cover = max(bands[0][0] - k * rv["min"], k * rv["max"] - bands[-1][1], 0.0)
            checks.append(_le("speed bands cover the vehicle's speed range (uncovered, m/s)", cover, 0.0))
        checks.append(_le("each mode's box speed range = its band (max difference, m/s)",
                          max(abs(e["vx_band"][i] - mm["box"]["v"][i]) for e, mm in zip(ests, d["modes"])
                              for i in (0, 1)), 0.0))
    return checks


def _certify_003(d: dict) -> list[Check]:
    """Paper 003 (switched PI observer, motorcycle roll angle and rider torque), numpy/scipy only.

    Re-evaluates the packaged numbers, independently of the LMI solver: the stored model against
    its re-derivation (``motorcycle_model.reduced_model``, when the design used it); y = states
    (F_d = F_f = 0); the bands against the switching edges; per mode the rank condition (24) at
    s = 0 and at the eigenvalues of A with Re >= 0, the closed loop A~ - L C~ Hurwitz, the H-inf norm
    of d~ = [Gamma; xi] -> r = C~ x~ (eq. 16, in the design's normalised units) by Hamiltonian
    bisection (``hinf.py``, no P) <= gamma_i, cross-checked by a frequency sweep, the norm
    d~ -> x~ <= gamma_i (what the ISS LMI (21) implies), the gain L = -P^-1 U (mapped to SI) of the
    stored P, U, the LMIs (20)-(23) re-evaluated on the stored P, U, gamma_bar, alpha_bar (ERRATA 003
    forms), the ISS constants (sqrt(lmax/lmin), decay rates), the largest gain and cond(P); the
    average dwell time ln(mu)/lambda_0 recomputed (generalized eigenvalues) against the stored one;
    and the FMU runtime's matrices and exact step map against scipy's expm.
    """
    import scipy.linalg

    checks: list[Check] = []
    opts, sc = d["options"], d["scaling"]
    xs, fs, ds = (np.asarray(sc[k], float) for k in ("x_scale", "f_scale", "d_scale"))
    D, Dx, Dd = np.diag(np.concatenate([xs, fs])), np.diag(xs), np.diag(ds)
    Di = np.linalg.inv(D)
    n, nf = len(xs), len(fs)
    na = n + nf
    sym = lambda M: (M + M.T) / 2
    rederive = None
    if d["structure"].get("model_source") == "latobs.synthesis.motorcycle_model.reduced_model":
        from .motorcycle_model import reduced_model
        vehicle = parse_vehicle(d["vehicle"], f"design file {d['name']}")
        rederive = lambda v: reduced_model(vehicle, v)
    edges = [float(e) for e in d["switching"]["edges"]]
    checks.append(_le("switching edges bound the modes: |#edges - #modes - 1| + unsorted",
                      abs(len(edges) - len(d["modes"]) - 1) + (edges != sorted(edges)), 0.0))
    Ps, Acls, L_all = [], [], []
    for k, mode in enumerate(d["modes"]):
        vx = float(mode["vx"])
        where = f"mode {mode['index']} (vx = {vx:g} m/s)"
        band = [float(b) for b in mode["band"]]
        if k + 1 < len(edges):
            checks.append(_le(f"band = [edges[i], edges[i+1]] and the grid speed inside it (m/s), {where}",
                              max(abs(band[0] - edges[k]), abs(band[1] - edges[k + 1]), band[0] - vx, vx - band[1], 0.0),
                              0.0))
        mod = mode["model"]
        A, Ef, Ed, C, Fd, Ff, Hx = (np.asarray(mod[key], float) for key in ("A", "E_f", "E_d", "C", "F_d", "F_f", "H_x"))
        Hphi = np.asarray(mod["H_phi"], float)
        if rederive is not None:
            m = rederive(vx)
            err = max(_rel_err(A, m.A), _rel_err(Ef, np.column_stack([np.ravel(m.E_phi), np.ravel(m.B_tau)])),
                      _rel_err(Ed, m.E_gamma), _rel_err(C, m.C), _rel_err(Hx, m.H_x), _rel_err(Hphi, np.ravel(m.H_phi)))
            checks.append(_le(f"model equals the reduced model re-derived from the vehicle parameters, {where}", err, 1e-12))
        sel = float(np.max(np.abs(np.sort(C, axis=1) - np.eye(1, n, n - 1)))) + abs(len(set(np.argmax(C, 1))) - C.shape[0])
        checks.append(_le(f"y = states: C a 0/1 selection of distinct states, F_d = F_f = 0 (max deviation), {where}",
                          max(sel, float(np.max(np.abs(Fd))), float(np.max(np.abs(Ff))) if Ff.size else 0.0), 0.0))
        # rank condition (24): only s = 0 and the eigenvalues of A with Re >= 0 can lower the rank
        ny = C.shape[0]
        margin = math.inf
        for s in [0.0] + [lam for lam in np.linalg.eigvals(A) if lam.real >= 0]:
            M = np.block([[s * np.eye(n) - A, -Ef], [np.zeros((nf, n)), s * np.eye(nf)], [C, np.zeros((ny, nf))]])
            sv = np.linalg.svd(M, compute_uv=False)
            margin = min(margin, float(sv[-1] / sv[0]))
        checks.append(_ge(f"rank condition (24): min sigma_min/sigma_max at s = 0 and eig(A) with Re >= 0, {where}",
                          margin, float(opts.get("rank_tol", 1e-9))))
        At = np.block([[A, Ef], [np.zeros((nf, n + nf))]])
        Ct = np.hstack([C, np.zeros((ny, nf))])
        Edt = np.vstack([Ed, np.zeros((nf, Ed.shape[1]))])
        It = np.vstack([np.eye(n), np.zeros((nf, n))])
        L = np.vstack([np.asarray(mode["gains"]["L_P"], float), np.asarray(mode["gains"]["L_I"], float)])
        checks.append(_le(f"gains L_P, L_I finite (count of non-finite entries), {where}",
                          float(np.sum(~np.isfinite(L))), 0.0))
        L = np.nan_to_num(L, nan=1e300, posinf=1e300, neginf=-1e300)
        L_all.append(L)
        Acl = At - L @ Ct
        max_re = float(np.max(np.linalg.eigvals(Acl).real))
        checks.append(_le(f"closed loop A~ - L C~ Hurwitz: max Re(eig), {where}", max_re, -1e-9))
        region = d.get("region") or {}
        if region.get("alpha") is not None or region.get("radius") is not None:
            reg = hinf.pole_region(Acl, float(region.get("alpha") or 0.0), float(region.get("radius") or math.inf))
            if region.get("alpha") is not None:
                checks.append(_le(f"pole region: max Re(eig) <= -alpha, {where}", reg["max_real_part"],
                                  -float(region["alpha"])))
            if region.get("radius") is not None:
                checks.append(_le(f"pole region: max |eig| <= radius, {where}", reg["max_modulus"], float(region["radius"])))
        # normalised units (the design's): x~ = D x~_n, d = Dd d_n, xi = Dx xi_n, r = Y r_n
        Y = C @ Dx @ C.T
        Yi = np.linalg.inv(Y)
        An, Cn = Di @ At @ D, Yi @ Ct @ D
        Bn = np.hstack([Di @ Edt @ Dd, Di @ It @ Dx])
        Acln = Di @ Acl @ D
        gi = float(mode["gamma"])
        if max_re < 0:
            hn = hinf.hinf_norm(Acln, Bn, Cn).norm
            sweep, _ = hinf.frequency_sweep_peak(Acln, Bn, Cn)
            gap = abs(hn - sweep) / max(hn, 1e-300)
            hx = hinf.hinf_norm(Acln, Bn, np.eye(na)).norm
        else:
            hn = gap = hx = math.inf
        checks.append(_le(f"H-inf d~ -> residual r (16), Hamiltonian, normalised <= gamma_i, {where}", hn, gi * (1 + REL_TOL)))
        checks.append(_le(f"Hamiltonian and frequency sweep agree (relative gap), {where}", gap, 1e-3))
        checks.append(_le(f"H-inf d~ -> x~ (implied by the ISS LMI (21)), normalised <= gamma_i, {where}", hx,
                          gi * (1 + REL_TOL)))
        P, U = sym(np.asarray(mode["P"], float)), np.asarray(mode["U"], float)
        gb, ab = float(mode["gamma_bar"]), float(mode["alpha_bar"])
        checks.append(_le(f"gamma_i = sqrt(gamma_bar) (ERRATA 003), relative error, {where}",
                          abs(gi - math.sqrt(max(gb, 0.0))) / max(gi, 1e-300), 1e-12))
        checks.append(_le(f"P symmetric: max |P - P'|, {where}", float(np.max(np.abs(np.asarray(mode["P"]) - np.asarray(mode["P"]).T))), 0.0))
        try:
            Ln = -np.linalg.solve(P, U)
            lerr = _rel_err(L, D @ Ln @ Yi)
        except np.linalg.LinAlgError:
            lerr = math.inf
        checks.append(_le(f"gains = D (-P^-1 U) Y^-1 of the stored P, U (ERRATA 003: L = -P^-1 U), rel. error, {where}",
                          lerr, 1e-8))
        PA = P @ An + U @ Cn
        core = PA + PA.T
        nd, nxi = Edt.shape[1], n
        Edn, Itn, Fdn = Di @ Edt @ Dd, Di @ It @ Dx, Yi @ Fd @ Dd
        Z = np.zeros((nd, nxi))
        Lam, Phi = P @ Edn + U @ Fdn + Cn.T @ Fdn, P @ Edn + U @ Fdn
        m20 = np.block([[core + Cn.T @ Cn, Lam, P @ Itn], [Lam.T, Fdn.T @ Fdn - gb * np.eye(nd), Z],
                        [(P @ Itn).T, Z.T, -gb * np.eye(nxi)]])
        m21 = np.block([[core + np.eye(na), Phi, P @ Itn], [Phi.T, -gb * np.eye(nd), Z],
                        [(P @ Itn).T, Z.T, -gb * np.eye(nxi)]])
        m22 = np.block([[ab * np.eye(na), P], [P, np.eye(na)]])
        checks.append(_le(f"LMI (20) on the stored P, U, gamma_bar: max eig, {where}", float(np.max(np.linalg.eigvalsh(sym(m20)))), 0.0))
        checks.append(_le(f"LMI (21) on the stored P, U, gamma_bar: max eig, {where}", float(np.max(np.linalg.eigvalsh(sym(m21)))), 0.0))
        checks.append(_ge(f"LMI (22) [[alpha_bar I, P], [P, I]] (ERRATA 003): min eig, {where}",
                          float(np.min(np.linalg.eigvalsh(m22))), 0.0))
        ev = np.linalg.eigvalsh(P)
        checks.append(_ge(f"LMI (23) P >= I: min eig(P) - 1, {where}", float(ev[0] - 1.0), 0.0))
        iss = mode.get("iss", {})
        kappa = math.sqrt(ev[-1] / ev[0]) if ev[0] > 0 else math.inf
        checks.append(_le(f"ISS constant sqrt(lmax(P)/lmin(P)) equals the stored one (relative error), {where}",
                          abs(kappa - float(iss.get("kappa", math.nan))) / kappa if math.isfinite(kappa) else math.inf, 1e-9))
        checks.append(_le(f"ISS decay rate 1/(2 lmax(P)) equals the stored one (relative error), {where}",
                          abs(1 / (2 * ev[-1]) - float(iss.get("decay_rate_paper", math.nan))) * 2 * ev[-1], 1e-9))
        gains = float(np.max(np.abs(L)))
        checks.append(_le(f"largest gain entry of L_P, L_I (SI), {where}", gains, float(opts.get("gain_limit", 1e6))))
        checks.append(_le(f"cond(P), {where}", float(np.linalg.cond(P)), float(opts.get("cond_limit", 1e8))))
        Ps.append(P)
        Acls.append(Acln)
    # average dwell time (Hespanha & Morse 1999): tau_a > ln(mu) / lambda_0
    lam = []
    for P, Acl in zip(Ps, Acls):
        try:
            lam.append(float(np.min(scipy.linalg.eigh(-sym(Acl.T @ P + P @ Acl), P, eigvals_only=True))))
        except (np.linalg.LinAlgError, ValueError):
            lam.append(-math.inf)
    lam0 = min(lam) if lam else -math.inf
    checks.append(_ge("Lyapunov decay lambda_0 = min_i max{l : A*_i'P_i + P_i A*_i <= -l P_i} > 0 (1/s)", lam0, 1e-9))
    k = len(Ps)
    mu = np.ones((k, k))
    for i in range(k):
        for j in range(k):
            if i != j:
                try:
                    mu[i, j] = float(np.max(scipy.linalg.eigh(Ps[j], Ps[i], eigvals_only=True)))
                except (np.linalg.LinAlgError, ValueError):
                    mu[i, j] = math.inf
    dw = d.get("dwell_time", {})
    for key, m in (("tau_a", float(np.max(mu))),
                   ("tau_a_adjacent", max([max(mu[i, i + 1], mu[i + 1, i]) for i in range(k - 1)], default=1.0))):
        tau = (math.log(m) / lam0 if m > 1 else 0.0) if lam0 > 0 else math.inf
        stored = float(dw.get(key, math.nan))
        checks.append(_le(f"average dwell time {key} = ln(mu)/lambda_0 = {tau:.4g} s equals the stored one (relative error)",
                          abs(tau - stored) / max(tau, 1e-300) if math.isfinite(tau) else math.inf, 1e-6))
    checks.append(_le("gamma = max over the modes of gamma_i (difference)",
                      abs(float(d["gamma"]) - max(float(m["gamma"]) for m in d["modes"])), 0.0))
    # the FMU runtime: its eq. (13) matrices and its exact step map
    try:
        from ..fmu_src.motorcycle_observer import MotorcycleFaultObserver, step_map
        rt = MotorcycleFaultObserver(d, {})
        rt_err, map_err = 0.0, 0.0
        for k, mode in enumerate(d["modes"]):
            A, Ef, C = (np.asarray(mode["model"][key], float) for key in ("A", "E_f", "C"))
            At = np.block([[A, Ef], [np.zeros((nf, n + nf))]])
            Ct = np.hstack([C, np.zeros((C.shape[0], nf))])
            M, G = At - L_all[k] @ Ct, L_all[k]
            rt_err = max(rt_err, _rel_err(rt._M[k], M), _rel_err(rt._G[k], G))
            for h in (1e-3, 1e-2):
                E = scipy.linalg.expm(np.block([[M * h, G * h], [np.zeros((G.shape[1], na + G.shape[1]))]]))
                W = np.asarray(step_map(M.tolist(), G.tolist(), h))
                map_err = max(map_err, _rel_err(W, E[:na]))
        runtime_error = ""
    except Exception as exc:       # the runtime rejects the file: the checks below fail
        rt_err = map_err = math.inf
        runtime_error = repr(exc)
    checks.append(_le("FMU runtime's eq. (13) matrices [[A - L_P C, E_f], [-L_I C, 0]], [L_P; L_I] (max rel. error)",
                      rt_err, 1e-12, runtime_error))
    checks.append(_le("FMU runtime's exact step map equals scipy's expm at h = 1 ms and 10 ms (max rel. error)",
                      map_err, 1e-9, runtime_error))
    return checks


def as_dicts(checks: list[Check]) -> list[dict]:
    return [asdict(c) for c in checks]


def summary(data: dict) -> dict:
    """Headline figures of a certified design (for notes and reports)."""
    if data.get("paper") == "002" and data.get("kind") == "fixed_order_estimator":
        return {"gamma": data["gamma"], "gamma_grid": data["gamma_grid"],
                "per_mode": [{"mode": m["index"], "vx_band": m["vx_band"], "gamma_lmi": m["gamma_lmi"],
                              "gamma_vertex": m["gamma_vertex"], "gamma_grid": m["gamma_grid"],
                              "grid_dc_floor": m["grid_dc_floor"], "estimator": m["estimator"]}
                             for m in data["modes"]]}
    if data.get("paper") == "002":          # the Kalman baseline: no modes to tabulate
        return {"gamma": data.get("gamma"), "per_mode": []}
    if data.get("paper") == "003":
        per_mode = []
        for m in data["modes"]:
            L = np.vstack([np.asarray(m["gains"]["L_P"], float), np.asarray(m["gains"]["L_I"], float)])
            per_mode.append({"mode": m["index"], "speed_ms": m["vx"], "band": m["band"], "gamma": m["gamma"],
                             "alpha_bar": m["alpha_bar"], "slowest_pole": float(max(m["poles"]["re"])),
                             "fastest_pole": float(min(m["poles"]["re"])), "kappa": m["iss"]["kappa"],
                             "largest_gain": float(np.max(np.abs(L)))})
        dw = data.get("dwell_time", {})
        return {"gamma": data["gamma"], "per_mode": per_mode, "beta": data.get("beta"),
                "dwell_time_s": dw.get("tau_a"), "dwell_time_adjacent_s": dw.get("tau_a_adjacent")}
    if data.get("paper") == "001":
        return {"gamma": data["gamma"], "iss_gain": data["iss_gain"],
                "per_mode": [{"mode": m["index"], "speed_ms": m["vx"], "band": m["band"],
                              "slowest_pole": float(np.max(np.linalg.eigvals(np.asarray(m["N"])).real)),
                              "largest_gain": float(max(np.max(np.abs(np.asarray(m[k]))) for k in ("E", "K", "J")))}
                             for m in data["modes"]]}
    out = {"gamma": data["gamma"], "per_mode": []}
    for mode in data["modes"]:
        K_P, K_I = np.asarray(mode["gains"]["K_P"]), np.asarray(mode["gains"]["K_I"])
        T, C = np.asarray(data["structure"]["T"]), np.asarray(data["structure"]["C"])
        for v in mode["design_speeds"]:
            Acl, Fa, La = closed_loop(mode["model"], K_P, K_I, T, C, v)
            e_w = np.zeros((1, Acl.shape[0])); e_w[0, -1] = 1.0
            out["per_mode"].append({
                "mode": mode["index"], "label": mode["label"], "speed_kmh": round(v * 3.6, 3),
                "hinf": hinf.hinf_norm(Acl, Fa, La).norm,
                "slowest_bank_pole": hinf.slowest_pole_seen_by(Acl, Fa, e_w)[0].real,
                "slowest_pole": float(np.max(np.linalg.eigvals(Acl).real)),
                "largest_gain": float(max(np.max(np.abs(K_P)), np.max(np.abs(K_I)))),
            })
    out["cond_P"] = float(np.linalg.cond(np.asarray(data["P"])))
    return out
