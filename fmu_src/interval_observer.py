"""Runtime of the switched interval observer of paper 001 (Ifqir, Ichalal, Ait-Oufroukh, Mammar,
ACC 2020), eq. (23), with guaranteed bounds between the communication points.

Standard library only; no FMI here (``framework.py`` does that). Reads a design file
(``latobs.synthesis.interval_001.to_design_dict``). Model (eq. 9 with ERRATA 001's sign):
    x = [vy (m/s), r (rad/s), x3 = (Fyf + Fyr)/m = ay (m/s^2), x4 = (lf Fyf - lr Fyr)/Iz (rad/s^2)]
    x' = A(vx, c) x + B(vx, c) delta,   y = [r, ay] = C x
    A(vx, c) = A0 + vx A1 + dA(c),  B(vx, c) = vx (B1 + dB1(c)),  dA, dB1 in elementwise bounds
    (eq. 18) for cornering stiffnesses c in the design's box (eq. 10).
Mode j (eq. 44, speed bands) has the model A_j = A0 + vx_j A1, B_j = vx_j B1 at its grid speed
vx_j and the gains N, E, J, H, P = I - E C, K of eq. (23)/(30)/(33). With xi = P x the true state
obeys (exactly, from (30a) and (30b))
    xi' = N xi + J y + H delta + P omega,   omega = (A(vx, c) - A_j) x + (B(vx, c) - B_j) delta,
so that the bounds of eq. (23), xi_up' = N xi_up + J y + H delta + Omega_up (and likewise lower),
stay ordered around P x whenever N is Metzler (Lemma 2) and Omega_lo <= P omega <= Omega_up.

Sampling. The paper's observer is driven by y(t) continuously; here y is sampled at the
communication points and the inputs are held over each step (zero-order hold, as the
co-simulation plant sees delta and vx). The guarantee is kept between the samples, and the
information of y between them is recovered up to O(h^2) remainders by running the observer ONE
STEP BEHIND: the update over [t_k, t_k+1] (``_source_correct``) is done in the call at t_k+1,
when y(t_k+1) is known; what is published at t_k+1 is the guaranteed model PREDICTION from the
corrected box at t_k (``_source_predict``). (With y(t_k+1) unknown, y(s) over the step is only
known to within s C F, and the large output-injection gains, |J| ~ 170 on the yaw rate for
N ~ -7 I, turned that into a width feedback of ~1000 h /s: the bounds diverged at h = 5-10 ms
near the band edges. With the delayed correction the vy width decays at 5.5 /s (h = 1 ms),
5 /s (5 ms), 4 /s (10 ms), 2-3 /s (20 ms) in every band and just outside the grid.)
The remainders of y between the samples still grow with the bounds' width, times h^2 |J|: above
some step the decay of exp(N h) loses and this correction alone diverges (sedan: from ~30 ms at
10 m/s; 1e30 m/s at 50 ms).
So a second, SAMPLED-MEASUREMENT correction (a continuous-discrete interval observer; not in the
paper) runs beside it and the two are intersected (both enclose x, so the intersection does, and
it is never wider than either): between two samples x is propagated by the model alone, without
output injection, over internal substeps of at most ``SAMPLED_SUBSTEP`` (the model's transition
exp(A s) from the box at t in midpoint-radius form, the stiffness part bounded over each
substep's a priori enclosure: ``_sampled_predict``), and at the sample the measurement enters
through gains L with x = (I - L C) x + L y, exact for any L (``_sampled_correct``; the gains that
let the two samples determine vy and x4: ``sampled_maps``). Its width does not feed back through
the remainders of y, so it stays bounded far longer: the vy width decays at ~150 /s at 10 ms,
~78 /s at 20 ms, ~29 /s at 50 ms, 3-7 /s at 200 ms (sedan, zero inputs). It is used from
``SAMPLED_MIN_STEP`` (10 ms) on: its gains grow like 1/h^2 and amplify the departures of a real
plant from the model (a four-wheel plant with atan slip angles and cos(delta) left the bounds by
0.1-0.4 mm/s at 5 ms, once in 200 runs), where the continuous correction alone is tight enough
(sedan, 200 plants x 60 s: mean vy width 0.067 m/s at 5 ms, 0.040 at 20 ms, 0.16 at 200 ms; the
continuous one alone: 0.160 at 20 ms and divergence from ~30 ms). A step longer than
``max_communication_step()`` (0.452 s for the sedan: where even this one stops contracting; decided
from the design, the same constant in the native C model) is refused with an error, the state kept.

One call of ``step(h, u)``, u the inputs at t (held over [t, t + h]):
 1. measurement intersection: the published box of the measured states (x2, x3) at t is
    intersected with [y - nu, y + nu] (nu = runtime.y_error_bound). DEPARTURE: the paper does not
    intersect; both sets contain x, so their intersection does too (a tightening that keeps the
    guarantee). An empty intersection (beyond ``CONSISTENCY_TOL``) means the measurement
    contradicts the bounds (outside the guarantee: stiffness outside the box, saturated tires, a
    speed varying within the step): ``consistent`` = 0 for that step, one warning per episode,
    and the bounds RESTART like at initialisation: the measured states become [y - nu, y + nu],
    the unmeasured ones the hull of their bounds and of the initial box +-x0_halfwidth (so the
    enclosure holds again once the model holds and the true state is inside that box), xi is
    re-based.
 2. correction of the previous step [t - h', t] (eq. 23, exactly discretised; details in
    ``_source_correct``): xi(t) = Phi xi(t - h') + the integral of exp(N (h' - s)) times
    J y(s) + H delta + P omega(s), bounded with Phi = exp(N h') >= 0 and nonnegative kernels:
    ORDER PRESERVING (a plain RK4 step is not). xi is first re-based: [xi_lo, xi_up] intersected
    with the hull of P_j x over the box (eq. 20): both contain P_j x; after a mode switch (P
    changes) the hull alone (ERRATA 001: the bounds stay continuous across switches). Then the
    box at t: x = xi + E y(t), intersected with the prediction.
      * omega = (A(vx, c) - A_j) x + (B(vx, c) - B_j) delta, eq. (25) via Lemma 3: the speed part
        (vx - vx_j) A1 x by eq. (20), the nominal input part (vx - vx_j) B1 delta exactly (delta is
        known), and the stiffness part dA x + vx dB1 delta by its structure (``STIFFNESS``, below).
        DEPARTURE: the paper's A_sigma is the grid speed's model and it ignores the speed mismatch
        inside a band; here it is bounded at the measured speed (the certificate checks the width
        dynamics).
      * the stiffness part (DEPARTURE: a tightening of eq. (25) that keeps the guarantee). The
        uncertainty has rank 2: with dcf, dcr the stiffness errors (stiffness_box minus the nominal
        model.Cf, model.Cr) and the slip angles of eq. (4), af = delta - (x1 + lf x2)/vx,
        ar = (-x1 + lr x2)/vx,
            dA x + vx dB1 delta = (vx/sigma) [0, 0, (dcf af + dcr ar)/m, (lf dcf af - lr dcr ar)/Iz],
        so ``STIFFNESS = "structured"`` (default) bounds it by [af], [ar] from the box by interval
        arithmetic, the exact interval products dcf [af], dcr [ar] and interval addition with signs
        (exact: dcf and dcr are independent); x2 is measured and the vy interval is narrow, so
        [af], [ar] are narrow (sedan, +-20 % box, steady turn at 15 m/s and ay = 4 m/s^2 with a
        0.1 m/s wide vy interval: +-27 m/s^3 on x3' and +-20 rad/s^3 on x4', against +-54 and +-38
        elementwise). For the design's box, symmetric about the nominal stiffnesses, it lies
        inside the elementwise bound whatever the box of x (term by term: max|uf| <= |vx delta| +
        max|x1| + lf max|x2|, and likewise for ur); for an asymmetric box both are computed and
        intersected. ``STIFFNESS = "elementwise"``: [dA][x] by the exact interval product
        (``PRODUCT = "hull"``; contained in eq. (21)'s bound, which ``PRODUCT = "eq21"`` uses) plus
        vx [dB1] delta, entry by entry (dA, dB1 bounded over the box independently).
      * Omega, eq. (24): Omega_up = P+ omega_up - P- omega_lo, Omega_lo = P+ omega_lo - P- omega_up
        with P+ = max(P, 0), P- = P+ - P >= 0 (Efimov's convention, under which eqs. (20), (21),
        (24) and (25) hold; the paper's text defines *- = * - *+ <= 0, with which they would not),
        evaluated in the equivalent midpoint-radius form P m +- |P| r; likewise J y: the upper
        bound takes J+ y_up - J- y_lo (= J m + |J| r).
 3. mode j of vx (eq. 44); outside the grid the nearest mode (one warning per excursion);
    |vx| < vx_hold: everything frozen, outputs held (one warning per entry); on resumption the
    bounds restart from the measurement like at initialisation (the state moved meanwhile).
 4. a priori enclosure T of x over [t, t + h] (validated-ODE style, ``_source_enclose``): G(X) =
    hull of A(vx, c) x + B(vx, c) delta over x in X and c in the box, from (A0 + vx A1)[X] (eq. 20,
    exact for a point matrix), vx B1 delta and the stiffness part over X (``STIFFNESS``, as in
    omega), without the known diagonal of the damped rows (x3, x4: -vx/sigma), which is
    integrated exactly (a convex combination, no wrapping); S is accepted when T(S) lies inside S
    (then x(s) is in T(S) for all s in the step), starting from X_t extended by twice the extents
    of T(X_t), then by twice the (never shrinking) extents of the last T(S) (``ENCLOSURE_MULT`` = 1:
    the factor stays 2; the former doubling of the factor per try compounded with the growing
    extents, overshot, and made the enclosure, hence the bounds, wider for a TIGHTER X at
    h >= 10 ms), ``ENCLOSURE_TRIES`` tries; if all fail (very long steps, extreme speeds): the
    comparison bound |x(s) - x_t| <= Gamma(M, h) g (M the Metzler majorant of A over the box,
    g = max |F(X_t)|), rigorous for any h and wider, one warning per episode. Steps with
    h rho(|A|) > ``SUBSTEP_RHO_H`` chain substeps for T only.
 5. prediction of the box at t + h from the box at t and T; published (step 6 below); the
    correction of this step waits for y(t + h).
 6. outputs (eq. 8 inverted, eq. 45): vy = x1; beta = atan(x1 / vx) (monotone in x1); yaw rate
    = x2; Fyf = (m lr x3 + Iz x4)/L, Fyr = (m lf x3 - Iz x4)/L, L = lf + lr, by interval
    arithmetic. DEPARTURE: eq. (45) prints the same expression for the upper and the lower force
    bounds (a misprint): the lower bound of Fyr takes the UPPER bound of x4.

Optional design-file field ``runtime.disturbance_bound`` (4 values >= 0, the units of x', default
0; not in the paper): an additive model error x' = A x + B delta + w, |w_i| <= the bound, enters
the enclosure and omega (e.g. to cover the roll and load-transfer dynamics of a plant that the
relaxation model omits; without it, the bounds contract onto the state at rest and any model
error shows as an inconsistency).

The bounds are guaranteed for the linear model with any stiffnesses in the box (constant or
time-varying) and any w within its bound, vx and delta constant over each step, the measurement
within +-nu and the initial state in the initial box; floating-point rounding is not directed (errors ~1e-15
relative, far below the widths). Everything per (mode, step size) is compiled once into
straight-line code with the coefficients as literals (like ``pi_observer``), cached per process
(at most ``CACHE_SIZE``).
"""
from __future__ import annotations

import math
import threading
from bisect import bisect_right

from .linalg import matrix as _matrix

OUTPUT_NAMES = ("vy_lower", "vy_upper", "beta_lower", "beta_upper", "yaw_rate_lower", "yaw_rate_upper",
                "Fyf_lower", "Fyf_upper", "Fyr_lower", "Fyr_upper")
INTEGER_OUTPUTS = ("mode", "consistent")

_N = 4            # states
_INF = math.inf
_NO_XI = (-_INF,) * _N + (_INF,) * _N


# -- small dense helpers (lists of rows) ----------------------------------------------------------
def _matmul(A, B):
    cols = list(zip(*B))
    return [[sum([a * b for a, b in zip(row, col)]) for col in cols] for row in A]


def _matvec(A, v):
    return [sum([a * b for a, b in zip(row, v)]) for row in A]


def _expm_taylor(M):
    """exp(M) of a square matrix (lists of rows): scaling X = M / 2^s with ||X||_inf <= 1/2, Horner's
    Taylor series of degree 16 (truncation < 0.5^17/17! ~ 2e-20 relative), s squarings. ValueError
    if ||M||_inf is not finite or above 1e300. Pure Python; the native C model's ``expm_taylor``
    runs the same operations in the same order."""
    m = len(M)
    norm = max(sum(abs(x) for x in row) for row in M)
    if not norm <= 1e300:
        raise ValueError(f"no finite step map (||M h|| = {norm!r})")
    s = max(0, math.ceil(math.log2(norm / 0.5))) if norm > 0.5 else 0
    scale = 0.5 ** s
    X = [[x * scale for x in row] for row in M]
    E = [[1.0 if i == j else 0.0 for j in range(m)] for i in range(m)]
    for k in range(16, 0, -1):                       # Horner: I + X/1 (I + X/2 (... (I + X/16)))
        XE = _matmul(X, E)
        E = [[(1.0 if i == j else 0.0) + XE[i][j] / k for j in range(m)] for i in range(m)]
    for _ in range(s):
        E = _matmul(E, E)
    return E


