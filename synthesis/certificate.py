"""Independent certificate of a design file: numpy/scipy only, never the LMI solver.

A certificate re-evaluates the numbers that will be packaged (the design file's model
coefficients and gains), not the solver's internal state. A design whose certificate fails is
never packaged (``latobs.packaging`` re-runs it).

Paper 000 (``_certify_000``, switched H-infinity PI observer with a common P). The closed loop of
eq. (19) is rebuilt here from the file's own numbers (``closed_loop_000``: T, C, the mode's model
coefficients, K_P, K_I, model_error.E; nothing from the design module), error e = [x~; phi_r - w^]:
  * the stored model equals its re-derivation from the vehicle parameters (``bicycle_roll_model``);
    the model-error input E equals the certificate's own derivation (``_model_error_000``); C
    measures [r, phi, phidot]; T + N C = I;
  * coverage: a mode whose model runs at the measured speed (clamped to [lo, hi]) has LMI vertices
    (d["lmi_vertices"]) whose convex hull holds the arc (1/Vx, 1/Vx^2), Vx in [lo, hi] (exact, per
    hull edge); a fixed model speed is a vertex. Exception, the faithful tire modes (the paper's
    LMIs at the grid speeds only): both ends of the range must be vertices, and between them the
    claim is tested on the dense grid (below), not proved;
  * at every vertex, on the stored P, gamma and gamma2: LMI (20), alpha-stability, disk and (gamma2
    given) the model-error H-infinity LMI, each negative definite (largest eigenvalue after a
    Jacobi congruence, sign-invariant). Every block is affine in (v, w) = (1/Vx, 1/Vx^2), so for a
    covered mode they prove both H-infinity bounds, the pole region and V' <= -lambda V on its
    whole range, for any switching and any time-varying speed (linear model);
  * dense grid per mode, frozen speed (41 speeds over a measured range plus the design speeds; the
    model speed of a fixed mode): eigenvalues in the region (and the slowest pole seen by the bank
    estimate), the common P decreasing, both H-infinity norms by Hamiltonian bisection (``hinf.py``,
    no P) <= gamma, gamma2, cross-checked by a frequency sweep where each is worst, the runtime's
    RK4 step (stable and accurate on the closed loops and the frozen x~-blocks). The worst norm of
    each channel over a mode's grid is its "gamma per band" (``summary``). For covered modes this
    re-checks numerically what the vertices prove; for the faithful tire modes it is the test;
  * frozen integral (validity.freeze_integral: while not valid the runtime holds w^; A_fr = A_cl
    with its last row zero): the x~-block T A - K_P C Hurwitz on the grid, the growth factor
    mu = sup_t ||P^1/2 exp(A_fr t) P^-1/2||^2 (max over the modes and the grid; per point sampled on
    a log time grid until exp(A_fr t) has converged, refined at its peak: a computed value, not an
    enclosure) and the decay rate lambda = min over the vertices and the grid of
    -max eig(P^-1/2 (A_cl'P + P A_cl) P^-1/2) (for covered modes the vertices' minimum holds on the
    whole hull: the eigenvalue is convex in (v, w)). Proved, for the linear model, a constant bank
    (then e' = A_cl e while valid, e' = A_fr e while frozen) and mu as computed: a freeze multiplies
    V = e'Pe by at most mu whatever its length, valid time by at most exp(-lambda t) (any switching
    and speed variation inside covered modes), so every freeze followed by a valid interval of at
    least tau = ln(mu)/lambda ends with V no larger than at the freeze's start (smaller by a fixed
    factor per cycle if longer: V -> 0); with a varying bank or model error the same per-cycle
    contraction keeps the error bounded (not quantified here). Not proved: a mode or speed change
    during a freeze (mu is per frozen mode and speed; between grid speeds sampled), the faithful
    tire modes between grid speeds, the nonlinear vehicle;
  * largest gain, cond(P), P symmetric as stored (the runtime never reads P and the proofs use its
    symmetric part: an asymmetric P means the file was altered), P positive definite.
  Not checks, because they cannot fail on their own: the slowest bank pole against -alpha (one of
  the eigenvalues the pole-region check bounds), lambda > 0 (the same statement as "P decreases"
  and the alpha-stability LMI); both are reported in the details and the summary.

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
    from .table_checks import checks as table_checks
    checks = checks + table_checks(data)      # the runtime's tables, checked independently
    return all(c.passed for c in checks) and bool(checks), checks


# -- paper 000: switched H-infinity PI observer, common P ---------------------------------------
GRID_000 = 41           # speeds of the dense grid over each measured model-speed range


def _sym(M: np.ndarray) -> np.ndarray:
    return (M + M.T) / 2


def _neg_margin(M: np.ndarray) -> float:
    """Largest eigenvalue of the symmetric part of M after the congruence D M D, D = diag(|M_ii|^-1/2)
    (Jacobi scaling): by Sylvester's law of inertia M < 0 iff this value < 0, and the scaled matrix
    has unit diagonal, so the value is dimensionless (in (-1, 0) for a negative definite M) and its
    sign is not at the mercy of the LMI's units. A diagonal entry >= 0 already disproves M < 0:
    then the unscaled largest eigenvalue (>= 0) is returned."""
    M = _sym(np.asarray(M, float))
    if not np.all(np.isfinite(M)):
        return math.inf
    dg = np.diag(M)
    if np.any(dg >= 0):
        return float(np.max(np.linalg.eigvalsh(M)))
    s = 1.0 / np.sqrt(-dg)
    return float(np.max(np.linalg.eigvalsh(M * s[:, None] * s[None, :])))


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
    from .params import G

    p = vehicle.require(("m", "Iz", "Ix", "lf", "lr", "hr"), "the certificate's model-error input")
    m, Iz, Ix, lf, lr, hr = (p[k] for k in ("m", "Iz", "Ix", "lf", "lr", "hr"))
    Mq = np.array([[m, 0.0, -m * hr], [0.0, Iz, 0.0], [0.0, 0.0, Ix]])
    Q = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [hr, 0.0, 1.0]]) * np.array([m, m * (lf + lr), m * hr]) * G
    a = np.linalg.solve(Mq, Q)
    E0, E1 = np.zeros((4, 3)), np.zeros((4, 3))
    E1[0] = a[0]
    E0[1], E0[3] = a[1], a[2]
    return [E0, E1]


def _model_at(coeffs, v: float, w: float) -> np.ndarray:
    """sum_k M_k basis_k with basis (1, v, w) (w stands for 1/Vx^2, off the curve at tangent corners);
    degrees > 2 (never in a valid file) as v**k."""
    basis = [1.0, v, w]
    return sum(np.asarray(M, float) * (basis[k] if k < 3 else v**k) for k, M in enumerate(coeffs))


def closed_loop_000(d: dict, mode: dict, v: float, w: float | None = None) -> dict:
    """The certificate's own closed loop of eq. (19) for ``mode`` (an entry of d["modes"]) with its
    model at (v, w) = (1/Vx, 1/Vx^2) (w given: a polytope vertex), from the design file's numbers
    only (T, C, the mode's model coefficients and gains, model_error.E):
        A_cl = [[T A - K_P C, T F], [-K_I C, 0]]   (= A_a - K_a C_a, A_a = [[T A, T F], [0, 0]])
        F_a = [-T F; 0], L_a = [-L, 0], L = [1 0 0 0]          channel 1: bank -> beta error
        E_a = [-T E; 0], Z = [[0 0 0 0 1]; L_a]                 channel 2 (unweighted)
        A_fr = A_cl with its last row zero                      integral action frozen
    The error state is e = [x~; phi_r - w^] (constant bank: e' = A_cl e)."""
    w = v * v if w is None else w
    T, C = (np.asarray(d["structure"][k], float) for k in ("T", "C"))
    K_P, K_I = (np.asarray(mode["gains"][k], float) for k in ("K_P", "K_I"))
    A = _model_at(mode["model"]["A"], v, w)
    F = _model_at(mode["model"]["F"], v, w)
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


def _hull_2d(points) -> list[tuple[float, float]]:
    """Convex hull (Andrew's monotone chain), counter-clockwise, collinear points dropped."""
    pts = sorted(set(points))
    if len(pts) < 3:
        return pts

    def cross(o, a, b):
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
    lower, upper = [], []
    for p in pts:
        while len(lower) >= 2 and cross(lower[-2], lower[-1], p) <= 0:
            lower.pop()
        lower.append(p)
    for p in reversed(pts):
        while len(upper) >= 2 and cross(upper[-2], upper[-1], p) <= 0:
            upper.pop()
        upper.append(p)
    return lower[:-1] + upper[:-1]


def _curve_outside_hull(points, v_lo: float, v_hi: float) -> float:
    """max over v in [v_lo, v_hi] of the distance of (v, v^2) outside the convex hull of ``points``
    (<= 0: the whole arc is inside), exactly: for each hull edge with outward unit normal (a, b)
    through p, a (v - p_v) + b (v^2 - p_w) is a quadratic in v maximised at an end or its vertex.
    A degenerate hull (fewer than 3 points not on a line) holds no arc: inf."""
    hull = _hull_2d([(float(p[0]), float(p[1])) for p in points])
    if len(hull) < 3:
        return math.inf
    worst = -math.inf
    for p, q in zip(hull, hull[1:] + hull[:1]):
        a, b = q[1] - p[1], -(q[0] - p[0])           # outward normal of a counter-clockwise edge
        nrm = math.hypot(a, b)
        a, b = a / nrm, b / nrm
        cand = [v_lo, v_hi]
        if b < 0:                                    # concave quadratic: interior maximum
            vs = -a / (2 * b)
            if v_lo < vs < v_hi:
                cand.append(vs)
        worst = max(worst, max(a * (v - p[0]) + b * (v * v - p[1]) for v in cand))
    return worst


def _growth_factor(Ah: np.ndarray) -> tuple[float, float]:
    """(mu, t*) with mu = sup_{t >= 0} ||exp(Ah t)||_2^2 for Ah = P^1/2 A_fr P^-1/2 (A_fr: one zero
    eigenvalue, the others Re < 0, so exp(Ah t) converges to the spectral projector of 0): sampled
    on 400 log-spaced times from 1e-3/|lambda|max to 60/|Re lambda|min (where the transient has
    decayed below e^-60), the largest sample refined by bounded Brent on log t, and the limit
    t -> inf included; inf when a non-zero eigenvalue has Re >= 0 or the samples do not converge."""
    import scipy.linalg
    from scipy.optimize import minimize_scalar

    if not np.all(np.isfinite(Ah)):
        return math.inf, math.nan
    lam, V = np.linalg.eig(Ah)
    k0 = int(np.argmin(np.abs(lam)))
    rest = np.delete(lam, k0)
    if np.max(rest.real) >= 0:
        return math.inf, math.nan
    fast, slow = float(np.max(np.abs(rest))), float(-np.max(rest.real))
    if np.linalg.cond(V) < 1e8:                      # modal form: exp(Ah t) = V exp(lambda t) V^-1
        Vi = np.linalg.inv(V)
        lam = lam.copy()
        lam[k0] = 0.0                                # exactly 0 (the last row of A_fr is zero)
        limit = float(np.linalg.norm(np.outer(V[:, k0], Vi[k0]), 2))

        def norms(ts):                               # ||M||_2 = sqrt(max eig M'M), M real
            Ms = np.einsum("ij,tj,jk->tik", V, np.exp(np.outer(ts, lam)), Vi).real
            return np.sqrt(np.maximum(np.linalg.eigvalsh(np.einsum("tji,tjk->tik", Ms, Ms))[:, -1], 0.0))
    else:                                            # (nearly) defective: scipy's expm per time
        def norms(ts):
            return np.array([np.linalg.norm(scipy.linalg.expm(Ah * t), 2) for t in ts])
        limit = float(norms([200.0 / slow])[0])
    ts = np.logspace(math.log10(1e-3 / fast), math.log10(60.0 / slow), 400)
    g = norms(ts)
    if abs(g[-1] - limit) > 1e-9 * max(limit, 1.0):
        return math.inf, math.nan
    i = int(np.argmax(g))
    best, t_best = float(g[i]), float(ts[i])
    lo, hi = math.log(ts[max(i - 1, 0)]), math.log(ts[min(i + 1, len(ts) - 1)])
    if hi > lo:
        res = minimize_scalar(lambda s: -norms(np.array([math.exp(s)]))[0], bounds=(lo, hi), method="bounded",
                              options={"xatol": 1e-10})
        if -res.fun > best:
            best, t_best = float(-res.fun), float(math.exp(res.x))
    return max(best, limit, 1.0) ** 2, t_best


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
    """Checks and headline figures of a paper-000 design file (see the module docstring)."""
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
    model_err = 0.0
    for mode in d["modes"]:
        kf, kr = (float(k) for k in mode["stiffness_scale"])
        ref = brm.lpv_coefficients(vehicle, kf * vehicle.Cf, kr * vehicle.Cr)
        model_err = max(model_err, _rel_err(mode["Cf"], kf * vehicle.Cf), _rel_err(mode["Cr"], kr * vehicle.Cr))
        for key, mats in ref.items():
            stored = mode["model"][key]
            if len(stored) != len(mats):
                model_err = math.inf
                continue
            for S, M in zip(stored, mats):
                model_err = max(model_err, _rel_err(S, M))
    checks.append(_le("model equals the model re-derived from the vehicle parameters", model_err, 1e-12))
    E_ref = _model_error_000(vehicle)
    E_st = me["E"]
    e_err = max(_rel_err(s, r) for s, r in zip(E_st, E_ref)) if len(E_st) == 2 else math.inf
    checks.append(_le("model-error input E equals the certificate's own re-derivation from the vehicle parameters",
                      e_err, 1e-12))

    # -- LMI vertices: well formed, covering each mode's model speeds -----------------------------
    modes = {int(m["index"]): m for m in d["modes"]}
    verts = d["lmi_vertices"]
    bad = [x for x in verts if int(x["mode"]) not in modes
           or not (math.isfinite(float(x["v"])) and math.isfinite(float(x["w"])) and float(x["v"]) > 0 and float(x["w"]) > 0)]
    checks.append(_le("LMI vertices well formed: count naming no mode or with v, w not finite > 0", len(bad), 0))
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
            cl = closed_loop_000(d, mode, float(x["v"]), float(x["w"]))
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
    return checks, figures


_ANALYSES_000: dict = {}    # fingerprint of a design dict -> (checks, figures), for ``summary`` only


def _fingerprint_000(d: dict) -> str:
    import hashlib
    import json

    body = {k: v for k, v in d.items() if k not in ("checks", "certified")}
    text = json.dumps(body, sort_keys=True, default=lambda o: o.tolist() if hasattr(o, "tolist") else repr(o))
    return hashlib.sha256(text.encode()).hexdigest()


def _certify_000(d: dict) -> list[Check]:
    """Always computed afresh; the result is remembered for ``summary`` of the same numbers (the
    pipeline summarises right after certifying: the analysis takes ~1 s)."""
    missing = [k for k in ("vehicle", "options", "structure", "modes", "gamma", "model_error", "lmi_vertices",
                           "region", "P", "runtime") if k not in d]
    if missing:                         # e.g. a file written before issue 9 (no model_error, lmi_vertices)
        return [_le("design file has every section the certificate reads (count missing)", len(missing), 0,
                    "missing: " + ", ".join(missing))]
    checks, figures = _analysis_000(d)
    if len(_ANALYSES_000) >= 16:
        _ANALYSES_000.clear()
    _ANALYSES_000[_fingerprint_000(d)] = (checks, figures)
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

    from ..fmu_src.kalman_observer import KalmanObserver
    from ..fmu_src.kalman_observer import _expm as _expm3
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
    vehicle = parse_vehicle(d["vehicle"], f"design file {d['name']}")
    par = vehicle.require(("m", "Iz", "lf", "lr"), f"certificate of {d['name']} (bicycle model, eq. 2)")
    model = d.get("model", {})
    checks.append(_le("bicycle model m, Iz, lf, lr = the design file's vehicle (max relative difference)",
                      max(abs(float(model.get(k, math.nan)) - par[k]) / par[k] for k in par)
                      if all(k in model for k in par) else math.inf, 1e-9))
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
    return out
