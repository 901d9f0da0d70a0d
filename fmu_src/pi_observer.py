"""Runtime of the switched PI observer of paper 000 (Menhour et al., ECC 2014), eq. (5).

Standard library only; no FMI here (``framework.py`` does that). Reads a design file
(``latobs.synthesis.pi_hinf_000.to_design_dict``). States z (4) and w^ (1, bank angle):
    x^ = z + N y
    z'  = T A x^ + T B u + T F w^ + K_P (y - C x^)        (ERRATA 000; = eq. (5) with
    w^' = K_I (y - C x^)                                    Pi = T A - K_P C, K_p = K_P + Pi N)
u = delta (rad), y = [yaw rate (rad/s), roll angle (rad), roll rate (rad/s)], A, B, F the active
mode's model at its model speed. The extended state s = [z; w^] obeys the linear ODE
s' = M s + G w, w = [y; delta], integrated over one call of ``step(h, u)`` by classical RK4 with
n = ceil(h / max_step) equal substeps hs = h / n (``runtime.max_step``: the certificate proves
that step stable and accurate).

Design keys read. Required: structure.T/N/C; modes[i].model (A, B, F: coefficient lists in 1/vx),
modes[i].gains.K_P/K_I, modes[i].model_speed; switching ("speed_bands": edges; "tire_slip": lf,
lr, alpha_star, hysteresis); runtime.max_step; runtime.vx_hold (the parameter's default). Optional
(issue 9; absent: the behaviour before it):
  * modes[i].model_speed, per mode: {"kind": "fixed", "value": V} (the model at V m/s, eq. (25)
    literally) or {"kind": "measured", "range": [lo, hi]} (the model at the measured vx clamped
    to THIS mode's [lo, hi] m/s: LPV; speed bands: usually the mode's own band, tire modes: one
    range for both). Both kinds may be mixed;
  * runtime.input_hold: "zero_order" (default) or "first_order" (below);
  * validity: {"alpha_max" (rad), "ay_max" (m/s^2), "release" (in (0, 1)), "lf", "lr" (m; default
    the switching's), "freeze_integral" (default false)} (below).

Over a step [t, t + h] (t the start of the call):
  * held: the mode (chosen at t), the model speed (vx at t, clamped to the mode's range) and
    ``valid`` (decided at t);
  * the measurements w = [y; delta] follow the design's hold. Zero-order: w(t + tau) = w_k.
    First-order (causal, predictive): w(t + tau) = w_k + tau (w_k - w_{k-1}) / h_{k-1}, w_{k-1}
    and h_{k-1} the inputs and size of the previous step; slope 0 at the first step, after a
    frozen period (vx < vx_hold) and after ``initialize``. RK4 evaluates it at its stage times;
  * outputs are those at t + h: x^ = z + N y with the hold's y at t + h (zero-order: y_k;
    first-order: y_k + h (y_k - y_{k-1}) / h_{k-1}), bank_angle_hat = w^, mode, valid.
Hold error, measured (``tests/test_runtime_000_lpv.py::_hold_errors`` with t_end 4 s, the gains of
the default speed design when written: speed mode 2 at its grid speed 17.5 m/s, the smooth
measurements of ``test_fast_step_000.measurements``, 0.37 to 5.3 rad/s; error against the exact
solution of the same linear ODE with the continuous w(t), scipy DOP853 rtol 1e-12, max over
t in [1, 4] s):
                      h = 5 ms: beta^    bank^    x^      h = 1 ms: beta^    bank^    x^
    zero-order hold           4.4e-5   4.3e-4   1.3e-3            9.3e-6   8.6e-5   2.6e-4
    first-order hold          6.9e-7   3.5e-6   9.6e-6            2.6e-8   1.4e-7   3.8e-7
(rad and rad/s; x^ against the exact z + N y(t + h)): O(h) and O(h^2). Over [0, 4] s the
first-order maximum at 5 ms is 4.2e-5 (beta^) / 7.9e-5 (bank^), from the first step (slope 0),
which the slow bank integrator forgets slowly. The price of the first-order hold: the N y part of
r^, phi^, phidot^ extrapolates the measurement noise (variance x5 at constant h; beta^ and bank^
see it only through the integration), and a host that repeats the inputs between sensor
samples makes the slope alternate between 0 and steep: keep the zero-order hold there.

Modes: speed bands (eq. (25)): mode i on [edges[i], edges[i + 1]); tire modes (eq. (27)): on the
slip angles of eq. (2) from beta^, r^ at t (x^ = z + N y_k), with a hysteresis band.

``valid`` (design "validity"; without it valid = 1 always): at t, with beta^, r^ the estimates at
t (as the tire premise) and the measured vx, yaw rate, delta: alpha_f = delta - beta^ - lf r^/vx,
alpha_r = -beta^ + lr r^/vx. valid 1 -> 0 when max(|alpha_f|, |alpha_r|) > alpha_max or
|vx yaw_rate| > ay_max; 0 -> 1 only when both are below release x their limits (hysteresis).
While valid = 0 and freeze_integral: the integral action is frozen, i.e. the step uses M, G with
w^'s row zero: bank_angle_hat is held to the bit while z keeps integrating (with w^ held in
T F w^). One warning per entry into valid = 0, at most one per ``INVALID_LOG_PERIOD`` (1 s) of
simulated time (the sum of the steps); the next message counts the entries not logged, and
``invalid_entries`` counts them all.

How a step is computed (exactly that discretisation, without per-step matrix work):
  * RK4 on a linear ODE with held inputs is one affine map per substep, s+ = R s + S G w with
    X = hs M, R = I + X + X^2/2 + X^3/6 + X^4/24, S = hs (I + X/2 + X^2/6 + X^3/24); n substeps
    compose to s+ = Phi s + Gam w, Phi = R^n, Gam = (sum_{k<n} R^k) S G: the same numbers as n
    RK4 substeps up to rounding (~1e-16 relative), not another discretisation.
  * First-order hold: the hold becomes a state, [s; w]' = [[M, G], [0, 0]] [s; w] + [[0], [I/h]] e
    with the held input e = h (w_k - w_{k-1}) / h_{k-1} (the hold's increment over the step, in the
    units of w so that the truncation bound below weighs it like w). w is linear in time, so RK4
    on this system evaluates w exactly at the stage times: its maps ARE the RK4 substeps of
    s' = M s + G w(tau), built by the same machinery; their top rows give
    s+ = Phi s + Gam w_k + Gam_e e (13 columns instead of 9).
  * Map index: the mode i, or n_modes + i for mode i with the integral frozen (w^ row of M, G
    zero): separate maps, built and cached like the others.
  * Fixed-speed modes: Phi, Gam are computed once per (index, h) (binary powering) and compiled
    together with the outputs (x^ = z+ + N y, bank = w^+) into one straight-line function with
    the coefficients as literals (``_compile``). Measured on 5 states: 3x faster than prebuilt
    rows with ``sum(map(mul, row, v))``, 2x faster than numpy ``Phi @ s + Gam @ w``.
  * Measured-speed modes (tire modes, LPV speed modes): M and G are polynomials in v = 1/vx (the
    design file's A, B, F are coefficient lists in 1/vx; their coefficient matrices in v are
    formed once at construction), hence so is the step map [Phi | Gam](v). Per (index, h) the
    mode's own clamped range of v is cut into K equal intervals (``_TireTable``); on each, the
    map is replaced by its Taylor polynomial in v - v_c, exact coefficients computed by
    truncated matrix-series arithmetic, and terms are dropped (smallest first, per row) only
    while a rigorous bound of everything dropped (exact coefficients up to degree J, a majorant
    series beyond: ``_truncation_bound``) stays below ``TAYLOR_TOL`` = 1e-16 relative to
    ||[Phi | Gam]||, i.e. below the rounding of the map itself (a looser 1e-13 was measured to
    accumulate to 2e-12 through the slow bank integrator). Compiled like the fixed-speed maps
    (Horner in v - v_c), when first visited (~10 ms each at 5 ms). K is chosen so that about
    ``TAYLOR_DEGREE`` = 4 suffices: at 5 ms K = 75/65 for the tire modes over 6.25..28.75 m/s,
    51/16/8 for speed bands 6.25..13.75..21.25..28.75 m/s (the first-order hold: about the same);
    an interval whose bound cannot be met (very long steps) runs the RK4 substeps. Measured
    earlier on the tire modes (warm, 5 ms): degree 3: 3.9 us/step but 4x the intervals, degree
    4: 4.4, degree 5: 5.0, degree 6: 5.4; unrolled straight-line RK4 substeps with
    M(v) s = M0 s + v M1 s + v^2 M2 s (exact, no build): 11 us for the map alone at 5 ms,
    proportional to the substeps; the coefficients passed as a tuple to one compiled function
    instead of literals: +13 %.
  * Cost per step (warm, h = 5 ms, 3000 calls of ``step``, best of 15 interleaved runs on a
    loaded 2-core machine; before = the runtime without issue 9, same dicts): fixed-speed modes,
    zero-order hold 1.6 us (before 1.5), first-order 2.1 us (x1.45 of before); tire modes
    zero-order 4.6 us (before 4.3), first-order 6.1 us (x1.4), and with validity and freeze
    6.6 us; LPV speed modes zero-order 4.3 us, first-order 6.0 us, with validity 6.5 us. The
    first-order maps cost 13 columns instead of 9 (Gam_e is about Gam / 2: nothing to drop).
  * Maps are cached per process, keyed by the design (content fingerprint), map index and the
    float h, so that re-instantiating an FMU does not rebuild them; at most ``MAP_CACHE_SIZE``
    maps and ``MAX_COMPILED`` compiled functions (~15 kB each) are kept, oldest dropped. The
    first step of an instance with a given (index, h) runs the RK4 substeps directly: a host
    with ever-changing step sizes builds nothing, and which steps use a map depends only on the
    instance's own history, so results are bitwise reproducible whatever else ran in the process.

Documented clamps (never an exception for finite inputs):
  * vx < vx_hold (default 1 m/s, parameter, > 0), standstill AND reversing: integration frozen
    and every output held at its last value, ``valid`` included (the measurements are not even
    read; the first-order hold restarts with slope 0 afterwards), one warning per entry (the
    model has 1/Vx terms; at standstill sideslip is undefined; driving backwards the forward
    model is wrong);
  * vx outside the design grid (the band edges; tire modes: the union of the modes' ranges):
    speed bands use the nearest mode; a measured-speed model is evaluated at the nearest edge of
    its mode's range; one warning per excursion. (A mode whose range is narrower than its band
    clamps inside the grid too, silently: that is its design.)
  * ``initialize`` (at exitInitializationMode, or else the first step) sets x^ = [0, y] (beta^ = 0,
    measured r, phi, phidot) and the mode of the initial speed, and restarts the first-order hold.
Non-finite inputs never reach this runtime: the framework refuses such a step (fmi2Discard), so
the state, the previous inputs of the first-order hold and ``valid`` are those of the last
accepted step.
"""
from __future__ import annotations

