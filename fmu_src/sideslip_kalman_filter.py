"""Runtime of the Kalman peer of paper 002: the linear bicycle-model Kalman filter of the MBDS
dataset's authors, x = [vy, r], measuring y = [ay, r].

Standard library only; the model's speed-free coefficients come from the design file's ``tables``
(``synthesis/tables/sideslip_kalman_filter.py``). Behaviour: docs/runtime/sideslip_kalman_filter.md.
"""
from __future__ import annotations

import math
from functools import reduce
from operator import add, mul

from .linalg import total
from .spec import tables_of

OUTPUT_NAMES = ("beta_hat", "vy_hat", "yaw_rate_hat", "beta_filtered", "vy_filtered", "yaw_rate_filtered")


# Small dense algebra on lists of rows. Every dot product is summed left to right from its first
# term (not math.fsum, not from 0.0), so the results are those of the C model (sideslip_kalman_filter.c).
def _dot(a, b) -> float:
    return reduce(add, map(mul, a, b))


def _matmul(A, B):
    cols = list(zip(*B))
    return [[reduce(add, map(mul, row, col)) for col in cols] for row in A]


def _transpose(A):
    return [list(col) for col in zip(*A)]


def _norm_inf(M) -> float:
    """Induced infinity norm: the largest row sum of |m| (each summed from 0, left to right)."""
    return max([total(map(abs, row)) for row in M])


def _expm(M):
    """exp(M) by scaling and squaring: s the least integer >= 0 with ||M||_inf 2^-s <= 1/2, the
    Taylor series of exp(M 2^-s) summed until a term is below 1e-18 relative, squared s times."""
    n = len(M)
    norm = _norm_inf(M)
    s = max(0, math.ceil(math.log2(norm / 0.5))) if norm > 0.5 else 0
    sc = 2.0 ** -s
    X = [[a * sc for a in row] for row in M]
    E = [[1.0 if i == j else 0.0 for j in range(n)] for i in range(n)]
    T = [row[:] for row in E]
    X_cols = list(zip(*X))
    for k in range(1, 40):
        T = [[reduce(add, map(mul, row, col)) / k for col in X_cols] for row in T]      # T X / k
        E = [[e + t for e, t in zip(re, rt)] for re, rt in zip(E, T)]
        if _norm_inf(T) <= 1e-18 * _norm_inf(E):
            break
    for _ in range(s):
        E = _matmul(E, E)
    return E


def _symmetric(N):
    """N with its off-diagonal pair replaced by their mean (P stays symmetric under rounding)."""
    off = 0.5 * (N[0][1] + N[1][0])
    return [[N[0][0], off], [off, N[1][1]]]


def _mat2(x, what):
    try:
        M = [[float(a) for a in row] for row in x]
    except (TypeError, ValueError) as exc:
        raise ValueError(f"data file: {what} must be a 2x2 matrix of numbers ({exc})") from exc
    if len(M) != 2 or any(len(row) != 2 for row in M):
        raise ValueError(f"data file: {what} must be 2x2, got {x!r}")
    if not all(math.isfinite(a) for row in M for a in row):
        raise ValueError(f"data file: {what} has a non-finite entry")
    if abs(M[0][1] - M[1][0]) > 1e-12 * max(1.0, abs(M[0][1])):
        raise ValueError(f"data file: {what} must be symmetric, got {M}")
    return M


def _definite(M, what, strict):
    det = M[0][0] * M[1][1] - M[0][1] * M[1][0]
    ok = (M[0][0] > 0 and det > 0) if strict else (M[0][0] >= 0 and M[1][1] >= 0 and det >= 0)
    if not ok:
        raise ValueError(f"data file: {what} must be positive {'definite' if strict else 'semidefinite'}, got {M}")


