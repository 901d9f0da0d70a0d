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

    if d.get("method") == "measured_speed":
        return certify_measured(d)

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
    if data.get("method") == "measured_speed":
        return summary_measured(data)
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


# -- the measured-speed design (synthesis.motorcycle_fault_observer_lpv) -----------------------------
def _augmented_003(r, nt: int):
    """The measured-speed design's model rebuilt from a ReducedModel by blocks (not the design
    module's code): x = [x_paper; phi] with phi' = e_roll_rate' x; s = [x; tau; tau' ...] with the
    torque chain a shift matrix."""
    e_p = np.eye(1, 5, 2)                                   # the roll rate's row selector
    Ax = np.block([[r.A, np.reshape(r.E_phi, (5, 1))], [e_p, np.zeros((1, 1))]])
    Bt = np.vstack([np.reshape(r.B_tau, (5, 1)), np.zeros((1, 1))]) @ np.eye(1, nt)
    A = np.block([[Ax, Bt], [np.zeros((nt, 6)), np.eye(nt, k=1)]])
    Ed = np.vstack([r.E_gamma, np.zeros((1 + nt, 2))])
    C = np.hstack([r.C, np.zeros((3, 1 + nt))])
    H = np.hstack([r.H_x, np.reshape(r.H_phi, (2, 1))])
    return A, Ed, C, H


