"""Reference runtime of paper 001's switched interval observer (Ifqir, Ichalal, Ait-Oufroukh, Mammar,
ACC 2020): Theorem 1's observer eq. (23) with guaranteed bounds between the communication points.

Evaluates the design's tables (``synthesis.tables.lateral_interval_observer``: the model, the gains,
the step maps at the default step) with the standard library only; the native C model
(``c/lateral_interval_observer.c``) performs the same operations in the same order. The behaviour, every
departure from the printed paper and the tuning are specified in
docs/runtime/lateral_interval_observer.md; the departures are also commented where they happen.
State x = [vy, r, ay, x4]; a box is [lower0..3, upper0..3]; y = [r, ay] = [x2, x3].
Over ~600 lines because the guarantee between the samples needs more than eq. (23): the a priori
enclosure of each step, the sampled-measurement correction and the probes of the longest step.
"""
from __future__ import annotations

import math
from bisect import bisect_right
from operator import add

from .linalg import _ETA, _U, dot, expm_taylor as _expm_taylor, matvec as _matvec, phi_gamma, total

OUTPUT_NAMES = ("vy_lower", "vy_upper", "beta_lower", "beta_upper", "yaw_rate_lower", "yaw_rate_upper",
                "Fyf_lower", "Fyf_upper", "Fyr_lower", "Fyr_upper")
INTEGER_OUTPUTS = ("mode", "consistent")

_N = 4                          # states
_R = range(_N)
_INF = math.inf
_NO_XI = (-_INF,) * _N + (_INF,) * _N   # no xi bounds (after a restart or a mode switch)
MEAS, UNMEAS = (1, 2), (0, 3)   # measured states (r, ay) and the others (vy, x4)
NU_PARAMETERS = ("yaw_rate_error_bound", "ay_error_bound")      # nu of the measured rows, in MEAS order
NU_UNITS = {"yaw_rate_error_bound": "rad/s", "ay_error_bound": "m/s2"}
# the probes of the longest communication step: never frozen, exact measurements (the width map at
# zero inputs is then positively homogeneous; ``_probe_data``), so the step does not depend on nu
PROBE_PARAMETERS = {"vx_hold": 0.0, "yaw_rate_error_bound": 0.0, "ay_error_bound": 0.0}
STIFF_ROWS = (2, 3)             # rows of the stiffness part (x3', x4'), eq. (9)
CACHE_SIZE = 64                 # step maps kept per instance, per kind


# -- linear algebra (lists of rows; sums from the left) ---------------------------------------------
def _matmul(A, B):
    cols = list(zip(*B))
    return [[dot(row, col) for col in cols] for row in A]


def _addv(a, b):
    return list(map(add, a, b))


def _absm(A):
    return [[abs(x) for x in row] for row in A]


def _acc(s, coeffs, x):
    """s + sum of c_j x_j over the NONZERO c_j, left to right (a zero coefficient never meets an
    infinite bound)."""
    for c, v in zip(coeffs, x):
        if c != 0.0:
            s += c * v
    return s


def _acc_abs(s, coeffs, x):
    for c, v in zip(coeffs, x):
        if c != 0.0:
            s += abs(c) * v
    return s


def _mid_rad(X):
    """Midpoint c and radius r of the box X = [lower0..3, upper0..3], r rounded up so that the box
    lies in [c - r, c + r] exactly."""
    n = len(X) // 2
    c = [(X[j] + X[n + j]) * 0.5 for j in range(n)]
    return c, [_na(max(X[n + j] - c[j], c[j] - X[j]), _INF) for j in range(n)]


# -- rigorous rounding (DEPARTURE, not in the paper: its bounds are real numbers) -------------------
# Every bound the observer computes contains the exact real value of what it bounds for the doubles
# it is given. Sums of n products in midpoint-radius form (mid s = sum c_k m_k, rad t = sum |c_k| r_k,
# shadow a = sum |c_k| |m_k|, all added from the left in round to nearest) contain the exact
# sum c_k [m_k -+ r_k] within s -+ R, R = t + e + k u (a + t + e) + k eta, k = 2 n + 4 (Higham,
# Accuracy and Stability, 2nd ed., eq. 3.13: |fl(sum) - sum| <= gamma_n sum |terms| + n eta; the
# margin k u covers gamma_n twice over and the roundings of R itself), e the coefficients' own
# errors (coefficient error bound x sum of |m_k| + r_k) and the design residuals' effect. A single
# operation's result is rounded outward by one ulp (``_na``: the exact result lies within half an
# ulp of the rounded one); libm's exp and expm1 by 3 ulps (within 2). u, eta: ``linalg``'s.
_na = math.nextafter    # _na(x, _NINF): the next double below x (above the exact result x rounds); _INF: above
_NINF = -_INF


def _radius(t: float, a: float, e: float, n: int) -> float:
    """R >= |exact - s| for a chain of at most n terms (see above): t its radius, a its shadow, e the
    coefficients' errors."""
    k = 2 * n + 4
    return _na(t + e + k * _U * (a + t + e) + k * _ETA, _INF)


def expm_gamma(A, h: float, dA: float = 0.0):
    """(exp(A h), int_0^h exp(A s) ds, e) for any square A: the top blocks of exp([[A, I], [0, 0]] h),
    and e >= every entry's error for any exact A' with ||A' - A||_inf <= dA (``expm_taylor``'s bound,
    plus ||D|| e^(||M|| + ||D||) for the perturbation D of the block matrix: dA h and the roundings
    of A h). Infinite e: no useful bound."""
    n = len(A)
    M = [[0.0] * (2 * n) for _ in range(2 * n)]
    for i in range(n):
        for j in range(n):
            M[i][j] = A[i][j] * h
        M[i][n + i] = h
    E, e = _expm_taylor(M, with_error=True)
    nM = max(total(map(abs, row)) for row in M)
    nD = (dA * h + 2.0 * _U * nM) * (1.0 + 2.0 ** -20) + 2 * n * _ETA
    e = _na((e + nD * math.exp(nM + nD)) * (1.0 + 2.0 ** -20), _INF)
    return [row[:n] for row in E[:n]], [row[n:] for row in E[:n]], e if math.isfinite(e) else _INF


def _norm_rows(A) -> float:
    """max row sum of |A| (rounded up: a bound)."""
    return _na(max(total(map(abs, row)) for row in A) * (1.0 + 4.0 * _U), _INF)


def _mm_err(A, eA: float, B, eB: float):
    """(A B, e): the product summed from the left and e >= each entry's error against the exact
    product of matrices within eA, eB (entrywise) of A, B: ||A|| eB + eA ||B||_1 + n eA eB (the
    factors' errors) + (n + 2) u ||A|| max|B| (the rounding of the sums), rounded up."""
    C = _matmul(A, B)
    n = len(B)
    ra = _norm_rows(A)
    cb = _norm_rows(list(zip(*B)))
    bmax = max(abs(x) for row in B for x in row)
    e = (ra * eB + eA * cb + n * eA * eB + (n + 2) * _U * ra * bmax) * (1.0 + 2.0 ** -20) + n * _ETA
    return C, _na(e, _INF)


def _mv_err(A, eA: float, v, ev: float):
    """(A v, e) as ``_mm_err`` for a vector v (entries within ev)."""
    n = len(v)
    ra = _norm_rows(A)
    va = total(map(abs, v))
    vmax = max(abs(x) for x in v)
    e = (ra * ev + eA * va + n * eA * ev + (n + 2) * _U * ra * vmax) * (1.0 + 2.0 ** -20) + n * _ETA
    return _matvec(A, v), _na(e, _INF)


# -- Lemma 3 and eq. (24) ---------------------------------------------------------------------------
def lemma3_constant(A, xl, xu):
    """Eq. (20): A+ xl - A- xu <= A x <= A+ xu - A- xl for xl <= x <= xu, with A- = A+ - A >= 0
    (Efimov's convention; the paper's text defines A- = A - A+ <= 0, under which eq. (20) fails)."""
    pos = [[max(a, 0.0) for a in row] for row in A]
    neg = [[max(-a, 0.0) for a in row] for row in A]
    lo = [total(p * l - q * u for p, q, l, u in zip(rp, rn, xl, xu)) for rp, rn in zip(pos, neg)]
    hi = [total(p * u - q * l for p, q, l, u in zip(rp, rn, xl, xu)) for rp, rn in zip(pos, neg)]
    return lo, hi


def omega_bounds(P, wl, wu):
    """Eq. (24): Omega_lo = P+ wl - P- wu <= P w <= P+ wu - P- wl = Omega_up (eq. 20 applied to P).
    The runtime evaluates it in the equivalent midpoint-radius form P m +- |P| r."""
    return lemma3_constant(P, wl, wu)


# -- outward rounding of the published bounds ----------------------------------------------------
_TINY = 4.0 * _ETA              # the rounding errors' absolute floor (subnormal results)