class KalmanObserver:
    """Linear bicycle-model Kalman filter measuring ay and the yaw rate: per step an update with
    the measurement, then an exact zero-order-hold prediction over h."""

    PARAMETERS: dict = {}

    def __init__(self, data: dict, params: dict | None = None):
        t = tables_of(data, "Kalman filter")
        try:
            self._a = tuple(float(x) for x in t["a"])
            self._b = tuple(float(x) for x in t["b"])
            self.Q = _mat2(t["Q"], "noise.q")
            self.R = _mat2(t["R"], "noise.r")
            self.P0 = _mat2(t["P0"], "initial.P0")
            self.vx_min = float(t["vx_min"])
            self.vx_max = float(t["vx_max"])
        except (KeyError, TypeError, AttributeError) as exc:
            raise ValueError(f"data file: tables lack {exc} needed by the Kalman observer runtime") from exc
        _definite(self.Q, "noise.q", strict=False)
        _definite(self.R, "noise.r", strict=True)
        _definite(self.P0, "initial.P0", strict=True)
        if not (math.isfinite(self.vx_min) and math.isfinite(self.vx_max) and 0 < self.vx_min < self.vx_max):
            raise ValueError(f"data file: runtime.vx_min/vx_max must be finite with 0 < vx_min < vx_max, "
                             f"got {self.vx_min}, {self.vx_max}")
        self.x = [0.0, 0.0]
        self.P = [row[:] for row in self.P0]
        self._started = False
        self._outside = False
        self.events: list = []
        self.y = {name: 0.0 for name in OUTPUT_NAMES}

    @classmethod
    def parameter_defaults(cls, data: dict) -> dict:
        return {}

    def _speed(self, vx: float) -> float:
        """vx clamped to [vx_min, vx_max] (the model has 1/vx), one warning per excursion."""
        if self.vx_min <= vx <= self.vx_max:
            self._outside = False
            return vx
        if not self._outside:
            self.events.append(("warning", f"vx = {vx:.4g} m/s outside [{self.vx_min:g}, {self.vx_max:g}] m/s: "
                                           "the model is evaluated at the nearest bound"))
        self._outside = True
        return self.vx_min if vx < self.vx_min else self.vx_max

    def _publish(self, v: float, xf=None) -> None:
        """The outputs: the prediction x_{k+1|k} and the filtered x_{k|k} of the step's start
        (``xf``; None at the start: the initial state), both at the speed v of the step's start."""
        vy, r = self.x
        self.y["beta_hat"] = math.atan(vy / v)
        self.y["vy_hat"] = vy
        self.y["yaw_rate_hat"] = r
        fvy, fr = self.x if xf is None else xf
        self.y["beta_filtered"] = math.atan(fvy / v)
        self.y["vy_filtered"] = fvy
        self.y["yaw_rate_filtered"] = fr

    def model(self, v: float):
        """(A, B, C, D) of the model at the speed v (m/s, already clamped) as lists: A 2x2 (1/s),
        B 2 (m/s^2/rad, rad/s^2/rad), C 2x2 (rows ay, r), D 2 (m/s^2/rad, 0)."""
        a00, a01, a10, a11 = self._a
        b0, b1 = self._b
        A = [[a00 / v, a01 / v - v], [a10 / v, a11 / v]]
        C = [[a00 / v, a01 / v], [0.0, 1.0]]               # ay = vy' + v r: A's first row + [0, v]
        return A, [b0, b1], C, [b0, 0.0]

    def initialize(self, u: dict) -> None:
        """x = [0, yaw_rate] (a non-finite yaw rate: 0, with a warning), P = P0; outputs at vx."""
        r0, vx = float(u["yaw_rate"]), float(u["vx"])
        if not (math.isfinite(r0) and math.isfinite(vx)):
            self.events.append(("warning", f"non-finite initial input (yaw_rate, vx) = {(r0, vx)!r}: "
                                           "the filter starts from x = 0 at vx_min"))
            r0 = r0 if math.isfinite(r0) else 0.0
            vx = vx if math.isfinite(vx) else self.vx_min
        self.x = [0.0, r0]
        self.P = [row[:] for row in self.P0]
        self._started = True
        self._publish(self._speed(vx))

    def step(self, h: float, u: dict) -> None:
        """Update with y = [ay, yaw_rate], then predict over h (s) with the inputs u held; the
        outputs are the prediction x_{k+1|k} (``*_hat``) and the filtered estimate x_{k|k} of the
        step's start t (``*_filtered``: one step behind; a filtered estimate of the current time
        would make the outputs depend on the inputs at that time, a direct feedthrough)."""
        delta, vx, ay, yr = u["delta"], u["vx"], u["ay"], u["yaw_rate"]
        if not (math.isfinite(delta) and math.isfinite(vx) and math.isfinite(ay) and math.isfinite(yr)):
            self.events.append(("warning", f"non-finite input (delta, vx, ay, yaw_rate) = {(delta, vx, ay, yr)!r}: "
                                           "no step, outputs held"))
            return
        if not self._started:
            self.initialize(u)
        if not h > 0 or not math.isfinite(h):
            self.events.append(("warning", f"step size h = {h!r} s is not finite and > 0: no step, outputs held"))
            return
        v = self._speed(vx)        # the model has 1/vx: evaluated inside [vx_min, vx_max]
        A, B, C, D = self.model(v)
        x, P = self.x, self.P
        # 1. update: S = C P C' + R, K = P C' S^-1 (P symmetric: P C' = (C P)'), x += K (y - C x - D delta)
        CP = _matmul(C, P)
        S = [[s + r for s, r in zip(srow, rrow)] for srow, rrow in zip(_matmul(CP, _transpose(C)), self.R)]
        det = S[0][0] * S[1][1] - S[0][1] * S[1][0]
        Sinv = [[S[1][1] / det, -S[0][1] / det], [-S[1][0] / det, S[0][0] / det]]
        K = _matmul(_transpose(CP), Sinv)
        e = [y - _dot(c, x) - d * delta for y, c, d in zip((ay, yr), C, D)]
        x = [xi + _dot(k, e) for xi, k in zip(x, K)]
        xf = x                                             # x_{k|k}
        KC = _matmul(K, C)
        IKC = [[(1.0 - kc) if i == j else -kc for j, kc in enumerate(row)] for i, row in enumerate(KC)]
        P = _symmetric(_matmul(IKC, P))                    # P = (I - K C) P
        # 2. predict over h: [[Phi, Gam], [0, 1]] = expm(h [[A, B], [0, 0]]) (Van Loan, exact ZOH)
        try:
            E = _expm([[*(a * h for a in A[0]), B[0] * h], [*(a * h for a in A[1]), B[1] * h], [0.0, 0.0, 0.0]])
        except (OverflowError, ValueError, ZeroDivisionError):
            E = None
        if E is None or not all(math.isfinite(a) for row in E for a in row):
            self.events.append(("warning", f"the model discretised over h = {h!r} s is not finite: step refused, "
                                           "state held"))
            return
        Phi, Gam = [row[:2] for row in E[:2]], [row[2] for row in E[:2]]
        x = [_dot(f, x) + g * delta for f, g in zip(Phi, Gam)]
        PhiP = _matmul(Phi, P)
        P = _symmetric([[_dot(m, f) + q * h for f, q in zip(Phi, qrow)] for m, qrow in zip(PhiP, self.Q)])
        if not all(math.isfinite(a) for a in (x[0], x[1], P[0][0], P[0][1], P[1][1])):
            self.events.append(("warning", "the filter's state became non-finite: step refused, state held"))
            return
        self.x = x
        self.P = P
        self._publish(v, xf)