import itertools
import math
import threading
from bisect import bisect_right
from operator import mul

OUTPUT_NAMES = ("beta_hat", "yaw_rate_hat", "roll_angle_hat", "roll_rate_hat", "bank_angle_hat", "mode", "valid")


# -- dense matrices as lists of rows ---------------------------------------------------------
def _floats(M) -> list[list[float]]:
    return [[float(x) for x in row] for row in M]


def _matvec(M, v):
    return [sum(map(mul, row, v)) for row in M]


def _matmul(A, B):
    cols = list(zip(*B))
    return [[sum(map(mul, row, col)) for col in cols] for row in A]


def _add(A, B):
    return [[a + b for a, b in zip(ra, rb)] for ra, rb in zip(A, B)]


def _scale(A, s):
    return [[a * s for a in row] for row in A]


def _eye(n):
    return [[1.0 if i == j else 0.0 for j in range(n)] for i in range(n)]


def _zeros(r, c):
    return [[0.0] * c for _ in range(r)]


def _norm_inf(A) -> float:
    """Induced infinity norm (largest row sum of |a|)."""
    return max(sum(map(abs, row)) for row in A)


# -- matrix power series in d (list of matrices, index = power of d), truncated at degree J ----
def _smul(P, Q, J):
    out = [None] * min(len(P) + len(Q) - 1, J + 1)
    for a, Pa in enumerate(P):
        for b, Qb in enumerate(Q):
            if a + b > J:
                break
            prod = _matmul(Pa, Qb)
            out[a + b] = prod if out[a + b] is None else _add(out[a + b], prod)
    return out


def _sadd(P, Q):
    if len(P) < len(Q):
        P, Q = Q, P
    return [_add(Pa, Q[j]) if j < len(Q) else Pa for j, Pa in enumerate(P)]


