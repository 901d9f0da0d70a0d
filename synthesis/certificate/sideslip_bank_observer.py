"""Certificate of the sideslip and bank-angle observer (paper 000: switched H-infinity PI observer
with a common Lyapunov matrix): the closed loop of eq. (19) rebuilt from the design file's own
numbers, its LMIs at the stored polytope vertices, a dense frozen-speed grid, the frozen-integral
growth factor. What is checked and why: ``docs/certificates.md``.
"""
from __future__ import annotations

import math

import numpy as np

from .. import bicycle_roll_model as brm
from .. import hinf
from ..params import parse_vehicle
from .checks import REL_TOL, Check, _curve_outside_hull, _ge, _growth_factor, _le, _neg_margin, _rel_err, _sym

GRID_000 = 41           # speeds of the dense grid over each measured model-speed range


def _rk4_factor(z: np.ndarray) -> np.ndarray:
    return 1 + z + z**2 / 2 + z**3 / 6 + z**4 / 24


def _model_error_000(vehicle) -> list[np.ndarray]:
    """E(Vx) = E_0 + E_1 / Vx of x' = ... + E d, written here from the equations of motion (not
    copied from ``bicycle_roll_model``): residuals enter like the model's own generalised forces,
    a lateral force dF through the roll axis (like the tire forces), a yaw moment dMz, a roll moment
    dMx (like -Kr phi - br phi'). With a = [Vx beta', r', phi'']:
        m (Vx beta' + Vx r) - m hr phi'' = ... + dF          (lateral, at the CG)
        Iz r'                             = ... + dMz         (yaw)
        Ix phi''                          = ... + hr dF + dMx (roll about the CG)
    so a = Mq^-1 Q d with Mq the mass matrix below and Q the generalised force of each residual;
    d is per unit of [m g, m g (lf + lr), m g hr]. beta' = a_0 / Vx gives E_1 (row 0), r' and phi''
    give E_0 (rows 1, 3); phi' (row 2) has no input."""
    from ..params import G

    p = vehicle.require(("m", "Iz", "Ix", "lf", "lr", "hr"), "the certificate's model-error input")
    m, Iz, Ix, lf, lr, hr = (p[k] for k in ("m", "Iz", "Ix", "lf", "lr", "hr"))
    Mq = np.array([[m, 0.0, -m * hr], [0.0, Iz, 0.0], [0.0, 0.0, Ix]])
    Q = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [hr, 0.0, 1.0]]) * np.array([m, m * (lf + lr), m * hr]) * G
    a = np.linalg.solve(Mq, Q)
    E0, E1 = np.zeros((4, 3)), np.zeros((4, 3))
    E1[0] = a[0]
    E0[1], E0[3] = a[1], a[2]
    return [E0, E1]


def _model_at(coeffs, v: float, w: float, u: float | None = None, p0: int = 0) -> np.ndarray:
    """sum_k M_k basis_(k + p0) with basis (u, 1, v, w) for the powers -1, 0, 1, 2 of 1/Vx (u stands for
    Vx, default 1/v; w for 1/Vx^2; off the curve at tangent corners); degrees > 2 (never in a valid
    file) as v**k. p0 = structure.first_power (-1: the model with relaxed axle forces, a term in Vx)."""
    basis = {-1: 1.0 / v if u is None else u, 0: 1.0, 1: v, 2: w}
    return sum(np.asarray(M, float) * (basis[k + p0] if k + p0 < 3 else v**(k + p0)) for k, M in enumerate(coeffs))


def _first_power(d: dict) -> int:
    return int(d["structure"].get("first_power", 0))


def closed_loop_000(d: dict, mode: dict, v: float, w: float | None = None, u: float | None = None) -> dict:
    """The certificate's own closed loop of eq. (19) for ``mode`` (an entry of d["modes"]) with its
    model at (u, v, w) = (Vx, 1/Vx, 1/Vx^2) (w or u given: a polytope vertex), from the design file's numbers
    only (T, C, the mode's model coefficients and gains, model_error.E):
        A_cl = [[T A - K_P C, T F], [-K_I C, 0]]   (= A_a - K_a C_a, A_a = [[T A, T F], [0, 0]])
        F_a = [-T F; 0], L_a = [-L, 0], L = [1 0 0 0]          channel 1: bank -> beta error
        E_a = [-T E; 0], Z = [[0 0 0 0 1]; L_a]                 channel 2 (unweighted)
        A_fr = A_cl with its last row zero                      integral action frozen
    The error state is e = [x~; phi_r - w^] (constant bank: e' = A_cl e)."""
    w = v * v if w is None else w
    T, C = (np.asarray(d["structure"][k], float) for k in ("T", "C"))
    K_P, K_I = (np.asarray(mode["gains"][k], float) for k in ("K_P", "K_I"))
    p0 = _first_power(d)
    A = _model_at(mode["model"]["A"], v, w, u, p0)
    F = _model_at(mode["model"]["F"], v, w, u, p0)
    E = _model_at(d["model_error"]["E"], v, w)
    n, nw = A.shape[0], F.shape[1]
    Acl = np.block([[T @ A - K_P @ C, T @ F], [-K_I @ C, np.zeros((nw, nw))]])
    L = np.zeros((1, n + nw))
    L[0, 0] = -1.0
    Zw = np.zeros((1, n + nw))
    Zw[0, n] = 1.0
    Afr = Acl.copy()
    Afr[n:] = 0.0
    return {"Acl": Acl, "Fa": np.vstack([-T @ F, np.zeros((nw, nw))]), "La": L,
            "Ea": np.vstack([-T @ E, np.zeros((nw, E.shape[1]))]), "Z": np.vstack([Zw, L]),
            "Afr": Afr, "Ax": T @ A - K_P @ C}


