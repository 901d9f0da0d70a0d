"""Runtime of paper 002's transfer-function sideslip estimator (Delibasi 2014), beta^ = (y(s)/x(s)) r.

Standard library only; no FMI here (``framework.py`` does that). Input: the yaw rate r (rad/s)
and, for a speed-scheduled data file, the speed vx (m/s); output: beta_hat (rad), and ``mode``
(1-based index of the estimator in use).

Data file
    ``{"estimator": {"num": [y_0, .., y_m], "den": [x_0, .., x_n]}, "runtime": {...}}``
    Coefficients are ASCENDING in s (``num[k]`` multiplies s**k), as in
    ``synthesis/fixed_order_002.py``. Proper: m <= n (trailing zeros of ``num`` are dropped),
    ``den[n] != 0``, 0 <= n (n = 0: a static gain), every coefficient finite, and x(s) Hurwitz
    (every root in the open left half-plane, checked by Routh's array) for n >= 1: the
    estimator is a stable filter of the measured yaw rate.

    Speed scheduling (optional): ``{"estimators": [{"num", "den", "vx_band": [lo, hi]}, ...]}``
    instead of ``"estimator"``, bands increasing and contiguous (band i's hi = band i+1's lo),
    every ``den`` of the same degree n (bumpless switching re-uses the state, so the state
    dimension must be the same). Estimator i is used for lo_i <= vx < hi_i; outside the grid the
    nearest band, with one warning per excursion.

    ``runtime`` (optional keys): ``cache_size`` (int >= 1, default 64): step maps kept per
    process, oldest dropped.

Realisation (controllable canonical form). With x(s) normalised monic,
x = s^n + a_{n-1} s^{n-1} + .. + a_0 and y = b_n s^n + .. + b_0 (b_k = 0 above deg num):

    z' = A z + B r,   A = companion (ones on the superdiagonal, last row -a_0 .. -a_{n-1}),
    B = e_n,          beta^ = C z + D r,   C_k = b_k - b_n a_k,   D = b_n,

so that C (sI - A)^-1 B + D = y(s)/x(s) (the standard identity for the companion form).

Discretisation: exact zero-order hold over each call ``step(h, u)`` (r held):
    z+ = Phi z + Gam r,  [[Phi, Gam], [0, 1]] = expm(h [[A, B], [0, 0]])            (Van Loan)
expm by scaling and squaring: the augmented matrix M is scaled by 2^-s so that ||M||_inf 2^-s
<= 1/2, exp of the scaled matrix by its Taylor series summed until a term's norm falls below
1e-18 relative (the remainder is then below ~2e-18 relative, since every later term is at least
2x smaller than its predecessor), then squared s times. Maps are cached per process keyed by
(A, B, h), at most ``runtime.cache_size`` of them, oldest dropped.

Timing: ``beta_hat`` after ``step(h, u)`` is C z(t+h) + D r, with r the held input of the step
(no direct feedthrough at the FMI level: the output changes only in ``step``).

Documented clamps (never an exception for finite inputs):
  * ``initialize(u)`` (or else the first step) starts in steady state for the current yaw rate,
    z = [r / a_0, 0, .., 0] (A z + B r = 0; a_0 > 0 since x is Hurwitz), so beta^ = (y_0/x_0) r;
    the initial band is that of vx;
  * h <= 0: no step, outputs held, one warning per occurrence;
  * a step map that is not finite (an absurd h, far beyond any stable use): the step is refused,
    state held, with a warning;
  * vx outside the scheduling grid: the nearest band, one warning per excursion; a scheduled
    runtime stepped without ``vx`` in its inputs keeps its current band.
"""
from __future__ import annotations

import math
import threading

from .linalg import zoh_map

OUTPUT_NAMES = ("beta_hat", "mode")

_LOCK = threading.Lock()
_MAPS: dict = {}        # (A, B, h) -> (Phi, Gam), oldest first


def zoh(A, B, h: float):
    """(Phi, Gam): exact zero-order-hold discretisation of z' = A z + B u (B a column list) over h."""
    n = len(A)
    E = zoh_map(A, [[b] for b in B], h)
    return [row[:n] for row in E], [row[n] for row in E]


def _vector(v, what: str) -> list[float]:
    if isinstance(v, (str, bytes)) or not hasattr(v, "__iter__"):
        raise ValueError(f"data file: {what} must be a list of numbers, got {v!r}")
    try:
        out = [float(x) for x in v]
    except (TypeError, ValueError) as exc:
        raise ValueError(f"data file: {what} must be a list of numbers ({exc})") from exc
    if not all(math.isfinite(x) for x in out):
        raise ValueError(f"data file: {what} has a non-finite entry: {out}")
    return out


