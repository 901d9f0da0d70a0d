"""Runtime of the switched PI observer of paper 000 (Menhour et al., ECC 2014), eq. (5).

Standard library only; no FMI here (``framework.py`` does that). Reads a design file
(``latobs.synthesis.pi_hinf_000.to_design_dict``). States z (4) and w^ (1, bank angle):
    x^ = z + N y
    z'  = T A x^ + T B u + T F w^ + K_P (y - C x^)        (ERRATA 000; = eq. (5) with
    w^' = K_I (y - C x^)                                    Pi = T A - K_P C, K_p = K_P + Pi N)
u = delta (rad), y = [yaw rate (rad/s), roll angle (rad), roll rate (rad/s)], A, B, F the mode's
model at its model speed: the grid speed (speed modes, eq. 25) or the measured speed clamped to
the grid (tire modes). Over one call of ``step(h, u)`` the inputs are held (zero-order hold) and
the extended state [z; w^] obeys the linear ODE s' = M s + b, integrated by classical RK4 with
substeps of at most ``runtime.max_step`` (the certificate proves that step stable and accurate).

Documented clamps (never an exception for finite inputs):
  * |vx| < vx_hold (default 1 m/s, parameter): integration frozen, estimates held, one warning
    per entry (the model has 1/Vx terms; at standstill sideslip is undefined);
  * vx outside the design grid: speed modes use the nearest mode; tire modes evaluate the model
    at the nearest grid edge; one warning per excursion;
  * ``initialize`` (at exitInitializationMode, or else the first step) sets x^ = [0, y] (beta^ = 0,
    measured r, phi, phidot) and the mode of the initial speed.
Outputs are those at the end of the step, x^ = z + N y with the held measurement.
"""
from __future__ import annotations

import math

OUTPUT_NAMES = ("beta_hat", "yaw_rate_hat", "roll_angle_hat", "roll_rate_hat", "bank_angle_hat", "mode")


def _matvec(M, v):
    return [sum(a * b for a, b in zip(row, v)) for row in M]


def _matmul(A, B):
    cols = list(zip(*B))
    return [[sum(a * b for a, b in zip(row, col)) for col in cols] for row in A]


def _add(A, B):
    return [[a + b for a, b in zip(ra, rb)] for ra, rb in zip(A, B)]


def _scale(A, s):
    return [[a * s for a in row] for row in A]


def _poly(coeffs, inv_v):
    """sum_k M_k inv_v**k for a list of matrices M_k (the design file's 1/Vx form)."""
    out = _scale(coeffs[0], 1.0)
    for k, M in enumerate(coeffs[1:], start=1):
        out = _add(out, _scale(M, inv_v**k))
    return out