def _mode_ranges_000(mode: dict):
    """(kind, lo, hi, ok) of the mode's model speed in m/s (fixed: lo = hi = the value); ok: finite
    and 0 < lo <= hi (otherwise every check of the mode fails)."""
    ms = mode["model_speed"]
    if ms["kind"] == "fixed":
        lo = hi = float(ms["value"])
    else:
        lo, hi = (float(x) for x in ms["range"])
    ok = math.isfinite(lo) and math.isfinite(hi) and 0 < lo <= hi
    return ("fixed" if ms["kind"] == "fixed" else "measured"), lo, hi, ok


def _analysis_000(d: dict) -> tuple[list[Check], dict]:
    """Checks and headline figures of a paper-000 design file (``docs/certificates.md``)."""
    checks: list[Check] = []
    T, N, C = (np.asarray(d["structure"][k], float) for k in ("T", "N", "C"))
    n = T.shape[0]
    P_stored = np.asarray(d["P"], float)
    P = _sym(P_stored)
    gamma = float(d["gamma"])
    me = d["model_error"]
    gamma2 = None if me.get("gamma") is None else float(me["gamma"])
    Wd, Wz = np.diag(np.asarray(me["input_weights"], float)), np.diag(np.asarray(me["output_weights"], float))
    a, R = float(d["region"]["alpha"]), float(d["region"]["radius"])
    opts = d["options"]
    faithful_tire = bool(opts.get("faithful")) and opts.get("switching") == "tire"
    freeze = bool((d.get("validity") or {}).get("freeze_integral", False))
    max_step = float(d["runtime"]["max_step"])
    kmh = lambda vx: f"{vx * 3.6:.4g} km/h"

    # -- structure and model ----------------------------------------------------------------
    checks.append(_le("T + N C = I (eq. 6)", np.max(np.abs(T + N @ C - np.eye(n))), 1e-12))
    sel = np.zeros((3, n))
    sel[0, 1] = sel[1, 2] = sel[2, 3] = 1.0
    checks.append(_le("C measures [r, phi, phidot] (y = x[1:]): max |C - selection|",
                      float(np.max(np.abs(C - sel))) if C.shape == sel.shape else math.inf, 0.0))
    vehicle = parse_vehicle(d["vehicle"], f"design file {d['name']}")
    relaxed = _first_power(d) == -1          # the model with relaxed axle forces (else eq. 1: certify checked)
    model_of = brm.relaxed_lpv_coefficients if relaxed else brm.lpv_coefficients
    model_err = 0.0
    for mode in d["modes"]:
        kf, kr = (float(k) for k in mode["stiffness_scale"])
        ref = model_of(vehicle, kf * vehicle.Cf, kr * vehicle.Cr)
        model_err = max(model_err, _rel_err(mode["Cf"], kf * vehicle.Cf), _rel_err(mode["Cr"], kr * vehicle.Cr))
        for key, mats in ref.items():
            if key == "first_power":
                continue
            stored = mode["model"][key]
            if len(stored) != len(mats):
                model_err = math.inf
                continue
            for S, M in zip(stored, mats):
                model_err = max(model_err, _rel_err(S, M))
    checks.append(_le("model equals the model re-derived from the vehicle parameters", model_err, 1e-12))
    E_ref = [np.vstack([E, np.zeros((n - E.shape[0], E.shape[1]))]) for E in _model_error_000(vehicle)]
    E_st = me["E"]
    e_err = max(_rel_err(s, r) for s, r in zip(E_st, E_ref)) if len(E_st) == 2 else math.inf
    checks.append(_le("model-error input E equals the certificate's own re-derivation from the vehicle parameters",
                      e_err, 1e-12))

    # -- LMI vertices: well formed, covering each mode's model speeds -----------------------------
    modes = {int(m["index"]): m for m in d["modes"]}
    verts = d["lmi_vertices"]
    coords = ("u", "v", "w") if relaxed else ("v", "w")
    bad = [x for x in verts if int(x["mode"]) not in modes
           or not all(math.isfinite(float(x.get(k, math.nan))) and float(x.get(k, math.nan)) > 0 for k in coords)]
    checks.append(_le(f"LMI vertices well formed: count naming no mode or with {', '.join(coords)} not finite > 0",
                      len(bad), 0))
    verts = [x for x in verts if x not in bad]
    for i, mode in modes.items():
        kind, lo, hi, ok = _mode_ranges_000(mode)
        pts = [(float(x["v"]), float(x["w"])) for x in verts if int(x["mode"]) == i]
        where = f"mode {i}"
        if not ok:
            checks.append(_le(f"model speed finite with 0 < lo <= hi (m/s), {where}", math.inf, 0.0, f"[{lo}, {hi}]"))
        elif kind == "fixed":
            v0 = 1.0 / lo
            dist = min((math.hypot(pv - v0, pw - v0 * v0) / v0 for pv, pw in pts), default=math.inf)
            checks.append(_le(f"an LMI vertex at the fixed model speed {kmh(lo)} (relative distance), {where}", dist, 1e-12))
        elif faithful_tire:
            # the paper's tire modes: LMIs at the grid speeds only, no polytope; between them the claim
            # is tested on the dense grid below (P decreases, H-inf <= gamma)
            dist = max(min((math.hypot(pv - v0, pw - v0 * v0) / v0 for pv, pw in pts), default=math.inf)
                       for v0 in (1.0 / hi, 1.0 / lo))
            checks.append(_le(f"LMI vertices at both ends {kmh(lo)}, {kmh(hi)} of the model-speed range (faithful "
                              f"tire mode: grid speeds only, in between see the dense grid), {where}", dist, 1e-12))
        elif relaxed:
            uv = [(float(x["u"]), float(x["v"])) for x in verts if int(x["mode"]) == i]
            out = _curve_outside_hull(uv, 1.0 / hi, 1.0 / lo, reciprocal=True)
            checks.append(_le(f"LMI vertices cover the model speeds: (Vx, 1/Vx) over {kmh(lo)}..{kmh(hi)} inside "
                              f"their convex hull (max distance outside), {where}", out, 1e-12,
                              f"{len(uv)} vertices; exact test per hull edge"))
        else:
            out = _curve_outside_hull(pts, 1.0 / hi, 1.0 / lo) * lo
            checks.append(_le(f"LMI vertices cover the model speeds: (1/Vx, 1/Vx^2) over {kmh(lo)}..{kmh(hi)} inside "
                              f"their convex hull (max distance outside x Vx_min), {where}", out, 1e-12,
                              f"{len(pts)} vertices; exact test per hull edge"))

    # -- the LMIs re-evaluated on the stored P, gamma(s) at every vertex --------------------------
    worst_vertex_rate = (math.inf, "")
    w_, U = np.linalg.eigh(P)
    Ph = (U * np.sqrt(np.abs(w_))) @ U.T
    Phi = (U / np.sqrt(np.abs(w_))) @ U.T if np.all(w_ > 0) else np.full_like(P, np.nan)

    def rate(Acl):
        """lambda with V' <= -lambda V (V = e'Pe): -max eig of P^-1/2 (Acl'P + P Acl) P^-1/2."""
        Ah = Ph @ Acl @ Phi
        return -float(np.max(np.linalg.eigvalsh(_sym(Ah + Ah.T)))) if np.all(np.isfinite(Ah)) else -math.inf
    for i, mode in modes.items():
        fam = {"LMI (20) bank -> beta error on the stored P, gamma": [], "alpha-stability LMI": [],
               "disk LMI": []}
        if gamma2 is not None:
            fam["model-error H-inf LMI on the stored P, gamma2"] = []
        for x in verts:
            if int(x["mode"]) != i:
                continue
            cl = closed_loop_000(d, mode, float(x["v"]), float(x["w"]), float(x["u"]) if relaxed else None)
            A, Fa, La = cl["Acl"], cl["Fa"], cl["La"]
            lyap = A.T @ P + P @ A
            nw = Fa.shape[1]
            m20 = np.block([[lyap, P @ Fa, La.T], [Fa.T @ P, -gamma**2 * np.eye(nw), np.zeros((nw, 1))],
                            [La, np.zeros((1, nw)), -np.eye(1)]])
            vals = [_neg_margin(m20), _neg_margin(lyap + 2 * a * P),
                    _neg_margin(np.block([[-R * P, P @ A], [A.T @ P, -R * P]]))]
            if gamma2 is not None:
                Ew, Zw = cl["Ea"] @ Wd, Wz @ cl["Z"]
                nd, nz = Ew.shape[1], Zw.shape[0]
                vals.append(_neg_margin(np.block([[lyap, P @ Ew, Zw.T], [Ew.T @ P, -gamma2**2 * np.eye(nd), np.zeros((nd, nz))],
                                                  [Zw, np.zeros((nz, nd)), -np.eye(nz)]])))
            for key, val in zip(fam, vals):
                fam[key].append((val, x["label"]))
            r = rate(A)
            if r < worst_vertex_rate[0]:
                worst_vertex_rate = (r, f"mode {i} at {x['label']}")
        for key, vals in fam.items():
            val, lab = max(vals, default=(math.inf, "no vertex"))
            checks.append(_le(f"{key}: max eig (Jacobi-scaled) over the vertices, mode {i}", val, 0.0,
                              f"worst at {lab}; {len(vals)} vertices"))

    # -- dense speed grid per mode (frozen speed) ----------------------------------------------------
    e_w = np.zeros((1, n + 1))
    e_w[0, -1] = 1.0
    figures = {"bands": []}
    worst_rate = worst_vertex_rate
    mu_all = (1.0, "", math.nan)
    for i, mode in modes.items():
        kind, lo, hi, ok = _mode_ranges_000(mode)
        grid = [] if not ok else [lo] if kind == "fixed" else sorted(
            set(np.linspace(lo, hi, GRID_000).tolist()) | {float(s) for s in mode["design_speeds"] if lo <= s <= hi})
        # worst value and where; no grid (invalid range): every check of the mode fails
        acc = {k: (-math.inf if grid else math.inf, None)
               for k in ("re", "mod", "lyap", "h1", "h2", "bank", "amp", "err", "xre")}
        mu_mode = (1.0, None, math.nan)
        for vx in grid:
            cl = closed_loop_000(d, mode, 1.0 / vx)
            A, Fa, La = cl["Acl"], cl["Fa"], cl["La"]
            if not np.all(np.isfinite(A)):
                for k in acc:
                    acc[k] = (math.inf, vx)
                continue
            lam = np.linalg.eigvals(A)
            vals = {"re": float(np.max(lam.real)), "mod": float(np.max(np.abs(lam))),
                    "lyap": _neg_margin(A.T @ P + P @ A)}
            stable = vals["re"] < 0
            vals["h1"] = hinf.hinf_norm(A, Fa, La).norm if stable else math.inf
            if gamma2 is not None:
                vals["h2"] = hinf.hinf_norm(A, cl["Ea"] @ Wd, Wz @ cl["Z"]).norm if stable else math.inf
            try:
                vals["bank"] = hinf.slowest_pole_seen_by(A, Fa, e_w)[0].real
            except ValueError:             # the bank does not reach its estimate
                vals["bank"] = math.inf
            z = max_step * lam
            amp, err = np.abs(_rk4_factor(z)), np.abs(_rk4_factor(z) - np.exp(z))
            if freeze:
                lx = np.linalg.eigvals(cl["Ax"])
                vals["xre"] = float(np.max(lx.real))
                zx = max_step * lx
                amp = np.concatenate([amp, np.abs(_rk4_factor(zx))])
                err = np.concatenate([err, np.abs(_rk4_factor(zx) - np.exp(zx))])
                if vals["xre"] < 0 and np.all(np.isfinite(Phi)):
                    mu, t_mu = _growth_factor(Ph @ cl["Afr"] @ Phi)
                else:
                    mu, t_mu = math.inf, math.nan
                if not mu <= mu_mode[0]:
                    mu_mode = (mu, vx, t_mu)
            vals["amp"], vals["err"] = float(np.max(amp)), float(np.max(err))
            for k, val in vals.items():
                if not val <= acc[k][0]:
                    acc[k] = (val, vx)
            r = rate(A)
            if r < worst_rate[0]:
                worst_rate = (r, f"mode {i} at {kmh(vx)}")
        at = lambda k: f"worst at {kmh(acc[k][1])}" if acc[k][1] is not None else "not evaluated"
        span = (f"{kmh(lo)}" if kind == "fixed" else f"{len(grid)} speeds over {kmh(lo)}..{kmh(hi)}")
        where = f"dense grid ({span}), mode {i}"
        checks.append(_le(f"pole region: max Re(eig) <= -alpha, {where}", acc["re"][0], -a,
                          f"{at('re')}; slowest pole seen by the bank estimate {acc['bank'][0]:.4g} 1/s "
                          f"(at {kmh(acc['bank'][1]) if acc['bank'][1] is not None else '-'})"))
        checks.append(_le(f"pole region: max |eig| <= radius, {where}", acc["mod"][0], R, at("mod")))
        checks.append(_le(f"common P decreases: max eig (Jacobi-scaled) of Acl'P + P Acl, {where}", acc["lyap"][0], 0.0,
                          at("lyap")))
        checks.append(_le(f"H-inf bank->beta error (Hamiltonian) <= gamma: gamma of the band, {where}", acc["h1"][0],
                          gamma * (1 + REL_TOL), at("h1")))
        # cross-check of the Hamiltonian by a frequency sweep where each channel is worst
        gap = 0.0
        for k in ("h1", "h2"):
            val, vx = acc[k]
            if vx is None or not math.isfinite(val):
                gap = math.inf if vx is not None else gap
                continue
            cl = closed_loop_000(d, mode, 1.0 / vx)
            B, Cz = (cl["Fa"], cl["La"]) if k == "h1" else (cl["Ea"] @ Wd, Wz @ cl["Z"])
            sweep, _ = hinf.frequency_sweep_peak(cl["Acl"], B, Cz)
            gap = max(gap, abs(val - sweep) / max(val, 1e-300))
        checks.append(_le(f"Hamiltonian and frequency sweep agree at the worst speed of each channel, {where}", gap, 1e-3))
        if gamma2 is not None:
            checks.append(_le(f"H-inf weighted model error -> [bank, beta] errors (Hamiltonian) <= gamma2: gamma2 of the "
                              f"band, {where}", acc["h2"][0], gamma2 * (1 + REL_TOL), at("h2")))
        rk = "closed loops and frozen x~-blocks" if freeze else "closed loops"
        checks.append(_le(f"runtime RK4 step {max_step * 1e3:.3g} ms stable (max |R(h lambda)|, {rk}), {where}",
                          acc["amp"][0], 1.0 - 1e-9, at("amp")))
        checks.append(_le(f"runtime RK4 one-step error |R(h lambda) - exp(h lambda)| ({rk}), {where}", acc["err"][0],
                          1e-6, at("err")))
        if freeze:
            checks.append(_le(f"frozen integral: x~-block T A - K_P C Hurwitz (max Re eig), {where}", acc["xre"][0],
                              -1e-9, at("xre")))
            if not mu_mode[0] <= mu_all[0]:
                mu_all = (mu_mode[0], f"mode {i} at {kmh(mu_mode[1])}" if mu_mode[1] is not None else "", mu_mode[2])
        figures["bands"].append({"mode": i, "label": mode["label"], "model_speed": kind,
                                 "range_kmh": [round(lo * 3.6, 4), round(hi * 3.6, 4)], "speeds": len(grid),
                                 "gamma_band": acc["h1"][0],
                                 "gamma_band_at_kmh": None if acc["h1"][1] is None else round(acc["h1"][1] * 3.6, 4),
                                 "gamma2_band": acc["h2"][0] if gamma2 is not None else None,
                                 "slowest_bank_pole": acc["bank"][0],
                                 "mu": mu_mode[0] if freeze else None})

    # -- decay rate of V, frozen-integral growth factor, dwell time -----------------------------------
    lam_v, lam_at = worst_rate
    frozen = None
    if freeze:
        mu, mu_at, t_mu = mu_all
        tau = math.log(mu) / lam_v if (math.isfinite(mu) and lam_v > 0) else math.inf
        frozen = {"mu": mu, "mu_at": mu_at, "t_peak_s": t_mu, "lambda": lam_v, "lambda_at": lam_at, "tau_s": tau}
        checks.append(_le("frozen integral: growth factor mu = sup_t ||P^1/2 exp(A_fr t) P^-1/2||^2 finite (max over "
                          "modes and the dense grid)", mu, 1e6,
                          f"worst at {mu_at} (peak at t = {t_mu:.3g} s); decay rate of V = e'Pe under the full "
                          f"loop lambda = {lam_v:.4g} 1/s (min over the vertices and the dense grid, at {lam_at}): every "
                          f"freeze followed by a valid interval of at least tau = ln(mu)/lambda = {tau:.4g} s ends "
                          f"with V no larger than at the freeze's start (constant bank, no mode/speed change during "
                          f"the freeze)"))

    # -- gains and P ---------------------------------------------------------------------------------
    gains = max(max(np.max(np.abs(np.asarray(m["gains"]["K_P"]))), np.max(np.abs(np.asarray(m["gains"]["K_I"]))))
                for m in d["modes"])
    checks.append(_le("largest gain entry", gains, opts.get("gain_limit", 1e4)))
    checks.append(_le("cond(P)", np.linalg.cond(P), opts.get("cond_limit", 1e7)))
    checks.append(_le("P symmetric as stored: max |P - P'| / max |P|",
                      float(np.max(np.abs(P_stored - P_stored.T)) / max(np.max(np.abs(P_stored)), 1e-300)), 1e-12))
    checks.append(_ge("P positive definite: min eig(P) / max eig(P)", float(w_[0] / w_[-1]), 1e-12))
    figures.update(gamma=gamma, gamma_model_error=gamma2, frozen_integral=frozen, decay_rate=lam_v,
                   cond_P=float(np.linalg.cond(P)))
    if "robust_h2" in d:
        h2_checks, figures["robust_h2"] = _robust_h2_000(d, vehicle, modes, verts)
        checks += h2_checks
    return checks, figures