def phi_gamma(N, h: float, eta: float, order: int = 1):
    """(Phi, Gam) = (exp(N h), int_0^h exp(N s) ds) for a Metzler N with N + eta I >= 0, h > 0;
    ``order`` = 3 adds Gam1 = int_0^h exp(N (h - s)) s ds and Gam2 = int_0^h exp(N (h - s)) s^2/2 ds
    (the weights of forcings growing like s and s^2/2 over the step).

    exp(M h) of the block matrix M = [[N + eta I, I, 0, ..], [0, eta I, I, ..], .., [0, .., eta I]]
    ((order + 1) blocks, all entries >= 0) is exp(eta h) [[Phi, Gam, Gam1, Gam2], ...], so the
    maps are its top blocks times exp(-eta h). Scaling and squaring: X = M h / 2^s with
    ||X||_inf <= 1/2, Taylor series to degree 16 (truncation < 0.5^17/17! ~ 2e-20 relative to
    ||exp(X)|| >= 1), then s squarings. Every Taylor term and every product is a sum of products
    of nonnegative numbers, so the results are >= 0 elementwise in floating point too (no
    cancellation: ~1e-16 relative error per entry, growing like 2^s through the squarings).
    Pure Python."""
    n = len(N)
    if not (h > 0 and math.isfinite(h)):
        raise ValueError(f"step size must be finite and > 0 s, got {h!r}")
    nb = order + 1
    m = nb * n
    M = [[0.0] * m for _ in range(m)]
    for i in range(n):
        for j in range(n):
            M[i][j] = (N[i][j] + (eta if i == j else 0.0)) * h
    for b in range(1, nb):
        for i in range(n):
            M[(b - 1) * n + i][b * n + i] = h
            M[b * n + i][b * n + i] = eta * h
    if min(min(row) for row in M) < 0:
        raise ValueError("phi_gamma needs N + eta I >= 0 elementwise (N Metzler, eta large enough)")
    E = _expm_taylor(M)
    damp = math.exp(-eta * h)
    return tuple([[E[i][b * n + j] * damp for j in range(n)] for i in range(n)] for b in range(nb))


# -- Lemma 3 and eq. (24), reference forms (the compiled step uses equivalent forms) --------------
def _pos(a):
    return a if a > 0.0 else 0.0


def _neg(a):
    """a- = a+ - a = max(-a, 0) >= 0: the convention under which eqs. (20), (21), (24) hold."""
    return -a if a < 0.0 else 0.0


def lemma3_constant(A, xl, xu):
    """Eq. (20): A+ xl - A- xu <= A x <= A+ xu - A- xl for xl <= x <= xu (A- = A+ - A)."""
    lo = [sum(_pos(a) * l - _neg(a) * u for a, l, u in zip(row, xl, xu)) for row in A]
    hi = [sum(_pos(a) * u - _neg(a) * l for a, l, u in zip(row, xl, xu)) for row in A]
    return lo, hi


def lemma3_interval(Al, Au, xl, xu):
    """Eq. (21) (Efimov et al. 2013): for Al <= A <= Au and xl <= x <= xu,
    Al+ xl+ - Au+ xl- - Al- xu+ + Au- xu- <= A x <= Au+ xu+ - Al+ xu- - Au- xl+ + Al- xl-
    (x+ = max(x, 0), x- = x+ - x). The seed text shows A+ in the first term: read Al+."""
    lo, hi = [], []
    for rl, ru in zip(Al, Au):
        lo.append(sum(_pos(al) * _pos(l) - _pos(au) * _neg(l) - _neg(al) * _pos(u) + _neg(au) * _neg(u)
                      for al, au, l, u in zip(rl, ru, xl, xu)))
        hi.append(sum(_pos(au) * _pos(u) - _pos(al) * _neg(u) - _neg(au) * _pos(l) + _neg(al) * _neg(l)
                      for al, au, l, u in zip(rl, ru, xl, xu)))
    return lo, hi


def interval_product(Al, Au, xl, xu):
    """The exact hull of A x over Al <= A <= Au, xl <= x <= xu (entrywise min/max of the corner
    products): contained in the bounds of eq. (21), which it tightens when both factors change
    sign (e.g. [-1, 1] [-1, 1]: [-1, 1] against eq. (21)'s [-2, 2])."""
    lo, hi = [], []
    for rl, ru in zip(Al, Au):
        ps = [(al * l, al * u, au * l, au * u) for al, au, l, u in zip(rl, ru, xl, xu)]
        lo.append(sum(min(p) for p in ps))
        hi.append(sum(max(p) for p in ps))
    return lo, hi


def omega_bounds(P, wl, wu):
    """Eq. (24): (Omega_lo, Omega_up) = (P+ wl - P- wu, P+ wu - P- wl), P- = P+ - P, so that
    Omega_lo <= P w <= Omega_up for every wl <= w <= wu (eq. (20) applied to P)."""
    return lemma3_constant(P, wl, wu)


# -- code generation ----------------------------------------------------------------------------
def _lin(coeffs, names) -> str:
    """'c0*n0 + c1*n1 ...' over the nonzero coefficients whose name is not None; '0.0' if none."""
    terms = []
    for c, x in zip(coeffs, names):
        if x is None or c == 0.0:
            continue
        terms.append(x if c == 1.0 else f"-{x}" if c == -1.0 else f"{c!r}*{x}")
    if not terms:
        return "0.0"
    return " + ".join(terms).replace("+ -", "- ")


def _sum(parts) -> str:
    """'p0 + p1 ...' over the parts that are not '0.0'; '0.0' if none."""
    parts = [p for p in parts if p != "0.0"]
    return " + ".join(parts).replace("+ -", "- ") if parts else "0.0"


def _product_terms(al: float, au: float, l: str, u: str, mag: str, product: str):
    """(lower, upper) expressions of [al, au] * [l, u]; ``mag`` names max(|l|, |u|).
    product = "hull": the exact interval product; "eq21": the bounds of eq. (21)."""
    if product == "eq21":
        lp, lm, up, um = f"({l} if {l} > 0.0 else 0.0)", f"(-{l} if {l} < 0.0 else 0.0)", \
            f"({u} if {u} > 0.0 else 0.0)", f"(-{u} if {u} < 0.0 else 0.0)"
        lo = _lin([_pos(al), -_pos(au), -_neg(al), _neg(au)], [lp, lm, up, um])
        hi = _lin([_pos(au), -_pos(al), -_neg(au), _neg(al)], [up, um, lp, lm])
        return f"({lo})", f"({hi})"
    if al == au:
        return (f"{al!r}*{l}", f"{al!r}*{u}") if al >= 0 else (f"{al!r}*{u}", f"{al!r}*{l}")
    if al >= 0.0:
        return f"({l}*{al!r} if {l} >= 0.0 else {l}*{au!r})", f"({u}*{au!r} if {u} >= 0.0 else {u}*{al!r})"
    if au <= 0.0:
        return f"({u}*{al!r} if {u} >= 0.0 else {u}*{au!r})", f"({l}*{au!r} if {l} >= 0.0 else {l}*{al!r})"
    if abs(al + au) <= 1e-9 * max(-al, au):      # symmetric up to rounding: the outer magnitude
        a = max(-al, au)
        return f"-{a!r}*{mag}", f"{a!r}*{mag}"
    return f"min({l}*{au!r}, {u}*{al!r})", f"max({l}*{al!r}, {u}*{au!r})"


def _emit_stiffness(lines, dAl, dAu, l, u, out_lo, out_hi, product, indent="    "):
    """Lines adding the bounds of [dA] x (x in [l, u], name lists) to out_lo[i], out_hi[i]
    (names), for the rows with a nonzero entry. Returns the set of rows touched."""
    rows, body = set(), []
    for i in range(_N):
        los, his = [], []
        for j in range(_N):
            if dAl[i][j] == 0.0 and dAu[i][j] == 0.0:
                continue
            lo, hi = _product_terms(dAl[i][j], dAu[i][j], l[j], u[j], f"g{j}", product)
            los.append(lo)
            his.append(hi)
        if los:
            rows.add(i)
            body.append(f"{indent}{out_lo[i]} += {_sum(los)}")
            body.append(f"{indent}{out_hi[i]} += {_sum(his)}")
    text = "\n".join(body)
    for j in range(_N):   # max(|l_j|, |u_j|), where a symmetric entry needs it
        if f"g{j}" in text:
            lines.append(f"{indent}g{j} = {u[j]} if {u[j]} > -{l[j]} else -{l[j]}")
    lines.extend(body)
    return rows



def _emit_structured(lines, model, l, u, vd, out_lo, out_hi, tag, product, indent="    "):
    """Lines adding the bounds of the stiffness part dA(dc) x + vx dB1(dc) d (``vd`` names vx d;
    None: without the input part, dA(dc) x alone) over x in [l, u] (name lists) and the stiffness
    box to out_lo[i], out_hi[i], by the STRUCTURE of the uncertainty (``model["stiff"]``):
        dA x + vx dB1 d = [0, 0, (p + q)/(m sigma), (lf p - lr q)/(Iz sigma)],
        p = dcf uf, q = dcr ur,  uf = vx d - x1 - lf x2 = vx af,  ur = -x1 + lr x2 = vx ar
    (af, ar the slip angles of eq. (4)): [uf], [ur] by interval arithmetic, p and q the exact
    interval products with [dcf], [dcr], and the rows by interval addition with signs (exact: p
    and q are independent). This is the brief's vx/sigma [af] form multiplied out (vx [af] =
    [uf] exactly), which needs no division and holds for either sign of vx. For a box that is
    symmetric about the nominal stiffnesses it lies inside the elementwise bound (see
    ``STIFFNESS``); otherwise that bound is computed too and the two are intersected (both contain
    the true value), so it is never wider. Returns the rows touched."""
    sk = model["stiff"]
    i3, i4 = sk["rows"]
    j1, j2 = sk["cols"]
    lf, lr = sk["lf"], sk["lr"]
    k3, k4f, k4r = sk["k3"], sk["k4f"], sk["k4r"]
    pre = "" if vd is None else f"{vd} "
    lines += [f"{indent}ufl{tag} = {pre}- {u[j1]} - {lf!r}*{u[j2]}".replace("= - ", "= -"),
              f"{indent}ufu{tag} = {pre}- {l[j1]} - {lf!r}*{l[j2]}".replace("= - ", "= -"),
              f"{indent}url{tag} = {lr!r}*{l[j2]} - {u[j1]}",
              f"{indent}uru{tag} = {lr!r}*{u[j2]} - {l[j1]}"]
    for p, (al, au), n in (("p", sk["dcf"], "f"), ("q", sk["dcr"], "r")):
        lo, hi = _product_terms(al, au, f"u{n}l{tag}", f"u{n}u{tag}", f"m{n}{tag}", "hull")
        if f"m{n}{tag}" in lo + hi:
            lines.append(f"{indent}m{n}{tag} = u{n}u{tag} if u{n}u{tag} > -u{n}l{tag} else -u{n}l{tag}")
        lines += [f"{indent}{p}l{tag} = {lo}", f"{indent}{p}u{tag} = {hi}"]
    row = {i3: (f"{k3!r}*(pl{tag} + ql{tag})", f"{k3!r}*(pu{tag} + qu{tag})"),
           i4: (f"{k4f!r}*pl{tag} - {k4r!r}*qu{tag}", f"{k4f!r}*pu{tag} - {k4r!r}*ql{tag}")}
    if sk["symmetric"]:
        for i, (lo, hi) in row.items():
            lines += [f"{indent}{out_lo[i]} += {lo}", f"{indent}{out_hi[i]} += {hi}"]
        return set(row)
    # an asymmetric box: intersected with the elementwise bound ([dA][x] + vd [dB1])
    el, eu = [f"el{tag}{i}" for i in range(_N)], [f"eu{tag}{i}" for i in range(_N)]
    for i in row:
        lines += [f"{indent}{el[i]} = 0.0", f"{indent}{eu[i]} = 0.0"]
    _emit_stiffness(lines, model["dA_lower"], model["dA_upper"], l, u, el, eu, product, indent)
    for i, (lo, hi) in row.items():
        bl, bu = model["dB1_lower"][i], model["dB1_upper"][i]
        if vd is not None and (bl != 0.0 or bu != 0.0):
            lines += [f"{indent}if {vd} >= 0.0:",
                      f"{indent}    {el[i]} += {vd}*{bl!r}",
                      f"{indent}    {eu[i]} += {vd}*{bu!r}",
                      f"{indent}else:",
                      f"{indent}    {el[i]} += {vd}*{bu!r}",
                      f"{indent}    {eu[i]} += {vd}*{bl!r}"]
        lines += [f"{indent}sl = {lo}",
                  f"{indent}su = {hi}",
                  f"{indent}if {el[i]} > sl: sl = {el[i]}",
                  f"{indent}if {eu[i]} < su: su = {eu[i]}",
                  f"{indent}if sl > su: sl, su = su, sl",        # rounding only: both contain the value
                  f"{indent}{out_lo[i]} += sl",
                  f"{indent}{out_hi[i]} += su"]
    return set(row)


