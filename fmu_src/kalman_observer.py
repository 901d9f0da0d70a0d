"""Runtime of the baseline linear bicycle-model Kalman filter (the MBDS dataset authors' estimator).

Standard library only; no FMI here. The same filter as ``synthesis/kalman_baseline.py``
(``run_kalman(..., estimate="predicted")``), with 2x2 matrices written out by hand. States
x = [vy, r] (lateral velocity at the CG, m/s; yaw rate, rad/s); inputs delta (rad), vx (m/s),
yaw_rate (rad/s), ay (m/s^2); outputs beta_hat (rad), vy_hat (m/s), yaw_rate_hat (rad/s).

Model at the speed v (linear tires Fyf = Cf (delta - (vy + lf r)/v), Fyr = Cr (-(vy - lr r)/v)):
    vy' = -(Cf + Cr)/(m v) vy - ((lf Cf - lr Cr)/(m v) + v) r + Cf/m delta
    r'  = -(lf Cf - lr Cr)/(Iz v) vy - (lf^2 Cf + lr^2 Cr)/(Iz v) r + lf Cf/Iz delta
    y = [ay, r],  ay = (Fyf + Fyr)/m = -(Cf + Cr)/(m v) vy - (lf Cf - lr Cr)/(m v) r + Cf/m delta.

One call ``step(h, u)`` (inputs of the step held, v = vx clamped):
    1. update with y = [ay, yaw_rate]: S = C P C' + R, K = P C' S^-1, x += K (y - C x - D delta),
       P = (I - K C) P, symmetrised;
    2. predict over h with delta held, exact zero-order hold (Van Loan):
       [[Phi, Gam], [0, 1]] = expm(h [[A, B], [0, 0]]) (scaling and squaring, Taylor series),
       x = Phi x + Gam delta, P = Phi P Phi' + Q h.
Outputs at the end of the step: x_{k+1|k}, beta_hat = atan(vy_hat / v) with the step's v.

Data file (``kalman_baseline.to_data_dict``, or the design file of ``kalman_baseline.design``)::

    {"vehicle": {"m", "lf", "lr", "Iz", "Cf", "Cr"},            all finite > 0 (kg, m, m, kg m^2,
                                                                 N/rad, N/rad), or a vehicle set as
                                                                 in design files: {"name", "parameters":
                                                                 {"m": {"value": ..., "unit": ...}, ...}}
     "noise": {"q": 2x2 (PSD; process-noise intensity on [vy', r'], per s),
               "r": 2x2 (positive definite; measurement covariance on [ay, r])},
     "initial": {"P0": 2x2 positive definite},                   (optional, default diag(1, 0.01))
     "runtime": {"vx_min": 1.0, "vx_max": 200.0}}                (optional, m/s)

Documented clamps (never an exception for finite inputs):
  * ``initialize(u)`` (or else the first step): x = [0, yaw_rate], P = P0; outputs beta 0;
  * vx outside [vx_min, vx_max] (the model has 1/vx; reversing is not modelled): the model is
    evaluated at the nearest bound, one warning per excursion;
  * h <= 0 or a non-finite input or h: no step, outputs held, with a warning (the FMI framework
    already refuses non-finite inputs); a step whose discretised model or result is not finite
    (an absurd h): refused, state held, with a warning.

``model(v)`` gives the (A, B, C, D) that ``step`` uses at the (clamped) speed v (m/s); the design
certificate compares it with an independent derivation.
"""
from __future__ import annotations

import math

OUTPUT_NAMES = ("beta_hat", "vy_hat", "yaw_rate_hat")
_VEHICLE = ("m", "lf", "lr", "Iz", "Cf", "Cr")