def _outward_atan(q: float, side: int) -> float:
    """atan of the exact quotient that q = fl(num / den) rounds, rounded outward (side -1: below, +1:
    above) by 3 ulps: the division's error moves atan by at most half an ulp (|atan'(q) q| <= |atan q|),
    and libm's atan is within 2 ulps (glibc's, within 1)."""
    t = math.atan(q)
    for _ in range(3):
        t = math.nextafter(t, side * math.inf)
    return t


def _outward_sum(t1: float, t2: float, side: int) -> float:
    """t1 + t2, each a coefficient (three roundings: L = lf + lr, m lr, / L) times a bound, rounded
    outward by 8 u (|t1| + |t2|) (the error is below 5 u (|t1| + |t2|): three roundings of the
    coefficient, one of the product, one of the sum) and one ulp for the rounding of that margin."""
    err = 8.0 * _U * (abs(t1) + abs(t2)) + _TINY
    return math.nextafter(t1 + t2 + side * err, side * math.inf)


def _measured_box(y: float, nu: float) -> tuple[float, float]:
    """[y - nu, y + nu], each end rounded outward by one ulp when nu > 0 (the rounding of y -+ nu is
    within half an ulp): the box contains every value within nu of y, exactly."""
    if nu == 0.0:
        return y, y
    return math.nextafter(y - nu, -math.inf), math.nextafter(y + nu, math.inf)


def _one_minus_cos(d: float) -> float:
    """k >= 1 - cos(d), rounded up: d^2/2 (1 - cos d <= d^2/2 for every real d: exact to the
    series' first term, over by at most d^2/12 relative, no cancellation, no libm), at most 1 (cos d
    >= 0 on the input's declared range |d| <= pi/2; a documented clamp beyond it, which the FMI
    layers refuse and only a direct call of the runtime reaches); exactly 0 for d = 0."""
    if d == 0.0:
        return 0.0
    k = _na(_na(d * d, _INF) * 0.5, _INF)
    return k if k <= 1.0 else 1.0      # (a NaN steering: 1)


def _product_hull(al, au, l, u):
    """The interval product [al, au] [l, u] (contained in the bound of eq. (21), which it tightens
    when both factors change sign), by the signs of the constant factor, rounded outward."""
    if al == au:
        return (_na(al * l, _NINF), _na(al * u, _INF)) if al >= 0 else (_na(al * u, _NINF), _na(al * l, _INF))
    if al >= 0.0:
        return _na(l * al if l >= 0.0 else l * au, _NINF), _na(u * au if u >= 0.0 else u * al, _INF)
    if au <= 0.0:
        return _na(u * al if u >= 0.0 else u * au, _NINF), _na(l * au if l >= 0.0 else l * al, _INF)
    if abs(al + au) <= 1e-9 * max(-al, au):      # symmetric up to rounding: the outer magnitude
        a, mag = max(-al, au), (u if u > -l else -l)
        return _na(-a * mag, _NINF), _na(a * mag, _INF)
    return _na(min(l * au, u * al), _NINF), _na(max(l * al, u * au), _INF)


def _theta(alo: float, ahi: float, h: float) -> tuple[float, float]:
    """[th_lo, th_hi] containing theta(a, h) = (1 - exp(-a h)) / a for every a in [alo, ahi], alo > 0
    (theta falls with a): libm's expm1 within 2 ulps, the argument and the quotient rounded."""
    hi = -math.expm1(_na(-alo * h, _NINF))
    for _ in range(3):
        hi = _na(hi, _INF)
    lo = -math.expm1(_na(-ahi * h, _INF))
    for _ in range(3):
        lo = _na(lo, _NINF)
    return max(0.0, _na(lo / ahi, _NINF)), _na(hi / alo, _INF)


