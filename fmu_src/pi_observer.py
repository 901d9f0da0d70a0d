"""Runtime of the switched PI observer of paper 000 (Menhour et al., ECC 2014), eq. (5).

Standard library only; no FMI here (``framework.py`` does that). Reads a design file
(``latobs.synthesis.pi_hinf_000.to_design_dict``). States z (4) and w^ (1, bank angle):
    x^ = z + N y
    z'  = T A x^ + T B u + T F w^ + K_P (y - C x^)        (ERRATA 000; = eq. (5) with
    w^' = K_I (y - C x^)                                    Pi = T A - K_P C, K_p = K_P + Pi N)
u = delta (rad), y = [yaw rate (rad/s), roll angle (rad), roll rate (rad/s)], A, B, F the mode's
model at its model speed: the grid speed (speed modes, eq. 25) or the measured speed clamped to
the grid (tire modes). Over one call of ``step(h, u)`` the inputs are held (zero-order hold) and
the extended state s = [z; w^] obeys the linear ODE s' = M s + G w, w = [y; delta], integrated by
classical RK4 with n = ceil(h / max_step) equal substeps hs = h / n (``runtime.max_step``: the
certificate proves that step stable and accurate).

How a step is computed (exactly that discretisation, without per-step matrix work):
  * RK4 on a linear ODE with held inputs is one affine map per substep, s+ = R s + S G w with
    X = hs M, R = I + X + X^2/2 + X^3/6 + X^4/24, S = hs (I + X/2 + X^2/6 + X^3/24); n substeps
    compose to s+ = Phi s + Gam w, Phi = R^n, Gam = (sum_{k<n} R^k) S G: the same numbers as n
    RK4 substeps up to rounding (~1e-16 relative), not another discretisation.
  * Speed modes (fixed model per mode): Phi, Gam are computed once per (mode, h) (binary powering)
    and compiled together with the outputs (x^ = z+ + N y, bank = w^+) into one straight-line
    function with the coefficients as literals (``_compile``). Measured on 5 states: 3x faster
    than prebuilt rows with ``sum(map(mul, row, v))``, 2x faster than numpy ``Phi @ s + Gam @ w``.
  * Tire modes (model at the measured speed): M and G are polynomials in v = 1/vx (the design
    file's A, B, F are coefficient lists in 1/vx; their coefficient matrices in v are formed once
    at construction), hence so is the step map [Phi | Gam](v). Per (mode, h) the clamped range of
    v is cut into K equal intervals (``_TireTable``); on each, the map is replaced by its Taylor
    polynomial in v - v_c, exact coefficients computed by truncated matrix-series arithmetic, and
    terms are dropped (smallest first, per row) only while a rigorous bound of everything dropped
    (exact coefficients up to degree J, a majorant series beyond: ``_truncation_bound``) stays
    below ``TAYLOR_TOL`` = 1e-16 relative to ||[Phi | Gam]||, i.e. below the rounding of the
    map itself (a looser 1e-13 was measured to accumulate to 2e-12 through the slow bank
    integrator). Compiled like the speed modes (Horner in v - v_c), when first visited. K is
    chosen so that about ``TAYLOR_DEGREE`` = 4 suffices (K = 30/25 at 5 ms); an interval whose
    bound cannot be met (very long steps) runs the RK4 substeps. Measured (warm, 5 ms):
    degree 3: 3.9 us/step but K = 229/188 (4x the builds and memory), degree 4: 4.4, degree 5:
    5.0, degree 6: 5.4; unrolled straight-line RK4 substeps with M(v) s = M0 s + v M1 s + v^2 M2 s
    (exact, no build): 11 us for the map alone at 5 ms, proportional to the substeps; the
    coefficients passed as a tuple to one compiled function instead of literals: +13 %.
  * Maps are cached per process, keyed by the design (content fingerprint), mode and the float h,
    so that re-instantiating an FMU does not rebuild them; at most ``MAP_CACHE_SIZE`` maps and
    ``MAX_COMPILED`` compiled functions (~15 kB each) are kept, oldest dropped. The first step of
    an instance with a given (mode, h) runs the RK4 substeps directly: a host with ever-changing
    step sizes builds nothing, and which steps use a map depends only on the instance's own
    history, so results are bitwise reproducible whatever else ran in the process.

Documented clamps (never an exception for finite inputs):
  * vx < vx_hold (default 1 m/s, parameter, > 0), standstill AND reversing: integration frozen
    and every output held at its last value (the measurements are not even read), one warning
    per entry (the model has 1/Vx terms; at standstill sideslip is undefined; driving backwards
    the forward model is wrong);
  * vx outside the design grid: speed modes use the nearest mode; tire modes evaluate the model
    at the nearest grid edge; one warning per excursion;
  * ``initialize`` (at exitInitializationMode, or else the first step) sets x^ = [0, y] (beta^ = 0,
    measured r, phi, phidot) and the mode of the initial speed.
Outputs are those at the end of the step, x^ = z + N y with the held measurement.
"""
from __future__ import annotations