def _shift(coeffs, v0):
    """Coefficients in d of sum_k coeffs[k] (v0 + d)**k."""
    out = []
    for j in range(len(coeffs)):
        acc = None
        for k in range(j, len(coeffs)):
            term = _scale(coeffs[k], math.comb(k, j) * v0 ** (k - j))
            acc = term if acc is None else _add(acc, term)
        out.append(acc)
    return out


def _substep(Ms, Gs, hs, J):
    """One RK4 substep with held inputs as a series of affine maps [R | S G] in d."""
    n = len(Ms[0])
    eye = _eye(n)
    X = [_scale(M, hs) for M in Ms]
    Q = [eye]
    for c in (4.0, 3.0, 2.0):                       # Q = I + X/2 (I + X/3 (I + X/4))
        Q = _sadd([eye], [_scale(P, 1.0 / c) for P in _smul(X, Q, J)])
    R = _sadd([eye], _smul(X, Q, J))                # R = I + X Q
    SG = [_scale(P, hs) for P in _smul(Q, Gs, J)]   # S G = hs Q G
    m = len(Gs[0][0])
    R += [_zeros(n, n)] * (len(SG) - len(R))
    SG += [_zeros(n, m)] * (len(R) - len(SG))
    return [[ra + rb for ra, rb in zip(A, B)] for A, B in zip(R, SG)]


def _compose(W2, W1, n, J):
    """Series of the affine map W2 after W1, each [A | b] (n rows)."""
    out = _smul([[row[:n] for row in P] for P in W2], W1, J)
    for j, P in enumerate(W2):
        for ro, rp in zip(out[j], P):
            for c in range(n, len(rp)):
                ro[c] += rp[c]
    return out


def _power(W, k, n, J):
    """W composed k >= 1 times (binary powering; all factors commute)."""
    result = None
    while True:
        if k & 1:
            result = W if result is None else _compose(W, result, n, J)
        k >>= 1
        if not k:
            return result
        W = _compose(W, W, n, J)


def _augment(Ms, Gs, h):
    """First-order hold as a held input: series (in v or d) of M, G -> those of
    [s; w]' = [[M, G], [0, 0]] [s; w] + [[0], [I / h]] e, e = the hold's increment over the step,
    so that w(t + tau) = w_k + (tau / h) e is a state. RK4 on this system evaluates w exactly at
    the stage times (w is linear in time), so its maps ARE the RK4 substeps with that input."""
    n1, nw = len(Ms[0]), len(Gs[0][0])
    Ma = []
    for k in range(max(len(Ms), len(Gs))):
        M = Ms[k] if k < len(Ms) else _zeros(n1, n1)
        G = Gs[k] if k < len(Gs) else _zeros(n1, nw)
        Ma.append([list(rm) + list(rg) for rm, rg in zip(M, G)] + _zeros(nw, n1 + nw))
    return Ma, [_zeros(n1, nw) + _scale(_eye(nw), 1.0 / h)]


# -- compiled maps ------------------------------------------------------------------------------
_NAMESPACE = {"__builtins__": {}, "inf": math.inf, "nan": math.nan}


def _compile(series, N, var: str | None = None, center: float = 0.0, foh: bool = False):
    """Compile the step map sum_j series[j] (v - center)**j with the output map into
    f(s, y0, .., dl[, e0, .., e_dl][, v]) -> (s+, x^_0, .., x^_{n-1}). Only the first n + 1 rows
    of series[j] are used: [Phi | Gam] (zero-order hold; x^ = z+ + N y) or, with ``foh``, the
    top rows [Phi | Gam | Gam_e] of the augmented map (x^ = z+ + N (y + e_y), the hold at t + h)."""
    n, ny = len(N), len(N[0])
    n1 = n + 1
    names = [f"s{i}" for i in range(n1)] + [f"y{j}" for j in range(ny)] + ["dl"]
    if foh:
        names += [f"e{j}" for j in range(ny + 1)]

    def lin(row):
        terms = [f"{c!r}*{x}" for c, x in zip(row, names) if c != 0.0]
        return "(" + " + ".join(terms) + ")" if terms else None

    lines = [f"def f(s, {', '.join(names[n1:])}{', ' + var if var else ''}):",
             f"    {', '.join(names[:n1])}, = s"]
    if var:
        lines.append(f"    d = {var} - {center!r}")
    for i in range(n1):
        polys = [lin(P[i]) for P in series]         # Horner in d, skipping vanished terms
        while len(polys) > 1 and polys[-1] is None:
            polys.pop()
        expr = polys[-1] or "0.0"
        for p in reversed(polys[:-1]):
            expr = f"{p} + d*({expr})" if p else f"d*({expr})"
        lines.append(f"    a{i} = {expr}")
    outs = []
    for i in range(n):
        terms = [f"{c!r}*y{j}" for j, c in enumerate(N[i]) if c != 0.0]
        if foh:
            terms += [f"{c!r}*e{j}" for j, c in enumerate(N[i]) if c != 0.0]
        outs.append(" + ".join([f"a{i}"] + terms))
    lines.append(f"    return ({', '.join(f'a{i}' for i in range(n1))},), {', '.join(outs)}")
    ns = dict(_NAMESPACE)
    exec(compile("\n".join(lines), "<pi_observer step map>", "exec"), ns)
    return ns["f"]


def _truncation_bound(coeffs, D, delta, E1, alpha, nsub):
    """Rigorous bound of ||sum_{j > D} coeffs_j d^j||_inf for |d| <= delta, where the map is
    E(d)^nsub (top rows), E(d) = E_0 + sum_{j>=1} E_j d^j the augmented substep map.

    Degrees D < j <= J = len(coeffs) - 1: the exact coefficients. Degrees > J: every coefficient
    of E^nsub = sum over words in E_0 and H = E - E_0 is bounded (coefficientwise) by those of
    f(t) = alpha (1 + alpha eta(t))^nsub, alpha = max_{a <= nsub} ||E_0^a||, eta(t) = sum_j
    ||E_j|| t^j (E1 = [||E_1||, ||E_2||, ...]); for nonnegative coefficients sum_{j > J} f_j
    delta^j <= f(rho) (delta / rho)^(J + 1) for any rho > delta (minimised over a grid of rho).
    """
    J = len(coeffs) - 1
    exact = sum(_norm_inf(coeffs[j]) * delta**j for j in range(D + 1, J + 1))
    best = math.inf
    for k in range(1, 60):
        rho = delta * 1.25**k
        eta = sum(e * rho ** (j + 1) for j, e in enumerate(E1))
        log_f = math.log(alpha) + nsub * math.log1p(alpha * eta)
        log_tail = log_f + (J + 1) * math.log(delta / rho)
        best = min(best, math.exp(log_tail) if log_tail < 700 else math.inf)
    return exact + best


