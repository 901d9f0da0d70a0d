"""Certificate of the lateral interval observer (paper 001): the model and stiffness box against
their re-derivation, the observer's structure, Metzler and Hurwitz conditions, LMI (35) on the
stored Q, the width dynamics over the stiffness box (small gain) and the ISS gain of eq. (37).
What is checked and why: ``docs/certificates.md``.
"""
from __future__ import annotations

import math

import numpy as np

from .. import relaxation_model as rm
from ..params import parse_vehicle
from .checks import Check, _ge, _le, _rel_err


def certify(d: dict) -> list[Check]:
    """The checks of a paper-001 design file (``docs/certificates.md``)."""
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


def summary(data: dict) -> dict:
    """Headline figures of a certified design (for notes and reports)."""
    return {"gamma": data["gamma"], "iss_gain": data["iss_gain"],
            "per_mode": [{"mode": m["index"], "speed_ms": m["vx"], "band": m["band"],
                          "slowest_pole": float(np.max(np.linalg.eigvals(np.asarray(m["N"])).real)),
                          "largest_gain": float(max(np.max(np.abs(np.asarray(m[k]))) for k in ("E", "K", "J")))}
                         for m in data["modes"]]}