import itertools
import math
import threading
from bisect import bisect_right
from operator import mul

OUTPUT_NAMES = ("beta_hat", "yaw_rate_hat", "roll_angle_hat", "roll_rate_hat", "bank_angle_hat", "mode")


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


# -- compiled maps ------------------------------------------------------------------------------
_NAMESPACE = {"__builtins__": {}, "inf": math.inf, "nan": math.nan}


def _compile(series, N, var: str | None = None, center: float = 0.0):
    """Compile the step map sum_j series[j] (v - center)**j (each (n+1) x (n+1+ny+1): [Phi | Gam])
    with the output map into f(s, y0, .., dl[, v]) -> (s+, x^_0, .., x^_{n-1}), x^ = z+ + N y."""
    n1 = len(series[0])
    n, ny = n1 - 1, len(N[0])
    names = [f"s{i}" for i in range(n1)] + [f"y{j}" for j in range(ny)] + ["dl"]

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


def _rk4(M, G, N, nsub, hs, s, w):
    """n classical RK4 substeps of s' = M s + G w with w held, and the outputs: the reference
    form of the compiled maps (used at the first step with a new h and for long tire steps)."""
    b = _matvec(G, w)
    s = list(s)
    for _ in range(nsub):
        k1 = [p + q for p, q in zip(_matvec(M, s), b)]
        s2 = [x + 0.5 * hs * k for x, k in zip(s, k1)]
        k2 = [p + q for p, q in zip(_matvec(M, s2), b)]
        s3 = [x + 0.5 * hs * k for x, k in zip(s, k2)]
        k3 = [p + q for p, q in zip(_matvec(M, s3), b)]
        s4 = [x + hs * k for x, k in zip(s, k3)]
        k4 = [p + q for p, q in zip(_matvec(M, s4), b)]
        s = [x + hs / 6.0 * (a + 2 * b_ + 2 * c + d) for x, a, b_, c, d in zip(s, k1, k2, k3, k4)]
    return (tuple(s), *(s[i] + sum(map(mul, row, w)) for i, row in enumerate(N)))


def _rk4_map(Mc, Gc, N, nsub, hs):
    """f(s, y0, .., dl, v) running the RK4 substeps with the model at v = 1/vx (not compiled)."""
    def f(s, *w_v):
        v = w_v[-1]
        return _rk4(_shift(Mc, v)[0], _shift(Gc, v)[0], N, nsub, hs, s, w_v[:-1])
    return f