def robust_system_000(d: dict, mode: dict, car: dict, v: float, w: float | None = None, u: float | None = None):
    """The certificate's own [x; e_a] system of the robust-H2 criterion for ``mode`` (its gains) and the
    car ``car`` (1/Vx coefficients at the car's stiffnesses), at (u, v, w) = (Vx, 1/Vx, 1/Vx^2), from the
    design file's numbers: the car x' = A_t x + B_t delta; the observer's error e_a = [T x - z; phi_r - w^]
    (eq. 19) with y = C x + n and the bank's rate omega:
        e_a' = A_cl e_a + [T (A_t - A); 0] x + [T (B_t - B); 0] delta + [0; 1] omega
               - ([T A N; 0] + K_a (I - C N)) n
    (the observer's z' = T (A x^ + B delta + F w^) + K_P (y - C x^), x^ = z + N y, w^' = K_I (y - C x^)
    subtracted from T x'); inputs weighted by robust_h2.input_weights, outputs [e_a[0];
    bank_weight e_a[4]]. Returns (A, B, C_z)."""
    w = v * v if w is None else w
    h = d["robust_h2"]
    T, N, C = (np.asarray(d["structure"][k], float) for k in ("T", "N", "C"))
    wd, wo, *wn = (float(x) for x in h["input_weights"])
    Wn = np.diag(wn)
    p0 = _first_power(d)
    A, B = _model_at(mode["model"]["A"], v, w, u, p0), _model_at(mode["model"]["B"], v, w, u, p0)
    At, Bt = _model_at(car["A"], v, w, u, p0), _model_at(car["B"], v, w, u, p0)
    Acl = closed_loop_000(d, mode, v, w, u)["Acl"]
    Ka = np.vstack([np.asarray(mode["gains"]["K_P"], float), np.asarray(mode["gains"]["K_I"], float)])
    n, ny = At.shape[0], C.shape[0]
    e_top = lambda M: np.vstack([M, np.zeros((1, M.shape[1]))])
    Abig = np.block([[At, np.zeros((n, n + 1))], [e_top(T @ (At - A)), Acl]])
    omega = np.zeros((n + 1, 1))
    omega[n, 0] = wo
    Bbig = np.block([[Bt * wd, np.zeros((n, 1 + ny))],
                     [e_top(T @ (Bt - B)) * wd, omega, -e_top(T @ A @ N) @ Wn - Ka @ (np.eye(ny) - C @ N) @ Wn]])
    Cz = np.zeros((2, 2 * n + 1))
    Cz[0, n] = 1.0
    Cz[1, 2 * n] = float(h["bank_weight"])
    return Abig, Bbig, Cz


