"""Runtime of the switched PI observer of paper 003 (motorcycle roll angle and rider torque), eq. (13).

Standard library only; no FMI here (``framework.py`` does that). Reads a design file
(``latobs.synthesis.pi_switched_003.to_design_dict``). States x^ (5: vy, yaw rate, roll rate,
steer angle, steer rate) and f^ (2: roll angle phi, rider torque tau); u = 0 (torque not measured):
    x^' = A_s x^ + L_P,s (y - C x^) + E_f,s f^
    f^' = L_I,s (y - C x^)                                        (eq. 13)
y = [steer angle (rad), yaw rate (rad/s), roll rate (rad/s)], A_s, E_f,s, L_P,s, L_I,s of the
active mode s (the model at its grid speed). With s = [x^; f^] this is the linear ODE
    s' = M_s s + G_s y,   M_s = [[A - L_P C, E_f], [-L_I C, 0]],   G_s = [L_P; L_I].
Over one call of ``step(h, u)`` the inputs are held (zero-order hold) and the step is the exact
solution: [Phi | Gam] = the top rows of exp([[M_s h, G_s h], [0, 0]]) (scaling and squaring with a
Taylor series summed to 1e-18 relative, ``linalg.expm``), s+ = Phi s + Gam y. The map is computed once
per (design, mode, h) and cached (a process-wide cache of at most ``MAP_CACHE_SIZE`` maps, oldest
dropped); it is a deterministic function of (mode, h), so results do not depend on what is cached.
The state s is kept across mode switches (only M_s, G_s change). Measured: ~7 us per step with a
cached map, ~1 ms to build a map (a host changing its step size at every step pays that each step).

Outputs (at the end of the step, with the held measurement):
    roll_angle_hat = phi^, rider_torque_hat = tau^, vy_hat, steer_rate_hat (from x^),
    [Ff_hat, Fr_hat] = H_x x^ + H_phi phi^ (the algebraic tyre forces of the reduced model,
        relaxation lengths zero, WITHOUT the non-linear parts Gamma, which are not estimated),
    residual_norm = |y - C x^|_2 (eq. 14) in SI units of mixed kind (rad and rad/s added as
        numbers: a monitoring signal, not a physical quantity),
    mode = the active mode, 1-based.

Documented clamps (never an exception for finite inputs; the framework refuses non-finite inputs
and step sizes before ``step`` is called, keeping the state):
  * |vx| < vx_hold (default 1 m/s, parameter): integration frozen, estimates held, one warning per
    entry (at standstill the model's 1/vx terms are meaningless);
  * vx outside the design grid's bands (including negative speeds beyond -vx_hold): the nearest
    mode (the first or the last), one warning per excursion;
  * mode switching with hysteresis (design file ``switching``): the active mode is kept while vx
    stays within its band widened by ``hysteresis`` (the design's dwell-time analysis assumes no
    chattering at band edges);
  * ``initialize`` (at exitInitializationMode, or else the first step) sets x^ = C' y (measured
    states from y, vy^ = steer rate^ = 0), f^ = 0, and the mode of the initial speed.
"""
from __future__ import annotations

import math
import threading
from bisect import bisect_right
from operator import mul