class IntervalObserver:
    """Switched interval observer of paper 001 from its design file and tables.

    Inputs u = {delta (rad), vx (m/s), yaw_rate (rad/s), ay (m/s^2)}; outputs ``OUTPUT_NAMES``
    (floats) and ``mode`` (1-based), ``consistent`` (0 on a step whose measurement lay outside the
    bounds). ``box`` holds the current bounds [xl, xu] of x."""

    # vx_hold (m/s): below this speed the observer is frozen; the bounds of |measured - true| of the
    # yaw rate (rad/s) and ay (m/s^2), the nu of the measured rows (not in the paper: its y is exact)
    PARAMETERS = {"vx_hold": 1.0, "yaw_rate_error_bound": 0.0, "ay_error_bound": 0.0}
    # the largest communication step when the design file does not state it: the widths of vy and
    # x4 must decay at >= DECAY (1/s) between PROBE/2 and PROBE s, on a RESOLUTION grid up to CEILING
    MAX_COMM_STEP_DECAY = 1.0
    MAX_COMM_STEP_PROBE = 1.0
    MAX_COMM_STEP_RESOLUTION = 1e-3
    MAX_COMM_STEP_CEILING = 1.0

    def __init__(self, data: dict, params: dict | None = None):
        tb = data.get("tables")
        if not tb or "modes" not in tb:
            raise ValueError("design file lacks its tables (synthesis.tables) needed by the paper-001 interval "
                             "observer runtime")
        self._data, self.tables = data, tb
        md, sk, tu = tb["model"], tb["stiffness"], tb["tuning"]
        self.model, self.modes, self.edges = md, tb["modes"], tb["edges"]
        self.w0 = tb["x0_halfwidth"]
        self.meas, self.unmeas = list(MEAS), list(UNMEAS)
        self._sk, self._tu = sk, tu
        self._damped = [i in tb["damped"] for i in _R]
        self._smooth = [j in tb["smooth"] for j in _R]
        # A0, A1 without the damped rows' diagonal (integrated exactly by the enclosure)
        self._a0u = [[0.0 if (i == j and self._damped[i]) else md["A0"][i][j] for j in _R] for i in _R]
        self._a1u = [[0.0 if (i == j and self._damped[i]) else md["A1"][i][j] for j in _R] for i in _R]
        # G's terms per row, by which of A0, A1 are nonzero (the same products in the same order as
        # the loop over j with those tests, without the tests: G runs ~10^5 times per second of probes)
        self._g_rows = []
        for i in _R:
            a0r, a1r = self._a0u[i], self._a1u[i]
            self._g_rows.append((
                [(j, a0r[j]) for j in _R if a0r[j] != 0.0], [(j, a1r[j]) for j in _R if a1r[j] != 0.0],
                [(j, abs(a0r[j])) for j in _R if a0r[j] != 0.0 and a1r[j] == 0.0],
                [(j, abs(a1r[j])) for j in _R if a0r[j] == 0.0 and a1r[j] != 0.0],
                [(j, a0r[j], a1r[j]) for j in _R if a0r[j] != 0.0 and a1r[j] != 0.0],
                md["B1"][i], md["w"][i]))
        params = dict(params or {})
        self.vx_hold = float(params.get("vx_hold", tb["vx_hold"]))
        if not (math.isfinite(self.vx_hold) and self.vx_hold >= 0):
            raise ValueError(f"parameter vx_hold must be finite and >= 0 m/s, got {self.vx_hold}")
        self.nu = [float(params.get(k, nu)) for k, nu in zip(NU_PARAMETERS, tb["nu"])]
        for k, nu in zip(NU_PARAMETERS, self.nu):
            if not (math.isfinite(nu) and nu >= 0):
                raise ValueError(f"parameter {k} ({NU_UNITS[k]}) must be finite and >= 0, got {nu}")
        self._max_comm_step = tb["max_communication_step"]
        # eq. (8) inverted: Fyf = a x3 + b x4 (``_fyf``); lr / L = a / m (``_ay_band``)
        L = md["lf"] + md["lr"]
        self._fa, self._fb, self._lr_l = md["m"] * md["lr"] / L, md["Iz"] / L, md["lr"] / L
        self._d_last = 0.0               # the steering of the last call (held over the step just ended)
        self._cores: dict = {}
        self._sampled: dict = {}
        self.mode = 0
        self.box = [0.0] * (2 * _N)
        self._xi, self._xi_mode = None, -1
        self._pending = None
        self._vx = max(self.vx_hold, 1e-3)
        self._started = self._holding = self._outside = self._inconsistent = self._fallback_episode = False
        self._fallback_steps = 0
        self.events: list[tuple[str, str]] = []
        self.y: dict = {name: 0.0 for name in OUTPUT_NAMES}
        self.y["mode"], self.y["consistent"] = 1, 1

    @classmethod
    def parameter_defaults(cls, data: dict) -> dict:
        """vx_hold and the measurement-error bounds of the design file (runtime.y_error_bound)."""
        rt = data.get("runtime", {})
        nu = rt.get("y_error_bound", [0.0, 0.0])
        return {"vx_hold": float(rt.get("vx_hold", cls.PARAMETERS["vx_hold"])),
                **{k: float(x) for k, x in zip(NU_PARAMETERS, nu)}}

    # -- the model's right-hand side ------------------------------------------------------------
    def _stiffness(self, l, u, vd, lo, hi):
        """Adds to lo/hi (rows x3', x4') the bound of dA(dc) x + vx dB1(dc) delta over x in [l, u]
        and the stiffness box (vd = vx delta; None: dA x alone). DEPARTURE (a tightening of eq. (25)
        that keeps the guarantee): by the uncertainty's structure, with the slip angles of eq. (4)
        multiplied by vx, uf = vx delta - x1 - lf x2, ur = -x1 + lr x2:
            dA x + vx dB1 delta = [0, 0, k3 (p + q), k4f p - k4r q],  p = dcf uf,  q = dcr ur,
        exact interval products and interval addition with signs (p, q independent). An asymmetric
        box: intersected with the elementwise bound [dA][x] + vd [dB1] (both contain the value)."""
        # every operation rounded outward (vd = fl(vx delta): the exact product within [_dn, _up])
        sk, md = self._sk, self.model
        lf, lr = sk["lf"], sk["lr"]
        if vd is None:
            ufl, ufu = _na(-u[0] - _na(lf * u[1], _INF), _NINF), _na(-l[0] - _na(lf * l[1], _NINF), _INF)
        else:
            ufl = _na(_na(_na(vd, _NINF) - u[0], _NINF) - _na(lf * u[1], _INF), _NINF)
            ufu = _na(_na(_na(vd, _INF) - l[0], _INF) - _na(lf * l[1], _NINF), _INF)
        url, uru = _na(_na(lr * l[1], _NINF) - u[0], _NINF), _na(_na(lr * u[1], _INF) - l[0], _INF)
        pl, pu = _product_hull(sk["dcf"][0], sk["dcf"][1], ufl, ufu)
        ql, qu = _product_hull(sk["dcr"][0], sk["dcr"][1], url, uru)
        k3, k4f, k4r = sk["k3"], sk["k4f"], sk["k4r"]
        rl = [_na(k3 * _na(pl + ql, _NINF), _NINF), _na(_na(k4f * pl, _NINF) - _na(k4r * qu, _INF), _NINF)]
        ru = [_na(k3 * _na(pu + qu, _INF), _INF), _na(_na(k4f * pu, _INF) - _na(k4r * ql, _NINF), _INF)]
        if not sk["symmetric"]:
            for k, i in enumerate(STIFF_ROWS):
                el = eu = 0.0
                for j in _R:
                    al, au = md["dA_lower"][i][j], md["dA_upper"][i][j]
                    if al != 0.0 or au != 0.0:
                        a, b = _product_hull(al, au, l[j], u[j])
                        el = _na(el + a, _NINF)
                        eu = _na(eu + b, _INF)
                bl, bu = md["dB1_lower"][i], md["dB1_upper"][i]
                if vd is not None and (bl != 0.0 or bu != 0.0):
                    a, b = _product_hull(bl, bu, _na(vd, _NINF), _na(vd, _INF))
                    el = _na(el + a, _NINF)
                    eu = _na(eu + b, _INF)
                sl, su = max(rl[k], el), min(ru[k], eu)
                rl[k], ru[k] = (su, sl) if sl > su else (sl, su)     # (both contain the value: never)
        for k, i in enumerate(STIFF_ROWS):
            lo[i] = _na(lo[i] + rl[k], _NINF)
            hi[i] = _na(hi[i] + ru[k], _INF)

    def stiffness_bounds(self, vx: float, d: float, box):
        """(lower0..3, upper0..3): the bound of dA(dc) x + vx dB1(dc) d over the box and the stiffness box."""
        lo, hi = [0.0] * _N, [0.0] * _N
        self._stiffness(box[:_N], box[_N:], vx * d, lo, hi)
        return lo + hi

    def G(self, vx: float, d: float, X):
        """The hull of A(vx, c) x + B(vx, c) d (+-w) over x in X and c in the stiffness box, WITHOUT the
        damped rows' diagonal terms: the point matrix A0 + vx A1 by eq. (20) in midpoint-radius form."""
        avx, vd = abs(vx), vx * d
        c, r = _mid_rad(X)
        ac = [abs(x) for x in c]
        lo, hi = [0.0] * _N, [0.0] * _N
        for i, (nz0, nz1, only0, only1, both, b1, wi) in enumerate(self._g_rows):
            m = w = a = 0.0           # mid, radius, shadow (rigorous rounding, above)
            for j, c0 in nz0:
                m += c0 * c[j]
                a += abs(c0) * ac[j]
            for j, c0 in only0:
                w += c0 * r[j]
            if nz1:
                m1 = a1 = 0.0
                for j, c1 in nz1:
                    m1 += c1 * c[j]
                    a1 += abs(c1) * ac[j]
                m += vx * m1
                a += avx * a1
            if only1:
                w1 = 0.0
                for j, c1 in only1:
                    w1 += c1 * r[j]
                w += avx * w1
            for j, a0, a1 in both:    # |a0 + vx a1| within 2 u (|a0| + |vx a1|) of its exact value
                w += abs(a0 + vx * a1) * r[j]
                a += (abs(a0) + avx * abs(a1)) * r[j]
            if b1 != 0.0:             # vd = fl(vx d): one more rounding
                m += vd * b1
                a += abs(vd * b1)
            if wi != 0.0:      # runtime.disturbance_bound (not in the paper)
                w += wi
            R = _radius(w, a, 0.0, 16)
            lo[i], hi[i] = _na(m - R, _NINF), _na(m + R, _INF)
        self._stiffness(X[:_N], X[_N:], vd, lo, hi)
        return lo + hi

    def F(self, vx: float, d: float, box):
        """The hull of A(vx, c) x + B(vx, c) d over the box and the stiffness box (G + the damped diagonal)."""
        f = self.G(vx, d, box)
        for i in _R:
            if self._damped[i]:
                alo, ahi = self._decay(i, vx)
                pl, pu = _product_hull(-ahi, -alo, box[i], box[_N + i])
                f[i], f[_N + i] = _na(f[i] + pl, _NINF), _na(f[_N + i] + pu, _INF)
        return f

    def _decay(self, i, vx):
        """[alo, ahi] containing a = -d_i(vx) = -(A0_ii + vx A1_ii): the known decay rate of a damped
        row (1/s), its evaluation rounded outward."""
        a0, a1 = self.model["A0"][i][i], self.model["A1"][i][i]
        return _na(-a0 - _na(vx * a1, _INF), _NINF), _na(-a0 - _na(vx * a1, _NINF), _INF)

    # -- a priori enclosure of x over a (sub)step ----------------------------------------------------
    def _extents(self, hs, a, th, X, g, S):
        """T(S), rounded outward: a damped row with a > 0 (a in [alo, ahi] = a[i]) by the convex
        combination x_i(s) = x_i(0) + theta(s) (g - a x_i(0)), theta(s) in [0, th] (no wrapping),
        th >= (1 - exp(-alo hs))/alo; another damped row x_i(0) + [0, hs] (g - a S_i); the others
        x_i(0) + [0, hs] G_i(S)."""
        T = [0.0] * (2 * _N)
        for i in _R:
            l, u, gl, gu = X[i], X[_N + i], g[i], g[_N + i]
            if self._damped[i]:
                alo, ahi = a[i]
                if alo > 0.0:
                    pl, pu = _product_hull(alo, ahi, l, l)
                    t = _na(gl - pu, _NINF)
                    T[i] = _na(l + _na(th[i] * t, _NINF), _NINF) if t < 0.0 else l
                    pl, pu = _product_hull(alo, ahi, u, u)
                    t = _na(gu - pl, _INF)
                    T[_N + i] = _na(u + _na(th[i] * t, _INF), _INF) if t > 0.0 else u
                    continue
                pl, pu = _product_hull(alo, ahi, S[i], S[_N + i])
                gl, gu = _na(gl - pu, _NINF), _na(gu - pl, _INF)
            T[i] = _na(l + _na(hs * gl, _NINF), _NINF) if gl < 0.0 else l
            T[_N + i] = _na(u + _na(hs * gu, _INF), _INF) if gu > 0.0 else u
        return T

    def _enclose(self, hs, vx, d, X):
        """S is accepted when T(S) lies in S: then x(s) is in T(S) for all s in [0, hs] (returned after
        one refining pass T(T)). S: X extended by ``enclosure_grow`` times the extents of T(X), then of
        the last T(S) (never shrinking); None after ``enclosure_tries`` tries."""
        tu = self._tu
        a, th = [(0.0, 0.0)] * _N, [0.0] * _N
        for i in _R:
            if self._damped[i]:
                a[i] = self._decay(i, vx)
                if a[i][0] > 0.0:
                    th[i] = _theta(a[i][0], a[i][1], hs)[1]
        T = self._extents(hs, a, th, X, self.G(vx, d, X), X)
        e = [T[i] - X[i] for i in range(2 * _N)]
        grow = tu["enclosure_grow"]
        for _ in range(tu["enclosure_tries"]):
            S = [X[i] + grow * e[i] for i in range(2 * _N)]
            T = self._extents(hs, a, th, X, self.G(vx, d, S), S)
            if all(T[i] >= S[i] and T[_N + i] <= S[_N + i] for i in _R):
                return self._extents(hs, a, th, X, self.G(vx, d, T), T)
            for i in _R:                # the extents never shrink
                if T[i] - X[i] < e[i]:
                    e[i] = T[i] - X[i]
                if T[_N + i] - X[_N + i] > e[_N + i]:
                    e[_N + i] = T[_N + i] - X[_N + i]
            if tu["enclosure_mult"] != 1.0:
                grow = tu["enclosure_mult"] * grow
        return None

    def _majorant(self, vx: float):
        """Metzler majorant of A(vx, c) over the stiffness box: largest diagonal, largest |off-diagonal|
        (rounded up)."""
        md = self.model
        M = [[0.0] * _N for _ in _R]
        for i in _R:
            for j in _R:
                a0, a1 = md["A0"][i][j], md["A1"][i][j]
                lo = _na(_na(a0 + _na(vx * a1, _NINF), _NINF) + md["dA_lower"][i][j], _NINF)
                hi = _na(_na(a0 + _na(vx * a1, _INF), _INF) + md["dA_upper"][i][j], _INF)
                M[i][j] = hi if i == j else max(abs(lo), abs(hi))
        return M

    def _comparison_enclosure(self, hs, vx, d, box):
        """Fallback for any hs: d(s) = x(s) - x_k obeys |d|' <= M |d| + g (M the Metzler majorant,
        g = max |F(X_k)|), so |d(s)| <= Gamma(M, hs) g (comparison principle; Gamma's entries within
        its bracket e, the sum rounded up); intersected with X_k + [0, hs] F(S)."""
        f = self.F(vx, d, box)
        g = [max(abs(f[i]), abs(f[_N + i])) for i in _R]
        M = self._majorant(vx)
        shift = max(0.0, max(-M[i][i] for i in _R))
        _, Gam, e = phi_gamma(M, hs, shift, with_error=True)
        if not math.isfinite(e):
            raise ValueError(f"no finite comparison bound (hs = {hs!r} s, vx = {vx!r} m/s)")
        sg = total(g)
        R = [_na(x * (1.0 + 8.0 * _U) + e * sg * (1.0 + 8.0 * _U), _INF) for x in _matvec(Gam, g)]
        S = [_na(box[i] - R[i], _NINF) for i in _R] + [_na(box[_N + i] + R[i], _INF) for i in _R]
        f = self.F(vx, d, S)
        T = [_na(box[i] + _na(hs * f[i], _NINF), _NINF) if f[i] < 0.0 else box[i] for i in _R] + \
            [_na(box[_N + i] + _na(hs * f[_N + i], _INF), _INF) if f[_N + i] > 0.0 else box[_N + i] for i in _R]
        return [max(S[i], T[i]) for i in _R] + [min(S[_N + i], T[_N + i]) for i in _R]

    def _predict(self, h, vx, d, X, T):
        """(Fbar, B): Fbar the hull of F over the enclosure T, B the box of x(t + h) from the box X of
        x(t): a damped row with a > 0 exactly (x_i(h) = x_i(0) + theta(h) (gbar - a x_i(0)), theta(h)
        in [th_lo, th_hi]), the others x(h) in x(0) + h Fbar; intersected with T; rounded outward."""
        F = self.G(vx, d, T)
        B = [0.0] * (2 * _N)
        for i in _R:
            l, u = X[i], X[_N + i]
            if self._damped[i]:
                alo, ahi = self._decay(i, vx)
                if alo > 0.0:
                    tl, th = _theta(alo, ahi, h)
                    t = _na(F[i] - _product_hull(alo, ahi, l, l)[1], _NINF)
                    B[i] = _na(l + min(_na(tl * t, _NINF), _na(th * t, _NINF)), _NINF)
                    t = _na(F[_N + i] - _product_hull(alo, ahi, u, u)[0], _INF)
                    B[_N + i] = _na(u + max(_na(tl * t, _INF), _na(th * t, _INF)), _INF)
                pl, pu = _product_hull(-ahi, -alo, T[i], T[_N + i])
                F[i], F[_N + i] = _na(F[i] + pl, _NINF), _na(F[_N + i] + pu, _INF)
                if alo <= 0.0:
                    B[i], B[_N + i] = _na(l + _na(h * F[i], _NINF), _NINF), _na(u + _na(h * F[_N + i], _INF), _INF)
            else:
                B[i], B[_N + i] = _na(l + _na(h * F[i], _NINF), _NINF), _na(u + _na(h * F[_N + i], _INF), _INF)
            if B[i] < T[i]:
                B[i] = T[i]
            if B[_N + i] > T[_N + i]:
                B[_N + i] = T[_N + i]
        return F, B

    # -- the sampled-measurement correction (a continuous-discrete interval observer; not in the paper)
    def _sampled_maps(self, vx: float, h: float):
        """The maps of a step h at the model speed vx, n substeps of hs = h / n, n a power of two (so
        n hs = h exactly) (A = A0 + vx A1, Bv = vx B1): phi[m] = exp(A m hs), aphi[m] = |phi[m]|,
        gamb[m] = int_0^(m hs) exp(A s) ds Bv, pg[i] = exp(A i hs) Gam(hs), apg[i] = |exp(A i hs)|
        Gam_M(hs) (M the Metzler majorant of A: |exp(A t)| <= exp(M t)), each with e >= its entries'
        errors (``ephi``, ...: the bracket of the exact map), and the gains L (K = I - L C): L = 0, the
        deadbeat gain that lets the two samples determine vy and x4, and the gains cancelling one
        unmeasured column by one measurement. Each gain: (L, K phi[n], |K phi[n]|, K gamb[n],
        [K pg[i]], [|K phi[i]| Gam_M], |L|, and the errors of K phi[n], K gamb[n], [K pg[i]],
        [|K phi[i]| Gam_M]); K = I - L C exactly up to its rounding (within u |K|)."""
        key = (vx, h)
        sm = self._sampled.get(key)
        if sm is not None:
            return sm
        md, tu = self.model, self._tu
        A = [[a + vx * b for a, b in zip(r0, r1)] for r0, r1 in zip(md["A0"], md["A1"])]
        Al = [[_na(a + _na(vx * b, _NINF), _NINF) for a, b in zip(r0, r1)] for r0, r1 in zip(md["A0"], md["A1"])]
        Au = [[_na(a + _na(vx * b, _INF), _INF) for a, b in zip(r0, r1)] for r0, r1 in zip(md["A0"], md["A1"])]
        dA = _norm_rows([[u - l for l, u in zip(rl, ru)] for rl, ru in zip(Al, Au)])
        Bv = [vx * b for b in md["B1"]]
        eBv = _na(max(map(abs, Bv)) * 2.0 * _U, _INF)
        n = min(max(1, math.ceil(h / tu["sampled_substep"] - 1e-9)), tu["sampled_max_substeps"])
        n = 1 << (n - 1).bit_length()          # a power of two: h / n exact
        if n > tu["sampled_max_substeps"]:
            raise ValueError(f"sampled_max_substeps = {tu['sampled_max_substeps']} is not a power of two")
        hs = h / n
        norm = max(total(map(abs, row)) for row in A) * hs
        if not norm <= tu["sampled_max_norm"]:        # |vx| far beyond any vehicle
            raise ValueError(f"no sampled step map at vx = {vx!r} m/s (||A hs|| = {norm:g})")
        phid, gamd, ed = expm_gamma(A, hs, dA)
        Mj = [[Au[i][j] if i == j else max(abs(Al[i][j]), abs(Au[i][j])) for j in _R] for i in _R]
        _, gamM, eM = phi_gamma(Mj, hs, max(0.0, max(-Mj[i][i] for i in _R)), with_error=True)
        gdb, egdb = _mv_err(gamd, ed, Bv, eBv)
        eye = [[1.0 if i == j else 0.0 for j in _R] for i in _R]
        # phi[m] = phi[m-1] phid: with Phi = exp(A hs) exact, phi[m] - Phi^m = sum_k delta_k Phi^(m-k),
        # ||delta_k|| <= c_k = ||phi[k-1]|| ed + 6 u ||phi[k-1]|| ||phid|| (the product's rounding) and
        # ||Phi^j|| <= ||phi[j]|| + ephi[j]: errors grow linearly in m, not as ||phid||^m
        phi, ephi, gamb, egamb = [eye], [0.0], [[0.0] * _N], [0.0]
        nphi, cs, nd = [1.0], [], _norm_rows(phid)
        for m in range(1, n + 1):
            g, eg = _mv_err(phi[-1], ephi[-1], gdb, egdb)
            gamb.append(_addv(gamb[-1], g))
            egamb.append(_na((egamb[-1] + eg + 2.0 * _U * max(map(abs, gamb[-1]))) * (1.0 + 2.0 ** -20), _INF))
            cs.append((nphi[-1] * ed + 6.0 * _U * nphi[-1] * nd) * (1.0 + 2.0 ** -20) + _N * _ETA)
            phi.append(_matmul(phi[-1], phid))
            nphi.append(_norm_rows(phi[-1]))
            ephi.append(_na(total(cs[k - 1] * (nphi[m - k] + ephi[m - k]) for k in range(1, m + 1))
                            * (1.0 + 2.0 ** -20), _INF))
        aphi = [_absm(p) for p in phi]
        pg, epg, apg, eapg = [], [], [], []
        for p, ep, ap in zip(phi[:n], ephi[:n], aphi[:n]):
            x, ex = _mm_err(p, ep, gamd, ed)
            pg.append(x)
            epg.append(ex)
            x, ex = _mm_err(ap, ep, gamM, eM)
            apg.append(x)
            eapg.append(ex)
        ph = phi[n]
        options = []                    # the unmeasured rows' L (one entry per measurement)
        D = [[ph[q][j] for j in UNMEAS] for q in MEAS]
        det = D[0][0] * D[1][1] - D[0][1] * D[1][0]
        if det != 0.0 and math.isfinite(det):
            inv = [[D[1][1] / det, -D[0][1] / det], [-D[1][0] / det, D[0][0] / det]]
            options.append({i: [total(ph[i][UNMEAS[k]] * inv[k][q] for k in range(2)) for q in range(2)]
                            for i in UNMEAS})
        for j in UNMEAS:
            for q, jm in enumerate(MEAS):
                if ph[jm][j] != 0.0:
                    options.append({i: [ph[i][j] / ph[jm][j] if qq == q else 0.0 for qq in range(2)] for i in UNMEAS})
        gains = []
        for opt in options:
            L = [[0.0, 0.0] for _ in _R]
            for q, jm in enumerate(MEAS):
                L[jm][q] = 1.0
            for i, li in opt.items():
                L[i] = li
            if not all(math.isfinite(x) for r in L for x in r):
                continue
            K = [[eye[i][j] - total(L[i][q] for q, jm in enumerate(MEAS) if jm == j) for j in _R] for i in _R]
            eK = _na(max(abs(x) for r in K for x in r) * _U, _INF)
            Kphi, eKphi = _mm_err(K, eK, ph, ephi[n])
            Kgb, eKgb = _mv_err(K, eK, gamb[n], egamb[n])
            Kpg, eKpg, aKpg, eaKpg = [], [], [], []
            for x, ex, p, ep in zip(pg, epg, phi[:n], ephi[:n]):
                y, ey = _mm_err(K, eK, x, ex)
                Kpg.append(y)
                eKpg.append(ey)
                y, ey = _mm_err(K, eK, p, ep)
                y, ey = _mm_err(_absm(y), ey, gamM, eM)
                aKpg.append(y)
                eaKpg.append(ey)
            gains.append((L, Kphi, _absm(Kphi), Kgb, Kpg, aKpg, _absm(L), eKphi, eKgb, eKpg, eaKpg))
        sm = (n, hs, phi, aphi, gamb, pg, apg, gains, ephi, egamb, epg, eapg)
        if len(self._sampled) >= CACHE_SIZE:
            self._sampled.pop(next(iter(self._sampled)))
        self._sampled[key] = sm
        return sm

    def _sampled_predict(self, h: float, vx: float, d: float, X):
        """The box of x(t + h) by the model alone (no output injection):
            x(s) = exp(A s) x(t) + int_0^s exp(A u) du Bv d + int_0^s exp(A (s - u)) omega(u) du,
        omega the stiffness part (over each substep's a priori enclosure, any stiffness in the box),
        the speed mismatch vx - vq and the disturbance: [mo_m -+ ro_m] per substep; in
        midpoint-radius form from x(t) (no wrapping), rounded rigorously (the maps' brackets and the
        sums' rounding). Also what ``_sampled_correct`` needs."""
        vq = self._tu["sampled_dv"] * round(vx / self._tu["sampled_dv"])
        sm = self._sampled_maps(vq, h)
        n, hs, phi, aphi, gamb, pg, apg, _, ephi, egamb, epg, eapg = sm
        c0, r0 = _mid_rad(X)
        ac0 = [abs(x) for x in c0]
        s0 = total(ac0) + total(r0)
        md = self.model
        dv = vx - vq
        adv, ad = abs(dv), abs(d)
        mo, ro, so = [], [], []
        for m in range(n + 1):
            c = _addv(_matvec(phi[m], c0), [g * d for g in gamb[m]])
            r = _matvec(aphi[m], r0)
            a = _addv(_matvec(aphi[m], ac0), [abs(g * d) for g in gamb[m]])
            e = ephi[m] * s0 + egamb[m] * ad
            for i in range(m):
                P, aP = pg[m - 1 - i], apg[m - 1 - i]
                c = _addv(c, _matvec(P, mo[i]))
                r = _addv(r, _matvec(aP, ro[i]))
                a = _addv(a, _matvec(_absm(P), [abs(x) for x in mo[i]]))
                e += epg[m - 1 - i] * so[i] + eapg[m - 1 - i] * total(ro[i])
            R = [_radius(r[i], a[i], e, 8 * m + 8) for i in _R]
            Bm = [_na(c[i] - R[i], _NINF) for i in _R] + [_na(c[i] + R[i], _INF) for i in _R]
            if m == n:
                break
            T = self._enclose(hs, vx, d, Bm)
            if T is None:
                T = self._comparison_enclosure(hs, vx, d, Bm)
            S = self.stiffness_bounds(vx, d, T)
            tc, tr = _mid_rad(T)
            ms, rs = _mid_rad(S)
            om, orr = [], []
            for i in _R:              # (vx - vq) (A1 x + B1 d) over T: dv = fl(vx - vq) one rounding
                a1, b1 = md["A1"][i], md["B1"][i]
                x = dot(a1, tc) + b1 * d
                om.append(ms[i] + dv * x)
                t = rs[i] + md["w"][i] + adv * dot(map(abs, a1), tr)
                sa = abs(ms[i]) + adv * (dot(map(abs, a1), map(abs, tc)) + abs(b1 * d))
                orr.append(_radius(t, sa, 0.0, 12))
            mo.append(om)
            ro.append(orr)
            so.append(total(map(abs, om)) + total(orr))
        if not all(map(math.isfinite, Bm)):
            return None, None
        return Bm, (sm, c0, r0, d, mo, ro, so, s0)

    def _sampled_correct(self, state, Y):
        """x(t + h) = (I - L C) x(t + h) + L y(t + h) exactly for every gain L, with y in Y = [yl, yu]:
        K phi[n] c0 + K gamb[n] d + sum_i K pg[n-1-i] mo_i + L yc
        +- (|K phi[n]| r0 + sum_i |K phi[n-1-i]| Gam_M ro_i + |L| yr), intersected over the gains;
        rounded rigorously (the maps' brackets, K's rounding and the sums')."""
        sm, c0, r0, d, mo, ro, so, s0 = state
        n, gains = sm[0], sm[7]
        yc, yr = _mid_rad(Y)
        ac0, ayc, ad = [abs(x) for x in c0], [abs(x) for x in yc], abs(d)
        amo = [[abs(x) for x in v] for v in mo]
        sro = [total(v) for v in ro]
        lo, hi = [-_INF] * _N, [_INF] * _N
        for L, Kphi, aKphi, Kgb, Kpg, aKpg, aL, eKphi, eKgb, eKpg, eaKpg in gains:
            c = _addv(_addv(_matvec(Kphi, c0), [g * d for g in Kgb]), _matvec(L, yc))
            r = _addv(_matvec(aKphi, r0), _matvec(aL, yr))
            a = _addv(_addv(_matvec(aKphi, ac0), [abs(g * d) for g in Kgb]), _matvec(aL, ayc))
            e = eKphi * s0 + eKgb * ad
            for i in range(n):
                P = Kpg[n - 1 - i]
                c = _addv(c, _matvec(P, mo[i]))
                r = _addv(r, _matvec(aKpg[n - 1 - i], ro[i]))
                a = _addv(a, _matvec(_absm(P), amo[i]))
                e += eKpg[n - 1 - i] * so[i] + eaKpg[n - 1 - i] * sro[i]
            for i in _R:
                R = _radius(r[i], a[i], e, 8 * n + 8)
                if _na(c[i] - R, _NINF) > lo[i]:
                    lo[i] = _na(c[i] - R, _NINF)
                if _na(c[i] + R, _INF) < hi[i]:
                    hi[i] = _na(c[i] + R, _INF)
        return lo + hi

    # -- eq. (23) over a step ------------------------------------------------------------------------
    def _core(self, mode: int, h: float) -> dict:
        """The correction's coefficients of (mode, h) from the step maps (the tables' at the default
        step, else ``phi_gamma``), and the enclosure's substeps (hs rho(|A|) <= substep_rho_h). With
        W1 = Gam1/h, W0 = Gam - W1 (the weights of the samples y(t), y(t + h)), W2 = |h Gam1/2 - Gam2|
        and W3 = 2 W2/h (of the remainder of y between them)."""
        core = self._cores.get((mode, h))
        if core is not None:
            return core
        m, tb = self.modes[mode], self.tables
        nsub = max(1, math.ceil(h * m["rho"] / self._tu["substep_rho_h"] - 1e-9))
        if h == tb["h0"]:
            (Phi, Gam, Gam1, Gam2), e = m["maps_h0"], m["maps_h0_error"]
        else:
            Phi, Gam, Gam1, Gam2, e = phi_gamma(m["N"], h, m["eta"], order=3, with_error=True)
            if not math.isfinite(e):
                raise ValueError(f"no finite step map of mode {mode + 1} for h = {h!r} s")
        J, P = m["J"], m["P"]
        W1 = [[x / h for x in row] for row in Gam1]
        W0 = [[x - w for x, w in zip(rg, rw)] for rg, rw in zip(Gam, W1)]
        W2 = [[abs(h * g1 / 2 - g2) for g1, g2 in zip(r1, r2)] for r1, r2 in zip(Gam1, Gam2)]
        W3 = [[2 * w / h for w in row] for row in W2]
        W0J, W1J, W2J, W2aJ, W3aJ = (_matmul(W0, J), _matmul(W1, J), _matmul(W2, J), _matmul(W2, _absm(J)),
                                     _matmul(W3, _absm(J)))
        sm = [self._smooth[j] for j in MEAS]
        # the coefficients' error bounds (each entry against the exact maps' coefficients), from the maps'
        # e (g: their largest entry): W1 = Gam1/h, W0 = Gam - W1, W2 = |h Gam1/2 - Gam2|, W3 = 2 W2/h,
        # then the products with J, |J| (column sums <= cJ), P, |P| (cP) and H with their rounding (5 u)
        g = max(abs(x) for M in (Phi, Gam, Gam1, Gam2) for row in M for x in row)
        H = m["H"]
        cJ = max(total(abs(row[j]) for row in J) for j in range(2))
        cP = max(total(abs(row[j]) for row in P) for j in _R)
        eW1 = (e + _U * g) / h
        eW0 = e + eW1 + _U * (g + g / h)
        eW2 = e * (1.0 + h) + 2.0 * _U * g * (1.0 + h)
        eW3 = 2.0 * eW2 / h + _U * g * (1.0 + 2.0 / h)
        gW = g * (2.0 + 2.0 / h)              # >= every entry of W0 .. W3
        slack = 1.0 + 2.0 ** -20
        up = lambda x: _na(x * slack, _INF)     # noqa: E731
        err = {"phi": e, "w0j": up((eW0 + 5.0 * _U * gW) * cJ), "w1j": up((eW1 + 5.0 * _U * gW) * cJ),
               "w2j": up((eW2 + 5.0 * _U * gW) * cJ), "w3j": up(2.0 * (eW3 + 5.0 * _U * gW) * cJ),
               "gp": up((e + 5.0 * _U * g) * cP), "gh": up((e + 5.0 * _U * g) * total(map(abs, H)))}
        # the row sums of Gam (rounded up, with its bracket): the weight of the design residuals
        gsum = [_na(total(row) * (1.0 + 8.0 * _U) + 4.0 * e, _INF) for row in Gam]
        core = {"nsub": nsub, "err": err, "gsum": gsum, "hs": h / nsub, "phi": Phi, "w0j": W0J,
                "aw0j": _absm(W0J), "w1j": W1J, "aw1j": _absm(W1J),
                "w2j_neg": [[-x if s else 0.0 for x, s in zip(row, sm)] for row in W2J],
                "w2aj": [[x if s else 0.0 for x, s in zip(row, sm)] for row in W2aJ],
                "w3aj2": [[0.0 if s else 2.0 * x for x, s in zip(row, sm)] for row in W3aJ],
                "gp": _matmul(Gam, P), "gap": _matmul(Gam, _absm(P)), "g1p": _matmul(Gam1, P),
                "g1ap": _matmul(Gam1, _absm(P)), "gh": _matvec(Gam, m["H"])}
        if len(self._cores) >= CACHE_SIZE:
            self._cores.pop(next(iter(self._cores)))
        self._cores[(mode, h)] = core
        return core

    def _omega(self, mode, vx, d, X, c, r, with_input):
        """Midpoint and radius of omega = (A(vx, c) - A_j) x + (B(vx, c) - B_j) d over the box X (eq. 25
        via Lemma 3). DEPARTURE: the paper's A_sigma is the grid speed's model and ignores the speed
        mismatch inside a band; here (vx - vx_j) A1 x is bounded by eq. (20), (vx - vx_j) B1 d exactly
        (with_input), the stiffness part by its structure (``_stiffness``), plus the disturbance.
        The radius is rigorous (dv = fl(vx - vx_j) one rounding; the shadow counts it)."""
        md = self.model
        dv = vx - self.modes[mode]["vx"]
        adv, dvd = abs(dv), dv * d
        ac = [abs(x) for x in c]
        sl, su = [0.0] * _N, [0.0] * _N
        self._stiffness(X[:_N], X[_N:], vx * d if with_input else None, sl, su)
        oc, orad = [0.0] * _N, [0.0] * _N
        for i in _R:
            mid = rad = sh = 0.0
            if any(a != 0.0 for a in md["A1"][i]):
                mid += dv * _acc(0.0, md["A1"][i], c)
                rad += adv * _acc_abs(0.0, md["A1"][i], r)
                sh += adv * _acc_abs(0.0, md["A1"][i], ac)
            if with_input and md["B1"][i] != 0.0:
                mid += dvd * md["B1"][i]
                sh += abs(dvd * md["B1"][i])
            if with_input and md["w"][i] != 0.0:
                rad += md["w"][i]
            if i in STIFF_ROWS:
                ms = (sl[i] + su[i]) * 0.5
                mid += ms
                rad += _na(max(su[i] - ms, ms - sl[i]), _INF)
                sh += abs(ms)
            oc[i], orad[i] = mid, _radius(rad, sh, 0.0, 12)
        return oc, orad

    @staticmethod
    def _rebase(P, c, r, xi):
        """xi := xi intersected with the hull of P x over the box (midpoint c, radius r; eq. 20, rounded
        outward): both contain P x; after a mode switch (no xi: +-inf) the hull alone, so the bounds
        of x stay continuous across switches (the paper re-uses xi with the new P)."""
        ac = [abs(x) for x in c]
        for i in _R:
            p, q = _acc(0.0, P[i], c), _acc_abs(0.0, P[i], r)
            R = _radius(q, _acc_abs(0.0, P[i], ac), 0.0, 4)
            pl, pu = _na(p - R, _NINF), _na(p + R, _INF)
            if pl > xi[i]:
                xi[i] = pl
            if pu < xi[_N + i]:
                xi[_N + i] = pu
            if xi[i] > xi[_N + i]:
                xi[i], xi[_N + i] = pl, pu
        return xi

    def _correct(self, k, p, Y, B):
        """Eq. (23) over the pending step [t - h, t] once y(t) is known (the observer runs one step
        behind its published prediction), exactly discretised:
            xi(t) = Phi xi + int_0^h exp(N (h - s)) (J y(s) + H d + P omega(s)) ds,
        bounded term by term with the nonnegative kernels exp(N s) >= 0 (order preserving; a plain
        RK4 step is not). DEPARTURE (sampled y): y(s) = the interpolation of its two samples (weights
        W0, W1) plus a remainder, -(s (h - s)/2) [y''] on the smooth rows ([y''] = the row's form over
        Fbar; weight W2), +-(s (h - s)/h) width(Fbar_j) otherwise (weight W3); omega over the box at
        the start (weight Gam) plus its growth over Fbar (Gam1); Omega by eq. (24) and J y alike in
        midpoint-radius form. Then the box x = xi + E y(t), intersected with the predicted box B and,
        on the measured rows, with Y. DEPARTURE (floating point): rounded rigorously, with the
        coefficients' error bound (``_core``) and the design residuals' effect: with R1 = P A_j - N P
        - J C, R2 = P B_j - H, R3 = I - E C - P (exactly 0 in the paper; the tables bound their
        doubles' ||.||_inf, rho), xi' gains R1 x + R2 d (<= rho1 |x| + rho2 |d|, weighted by Gam's
        row sums) and x = xi + E y + R3 x. Returns box + xi."""
        mode, h, vx, d, X, xi, Fb = p[:7]
        md, m = self.model, self.modes[mode]
        c, r = _mid_rad(X)
        xc, xr = _mid_rad(self._rebase(m["P"], c, r, list(xi)))
        fc, fr = _mid_rad(Fb)
        yc, yr = _mid_rad(Y)
        c0, r0, frm = [c[j] for j in MEAS], [r[j] for j in MEAS], [fr[j] for j in MEAS]
        dc, dr = [0.0, 0.0], [0.0, 0.0]
        afc = [abs(x) for x in fc]
        for q, j in enumerate(MEAS):
            if self._smooth[j]:         # [y''] of a smooth row: (A0 + vx A1)[j, :] over Fbar
                dc[q] = _acc(0.0, md["A0"][j], fc)
                sh = _acc_abs(0.0, md["A0"][j], afc)     # the shadow of dc (rigorous rounding)
                if any(a != 0.0 for a in md["A1"][j]):
                    dc[q] += vx * _acc(0.0, md["A1"][j], fc)
                    sh += abs(vx) * _acc_abs(0.0, md["A1"][j], afc)
                for i in _R:
                    if md["A1"][j][i] == 0.0 and md["A0"][j][i] != 0.0:
                        dr[q] += abs(md["A0"][j][i]) * fr[i]
                for i in _R:
                    if md["A1"][j][i] != 0.0:
                        dr[q] += abs(md["A0"][j][i] + vx * md["A1"][j][i]) * fr[i]
                        sh += (abs(md["A0"][j][i]) + abs(vx) * abs(md["A1"][j][i])) * fr[i]
                dr[q] = _radius(dr[q], sh, 0.0, 16)
        oc0, or0 = self._omega(mode, vx, d, X, c, r, True)
        oc1, or1 = self._omega(mode, vx, d, Fb, fc, fr, False)
        # the coefficients' errors (each term's coefficient error x sum of |mid| + rad) ..
        S = lambda mid, rad: total(map(abs, mid)) + total(rad)     # noqa: E731
        ad = abs(d)
        er = k["err"]
        e = (er["phi"] * S(xc, xr) + er["w0j"] * S(c0, r0) + er["w1j"] * S(yc, yr) + er["w2j"] * S(dc, dr)
             + er["w3j"] * total(frm) + er["gp"] * S(oc0, or0) + er["gp"] * S(oc1, or1) + er["gh"] * ad)
        # .. and the design residuals': |x| <= xmax over the step (x in X + [0, h] Fbar)
        xmax = max(abs(c[j]) + r[j] + h * max(abs(Fb[j]), abs(Fb[_N + j])) for j in _R) * (1.0 + 8.0 * _U)
        rho1, rho2, rho3 = m["residual"]
        eres = rho1 * xmax + rho2 * ad
        ax = [abs(x) for x in xc]
        a0, ay, adc, ao0, ao1 = ([abs(x) for x in v] for v in (c0, yc, dc, oc0, oc1))
        out = [0.0] * (4 * _N)
        for i in _R:
            nc = _acc(0.0, k["phi"][i], xc)
            nc = _acc(nc, k["w0j"][i], c0)
            nc = _acc(nc, k["w1j"][i], yc)
            nc = _acc(nc, k["w2j_neg"][i], dc)
            nc = _acc(nc, k["gp"][i], oc0)
            nc = _acc(nc, k["g1p"][i], oc1)
            if k["gh"][i] != 0.0:
                nc += k["gh"][i] * d
            nr = _acc(0.0, k["phi"][i], xr)
            nr = _acc(nr, k["aw0j"][i], r0)
            nr = _acc(nr, k["aw1j"][i], yr)
            nr = _acc(nr, k["w2aj"][i], dr)
            nr = _acc(nr, k["w3aj2"][i], frm)
            nr = _acc(nr, k["gap"][i], or0)
            nr = _acc(nr, k["g1ap"][i], or1)
            na = _acc(0.0, k["phi"][i], ax)          # the shadow of nc
            na = _acc(na, k["aw0j"][i], a0)
            na = _acc(na, k["aw1j"][i], ay)
            na = _acc(na, k["w2aj"][i], adc)
            na = _acc(na, k["gap"][i], ao0)
            na = _acc(na, k["g1ap"][i], ao1)
            na += abs(k["gh"][i] * d)
            ei = e + k["gsum"][i] * eres
            R = _radius(nr, na, ei, 24)
            bc, br = _acc(nc, m["E"][i], yc), _acc_abs(nr, m["E"][i], yr)
            Rb = _radius(br, _acc_abs(na, m["E"][i], ay), ei + rho3 * xmax, 26)
            xl, xu = _na(bc - Rb, _NINF), _na(bc + Rb, _INF)
            if xl < B[i]:
                xl = B[i]
            if xu > B[_N + i]:
                xu = B[_N + i]
            if xl > xu:
                xl, xu = B[i], B[_N + i]
            out[i], out[_N + i], out[2 * _N + i], out[3 * _N + i] = xl, xu, _na(nc - R, _NINF), _na(nc + R, _INF)
        for q, j in enumerate(MEAS):    # the measured states: with their measurement
            if out[j] < Y[q]:
                out[j] = Y[q]
            if out[_N + j] > Y[2 + q]:
                out[_N + j] = Y[2 + q]
            if out[j] > out[_N + j]:
                out[j], out[_N + j] = Y[q], Y[2 + q]
        return out

    # -- the measurement of ay -----------------------------------------------------------------------
    def _fyf(self, box):
        """(lower, upper) of Fyf = a x3 + b x4 over the box (eq. 8 inverted), rounded outward
        (``_outward_sum``): the published bounds, and |Fyf| for ``_ay_nu``."""
        a, b = self._fa, self._fb
        return _outward_sum(a * box[2], b * box[3], -1), _outward_sum(a * box[_N + 2], b * box[_N + 3], 1)

    def _ay_nu(self, k: float, fl: float, fu: float) -> float:
        """The nu of the ay row: ay_error_bound + k |Fyf| / m for Fyf in [fl, fu], k >= 1 - cos(delta),
        rounded up (ay_error_bound itself when k = 0: delta = 0).
        DEPARTURE from the measurement equation of paper 001 (y = C x, eq. 9 and 11: ay = x3 =
        (Fyf + Fyr)/m; eq. 46): the accelerometer of a car whose front wheels are steered by delta
        measures (Fyf cos(delta) + Fyr)/m (CarPlant's ay), so ay - x3 = -Fyf (1 - cos delta)/m, which
        the small-angle model leaves out. It jumps with the held steering at every communication
        point (1e-4 .. 5e-4 m/s2 in a slalom) and a short step exposed it as an inconsistency (issue
        47: 1 us / 50 ms steps restarted 120 times in 30 s); bounded here, the bounds stay
        guaranteed for that car too."""
        nu = self.nu[1]
        if k == 0.0:
            return nu
        F = fu if fu > -fl else -fl                         # max |Fyf| (fl <= fu)
        e = _na(_na(k * F, _INF) / self.model["m"], _INF)
        if not e >= 0.0:                                    # (NaN bounds: no bound)
            e = _INF
        return _na(nu + e, _INF)

    def _ay_nu_apriori(self, ay: float, k: float, x4l: float, x4u: float) -> float:
        """``_ay_nu`` without a box of x3 (a restart): |x3| <= |ay| + nu + k |Fyf|/m and
        |Fyf| <= a |x3| + b max|x4| give |Fyf| <= (a (|ay| + nu) + b max|x4|) / (1 - k lr/L) (a/m =
        lr/L; k <= 1: the denominator is >= lf/L > 0); x4 in [x4l, x4u],
        the restart's box. Rounded up (lr/L carries two roundings: the factor 1 + 4u)."""
        if k == 0.0:
            return self.nu[1]
        h = _na(abs(ay) + self.nu[1], _INF)
        fl, fu = self._fyf([0.0, 0.0, -h, x4l, 0.0, 0.0, h, x4u])
        F = fu if fu > -fl else -fl
        den = _na(1.0 - _na(_na(k * self._lr_l, _INF) * (1.0 + 4.0 * _U), _INF), _NINF)
        F = _na(F / den, _INF) if den > 0.0 else _INF
        return self._ay_nu(k, -F, F)

    # -- modes, restarts, the longest communication step --------------------------------------------
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

    def _restart(self, y, keep: bool, k: float) -> None:
        """Initial box: the unmeasured states +-x0_halfwidth (hull with the current bounds if
        ``keep``), the measured ones y +- nu, ay's nu widened by ``_ay_nu_apriori`` (k >= 1 - cos
        delta); no xi, no pending correction."""
        box = self.box
        for j in self.unmeas:
            lo, hi = -self.w0[j], self.w0[j]
            if keep:
                lo, hi = min(lo, box[j]), max(hi, box[_N + j])
            box[j], box[_N + j] = lo, hi
        nus = (self.nu[0], self._ay_nu_apriori(y[1], k, box[3], box[_N + 3]))
        for q, j in enumerate(self.meas):
            box[j], box[_N + j] = _measured_box(y[q], nus[q])
        self._xi = None
        self._xi_mode = -1
        self._pending = None

    @classmethod
    def build_time_facts(cls, data: dict) -> dict:
        """What packaging stores in the design's ``runtime`` before building (both backends read
        it): the longest communication step, when the design file does not hold it yet."""
        if data.get("runtime", {}).get("max_communication_step") is not None:
            return {}
        return {"max_communication_step": cls(data).max_communication_step()}

    def max_communication_step(self) -> float:
        """The longest communication step (s) this design accepts (``step`` refuses a longer one):
        runtime.max_communication_step, which the synthesis decides with ``_find_max_communication_step``
        (the longest step at which the widths of vy and x4 still decay at >= MAX_COMM_STEP_DECAY 1/s
        from the initial box at zero inputs, at every band edge and grid speed; the decay falls with
        h: bisections on a MAX_COMM_STEP_RESOLUTION grid). A design file without it gets it here, once."""
        if self._max_comm_step is None:
            self._max_comm_step = self._find_max_communication_step()
        return self._max_comm_step

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
            probe = type(self)(self._probe_data(), PROBE_PARAMETERS)
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
        """The design without its disturbance bound (w = 0, the tables' "probe_smooth" rows; run
        with nu = 0, PROBE_PARAMETERS): the probes of ``decay_rate`` measure how fast an initial
        error is forgotten, which the width map at zero inputs shows when it is positively
        homogeneous; a disturbance or measurement-error bound adds a constant floor that a fast
        correction reaches within the probe (then no decay is left to measure)."""
        tb = dict(self.tables)
        tb["model"] = {**tb["model"], "w": [0.0] * _N}
        tb["smooth"] = tb["probe_smooth"]
        return {**self._data, "tables": tb}

    def _find_max_communication_step(self) -> float:
        """The largest k MAX_COMM_STEP_RESOLUTION at which every probe speed decays fast enough. The
        decay rate falls with h at each speed, so that k is the least over the speeds of each one's
        largest: the first speed's by bisection, then each other speed tried at the current k only;
        one that fails there is searched below k by steps doubling from 1 (k - 1, k - 2, k - 4, ...:
        the next speed's limit is usually just below the last one's) until one passes, then
        bisected between them (each speed but the limiting ones probed once)."""
        res = self.MAX_COMM_STEP_RESOLUTION
        probe = type(self)(self._probe_data(), PROBE_PARAMETERS)
        k = int(round(self.MAX_COMM_STEP_CEILING / res)) + 1        # (no step tried yet: exclusive)
        first = True

        def passes(j: int, v: float) -> bool:
            return self.decay_rate(j * res, v, probe) >= self.MAX_COMM_STEP_DECAY

        for v in self._probe_speeds():
            if k == 0:                        # no step passes
                break
            if first:
                lo, hi = 0, k                 # the exclusive ceiling
            elif passes(k, v):
                continue
            else:                             # k fails at v: gallop down to a step that passes (or 0)
                hi, gap = k, 1
                while True:
                    lo = max(0, k - gap)
                    if lo == 0 or passes(lo, v):
                        break
                    hi, gap = lo, 2 * gap
            while hi - lo > 1:                # lo passes (or is 0), hi fails
                mid = (lo + hi) // 2
                if passes(mid, v):
                    lo = mid
                else:
                    hi = mid
            k, first = lo, False
        return round(k * res, 12)

    def initialize(self, u: dict) -> None:
        """The bounds at the start: vy in +-x0_halfwidth[0], x4 in +-x0_halfwidth[3], the measured
        yaw rate and ay +-y_error_bound; the mode of the initial speed; outputs published."""
        y = (u["yaw_rate"], u["ay"])
        self._d_last = u["delta"]
        self._restart(y, keep=False, k=_one_minus_cos(u["delta"]))
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
        y(t) is known (eq. 23, ``_correct``), (3) the mode of vx (eq. 44), (4) the enclosure T of x
        over [t, t + h] and the predicted box at t + h (``_predict``), published; the correction of
        this step waits for the measurement at t + h (the observer runs one step behind the
        published prediction, which is itself a guaranteed bound)."""
        h = float(h)
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
        # 1 - cos of the steering before and after t (``_ay_nu``): the accelerometer's y(t) may
        # follow either (CarPlant's, as a master wires it, follows the one held over the step just ended)
        k, kl = _one_minus_cos(d), _one_minus_cos(self._d_last)
        if kl > k:
            k = kl
        self._d_last = d
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
            self._restart(y, keep=False, k=k)
        # 1. DEPARTURE (a tightening; the paper does not intersect): the published box of the measured
        #    states intersected with [y - nu, y + nu]; both contain x. Empty: the model does not hold.
        #    ay's nu covers the small-angle error of the paper's y = C x (``_ay_nu``), with |Fyf|
        #    bounded over this box (the prediction: it contains x(t))
        nus = (self.nu[0], self._ay_nu(k, *self._fyf(box)))
        consistent = 1
        for q, j in enumerate(self.meas):
            lo, hi = box[j], box[_N + j]
            ml, mu = _measured_box(y[q], nus[q])
            if ml > lo:
                lo = ml
            if mu < hi:
                hi = mu
            if lo > hi:
                if lo - hi <= self._tu["consistency_tol"] * (1.0 + abs(y[q])):
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
            self._restart(y, keep=True, k=k)
        else:
            self._inconsistent = False
        self.y["consistent"] = consistent
        # 2. the correction of the previous step
        p = self._pending
        if p is not None:
            mode_p, h_p, sampled = p[0], p[1], p[7]
            Y = [box[j] for j in self.meas] + [box[_N + j] for j in self.meas]
            out = self._correct(self._core(mode_p, h_p), p, Y, box)
            if sampled is not None:      # intersected with the sampled-measurement correction
                sb = self._sampled_correct(sampled, Y)
                for i in range(_N):
                    lo, hi = max(out[i], sb[i]), min(out[_N + i], sb[_N + i])
                    if lo <= hi:
                        out[i], out[_N + i] = lo, hi
            if all(map(math.isfinite, out)):
                box[:] = out[:2 * _N]
                self._xi, self._xi_mode = out[2 * _N:], mode_p
            else:
                # DEPARTURE (floating point): the correction only tightens the box, the prediction of
                # the pending step intersected with y(t), itself a guaranteed (and finite) enclosure.
                # A correction without finite bounds (a step so short, below ~1e-290 s, that its
                # coefficients' error bounds, ~u/h, overflow; see ``_core``) is skipped: the box kept,
                # xi dropped as after a mode switch (a restart here widened the bounds to x0_halfwidth)
                self._xi, self._xi_mode = None, -1
        # 3. the mode of this step
        self.mode = mode = self._band(vx)
        core = self._core(mode, h)
        # 4. the enclosure over [t, t + h] and the prediction at t + h
        X = list(box)
        fallback = False
        if core["nsub"] == 1:
            T = self._enclose(h, vx, d, X)
            if T is None:
                fallback = True
                T = self._comparison_enclosure(h, vx, d, X)
            Fb, B = self._predict(h, vx, d, X, T)
        else:                            # long steps: the enclosure from substeps
            hs, Xm, T = core["hs"], X, None
            for _ in range(core["nsub"]):
                Tm = self._enclose(hs, vx, d, Xm)
                if Tm is None:
                    fallback = True
                    Tm = self._comparison_enclosure(hs, vx, d, Xm)
                Xm = self._predict(hs, vx, d, Xm, Tm)[1]
                T = Tm if T is None else [min(a, b) for a, b in zip(T[:_N], Tm[:_N])] + \
                    [max(a, b) for a, b in zip(T[_N:], Tm[_N:])]
            Fb, B = self._predict(h, vx, d, X, T)
            B = [max(a, b) for a, b in zip(B[:_N], Xm[:_N])] + [min(a, b) for a, b in zip(B[_N:], Xm[_N:])]
        if fallback:
            self._fallback_steps += 1
            if not self._fallback_episode:
                self.events.append(("warning", f"a priori enclosure not found in {self._tu['enclosure_tries']} tries "
                                               f"(h = {h:g} s, vx = {vx:.4g} m/s): comparison bound used, wider"))
            self._fallback_episode = True
        else:
            self._fallback_episode = False
        if not (all(map(math.isfinite, Fb)) and all(map(math.isfinite, B))):
            self.events.append(("warning", "bounds became non-finite: restarted from the measurement and "
                                           "x0_halfwidth"))
            self._restart(y, keep=False, k=k)
        else:
            xi = self._xi if (self._xi is not None and self._xi_mode == mode) else _NO_XI
            sampled = None
            if self._tu["sampled"] and h >= self._tu["sampled_min_step"]:     # the box by the model alone, intersected
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
            self._pending = (mode, h, vx, d, X, xi, Fb, sampled)
            box[:] = B
        self._vx = vx
        self._publish()

    def _publish(self) -> None:
        xl0, xl1, xl2, xl3, xu0, xu1, xu2, xu3 = self.box
        md = self.model
        vx = self._vx
        out = self.y
        out["vy_lower"], out["vy_upper"] = xl0, xu0
        # DEPARTURE (floating point, not in the paper): beta and the forces are evaluated in doubles
        # and rounded outward by a bound of that evaluation's error, so that they contain the exact
        # values for every x in the box (``_outward_atan``, ``_outward_sum``)
        if vx > 0:
            out["beta_lower"], out["beta_upper"] = _outward_atan(xl0 / vx, -1), _outward_atan(xu0 / vx, 1)
        else:                              # reversing: atan(x / vx) decreases in x
            out["beta_lower"], out["beta_upper"] = _outward_atan(xu0 / vx, -1), _outward_atan(xl0 / vx, 1)
        out["yaw_rate_lower"], out["yaw_rate_upper"] = xl1, xu1
        L = md["lf"] + md["lr"]
        b, c = md["Iz"] / L, md["m"] * md["lf"] / L
        # inverse of eq. (8); DEPARTURE from eq. (45) (misprint): Fyr's lower bound uses x4's upper
        out["Fyf_lower"], out["Fyf_upper"] = self._fyf(self.box)
        out["Fyr_lower"], out["Fyr_upper"] = _outward_sum(c * xl2, -b * xu3, -1), _outward_sum(c * xu2, -b * xl3, 1)
        out["mode"] = self.mode + 1
