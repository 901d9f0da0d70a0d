"""Runtime of paper 003's switched PI observer (motorcycle roll angle and rider torque), eq. (13).

Standard library only; evaluates the design file's ``tables`` (``synthesis/tables/
motorcycle_fault_observer.py``: per mode s' = M s + G y, s = [x^; f^], and its exact step map at
the default step). Behaviour: docs/runtime/motorcycle_fault_observer.md.
"""
from __future__ import annotations

import math
import threading
from bisect import bisect_right

from .linalg import dot, matmul_left, total, zoh_map
from .spec import tables_of

OUTPUT_NAMES = ("roll_angle_hat", "rider_torque_hat", "vy_hat", "steer_rate_hat", "Ff_hat", "Fr_hat",
                "residual_norm", "mode")
MEASUREMENTS = ("steer_angle", "yaw_rate", "roll_rate")
STATES = ("vy", "yaw_rate", "roll_rate", "steer_angle", "steer_rate")


def step_map(M, G, h: float):
    """[Phi | Gam] (rows of length n + m): the exact map of s' = M s + G y over h with y held."""
    return tuple(tuple(row) for row in zoh_map(M, G, h))


_LOCK = threading.Lock()
_MAPS: dict = {}          # (design fingerprint, mode, h) -> [Phi | Gam] rows, oldest first