from .linalg import matmul as _matmul
from .linalg import zoh_map
from .linalg import matrix as _matrix

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
    """Switched PI observer of paper 003 from its design file (see the module docstring)."""

    PARAMETERS = {"vx_hold": 1.0}  # m/s: below this speed the estimates are held
    MAP_CACHE_SIZE = 64            # (design, mode, step size) maps kept at most, per process
    N, NF, NY = 5, 2, 3

    def __init__(self, data: dict, params: dict | None = None):
        params = dict(params or {})
        n, nf, ny = self.N, self.NF, self.NY
        try:
            st = data["structure"]
            if list(st["measurements"]) != list(MEASUREMENTS):
                raise ValueError(f"design file: measurements {st['measurements']} are not {list(MEASUREMENTS)}")
            if list(st["states"]) != list(STATES):
                raise ValueError(f"design file: states {st['states']} are not {list(STATES)}")
            sw = data["switching"]
            self._edges = [float(e) for e in sw["edges"]]
            self._hyst = float(sw.get("hysteresis", 0.0))
            vx_hold = data.get("runtime", {}).get("vx_hold", self.PARAMETERS["vx_hold"])
            modes = data["modes"]
            self._M, self._G, self._C, self._F = [], [], [], []
            for k, mode in enumerate(modes):
                what = f"mode {k + 1}"
                mod, g = mode["model"], mode["gains"]
                A = _matrix(mod["A"], n, n, f"{what} A")
                Ef = _matrix(mod["E_f"], n, nf, f"{what} E_f")
                C = _matrix(mod["C"], ny, n, f"{what} C")
                Hx = _matrix(mod["H_x"], 2, n, f"{what} H_x")
                Hphi = _matrix([mod["H_phi"]], 1, 2, f"{what} H_phi")[0]
                LP = _matrix(g["L_P"], n, ny, f"{what} L_P")
                LI = _matrix(g["L_I"], nf, ny, f"{what} L_I")
                LPC, LIC = _matmul(LP, C), _matmul(LI, C)
                # eq. (13): s' = [[A - L_P C, E_f], [-L_I C, 0]] s + [L_P; L_I] y
                M = [[A[i][j] - LPC[i][j] for j in range(n)] + Ef[i] for i in range(n)]
                M += [[-LIC[i][j] for j in range(n)] + [0.0] * nf for i in range(nf)]
                self._M.append(M)
                self._G.append(LP + LI)
                self._C.append(C)
                # forces [Ff, Fr] = H_x x^ + H_phi phi^ (phi^ = s[n])
                self._F.append([Hx[r] + [Hphi[r], 0.0] for r in range(2)])
        except (KeyError, TypeError, IndexError) as exc:
            raise ValueError(f"design file lacks {exc!r} needed by the paper-003 observer runtime") from exc
        if len(self._edges) != len(modes) + 1 or self._edges != sorted(self._edges):
            raise ValueError(f"design file: switching edges {self._edges} do not bound {len(modes)} modes")
        if not (math.isfinite(self._hyst) and self._hyst >= 0):
            raise ValueError(f"design file: switching hysteresis must be >= 0, got {self._hyst}")
        self.vx_hold = float(params.get("vx_hold", vx_hold))
        if not (math.isfinite(self.vx_hold) and self.vx_hold >= 0):
            raise ValueError(f"parameter vx_hold must be finite and >= 0 m/s, got {self.vx_hold}")
        self.n_modes = len(modes)
        self._key = repr((self._M, self._G))
        self._fns: dict = {}               # (mode, h) -> map, this instance's
        self.mode = 0                      # 0-based; the output is 1-based
        self.s = [0.0] * (n + nf)          # [x^; f^]
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
        if lo <= vx < hi:
            return cur
        i = bisect_right(e, vx) - 1
        return 0 if i < 0 else min(i, k - 1)

    def _map(self, mode: int, h: float):
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

    # -- stepping --------------------------------------------------------------------------------
    def initialize(self, u: dict) -> None:
        """x^(0) = C' y(0) (measured states), f^(0) = 0, the mode of the initial speed."""
        y = [u[k] for k in MEASUREMENTS]
        C = self._C[0]
        x0 = [sum(C[r][j] * y[r] for r in range(self.NY)) for j in range(self.N)]
        self.s = x0 + [0.0] * self.NF
        self._started = True
        vx = u["vx"]
        if abs(vx) >= self.vx_hold:
            self.mode = self._select(vx)
            self._check_grid(vx)
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
        if -hold < vx < hold:
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
        W = self._fns.get((mode, h)) or self._map(mode, h)
        v = self.s + y
        self.s = [sum(map(mul, row, v)) for row in W]
        self._publish(y)

    def _publish(self, y) -> None:
        s, out = self.s, self.y
        n = self.N
        C = self._C[self.mode]
        res = 0.0
        for r in range(self.NY):
            e = y[r] - sum(map(mul, C[r], s[:n]))
            res += e * e
        Ff, Fr = (sum(map(mul, row, s)) for row in self._F[self.mode])
        out["roll_angle_hat"] = s[n]
        out["rider_torque_hat"] = s[n + 1]
        out["vy_hat"] = s[0]
        out["steer_rate_hat"] = s[4]
        out["Ff_hat"] = Ff
        out["Fr_hat"] = Fr
        out["residual_norm"] = math.sqrt(res)
        out["mode"] = self.mode + 1