def _h2_norm(A: np.ndarray, B: np.ndarray, Cz: np.ndarray) -> tuple[float, float]:
    """H2 norm of (A, B, Cz) (A Hurwitz) twice: from the controllability and the observability
    Gramian (two Lyapunov equations); inf if A is not Hurwitz."""
    import scipy.linalg

    if not np.max(np.linalg.eigvals(A).real) < 0:
        return math.inf, math.inf
    Wc = scipy.linalg.solve_continuous_lyapunov(A, -B @ B.T)
    Wo = scipy.linalg.solve_continuous_lyapunov(A.T, -Cz.T @ Cz)
    return (math.sqrt(max(float(np.trace(Cz @ Wc @ Cz.T)), 0.0)), math.sqrt(max(float(np.trace(B.T @ Wo @ B)), 0.0)))


def _robust_h2_000(d: dict, vehicle, modes: dict, verts: list) -> tuple[list[Check], dict]:
    """Checks of the robust-H2 section (``docs/certificates.md``): the stored corners are the box's; at every
    LMI vertex and stiffness corner, the Lyapunov LMI on diag(P_car, P_err) and trace(B' diag(P_car, P_err) B) <= bound^2
    (both affine in the car and the speed, so they hold on the whole box and speed polytope); on the dense grid
    (frozen speeds x the corners and the box's centre), the frozen H2 norm from two Gramians <= bound."""
    h = d["robust_h2"]
    checks: list[Check] = []
    bound = float(h["bound"])
    lo, hi = (float(x) for x in h["stiffness_box"])
    box_ok = math.isfinite(lo) and math.isfinite(hi) and 0 < lo <= 1 <= hi
    corners = sorted({(a, b) for a in (lo, hi) for b in (lo, hi)}) if box_ok else []
    stored = sorted(tuple(float(x) for x in c) for c in h["stiffness_corners"])
    checks.append(_le("robust H2: stored stiffness corners are the corners of the box (count differing)",
                      len(set(stored) ^ set(corners)) if box_ok else math.inf, 0, f"box {h['stiffness_box']}"))
    # P_car: common to the modes, or one per mode (the model with relaxed forces: its rate Vx / sigma)
    P_cars, P_err = np.asarray(h["P_car"], float), _sym(np.asarray(h["P_err"], float))
    P_cars = P_cars[None] if P_cars.ndim == 2 else P_cars
    relaxed = _first_power(d) == -1
    model_of = brm.relaxed_lpv_coefficients if relaxed else brm.lpv_coefficients

    def pbig(i: int) -> np.ndarray:
        P_car = _sym(P_cars[min(i - 1, len(P_cars) - 1)])
        n = P_car.shape[0]
        return np.block([[P_car, np.zeros((n, P_err.shape[0]))], [np.zeros((P_err.shape[0], n)), P_err]])
    per_mode = len(P_cars) == len(modes) or len(P_cars) == 1
    ratio = min(float(e[0] / e[-1]) for e in (np.linalg.eigvalsh(pbig(i)) for i in modes)) if per_mode else -math.inf
    checks.append(_ge("robust H2: diag(P_car, P_err) positive definite (min eig / max eig)", ratio, 1e-12,
                      f"{len(P_cars)} P_car" + ("" if per_mode else f" for {len(modes)} modes: neither one nor one per mode")))
    worst = (0.0, "")                      # the largest frozen H2 norm over the modes, and where
    for i, mode in modes.items():
        Pbig = pbig(i)
        cars = {c: model_of(vehicle, c[0] * vehicle.Cf * float(mode["stiffness_scale"][0]),
                            c[1] * vehicle.Cr * float(mode["stiffness_scale"][1]))
                for c in corners + [(1.0, 1.0)]}
        lyap, trace = (-math.inf, ""), (-math.inf, "")
        for x in (x for x in verts if int(x["mode"]) == i):
            for c in corners:
                A, B, Cz = robust_system_000(d, mode, cars[c], float(x["v"]), float(x["w"]),
                                             float(x["u"]) if relaxed else None)
                where = f"{x['label']}, stiffness x {c}"
                val = _neg_margin(Pbig @ A + A.T @ Pbig + Cz.T @ Cz)
                if not val <= lyap[0]:
                    lyap = (val, where)
                tr = float(np.trace(B.T @ Pbig @ B))
                if not tr <= trace[0]:
                    trace = (tr, where)
        checks.append(_le(f"robust H2 Lyapunov LMI He(P A) + Cz'Cz < 0 on diag(P_car, P_err): max eig (Jacobi-scaled) over "
                          f"the vertices x corners, mode {i}", lyap[0] if corners else math.inf, 0.0, f"worst at {lyap[1]}"))
        checks.append(_le(f"robust H2 bound: max trace(B' diag(P_car, P_err) B) over the vertices x corners <= bound^2, mode {i}",
                          trace[0] if corners else math.inf, bound**2 * (1 + REL_TOL), f"worst at {trace[1]}"))
        kind, vlo, vhi, ok = _mode_ranges_000(mode)
        grid = np.linspace(vlo, vhi, 9) if ok else []
        gap, frozen = 0.0, (-math.inf, "")
        for vx in grid:
            for c in corners + [(1.0, 1.0)]:
                n1, n2 = _h2_norm(*robust_system_000(d, mode, cars[c], 1.0 / vx))
                gap = max(gap, abs(n1 - n2) / max(n1, 1e-300)) if math.isfinite(n1) else math.inf
                if not n1 <= frozen[0]:
                    frozen = (n1, f"{vx * 3.6:.4g} km/h, stiffness x {c}")
        checks.append(_le(f"robust H2: frozen H2 norm (controllability Gramian) <= bound on the dense grid "
                          f"({len(grid)} speeds x {len(corners) + 1} cars), mode {i}", frozen[0] if len(grid) else math.inf,
                          bound * (1 + REL_TOL), f"worst at {frozen[1]}"))
        checks.append(_le(f"robust H2: the two Gramians' H2 norms agree (relative difference), mode {i}", gap, 1e-6))
        if frozen[0] > worst[0]:
            worst = (frozen[0], f"mode {i} at {frozen[1]}")
    return checks, {"bound": bound, "worst_frozen_norm": worst[0], "worst_frozen_at": worst[1]}