class MotorcycleFaultObserver:
    """Switched PI observer of paper 003: s' = M_s s + G_s y in the mode s of the speed, stepped
    exactly with y held (zero-order hold); the state is kept across mode switches."""

    PARAMETERS = {"vx_hold": 1.0}  # m/s: below this speed the estimates are held
    MAP_CACHE_SIZE = 64            # (design, mode, step size) maps kept at most, per process
    NY = 3                         # y; x^ and f^ sizes (N, NF) come from the tables
    I_ROLL, I_TORQUE = 5, 6        # in s, for both designs

    def __init__(self, data: dict, params: dict | None = None):
        params = dict(params or {})
        t = tables_of(data, "paper-003 observer")
        try:
            self._edges, self._hyst, self._h0 = t["edges"], float(t["hysteresis"]), float(t["h0"])
            modes = t["modes"]
            self._M = [m["M"] for m in modes]
            self._G = [m["G"] for m in modes]
            self._C = [m["C"] for m in modes]
            self._F = [m["F"] for m in modes]
            self._measured = bool(t.get("measured", False))
            if self._measured:
                self._coef = [tuple((m[k], m[k + "_vx"], m[k + "_ivx"]) for k in ("M", "G", "F")) for m in modes]
                self._ranges = [tuple(m["vx_range"]) for m in modes]
                self._maps_h0 = None
            else:
                self._maps_h0 = [m["map_h0"] for m in modes]
            vx_hold = data.get("runtime", {}).get("vx_hold", self.PARAMETERS["vx_hold"])
        except (KeyError, TypeError, AttributeError) as exc:
            raise ValueError(f"design file: tables lack {exc!r} needed by the paper-003 observer runtime") from exc
        self.vx_hold = float(params.get("vx_hold", vx_hold))
        if not (math.isfinite(self.vx_hold) and self.vx_hold >= 0):
            raise ValueError(f"parameter vx_hold must be finite and >= 0 m/s, got {self.vx_hold}")
        self.n_modes = len(modes)
        self.N = len(self._C[0][0])               # x^ (5, or 6 with the roll angle a state)
        self.NF = len(self._M[0]) - self.N        # f^ (the unknown inputs / torque integrators)
        self._v = None                            # model speed of the last step (measured designs)
        self._last = None                         # (mode, v, h, map) of the last measured step
        self._key = repr((self._M, self._G))
        self._fns: dict = {}               # (mode, h) -> map, this instance's
        self.mode = 0                      # 0-based; the output is 1-based
        self.s = [0.0] * (self.N + self.NF)  # [x^; f^]
        self._started = False
        self._holding = False
        self._outside = False
        self.events: list[tuple[str, str]] = []
        self.y = {name: 0.0 for name in OUTPUT_NAMES}
        self.y["mode"] = 1

    # -- scheduling ------------------------------------------------------------------------------
    def _select(self, vx: float) -> int:
        """Nearest grid speed (bands [edges[i], edges[i+1])), nearest mode outside the grid; the
        current mode is kept while vx is inside its band widened by the hysteresis."""
        e, k, cur = self._edges, self.n_modes, self.mode
        lo = e[cur] - self._hyst if cur > 0 else -math.inf
        hi = e[cur + 1] + self._hyst if cur < k - 1 else math.inf
        if lo <= vx < hi:          # departure: hysteresis at the band edges (no chattering; the
            return cur             # dwell-time analysis assumes it)
        return self._band(vx)

    def _band(self, vx: float) -> int:
        """The band of vx, [edges[i], edges[i+1]) (the nearest one outside the grid): the mode at
        the start, where no mode is active yet whose band the hysteresis would widen."""
        i = bisect_right(self._edges, vx) - 1
        return 0 if i < 0 else min(i, self.n_modes - 1)

    def _map(self, mode: int, h: float):
        """[Phi | Gam] of ``mode`` over h: the stored map at the default step, else computed
        (Van Loan) and cached per process."""
        if h == self._h0:
            return self._maps_h0[mode]
        key = (self._key, mode, h)
        with _LOCK:
            W = _MAPS.get(key)
            if W is None:
                W = step_map(self._M[mode], self._G[mode], h)
                _MAPS[key] = W
                while len(_MAPS) > self.MAP_CACHE_SIZE:
                    del _MAPS[next(iter(_MAPS))]
        if len(self._fns) >= 4 * self.MAP_CACHE_SIZE:
            self._fns.clear()
        self._fns[(mode, h)] = W
        return W

    def _speed(self, mode: int, vx: float) -> float:
        """The model speed: vx clamped to the band's range (a documented clamp: outside it the
        model of the band's edge is used, as the certificate covers the range only)."""
        lo, hi = self._ranges[mode]
        return lo if not vx >= lo else (hi if vx > hi else vx)

    @staticmethod
    def _at(coef, v: float):
        """M + v M_vx + (1/v) M_ivx, entry by entry from the left (the C model's order)."""
        M0, M1, M2 = coef
        w = 1.0 / v
        return [[a + v * b + w * c for a, b, c in zip(r0, r1, r2)] for r0, r1, r2 in zip(M0, M1, M2)]

    def _measured_map(self, mode: int, v: float, h: float):
        """[Phi | Gam] of s' = M(v) s + G(v) y over h (Van Loan), the last one reused."""
        last = self._last
        if last is not None and last[0] == mode and last[1] == v and last[2] == h:
            return last[3]
        cM, cG, _ = self._coef[mode]
        # products summed from the left, as the C model's la_zoh_map: both give the same bits
        W = tuple(tuple(row) for row in zoh_map(self._at(cM, v), self._at(cG, v), h, matmul_left))
        self._last = (mode, v, h, W)
        return W

    # -- stepping --------------------------------------------------------------------------------
    def initialize(self, u: dict) -> None:
        """x^(0) = C' y(0) (measured states), f^(0) = 0, the mode of the initial speed."""
        # departure: the paper leaves the initial estimate free; the measured states start at
        # their measurement, the others (vy, steer rate, f) at 0
        y = [u[k] for k in MEASUREMENTS]
        C = self._C[0]
        x0 = [total(C[r][j] * y[r] for r in range(self.NY)) for j in range(self.N)]
        self.s = x0 + [0.0] * self.NF
        self._started = True
        vx = u["vx"]
        if abs(vx) >= self.vx_hold:
            self.mode = self._band(vx)
            self._check_grid(vx)
        if self._measured:
            self._v = self._speed(self.mode, vx if abs(vx) >= self.vx_hold else self._ranges[self.mode][0])
        self._publish(y)

    def _check_grid(self, vx: float) -> None:
        lo, hi = self._edges[0], self._edges[-1]
        if lo <= vx <= hi:
            self._outside = False
        else:
            if not self._outside:
                self.events.append(("warning", f"vx = {vx:.4g} m/s outside the design grid [{lo:.4g}, {hi:.4g}] m/s: "
                                               f"the nearest mode ({self._select(vx) + 1}) is used"))
            self._outside = True

    def step(self, h: float, u: dict) -> None:
        if not self._started:
            self.initialize(u)
        vx = u["vx"]
        y = [u["steer_angle"], u["yaw_rate"], u["roll_rate"]]
        hold = self.vx_hold
        if -hold < vx < hold:      # departure: below vx_hold the 1/vx model is meaningless: estimates held
            if not self._holding:
                self.events.append(("warning", f"|vx| = {abs(vx):.3g} m/s < vx_hold = {hold:g} m/s: "
                                               "observer frozen, estimates held"))
            self._holding = True
            self._publish(y)
            return
        if self._holding:
            self.events.append(("warning", f"vx = {vx:.3g} m/s: observer resumes"))
            self._holding = False
        self._check_grid(vx)
        self.mode = mode = self._select(vx)
        # eq. (13) in continuous time, stepped exactly with y held over h (zero-order hold)
        if self._measured:
            speed = self._speed(mode, vx)
            W = self._measured_map(mode, speed, h)
            self._v = speed                # the forces' model speed, once the step is certain
        else:
            W = self._fns.get((mode, h)) or self._map(mode, h)
        v = self.s + y
        self.s = [dot(row, v) for row in W]
        self._publish(y)

    def _publish(self, y) -> None:
        s, out = self.s, self.y
        n = self.N
        C = self._C[self.mode]
        res = 0.0
        for r in range(self.NY):
            e = y[r] - dot(C[r], s[:n])
            res += e * e
        F = self._at(self._coef[self.mode][2], self._v) if self._measured else self._F[self.mode]
        Ff, Fr = (dot(row, s) for row in F)
        out["roll_angle_hat"] = s[self.I_ROLL]       # f^_1 of the paper's design, x^_6 of the measured-speed one
        out["rider_torque_hat"] = s[self.I_TORQUE]
        out["vy_hat"] = s[0]
        out["steer_rate_hat"] = s[4]
        out["Ff_hat"] = Ff
        out["Fr_hat"] = Fr
        out["residual_norm"] = math.sqrt(res)
        out["mode"] = self.mode + 1