def _rk4(M, G, N, nsub, hs, s, w, e=None, h=None):
    """n classical RK4 substeps of s' = M s + G w and the outputs: the reference form of the
    compiled maps (used at the first step with a new h and for long tire steps). Zero-order hold
    (e None): w held. First-order hold: w(tau) = w + (tau / h) e evaluated at the stage times."""
    b = _matvec(G, w)
    s = list(s)
    # d/dtau of G w(tau); zero-order hold: 0, and b + t * 0.0 == b exactly (the held-input RK4)
    g = [0.0] * len(b) if e is None else [x / h for x in _matvec(G, e)]
    for j in range(nsub):
        t1, t2, t4 = j * hs, (j + 0.5) * hs, (j + 1) * hs
        b1 = [p + t1 * q for p, q in zip(b, g)]
        b2 = [p + t2 * q for p, q in zip(b, g)]
        b4 = [p + t4 * q for p, q in zip(b, g)]
        k1 = [p + q for p, q in zip(_matvec(M, s), b1)]
        s2 = [x + 0.5 * hs * k for x, k in zip(s, k1)]
        k2 = [p + q for p, q in zip(_matvec(M, s2), b2)]
        s3 = [x + 0.5 * hs * k for x, k in zip(s, k2)]
        k3 = [p + q for p, q in zip(_matvec(M, s3), b2)]
        s4 = [x + hs * k for x, k in zip(s, k3)]
        k4 = [p + q for p, q in zip(_matvec(M, s4), b4)]
        s = [x + hs / 6.0 * (a + 2 * b_ + 2 * c + d) for x, a, b_, c, d in zip(s, k1, k2, k3, k4)]
    w_end = w if e is None else [a + c for a, c in zip(w, e)]   # the hold at t + h
    return (tuple(s), *(s[i] + sum(map(mul, row, w_end)) for i, row in enumerate(N)))


def _rk4_map(Mc, Gc, N, nsub, hs, h=None):
    """f(s, y0, .., dl[, e0, .., e_dl], v) running the RK4 substeps with the model at v = 1/vx
    (not compiled); ``h`` given: first-order hold with increments e over the step h."""
    nw = len(Gc[0][0])

    def f(s, *args):
        v = args[-1]
        M, G = _shift(Mc, v)[0], _shift(Gc, v)[0]
        if h is None:
            return _rk4(M, G, N, nsub, hs, s, args[:-1])
        return _rk4(M, G, N, nsub, hs, s, args[:nw], args[nw:-1], h)
    return f


# -- the cache of step maps, shared by the instances of one process ---------------------------
# Instances with the same design (same fingerprint: model, gains, N, max_step, speed ranges, hold,
# freeze and the tuning constants) share their maps, so that re-instantiating an FMU does not
# rebuild them.
_LOCK = threading.RLock()
_MAPS: dict = {}          # (design id, map index, h) -> compiled map or _TireTable, oldest first
_HELD = [0]               # compiled functions held by _MAPS
_IDS: dict = {}           # design fingerprint -> design id (ids are never reused)
_NEW_ID = itertools.count(1)


def _trim(keep, max_maps: int, max_compiled: int) -> None:
    """Drop the oldest cached maps (never ``keep``) beyond max_maps entries / max_compiled functions."""
    while len(_MAPS) > max_maps or _HELD[0] > max_compiled:
        key = next((k for k, m in _MAPS.items() if m is not keep), None)
        if key is None:
            return
        dropped = _MAPS.pop(key)
        _HELD[0] -= dropped.built if dropped.__class__ is _TireTable else 1