_ANALYSES_000: dict = {}    # fingerprint of a design dict -> (checks, figures), for ``summary`` only


def _fingerprint_000(d: dict) -> str:
    import hashlib
    import json

    body = {k: v for k, v in d.items() if k not in ("checks", "certified")}
    text = json.dumps(body, sort_keys=True, default=lambda o: o.tolist() if hasattr(o, "tolist") else repr(o))
    return hashlib.sha256(text.encode()).hexdigest()


def _size_errors(d: dict) -> list[str]:
    """What does not have the size of the file's model (eq. 1, or with relaxed axle forces when
    structure.first_power is -1), re-derived from its vehicle: each mode's coefficient lists, gains,
    P; an empty list when all fit."""
    p0 = d["structure"].get("first_power", 0)
    if p0 not in (0, -1) or isinstance(p0, bool):
        return [f"structure.first_power {p0!r} is neither 0 nor -1"]
    try:
        vehicle = parse_vehicle(d["vehicle"], f"design file {d.get('name')}")
        ref = (brm.relaxed_lpv_coefficients if p0 == -1 else brm.lpv_coefficients)(vehicle)
    except ValueError as exc:
        return [str(exc)]
    n = ref["A"][0].shape[0]
    wrong = []
    for m in d["modes"]:
        for key in ("A", "B", "F"):
            got, want = [np.shape(M) for M in m["model"][key]], [M.shape for M in ref[key]]
            if got != want:
                wrong.append(f"mode {m.get('index')} model {key}: {got}, the model's {want}")
        for key, shape in (("K_P", (n, 3)), ("K_I", (1, 3))):
            if np.shape(m["gains"][key]) != shape:
                wrong.append(f"mode {m.get('index')} {key}: {np.shape(m['gains'][key])}, not {shape}")
    for what, got, shape in (("T", d["structure"]["T"], (n, n)), ("C", d["structure"]["C"], (3, n)),
                             ("P", d["P"], (n + 1, n + 1))):
        if np.shape(got) != shape:
            wrong.append(f"{what}: {np.shape(got)}, not {shape}")
    return wrong


