"""Runtime of paper 000's switched PI observer (Menhour et al., ECC 2014): eq. (5), stepped.

A reference implementation, standard library only, that evaluates the tables of its design file
(``synthesis.tables.sideslip_bank_observer``): the model M(v), G(v) in v = 1/vx and the step maps at
the default step. It gives the native C model's (``c/sideslip_bank_observer.c``) outputs bit for bit, with the
same operations in the same order. FMI is in ``framework.py``; the behaviour (holds, modes, clamps,
validity) is specified in ``docs/runtime/sideslip_bank_observer.md``.
"""
from __future__ import annotations

import math
from bisect import bisect_right

from .linalg import dot as _dot   # sum_j row[j] x[j] from the left, as ``dot_from(0.0, ...)`` in C

#: s (2^-30, about 0.93 ns): the shortest baseline over which the first-order hold takes its slope,
#: and the shortest step that extrapolates it. Departure (no such rule in the paper, whose
#: measurements are continuous): below it the slope (w_k - w_a) / (t_k - t_a) is meaningless in
#: doubles (the rounding of w_k - w_a, u |w|, divided by a subnormal baseline overflows), and an
#: extrapolation factor h / baseline <= 2^30 (h <= 1 s, the longest step any FMU accepts) keeps
#: that rounding below 2^-22 |w|. A step shorter than it holds w (zero-order): its slope term
#: moves w by at most 2^-30 s times the slope, s by O(h^2). Such a step keeps the hold's previous
#: sample as the baseline (its age grows by h), so that the next slope spans a real interval.
#: The C model (c/sideslip_bank_observer.c, FOH_MIN_BASE) uses the same value.
FOH_MIN_BASE = 2.0 ** -30

OUTPUT_NAMES = ("beta_hat", "yaw_rate_hat", "roll_angle_hat", "roll_rate_hat", "bank_angle_hat", "mode", "valid")
ESTIMATES = OUTPUT_NAMES[:4]


def _matmul(A, B):
    cols = list(zip(*B))
    return [[_dot(row, col) for col in cols] for row in A]


def _substep_map(Ma, Gi, hs):
    """One classical RK4 substep of a' = Ma a + Gi i with the input i held, as the affine map
    [R | S Gi]: X = hs Ma, Q = I + X/2 (I + X/3 (I + X/4)), R = I + X Q, S Gi = hs Q Gi (the
    degree-0 case of ``synthesis/tables/series.py``, which an FMU cannot import: the same operations,
    so that a map built here for another step equals the C model's)."""
    n = len(Ma)
    X = [[x * hs for x in row] for row in Ma]
    Q = [[1.0 if i == j else 0.0 for j in range(n)] for i in range(n)]
    for c in (4.0, 3.0, 2.0):
        Q = [[(1.0 if i == j else 0.0) + t * (1.0 / c) for j, t in enumerate(row)] for i, row in enumerate(_matmul(X, Q))]
    R = [[(1.0 if i == j else 0.0) + t for j, t in enumerate(row)] for i, row in enumerate(_matmul(X, Q))]
    return [r + [x * hs for x in sg] for r, sg in zip(R, _matmul(Q, Gi))]


def _compose(W2, W1):
    """The affine map W2 after W1, each [A | b]: [A2 A1 | A2 b1 + b2]."""
    n = len(W2)
    out = _matmul([row[:n] for row in W2], W1)
    return [ro[:n] + [a + b for a, b in zip(ro[n:], r2[n:])] for ro, r2 in zip(out, W2)]


def _power(W, k):
    """W composed k >= 1 times, by binary powering (all factors commute)."""
    result = None
    while True:
        if k & 1:
            result = W if result is None else _compose(W, result)
        k >>= 1
        if not k:
            return result
        W = _compose(W, W)