def structured_stiffness(sk, vx: float, d: float, xl, xu):
    """Reference form (pure Python, vx > 0) of ``_emit_structured``, as the brief states it:
    [af] = d - ([x1] + lf [x2])/vx, [ar] = (-[x1] + lr [x2])/vx, p in [dcf][af], q in [dcr][ar]
    (exact interval products), rows 3 and 4 the hulls of (vx/(sigma m)) (p + q) and
    (vx/(sigma Iz)) (lf p - lr q). ``sk`` = ``IntervalObserver.model["stiff"]``. (lo, hi) 4-vectors."""
    i3, i4 = sk["rows"]
    j1, j2 = sk["cols"]
    lf, lr = sk["lf"], sk["lr"]
    afl, afu = d - (xu[j1] + lf * xu[j2]) / vx, d - (xl[j1] + lf * xl[j2]) / vx
    arl, aru = (-xu[j1] + lr * xl[j2]) / vx, (-xl[j1] + lr * xu[j2]) / vx

    def mul(a, b, c, e):
        ps = (a * c, a * e, b * c, b * e)
        return min(ps), max(ps)

    pl, pu = mul(*sk["dcf"], afl, afu)
    ql, qu = mul(*sk["dcr"], arl, aru)
    lo, hi = [0.0] * _N, [0.0] * _N
    lo[i3], hi[i3] = vx * sk["k3"] * (pl + ql), vx * sk["k3"] * (pu + qu)
    lo[i4], hi[i4] = vx * (sk["k4f"] * pl - sk["k4r"] * qu), vx * (sk["k4f"] * pu - sk["k4r"] * ql)
    return lo, hi


def elementwise_stiffness(model, vx: float, d: float, xl, xu):
    """Reference form of the elementwise bound: [dA][x] by the exact interval product plus
    vx d [dB1], entry by entry. (lo, hi) 4-vectors."""
    lo, hi = interval_product(model["dA_lower"], model["dA_upper"], xl, xu)
    vd = vx * d
    for i in range(_N):
        a, b = vd * model["dB1_lower"][i], vd * model["dB1_upper"][i]
        lo[i] += min(a, b)
        hi[i] += max(a, b)
    return lo, hi


def _compile(src: str, name: str, **extra):
    ns = {"__builtins__": {}, "min": min, "max": max, "abs": abs, "range": range, "expm1": math.expm1, **extra}
    exec(compile(src, f"<interval_observer {name}>", "exec"), ns)
    return ns[name]


def _damped_rows(model) -> list[int]:
    """Rows i whose diagonal coefficient is known, d_i(vx) = A0_ii + vx A1_ii (no stiffness
    uncertainty on it) and not identically 0: the a priori enclosure treats them exactly."""
    A0, A1, dAl, dAu = (model[k] for k in ("A0", "A1", "dA_lower", "dA_upper"))
    return [i for i in range(_N) if dAl[i][i] == 0.0 and dAu[i][i] == 0.0 and (A0[i][i] != 0.0 or A1[i][i] != 0.0)]


def _source_G(model, product: str) -> str:
    """G(vx, d, l0..l3, u0..u3) -> (lower0..3, upper0..3): the hull of A(vx, c) x + B(vx, c) d over
    x in [l, u] and c in the box WITHOUT the diagonal terms d_i(vx) x_i of the damped rows (for
    the other rows: the whole right-hand side F). The stiffness part dA x + vx dB1 d: by its
    structure (``_emit_structured``) if ``model["stiff"]``, else elementwise ([dA][X] + vx [dB1] d)."""
    A0, A1, B1, dAl, dAu, dBl, dBu = (model[k] for k in ("A0", "A1", "B1", "dA_lower", "dA_upper",
                                                           "dB1_lower", "dB1_upper"))
    structured = model.get("stiff") is not None
    damped = _damped_rows(model)
    A0 = [[0.0 if (i == j and i in damped) else A0[i][j] for j in range(_N)] for i in range(_N)]
    A1 = [[0.0 if (i == j and i in damped) else A1[i][j] for j in range(_N)] for i in range(_N)]
    L = [f"l{j}" for j in range(_N)]
    U = [f"u{j}" for j in range(_N)]
    lines = [f"def G(vx, d, {', '.join(L)}, {', '.join(U)}):",
             "    avx = vx if vx >= 0.0 else -vx",
             "    vd = vx*d",
             "    avd = vd if vd >= 0.0 else -vd"]
    for j in range(_N):
        lines.append(f"    c{j} = (l{j} + u{j})*0.5")
        lines.append(f"    r{j} = (u{j} - l{j})*0.5")
    C = [f"c{j}" for j in range(_N)]
    R = [f"r{j}" for j in range(_N)]
    for i in range(_N):
        # midpoint-radius form of eq. (20) for the point matrix A0 + vx A1: M c +- |M| r
        mid = [_lin(A0[i], C)]
        a1 = _lin(A1[i], C)
        if a1 != "0.0":
            mid.append(f"vx*({a1})")
        only0 = [abs(A0[i][j]) if A1[i][j] == 0.0 else 0.0 for j in range(_N)]
        only1 = [abs(A1[i][j]) if A0[i][j] == 0.0 else 0.0 for j in range(_N)]
        rad = [_lin(only0, R)]
        r1 = _lin(only1, R)
        if r1 != "0.0":
            rad.append(f"avx*({r1})")
        rad += [f"abs({A0[i][j]!r} + vx*{A1[i][j]!r})*r{j}" for j in range(_N)
                if A0[i][j] != 0.0 and A1[i][j] != 0.0]
        if structured:                  # the stiffness part of the input term with dA's, below
            bm, br = B1[i], 0.0
        else:
            bm, br = (B1[i] + 0.5 * (dBl[i] + dBu[i])), 0.5 * (dBu[i] - dBl[i])
        if bm != 0.0:
            mid.append(f"vd*{bm!r}")
        if br != 0.0:
            rad.append(f"avd*{br!r}")
        if model["w"][i] != 0.0:
            rad.append(repr(model["w"][i]))
        lines.append(f"    m = {_sum(mid)}")
        lines.append(f"    w = {_sum(rad)}")
        lines.append(f"    fl{i} = m - w")
        lines.append(f"    fu{i} = m + w")
    FL, FU = [f"fl{i}" for i in range(_N)], [f"fu{i}" for i in range(_N)]
    if structured:
        _emit_structured(lines, model, L, U, "vd", FL, FU, "", product)
    else:
        _emit_stiffness(lines, dAl, dAu, L, U, FL, FU, product)
    lines.append(f"    return ({', '.join(f'fl{i}' for i in range(_N))}, {', '.join(f'fu{i}' for i in range(_N))})")
    return "\n".join(lines)


def _source_stiffness(model, product: str) -> str:
    """S(vx, d, l0..3, u0..3) -> (lower0..3, upper0..3): the runtime's bound of the stiffness part
    dA(dc) x + vx dB1(dc) d over x in [l, u] and the stiffness box, by the same emitters as G and
    the correction (for the tests and measurements; the step does not call it)."""
    L = [f"l{j}" for j in range(_N)]
    U = [f"u{j}" for j in range(_N)]
    lines = [f"def S(vx, d, {', '.join(L)}, {', '.join(U)}):", "    vd = vx*d"]
    SL, SU = [f"sl{i}" for i in range(_N)], [f"su{i}" for i in range(_N)]
    for i in range(_N):
        lines += [f"    sl{i} = 0.0", f"    su{i} = 0.0"]
    if model.get("stiff") is not None:
        _emit_structured(lines, model, L, U, "vd", SL, SU, "", product)
    else:
        _emit_stiffness(lines, model["dA_lower"], model["dA_upper"], L, U, SL, SU, product)
        for i in range(_N):
            bl, bu = model["dB1_lower"][i], model["dB1_upper"][i]
            if bl != 0.0 or bu != 0.0:
                lines += [f"    sl{i} += vd*{bl!r} if vd >= 0.0 else vd*{bu!r}",
                          f"    su{i} += vd*{bu!r} if vd >= 0.0 else vd*{bl!r}"]
    lines.append(f"    return ({', '.join(SL + SU)})")
    return "\n".join(lines)


def _emit_extents(lines, model, indent, S, out):
    """Lines setting out_l{i}, out_u{i} to the enclosure of x_i over the substep given G's values
    g{i}/h{i} over the box S (names sl/su): for a damped row with a = -d_i(vx) > 0,
        x_i(s) = x_i(0) + theta(s) (gbar/a - x_i(0)),  theta(s) = 1 - exp(-a s) in [0, 1 - exp(-a hs)],
    gbar a weighted mean of g over [0, s], hence (convex combination)
        x_i(s) in [l + min(0, th (g_lo - a l)), u + max(0, th (g_up - a u))], th = -expm1(-a hs)/a;
    otherwise x_i(s) in x_i(0) + [0, hs] F_i(S) (F_i = g_i + d_i [S_i] for a damped row)."""
    damped = _damped_rows(model)
    sl, su = S
    for i in range(_N):
        if i in damped:
            lines += [f"{indent}if a{i} > 0.0:",
                      f"{indent}    t = gl{i} - a{i}*l{i}",
                      f"{indent}    {out}l{i} = l{i} + th{i}*t if t < 0.0 else l{i}",
                      f"{indent}    t = gu{i} - a{i}*u{i}",
                      f"{indent}    {out}u{i} = u{i} + th{i}*t if t > 0.0 else u{i}",
                      f"{indent}else:",
                      f"{indent}    t = gl{i} - a{i}*{sl}{i}",
                      f"{indent}    {out}l{i} = l{i} + hs*t if t < 0.0 else l{i}",
                      f"{indent}    t = gu{i} - a{i}*{su}{i}",
                      f"{indent}    {out}u{i} = u{i} + hs*t if t > 0.0 else u{i}"]
        else:
            lines += [f"{indent}{out}l{i} = l{i} + hs*gl{i} if gl{i} < 0.0 else l{i}",
                      f"{indent}{out}u{i} = u{i} + hs*gu{i} if gu{i} > 0.0 else u{i}"]


def _source_enclose(model, tries: int, grow: float, refine: bool = True, mult: float = 2.0) -> str:
    """enclose(hs, vx, d, l0..3, u0..3) -> (lower0..3, upper0..3) of x over the substep, or None.
    S is accepted when T(S) (``_emit_extents`` with G over S) lies inside it: then the solution
    stays in S (the Picard operator maps the functions valued in S into those valued in T(S),
    a subset) and x(s) is in T(S) for all s in [0, hs], which is returned. First S: X_k extended by
    ``grow`` times the extents of T(X_k); then by the factor times the extents of the last T (never
    shrinking), the factor multiplied by ``mult`` per try (1: constant; 2: doubling, which
    compounds with the growing extents and overshoots)."""
    n = range(_N)
    damped = _damped_rows(model)
    A0, A1 = model["A0"], model["A1"]
    L = ", ".join(f"l{i}" for i in n)
    U = ", ".join(f"u{i}" for i in n)
    GL = ", ".join(f"gl{i}" for i in n)
    GU = ", ".join(f"gu{i}" for i in n)
    lines = [f"def enclose(hs, vx, d, {L}, {U}):"]
    for i in damped:
        lines.append(f"    a{i} = -({A0[i][i]!r} + vx*{A1[i][i]!r})")
        lines.append(f"    th{i} = -expm1(-a{i}*hs)/a{i} if a{i} > 0.0 else hs")
    lines.append(f"    {GL}, {GU} = G(vx, d, {L}, {U})")
    _emit_extents(lines, model, "    ", ("l", "u"), "t")
    for i in n:   # extents of T(X_k): e_lo <= 0 <= e_up
        lines.append(f"    el{i} = tl{i} - l{i}")
        lines.append(f"    eu{i} = tu{i} - u{i}")
    lines.append(f"    g = {grow!r}")
    lines.append(f"    for _ in range({tries}):")
    for i in n:
        lines.append(f"        sl{i} = l{i} + g*el{i}")
        lines.append(f"        su{i} = u{i} + g*eu{i}")
    SL = ", ".join(f"sl{i}" for i in n)
    SU = ", ".join(f"su{i}" for i in n)
    lines.append(f"        {GL}, {GU} = G(vx, d, {SL}, {SU})")
    _emit_extents(lines, model, "        ", ("sl", "su"), "t")
    cond = " and ".join(f"tl{i} >= sl{i} and tu{i} <= su{i}" for i in n)
    lines.append(f"        if {cond}:")
    if refine:   # one more pass: x(s) in T for all s, hence in T(T), a subset
        TL = ", ".join(f"tl{i}" for i in n)
        TU = ", ".join(f"tu{i}" for i in n)
        lines.append(f"            {GL}, {GU} = G(vx, d, {TL}, {TU})")
        for i in n:
            lines.append(f"            sl{i} = tl{i}")
            lines.append(f"            su{i} = tu{i}")
        _emit_extents(lines, model, "            ", ("sl", "su"), "t")
    lines.append(f"            return ({', '.join(f'tl{i}' for i in n)}, {', '.join(f'tu{i}' for i in n)})")
    for i in n:   # the extents never shrink: a side that needed none may need some later
        lines.append(f"        t = tl{i} - l{i}")
        lines.append(f"        if t < el{i}: el{i} = t")
        lines.append(f"        t = tu{i} - u{i}")
        lines.append(f"        if t > eu{i}: eu{i} = t")
    if mult != 1.0:
        lines.append(f"        g = {mult!r}*g")
    lines.append("    return None")
    return "\n".join(lines)