# -- the cache of step maps, shared by the instances of one process ---------------------------
# Instances with the same design (same fingerprint: model, gains, N, max_step, speed range and
# the tuning constants) share their maps, so that re-instantiating an FMU does not rebuild them.
_LOCK = threading.RLock()
_MAPS: dict = {}          # (design id, mode, h) -> compiled map or _TireTable, oldest first
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
    """Step maps of one tire mode and step size h: piecewise Taylor polynomials in v = 1/vx on
    K equal intervals of the clamped range of v, each compiled when first visited.
    ``taylor=False``: one interval running the RK4 substeps themselves (long steps)."""

    __slots__ = ("key", "Mc", "Gc", "N", "nsub", "hs", "D", "J", "tol", "limits", "v_lo", "v_hi", "scale",
                 "K", "fns", "built")

    def __init__(self, key, Mc, Gc, N, v_lo, v_hi, nsub, hs, degree, tol, max_intervals, limits, taylor=True):
        self.key, self.Mc, self.Gc, self.N, self.nsub, self.hs = key, Mc, Gc, N, nsub, hs
        self.D, self.J, self.tol, self.limits = degree, degree + 3, tol, limits
        self.v_lo, self.v_hi = v_lo, v_hi
        self.built = 0
        width = v_hi - v_lo
        K = 1
        if taylor and width > 0:
            # probe the coefficients at the middle of the range: K such that the degrees D + 1 and
            # D + 2 contribute about tol / 4 there (each interval is then checked on its own)
            coeffs, *_ = self._series(0.5 * (v_lo + v_hi))
            goal = tol * _norm_inf(coeffs[0]) / 4
            half = min((goal / max(_norm_inf(coeffs[j]), 1e-300)) ** (1.0 / j) for j in (degree + 1, degree + 2))
            K = max(1, min(max_intervals, math.ceil(width / (2 * half))))
        self.K = K
        self.scale = K / width if width > 0 else 0.0
        self.fns = [None if taylor else _rk4_map(Mc, Gc, N, nsub, hs)] * K

    def _series(self, v0):
        """Exact Taylor coefficients (degree <= J) in d = v - v0 of the n-substep map, and what
        the truncation bound needs: ||E_j|| (j >= 1) and max_{a <= n} ||E_0^a|| of the substep."""
        Ms, Gs = _shift(self.Mc, v0), _shift(self.Gc, v0)
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

    def build(self, k):
        """Compile interval k. Per row, the Taylor terms c d^j (j >= 1) are dropped, smallest
        |c| delta^j first, while their sum plus the bound of all terms beyond degree J stays
        within tol ||[Phi | Gam]||_inf: a rigorous bound of the row's truncation error per unit
        ||[s; w]||_inf. If the terms beyond J alone exceed it: the RK4 substeps."""
        width = self.v_hi - self.v_lo
        center = self.v_lo + (k + 0.5) * width / self.K
        delta = 0.5 * width / self.K * (1 + 1e-6) + 1e-300   # slack for the rounding of k
        coeffs, E1, alpha = self._series(center)
        budget = self.tol * _norm_inf(coeffs[0]) - _truncation_bound(coeffs, self.J, delta, E1, alpha, self.nsub)
        if budget < 0:
            fn = _rk4_map(self.Mc, self.Gc, self.N, self.nsub, self.hs)
        else:
            kept = [[row[:] for row in P] for P in coeffs]
            for i in range(len(kept[0])):
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
            fn = _compile(kept, self.N, "v", center)
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