class SwitchedPIObserver:
    """Switched PI observer of paper 000 from its design file (see the module docstring)."""

    PARAMETERS = {"vx_hold": 1.0}  # m/s: below this speed the estimates are held

    def __init__(self, data: dict, params: dict | None = None):
        params = dict(params or {})
        try:
            st = data["structure"]
            self.T, self.N, self.C = st["T"], st["N"], st["C"]
            self.modes = data["modes"]
            self.switching = data["switching"]
            self.max_step = float(data["runtime"]["max_step"])
        except (KeyError, TypeError) as exc:
            raise ValueError(f"design file lacks {exc} needed by the paper-000 observer runtime") from exc
        self.vx_hold = float(params.get("vx_hold", data["runtime"].get("vx_hold", self.PARAMETERS["vx_hold"])))
        if not (math.isfinite(self.vx_hold) and self.vx_hold >= 0):
            raise ValueError(f"parameter vx_hold must be finite and >= 0 m/s, got {self.vx_hold}")
        if not (0 < self.max_step <= 0.01):
            raise ValueError(f"design runtime.max_step must be in (0, 0.01] s, got {self.max_step}")
        self.n = len(self.T)
        self.ny = len(self.C)
        # I - C N, used in y - C x^ = (I - C N) y - C z
        CN = _matmul(self.C, self.N)
        self.I_CN = [[(1.0 if i == j else 0.0) - CN[i][j] for j in range(self.ny)] for i in range(self.ny)]
        self._fixed = {}
        for i, m in enumerate(self.modes):
            if m["model_speed"]["kind"] == "fixed":
                self._fixed[i] = self._system(i, float(m["model_speed"]["value"]))
        self.mode = 0                      # 0-based index; the output is 1-based
        self.s = [0.0] * (self.n + 1)      # [z; w^]
        self._started = False
        self._holding = False
        self._outside = False
        self.events: list[tuple[str, str]] = []
        self.y = {name: 0.0 for name in OUTPUT_NAMES}
        self.y["mode"] = 1

    # -- model -------------------------------------------------------------------------------
    def _system(self, i: int, vx: float):
        """(M, G) with s' = M s + G [y; u] for mode i with its model at speed vx (m/s)."""
        mode = self.modes[i]
        inv_v = 1.0 / vx
        A = _poly(mode["model"]["A"], inv_v)
        B = _poly(mode["model"]["B"], inv_v)
        F = _poly(mode["model"]["F"], inv_v)
        TA, TB, TF = _matmul(self.T, A), _matmul(self.T, B), _matmul(self.T, F)
        KP, KI = mode["gains"]["K_P"], mode["gains"]["K_I"]
        n, ny = self.n, self.ny
        KPC, KIC = _matmul(KP, self.C), _matmul(KI, self.C)
        M = [[TA[r][c] - KPC[r][c] for c in range(n)] + [TF[r][0]] for r in range(n)]
        M.append([-KIC[0][c] for c in range(n)] + [0.0])
        # inputs: y enters through T A N y + K_P (I - C N) y (z rows) and K_I (I - C N) y (w row)
        TAN, KPI, KII = _matmul(TA, self.N), _matmul(KP, self.I_CN), _matmul(KI, self.I_CN)
        G = [[TAN[r][c] + KPI[r][c] for c in range(ny)] + [TB[r][0]] for r in range(n)]
        G.append([KII[0][c] for c in range(ny)] + [0.0])
        return M, G

    def _select_mode(self, vx: float, delta: float, y_meas) -> int:
        sw = self.switching
        if sw["kind"] == "speed_bands":
            edges = sw["edges"]
            for i in range(len(self.modes)):
                if edges[i] <= vx < edges[i + 1]:
                    return i
            return 0 if vx < edges[0] else len(self.modes) - 1
        # tire modes, eq. (27) with the slip angles of eq. (2) from the estimates
        xhat = self.xhat(y_meas)
        beta, r = xhat[0], xhat[1]
        a_f = delta - beta - sw["lf"] * r / vx
        a_r = -beta + sw["lr"] * r / vx
        premise = max(abs(a_f), abs(a_r))
        # departure from eq. (27): a hysteresis band of +-hysteresis around alpha* (the paper
        # switches exactly at alpha*, which chatters when the estimated slip hovers there)
        if self.mode == 0 and premise > sw["alpha_star"] + sw["hysteresis"]:
            return 1
        if self.mode == 1 and premise < sw["alpha_star"] - sw["hysteresis"]:
            return 0
        return self.mode

    def _speed_range(self) -> tuple[float, float]:
        sw = self.switching
        if sw["kind"] == "speed_bands":
            return sw["edges"][0], sw["edges"][-1]
        lo, hi = self.modes[0]["model_speed"]["range"]
        return lo, hi

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
        self.s[: self.n] = [a - b for a, b in zip(x0, Ny)]
        self._started = True
        if self.switching["kind"] == "speed_bands" and abs(u["vx"]) >= self.vx_hold:
            self.mode = self._select_mode(u["vx"], u["delta"], y_meas)
        self._publish(y_meas)

    def step(self, h: float, u: dict) -> None:
        vx = u["vx"]
        y_meas = [u["yaw_rate"], u["roll_angle"], u["roll_rate"]]
        delta = u["delta"]
        if not self._started:
            self.initialize(u)
        if abs(vx) < self.vx_hold:
            if not self._holding:
                self.events.append(("warning", f"|vx| = {abs(vx):.3g} m/s < vx_hold = {self.vx_hold:g} m/s: "
                                               "observer frozen, estimates held"))
            self._holding = True
            self._publish(y_meas)
            return
        if self._holding:
            self.events.append(("warning", f"vx = {vx:.3g} m/s: observer resumes"))
        self._holding = False
        lo, hi = self._speed_range()
        outside = not (lo <= vx <= hi)
        if outside and not self._outside:
            self.events.append(("warning", f"vx = {vx:.4g} m/s outside the design grid [{lo:.4g}, {hi:.4g}] m/s: "
                                           "clamped to the nearest grid mode/speed"))
        self._outside = outside
        self.mode = self._select_mode(vx, delta, y_meas)
        if self.mode in self._fixed:
            M, G = self._fixed[self.mode]
        else:
            M, G = self._system(self.mode, min(max(vx, lo), hi))
        b = _matvec(G, y_meas + [delta])
        nsub = max(1, math.ceil(h / self.max_step - 1e-9))
        hs = h / nsub
        s = self.s
        for _ in range(nsub):
            k1 = [p + q for p, q in zip(_matvec(M, s), b)]
            s2 = [x + 0.5 * hs * k for x, k in zip(s, k1)]
            k2 = [p + q for p, q in zip(_matvec(M, s2), b)]
            s3 = [x + 0.5 * hs * k for x, k in zip(s, k2)]
            k3 = [p + q for p, q in zip(_matvec(M, s3), b)]
            s4 = [x + hs * k for x, k in zip(s, k3)]
            k4 = [p + q for p, q in zip(_matvec(M, s4), b)]
            s = [x + hs / 6.0 * (a + 2 * b_ + 2 * c + d) for x, a, b_, c, d in zip(s, k1, k2, k3, k4)]
        self.s = s
        self._publish(y_meas)

    def _publish(self, y_meas) -> None:
        xh = self.xhat(y_meas)
        self.y.update(beta_hat=xh[0], yaw_rate_hat=xh[1], roll_angle_hat=xh[2], roll_rate_hat=xh[3],
                      bank_angle_hat=self.s[self.n], mode=self.mode + 1)