def _emit_omega(lines, model, product, c, r, lo, hi, tag, with_input):
    """Lines for the midpoint/radius (oc{tag}{i}, or{tag}{i}) of (vx - vx_j) A1 x + [dA] x over the
    box x in [lo, hi] (names; c, r its midpoint/radius names), plus, if ``with_input``, the input
    part ((vx - vx_j) B1 + vx [dB1]) d. The stiffness part ([dA] x + vx [dB1] d): by its structure
    (``_emit_structured``) if ``model["stiff"]``, else elementwise. Returns the rows that are not
    identically 0."""
    A1, B1, dAl, dAu, dBl, dBu = (model[k] for k in ("A1", "B1", "dA_lower", "dA_upper", "dB1_lower", "dB1_upper"))
    structured = model.get("stiff") is not None
    for i in range(_N):
        lines.append(f"    sl{tag}{i} = 0.0")
        lines.append(f"    su{tag}{i} = 0.0")
    SL, SU = [f"sl{tag}{i}" for i in range(_N)], [f"su{tag}{i}" for i in range(_N)]
    if structured:
        stiff = _emit_structured(lines, model, lo, hi, "vd" if with_input else None, SL, SU, tag, product)
    else:
        stiff = _emit_stiffness(lines, dAl, dAu, lo, hi, SL, SU, product)
    live = []
    for i in range(_N):
        mid, rad = [], []
        a1 = _lin(A1[i], c)
        if a1 != "0.0":
            mid.append(f"dv*({a1})")
            rad.append(f"adv*({_lin([abs(x) for x in A1[i]], r)})")
        if with_input:
            if B1[i] != 0.0:
                mid.append(f"dvd*{B1[i]!r}")
            bm, br = (0.0, 0.0) if structured else (0.5 * (dBl[i] + dBu[i]), 0.5 * (dBu[i] - dBl[i]))
            if bm != 0.0:
                mid.append(f"vd*{bm!r}")
            if br != 0.0:
                rad.append(f"avd*{br!r}")
            if model["w"][i] != 0.0:         # the additive disturbance bound (runtime.disturbance_bound)
                rad.append(repr(model["w"][i]))
        if i in stiff:
            mid.append(f"(sl{tag}{i} + su{tag}{i})*0.5")
            rad.append(f"(su{tag}{i} - sl{tag}{i})*0.5")
        if mid or rad:
            live.append(i)
            lines.append(f"    oc{tag}{i} = {_sum(mid)}")
            lines.append(f"    or{tag}{i} = {_sum(rad)}")
    return live


def _source_predict(model) -> str:
    """predict(h, vx, d, l.., u.., tl.., tu..) -> (fl.., fu.., bl.., bu..): Fbar = the hull of F over
    the enclosure T of the step, and the box B of x(t + h) from the box [l, u] of x(t): for a
    damped row with a = -d_i(vx) > 0, x_i(h) = x_i(0) + th (gbar - a x_i(0)), th = (1 - exp(-a h))/a,
    gbar in G_i(T) (``_emit_extents``); for the others x(h) in x(0) + h Fbar; intersected with T."""
    n = range(_N)
    damped = _damped_rows(model)
    A0, A1 = model["A0"], model["A1"]
    names = lambda p: [f"{p}{i}" for i in n]  # noqa: E731
    lines = [f"def predict(h, vx, d, {', '.join(names('l') + names('u') + names('tl') + names('tu'))}):",
             f"    {', '.join(names('fl') + names('fu'))} = G(vx, d, {', '.join(names('tl') + names('tu'))})"]
    for i in n:
        if i in damped:
            lines += [f"    a = -({A0[i][i]!r} + vx*{A1[i][i]!r})",
                      "    if a > 0.0:",
                      "        th = -expm1(-a*h)/a",
                      f"        bl{i} = l{i} + th*(fl{i} - a*l{i})",
                      f"        bu{i} = u{i} + th*(fu{i} - a*u{i})",
                      f"        fl{i} -= a*tu{i}",
                      f"        fu{i} -= a*tl{i}",
                      "    else:",
                      f"        fl{i} -= a*tl{i}",
                      f"        fu{i} -= a*tu{i}",
                      f"        bl{i} = l{i} + h*fl{i}",
                      f"        bu{i} = u{i} + h*fu{i}"]
        else:
            lines += [f"    bl{i} = l{i} + h*fl{i}",
                      f"    bu{i} = u{i} + h*fu{i}"]
        lines += [f"    if bl{i} < tl{i}: bl{i} = tl{i}",
                  f"    if bu{i} > tu{i}: bu{i} = tu{i}"]
    lines.append(f"    return ({', '.join(names('fl') + names('fu') + names('bl') + names('bu'))})")
    return "\n".join(lines)


def _smooth_rows(model, meas) -> list[int]:
    """Measured states j whose derivative is a known linear form, x_j' = (A0 + vx A1)[j, :] x (no
    stiffness, no input): their second derivative is bounded by that form over Fbar (the yaw rate:
    r' = x4, r'' = x4'), valid for time-varying stiffness too."""
    dAl, dAu, B1, dBl, dBu, w = (model[k] for k in ("dA_lower", "dA_upper", "B1", "dB1_lower", "dB1_upper", "w"))
    return [j for j in meas if not any(dAl[j]) and not any(dAu[j]) and B1[j] == 0.0 and dBl[j] == 0.0
            and dBu[j] == 0.0 and w[j] == 0.0]


def _source_correct(model, mode, h, maps, meas, product: str) -> str:
    """correct(vx, d, l.., u.., a.., b.., tl.., tu.., fl.., fu.., yl.., yu.., bl.., bu..) -> (box, xi)
    at the END of a step [t, t + h] of one mode, once the measurement at t + h is known (the
    observer runs one step behind; the published box is ``predict``'s). Arguments: [l, u] the box
    at t (after its measurement), [a, b] the xi bounds at t of this mode (+-inf: none), [tl, tu]
    the enclosure T over the step and [fl, fu] the hull Fbar of F over T, [yl, yu] the measured
    states at t + h (their measurement intersected with [bl, bu], the predicted box at t + h).

    Eq. (23) over the step, xi(t + h) = Phi xi(t) + int_0^h exp(N (h - s)) (J y(s) + H d + P omega(s)) ds
    with exp(N (h - s)) >= 0 (N Metzler), bounded term by term (every bound is the midpoint-radius
    form of eq. (20)/(24): M m +- |M| r for a constant, W m +- W |M| r for a kernel W >= 0):
      * y(s) = (1 - s/h) y(0) + (s/h) y(h) + rho(s), rho(0) = rho(h) = 0: the known samples with the
        weights W0 = Gam - Gam1/h, W1 = Gam1/h (y(0), y(h) constants: (W J) m +- |W J| r); rho'' = y''
        gives rho(s) in -(s (h - s)/2) [y''] for the smooth rows (``_smooth_rows``: [y''] = the
        row's form over Fbar), weight W2 = h Gam1/2 - Gam2; for the others y(s) - y(0) in s [Fbar]
        and y(h) - y(s) in (h - s) [Fbar] give rho(s) in (s (h - s)/h) [-w, w], w = width of
        [Fbar_j], weight W3 = 2 W2/h. (DEPARTURE: the paper has y(t) continuously; with sampled
        measurements this keeps its information up to O(h^2) remainders.)
      * omega(s) = (A(s) - A_j) x_k + (A(s) - A_j)(x(s) - x_k) + (B - B_j) d with x_k in [l, u] and
        x(s) - x_k in s Fbar: omega0 = omega over [l, u] (weight Gam), omega1 = (A - A_j)[Fbar]
        (weight Gam1); Omega by eq. (24); speed part (vx - vx_j) A1 by eq. (20), nominal input
        part exact (DEPARTURE: the measured speed), stiffness part (dA x_k + vx dB1 d over [l, u],
        and dA (x(s) - x_k) over Fbar, each over the whole stiffness box, so time-varying
        stiffnesses are covered) by ``_emit_structured`` or elementwise (``STIFFNESS``).
    Before: xi := [a, b] intersected with the hull of P x over [l, u] (eq. 20). After: the box at
    t + h, x = xi + E y(h), intersected with the predicted box."""
    n = range(_N)
    Phi, Gam, Gam1, Gam2 = maps
    P, E, J, H = mode["P"], mode["E"], mode["J"], mode["H"]
    absP = [[abs(x) for x in row] for row in P]
    absE = [[abs(x) for x in row] for row in E]
    absJ = [[abs(x) for x in row] for row in J]
    W1 = [[g / h for g in row] for row in Gam1]
    W0 = [[g - w for g, w in zip(rg, rw)] for rg, rw in zip(Gam, W1)]
    W2 = [[abs(h * g1 / 2 - g2) for g1, g2 in zip(r1, r2)] for r1, r2 in zip(Gam1, Gam2)]
    W3 = [[2 * w / h for w in row] for row in W2]
    W0J, W1J = _matmul(W0, J), _matmul(W1, J)
    aW0J, aW1J = [[abs(x) for x in row] for row in W0J], [[abs(x) for x in row] for row in W1J]
    W2J, W2aJ, W3aJ = _matmul(W2, J), _matmul(W2, absJ), _matmul(W3, absJ)
    GP, GaP, G1P, G1aP = _matmul(Gam, P), _matmul(Gam, absP), _matmul(Gam1, P), _matmul(Gam1, absP)
    GH = _matvec(Gam, H)
    smooth = _smooth_rows(model, meas)
    A0, A1 = model["A0"], model["A1"]
    names = lambda p: [f"{p}{i}" for i in n]  # noqa: E731
    args = names("l") + names("u") + names("a") + names("b") + names("tl") + names("tu") + names("fl") + \
        names("fu") + [f"yl{j}" for j in meas] + [f"yu{j}" for j in meas] + names("bl") + names("bu")
    lines = [f"def correct(vx, d, {', '.join(args)}):"]
    # 7a. re-base: xi := [a, b] intersected with the hull of P x over [l, u] (eq. 20, midpoint form)
    for j in n:
        lines.append(f"    c{j} = (l{j} + u{j})*0.5")
        lines.append(f"    r{j} = (u{j} - l{j})*0.5")
    for i in n:
        lines.append(f"    p = {_lin(P[i], names('c'))}")
        lines.append(f"    q = {_lin(absP[i], names('r'))}")
        lines.append("    t = p - q")
        lines.append(f"    if t > a{i}: a{i} = t")
        lines.append("    t = p + q")
        lines.append(f"    if t < b{i}: b{i} = t")
        lines.append(f"    if a{i} > b{i}: a{i} = p - q; b{i} = p + q")
        lines.append(f"    xc{i} = (a{i} + b{i})*0.5")
        lines.append(f"    xr{i} = (b{i} - a{i})*0.5")
    for j in n:
        lines.append(f"    fc{j} = (fl{j} + fu{j})*0.5")
        lines.append(f"    fr{j} = (fu{j} - fl{j})*0.5")
    # the measured samples at t + h, and the remainders rho of the measured states
    for j in meas:
        lines.append(f"    yc{j} = (yl{j} + yu{j})*0.5")
        lines.append(f"    yr{j} = (yu{j} - yl{j})*0.5")
    dc, dr = [], []
    for j in meas:
        if j in smooth:
            mid = [_lin(A0[j], names("fc"))]
            if any(A1[j]):
                mid.append(f"vx*({_lin(A1[j], names('fc'))})")
            lines.append(f"    dc{j} = {_sum(mid)}")
            rad = [_lin([abs(A0[j][k]) if A1[j][k] == 0.0 else 0.0 for k in n], names("fr"))]
            rad += [f"abs({A0[j][k]!r} + vx*{A1[j][k]!r})*fr{k}" for k in n if A1[j][k] != 0.0]
            lines.append(f"    dr{j} = {_sum(rad)}")
            dc.append(f"dc{j}")
            dr.append(f"dr{j}")
        else:
            dc.append(None)
            dr.append(None)
    wo = [None if j in smooth else f"fr{j}" for j in meas]   # rho in +-(s (h - s)/h) 2 fr_j
    # 4. omega over [l, u] (with the input part) and its growth rate over Fbar
    lines += [f"    dv = vx - {float(mode['vx'])!r}",
              "    adv = dv if dv >= 0.0 else -dv",
              "    dvd = dv*d",
              "    vd = vx*d",
              "    avd = vd if vd >= 0.0 else -vd"]
    live0 = _emit_omega(lines, model, product, names("c"), names("r"), names("l"), names("u"), "0", True)
    live1 = _emit_omega(lines, model, product, names("fc"), names("fr"), names("fl"), names("fu"), "1", False)
    oc0 = [f"oc0{i}" if i in live0 else None for i in n]
    or0 = [f"or0{i}" if i in live0 else None for i in n]
    oc1 = [f"oc1{i}" if i in live1 else None for i in n]
    or1 = [f"or1{i}" if i in live1 else None for i in n]
    y0c, y0r = [f"c{j}" for j in meas], [f"r{j}" for j in meas]
    y1c, y1r = [f"yc{j}" for j in meas], [f"yr{j}" for j in meas]
    # 5.-7. eq. (23) over the step
    for i in n:
        mid = [_lin(Phi[i], names("xc")), _lin(W0J[i], y0c), _lin(W1J[i], y1c),
               _lin([-x for x in W2J[i]], dc), _lin(GP[i], oc0), _lin(G1P[i], oc1)]
        if GH[i] != 0.0:
            mid.append(f"{GH[i]!r}*d")
        rad = [_lin(Phi[i], names("xr")), _lin(aW0J[i], y0r), _lin(aW1J[i], y1r), _lin(W2aJ[i], dr),
               _lin([2.0 * x for x in W3aJ[i]], wo), _lin(GaP[i], or0), _lin(G1aP[i], or1)]
        lines.append(f"    nc{i} = {_sum(mid)}")
        lines.append(f"    nr{i} = {_sum(rad)}")
    # 8. the box at t + h: x = xi + E y(h), intersected with the predicted box
    for i in n:
        lines.append(f"    bc = nc{i} + {_lin(E[i], y1c)}")
        lines.append(f"    br = nr{i} + {_lin(absE[i], y1r)}")
        lines.append(f"    xl{i} = bc - br")
        lines.append(f"    xu{i} = bc + br")
        lines.append(f"    if xl{i} < bl{i}: xl{i} = bl{i}")
        lines.append(f"    if xu{i} > bu{i}: xu{i} = bu{i}")
        lines.append(f"    if xl{i} > xu{i}: xl{i} = bl{i}; xu{i} = bu{i}")
    for j in meas:                      # the measured states: with their measurement
        lines.append(f"    if xl{j} < yl{j}: xl{j} = yl{j}")
        lines.append(f"    if xu{j} > yu{j}: xu{j} = yu{j}")
        lines.append(f"    if xl{j} > xu{j}: xl{j} = yl{j}; xu{j} = yu{j}")
    outs = names("xl") + names("xu") + [f"nc{i} - nr{i}" for i in n] + [f"nc{i} + nr{i}" for i in n]
    lines.append(f"    return ({', '.join(outs)})")
    return "\n".join(lines)