def hurwitz(p) -> bool:
    """True iff the polynomial p (ascending, p[-1] != 0) has every root in Re s < 0 (Routh)."""
    c = [x / p[-1] for x in reversed(p)]           # descending, monic
    if any(x <= 0 for x in c):                     # necessary: all coefficients positive
        return False
    r0, r1 = c[0::2], c[1::2]
    while r1:
        if r1[0] <= 0:
            return False
        nxt = [r0[k + 1] - r0[0] / r1[0] * (r1[k + 1] if k + 1 < len(r1) else 0.0) for k in range(len(r0) - 1)]
        r0, r1 = r1, nxt
    return True


def realise(num, den, what: str = "estimator"):
    """(A, B, C, D, a) of the controllable canonical form of num/den (ascending lists), a the
    monic denominator's ascending coefficients a_0 .. a_{n-1}. Validates; errors name ``what``."""
    num = _vector(num, f"{what}.num")
    den = _vector(den, f"{what}.den")
    if not den:
        raise ValueError(f"data file: {what}.den is empty")
    if den[-1] == 0.0:
        raise ValueError(f"data file: {what}.den's leading (last, ascending order) coefficient is 0; "
                         f"coefficients are ascending in s: {den}")
    while num and num[-1] == 0.0:
        num.pop()
    n = len(den) - 1
    if len(num) - 1 > n:
        raise ValueError(f"data file: {what} is not proper: deg num = {len(num) - 1} > deg den = {n} "
                         "(coefficients are ascending in s)")
    if n >= 1 and not hurwitz(den):
        raise ValueError(f"data file: {what}.den = {den} is not Hurwitz (a root with Re s >= 0); "
                         "coefficients are ascending in s")
    lead = den[-1]
    a = [x / lead for x in den[:-1]]
    b = [x / lead for x in num] + [0.0] * (n + 1 - len(num))
    D = b[n]
    C = [b[k] - D * a[k] for k in range(n)]
    A = [[1.0 if j == i + 1 else 0.0 for j in range(n)] for i in range(n - 1)]
    if n:
        A.append([-x for x in a])
    B = [0.0] * (n - 1) + [1.0] if n else []
    return A, B, C, D, a