def certify(d: dict) -> list[Check]:
    """Always computed afresh; the result is remembered for ``summary`` of the same numbers (the
    pipeline summarises right after certifying: the analysis takes ~1 s)."""
    missing = [k for k in ("vehicle", "options", "structure", "modes", "gamma", "model_error", "lmi_vertices",
                           "region", "P", "runtime") if k not in d]
    if missing:                         # e.g. an old file without model_error and lmi_vertices
        return [_le("design file has every section the certificate reads (count missing)", len(missing), 0,
                    "missing: " + ", ".join(missing))]
    wrong = _size_errors(d)
    if wrong:                           # e.g. a model of one kind read as the other's (first_power)
        return [_le("design file's matrices have the sizes of its model (count wrong)", len(wrong), 0,
                    "; ".join(wrong[:5]))]
    checks, figures = _analysis_000(d)
    if len(_ANALYSES_000) >= 16:
        _ANALYSES_000.clear()
    _ANALYSES_000[_fingerprint_000(d)] = (checks, figures)
    return checks


def summary(data: dict) -> dict:
    """Headline figures of a certified design (for notes and reports)."""
    # paper 000: the figures of the certificate's analysis (dense grid, frozen integral) and, per
    # design speed, the frozen-speed H-infinity norms of the certificate's own closed loop
    key = _fingerprint_000(data)
    _checks, fig = _ANALYSES_000.get(key) or _analysis_000(data)
    bands = {b["mode"]: b for b in fig["bands"]}
    me = data["model_error"]
    Wd, Wz = np.diag(np.asarray(me["input_weights"], float)), np.diag(np.asarray(me["output_weights"], float))
    out = {"gamma": data["gamma"], "gamma_model_error": fig["gamma_model_error"], "per_mode": [],
           "bands": fig["bands"], "decay_rate": fig["decay_rate"], "frozen_integral": fig["frozen_integral"]}
    for mode in data["modes"]:
        K_P, K_I = np.asarray(mode["gains"]["K_P"]), np.asarray(mode["gains"]["K_I"])
        band = bands[int(mode["index"])]
        for v in mode["design_speeds"]:
            cl = closed_loop_000(data, mode, 1.0 / v)
            A = cl["Acl"]
            e_w = np.zeros((1, A.shape[0])); e_w[0, -1] = 1.0
            out["per_mode"].append({
                "mode": mode["index"], "label": mode["label"], "speed_kmh": round(v * 3.6, 3),
                "hinf": hinf.hinf_norm(A, cl["Fa"], cl["La"]).norm,
                "hinf_model_error": (hinf.hinf_norm(A, cl["Ea"] @ Wd, Wz @ cl["Z"]).norm
                                     if fig["gamma_model_error"] is not None else None),
                "slowest_bank_pole": hinf.slowest_pole_seen_by(A, cl["Fa"], e_w)[0].real,
                "slowest_pole": float(np.max(np.linalg.eigvals(A).real)),
                "largest_gain": float(max(np.max(np.abs(K_P)), np.max(np.abs(K_I)))),
                "band_kmh": band["range_kmh"], "gamma_band": band["gamma_band"], "gamma2_band": band["gamma2_band"],
            })
    out["cond_P"] = fig["cond_P"]
    if "robust_h2" in fig:
        out["robust_h2"] = fig["robust_h2"]
    return out