class SwitchedPIObserver:
    """Switched PI observer of paper 000 from its design file (see the module docstring)."""

    PARAMETERS = {"vx_hold": 1.0}  # m/s: below this speed the estimates are held
    MAP_CACHE_SIZE = 32            # (design, mode, step size) maps kept at most, per process
    MAX_COMPILED = 1024            # compiled functions kept at most, per process (~15 kB each)
    TAYLOR_DEGREE = 4              # tire modes: the degree the interval count K aims at
    TAYLOR_TOL = 1e-16             # tire modes: truncation bound relative to ||[Phi | Gam]||_inf
    TAYLOR_MAX_SUBSTEPS = 64       # tire modes: longer steps run the RK4 substeps directly
    MAX_INTERVALS = 512            # tire modes: intervals K per (mode, h) at most

    def __init__(self, data: dict, params: dict | None = None):
        params = dict(params or {})
        try:
            st = data["structure"]
            self.T, self.N, self.C = _floats(st["T"]), _floats(st["N"]), _floats(st["C"])
            self.modes = data["modes"]
            self.switching = sw = data["switching"]
            self.max_step = float(data["runtime"]["max_step"])
            vx_hold = data["runtime"].get("vx_hold", self.PARAMETERS["vx_hold"])
            self._speed_bands = sw["kind"] == "speed_bands"
            if self._speed_bands:
                self._edges = [float(e) for e in sw["edges"]]
            else:
                self._slip = (float(sw["lf"]), float(sw["lr"]), sw["alpha_star"] + sw["hysteresis"],
                              sw["alpha_star"] - sw["hysteresis"])
            self._lo, self._hi = self._speed_range()
            self._fixed_v = [1.0 / float(m["model_speed"]["value"]) if m["model_speed"]["kind"] == "fixed" else None
                             for m in self.modes]
        except (KeyError, TypeError) as exc:
            raise ValueError(f"design file lacks {exc} needed by the paper-000 observer runtime") from exc
        self.vx_hold = float(params.get("vx_hold", vx_hold))
        if not (math.isfinite(self.vx_hold) and self.vx_hold > 0):       # 0 would reach 1/vx at vx = 0
            raise ValueError(f"parameter vx_hold must be finite and > 0 m/s, got {self.vx_hold}")
        if not (0 < self.max_step <= 0.01):
            raise ValueError(f"design runtime.max_step must be in (0, 0.01] s, got {self.max_step}")
        self.n = len(self.T)
        self.ny = len(self.C)
        try:
            # M(v), G(v) as polynomials in v = 1/vx: coefficient matrices, no products per step
            self._Mc, self._Gc = zip(*(self._coefficients(i) for i in range(len(self.modes))))
        except (KeyError, TypeError) as exc:
            raise ValueError(f"design file lacks {exc} needed by the paper-000 observer runtime") from exc
        self._N01 = tuple(self.N[0]) + tuple(self.N[1])   # rows of x^_0, x^_1 = beta^, r^ (tire premise)
        fingerprint = (self.max_step, self._lo, self._hi, tuple(self._fixed_v), repr((self._Mc, self._Gc, self.N)),
                       self.TAYLOR_DEGREE, self.TAYLOR_TOL, self.TAYLOR_MAX_SUBSTEPS, self.MAX_INTERVALS)
        with _LOCK:
            if fingerprint not in _IDS and len(_IDS) >= 256:
                _IDS.clear()
            self._id = _IDS.setdefault(fingerprint, next(_NEW_ID))
        self._seen: set = set()            # (mode, h) this instance has stepped with
        self._h = None                     # the step size self._fns is for
        self._fns = [None] * len(self.modes)
        self.mode = 0                      # 0-based index; the output is 1-based
        self.s = (0.0,) * (self.n + 1)     # [z; w^]
        self._started = False
        self._holding = False
        self._outside = False
        self.events: list[tuple[str, str]] = []
        self.y = {name: 0.0 for name in OUTPUT_NAMES}
        self.y["mode"] = 1

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

    def _speed_range(self) -> tuple[float, float]:
        sw = self.switching
        if sw["kind"] == "speed_bands":
            return float(sw["edges"][0]), float(sw["edges"][-1])
        lo, hi = self.modes[0]["model_speed"]["range"]
        return float(lo), float(hi)

    # -- step maps ---------------------------------------------------------------------------
    def _substeps(self, h: float) -> tuple[int, float]:
        nsub = max(1, math.ceil(h / self.max_step - 1e-9))
        return nsub, h / nsub

    def _use_step_size(self, h: float) -> None:
        """self._fns for step size h: the cached maps of the (mode, h) this instance has used;
        False for the others (their first step runs the RK4 substeps)."""
        self._h = h
        seen = self._seen
        self._fns = [_MAPS.get((self._id, i, h)) if (i, h) in seen else False for i in range(len(self.modes))]

    def _map(self, mode: int, h: float):
        """The step map of (mode, h), built if missing, or None (run the RK4 substeps) at the
        first step of this instance with (mode, h): which steps use a map depends only on the
        instance's own history, never on what other instances cached (bitwise reproducible)."""
        if self._fns[mode] is False:
            if len(self._seen) >= 4 * self.MAP_CACHE_SIZE:
                self._seen.clear()
            self._seen.add((mode, h))
            self._fns[mode] = None
            return None
        key = (self._id, mode, h)
        with _LOCK:
            fn = _MAPS.get(key)
            if fn is None:
                nsub, hs = self._substeps(h)
                v = self._fixed_v[mode]
                limits = (self.MAP_CACHE_SIZE, self.MAX_COMPILED)
                if v is not None:       # speed mode: the composite map, exact
                    W = _substep(_shift(self._Mc[mode], v)[:1], _shift(self._Gc[mode], v)[:1], hs, 0)
                    fn = _compile(_power(W, nsub, self.n + 1, 0), self.N)
                    _HELD[0] += 1
                else:
                    fn = _TireTable(key, self._Mc[mode], self._Gc[mode], self.N, 1.0 / self._hi, 1.0 / self._lo,
                                    nsub, hs, self.TAYLOR_DEGREE, self.TAYLOR_TOL, self.MAX_INTERVALS, limits,
                                    taylor=nsub <= self.TAYLOR_MAX_SUBSTEPS)
                _MAPS[key] = fn
                _trim(fn, *limits)
        self._fns[mode] = fn
        return fn

    def _step_rk4(self, mode, h, s, y0, y1, y2, delta, v):
        M, G = _shift(self._Mc[mode], v)[0], _shift(self._Gc[mode], v)[0]
        return _rk4(M, G, self.N, *self._substeps(h), s, (y0, y1, y2, delta))

    # -- stepping ----------------------------------------------------------------------------
    def xhat(self, y_meas):
        z = self.s[: self.n]
        Ny = _matvec(self.N, y_meas)
        return [a + b for a, b in zip(z, Ny)]

    def initialize(self, u: dict) -> None:
        """Start from the first measurement: x^(0) = [0, y(0)], i.e. z(0) = x^(0) - N y(0), and the
        mode of the initial speed (tire modes: mode 1)."""
        y_meas = [u["yaw_rate"], u["roll_angle"], u["roll_rate"]]
        x0 = [0.0] + y_meas
        Ny = _matvec(self.N, y_meas)
        self.s = tuple(a - b for a, b in zip(x0, Ny)) + tuple(self.s[self.n:])
        self._started = True
        if self._speed_bands and u["vx"] >= self.vx_hold:
            self.mode = self._band(u["vx"])
        self._publish(y_meas)

    def step(self, h: float, u: dict) -> None:
        vx = u["vx"]
        if not self._started:
            self.initialize(u)
        hold = self.vx_hold
        if vx < hold:                  # standstill or reversing: frozen, every output held as it is
            if not self._holding:
                self.events.append(("warning", f"vx = {vx:.3g} m/s < vx_hold = {hold:g} m/s (standstill or "
                                               "reversing): observer frozen, every estimate held"))
            self._holding = True
            return
        if self._holding:
            self.events.append(("warning", f"vx = {vx:.3g} m/s: observer resumes"))
            self._holding = False
        lo, hi = self._lo, self._hi
        if lo <= vx <= hi:
            self._outside = False
            vc = vx
        else:
            if not self._outside:
                self.events.append(("warning", f"vx = {vx:.4g} m/s outside the design grid [{lo:.4g}, {hi:.4g}] m/s: "
                                               "clamped to the nearest grid mode/speed"))
            self._outside = True
            vc = lo if vx < lo else hi
        y0, y1, y2, delta = u["yaw_rate"], u["roll_angle"], u["roll_rate"], u["delta"]
        s = self.s
        if h != self._h:
            self._use_step_size(h)
        if self._speed_bands:
            self.mode = mode = self._band(vx)
            fn = self._fns[mode] or self._map(mode, h)
            if fn is None:
                s, b, r, p, q = self._step_rk4(mode, h, s, y0, y1, y2, delta, self._fixed_v[mode])
            else:
                s, b, r, p, q = fn(s, y0, y1, y2, delta)
        else:
            n00, n01, n02, n10, n11, n12 = self._N01
            self.mode = mode = self._tire_mode(s[0] + (n00 * y0 + n01 * y1 + n02 * y2),
                                               s[1] + (n10 * y0 + n11 * y1 + n12 * y2), vx, delta)
            v = 1.0 / vc
            tab = self._fns[mode] or self._map(mode, h)
            if tab is None:
                s, b, r, p, q = self._step_rk4(mode, h, s, y0, y1, y2, delta, v)
            else:
                k = int((v - tab.v_lo) * tab.scale)
                if k >= tab.K:
                    k = tab.K - 1
                elif k < 0:
                    k = 0
                s, b, r, p, q = (tab.fns[k] or tab.build(k))(s, y0, y1, y2, delta, v)
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
                      bank_angle_hat=self.s[self.n], mode=self.mode + 1)
