"""Runtime of paper 002's fixed-order sideslip estimator beta^ = (y(s)/x(s)) r (Delibasi 2014).

Standard library only; evaluates the design file's ``tables`` (``synthesis/tables/
sideslip_fixed_order_estimator.py``: per speed band the controllable canonical form and its exact
zero-order-hold map at the default step). Behaviour: docs/runtime/sideslip_fixed_order_estimator.md.
"""
from __future__ import annotations

import math
import threading

from .linalg import dot, zoh_map
from .spec import tables_of

OUTPUT_NAMES = ("beta_hat", "mode")

_LOCK = threading.Lock()
_MAPS: dict = {}        # (A, B, h) -> (Phi, Gam), oldest first


def zoh(A, B, h: float):
    """(Phi, Gam): exact zero-order-hold discretisation of z' = A z + B u (B a column list) over h."""
    n = len(A)
    E = zoh_map(A, [[b] for b in B], h)
    return [row[:n] for row in E], [row[n] for row in E]


class TfEstimator:
    """beta^ = (y(s)/x(s)) r, exact ZOH per step; optionally speed-scheduled."""

    PARAMETERS: dict = {}
    CACHE_SIZE = 64

    def __init__(self, data: dict, params: dict | None = None):
        t = tables_of(data, "fixed-order estimator")
        rt = data.get("runtime", {}) or {}
        if not isinstance(rt, dict):
            raise ValueError("data file: runtime must be an object")
        cs = rt.get("cache_size", self.CACHE_SIZE)
        if isinstance(cs, bool) or not isinstance(cs, (int, float)) or cs != int(cs) or cs < 1:
            raise ValueError(f"data file: runtime.cache_size must be an integer >= 1, got {cs!r}")
        self.cache_size = int(cs)
        try:
            self.n, self.h0, self.edges = int(t["n"]), float(t["h0"]), t["edges"]
            # (A, B, C, D, a0) per band: z' = A z + B r, beta^ = C z + D r, steady state r / a0
            self.systems = [(b["A"], b["B"], b["C"], float(b["D"]), float(b["a0"])) for b in t["bands"]]
            self._maps_h0 = [(b["Phi_h0"], b["Gam_h0"]) for b in t["bands"]]
        except (KeyError, TypeError) as exc:
            raise ValueError(f"data file: tables lack {exc} needed by the fixed-order estimator runtime") from exc
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
        """(Phi, Gam) of band ``mode`` over h: the stored map at the default step, else computed
        (Van Loan) and cached per process; a non-finite map (an absurd h) is all NaN."""
        if h == self.h0:
            return self._maps_h0[mode]
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
                        m = zoh(A, B, h)
                    except (OverflowError, ValueError):     # fsum of inf - inf, log2(inf)
                        m = ([[math.nan] * self.n for _ in range(self.n)], [math.nan] * self.n)
                    _MAPS[key] = m
                    while len(_MAPS) > self.cache_size:
                        del _MAPS[next(iter(_MAPS))]
            self._maps[mode] = m
        return m

    def _publish(self, r: float) -> None:
        _, _, C, D, _ = self.systems[self.mode]
        self.y["beta_hat"] = dot(C, self.z, D * r)
        self.y["mode"] = self.mode + 1

    def initialize(self, u: dict) -> None:
        """Steady state for the current yaw rate: z = [r / a_0, 0, .., 0], beta^ = (y_0/x_0) r."""
        # departure: the paper states no initial condition; starting in steady state avoids a
        # start-up transient of the filter (A z + B r = 0, a_0 > 0 as x(s) is Hurwitz)
        r = float(u["yaw_rate"])
        if self.edges is not None and "vx" in u:
            self.mode = self._band(float(u["vx"]))
        a0 = self.systems[self.mode][4]
        self.z = ([r / a0] + [0.0] * (self.n - 1)) if self.n else []
        self._started = True
        self._publish(r)

    def step(self, h: float, u: dict) -> None:
        """z+ = Phi z + Gam r with r held over h; beta^ = C z+ + D r (no feedthrough at the FMI level)."""
        if not self._started:
            self.initialize(u)
        r = u["yaw_rate"]
        if not h > 0:
            self.events.append(("warning", f"step size h = {h!r} s <= 0: no step, outputs held"))
            return
        if self.edges is not None and "vx" in u:
            # departure: the paper designs one estimator for the whole speed box; a scheduled file
            # holds one per band, switched bumplessly (the state z is kept as it is)
            self.mode = self._band(u["vx"])
        if self.n:
            # the paper's continuous-time filter, stepped exactly with r held over h (zero-order hold)
            Phi, Gam = self._map(self.mode, h)
            z = self.z
            zn = [dot(row, z, g * r) for row, g in zip(Phi, Gam)]
            if not all(math.isfinite(x) for x in zn):
                self.events.append(("warning", f"the step map over h = {h!r} s is not finite: step refused, "
                                               "state held"))
                return
            self.z = zn
        self._publish(r)