class SwitchedPIObserver:
    """Switched PI observer of paper 000 from its design file and its tables (``data["tables"]``)."""

    PARAMETERS = {"vx_hold": 1.0}  # m/s: below this speed the estimates are held
    INVALID_LOG_PERIOD = 1.0       # s of simulated time: at most one "valid = 0" message per period

    def __init__(self, data: dict, params: dict | None = None):
        tab = data.get("tables") or {}
        if "maps" not in tab:
            raise ValueError("design file lacks the paper-000 observer's tables (data['tables'], computed by "
                             "synthesis.tables when the design is made or packaged)")
        self.h0, self.max_step, self.N = tab["step"], tab["max_step"], tab["N"]
        self.p0 = int(tab.get("first_power", 0))     # M[k] multiplies v**(k + p0); -1: a term in vx
        self.M, self.G, self.maps, self.modes = tab["M"], tab["G"], tab["maps"], tab["modes"]
        sw = tab["switching"]
        self.edges = sw["edges"] if sw["kind"] == "speed_bands" else None
        self.slip = None if self.edges else (sw["lf"], sw["lr"], sw["up"], sw["down"])
        self.lo, self.hi = tab["grid"]
        self.validity = tab["validity"]
        self.freeze = bool(self.validity and self.validity["freeze_integral"])
        self.foh = tab["input_hold"] == "first_order"
        self.vx_hold = float((params or {}).get("vx_hold", tab["vx_hold"]))
        if not (math.isfinite(self.vx_hold) and self.vx_hold > 0):      # 0 would reach 1/vx at vx = 0
            raise ValueError(f"parameter vx_hold must be finite and > 0 m/s, got {self.vx_hold}")
        self.n, self.nm = len(self.N), len(self.modes)
        self._map_h, self._fixed = None, {}   # the composite maps of a step h != h0 (fixed speeds)
        self.mode = 0                         # 0-based; the output is 1-based
        self.s = [0.0] * (self.n + 1)         # [z; w^]
        self.valid = 1
        self.invalid_entries = 0              # entries into valid = 0 since the start
        self._invalid_logged = None           # time of the last "valid = 0" message
        self._invalid_unlogged = 0            # entries since then without a message
        self._started = self._holding = self._outside = False
        self._t = 0.0                         # simulated time (sum of the steps; validity messages)
        self._prev = None                     # first-order hold: (w_{k-1}, h_{k-1})
        self.events: list[tuple[str, str]] = []
        self.y = {name: 0.0 for name in OUTPUT_NAMES}
        self.y["mode"] = self.y["valid"] = 1

    # -- eq. (5) and its step -------------------------------------------------------------------
    def system(self, idx: int, v: float):
        """M, G of map index idx at v = 1/vx: sum_k M_k v**(k + p0) (v**-1 as 1 / v)."""
        vk = [1.0 if k + self.p0 == 0 else 1.0 / v if k + self.p0 == -1 else v ** (k + self.p0)
              for k in range(len(self.M[idx]))]
        M = [[0.0] * len(self.M[idx][0][0]) for _ in self.s]
        G = [[0.0] * len(self.G[idx][0][0]) for _ in self.s]
        for out, coeffs in ((M, self.M[idx]), (G, self.G[idx])):
            for P, p in zip(coeffs, vk):
                for orow, prow in zip(out, P):
                    for j, c in enumerate(prow):
                        orow[j] += c * p
        return M, G

    def rk4(self, idx: int, v: float, h: float, x: list) -> list:
        """ceil(h / max_step) classical RK4 substeps of s' = M s + G w(tau) from x = [s; w(; e)]:
        departure from eq. (5)'s continuous time, the discretisation the certificate checks; the
        first-order hold's w(tau) = w + (tau / h) e is evaluated at the stage times."""
        ns, nw = self.n + 1, len(self.G[idx][0][0])
        M, G = self.system(idx, v)
        nsub = max(1, math.ceil(h / self.max_step - 1e-9))
        hs = h / nsub
        b = [_dot(row, x[ns:ns + nw]) for row in G]
        g = [_dot(row, x[ns + nw:]) / h for row in G] if self.foh else [0.0] * ns
        s = x[:ns]

        def f(s, c):
            return [_dot(row, s) + bi for row, bi in zip(M, c)]
        for j in range(nsub):
            b1, b2, b4 = ([bi + t * gi for bi, gi in zip(b, g)] for t in (j * hs, (j + 0.5) * hs, (j + 1) * hs))
            k1 = f(s, b1)
            k2 = f([a + 0.5 * hs * k for a, k in zip(s, k1)], b2)
            k3 = f([a + 0.5 * hs * k for a, k in zip(s, k2)], b2)
            k4 = f([a + hs * k for a, k in zip(s, k3)], b4)
            s = [a + hs / 6.0 * (p + 2 * q + 2 * r + t) for a, p, q, r, t in zip(s, k1, k2, k3, k4)]
        return s

    def fixed_map(self, idx: int, h: float):
        """The composite map of the RK4 substeps over h at a fixed model speed, [Phi | Gam (| Gam_e)]
        (rows of s): one substep's affine map, powered. First-order hold: the map of the augmented
        system [s; w]' = [[M, G], [0, 0]] [s; w] + [[0], [I / h]] e, on which RK4 evaluates the ramp
        w(tau) exactly at the stage times."""
        ns, nw = self.n + 1, len(self.G[idx][0][0])
        M, G = self.system(idx, self.modes[idx % self.nm]["fixed_v"])
        if self.foh:
            Ma = [m + g for m, g in zip(M, G)] + [[0.0] * (ns + nw) for _ in range(nw)]
            # a step below FOH_MIN_BASE has e = 0 (its column unused): 0, not 1/h (inf below ~5.6e-309 s,
            # whose product with e = 0 would be NaN)
            ih = 1.0 / h if h >= FOH_MIN_BASE else 0.0
            Gi = [[0.0] * nw for _ in range(ns)] + [[ih if i == j else 0.0 for j in range(nw)] for i in range(nw)]
        else:
            Ma, Gi = M, G
        nsub = max(1, math.ceil(h / self.max_step - 1e-9))
        return _power(_substep_map(Ma, Gi, h / nsub), nsub)[:ns]

    def advance(self, idx: int, v: float, h: float, x: list) -> list:
        """s+ over the step h from x = [s; w(; e)], map index idx, model at v = 1/vx."""
        if h == self.h0:               # the tables: the map of the interval of v holding v
            tab = self.maps[idx]
            piece = tab["intervals"][min(max(int((v - tab["v_lo"]) * tab["scale"]), 0), len(tab["intervals"]) - 1)]
            coef = piece["coef"]
            if coef is not None:       # Horner in d = v - center, rows of each degree's matrix times x
                d = v - piece["center"]
                out = []
                for r in range(self.n + 1):
                    acc = _dot(coef[-1][r], x)
                    for P in coef[-2::-1]:
                        acc = _dot(P[r], x) + d * acc
                    out.append(acc)
                return out
        elif self.modes[idx % self.nm]["fixed_v"] is not None:
            if self._map_h != h:       # one step size at a time, as the C model
                self._map_h, self._fixed = h, {}
            if idx not in self._fixed:
                self._fixed[idx] = self.fixed_map(idx, h)
            return [_dot(row, x) for row in self._fixed[idx]]
        return self.rk4(idx, v, h, x)

    def model_v(self, mode: int, vx: float) -> float:
        """v = 1/vx of the mode's model: its fixed speed (eq. 25 literally), or the measured vx clamped
        to the mode's range (a departure: the model follows the speed inside the mode, LPV)."""
        ms = self.modes[mode]
        return ms["fixed_v"] if ms["fixed_v"] is not None else 1.0 / min(max(vx, ms["vx_range"][0]), ms["vx_range"][1])

    # -- switching, validity --------------------------------------------------------------------
    def estimates01(self, w) -> tuple[float, float]:
        """beta^, r^: the first two rows of x^ = z + N y."""
        (n00, n01, n02), (n10, n11, n12) = self.N[0], self.N[1]
        s = self.s
        return s[0] + (n00 * w[0] + n01 * w[1] + n02 * w[2]), s[1] + (n10 * w[0] + n11 * w[1] + n12 * w[2])

    @staticmethod
    def slip_premise(beta: float, r: float, vx: float, delta: float, lf: float, lr: float) -> float:
        """max(|alpha_f|, |alpha_r|), the slip angles of eq. (2) from the estimates beta^, r^."""
        return max(abs(delta - beta - lf * r / vx), abs(-beta + lr * r / vx))

    def band(self, vx: float) -> int:
        """Eq. (25): mode i on [edges[i], edges[i + 1]); outside the grid the nearest mode."""
        i = bisect_right(self.edges, vx) - 1
        return 0 if i < 0 else min(i, self.nm - 1)

    def decide(self, vx: float, w, t: float) -> int:
        """The mode (eq. 25 or 27) and ``valid`` for the step starting at t; returns the map index."""
        if self.slip is not None or self.validity is not None:
            beta, r = self.estimates01(w)
        if self.slip is None:
            self.mode = self.band(vx)
        else:
            # departure from eq. (27): a hysteresis band (up, down) around alpha* (the paper switches
            # exactly at alpha*, which chatters when the estimated slip hovers there)
            lf, lr, up, down = self.slip
            premise = self.slip_premise(beta, r, vx, w[3], lf, lr)
            if self.mode == 0 and premise > up:
                self.mode = 1
            elif self.mode == 1 and premise < down:
                self.mode = 0
        if self.validity is not None and not self.check_validity(beta, r, vx, w, t) and self.freeze:
            return self.mode + self.nm   # the integral action frozen: w^'s row zero
        return self.mode

    def check_validity(self, beta: float, r: float, vx: float, w, t: float) -> int:
        """valid (1/0): the slip angles and |vx yaw_rate| against the validity limits, with the release
        hysteresis, and vx inside the design grid (neither in the paper: below the grid the model
        frozen at its lowest speed is far from the car's, and the bank estimate takes up the
        difference); one rate-limited warning per entry into valid = 0."""
        val = self.validity
        alpha = self.slip_premise(beta, r, vx, w[3], val["lf"], val["lr"])
        ay = abs(vx * w[0])
        inside = self.lo <= vx <= self.hi
        if self.valid:
            if alpha > val["alpha_max"] or ay > val["ay_max"] or not inside:
                self.valid = 0
                self.invalid_entries += 1
                last = self._invalid_logged
                if last is None or t - last >= self.INVALID_LOG_PERIOD:
                    more = (f"; {self._invalid_unlogged} more entries since the last message not logged"
                            if self._invalid_unlogged else "")
                    held = "; bank estimate held until valid again" if self.freeze else ""
                    why = ("estimates outside the validity limits" if inside else
                           f"vx = {vx:.4g} m/s outside the design grid [{self.lo:.4g}, {self.hi:.4g}] m/s, and")
                    self.events.append((
                        "warning", f"t = {t:.6g} s: valid = 0, {why}: "
                                   f"max(|alpha_f|, |alpha_r|) = {alpha:.3g} rad (limit {val['alpha_max']:.3g}), "
                                   f"|vx yaw_rate| = {ay:.3g} m/s^2 (limit {val['ay_max']:.3g}){held} "
                                   f"(entry {self.invalid_entries}{more})"))
                    self._invalid_logged, self._invalid_unlogged = t, 0
                else:
                    self._invalid_unlogged += 1
        elif alpha < val["alpha_release"] and ay < val["ay_release"] and inside:
            self.valid = 1
        self.y["valid"] = self.valid
        return self.valid

    # -- the framework's interface --------------------------------------------------------------
    def xhat(self, y_meas) -> list[float]:
        return [z + _dot(row, y_meas) for z, row in zip(self.s, self.N)]

    def initialize(self, u: dict) -> None:
        """Start from the first measurement (the paper gives no initial state): x^(0) = [0, y(0)]
        (z = x^ - N y; relaxed axle forces: x^(0) = [0, y(0), 0, 0]), the mode of the initial speed
        (speed bands); the first-order hold restarts."""
        w = [u["yaw_rate"], u["roll_angle"], u["roll_rate"]]
        ny = [_dot(row, w) for row in self.N]
        x0 = [0.0] + w + [0.0] * (self.n - 1 - len(w))
        self.s = [x - p for x, p in zip(x0, ny)] + self.s[self.n:]
        self._started, self._prev = True, None
        if self.edges and u["vx"] >= self.vx_hold:
            self.mode = self.band(u["vx"])
        self.y.update(zip(ESTIMATES, (z + p for z, p in zip(self.s, ny))), bank_angle_hat=self.s[self.n],
                      mode=self.mode + 1, valid=self.valid)

    def step(self, h: float, u: dict) -> None:
        vx, t = u["vx"], self._t
        if not self._started:
            self.initialize(u)
        if self.validity is not None:
            self._t = t + h
        if vx < self.vx_hold:          # not in the paper (its model has 1/vx terms): standstill or
            # reversing freezes the observer, every output held as it is
            if not self._holding:
                self.events.append(("warning", f"vx = {vx:.3g} m/s < vx_hold = {self.vx_hold:g} m/s (standstill "
                                               "or reversing): observer frozen, every estimate held"))
            self._holding, self._prev = True, None     # the first-order hold restarts with slope 0
            return
        if self._holding:
            self.events.append(("warning", f"vx = {vx:.3g} m/s: observer resumes"))
            self._holding = False
        if self.lo <= vx <= self.hi:   # outside the design grid: the nearest mode / model speed
            self._outside = False
        else:
            if not self._outside:
                self.events.append(("warning", f"vx = {vx:.4g} m/s outside the design grid [{self.lo:.4g}, "
                                               f"{self.hi:.4g}] m/s: clamped to the nearest grid mode/speed"))
            self._outside = True
        w = [u["yaw_rate"], u["roll_angle"], u["roll_rate"], u["delta"]]
        idx = self.decide(vx, w, t)
        x = self.s + w
        e = []
        if self.foh:                   # (not in the paper, whose measurements are continuous) the
            # increment e of the first-order hold w_k + tau (w_k - w_a) / (t_k - t_a) over the step h,
            # w_a the hold's previous sample (w_{k-1}, or an older one after steps < FOH_MIN_BASE)
            prev = self._prev
            if prev is None or prev[1] < FOH_MIN_BASE or h < FOH_MIN_BASE:
                e = [0.0] * len(w)     # no slope: first step, restart, too short a baseline or step
            else:
                e = [(a - p) * (h / prev[1]) for a, p in zip(w, prev[0])]
            self._prev = (w, h) if prev is None or h >= FOH_MIN_BASE else (prev[0], prev[1] + h)
            x += e
        self.s = s = self.advance(idx, self.model_v(self.mode, vx), h, x)
        for i, name in enumerate(ESTIMATES):   # x^ = z + N y with the hold's y at t + h
            acc = s[i]
            for c, y in zip(self.N[i], w):
                acc += c * y
            for c, y in zip(self.N[i], e):
                acc += c * y
            self.y[name] = acc
        self.y["bank_angle_hat"] = s[self.n]
        self.y["mode"] = self.mode + 1
