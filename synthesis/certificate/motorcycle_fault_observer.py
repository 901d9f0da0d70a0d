"""Certificate of the motorcycle roll-angle and rider-torque observer (paper 003: switched PI
observer): per mode the model against its re-derivation, the rank condition, the closed loop and
its H-infinity norms, the LMIs (20)-(23) on the stored P, U, the ISS constants; the average dwell
time across the modes. What is checked and why: ``docs/certificates.md``.
"""
from __future__ import annotations

import math

import numpy as np

from .. import hinf
from ..params import parse_vehicle
from .checks import REL_TOL, Check, _ge, _le, _rel_err


def certify(d: dict) -> list[Check]:
    """The checks of a paper-003 design file, independent of the LMI solver (``docs/certificates.md``)."""
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
        from ..motorcycle_model import reduced_model
        vehicle = parse_vehicle(d["vehicle"], f"design file {d['name']}")
        rederive = lambda v: reduced_model(vehicle, v)
    edges = [float(e) for e in d["switching"]["edges"]]
    checks.append(_le("switching edges bound the modes: |#edges - #modes - 1| + unsorted",
                      abs(len(edges) - len(d["modes"]) - 1) + (edges != sorted(edges)), 0.0))
    Ps, Acls = [], []
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
        checks.append(_le(f"gamma_i = sqrt(gamma_bar) (corrected from the print), relative error, {where}",
                          abs(gi - math.sqrt(max(gb, 0.0))) / max(gi, 1e-300), 1e-12))
        checks.append(_le(f"P symmetric: max |P - P'|, {where}", float(np.max(np.abs(np.asarray(mode["P"]) - np.asarray(mode["P"]).T))), 0.0))
        try:
            Ln = -np.linalg.solve(P, U)
            lerr = _rel_err(L, D @ Ln @ Yi)
        except np.linalg.LinAlgError:
            lerr = math.inf
        checks.append(_le(f"gains = D (-P^-1 U) Y^-1 of the stored P, U (corrected from the print: L = -P^-1 U), rel. error, {where}",
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
        checks.append(_ge(f"LMI (22) [[alpha_bar I, P], [P, I]] (sign corrected from the print): min eig, {where}",
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
    return checks


def summary(data: dict) -> dict:
    """Headline figures of a certified design (for notes and reports)."""
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