# -- the sampled-measurement (continuous-discrete) correction --------------------------------------
def expm_gamma(A, h: float):
    """(Phi, Gam) = (exp(A h), int_0^h exp(A s) ds) for ANY square A (no sign condition), h > 0:
    the top blocks of exp([[A, I], [0, 0]] h) (``_expm_taylor``)."""
    n = len(A)
    m = 2 * n
    M = [[0.0] * m for _ in range(m)]
    for i in range(n):
        for j in range(n):
            M[i][j] = A[i][j] * h
        M[i][n + i] = h
    E = _expm_taylor(M)
    return [row[:n] for row in E[:n]], [row[n:] for row in E[:n]]


def _absm(A):
    return [[abs(x) for x in row] for row in A]


def _addv(a, b):
    return [x + y for x, y in zip(a, b)]


SAMPLED_MAX_NORM = 1e6   # ||A hs||_inf above which ``sampled_maps`` gives up (vx ~ 1e8 m/s at 5 ms)


class _Sampled:
    """The maps of the sampled-measurement correction at one (speed, step): see
    ``IntervalObserver._sampled_maps``."""
    __slots__ = ("n", "hs", "phi", "aphi", "gamb", "pg", "apg", "cands")


def sampled_maps(model, meas, vx: float, h: float, substep: float, max_substeps: int) -> _Sampled:
    """The data of the sampled-measurement correction (``IntervalObserver._sampled_predict`` and
    ``_sampled_correct``) of a step h at the speed vx, with n = ceil(h / substep) substeps of
    hs = h / n: A = A0 + vx A1 and Bv = vx B1 the nominal model AT vx (the stiffness part is the
    only model error, bounded over each substep's enclosure),
        phi[m] = exp(A m hs), aphi[m] = |phi[m]|, gamb[m] = int_0^(m hs) exp(A s) ds Bv  (m = 0..n),
        pg[i] = exp(A i hs) Gam(hs)  = int over u in [i hs, (i + 1) hs] of exp(A u) du,
        apg[i] = |exp(A i hs)| Gam_M(hs) >= int over that u of |exp(A u)| du      (i = 0..n-1)
    (|exp(A t)| <= exp(M t) elementwise, M the Metzler majorant of A: diag(A) + |offdiag(A)|, by
    the comparison principle), and the measurement gains ``cands`` (list of (L, K phi[n], |K phi[n]|,
    K gamb[n], [K pg[i]], [|K phi[i]| Gam_M(hs)], |L|), K = I - L C): L = 0 (the prediction), and
    gains whose measured rows put the measured states at y and whose unmeasured rows (vy, x4)
    cancel the prediction's dependence on the unmeasured states at t, both at once (the two
    samples determine them: ``deadbeat``) or one column by one measurement."""
    n_x = _N
    A = [[a + vx * b for a, b in zip(r0, r1)] for r0, r1 in zip(model["A0"], model["A1"])]
    Bv = [vx * b for b in model["B1"]]
    n = min(max(1, math.ceil(h / substep - 1e-9)), max_substeps)
    hs = h / n
    norm = max(sum(abs(x) for x in row) for row in A) * hs
    if not norm <= SAMPLED_MAX_NORM:        # |vx| far beyond any vehicle: no useful map, and slow
        raise ValueError(f"no sampled step map at vx = {vx!r} m/s (||A hs|| = {norm:g})")
    phid, gamd = expm_gamma(A, hs)
    Mj = [[A[i][j] if i == j else abs(A[i][j]) for j in range(n_x)] for i in range(n_x)]
    shift = max(0.0, max(-Mj[i][i] for i in range(n_x)))
    gamM = phi_gamma(Mj, hs, shift)[1]
    gdb = _matvec(gamd, Bv)
    eye = [[1.0 if i == j else 0.0 for j in range(n_x)] for i in range(n_x)]
    phi, gamb = [eye], [[0.0] * n_x]
    for m in range(1, n + 1):
        gamb.append(_addv(gamb[-1], _matvec(phi[-1], gdb)))
        phi.append(_matmul(phi[-1], phid))
    sm = _Sampled()
    sm.n, sm.hs, sm.phi, sm.gamb = n, hs, phi, gamb
    sm.aphi = [_absm(p) for p in phi]
    sm.pg = [_matmul(p, gamd) for p in phi[:n]]
    sm.apg = [_matmul(a, gamM) for a in sm.aphi[:n]]
    unmeas = [j for j in range(n_x) if j not in meas]
    ph = phi[n]
    rows = []                           # the unmeasured rows' options: L_i (one entry per measurement)
    D = [[ph[q][j] for j in unmeas] for q in meas]
    det = D[0][0] * D[1][1] - D[0][1] * D[1][0]
    if det != 0.0 and math.isfinite(det):
        inv = [[D[1][1] / det, -D[0][1] / det], [-D[1][0] / det, D[0][0] / det]]
        rows.append({i: [sum(ph[i][unmeas[k]] * inv[k][q] for k in range(2)) for q in range(2)] for i in unmeas})
    for j in unmeas:
        for q, jm in enumerate(meas):
            if ph[jm][j] != 0.0:
                rows.append({i: [ph[i][j] / ph[jm][j] if qq == q else 0.0 for qq in range(2)] for i in unmeas})
    gains = []
    for opt in rows:
        L = [[0.0, 0.0] for _ in range(n_x)]
        for q, jm in enumerate(meas):
            L[jm][q] = 1.0
        for i, li in opt.items():
            L[i] = li
        if all(math.isfinite(x) for r in L for x in r):
            gains.append(L)
    sm.cands = []
    for L in gains:
        K = [[eye[i][j] - sum(L[i][q] for q, jm in enumerate(meas) if jm == j) for j in range(n_x)]
             for i in range(n_x)]
        Kphi = _matmul(K, ph)
        sm.cands.append((L, Kphi, _absm(Kphi), _matvec(K, gamb[n]), [_matmul(K, p) for p in sm.pg],
                         [_matmul(_absm(_matmul(K, p)), gamM) for p in phi[:n]], _absm(L)))
    return sm


# -- the per-process cache of compiled step maps --------------------------------------------------
_LOCK = threading.RLock()
_CACHE: dict = {}      # key -> compiled object, oldest first
_MAX_COMM_STEP: dict = {}   # (design, tuning) -> IntervalObserver.max_communication_step
_SAMPLED: dict = {}         # (design, speed, step, tuning) -> sampled_maps, oldest first


def _cached(key, build, size: int):
    with _LOCK:
        obj = _CACHE.get(key)
        if obj is None:
            obj = build()
            _CACHE[key] = obj
            while len(_CACHE) > size:
                _CACHE.pop(next(iter(_CACHE)))
        return obj


class _Core:
    """The compiled correction of one (mode, step size) and the substeps of its enclosure."""
    __slots__ = ("correct", "nsub", "hs")

    def __init__(self, correct, nsub, hs):
        self.correct, self.nsub, self.hs = correct, nsub, hs


# -- validation of the design file ----------------------------------------------------------------
def _vector(x, n: int, what: str):
    try:
        v = [float(a) for a in x]
    except (TypeError, ValueError) as exc:
        raise ValueError(f"design file: {what} must be a vector of {n} numbers ({exc})") from exc
    if len(v) != n:
        raise ValueError(f"design file: {what} must have {n} entries, got {len(v)}")
    if not all(math.isfinite(a) for a in v):
        raise ValueError(f"design file: {what} has a non-finite entry")
    return v


def _rel(a, b) -> float:
    """max |a - b| / max(1, max |b|) over two equal-shape matrices."""
    fa = [x for r in a for x in (r if isinstance(r, list) else [r])]
    fb = [x for r in b for x in (r if isinstance(r, list) else [r])]
    return max(abs(x - y) for x, y in zip(fa, fb)) / max(1.0, max(abs(y) for y in fb))


