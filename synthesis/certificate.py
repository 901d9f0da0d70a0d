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


def as_dicts(checks: list[Check]) -> list[dict]:
    return [asdict(c) for c in checks]


def summary(data: dict) -> dict:
    """Headline figures of a certified design (for notes and reports)."""
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
