"""Nonlinear car plant: two-track lateral / yaw / roll model, the truth model of every car observer.

Standard library only; runs inside the FMU (``framework.py`` drives it). Equations, states,
clamps and numerics: docs/runtime/car_plant.md.
"""
from __future__ import annotations

import math

from .spec import runtime_parameters

G = 9.81  # m/s^2; must equal latobs.synthesis.params.G (checked by the tests)

_atan = math.atan
_sin = math.sin
_cos = math.cos

_REQUIRED = ("m", "Iz", "Ix", "lf", "lr", "hr", "Kr", "br", "Cf", "Cr", "sigma", "track",
             "h_rc", "roll_share_f", "mf_C", "mf_E", "mu")


class CarPlantModel:
    """Nonlinear two-track lateral/yaw/roll car with Magic-Formula tires (docs/runtime/car_plant.md).

    ``CarPlantModel(data, params)`` with ``data = {"vehicle": Vehicle.as_dict()}`` and ``params``
    the FMU parameters (missing or None entries take their defaults):

    * ``mu``      (1)    peak friction coefficient; default the vehicle's ``mu``.
    * ``scale_f`` (1)    front cornering stiffness scale factor; default 1.0.
    * ``scale_r`` (1)    rear cornering stiffness scale factor; default 1.0.
    * ``sigma``   (m)    tire relaxation length; default the vehicle's ``sigma``; <= 0 disables
                         the relaxation (algebraic tires).
    * ``linear_tires`` (1)  0 (default): Magic Formula tires; 1: their linearisation at zero slip,
                         Fy_ss = mu Fz B C alpha, no saturation (E6). Other values are refused.

    ``PARAMETERS`` holds the defaults for the representative sedan; ``parameter_defaults(data)``
    gives the defaults for a given vehicle (use it for the FMU start values).
    """

    PARAMETERS = {"mu": 1.0, "scale_f": 1.0, "scale_r": 1.0, "sigma": 0.5, "linear_tires": 0.0}
    PARAMETER_INFO = {
        "mu": ("1", "peak tire-road friction coefficient (default: the vehicle's mu)"),
        "scale_f": ("1", "front cornering stiffness scale factor"),
        "scale_r": ("1", "rear cornering stiffness scale factor"),
        "sigma": ("m", "tire relaxation length (default: the vehicle's sigma); <= 0 disables relaxation"),
        "linear_tires": ("1", "1: linear tires Fy = mu Fz B C alpha (the Magic Formula's slope at zero "
                              "slip, no saturation); 0: Magic Formula (default)"),
    }
    STATE_NAMES = ("vy", "yaw_rate", "roll_angle", "roll_rate", "Fy_fl", "Fy_fr", "Fy_rl", "Fy_rr")
    STATE_UNITS = ("m/s", "rad/s", "rad", "rad/s", "N", "N", "N", "N")
    INPUTS = {"delta": ("rad", "road-wheel steering angle, > 0 steers left"),
              "vx": ("m/s", "longitudinal speed (prescribed)"),
              "bank_angle": ("rad", "road bank angle; > 0 gives -g sin(bank) along body +y"),
              "stiffness_scale_f": ("1", "multiplies the front cornering stiffness on top of scale_f; "
                                         "optional, default 1.0, held per step, clamped to [0.1, 10]"),
              "stiffness_scale_r": ("1", "multiplies the rear cornering stiffness on top of scale_r; "
                                         "optional, default 1.0, held per step, clamped to [0.1, 10]")}
    #: inputs a caller may omit from ``u`` (their value when never given)
    OPTIONAL_INPUTS = {"stiffness_scale_f": 1.0, "stiffness_scale_r": 1.0}
    OUTPUTS = {"beta": ("rad", "sideslip angle atan(vy/vx) at the roll axis below the CG"),
               "vy": ("m/s", "lateral velocity at the roll axis below the CG"),
               "yaw_rate": ("rad/s", "yaw rate"),
               "ay": ("m/s^2", "lateral specific force at the CG, road-plane accelerometer: sum Fy / m"),
               "roll_angle": ("rad", "roll angle, > 0 leans right"),
               "roll_rate": ("rad/s", "roll rate"),
               "Fyf": ("N", "front tire forces along body y (both wheels)"),
               "Fyr": ("N", "rear tire forces along body y (both wheels)"),
               "alpha_f": ("rad", "mean front slip angle"),
               "alpha_r": ("rad", "mean rear slip angle"),
               "vy_cg": ("m/s", "lateral velocity of the CG (road-plane body axes): vy - hr phidot cos(phi)"),
               "beta_cg": ("rad", "sideslip angle at the CG: atan(vy_cg/vx)")}

    H_MAX = 1e-3          # s, largest internal (Heun) substep
    VX_MAX = 100.0        # m/s, larger vx inputs are clamped
    V_SLIP_MIN = 1.0      # m/s, floor of the wheel longitudinal velocity in the slip angle
    V_RELAX_MIN = 1.0     # m/s, floor of the speed in the relaxation rate (spec's v_floor)
    AX_MAX = 15.0         # m/s^2, clamp of the finite-difference longitudinal acceleration
    DELTA_MAX = 0.8       # rad, clamp of the road-wheel angle (~46 deg)
    BANK_MAX = 0.6        # rad, clamp of the road bank angle (~34 deg)
    ALPHA_SPIN = 0.5      # rad, |alpha_r| beyond which a "spun out" warning is issued (rear far past peak)
    SCALE_IN_MIN = 0.1    # 1, clamp of the stiffness_scale_f/r inputs (= the scale_f/r parameter range)
    SCALE_IN_MAX = 10.0   # 1

    # ------------------------------------------------------------------ construction
    @staticmethod
    def _vehicle_values(data) -> dict:
        try:
            vehicle = data["vehicle"]
            params = vehicle["parameters"]
        except (KeyError, TypeError) as exc:
            raise ValueError("CarPlant data must be {'vehicle': {'parameters': {...}}}") from exc
        name = vehicle.get("name", "?") if isinstance(vehicle, dict) else "?"
        vals = {}
        for k in _REQUIRED:
            if k not in params:
                raise ValueError(f"CarPlant: vehicle {name!r} lacks parameter {k!r}")
            entry = params[k]
            v = entry.get("value") if isinstance(entry, dict) else entry
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ValueError(f"CarPlant: vehicle {name!r} parameter {k!r} must be a finite number, got {v!r}")
            vals[k] = float(v)
        for k in ("m", "Iz", "Ix", "lf", "lr", "hr", "Kr", "Cf", "Cr", "track", "mu", "mf_C"):
            if not vals[k] > 0:
                raise ValueError(f"CarPlant: vehicle {name!r} parameter {k!r} must be > 0, got {vals[k]}")
        if vals["br"] < 0:
            raise ValueError(f"CarPlant: vehicle {name!r} parameter 'br' must be >= 0, got {vals['br']}")
        if not 0.0 <= vals["roll_share_f"] <= 1.0:
            raise ValueError(f"CarPlant: vehicle {name!r} parameter 'roll_share_f' must be in [0, 1], "
                             f"got {vals['roll_share_f']}")
        if vals["mf_C"] > 2.0:
            raise ValueError(f"CarPlant: vehicle {name!r} parameter 'mf_C' must be <= 2 (force sign "
                             f"flips beyond), got {vals['mf_C']}")
        if vals["mf_E"] > 1.0:
            raise ValueError(f"CarPlant: vehicle {name!r} parameter 'mf_E' must be <= 1 (non-monotonic "
                             f"Magic Formula argument), got {vals['mf_E']}")
        if not vals["Kr"] > vals["m"] * G * vals["hr"]:
            raise ValueError(f"CarPlant: vehicle {name!r} parameter 'Kr' = {vals['Kr']} must exceed "
                             f"m g hr = {vals['m'] * G * vals['hr']:.6g} (statically unstable roll)")
        return vals

    @classmethod
    def parameter_defaults(cls, data) -> dict:
        """The FMU parameter defaults for the vehicle in ``data`` (mu and sigma from the vehicle)."""
        return cls._defaults(cls._vehicle_values(data))

    @staticmethod
    def _defaults(v: dict) -> dict:
        return {"mu": v["mu"], "scale_f": 1.0, "scale_r": 1.0, "sigma": v["sigma"], "linear_tires": 0.0}

    def __init__(self, data: dict, params: dict | None = None):
        v = self._vehicle_values(data)
        p = runtime_parameters("CarPlant", self.PARAMETERS, self._defaults(v), params)
        for k in ("mu", "scale_f", "scale_r"):
            if not p[k] > 0:
                raise ValueError(f"CarPlant: parameter {k!r} must be > 0, got {p[k]}")
        if p["linear_tires"] not in (0.0, 1.0):
            raise ValueError(f"CarPlant: parameter 'linear_tires' must be 0 (Magic Formula) or 1 (linear "
                             f"tires), got {p['linear_tires']}")
        self.params = p
        self.vehicle = v

        m, lf, lr = v["m"], v["lf"], v["lr"]
        L = lf + lr
        t = v["track"]
        self._m, self._Iz, self._Ix = m, v["Iz"], v["Ix"]
        self._lf, self._lr, self._hr = lf, lr, v["hr"]
        self._Kr, self._br = v["Kr"], v["br"]
        self._t2 = 0.5 * t
        self._mu = p["mu"]
        self._sigma = p["sigma"]
        self._relax = p["sigma"] > 0.0
        self._C, self._E = v["mf_C"], v["mf_E"]
        self._linear = p["linear_tires"] == 1.0
        # flat-road static wheel loads (N) and the per-axle Magic Formula B (E6)
        self._Wf = m * G * lr / (2.0 * L)
        self._Wr = m * G * lf / (2.0 * L)
        self._Cf_eff = p["scale_f"] * v["Cf"]       # N/rad, per axle
        self._Cr_eff = p["scale_r"] * v["Cr"]
        self._Bf = 0.5 * self._Cf_eff / (self._mu * self._Wf * self._C)
        self._Br = 0.5 * self._Cr_eff / (self._mu * self._Wr * self._C)
        # load transfer coefficients (E5)
        self._kx = m * (v["h_rc"] + v["hr"]) / (2.0 * L)      # N per m/s^2, per wheel
        self._kyf = m * lr / L * v["h_rc"] / t               # N per m/s^2, front axle
        self._kyr = m * lf / L * v["h_rc"] / t
        self._ef = v["roll_share_f"] / t                     # 1/m, share of the roll moment
        self._er = (1.0 - v["roll_share_f"]) / t
        # estimate of the fastest mode per unit 1/speed (algebraic tires) and roll, for substeps
        hr, Ix, Iz = v["hr"], v["Ix"], v["Iz"]
        Ca0 = 2.0 * (self._Cf_eff + self._Cr_eff)  # x2: lateral load transfer can double a wheel's load
        Ca2 = 2.0 * (self._Cf_eff * lf * lf + self._Cr_eff * lr * lr)
        self._lam_alg = Ca0 * (1.0 / m + hr * hr / Ix) + Ca2 / Iz        # 1/s per 1/(m/s)
        self._lam_osc = math.sqrt(self._lam_alg)                         # relaxation oscillation scale
        self._lam_roll = v["br"] / Ix + math.sqrt(v["Kr"] / Ix)
        self._lam_osc_s = self._lam_osc / math.sqrt(self._sigma) if self._relax else 0.0
        # the constants of the right-hand side, unpacked once per step by _make_rhs
        mu = self._mu
        self._consts = (lf, lr, self._t2, m, hr, Ix, Iz, self._Kr, self._br, mu * self._kyf, mu * self._kyr,
                        mu * self._ef, mu * self._er, self._C, self._E, mu, -self._Bf, -self._Br,
                        self._Wf, self._Wr, self._kx, self._relax, self._sigma, self._linear,
                        -self._Bf * self._C, -self._Br * self._C)

        self.x = [0.0] * 8
        self.events: list = []
        self._vx_prev = None
        self._flags = set()
        self._last_u = (0.0, 0.0, 0.0, 0.0)  # delta, vx, bank, ax used for the outputs
        self._scales = (1.0, 1.0)            # stiffness_scale_f, _r used for the outputs (last valid)
        self.y: dict = {}
        self._update_outputs()

    # ------------------------------------------------------------------ the physics
    def _make_rhs(self, delta, vx, phir, ax, sf=1.0, sr=1.0):
        """Right-hand side E1-E7 for held inputs (already clamped): returns ``f``.

        ``sf``, ``sr``: the stiffness_scale_f/r inputs (clamped), multiplying the axles' B.

        ``f(vy, r, phi, phid, F1, F2, F3, F4)`` gives the 8 derivatives as a tuple (the tire ones
        0.0 with algebraic tires, whose forces are then computed from the body states and F1..F4
        are ignored). ``f(..., aux=1)``: the output quantities (S, Fyf, Fyr, alpha_f, alpha_r,
        F1, F2, F3, F4); with relaxation these need no Magic Formula (the forces are states).
        ``f(..., aux=2)``: the ``tire_state`` dict.

        ``f`` is the hot loop of ``step`` (10 calls per 5 ms step): everything that depends on
        the inputs and parameters only (sin/cos of delta and phi_r, the wheel loads after the
        longitudinal transfer, products of constants) is computed here, once per step, and mu is
        applied to the loads rather than to each wheel's Magic Formula value.
        """
        (lf, lr, t2, m, hr, Ix, Iz, Kr, br, mkyf, mkyr, mef, mer, C, E, mu, nBf, nBr, Wf, Wr, kx,
         relax, sigma, linear, nBCf, nBCr) = self._consts
        # time-varying cornering stiffness: the inputs multiply B (exact no-op at 1.0)
        nBf *= sf
        nBr *= sr
        nBCf *= sf
        nBCr *= sr
        vmin = self.V_SLIP_MIN
        atan, sin, cos = _atan, _sin, _cos
        sd = sin(delta)
        cd = cos(delta)
        # E4 constants: u_fl,fr = vx cd + vf sd -+ r (t/2) cd, v_fl,fr = vf cd - vx sd +- r (t/2) sd
        vxcd = vx * cd
        vxsd = vx * sd
        t2cd = t2 * cd
        t2sd = t2 * sd
        # E3: r' = (lf cd (Fy_fl + Fy_fr) + (t/2) sd (Fy_fl - Fy_fr) - lr (Fy_rl + Fy_rr)) / Iz
        zf = lf * cd / Iz
        zd = t2sd / Iz
        zr = lr / Iz
        # E5: static loads on the bank and the (clamped) longitudinal transfer
        cphr = cos(phir)
        Fzf = Wf * cphr
        Fzr = Wr * cphr
        dx = kx * ax
        if dx > Fzf:
            dx = Fzf
        elif dx < -Fzr:
            dx = -Fzr
        Fzf -= dx
        Fzr += dx
        mFzf = mu * Fzf                    # mu times the loads and the transfer coefficients:
        mFzr = mu * Fzr                    # the clamps below act on mu dFz (mu > 0)
        nmFzf = -mFzf
        nmFzr = -mFzr
        mgch = m * G * cphr * hr           # roll moment coefficient of the vertical reaction (E1)
        gs = G * sin(phir)                 # bank gravity component (E2)
        vrel = vx if vx > self.V_RELAX_MIN else self.V_RELAX_MIN
        k = vrel / sigma if relax else 0.0   # E7 relaxation rate

        def f(vy, r, phi, phid, F1, F2, F3, F4, aux=0):
            # E4: slip angles from the wheel-frame velocity (u along the wheel, v across it); the
            # wheel's longitudinal velocity is floored at V_SLIP_MIN. For u >= V_SLIP_MIN this is
            # exactly alpha = delta_w - atan2(vy + r xw, vx - r yw). Wheels 1..4 = fl, fr, rl, rr;
            # q = tan(-alpha) = v / max(u, V_SLIP_MIN).
            rt = r * t2
            ul = vx - rt                  # body-x velocity of the left wheels (yw = +t/2)
            ur = vx + rt                  # right wheels (yw = -t/2)
            vf = vy + r * lf              # body-y velocity of the front wheels
            vr = vy - r * lr              # rear wheels
            uf = vxcd + vf * sd
            wf = vf * cd - vxsd
            rc = r * t2cd
            rs = r * t2sd
            u1 = uf - rc
            u2 = uf + rc
            q1 = (wf + rs) / (u1 if u1 > vmin else vmin)
            q2 = (wf - rs) / (u2 if u2 > vmin else vmin)
            q3 = vr / (ul if ul > vmin else vmin)
            q4 = vr / (ur if ur > vmin else vmin)
            if aux == 1 and relax:   # outputs only
                Ffy = (F1 + F2) * cd
                return (Ffy + F3 + F4, Ffy, F3 + F4, -0.5 * (atan(q1) + atan(q2)),
                        -0.5 * (atan(q3) + atan(q4)), F1, F2, F3, F4)
            if linear:   # E6, linear_tires = 1: Fy_ss / (mu Fz) = B C alpha (alpha = -atan q)
                g1 = nBCf * atan(q1)
                g2 = nBCf * atan(q2)
                g3 = nBCr * atan(q3)
                g4 = nBCr * atan(q4)
            else:        # E6 with x = B alpha: Fy_ss / (mu Fz) = sin(C atan(x - E (x - atan x)))
                x = nBf * atan(q1)
                g1 = sin(C * atan(x - E * (x - atan(x))))
                x = nBf * atan(q2)
                g2 = sin(C * atan(x - E * (x - atan(x))))
                x = nBr * atan(q3)
                g3 = sin(C * atan(x - E * (x - atan(x))))
                x = nBr * atan(q4)
                g4 = sin(C * atan(x - E * (x - atan(x))))
            # E5: lateral load transfer, left wheels -dFz, right +dFz, clamped to the axle's load
            # (d = mu dFz: the forces are (mu Fz_axle -+ d) g)
            Mroll = Kr * phi + br * phid
            if relax:
                Ff = F1 + F2
                Fr = F3 + F4
                S = Ff * cd + Fr
                ay = S / m
            else:  # algebraic loop: pass 1 with ay = 0, pass 2 (below) with ay = S_pass1 / m
                df = mef * Mroll
                if df > mFzf:
                    df = mFzf
                elif df < nmFzf:
                    df = nmFzf
                dr = mer * Mroll
                if dr > mFzr:
                    dr = mFzr
                elif dr < nmFzr:
                    dr = nmFzr
                S = ((mFzf - df) * g1 + (mFzf + df) * g2) * cd + (mFzr - dr) * g3 + (mFzr + dr) * g4
                ay = S / m
            df = mkyf * ay + mef * Mroll
            if df > mFzf:
                df = mFzf
            elif df < nmFzf:
                df = nmFzf
            dr = mkyr * ay + mer * Mroll
            if dr > mFzr:
                dr = mFzr
            elif dr < nmFzr:
                dr = nmFzr
            s1 = (mFzf - df) * g1         # steady-state forces (E6)
            s2 = (mFzf + df) * g2
            s3 = (mFzr - dr) * g3
            s4 = (mFzr + dr) * g4
            if not relax:
                F1, F2, F3, F4 = s1, s2, s3, s4
                Ff = s1 + s2
                Fr = s3 + s4
                S = Ff * cd + Fr
                ay = S / m
            # E1 then E2, E3
            sphi = sin(phi)
            cphi = cos(phi)
            phidd = (hr * S * cphi + mgch * sphi - Mroll) / Ix
            vyd = ay - gs - vx * r + hr * (phidd * cphi - phid * phid * sphi)
            rd = zf * Ff + zd * (F1 - F2) - zr * Fr
            if aux:
                af = -0.5 * (atan(q1) + atan(q2))
                ar = -0.5 * (atan(q3) + atan(q4))
                if aux == 1:
                    return (S, Ff * cd, Fr, af, ar, F1, F2, F3, F4)
                return {"S": S, "Fyf": Ff * cd, "Fyr": Fr, "alpha_f": af, "alpha_r": ar,
                        "F": (F1, F2, F3, F4),
                        "Fz": ((mFzf - df) / mu, (mFzf + df) / mu, (mFzr - dr) / mu, (mFzr + dr) / mu)}
            if relax:
                return (vyd, rd, phid, phidd, k * (s1 - F1), k * (s2 - F2), k * (s3 - F3), k * (s4 - F4))
            return (vyd, rd, phid, phidd, 0.0, 0.0, 0.0, 0.0)

        return f

    def _clamp_inputs(self, u, warn: bool):
        delta = float(u["delta"])
        vx = float(u["vx"])
        phir = float(u["bank_angle"])
        if (self.V_SLIP_MIN <= vx <= self.VX_MAX and -self.DELTA_MAX <= delta <= self.DELTA_MAX
                and -self.BANK_MAX <= phir <= self.BANK_MAX and not (warn and self._flags)):
            return delta, vx, phir   # the common case: nothing clamped, no warning state to reset

        def note(key, active, msg):
            if not warn:
                return
            if active:
                if key not in self._flags:
                    self._flags.add(key)
                    self.events.append(("warning", msg()))
            else:
                self._flags.discard(key)

        note("vx<0", vx < 0.0, lambda: f"CarPlant: vx = {vx} m/s < 0 clamped to 0 (forward driving only)")
        note("vx>max", vx > self.VX_MAX, lambda: f"CarPlant: vx = {vx} m/s clamped to {self.VX_MAX} m/s")
        vx = min(max(vx, 0.0), self.VX_MAX)
        note("vx<min", vx < self.V_SLIP_MIN,
             lambda: f"CarPlant: vx = {vx} m/s below {self.V_SLIP_MIN} m/s: slip angles and relaxation "
                     f"regularised (model meant for vx >= 5 m/s)")
        note("delta", abs(delta) > self.DELTA_MAX,
             lambda: f"CarPlant: |delta| = {abs(delta)} rad clamped to {self.DELTA_MAX} rad")
        delta = min(max(delta, -self.DELTA_MAX), self.DELTA_MAX)
        note("bank", abs(phir) > self.BANK_MAX,
             lambda: f"CarPlant: |bank_angle| = {abs(phir)} rad clamped to {self.BANK_MAX} rad")
        phir = min(max(phir, -self.BANK_MAX), self.BANK_MAX)
        return delta, vx, phir

    def _clamp_scales(self, u, warn: bool):
        """The stiffness_scale_f/r inputs of ``u`` (1.0 if absent), clamped to [SCALE_IN_MIN,
        SCALE_IN_MAX]; a non-finite value holds the last valid one (docs/runtime/car_plant.md)."""
        get = u.get
        out = []
        lo, hi = self.SCALE_IN_MIN, self.SCALE_IN_MAX
        for i, key in enumerate(("stiffness_scale_f", "stiffness_scale_r")):
            try:
                x = float(get(key, self.OPTIONAL_INPUTS[key]))
            except (TypeError, ValueError):
                x = math.nan
            if lo <= x <= hi:          # the common case (False for nan)
                if warn and self._flags:
                    self._flags.discard(key)
                    self._flags.discard(key + "_nf")
                out.append(x)
                continue
            if not math.isfinite(x):
                held = self._scales[i]
                if warn and key + "_nf" not in self._flags:
                    self._flags.add(key + "_nf")
                    self.events.append(("warning", f"CarPlant: {key} = {x!r} is not finite: held at {held}"))
                out.append(held)
                continue
            c = lo if x < lo else hi
            if warn:
                self._flags.discard(key + "_nf")
                if key not in self._flags:
                    self._flags.add(key)
                    self.events.append(("warning", f"CarPlant: {key} = {x} clamped to {c} "
                                                   f"(allowed {lo} ... {hi})"))
            out.append(c)
        return out[0], out[1]

    # ------------------------------------------------------------------ public API
    def derivatives(self, x, u, ax: float = 0.0) -> list:
        """State derivative d/dt [vy, r, phi, phidot, Fy_fl, Fy_fr, Fy_rl, Fy_rr] (SI units).

        ``x`` has 8 entries (or 4 with algebraic tires, sigma <= 0: the tire entries are then
        ignored and their derivatives are 0); ``u`` = {delta, vx, bank_angle} and optionally
        stiffness_scale_f, stiffness_scale_r (default 1.0); ``ax`` (m/s^2) the longitudinal
        acceleration used for the load transfer. Inputs are clamped as in ``step`` (silently; a
        non-finite stiffness scale takes the last valid one of ``step``). For finite inputs a pure
        function of its arguments.
        """
        delta, vx, phir = self._clamp_inputs(u, warn=False)
        sf, sr = self._clamp_scales(u, warn=False)
        ax = min(max(float(ax), -self.AX_MAX), self.AX_MAX)
        xs = list(x) + [0.0] * (8 - len(x))
        d = self._make_rhs(delta, vx, phir, ax, sf, sr)(*xs[:8])
        return list(d[:len(x)]) if len(x) == 4 else list(d)

    def tire_state(self, x=None, u=None, ax: float = 0.0) -> dict:
        """Diagnostics at state ``x`` (default: current) and inputs ``u`` (default: last step's):
        total force S, wheel forces F (wheel frame) and loads Fz (fl, fr, rl, rr), slip angles."""
        if u is None:
            delta, vx, phir, ax = self._last_u
            sf, sr = self._scales
        else:
            delta, vx, phir = self._clamp_inputs(u, warn=False)
            sf, sr = self._clamp_scales(u, warn=False)
            ax = min(max(float(ax), -self.AX_MAX), self.AX_MAX)
        xs = list(self.x if x is None else x)
        xs += [0.0] * (8 - len(xs))
        return self._make_rhs(delta, vx, phir, ax, sf, sr)(*xs[:8], aux=2)

    @property
    def ax(self) -> float:
        """Longitudinal acceleration (m/s^2) used by the last ``step`` (vx finite difference)."""
        return self._last_u[3]

    def step(self, h: float, u: dict) -> None:
        """Advance ``h`` seconds with inputs ``u`` (delta, vx, bank_angle and optionally
        stiffness_scale_f, stiffness_scale_r, default 1.0) held; Heun's method, <= 1 ms substeps
        (docs/runtime/car_plant.md, "Numerics")."""
        h = float(h)
        delta, vx, phir = self._clamp_inputs(u, warn=True)
        sf, sr = self._clamp_scales(u, warn=True)
        if not h > 0.0:
            if h < 0.0:
                self.events.append(("warning", f"CarPlant: step size h = {h} s < 0 ignored"))
            return
        # E5: ax from consecutive vx inputs
        ax = 0.0 if self._vx_prev is None else (vx - self._vx_prev) / h
        if ax > self.AX_MAX or ax < -self.AX_MAX:
            if "ax" not in self._flags:
                self._flags.add("ax")
                self.events.append(("warning", f"CarPlant: longitudinal acceleration {ax:.4g} m/s^2 "
                                               f"(from vx inputs) clamped to +-{self.AX_MAX}"))
            ax = min(max(ax, -self.AX_MAX), self.AX_MAX)
        elif self._flags:
            self._flags.discard("ax")
        self._vx_prev = vx
        self._last_u = (delta, vx, phir, ax)
        self._scales = (sf, sr)

        # substeps: <= H_MAX, and fastest-mode estimate * substep <= 1
        # the tire-stiffness part of the estimate grows linearly (algebraic) or as the square
        # root (relaxation oscillation) with the stiffness; scales < 1 keep the nominal estimate
        smax = sf if sf > sr else sr
        if self._relax:
            vrel = vx if vx > self.V_RELAX_MIN else self.V_RELAX_MIN
            osc = self._lam_osc_s * math.sqrt(smax) if smax > 1.0 else self._lam_osc_s
            lam = vrel / self._sigma + osc + self._lam_roll
        else:
            vs = vx if vx > self.V_SLIP_MIN else self.V_SLIP_MIN
            alg = self._lam_alg * smax if smax > 1.0 else self._lam_alg
            lam = alg / vs + self._lam_roll
        n = max(math.ceil(h / self.H_MAX - 1e-9), math.ceil(h * lam - 1e-9), 1)
        dt = h / n
        f = self._make_rhs(delta, vx, phir, ax, sf, sr)
        s0, s1, s2, s3, s4, s5, s6, s7 = self.x
        # Heun's method (explicit trapezoidal rule, 2nd order): k1 = f(s), k2 = f(s + dt k1),
        # s+ = s + dt/2 (k1 + k2)
        hd = 0.5 * dt
        if self._relax:
            for _ in range(n):
                a0, a1, a2, a3, a4, a5, a6, a7 = f(s0, s1, s2, s3, s4, s5, s6, s7)
                b0, b1, b2, b3, b4, b5, b6, b7 = f(s0 + dt * a0, s1 + dt * a1, s2 + dt * a2, s3 + dt * a3,
                                                   s4 + dt * a4, s5 + dt * a5, s6 + dt * a6, s7 + dt * a7)
                s0 += hd * (a0 + b0)
                s1 += hd * (a1 + b1)
                s2 += hd * (a2 + b2)
                s3 += hd * (a3 + b3)
                s4 += hd * (a4 + b4)
                s5 += hd * (a5 + b5)
                s6 += hd * (a6 + b6)
                s7 += hd * (a7 + b7)
        else:  # algebraic tires: only the 4 body states are integrated (f ignores s4..s7)
            for _ in range(n):
                a0, a1, a2, a3, _a, _b, _c, _d = f(s0, s1, s2, s3, s4, s5, s6, s7)
                b0, b1, b2, b3, _a, _b, _c, _d = f(s0 + dt * a0, s1 + dt * a1, s2 + dt * a2, s3 + dt * a3,
                                                   s4, s5, s6, s7)
                s0 += hd * (a0 + b0)
                s1 += hd * (a1 + b1)
                s2 += hd * (a2 + b2)
                s3 += hd * (a3 + b3)
        # all finite <=> the sum of the states times 0 is 0 (inf * 0 and nan * 0 are nan)
        if (s0 * 0.0 + s1 * 0.0 + s2 * 0.0 + s3 * 0.0 + s4 * 0.0 + s5 * 0.0 + s6 * 0.0 + s7 * 0.0) != 0.0:
            self.events.append(("error", "CarPlant: state became non-finite; step undone"))
        else:
            self.x = [s0, s1, s2, s3, s4, s5, s6, s7]
        self._update_outputs(f)

    def _update_outputs(self, f=None) -> None:
        """Outputs at the current state and the last inputs; ``f``: the ``_make_rhs`` of those
        inputs if the caller has it."""
        x = self.x
        vx = self._last_u[1]
        if f is None:
            f = self._make_rhs(*self._last_u, *self._scales)
        S, Fyf, Fyr, af, ar, F1, F2, F3, F4 = f(*x, aux=1)
        if not self._relax:
            x[4] = F1   # algebraic tires: report the current forces as states
            x[5] = F2
            x[6] = F3
            x[7] = F4
        vs = vx if vx > self.V_SLIP_MIN else self.V_SLIP_MIN
        y = self.y
        y["beta"] = _atan(x[0] / vs)
        y["vy"] = x[0]
        y["yaw_rate"] = x[1]
        y["ay"] = S / self._m
        y["roll_angle"] = x[2]
        y["roll_rate"] = x[3]
        y["Fyf"] = Fyf
        y["Fyr"] = Fyr
        y["alpha_f"] = af
        y["alpha_r"] = ar
        vy_cg = x[0] - self._hr * x[3] * _cos(x[2])   # CG lateral velocity (docs/runtime/car_plant.md)
        y["vy_cg"] = vy_cg
        y["beta_cg"] = _atan(vy_cg / vs)
        if ar > self.ALPHA_SPIN or ar < -self.ALPHA_SPIN:
            if "spin" not in self._flags:
                self._flags.add("spin")
                self.events.append(("warning", f"CarPlant: |alpha_r| = {abs(ar):.3g} rad > {self.ALPHA_SPIN} rad: "
                                               f"the car has spun out; with prescribed vx the model is not valid "
                                               f"beyond this (the body keeps sliding sideways)"))
        elif self._flags:
            self._flags.discard("spin")