class TfEstimator:
    """beta^ = (y(s)/x(s)) r, exact ZOH per step; optionally speed-scheduled (module docstring)."""

    PARAMETERS: dict = {}
    CACHE_SIZE = 64

    def __init__(self, data: dict, params: dict | None = None):
        if not isinstance(data, dict):
            raise ValueError(f"data file must be a JSON object, got {type(data).__name__}")
        rt = data.get("runtime", {}) or {}
        if not isinstance(rt, dict):
            raise ValueError("data file: runtime must be an object")
        cs = rt.get("cache_size", self.CACHE_SIZE)
        if isinstance(cs, bool) or not isinstance(cs, (int, float)) or cs != int(cs) or cs < 1:
            raise ValueError(f"data file: runtime.cache_size must be an integer >= 1, got {cs!r}")
        self.cache_size = int(cs)
        if "estimator" in data and "estimators" in data:
            raise ValueError("data file: give either 'estimator' or 'estimators' (speed-scheduled), not both")
        if "estimator" in data:
            est = data["estimator"]
            if not isinstance(est, dict):
                raise ValueError("data file: estimator must be an object {num, den}")
            entries, self.edges = [("estimator", est)], None
        elif "estimators" in data:
            ests = data["estimators"]
            if not isinstance(ests, list) or not ests:
                raise ValueError("data file: estimators must be a non-empty list of {num, den, vx_band}")
            entries, self.edges = [], []
            for i, est in enumerate(ests):
                what = f"estimators[{i}]"
                if not isinstance(est, dict):
                    raise ValueError(f"data file: {what} must be an object {{num, den, vx_band}}")
                if "vx_band" not in est:
                    raise ValueError(f"data file: {what}.vx_band is missing (a speed-scheduled estimator needs it)")
                band = _vector(est["vx_band"], f"{what}.vx_band")
                if len(band) != 2 or not band[0] < band[1]:
                    raise ValueError(f"data file: {what}.vx_band must be [lo, hi] with lo < hi, got {band}")
                if i == 0:
                    self.edges.append(band[0])
                elif band[0] != self.edges[-1]:
                    raise ValueError(f"data file: {what}.vx_band starts at {band[0]} m/s but the previous band "
                                     f"ends at {self.edges[-1]} m/s (bands must be increasing and contiguous)")
                self.edges.append(band[1])
                entries.append((what, est))
        else:
            raise ValueError("data file lacks 'estimator' ({num, den}, ascending in s) or 'estimators'")
        self.systems = []
        for what, est in entries:
            for key in ("num", "den"):
                if key not in est:
                    raise ValueError(f"data file: {what}.{key} is missing")
            self.systems.append(realise(est["num"], est["den"], what))
        self.n = len(self.systems[0][0])
        for (what, _), sys_ in zip(entries, self.systems):
            if len(sys_[0]) != self.n:
                raise ValueError(f"data file: {what}.den has degree {len(sys_[0])}, the first estimator's "
                                 f"{self.n}: scheduled estimators need the same order (bumpless switching)")
        self._keys = [(tuple(map(tuple, A)), tuple(B)) for A, B, *_ in self.systems]
        self.mode = 0
        self.z = [0.0] * self.n
        self._started = False
        self._outside = False
        self._h = None
        self._maps = [None] * len(self.systems)
        self.events: list = []
        self.y = {"beta_hat": 0.0, "mode": 1}

    @classmethod
    def parameter_defaults(cls, data: dict) -> dict:
        return {}

    # -- helpers -----------------------------------------------------------------------------
    def _band(self, vx: float) -> int:
        """Band i with edges[i] <= vx < edges[i+1]; outside the grid the nearest, with a warning."""
        e = self.edges
        if e[0] <= vx <= e[-1]:
            self._outside = False
            i = 0
            while i < len(e) - 2 and vx >= e[i + 1]:
                i += 1
            return i
        if not self._outside:
            self.events.append(("warning", f"vx = {vx:.4g} m/s outside the scheduling grid [{e[0]:.4g}, "
                                           f"{e[-1]:.4g}] m/s: the nearest band's estimator is used"))
        self._outside = True
        return 0 if vx < e[0] else len(e) - 2

    def _map(self, mode: int, h: float):
        if h != self._h:
            self._h = h
            self._maps = [None] * len(self.systems)
        m = self._maps[mode]
        if m is None:
            key = self._keys[mode] + (h,)
            with _LOCK:
                m = _MAPS.get(key)
                if m is None:
                    A, B = self.systems[mode][:2]
                    try:
                        m = zoh(A, B, h) if self.n else ([], [])
                    except (OverflowError, ValueError):     # fsum of inf - inf, log2(inf)
                        m = ([[math.nan] * self.n for _ in range(self.n)], [math.nan] * self.n)
                    _MAPS[key] = m
                    while len(_MAPS) > self.cache_size:
                        del _MAPS[next(iter(_MAPS))]
            self._maps[mode] = m
        return m

    def _publish(self, r: float) -> None:
        _, _, C, D, _ = self.systems[self.mode]
        self.y["beta_hat"] = sum([c * z for c, z in zip(C, self.z)], D * r)
        self.y["mode"] = self.mode + 1

    # -- protocol ----------------------------------------------------------------------------
    def initialize(self, u: dict) -> None:
        """Steady state for the current yaw rate: z = [r / a_0, 0, .., 0], beta^ = (y_0/x_0) r."""
        r = float(u["yaw_rate"])
        if self.edges is not None and "vx" in u:
            self.mode = self._band(float(u["vx"]))
        a = self.systems[self.mode][4]
        self.z = ([r / a[0]] + [0.0] * (self.n - 1)) if self.n else []
        self._started = True
        self._publish(r)

    def step(self, h: float, u: dict) -> None:
        if not self._started:
            self.initialize(u)
        r = u["yaw_rate"]
        if not h > 0:
            self.events.append(("warning", f"step size h = {h!r} s <= 0: no step, outputs held"))
            return
        if self.edges is not None and "vx" in u:
            self.mode = self._band(u["vx"])    # bumpless: the state z is kept as it is
        if self.n:
            Phi, Gam = self._map(self.mode, h)
            z = self.z
            zn = [sum([p * x for p, x in zip(row, z)], g * r) for row, g in zip(Phi, Gam)]
            if not all(math.isfinite(x) for x in zn):
                self.events.append(("warning", f"the step map over h = {h!r} s is not finite: step refused, "
                                               "state held"))
                return
            self.z = zn
        self._publish(r)