class _TireTable:
    """Step maps of one measured-speed mode and step size h: piecewise Taylor polynomials in
    v = 1/vx on K equal intervals of the mode's clamped range of v, each compiled when first
    visited. ``taylor=False``: one interval running the RK4 substeps themselves (long steps).
    ``h`` given: first-order hold (maps of the augmented system, see ``_augment``)."""

    __slots__ = ("key", "Mc", "Gc", "N", "nsub", "hs", "h", "n1", "D", "J", "tol", "limits", "v_lo", "v_hi",
                 "scale", "K", "fns", "built")

    def __init__(self, key, Mc, Gc, N, v_lo, v_hi, nsub, hs, degree, tol, max_intervals, limits, taylor=True,
                 h=None):
        self.key, self.Mc, self.Gc, self.N, self.nsub, self.hs, self.h = key, Mc, Gc, N, nsub, hs, h
        self.n1 = len(Mc[0])                       # rows of [z; w^]: the rows compiled
        self.D, self.J, self.tol, self.limits = degree, degree + 3, tol, limits
        self.v_lo, self.v_hi = v_lo, v_hi
        self.built = 0
        width = v_hi - v_lo
        K = 1
        if taylor and width > 0:
            # probe the coefficients at the middle of the range: K such that the degrees D + 1 and
            # D + 2 contribute about tol / 4 there (each interval is then checked on its own)
            coeffs, *_ = self._series(0.5 * (v_lo + v_hi))
            goal = tol * _norm_inf(coeffs[0][: self.n1]) / 4
            half = min((goal / max(_norm_inf(coeffs[j]), 1e-300)) ** (1.0 / j) for j in (degree + 1, degree + 2))
            K = max(1, min(max_intervals, math.ceil(width / (2 * half))))
        self.K = K
        self.scale = K / width if width > 0 else 0.0
        self.fns = [None if taylor else _rk4_map(Mc, Gc, N, nsub, hs, h)] * K

    def piece(self, v):
        """The compiled map of the interval holding v = 1/vx (clamped to the table), built if new."""
        k = int((v - self.v_lo) * self.scale)
        if k >= self.K:
            k = self.K - 1
        elif k < 0:
            k = 0
        return self.fns[k] or self.build(k)

    def _series(self, v0):
        """Exact Taylor coefficients (degree <= J) in d = v - v0 of the n-substep map, and what
        the truncation bound needs: ||E_j|| (j >= 1) and max_{a <= n} ||E_0^a|| of the substep."""
        Ms, Gs = _shift(self.Mc, v0), _shift(self.Gc, v0)
        if self.h is not None:
            Ms, Gs = _augment(Ms, Gs, self.h)
        n = len(Ms[0])
        W = _substep(Ms, Gs, self.hs, 4 * (len(Ms) - 1) + len(Gs) - 1)   # all its degrees in d
        E1 = [_norm_inf(P) for P in W[1:]]
        # powers of E_0 = [[R0, b0], [0, I]]: ||E_0^a|| = max(1, ||[R0^a | sum_{k<a} R0^k b0]||)
        P, alpha = None, 1.0
        for _ in range(self.nsub):
            P = W[:1] if P is None else _compose(W[:1], P, n, 0)
            alpha = max(alpha, _norm_inf(P[0]))
        coeffs = _power(W[: self.J + 1], self.nsub, n, self.J)
        coeffs += [_zeros(n, len(W[0][0]))] * (self.J + 1 - len(coeffs))
        return coeffs, E1, alpha

    def coefficients(self, k):
        """(center, kept) of interval k: its center in v and the Taylor coefficients kept, kept[j]
        the top n + 1 rows of the map's coefficient of (v - center)**j (trailing all-zero degrees
        removed). Per row, the terms c d^j (j >= 1) are dropped, smallest |c| delta^j first, while
        their sum plus the bound of all terms beyond degree J stays within tol ||[Phi | Gam]||_inf:
        a rigorous bound of the row's truncation error per unit ||[s; w]||_inf (first-order hold:
        [s; w; e] and the top rows of the augmented map). kept is None if the terms beyond J
        alone exceed it (the interval runs the RK4 substeps)."""
        width = self.v_hi - self.v_lo
        center = self.v_lo + (k + 0.5) * width / self.K
        delta = 0.5 * width / self.K * (1 + 1e-6) + 1e-300   # slack for the rounding of k
        coeffs, E1, alpha = self._series(center)
        n1 = self.n1
        budget = (self.tol * _norm_inf(coeffs[0][:n1])
                  - _truncation_bound(coeffs, self.J, delta, E1, alpha, self.nsub))
        if budget < 0:
            return center, None
        kept = [[row[:] for row in P[:n1]] for P in coeffs]
        for i in range(n1):
            terms = sorted((abs(c) * delta**j, j, col) for j in range(1, len(kept))
                           for col, c in enumerate(kept[j][i]))
            dropped = 0.0
            for w, j, col in terms:
                dropped += w
                if dropped > budget:
                    break
                kept[j][i][col] = 0.0
        while len(kept) > 1 and not any(any(row) for row in kept[-1]):
            kept.pop()
        return center, kept

    def build(self, k):
        """Compile interval k (``coefficients``; the RK4 substeps where it has none)."""
        center, kept = self.coefficients(k)
        if kept is None:
            fn = _rk4_map(self.Mc, self.Gc, self.N, self.nsub, self.hs, self.h)
        else:
            fn = _compile(kept, self.N, "v", center, self.h is not None)
            fn.degree = len(kept) - 1
        with _LOCK:
            if self.fns[k] is not None:       # built meanwhile by another thread: same function
                return self.fns[k]
            self.fns[k] = fn
            if _MAPS.get(self.key) is self:   # still cached: count it (an evicted table that an
                self.built += 1               # instance still uses holds at most K functions)
                _HELD[0] += 1
                _trim(self, *self.limits)
        return fn


def _number(x, what: str, lo: float = -math.inf, hi: float = math.inf, open_lo: bool = False) -> float:
    """float(x), finite and in [lo, hi] (or (lo, hi]), else a ValueError naming ``what``."""
    if isinstance(x, bool):
        raise ValueError(f"design {what} must be a number, got {x!r}")
    x = float(x)
    if not (math.isfinite(x) and (x > lo if open_lo else x >= lo) and x <= hi):
        raise ValueError(f"design {what} must be finite and in {'(' if open_lo else '['}{lo:g}, {hi:g}], got {x!r}")
    return x