def _expm3(M):
    """exp of a 3x3 matrix (list of rows): scaling and squaring, Taylor series summed until a
    term is below 1e-18 relative: ``linalg.expm`` unrolled for 3x3, since the speed changes the
    model at every step (this is the per-step hot path)."""
    norm = max(sum(abs(a) for a in row) for row in M)
    s = max(0, math.ceil(math.log2(norm / 0.5))) if norm > 0.5 else 0
    sc = 2.0 ** -s
    X = [[a * sc for a in row] for row in M]
    E = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
    T = [row[:] for row in E]
    for k in range(1, 40):
        T = [[(T[i][0] * X[0][j] + T[i][1] * X[1][j] + T[i][2] * X[2][j]) / k for j in range(3)] for i in range(3)]
        E = [[e + t for e, t in zip(re, rt)] for re, rt in zip(E, T)]
        if max(sum(abs(a) for a in row) for row in T) <= 1e-18 * max(sum(abs(a) for a in row) for row in E):
            break
    for _ in range(s):
        E = [[E[i][0] * E[0][j] + E[i][1] * E[1][j] + E[i][2] * E[2][j] for j in range(3)] for i in range(3)]
    return E


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
    """Linear bicycle-model Kalman filter measuring ay and the yaw rate (module docstring)."""

    PARAMETERS: dict = {}

    def __init__(self, data: dict, params: dict | None = None):
        try:
            veh = data["vehicle"]
            where = "vehicle"
            if isinstance(veh.get("parameters"), dict):      # a vehicle set as in design files
                veh, where = veh["parameters"], "vehicle.parameters"
            vals = {}
            for k in _VEHICLE:
                if k not in veh:
                    raise ValueError(f"data file: {where}.{k} is missing")
                entry = veh[k]
                if isinstance(entry, dict):
                    entry = entry.get("value")
                try:
                    vals[k] = float(entry)
                except (TypeError, ValueError):
                    raise ValueError(f"data file: {where}.{k} must be a number, got {veh[k]!r}") from None
                if not (math.isfinite(vals[k]) and vals[k] > 0):
                    raise ValueError(f"data file: vehicle.{k} must be finite and > 0, got {vals[k]!r}")
            self.Q = _mat2(data["noise"]["q"], "noise.q")
            self.R = _mat2(data["noise"]["r"], "noise.r")
            self.P0 = _mat2(data.get("initial", {}).get("P0", [[1.0, 0.0], [0.0, 0.01]]), "initial.P0")
            rt = data.get("runtime", {}) or {}
            self.vx_min = float(rt.get("vx_min", 1.0))
            self.vx_max = float(rt.get("vx_max", 200.0))
        except (KeyError, TypeError, AttributeError) as exc:
            raise ValueError(f"data file lacks {exc} needed by the Kalman observer runtime") from exc
        _definite(self.Q, "noise.q", strict=False)
        _definite(self.R, "noise.r", strict=True)
        _definite(self.P0, "initial.P0", strict=True)
        if not (math.isfinite(self.vx_min) and math.isfinite(self.vx_max) and 0 < self.vx_min < self.vx_max):
            raise ValueError(f"data file: runtime.vx_min/vx_max must be finite with 0 < vx_min < vx_max, "
                             f"got {self.vx_min}, {self.vx_max}")
        m, lf, lr, Iz, Cf, Cr = (vals[k] for k in _VEHICLE)
        self.vehicle = vals
        # A = [[a00 / v, a01 / v - v], [a10 / v, a11 / v]], B = [b0, b1], ay row = A row 0 + [0, v]
        self._a = (-(Cf + Cr) / m, -(lf * Cf - lr * Cr) / m, -(lf * Cf - lr * Cr) / Iz, -(lf**2 * Cf + lr**2 * Cr) / Iz)
        self._b = (Cf / m, lf * Cf / Iz)
        self.x = [0.0, 0.0]
        self.P = [row[:] for row in self.P0]
        self._started = False
        self._outside = False
        self.events: list = []
        self.y = {"beta_hat": 0.0, "vy_hat": 0.0, "yaw_rate_hat": 0.0}

    @classmethod
    def parameter_defaults(cls, data: dict) -> dict:
        return {}

    def _speed(self, vx: float) -> float:
        if self.vx_min <= vx <= self.vx_max:
            self._outside = False
            return vx
        if not self._outside:
            self.events.append(("warning", f"vx = {vx:.4g} m/s outside [{self.vx_min:g}, {self.vx_max:g}] m/s: "
                                           "the model is evaluated at the nearest bound"))
        self._outside = True
        return self.vx_min if vx < self.vx_min else self.vx_max

    def _publish(self, v: float) -> None:
        vy, r = self.x
        self.y["beta_hat"] = math.atan(vy / v)
        self.y["vy_hat"] = vy
        self.y["yaw_rate_hat"] = r

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
        """Update with y = [ay, yaw_rate], then predict over h (s) with the inputs u held."""
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
        v = self._speed(vx)
        A, B, C, D = self.model(v)
        (a00, a01), (a10, a11) = A
        b0, b1 = B
        (c00, c01), (c10, c11) = C
        d0, d1 = D
        x0, x1 = self.x
        (p00, p01), (p10, p11) = self.P
        (r00, r01), (r10, r11) = self.R
        # 1. update with y = [ay, yaw_rate]: S = C P C' + R, K = P C' S^-1 (P symmetric: P C' = (C P)')
        cp00, cp01 = c00 * p00 + c01 * p10, c00 * p01 + c01 * p11
        cp10, cp11 = c10 * p00 + c11 * p10, c10 * p01 + c11 * p11
        s00 = cp00 * c00 + cp01 * c01 + r00
        s01 = cp00 * c10 + cp01 * c11 + r01
        s10 = cp10 * c00 + cp11 * c01 + r10
        s11 = cp10 * c10 + cp11 * c11 + r11
        det = s00 * s11 - s01 * s10
        i00, i01, i10, i11 = s11 / det, -s01 / det, -s10 / det, s00 / det
        k00 = cp00 * i00 + cp10 * i10
        k01 = cp00 * i01 + cp10 * i11
        k10 = cp01 * i00 + cp11 * i10
        k11 = cp01 * i01 + cp11 * i11
        e0 = ay - (c00 * x0 + c01 * x1) - d0 * delta
        e1 = yr - (c10 * x0 + c11 * x1) - d1 * delta
        x0 += k00 * e0 + k01 * e1
        x1 += k10 * e0 + k11 * e1
        q00, q01 = 1.0 - (k00 * c00 + k01 * c10), -(k00 * c01 + k01 * c11)       # I - K C
        q10, q11 = -(k10 * c00 + k11 * c10), 1.0 - (k10 * c01 + k11 * c11)
        n00, n01 = q00 * p00 + q01 * p10, q00 * p01 + q01 * p11
        n10, n11 = q10 * p00 + q11 * p10, q10 * p01 + q11 * p11
        p00, p11 = n00, n11
        p01 = p10 = 0.5 * (n01 + n10)
        # 2. predict over h (exact ZOH of the model at v)
        try:
            E = _expm3([[a00 * h, a01 * h, b0 * h],
                        [a10 * h, a11 * h, b1 * h],
                        [0.0, 0.0, 0.0]])
        except (OverflowError, ValueError, ZeroDivisionError):
            E = None
        if E is None or not all(math.isfinite(a) for row in E for a in row):
            self.events.append(("warning", f"the model discretised over h = {h!r} s is not finite: step refused, "
                                           "state held"))
            return
        f00, f01, g0 = E[0]
        f10, f11, g1 = E[1]
        x0, x1 = f00 * x0 + f01 * x1 + g0 * delta, f10 * x0 + f11 * x1 + g1 * delta
        m00, m01 = f00 * p00 + f01 * p10, f00 * p01 + f01 * p11
        m10, m11 = f10 * p00 + f11 * p10, f10 * p01 + f11 * p11
        (w00, w01), (w10, w11) = self.Q
        p00 = m00 * f00 + m01 * f01 + w00 * h
        p11 = m10 * f10 + m11 * f11 + w11 * h
        p01 = 0.5 * ((m00 * f10 + m01 * f11 + w01 * h) + (m10 * f00 + m11 * f01 + w10 * h))
        if not all(math.isfinite(a) for a in (x0, x1, p00, p01, p11)):
            self.events.append(("warning", "the filter's state became non-finite: step refused, state held"))
            return
        self.x = [x0, x1]
        self.P = [[p00, p01], [p01, p11]]
        self._publish(v)