def certify_measured(d: dict) -> list[Check]:
    """Checks of a measured-speed paper-003 design: the model's (1, vx, 1/vx) coefficients against the
    reduced model re-derived at other speeds; one P with the decay, disk and bounded-real LMIs at
    every band's (vx, 1/vx) box corners (affine in (vx, 1/vx): they then hold at every speed of the
    band, for any speed history and switching); poles and H-infinity norms on a dense speed grid."""
    import scipy.linalg

    checks: list[Check] = []
    o = d["options"]
    sym = lambda M: (M + M.T) / 2
    mod = d["model"]
    A, Ed, C, H = ([np.asarray(c, float) for c in mod[k]] for k in ("A", "E_d", "C", "H"))
    na, nt = A[0].shape[0], len(d["structure"]["faults"])
    at = lambda coef, v, w=None: coef[0] + v * coef[1] + (1.0 / v if w is None else w) * coef[2]
    checks.append(_le("model sizes: s = [6 states; torque integrators] (|na - 6 - nt|)", abs(na - 6 - nt), 0.0))
    if d["structure"].get("model_source") == "latobs.synthesis.motorcycle_model.reduced_model":
        from ..motorcycle_model import reduced_model
        vehicle = parse_vehicle(d["vehicle"], f"design file {d['name']}")
        err = 0.0
        for band in (m["band"] for m in d["modes"]):
            for v in np.linspace(float(band[0]), float(band[1]), 5):
                ref = _augmented_003(reduced_model(vehicle, float(v)), nt)
                err = max(err, *(_rel_err(at(c, float(v)), r) for c, r in zip((A, Ed, C, H), ref)))
        checks.append(_le("model A(vx), E_d, C, H(vx) in (1, vx, 1/vx) equal the reduced model re-derived at 5 speeds "
                          "per band (max rel. error)", err, 1e-10))
    C0 = C[0]
    checks.append(_le("y = states: C a speed-independent 0/1 selection (max deviation)",
                      float(np.max(np.abs(np.sort(C0, axis=1) - np.eye(1, na, na - 1)))) + float(np.max(np.abs(C[1])))
                      + float(np.max(np.abs(C[2]))), 0.0))
    xs, fs = np.asarray(o["x_scale"], float), np.asarray(o["f_scale"], float)
    D = np.diag(np.concatenate([xs, fs]))
    Di = np.linalg.inv(D)
    Y = np.diag([xs[i] for i in np.argmax(C0, axis=1)])
    Yi = np.linalg.inv(Y)
    Bw = np.zeros((na, 8))
    Bw[:, :2] = Di @ Ed[0] * float(o["d_scale"])
    Bw[:5, 2:7] = float(o["xi_weight"]) * np.eye(5)
    Bw[na - 1, 7] = float(o["w_weight"])
    Cz = np.zeros((2, na))
    Cz[0, 5] = 1.0
    Cz[1, 6] = float(o["z_tau"])
    ly = d["lyapunov"]
    Praw = np.asarray(ly["P"], float)
    P = sym(Praw)
    gb, alpha, radius = float(ly["gamma_bar"]), float(ly["alpha"]), float(ly["radius"])
    ev = np.linalg.eigvalsh(P)
    checks.append(_le("P symmetric: max |P - P'|", float(np.max(np.abs(Praw - Praw.T))), 0.0))
    checks.append(_ge("P >= I: min eig(P) - 1 (normalised)", float(ev[0] - 1.0), 0.0))
    checks.append(_le("cond(P)", float(ev[-1] / ev[0]), float(o.get("cond_limit", 1e8))))
    checks.append(_le("gamma = sqrt(gamma_bar) (relative error)", abs(float(d["gamma"]) - math.sqrt(max(gb, 0.0)))
                      / max(float(d["gamma"]), 1e-300), 1e-12))
    lam_min = math.inf
    edges = [float(e) for e in d["switching"]["edges"]]
    checks.append(_le("switching edges = the bands' ends (difference)",
                      max([abs(len(edges) - len(d["modes"]) - 1)]
                          + [abs(m["band"][0] - edges[k]) + abs(m["band"][1] - edges[k + 1])
                             for k, m in enumerate(d["modes"]) if k + 1 < len(edges)]), 0.0))
    for m in d["modes"]:
        lo, hi = (float(b) for b in m["band"])
        where = f"band {m['index']} [{lo:g}, {hi:g}] m/s"
        L = [np.asarray(x, float) for x in m["gains"]["L"]]
        bad = float(sum(np.sum(~np.isfinite(x)) for x in L))
        checks.append(_le(f"gains L_b finite (count of non-finite entries), {where}", bad, 0.0))
        if bad:
            continue
        checks.append(_le(f"largest gain entry of L(vx) on the band (SI), {where}",
                          max(float(np.max(np.abs(at(L, v)))) for v in np.linspace(lo, hi, 21)),
                          float(o.get("gain_limit", 1e6))))
        U = [np.asarray(x, float) for x in m["U"]]
        checks.append(_le(f"gains = D (-P^-1 U_b) Y^-1 of the stored P, U (max rel. error), {where}",
                          max(_rel_err(l, D @ (-np.linalg.solve(P, u)) @ Yi) for l, u in zip(L, U)), 1e-8))
        worst = {"decay": -math.inf, "disk": -math.inf, "bounded real": -math.inf}
        for v, w in ((lo, 1 / lo), (lo, 1 / hi), (hi, 1 / lo), (hi, 1 / hi)):
            An = Di @ (at(A, v, w) - at(L, v, w) @ C0) @ D
            PA = P @ An
            worst["decay"] = max(worst["decay"], float(np.max(np.linalg.eigvalsh(sym(PA + PA.T + 2 * alpha * P)))))
            worst["disk"] = max(worst["disk"], float(np.max(np.linalg.eigvalsh(
                sym(np.block([[-radius * P, PA], [PA.T, -radius * P]]))))))
            br = np.block([[PA + PA.T + Cz.T @ Cz, P @ Bw], [(P @ Bw).T, -gb * np.eye(Bw.shape[1])]])
            worst["bounded real"] = max(worst["bounded real"], float(np.max(np.linalg.eigvalsh(sym(br)))))
            lam_min = min(lam_min, float(np.min(scipy.linalg.eigh(-sym(PA + PA.T), P, eigvals_only=True))))
        checks.append(_le(f"decay LMI A_cl'P + P A_cl + 2 alpha P <= 0 at the 4 (vx, 1/vx) corners: max eig, {where}",
                          worst["decay"], 0.0))
        checks.append(_le(f"disk LMI |lambda| < radius at the 4 corners: max eig, {where}", worst["disk"], 0.0))
        checks.append(_le(f"bounded-real LMI (gamma_bar, w -> z) at the 4 corners: max eig, {where}",
                          worst["bounded real"], 0.0))
        re_max, mod_max, hn_max = -math.inf, 0.0, 0.0
        for v in np.linspace(lo, hi, 41):
            Acl = at(A, float(v)) - at(L, float(v)) @ C0
            eig = np.linalg.eigvals(Acl)
            re_max, mod_max = max(re_max, float(np.max(eig.real))), max(mod_max, float(np.max(np.abs(eig))))
        for v in np.linspace(lo, hi, 5):
            Acln = Di @ (at(A, float(v)) - at(L, float(v)) @ C0) @ D
            hn_max = max(hn_max, hinf.hinf_norm(Acln, Bw, Cz).norm if re_max < 0 else math.inf)
        checks.append(_le(f"closed-loop poles at 41 speeds: max Re <= -alpha, {where}", re_max, -alpha))
        checks.append(_le(f"closed-loop poles at 41 speeds: max |lambda| <= radius, {where}", mod_max, radius))
        checks.append(_le(f"H-inf w -> z (Hamiltonian) at 5 frozen speeds, normalised <= gamma, {where}", hn_max,
                          float(d["gamma"]) * (1 + REL_TOL)))
    checks.append(_ge("one Lyapunov matrix: decay of x'Px at every corner of every band (1/s) >= 2 alpha (any speed "
                      "history, any switching: no dwell time)", lam_min, 2 * float(ly["alpha"]) * (1 - 1e-9)))
    return checks


def summary_measured(data: dict) -> dict:
    """Headline figures of a certified measured-speed design."""
    per_mode = [{"mode": m["index"], "vx_band": m["band"], "band": m["band"], "slowest_pole": m["slowest_pole_re"],
                 "fastest_pole": m["fastest_pole_abs"],
                 "largest_gain": float(max(np.max(np.abs(np.asarray(x, float))) for x in m["gains"]["L"]))}
                for m in data["modes"]]
    P = np.asarray(data["lyapunov"]["P"], float)
    return {"gamma": data["gamma"], "method": "measured_speed", "decay_rate": data["lyapunov"]["alpha"],
            "cond_P": float(np.linalg.cond(P)), "per_mode": per_mode}