class SwitchedPIObserver:
    """Switched PI observer of paper 000 from its design file (see the module docstring)."""

    PARAMETERS = {"vx_hold": 1.0}  # m/s: below this speed the estimates are held
    MAP_CACHE_SIZE = 32            # (design, map index, step size) maps kept at most, per process
    MAX_COMPILED = 1024            # compiled functions kept at most, per process (~15 kB each)
    TAYLOR_DEGREE = 4              # measured-speed modes: the degree the interval count K aims at
    TAYLOR_TOL = 1e-16             # measured-speed modes: truncation bound relative to ||[Phi | Gam]||_inf
    TAYLOR_MAX_SUBSTEPS = 64       # measured-speed modes: longer steps run the RK4 substeps directly
    MAX_INTERVALS = 512            # measured-speed modes: intervals K per (mode, h) at most
    INVALID_LOG_PERIOD = 1.0       # s of simulated time: at most one "valid = 0" message per period
    INPUT_HOLDS = ("zero_order", "first_order")

    def __init__(self, data: dict, params: dict | None = None):
        params = dict(params or {})
        try:
            st = data["structure"]
            self.T, self.N, self.C = _floats(st["T"]), _floats(st["N"]), _floats(st["C"])
            self.modes = data["modes"]
            self.switching = sw = data["switching"]
            rt = data["runtime"]
            self.max_step = float(rt["max_step"])
            vx_hold = rt.get("vx_hold", self.PARAMETERS["vx_hold"])
            self.input_hold = rt.get("input_hold", "zero_order")
            self._speed_bands = sw["kind"] == "speed_bands"
            if self._speed_bands:
                self._edges = [float(e) for e in sw["edges"]]
            else:
                self._slip = (float(sw["lf"]), float(sw["lr"]), sw["alpha_star"] + sw["hysteresis"],
                              sw["alpha_star"] - sw["hysteresis"])
            self._model_speeds()
            self._lo, self._hi = self._speed_range()
            self._validity(data.get("validity"))
        except (KeyError, TypeError) as exc:
            raise ValueError(f"design file lacks {exc} needed by the paper-000 observer runtime") from exc
        if self.input_hold not in self.INPUT_HOLDS:
            raise ValueError(f"design runtime.input_hold must be one of {', '.join(self.INPUT_HOLDS)}, "
                             f"got {self.input_hold!r}")
        self._foh = self.input_hold == "first_order"
        self.vx_hold = float(params.get("vx_hold", vx_hold))
        if not (math.isfinite(self.vx_hold) and self.vx_hold > 0):       # 0 would reach 1/vx at vx = 0
            raise ValueError(f"parameter vx_hold must be finite and > 0 m/s, got {self.vx_hold}")
        if not (0 < self.max_step <= 0.01):
            raise ValueError(f"design runtime.max_step must be in (0, 0.01] s, got {self.max_step}")
        self.n = len(self.T)
        self.ny = len(self.C)
        nm = self._nm = len(self.modes)
        try:
            # M(v), G(v) as polynomials in v = 1/vx: coefficient matrices, no products per step
            Mc, Gc = zip(*(self._coefficients(i) for i in range(nm)))
        except (KeyError, TypeError) as exc:
            raise ValueError(f"design file lacks {exc} needed by the paper-000 observer runtime") from exc
        self._Mc, self._Gc = list(Mc), list(Gc)
        if self._freeze:
            # map indices nm + i: mode i with the integral action frozen (w^ row of M and G zero)
            self._Mc += [[P[:-1] + [[0.0] * len(P[-1])] for P in coeffs] for coeffs in Mc]
            self._Gc += [[P[:-1] + [[0.0] * len(P[-1])] for P in coeffs] for coeffs in Gc]
        self._N01 = tuple(self.N[0]) + tuple(self.N[1])   # rows of x^_0, x^_1 = beta^, r^ (premises)
        fingerprint = (self.max_step, self._lo, self._hi, tuple(self._fixed_v), tuple(self._v_range),
                       self.input_hold, self._freeze, repr((Mc, Gc, self.N)),
                       self.TAYLOR_DEGREE, self.TAYLOR_TOL, self.TAYLOR_MAX_SUBSTEPS, self.MAX_INTERVALS)
        with _LOCK:
            if fingerprint not in _IDS and len(_IDS) >= 256:
                _IDS.clear()
            self._id = _IDS.setdefault(fingerprint, next(_NEW_ID))
        self._seen: set = set()            # (map index, h) this instance has stepped with
        self._h = None                     # the step size self._fns is for
        self._fns = [None] * len(self._Mc)
        self.mode = 0                      # 0-based index; the output is 1-based
        self.s = (0.0,) * (self.n + 1)     # [z; w^]
        self._started = False
        self._holding = False
        self._outside = False
        self._t = 0.0                      # simulated time since the start (sum of the steps; validity only)
        self._prev = None                  # first-order hold: (y0, y1, y2, delta, h) of the last step
        self.valid = 1
        self.invalid_entries = 0           # entries into valid = 0 since the start
        self._invalid_logged = None        # time of the last "valid = 0" message
        self._invalid_unlogged = 0         # entries since then without a message
        self.events: list[tuple[str, str]] = []
        self.y = {name: 0.0 for name in OUTPUT_NAMES}
        self.y["mode"] = 1
        self.y["valid"] = 1

    # -- design ------------------------------------------------------------------------------
    def _model_speeds(self) -> None:
        """Per mode: the model speed. "fixed": v = 1/value; "measured": the range [lo, hi] (m/s)
        the measured speed is clamped to, as v = 1/vx in [1/hi, 1/lo]."""
        self._fixed_v, self._v_range, self._vx_range = [], [], []
        for i, m in enumerate(self.modes):
            ms = m["model_speed"]
            if ms["kind"] == "fixed":
                value = _number(ms["value"], f"modes[{i}].model_speed.value", 0.0, open_lo=True)
                self._fixed_v.append(1.0 / value)
                self._v_range.append(None)
                self._vx_range.append(None)
            elif ms["kind"] == "measured":
                lo, hi = ms["range"]
                lo = _number(lo, f"modes[{i}].model_speed.range[0]", 0.0, open_lo=True)
                hi = _number(hi, f"modes[{i}].model_speed.range[1]", lo)
                self._fixed_v.append(None)
                self._v_range.append((1.0 / hi, 1.0 / lo))
                self._vx_range.append((lo, hi))
            else:
                raise ValueError(f"design modes[{i}].model_speed.kind must be 'fixed' or 'measured', "
                                 f"got {ms['kind']!r}")

    def _speed_range(self) -> tuple[float, float]:
        """The design grid (m/s): the band edges, or the union of the modes' measured ranges."""
        if self._speed_bands:
            return self._edges[0], self._edges[-1]
        ranges = [r for r in self._vx_range if r is not None]
        if not ranges:
            raise ValueError("design: the tire-switched observer needs modes with a measured model speed")
        return min(r[0] for r in ranges), max(r[1] for r in ranges)

    def _validity(self, val) -> None:
        """data["validity"]: the domain where the estimates are declared valid (see the module
        docstring); absent: valid = 1 always, nothing frozen."""
        self._val = None
        self._freeze = False
        if val is None:
            return
        a_max = _number(val["alpha_max"], "validity.alpha_max", 0.0, open_lo=True)
        ay_max = _number(val["ay_max"], "validity.ay_max", 0.0, open_lo=True)
        release = _number(val["release"], "validity.release", 0.0, 1.0, open_lo=True)
        if release >= 1.0:
            raise ValueError(f"design validity.release must be in (0, 1), got {release!r}")
        sw = self.switching
        lf = _number(val["lf"] if "lf" in val else sw["lf"], "validity.lf")
        lr = _number(val["lr"] if "lr" in val else sw["lr"], "validity.lr")
        self._val = (a_max, ay_max, release * a_max, release * ay_max, lf, lr)
        self._freeze = bool(val.get("freeze_integral", False))

    # -- model -------------------------------------------------------------------------------
    def _coefficients(self, i: int):
        """Coefficient matrices (in v = 1/vx) of M(v), G(v) with s' = M s + G [y; u] for mode i."""
        mode = self.modes[i]
        model = {k: [_floats(P) for P in mode["model"][k]] for k in ("A", "B", "F")}
        KP, KI = _floats(mode["gains"]["K_P"]), _floats(mode["gains"]["K_I"])
        T, N, C, n, ny = self.T, self.N, self.C, self.n, self.ny
        CN = _matmul(C, N)
        I_CN = [[(1.0 if r == c else 0.0) - CN[r][c] for c in range(ny)] for r in range(ny)]
        Mc, Gc = [], []
        for k in range(max(len(v) for v in model.values())):
            A = model["A"][k] if k < len(model["A"]) else _zeros(n, n)
            B = model["B"][k] if k < len(model["B"]) else _zeros(n, 1)
            F = model["F"][k] if k < len(model["F"]) else _zeros(n, 1)
            TA, TB, TF = _matmul(T, A), _matmul(T, B), _matmul(T, F)
            TAN = _matmul(TA, N)
            if k == 0:
                # y enters through T A N y + K_P (I - C N) y (z rows) and K_I (I - C N) y (w row)
                TA, TAN = _add(TA, _scale(_matmul(KP, C), -1.0)), _add(TAN, _matmul(KP, I_CN))
                w_M, w_G = [-x for x in _matmul(KI, C)[0]] + [0.0], _matmul(KI, I_CN)[0] + [0.0]
            else:
                w_M, w_G = [0.0] * (n + 1), [0.0] * (ny + 1)
            Mc.append([TA[r] + [TF[r][0]] for r in range(n)] + [w_M])
            Gc.append([TAN[r] + [TB[r][0]] for r in range(n)] + [w_G])
        return Mc, Gc

    def _system(self, i: int, vx: float):
        """(M, G) with s' = M s + G [y; u] for mode i with its model at speed vx (m/s)."""
        v = 1.0 / vx
        return _shift(self._Mc[i], v)[0], _shift(self._Gc[i], v)[0]

    def _model_speed(self, mode: int, vx: float) -> float:
        """The speed (m/s) mode's model is evaluated at: its fixed speed, or vx clamped to its range."""
        if self._fixed_v[mode] is not None:
            return 1.0 / self._fixed_v[mode]
        lo, hi = self._vx_range[mode]
        return min(max(vx, lo), hi)

    def _select_mode(self, vx: float, delta: float, y_meas) -> int:
        if self._speed_bands:
            return self._band(vx)
        xhat = self.xhat(y_meas)
        return self._tire_mode(xhat[0], xhat[1], vx, delta)

    def _band(self, vx: float) -> int:
        """Eq. (25): mode i on [edges[i], edges[i + 1]); outside the grid the nearest mode."""
        i = bisect_right(self._edges, vx) - 1
        return 0 if i < 0 else min(i, len(self.modes) - 1)

    def _tire_mode(self, beta: float, r: float, vx: float, delta: float) -> int:
        """Eq. (27) with the slip angles of eq. (2) from the estimates beta^, r^."""
        lf, lr, up, down = self._slip
        a_f = delta - beta - lf * r / vx
        a_r = -beta + lr * r / vx
        premise = max(abs(a_f), abs(a_r))
        # departure from eq. (27): a hysteresis band of +-hysteresis around alpha* (the paper
        # switches exactly at alpha*, which chatters when the estimated slip hovers there)
        if self.mode == 0 and premise > up:
            return 1
        if self.mode == 1 and premise < down:
            return 0
        return self.mode

    def _check_validity(self, beta: float, r: float, vx: float, delta: float, yaw_rate: float, t: float) -> int:
        """valid (1/0) for the step starting at t: slip angles from beta^, r^ and |vx yaw_rate|
        against their limits, with the release hysteresis; one rate-limited event per entry."""
        a_max, ay_max, a_rel, ay_rel, lf, lr = self._val
        a_f = delta - beta - lf * r / vx
        a_r = -beta + lr * r / vx
        alpha = max(abs(a_f), abs(a_r))
        ay = abs(vx * yaw_rate)
        if self.valid:
            if alpha > a_max or ay > ay_max:
                self.valid = 0
                self.invalid_entries += 1
                last = self._invalid_logged
                if last is None or t - last >= self.INVALID_LOG_PERIOD:
                    more = (f"; {self._invalid_unlogged} more entries since the last message not logged"
                            if self._invalid_unlogged else "")
                    held = "; bank estimate held until valid again" if self._freeze else ""
                    self.events.append((
                        "warning", f"t = {t:.6g} s: valid = 0, estimates outside the validity limits: "
                                   f"max(|alpha_f|, |alpha_r|) = {alpha:.3g} rad (limit {a_max:.3g}), "
                                   f"|vx yaw_rate| = {ay:.3g} m/s^2 (limit {ay_max:.3g}){held} "
                                   f"(entry {self.invalid_entries}{more})"))
                    self._invalid_logged, self._invalid_unlogged = t, 0
                else:
                    self._invalid_unlogged += 1
                self.y["valid"] = 0
        elif alpha < a_rel and ay < ay_rel:
            self.valid = self.y["valid"] = 1
        return self.valid

    # -- step maps ---------------------------------------------------------------------------
    def _substeps(self, h: float) -> tuple[int, float]:
        nsub = max(1, math.ceil(h / self.max_step - 1e-9))
        return nsub, h / nsub

    def _use_step_size(self, h: float) -> None:
        """self._fns for step size h: the cached maps of the (index, h) this instance has used;
        False for the others (their first step runs the RK4 substeps)."""
        self._h = h
        seen = self._seen
        self._fns = [_MAPS.get((self._id, i, h)) if (i, h) in seen else False for i in range(len(self._Mc))]

    def _map(self, idx: int, h: float):
        """The step map of (map index, h), built if missing, or None (run the RK4 substeps) at the
        first step of this instance with (index, h): which steps use a map depends only on the
        instance's own history, never on what other instances cached (bitwise reproducible).
        Map index: the mode, + number of modes when the integral action is frozen."""
        if self._fns[idx] is False:
            if len(self._seen) >= 4 * self.MAP_CACHE_SIZE:
                self._seen.clear()
            self._seen.add((idx, h))
            self._fns[idx] = None
            return None
        key = (self._id, idx, h)
        with _LOCK:
            fn = _MAPS.get(key)
            if fn is None:
                if self._fixed_v[idx % self._nm] is not None:   # fixed model speed: the composite map
                    fn = _compile(self._fixed_map(idx, h), self.N, foh=self._foh)
                    _HELD[0] += 1
                else:
                    fn = self._table(idx, h, key)
                _MAPS[key] = fn
                _trim(fn, self.MAP_CACHE_SIZE, self.MAX_COMPILED)
        self._fns[idx] = fn
        return fn

    def _fixed_map(self, idx: int, h: float):
        """The composite map of the RK4 substeps over h for fixed-speed map index idx, exact: the
        series [[Phi | Gam]] (first-order hold: the augmented map, whose top rows are
        [Phi | Gam | Gam_e])."""
        nsub, hs = self._substeps(h)
        v = self._fixed_v[idx % self._nm]
        Ms, Gs = _shift(self._Mc[idx], v)[:1], _shift(self._Gc[idx], v)[:1]
        if self._foh:
            Ms, Gs = _augment(Ms, Gs, h)
        return _power(_substep(Ms, Gs, hs, 0), nsub, len(Ms[0]), 0)

    def _table(self, idx: int, h: float, key=None) -> _TireTable:
        """The piecewise Taylor table of measured-speed map index idx at step h (``key``: its
        entry in the map cache, for the count of compiled functions)."""
        nsub, hs = self._substeps(h)
        v_lo, v_hi = self._v_range[idx % self._nm]
        return _TireTable(key, self._Mc[idx], self._Gc[idx], self.N, v_lo, v_hi, nsub, hs, self.TAYLOR_DEGREE,
                          self.TAYLOR_TOL, self.MAX_INTERVALS, (self.MAP_CACHE_SIZE, self.MAX_COMPILED),
                          taylor=nsub <= self.TAYLOR_MAX_SUBSTEPS, h=h if self._foh else None)

    def _step_rk4(self, idx, h, s, w, v, e=None):
        M, G = _shift(self._Mc[idx], v)[0], _shift(self._Gc[idx], v)[0]
        return _rk4(M, G, self.N, *self._substeps(h), s, w, e, h)

    # -- stepping ----------------------------------------------------------------------------
    def xhat(self, y_meas):
        z = self.s[: self.n]
        Ny = _matvec(self.N, y_meas)
        return [a + b for a, b in zip(z, Ny)]

    def initialize(self, u: dict) -> None:
        """Start from the first measurement: x^(0) = [0, y(0)], i.e. z(0) = x^(0) - N y(0), and the
        mode of the initial speed (tire modes: mode 1). The first-order hold restarts (slope 0)."""
        y_meas = [u["yaw_rate"], u["roll_angle"], u["roll_rate"]]
        x0 = [0.0] + y_meas
        Ny = _matvec(self.N, y_meas)
        self.s = tuple(a - b for a, b in zip(x0, Ny)) + tuple(self.s[self.n:])
        self._started = True
        self._prev = None
        if self._speed_bands and u["vx"] >= self.vx_hold:
            self.mode = self._band(u["vx"])
        self._publish(y_meas)

    def step(self, h: float, u: dict) -> None:
        vx = u["vx"]
        if not self._started:
            self.initialize(u)
        if self._val is not None:      # simulated time: only the validity messages need it
            t = self._t
            self._t = t + h
        hold = self.vx_hold
        if vx < hold:                  # standstill or reversing: frozen, every output held as it is
            if not self._holding:
                self.events.append(("warning", f"vx = {vx:.3g} m/s < vx_hold = {hold:g} m/s (standstill or "
                                               "reversing): observer frozen, every estimate held"))
            self._holding = True
            self._prev = None          # the first-order hold restarts with slope 0
            return
        if self._holding:
            self.events.append(("warning", f"vx = {vx:.3g} m/s: observer resumes"))
            self._holding = False
        lo, hi = self._lo, self._hi
        if lo <= vx <= hi:
            self._outside = False
        else:
            if not self._outside:
                self.events.append(("warning", f"vx = {vx:.4g} m/s outside the design grid [{lo:.4g}, {hi:.4g}] m/s: "
                                               "clamped to the nearest grid mode/speed"))
            self._outside = True
        y0, y1, y2, delta = u["yaw_rate"], u["roll_angle"], u["roll_rate"], u["delta"]
        s = self.s
        if h != self._h:
            self._use_step_size(h)
        if self._speed_bands:
            self.mode = mode = self._band(vx)
            if self._val is not None:
                n00, n01, n02, n10, n11, n12 = self._N01
                beta, r = s[0] + (n00 * y0 + n01 * y1 + n02 * y2), s[1] + (n10 * y0 + n11 * y1 + n12 * y2)
        else:
            n00, n01, n02, n10, n11, n12 = self._N01
            beta, r = s[0] + (n00 * y0 + n01 * y1 + n02 * y2), s[1] + (n10 * y0 + n11 * y1 + n12 * y2)
            self.mode = mode = self._tire_mode(beta, r, vx, delta)
        idx = mode
        if self._val is not None and not self._check_validity(beta, r, vx, delta, y0, t) and self._freeze:
            idx += self._nm
        fn = self._fns[idx] or self._map(idx, h)
        v = fixed = self._fixed_v[mode]
        if fixed is None:              # the model at the measured speed clamped to the mode's range
            vlo, vhi = self._vx_range[mode]
            v = 1.0 / (vx if vlo <= vx <= vhi else (vlo if vx < vlo else vhi))
        if self._foh:
            prev = self._prev
            self._prev = (y0, y1, y2, delta, h)
            if prev is None:           # slope 0: first step, after a hold or an initialisation
                e0 = e1 = e2 = e3 = 0.0
            else:                      # the increment of w_k + tau (w_k - w_{k-1}) / h_{k-1} over h
                p0, p1, p2, p3, hp = prev
                c = h / hp
                e0, e1, e2, e3 = (y0 - p0) * c, (y1 - p1) * c, (y2 - p2) * c, (delta - p3) * c
            if fn is None:
                s, b, r, p, q = self._step_rk4(idx, h, s, (y0, y1, y2, delta), v, (e0, e1, e2, e3))
            elif fixed is not None:
                s, b, r, p, q = fn(s, y0, y1, y2, delta, e0, e1, e2, e3)
            else:
                s, b, r, p, q = fn.piece(v)(s, y0, y1, y2, delta, e0, e1, e2, e3, v)
        elif fn is None:
            s, b, r, p, q = self._step_rk4(idx, h, s, (y0, y1, y2, delta), v)
        elif fixed is not None:
            s, b, r, p, q = fn(s, y0, y1, y2, delta)
        else:
            s, b, r, p, q = fn.piece(v)(s, y0, y1, y2, delta, v)
        self.s = s
        y = self.y
        y["beta_hat"] = b
        y["yaw_rate_hat"] = r
        y["roll_angle_hat"] = p
        y["roll_rate_hat"] = q
        y["bank_angle_hat"] = s[-1]
        y["mode"] = mode + 1

    def _publish(self, y_meas) -> None:
        xh = self.xhat(y_meas)
        self.y.update(beta_hat=xh[0], yaw_rate_hat=xh[1], roll_angle_hat=xh[2], roll_rate_hat=xh[3],
                      bank_angle_hat=self.s[self.n], mode=self.mode + 1, valid=self.valid)