class IntervalObserver:
    """Switched interval observer of paper 001 from its design file (see the module docstring).

    Inputs u = {delta (rad), vx (m/s), yaw_rate (rad/s), ay (m/s^2)}; outputs ``OUTPUT_NAMES``
    (floats) and ``mode`` (1-based), ``consistent`` (1, or 0 on a step whose measurement lay
    outside the bounds). ``box`` holds the current bounds [xl, xu] of x."""

    PARAMETERS = {"vx_hold": 1.0}    # m/s: below this speed the observer is frozen
    TOL = 1e-9                       # relative tolerance of the design file's structural relations
    CONSISTENCY_TOL = 1e-9           # measurement outside the bounds by less (x (1 + |y|)): rounding
    ENCLOSURE_TRIES = 10             # a priori enclosure attempts before the comparison bound
    ENCLOSURE_GROW = 2.0             # inflation of the extents of T(X_k), then of the last T(S) ..
    ENCLOSURE_MULT = 1.0             # .. times this per failed attempt (2.0: the former doubling)
    SUBSTEP_RHO_H = 0.3              # substeps so that hs * rho(|A|) <= this at the band's top speed
    CACHE_SIZE = 64                  # compiled (design, mode, h) maps kept per process
    # the largest communication step (``max_communication_step``): the bounds must forget an initial error at
    # least this fast (1/s) at every probed speed, probed over this long (s), at this resolution (s)
    MAX_COMM_STEP_DECAY = 1.0
    MAX_COMM_STEP_PROBE = 1.0
    MAX_COMM_STEP_RESOLUTION = 1e-3
    MAX_COMM_STEP_CEILING = 1.0           # s: the longest step probed
    PRODUCT = "hull"                 # [dA][x]: "hull" exact interval product, "eq21" the bound of eq. (21)
    # the stiffness part dA x + vx dB1 delta (of omega and of G): "structured" through the slip
    # angles (``_emit_structured``; needs the design file's stiffness_box and the relaxation model
    # of eq. 9, checked), "elementwise" [dA][x] + vx [dB1] delta entry by entry (``PRODUCT``)
    STIFFNESS = "structured"
    # the sampled-measurement correction (``_sampled_predict``, ``_sampled_correct``), intersected
    # with the continuous one; its substep (s)
    SAMPLED = True
    SAMPLED_SUBSTEP = 0.005
    # below this step (s) the sampled correction is not used: its gains grow like 1/h^2 and
    # amplify the plant's departures from the model (a four-wheel plant with atan slip angles left
    # its bounds by 0.1-0.4 mm/s at 5 ms), where the continuous correction alone is tight
    SAMPLED_MIN_STEP = 0.01
    SAMPLED_MAX_SUBSTEPS = 32
    SAMPLED_DV = 0.1         # m/s: the model speed of the sampled maps, vx rounded to this grid
    SAMPLED_CACHE = 128      # (speed, step) maps kept per process

    def __init__(self, data: dict, params: dict | None = None):
        params = dict(params or {})
        try:
            self._read(data)
            self._read_structure(data)
        except (KeyError, TypeError, IndexError) as exc:
            raise ValueError(f"design file lacks {exc} needed by the paper-001 interval observer runtime") from exc
        self.vx_hold = float(params.get("vx_hold", self._vx_hold_default))
        if not (math.isfinite(self.vx_hold) and self.vx_hold >= 0):
            raise ValueError(f"parameter vx_hold must be finite and >= 0 m/s, got {self.vx_hold}")
        self._key = repr((self.model, self.modes, self.edges, self.eta, self.PRODUCT, self.STIFFNESS))
        self._data = data
        self._S = None
        self._G = _cached((self._key, "G"), lambda: _compile(_source_G(self.model, self.PRODUCT), "G"),
                          self.CACHE_SIZE)
        self._enclose = _cached((self._key, "enclose", self.ENCLOSURE_TRIES, self.ENCLOSURE_GROW, self.ENCLOSURE_MULT),
                                lambda: _compile(_source_enclose(self.model, self.ENCLOSURE_TRIES,
                                                                 self.ENCLOSURE_GROW, mult=self.ENCLOSURE_MULT),
                                                "enclose", G=self._G),
                                self.CACHE_SIZE)
        self._predict = _cached((self._key, "predict"), lambda: _compile(_source_predict(self.model), "predict",
                                                                          G=self._G), self.CACHE_SIZE)
        self._damped = _damped_rows(self.model)
        self._rho = [self._perron(self._majorant(max(abs(m["vx"]), self.edges[i + 1]), undamped=True))
                     for i, m in enumerate(self.modes)]
        self._cores: dict = {}
        self.mode = 0                       # 0-based; the output is 1-based
        self.box = [0.0] * (2 * _N)         # [xl0..xl3, xu0..xu3]: the published bounds of x
        self._xi = None                     # xi bounds [lo0..3, hi0..3] of P x at the current time ..
        self._xi_mode = -1                  # .. for the P of this mode
        self._pending = None                # the step awaiting its correction (see ``step``)
        self._vx = max(self.vx_hold, 1e-3)  # the speed of the published beta bounds
        self._started = False
        self._holding = False
        self._outside = False
        self._inconsistent = False
        self._fallback_episode = False
        self._fallback_steps = 0
        self.events: list[tuple[str, str]] = []
        self.y: dict = {name: 0.0 for name in OUTPUT_NAMES}
        self.y["mode"] = 1
        self.y["consistent"] = 1

    @classmethod
    def parameter_defaults(cls, data: dict) -> dict:
        return {"vx_hold": float(data.get("runtime", {}).get("vx_hold", cls.PARAMETERS["vx_hold"]))}

    # -- design file ------------------------------------------------------------------------
    def _read(self, data: dict) -> None:
        md = data["model"]
        model = {k: _matrix(md[k], _N, _N, f"model.{k}") for k in ("A0", "A1", "dA_lower", "dA_upper")}
        model.update({k: _vector(md[k], _N, f"model.{k}") for k in ("B1", "dB1_lower", "dB1_upper")})
        C = _matrix(md["C"], 2, _N, "model.C")
        meas = []
        for k, row in enumerate(C):
            ones = [j for j, c in enumerate(row) if c == 1.0]
            if len(ones) != 1 or any(c != 0.0 for j, c in enumerate(row) if j != ones[0]):
                raise ValueError(f"design file: model.C row {k + 1} must select one state (zeros and one 1), got {row}")
            meas.append(ones[0])
        if meas != [1, 2]:
            raise ValueError(f"design file: model.C must measure [r, ay] = states 2 and 3, got states "
                             f"{[j + 1 for j in meas]}")
        for lo, hi in (("dA_lower", "dA_upper"), ("dB1_lower", "dB1_upper")):
            a, b = model[lo], model[hi]
            flat = zip(sum(a, []), sum(b, [])) if lo == "dA_lower" else zip(a, b)
            if any(x > y for x, y in flat):
                raise ValueError(f"design file: model.{lo} must be <= model.{hi} elementwise")
        for k in ("m", "Iz", "lf", "lr"):
            v = float(md[k])
            if not (v > 0 and math.isfinite(v)):
                raise ValueError(f"design file: model.{k} must be finite and > 0, got {md[k]!r}")
            model[k] = v
        self.model, self.C, self.meas = model, C, meas
        self.unmeas = [j for j in range(_N) if j not in meas]
        sw = data["switching"]
        if sw.get("kind") != "speed_bands":
            raise ValueError(f"design file: switching.kind must be 'speed_bands', got {sw.get('kind')!r}")
        self.edges = [float(e) for e in sw["edges"]]
        if len(self.edges) < 2 or not all(math.isfinite(e) for e in self.edges) or \
                any(b <= a for a, b in zip(self.edges, self.edges[1:])):
            raise ValueError(f"design file: switching.edges must be >= 2 finite increasing speeds, got {sw['edges']}")
        rt = data["runtime"]
        self._vx_hold_default = float(rt.get("vx_hold", self.PARAMETERS["vx_hold"]))
        self.nu = _vector(rt.get("y_error_bound", [0.0, 0.0]), 2, "runtime.y_error_bound")
        self.w0 = _vector(rt["x0_halfwidth"], _N, "runtime.x0_halfwidth")
        model["w"] = _vector(rt.get("disturbance_bound", [0.0] * _N), _N, "runtime.disturbance_bound")
        if any(v < 0 for v in self.nu + self.w0 + model["w"]):
            raise ValueError("design file: runtime.y_error_bound, runtime.x0_halfwidth and "
                             "runtime.disturbance_bound must be >= 0")
        self._max_comm_step = rt.get("max_communication_step")   # the design's, else decided here
        if self._max_comm_step is not None:
            self._max_comm_step = float(self._max_comm_step)
            if not (math.isfinite(self._max_comm_step) and self._max_comm_step >= 0):
                raise ValueError("design file: runtime.max_communication_step must be finite and >= 0 s, got "
                                 f"{rt['max_communication_step']!r}")
        eta = float(rt.get("eta", 0.0))
        if not (math.isfinite(eta) and eta >= 0):
            raise ValueError(f"design file: runtime.eta must be finite and >= 0, got {rt.get('eta')!r}")
        modes = data["modes"]
        if len(modes) != len(self.edges) - 1:
            raise ValueError(f"design file: {len(self.edges) - 1} speed bands need as many modes, got {len(modes)}")
        self.modes = []
        eye = [[1.0 if i == j else 0.0 for j in range(_N)] for i in range(_N)]
        A0, A1, B1 = model["A0"], model["A1"], model["B1"]
        for k, m in enumerate(modes):
            where = f"mode {k + 1}"
            if int(m["index"]) != k + 1:
                raise ValueError(f"design file: {where} has index {m['index']!r}, expected {k + 1}")
            vx = float(m["vx"])
            if not math.isfinite(vx):
                raise ValueError(f"design file: {where} field vx must be finite, got {m['vx']!r}")
            g = {key: _matrix(m[key], _N, _N, f"{where} field {key}") for key in ("N", "P")}
            g.update({key: _matrix(m[key], _N, 2, f"{where} field {key}") for key in ("E", "J", "K")})
            g["H"] = _vector(m["H"], _N, f"{where} field H")
            N, P, E, J, K, H = (g[key] for key in ("N", "P", "E", "J", "K", "H"))
            scale = max(abs(x) for r in N for x in r)
            for i in range(_N):
                for j in range(_N):
                    if i != j and N[i][j] < 0:
                        if N[i][j] < -self.TOL * scale:
                            raise ValueError(f"design file: {where} field N is not Metzler: N[{i + 1}][{j + 1}] = "
                                             f"{N[i][j]!r} < 0 (the bounds would not stay ordered, Lemma 2)")
                        N[i][j] = 0.0    # rounding-level negative: exactly 0 (order preservation)
            EC = _matmul(E, C)
            checks = (("P", P, [[eye[i][j] - EC[i][j] for j in range(_N)] for i in range(_N)], "P = I - E C"),
                      ("J", J, [[a + b for a, b in zip(rk, rne)] for rk, rne in zip(K, _matmul(N, E))],
                       "J = K + N E (30a)"))
            Aj = [[a + vx * b for a, b in zip(r0, r1)] for r0, r1 in zip(A0, A1)]
            KC = _matmul(K, C)
            PA = _matmul(P, Aj)
            N33 = [[PA[i][j] - KC[i][j] for j in range(_N)] for i in range(_N)]
            checks += (("N", N, N33, "N = P A_j - K C (33), A_j = A0 + vx_j A1"),
                       ("H", [H], [_matvec(P, [vx * b for b in B1])], "H = P B_j (30b), B_j = vx_j B1"))
            for field, got, want, rel in checks:
                err = _rel(got, want)
                if not err <= self.TOL:
                    raise ValueError(f"design file: {where} field {field} violates {rel}: relative error {err:.3g} "
                                     f"> {self.TOL:g}")
            g["vx"] = vx
            g["eta"] = max(eta, max(-N[i][i] for i in range(_N)), 0.0)   # N + eta I >= 0
            self.modes.append(g)
        self.eta = eta

    def _read_structure(self, data: dict) -> None:
        """``model["stiff"]``: what the structured stiffness bound needs, from the design file's
        stiffness_box and model.{sigma, Cf, Cr}, after checking that the file's model IS the
        relaxation model of eq. (9) around (Cf, Cr) with that box: A0's stiffness entries (rows 3,
        4, columns 1, 2) and B1 at (Cf, Cr), and dA, dB1's elementwise bounds = their extremes
        over the box's vertices (zero elsewhere). Then dA(dc) x + vx dB1(dc) d is exactly the slip-
        angle form of ``_emit_structured`` for every dc in the box, and both bounds describe the
        same uncertainty. ``model["stiff"]`` = None for ``STIFFNESS = "elementwise"``."""
        model = self.model
        if self.STIFFNESS == "elementwise":
            model["stiff"] = None
            return
        if self.STIFFNESS != "structured":
            raise ValueError(f"STIFFNESS must be 'structured' or 'elementwise', got {self.STIFFNESS!r}")
        md, sb = data["model"], data["stiffness_box"]
        vals = {}
        for k in ("sigma", "Cf", "Cr"):
            vals[k] = v = float(md[k])
            if not (v > 0 and math.isfinite(v)):
                raise ValueError(f"design file: model.{k} must be finite and > 0, got {md[k]!r}")
        box = {}
        for k in ("Cf", "Cr"):
            b = _vector(sb[k], 2, f"stiffness_box.{k}")
            if not 0 < b[0] <= b[1]:
                raise ValueError(f"design file: stiffness_box.{k} must be 0 < lower <= upper, got {sb[k]!r}")
            box[k] = b
        m, Iz, lf, lr, sg = model["m"], model["Iz"], model["lf"], model["lr"], vals["sigma"]
        ms, Is = m * sg, Iz * sg

        def block(cf, cr):    # A0's stiffness entries (rows 3, 4; columns 1, 2) and B1's (rows 3, 4)
            return ([[-(cf + cr) / ms, (cr * lr - cf * lf) / ms],
                     [(cr * lr - cf * lf) / Is, -(cf * lf * lf + cr * lr * lr) / Is]],
                    [cf / ms, cf * lf / Is])

        Cf, Cr = vals["Cf"], vals["Cr"]
        A0n, B1n = block(Cf, Cr)
        corners = [block(cf, cr) for cf in box["Cf"] for cr in box["Cr"]]
        rows, cols = (2, 3), (0, 1)
        want = {k: [[0.0] * _N for _ in range(_N)] for k in ("dA_lower", "dA_upper")}
        want.update({k: [0.0] * _N for k in ("dB1_lower", "dB1_upper")})
        for a, i in enumerate(rows):
            for b, j in enumerate(cols):
                vs = [c[0][a][b] - A0n[a][b] for c in corners]
                want["dA_lower"][i][j], want["dA_upper"][i][j] = min(vs), max(vs)
            vs = [c[1][a] - B1n[a] for c in corners]
            want["dB1_lower"][i], want["dB1_upper"][i] = min(vs), max(vs)
        checks = [("model.A0", [[model["A0"][i][j] for j in cols] for i in rows], A0n),
                  ("model.B1", [[model["B1"][i] for i in rows]], [B1n])]
        checks += [(f"model.{k}", model[k] if k.startswith("dA") else [model[k]],
                    want[k] if k.startswith("dA") else [want[k]]) for k in want]
        for what, got, ref in checks:
            err = _rel(got, ref)
            if not err <= self.TOL:
                raise ValueError(f"design file: {what} is not the relaxation model (eq. 9) of model.Cf, model.Cr "
                                 f"and stiffness_box (relative error {err:.3g}): the structured stiffness bound "
                                 "needs it (STIFFNESS = 'elementwise' does not)")
        dcf, dcr = (box["Cf"][0] - Cf, box["Cf"][1] - Cf), (box["Cr"][0] - Cr, box["Cr"][1] - Cr)

        def symmetric(lo, hi):
            return abs(lo + hi) <= 1e-9 * (hi - lo)

        model["stiff"] = {"rows": rows, "cols": cols, "lf": lf, "lr": lr, "k3": 1.0 / ms, "k4f": lf / Is,
                          "k4r": lr / Is, "dcf": dcf, "dcr": dcr,
                          "symmetric": symmetric(*dcf) and symmetric(*dcr)}

    def stiffness_bounds(self, vx: float, d: float, box):
        """(lower0..3, upper0..3): the runtime's bound of dA(dc) x + vx dB1(dc) d over x in the box
        [box[:4], box[4:]] and the stiffness box (``STIFFNESS``); compiled on first use."""
        if self._S is None:
            self._S = _cached((self._key, "S"), lambda: _compile(_source_stiffness(self.model, self.PRODUCT), "S"),
                              self.CACHE_SIZE)
        return self._S(vx, d, *box)

    def _majorant(self, vx: float, undamped: bool = False):
        """Metzler majorant of A(vx, c) over the stiffness box: the largest diagonal entries and
        the largest |off-diagonal| entries (``undamped``: the damped rows' diagonal set to 0, as the
        a priori enclosure treats it exactly)."""
        md = self.model
        M = [[0.0] * _N for _ in range(_N)]
        for i in range(_N):
            for j in range(_N):
                a = md["A0"][i][j] + vx * md["A1"][i][j]
                lo, hi = a + md["dA_lower"][i][j], a + md["dA_upper"][i][j]
                M[i][j] = hi if i == j else max(abs(lo), abs(hi))
            if undamped and i in self._damped:
                M[i][i] = 0.0
        return M

    @staticmethod
    def _perron(M) -> float:
        """Spectral radius of |M| (power iteration on a nonnegative matrix; an upper estimate)."""
        A = [[abs(x) for x in row] for row in M]
        v = [1.0] * _N
        lam = 0.0
        for _ in range(200):
            w = [sum(a * b for a, b in zip(row, v)) + 1e-300 for row in A]
            lam = max(w) / max(v)
            s = max(w)
            v = [x / s for x in w]
        return lam

    # -- step maps ----------------------------------------------------------------------------
    def _core(self, mode: int, h: float) -> _Core:
        """The correction of (mode, h), compiled once per process (cached), and the enclosure's
        substeps: hs = h / nsub with hs rho(|A|) <= SUBSTEP_RHO_H at the band's top speed (rho
        without the damped diagonal), so that the enclosure succeeds at the first or second try."""
        core = self._cores.get((mode, h))
        if core is None:
            nsub = max(1, math.ceil(h * self._rho[mode] / self.SUBSTEP_RHO_H - 1e-9))

            def build():
                m = self.modes[mode]
                maps = phi_gamma(m["N"], h, m["eta"], order=3)
                src = _source_correct(self.model, m, h, maps, self.meas, self.PRODUCT)
                return _Core(_compile(src, "correct", G=self._G), nsub, h / nsub)

            core = _cached((self._key, mode, h), build, self.CACHE_SIZE)
            if len(self._cores) >= 4 * self.CACHE_SIZE:
                self._cores.clear()
            self._cores[(mode, h)] = core
        return core

    def F(self, vx: float, d: float, box):
        """(lower0..3, upper0..3): the hull of A(vx, c) x + B(vx, c) d over x in the box
        [box[:4], box[4:]] and c in the stiffness box (G plus the damped rows' diagonal terms)."""
        f = list(self._G(vx, d, *box))
        for i in self._damped:
            t = self.model["A0"][i][i] + vx * self.model["A1"][i][i]
            lo, hi = (t * box[i], t * box[_N + i]) if t >= 0 else (t * box[_N + i], t * box[i])
            f[i] += lo
            f[_N + i] += hi
        return f

    def _comparison_enclosure(self, hs, vx, d, box):
        """Fallback a priori enclosure for any hs: with f0 = A x_k + B d in F(X_k), d(s) = x(s) - x_k
        obeys |d|' <= M |d| + g (M the Metzler majorant, g = max |F(X_k)|), hence (comparison
        principle, M Metzler) |d(s)| <= int_0^s exp(M t) g dt <= Gamma(M, hs) g for s <= hs."""
        f = self.F(vx, d, box)
        g = [max(abs(f[i]), abs(f[_N + i])) for i in range(_N)]
        M = self._majorant(vx)
        shift = max(0.0, max(-M[i][i] for i in range(_N)))
        _, Gam = phi_gamma(M, hs, shift)
        R = _matvec(Gam, g)
        S = [box[i] - R[i] for i in range(_N)] + [box[_N + i] + R[i] for i in range(_N)]
        f = self.F(vx, d, S)              # x(s) in X_k + [0, hs] F(S) as well
        T = [box[i] + min(0.0, hs * f[i]) for i in range(_N)] + [box[_N + i] + max(0.0, hs * f[_N + i])
                                                                 for i in range(_N)]
        return [max(S[i], T[i]) for i in range(_N)] + [min(S[_N + i], T[_N + i]) for i in range(_N)]

    # -- stepping -----------------------------------------------------------------------------
    def _band(self, vx: float) -> int:
        """Eq. (44): mode i on [edges[i], edges[i + 1]); outside the grid the nearest mode, with
        one warning per excursion."""
        edges = self.edges
        if edges[0] <= vx <= edges[-1]:
            self._outside = False
        else:
            if not self._outside:
                self.events.append(("warning", f"vx = {vx:.4g} m/s outside the design grid [{edges[0]:.4g}, "
                                               f"{edges[-1]:.4g}] m/s: the nearest mode is used (the speed "
                                               "mismatch is bounded exactly, the bounds widen)"))
            self._outside = True
        i = bisect_right(edges, vx) - 1
        return 0 if i < 0 else min(i, len(self.modes) - 1)

    def _restart(self, y, keep: bool) -> None:
        """Initial box: measured states y +- nu, the others +-x0_halfwidth (hull with the current
        bounds if ``keep``); no xi, no pending correction."""
        box = self.box
        for k, j in enumerate(self.meas):
            box[j], box[_N + j] = y[k] - self.nu[k], y[k] + self.nu[k]
        for j in self.unmeas:
            lo, hi = -self.w0[j], self.w0[j]
            if keep:
                lo, hi = min(lo, box[j]), max(hi, box[_N + j])
            box[j], box[_N + j] = lo, hi
        self._xi = None
        self._xi_mode = -1
        self._pending = None

    # -- the sampled-measurement correction ---------------------------------------------------------
    def _sampled_maps(self, vx: float, h: float) -> _Sampled:
        """``sampled_maps`` of (vx, h), cached per process (the last ``SAMPLED_CACHE``)."""
        key = (self._key, vx, h, self.SAMPLED_SUBSTEP, self.SAMPLED_MAX_SUBSTEPS)
        with _LOCK:
            sm = _SAMPLED.get(key)
            if sm is None:
                sm = sampled_maps(self.model, self.meas, vx, h, self.SAMPLED_SUBSTEP, self.SAMPLED_MAX_SUBSTEPS)
                _SAMPLED[key] = sm
                while len(_SAMPLED) > self.SAMPLED_CACHE:
                    _SAMPLED.pop(next(iter(_SAMPLED)))
        return sm

    def _sampled_predict(self, h: float, vx: float, d: float, X):
        """The box of x(t + h) from the box X of x(t) by the model alone (no output injection), and
        what ``_sampled_correct`` needs: with A, Bv the nominal model at vx (``sampled_maps``),
            x(s) = exp(A s) x(t) + int_0^s exp(A u) du Bv d + int_0^s exp(A (s - u)) omega(u) du,
        omega = dA(c) x + vx dB1(c) d + w the stiffness part (any stiffness in the box, constant or
        not) and the disturbance. Over substep m, omega lies in the bound of the stiffness part over
        the a priori enclosure T_m of x over the substep (``_enclose`` from the box at its start;
        ``stiffness_bounds``; +-w): [mo_m - ro_m, mo_m + ro_m]. The box at s_m = m hs is then, in
        midpoint-radius form without wrapping (every term from x(t), ``sampled_maps``),
            phi[m] c0 + gamb[m] d + sum_i<m pg[m-1-i] mo_i  +-  aphi[m] r0 + sum_i<m apg[m-1-i] ro_i.
        (None if an enclosure is not finite.)"""
        vq = self.SAMPLED_DV * round(vx / self.SAMPLED_DV)
        sm = self._sampled_maps(vq, h)
        c0 = [(X[i] + X[_N + i]) * 0.5 for i in range(_N)]
        r0 = [(X[_N + i] - X[i]) * 0.5 for i in range(_N)]
        w = self.model["w"]
        A1, B1 = self.model["A1"], self.model["B1"]
        dv = vx - vq
        adv = abs(dv)
        mo, ro = [], []
        for m in range(sm.n + 1):
            c = _addv(_matvec(sm.phi[m], c0), [g * d for g in sm.gamb[m]])
            r = _matvec(sm.aphi[m], r0)
            for i in range(m):
                c = _addv(c, _matvec(sm.pg[m - 1 - i], mo[i]))
                r = _addv(r, _matvec(sm.apg[m - 1 - i], ro[i]))
            Bm = [a - b for a, b in zip(c, r)] + [a + b for a, b in zip(c, r)]
            if m == sm.n:
                break
            T = self._enclose(sm.hs, vx, d, *Bm)
            if T is None:
                T = self._comparison_enclosure(sm.hs, vx, d, Bm)
            S = self.stiffness_bounds(vx, d, T)
            tc = [(T[i] + T[_N + i]) * 0.5 for i in range(_N)]
            tr = [(T[_N + i] - T[i]) * 0.5 for i in range(_N)]
            mo.append([(S[i] + S[_N + i]) * 0.5 + dv * (sum(a * x for a, x in zip(A1[i], tc)) + B1[i] * d)
                       for i in range(_N)])
            ro.append([(S[_N + i] - S[i]) * 0.5 + w[i] + adv * sum(abs(a) * x for a, x in zip(A1[i], tr))
                       for i in range(_N)])
        if not all(map(math.isfinite, Bm)):
            return None, None
        return Bm, (sm, c0, r0, d, mo, ro)

    def _sampled_correct(self, state, Y):
        """The box of x(t + h) once the measured states at t + h are known to lie in [yl, yu] = Y:
        for every gain L of ``sampled_maps``, x(t + h) = (I - L C) x(t + h) + L y(t + h) exactly,
        bounded (midpoint-radius, K = I - L C) by
            K phi[n] c0 + K gamb[n] d + sum_i K pg[n-1-i] mo_i + L yc
            +- |K phi[n]| r0 + sum_i |K phi[n-1-i]| Gam_M ro_i + |L| yr;
        every gain gives an enclosure, so the rows are intersected over the gains. (A continuous-
        discrete interval observer: the measurements enter only at the samples, so the remainders
        of y between them that limit the continuous correction do not arise; not in the paper.)"""
        sm, c0, r0, d, mo, ro = state
        k = len(self.meas)
        yc = [(Y[q] + Y[k + q]) * 0.5 for q in range(k)]
        yr = [(Y[k + q] - Y[q]) * 0.5 for q in range(k)]
        n = sm.n
        lo, hi = [-_INF] * _N, [_INF] * _N
        for L, Kphi, aKphi, Kgb, Kpg, aKpg, aL in sm.cands:
            c = _addv(_addv(_matvec(Kphi, c0), [g * d for g in Kgb]), _matvec(L, yc))
            r = _addv(_matvec(aKphi, r0), _matvec(aL, yr))
            for i in range(n):
                c = _addv(c, _matvec(Kpg[n - 1 - i], mo[i]))
                r = _addv(r, _matvec(aKpg[n - 1 - i], ro[i]))
            for i in range(_N):
                if c[i] - r[i] > lo[i]:
                    lo[i] = c[i] - r[i]
                if c[i] + r[i] < hi[i]:
                    hi[i] = c[i] + r[i]
        return lo + hi

    # -- the longest communication step -----------------------------------------------------------
    def max_communication_step(self) -> float:
        """The longest communication step (s) this design accepts: ``step`` refuses a longer one.

        The measurements arrive only at the communication points. Between two of them the
        continuous correction (``_source_correct``) bounds y(s) by the samples at both ends and a
        remainder that grows with the bounds' own width, times the output-injection gains J (the
        width feedback grows like h^2 |J|); the sampled-measurement correction intersected with it
        (``_sampled_correct``) has no such feedback, but over a long step the enclosures of the
        trajectory, hence the stiffness part, grow with h, and from some step on (sedan: ~0.45 s at
        10 m/s) even the intersection stops forgetting an initial error: longer steps are refused.
        The bound is decided from the design itself, by running this runtime: from
        the initial box (+-x0_halfwidth on vy and x4) at zero inputs (then the width map is
        positively homogeneous: its decay rate is the rate at which any initial error is forgotten,
        the signals only add constant terms), at every band edge (both sides) and grid speed, the
        widths of vy and x4 must decay at >= ``MAX_COMM_STEP_DECAY`` (1/s) between
        MAX_COMM_STEP_PROBE/2 and MAX_COMM_STEP_PROBE seconds. The decay rate falls with h (sedan,
        +-20 %, the slowest probed speed: ~5 /s at 5 ms, ~150 /s at 10 ms, ~78 /s at 20 ms, ~3 /s at 200 ms,
        0.7 /s at 0.5 s, < 0 at 1 s); the largest step on a
        ``MAX_COMM_STEP_RESOLUTION`` grid up to ``MAX_COMM_STEP_CEILING`` that passes is found by
        bisection (0.0: none, every step refused). This is a measured decay, not a proof (the
        enclosure itself is guaranteed at any accepted step; the decay is what keeps it narrow).
        The design stores it (runtime.max_communication_step, from the synthesis, which calls
        this); a design file without it gets it computed here once per process. The native C model gets the same value as a constant
        (IV_MAX_COMM_STEP, from the emitter)."""
        if self._max_comm_step is not None:
            return self._max_comm_step
        key = (self._key, self.ENCLOSURE_TRIES, self.ENCLOSURE_GROW, self.ENCLOSURE_MULT, self.SUBSTEP_RHO_H,
               self.MAX_COMM_STEP_DECAY, self.MAX_COMM_STEP_PROBE, self.MAX_COMM_STEP_RESOLUTION,
               self.MAX_COMM_STEP_CEILING)
        with _LOCK:
            hmax = _MAX_COMM_STEP.get(key)
            if hmax is None:
                hmax = _MAX_COMM_STEP[key] = self._find_max_communication_step()
        return hmax

    def _probe_speeds(self) -> list[float]:
        """Every grid speed and band edge, an interior edge from both sides (eq. 44's half-open bands)."""
        e = self.edges
        below = [math.nextafter(x, -math.inf) for x in e[1:-1]]
        return sorted(set(e) | set(below) | {m["vx"] for m in self.modes if e[0] <= m["vx"] <= e[-1]})

    def decay_rate(self, h: float, vx: float, probe: "IntervalObserver | None" = None) -> float:
        """The rate (1/s) at which the widths of vy and x4 decay at step h and speed vx, zero inputs
        (the slower of the two, between MAX_COMM_STEP_PROBE/2 and MAX_COMM_STEP_PROBE; -inf if they do not
        stay finite or the bounds restart). ``probe``: an instance of this design to run (reset)."""
        if probe is None:
            probe = type(self)(self._probe_data(), {"vx_hold": 0.0})
        probe.events.clear()
        probe._holding = probe._outside = probe._inconsistent = probe._fallback_episode = False
        u = {"delta": 0.0, "vx": vx, "yaw_rate": 0.0, "ay": 0.0}
        probe.initialize(u)
        n = max(8, math.ceil(self.MAX_COMM_STEP_PROBE / h))
        half = n // 2
        rate = math.inf
        for k in range(n):
            probe._advance(h, u)
            w = (probe.box[_N] - probe.box[0], probe.box[2 * _N - 1] - probe.box[_N - 1])
            if k == half - 1:
                w_half = w
        if any(e[0] == "warning" for e in probe.events):
            return -math.inf                 # a restart (non-finite bounds) or an inconsistency
        for a, b in zip(w_half, w):
            if not (math.isfinite(b) and a > 0.0):
                return -math.inf
            if b > 0.0:
                rate = min(rate, math.log(a / b) / ((n - half) * h))
        return rate

    def _probe_data(self) -> dict:
        """The design file without its disturbance bound (runtime.disturbance_bound = 0): the probes
        of ``decay_rate`` measure how fast an initial error is forgotten, which the width map at
        zero inputs shows when it is positively homogeneous; a disturbance bound adds a constant
        floor that a fast correction reaches within the probe (then no decay is left to measure)."""
        data = dict(self._data)
        data["runtime"] = {**self._data["runtime"], "disturbance_bound": [0.0] * _N}
        return data

    def _find_max_communication_step(self) -> float:
        res = self.MAX_COMM_STEP_RESOLUTION
        speeds = self._probe_speeds()
        probe = type(self)(self._probe_data(), {"vx_hold": 0.0})

        def ok(k: int) -> bool:
            for i, v in enumerate(speeds):
                if not self.decay_rate(k * res, v, probe) >= self.MAX_COMM_STEP_DECAY:
                    speeds.insert(0, speeds.pop(i))       # the failing speed first next time
                    return False
            return True

        lo, hi = 0, int(round(self.MAX_COMM_STEP_CEILING / res)) + 1
        while hi - lo > 1:                   # the decay rate falls with h: bisection
            mid = (lo + hi) // 2
            if ok(mid):
                lo = mid
            else:
                hi = mid
        return round(lo * res, 12)

    def initialize(self, u: dict) -> None:
        """The bounds at the start: vy in +-x0_halfwidth[0], x4 in +-x0_halfwidth[3], the measured
        yaw rate and ay +-y_error_bound; the mode of the initial speed; outputs published."""
        y = (u["yaw_rate"], u["ay"])
        self._restart(y, keep=False)
        vx = u["vx"]
        if abs(vx) >= self.vx_hold and abs(vx) > 0:
            self.mode = self._band(vx)
            self._vx = vx
        self._started = True
        self.y["consistent"] = 1
        self._publish()

    def step(self, h: float, u: dict) -> None:
        """Advance from t to t + h with the inputs u (at t, held): (1) the measurement at t
        against the published box, (2) the correction of the previous step [t - h', t] now that
        y(t) is known (eq. 23, ``_source_correct``), (3) the mode of vx, (4) the enclosure T of x
        over [t, t + h] and the predicted box at t + h (``predict``), published; the correction of
        this step waits for the measurement at t + h (the observer runs one step behind the
        published prediction, which is itself a guaranteed bound)."""
        h = float(h)          # a numpy float would print as np.float64(...) into the generated code
        hmax = self.max_communication_step()
        if not h <= hmax:     # refused before anything changes: the state is kept
            raise ValueError(f"communication step {h:g} s refused: longer than {hmax:g} s, the longest step at "
                             "which this design's bounds contract (the measurements arrive only at the "
                             "communication points: over a longer step the bounds of the trajectory grow "
                             f"faster than one sample narrows them); use a step <= {hmax:g} s")
        self._advance(h, u)

    def _advance(self, h: float, u: dict) -> None:
        """``step`` without the check of h against ``max_communication_step`` (for its probes)."""
        if not self._started:
            self.initialize(u)
        vx, d = u["vx"], u["delta"]
        y = (u["yaw_rate"], u["ay"])
        hold = self.vx_hold
        if -hold < vx < hold or vx == 0.0:
            if not self._holding:
                self.events.append(("warning", f"|vx| = {abs(vx):.3g} m/s < vx_hold = {hold:g} m/s: interval "
                                               "observer frozen, bounds held"))
            self._holding = True
            self._pending = None
            return
        box = self.box
        if self._holding:
            self.events.append(("warning", f"vx = {vx:.3g} m/s: interval observer resumes; the bounds restart "
                                           "from the measurement and x0_halfwidth"))
            self._holding = False
            self._restart(y, keep=False)
        # 1. measurement intersection (DEPARTURE, see the module docstring: a tightening)
        consistent = 1
        for k, j in enumerate(self.meas):
            lo, hi = box[j], box[_N + j]
            ml, mu = y[k] - self.nu[k], y[k] + self.nu[k]
            if ml > lo:
                lo = ml
            if mu < hi:
                hi = mu
            if lo > hi:
                if lo - hi <= self.CONSISTENCY_TOL * (1.0 + abs(y[k])):
                    lo, hi = hi, lo            # rounding: the gap itself
                else:
                    consistent = 0
            box[j], box[_N + j] = lo, hi
        if not consistent:
            if not self._inconsistent:
                self.events.append(("warning", f"measurement (yaw_rate = {y[0]:.4g} rad/s, ay = {y[1]:.4g} m/s2) "
                                               "outside the bounds: the model does not hold (stiffness outside "
                                               "the box, saturated tires?); bounds restarted from the measurement "
                                               "and x0_halfwidth, consistent = 0"))
            self._inconsistent = True
            self._restart(y, keep=True)
        else:
            self._inconsistent = False
        self.y["consistent"] = consistent
        # 2. the correction of the previous step
        p = self._pending
        if p is not None:
            core_p, X, xi, T, Fb, vx_p, d_p, mode_p, sampled = p
            Y = [box[j] for j in self.meas] + [box[_N + j] for j in self.meas]
            out = core_p.correct(vx_p, d_p, *X, *xi, *T, *Fb, *Y, *box)
            if sampled is not None:      # intersected with the sampled-measurement correction
                out = list(out)
                sb = self._sampled_correct(sampled, Y)
                for i in range(_N):
                    lo, hi = max(out[i], sb[i]), min(out[_N + i], sb[_N + i])
                    if lo <= hi:
                        out[i], out[_N + i] = lo, hi
            if all(map(math.isfinite, out)):
                box[:] = out[:2 * _N]
                self._xi, self._xi_mode = out[2 * _N:], mode_p
            else:
                self.events.append(("warning", "bounds became non-finite: restarted from the measurement and "
                                               "x0_halfwidth"))
                self._restart(y, keep=False)
        # 3. the mode of this step
        self.mode = mode = self._band(vx)
        core = self._core(mode, h)
        # 4. the enclosure over [t, t + h] and the prediction at t + h
        X = tuple(box)
        fallback = False
        if core.nsub == 1:
            T = self._enclose(h, vx, d, *X)
            if T is None:
                fallback = True
                T = self._comparison_enclosure(h, vx, d, X)
            out = self._predict(h, vx, d, *X, *T)
            B = out[2 * _N:]
        else:                            # long steps: the enclosure from substeps
            hs, Xm, T = core.hs, X, None
            for _ in range(core.nsub):
                Tm = self._enclose(hs, vx, d, *Xm)
                if Tm is None:
                    fallback = True
                    Tm = self._comparison_enclosure(hs, vx, d, Xm)
                Xm = self._predict(hs, vx, d, *Xm, *Tm)[2 * _N:]
                T = Tm if T is None else [min(a, b) for a, b in zip(T[:_N], Tm[:_N])] + \
                    [max(a, b) for a, b in zip(T[_N:], Tm[_N:])]
            out = self._predict(h, vx, d, *X, *T)
            B = [max(a, b) for a, b in zip(out[2 * _N:3 * _N], Xm[:_N])] + \
                [min(a, b) for a, b in zip(out[3 * _N:], Xm[_N:])]
        if fallback:
            self._fallback_steps += 1
            if not self._fallback_episode:
                self.events.append(("warning", f"a priori enclosure not found in {self.ENCLOSURE_TRIES} tries "
                                               f"(h = {h:g} s, vx = {vx:.4g} m/s): comparison bound used, wider"))
            self._fallback_episode = True
        else:
            self._fallback_episode = False
        if not all(map(math.isfinite, out)):
            self.events.append(("warning", "bounds became non-finite: restarted from the measurement and "
                                           "x0_halfwidth"))
            self._restart(y, keep=False)
        else:
            xi = self._xi if (self._xi is not None and self._xi_mode == mode) else _NO_XI
            sampled = None
            if self.SAMPLED and h >= self.SAMPLED_MIN_STEP:     # the box by the model alone, intersected
                try:
                    Bs, sampled = self._sampled_predict(h, vx, d, X)
                except (ValueError, OverflowError):   # no finite step map (|vx| near the double range): skipped
                    Bs = sampled = None
                if Bs is not None:
                    B = list(B)
                    for i in range(_N):
                        lo, hi = max(B[i], Bs[i]), min(B[_N + i], Bs[_N + i])
                        if lo <= hi:
                            B[i], B[_N + i] = lo, hi
            self._pending = (core, X, xi, tuple(T), out[:2 * _N], vx, d, mode, sampled)
            box[:] = B
        self._vx = vx
        self._publish()

    def _publish(self) -> None:
        xl0, xl1, xl2, xl3, xu0, xu1, xu2, xu3 = self.box
        md = self.model
        vx = self._vx
        out = self.y
        out["vy_lower"], out["vy_upper"] = xl0, xu0
        if vx > 0:
            out["beta_lower"], out["beta_upper"] = math.atan(xl0 / vx), math.atan(xu0 / vx)
        else:                              # reversing: atan(x / vx) decreases in x
            out["beta_lower"], out["beta_upper"] = math.atan(xu0 / vx), math.atan(xl0 / vx)
        out["yaw_rate_lower"], out["yaw_rate_upper"] = xl1, xu1
        L = md["lf"] + md["lr"]
        a, b, c = md["m"] * md["lr"] / L, md["Iz"] / L, md["m"] * md["lf"] / L
        # inverse of eq. (8); DEPARTURE from eq. (45) (misprint): Fyr's lower bound uses x4's upper
        out["Fyf_lower"], out["Fyf_upper"] = a * xl2 + b * xl3, a * xu2 + b * xu3
        out["Fyr_lower"], out["Fyr_upper"] = c * xl2 - b * xu3, c * xu2 - b * xl3
        out["mode"] = self.mode + 1
