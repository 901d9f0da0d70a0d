"""Nonlinear motorcycle plant: Sharp's (1971) lateral model with Magic Formula tyres (paper 003).

Standard library only; runs inside the FMU (``framework.py`` drives it). Equations, states,
clamps and numerics: docs/runtime/motorcycle_plant.md.
"""
from __future__ import annotations

import math

from .linalg import matrix, total
from .spec import runtime_parameters, tables_of

_atan = math.atan
_sin = math.sin

G = 9.81  # m/s^2; must equal latobs.synthesis.params.G (checked by the tests)
SCHEMA = "latobs.motorcycle_structure/1"


def _mat(obj, rows: int, cols: int, name: str) -> list:
    return matrix(obj, rows, cols, f"structure {name!r}", source="MotorcyclePlant")


def _vec(obj, n, name):
    return _mat([obj], 1, n, name)[0]


class MotorcyclePlantModel:
    """Sharp's motorcycle with Magic Formula tyres and relaxation (docs/runtime/motorcycle_plant.md).

    ``MotorcyclePlantModel(data, params)`` with ``data`` the plant data file
    (``latobs.packaging.plant_data`` of a motorcycle: ``{"vehicle": ..., "structure": ...}``) and
    ``params`` the FMU parameters (missing or None entries take their defaults):

    * ``mu``  (1)           peak friction coefficient, default 1.0.
    * ``sigma`` (m)         relaxation length of both tyres, default the vehicle's; 0: algebraic
                            tyres (paper 003's reduced model); 0 < sigma < SIGMA_MIN refused.
    * ``linear_tires`` (1)  1: Fs = C1 alpha + C2 gamma (no saturation, Gamma = 0); 0 (default):
                            Magic Formula.
    * ``mf_C`` (1)          Magic Formula shape factor C, 0 < C < 2 (default 1.3).
    * ``mf_E`` (1)          Magic Formula curvature factor E, -5 <= E <= 1 (default 0).
    """

    PARAMETERS = {"mu": 1.0, "sigma": 0.2438, "linear_tires": 0.0, "mf_C": 1.3, "mf_E": 0.0}
    INPUTS = {"rider_torque": ("N.m", "rider steering torque, > 0 turns the handlebar to the right"),
              "vx": ("m/s", "forward speed (prescribed)")}
    OUTPUTS = {"steer_angle": ("rad", "steering angle about the steering axis, > 0 steers right"),
               "steer_rate": ("rad/s", "steering rate"),
               "yaw_rate": ("rad/s", "yaw rate, > 0 turns right"),
               "roll_angle": ("rad", "roll (lean) angle, > 0 leans right"),
               "roll_rate": ("rad/s", "roll rate"),
               "vy": ("m/s", "lateral velocity of the ground point below the rear-frame mass centre (> 0 right)"),
               "Ff": ("N", "front tyre side force (> 0 to the right)"),
               "Fr": ("N", "rear tyre side force (> 0 to the right)"),
               "Gamma_f": ("N", "nonlinear part of the front static tyre force, Fs_f - (Cf1 alpha_f + Cf2 gamma_f)"),
               "Gamma_r": ("N", "nonlinear part of the rear static tyre force, Fs_r - (Cr1 alpha_r + Cr2 gamma_r)"),
               "alpha_f": ("rad", "front slip angle"),
               "alpha_r": ("rad", "rear slip angle")}
    STATE_NAMES = ("roll_angle", "steer_angle", "vy", "yaw_rate", "roll_rate", "steer_rate", "Ff", "Fr")

    H_MAX = 1e-3          # s, largest RK4 substep
    LAM_DT = 1.0          # largest lam_est * substep
    LAM_MECH = 80.0       # 1/s, mechanical part of lam_est (wobble ~ 58 rad/s)
    VX_MAX = 60.0         # m/s
    V_SLIP_MIN = 1.0      # m/s, floor of vx in the slip angles
    V_RELAX_MIN = 1.0     # m/s, floor of vx in the relaxation rate
    V_WARN = 1.0          # m/s, below: warning (model meant for vx >= 5 m/s)
    TAU_MAX = 200.0       # N m, clamp of the rider torque
    SIGMA_MIN = 0.01      # m, smallest relaxation length (0 = algebraic tyres)
    ROLL_WARN = 1.0       # rad, |roll| beyond which the motorcycle has fallen (warning)

    # ------------------------------------------------------------------ construction
    @staticmethod
    def _structure(data) -> dict:
        try:
            s = data["structure"]
        except (KeyError, TypeError) as exc:
            raise ValueError("MotorcyclePlant data must hold the derived 'structure' of a motorcycle vehicle "
                             "(latobs.packaging.plant_data of a vehicle of kind 'motorcycle')") from exc
        if not isinstance(s, dict) or s.get("schema") != SCHEMA:
            raise ValueError(f"MotorcyclePlant: structure schema must be {SCHEMA!r}")
        return s

    @classmethod
    def parameter_defaults(cls, data) -> dict:
        """The FMU parameter defaults for the data file (sigma from the vehicle)."""
        s = cls._structure(data)
        sig = float(s["tyres"]["front"]["sigma"])
        return {**cls.PARAMETERS, "sigma": sig}

    def __init__(self, data: dict, params: dict | None = None):
        s = self._structure(data)
        self.M = _mat(s["M"], 4, 4, "M")
        self.C0 = _mat(s["C0"], 4, 4, "C0")
        self.C1 = _mat(s["C1"], 4, 4, "C1")
        self.K = _mat(s["K_sin"], 4, 2, "K_sin")
        self.BF = _mat(s["B_F"], 4, 2, "B_F")
        self.Btau = _vec(s["B_tau"], 4, "B_tau")
        tyres = []
        for key in ("front", "rear"):
            t = s["tyres"][key]
            sl = _vec(t["slip_velocity"], 4, f"{key} slip_velocity")
            cb = _vec(t["camber"], 2, f"{key} camber")
            vals = {k: float(t[k]) for k in ("heading", "C1", "C2", "Fz", "sigma")}
            if not all(math.isfinite(v) for v in vals.values()) or not (vals["C1"] > 0 and vals["Fz"] > 0):
                raise ValueError(f"MotorcyclePlant: {key} tyre needs finite data with C1 > 0 and Fz > 0")
            tyres.append((sl, vals["heading"], cb, vals["C1"], vals["C2"], vals["Fz"], vals["sigma"]))
        self._tyres = tyres
        if abs(float(s.get("g", G)) - G) > 1e-12:
            raise ValueError(f"MotorcyclePlant: structure g = {s.get('g')} differs from the runtime's {G}")

        p = runtime_parameters("MotorcyclePlant", self.PARAMETERS, self.parameter_defaults(data), params)
        if not p["mu"] > 0:
            raise ValueError(f"MotorcyclePlant: parameter 'mu' must be > 0, got {p['mu']}")
        if not (p["sigma"] == 0.0 or p["sigma"] >= self.SIGMA_MIN):
            raise ValueError(f"MotorcyclePlant: parameter 'sigma' must be 0 (algebraic tyres) or >= "
                             f"{self.SIGMA_MIN} m, got {p['sigma']}")
        if p["linear_tires"] not in (0.0, 1.0):
            raise ValueError(f"MotorcyclePlant: parameter 'linear_tires' must be 0 or 1, got {p['linear_tires']}")
        if not 0.0 < p["mf_C"] < 2.0:
            raise ValueError(f"MotorcyclePlant: parameter 'mf_C' must be in (0, 2), got {p['mf_C']}")
        if not -5.0 <= p["mf_E"] <= 1.0:
            raise ValueError(f"MotorcyclePlant: parameter 'mf_E' must be in [-5, 1], got {p['mf_E']}")
        self.params = p
        self._relax = p["sigma"] > 0.0
        self._sigma = p["sigma"]
        self._linear = p["linear_tires"] == 1.0
        t = tables_of(data, "MotorcyclePlant")
        self._Minv = _mat(t.get("Minv"), 4, 4, "tables Minv")   # (E1) solved for du/dt
        self._kt = float(t.get("kt", math.nan))                  # the substep rule's tyre-spring bound
        if not (math.isfinite(self._kt) and self._kt >= 0):
            raise ValueError(f"MotorcyclePlant: tables kt must be finite and >= 0, got {self._kt}")
        # tyre constants: (slip velocity row, heading, camber row, C1, C2/C1, D, B, C, E)
        self._tc = []
        for sl, hd, cb, c1, c2, fz, _ in tyres:
            D = p["mu"] * fz
            self._tc.append((sl, hd, cb, c1, c2 / c1, D, c1 / (p["mf_C"] * D)))

        self.x = [0.0] * 8
        self.events: list = []
        self._flags: set = set()
        self._u = (0.0, 0.0)      # (tau, vx) of the last step (clamped)
        self._valid = {"rider_torque": 0.0, "vx": 0.0}
        self.y: dict = {}
        self._update_outputs()

    # ------------------------------------------------------------------ the physics
    def _make_rhs(self, tau: float, vx: float):
        """Right-hand side (E1)-(E4) for held, clamped inputs. ``f(x)`` -> 8 derivatives;
        ``f(x, aux=True)`` -> (Ff, Fr, Gamma_f, Gamma_r, alpha_f, alpha_r) used by the mechanics."""
        Mi = self._Minv
        D = [[self.C0[i][j] + vx * self.C1[i][j] for j in range(4)] for i in range(4)]
        # u' = Gu u + Gs [sin phi, sin delta] + GF [Ff, Fr] + g0
        Gu = [[-total(Mi[i][k] * D[k][j] for k in range(4)) for j in range(4)] for i in range(4)]
        Gs = [[-total(Mi[i][k] * self.K[k][j] for k in range(4)) for j in range(2)] for i in range(4)]
        GF = [[total(Mi[i][k] * self.BF[k][j] for k in range(4)) for j in range(2)] for i in range(4)]
        g0 = [total(Mi[i][k] * self.Btau[k] for k in range(4)) * tau for i in range(4)]
        ((u00, u01, u02, u03), (u10, u11, u12, u13), (u20, u21, u22, u23), (u30, u31, u32, u33)) = Gu
        ((s00, s01), (s10, s11), (s20, s21), (s30, s31)) = Gs
        ((f00, f01), (f10, f11), (f20, f21), (f30, f31)) = GF
        g00, g01, g02, g03 = g0
        vs = vx if vx > self.V_SLIP_MIN else self.V_SLIP_MIN
        ivs = 1.0 / vs
        vr = vx if vx > self.V_RELAX_MIN else self.V_RELAX_MIN
        k = vr / self._sigma if self._relax else 0.0
        (slf, hdf, cbf, C1f, kgf, Df, Bf), (slr, hdr, cbr, C1r, kgr, Dr, Br) = self._tc
        af0, af1, af2, af3 = (-c * ivs for c in slf)
        ar0, ar1, ar2, ar3 = (-c * ivs for c in slr)
        cf0, cf1 = cbf
        cr0, cr1 = cbr
        C = self.params["mf_C"]
        E = self.params["mf_E"]
        linear = self._linear
        relax = self._relax
        sin, atan = _sin, _atan

        def f(x, aux=False):
            phi, delta, vy, r, p, d, Ff, Fr = x
            # E2: slip and camber; x_eq = alpha + (C2/C1) gamma
            al_f = af0 * vy + af1 * r + af2 * p + af3 * d + hdf * delta
            al_r = ar0 * vy + ar1 * r + ar2 * p + ar3 * d + hdr * delta
            xf = al_f + kgf * (cf0 * phi + cf1 * delta)
            xr = al_r + kgr * (cr0 * phi + cr1 * delta)
            # E3: Magic Formula (or its linear part)
            if linear:
                Fsf = C1f * xf
                Fsr = C1r * xr
            else:
                b = Bf * xf
                Fsf = Df * sin(C * atan(b - E * (b - atan(b))))
                b = Br * xr
                Fsr = Dr * sin(C * atan(b - E * (b - atan(b))))
            if not relax:
                Ff, Fr = Fsf, Fsr
            if aux:
                return (Ff, Fr, Fsf - C1f * xf, Fsr - C1r * xr, al_f, al_r)
            sp = sin(phi)
            sd = sin(delta)
            # E1
            return (p, d,
                    u00 * vy + u01 * r + u02 * p + u03 * d + s00 * sp + s01 * sd + f00 * Ff + f01 * Fr + g00,
                    u10 * vy + u11 * r + u12 * p + u13 * d + s10 * sp + s11 * sd + f10 * Ff + f11 * Fr + g01,
                    u20 * vy + u21 * r + u22 * p + u23 * d + s20 * sp + s21 * sd + f20 * Ff + f21 * Fr + g02,
                    u30 * vy + u31 * r + u32 * p + u33 * d + s30 * sp + s31 * sd + f30 * Ff + f31 * Fr + g03,
                    k * (Fsf - Ff) if relax else 0.0,
                    k * (Fsr - Fr) if relax else 0.0)

        return f

    def lam_est(self, vx: float) -> float:
        """Upper estimate (1/s) of the spectral radius of the linearisation at speed vx (Numerics)."""
        vx = min(max(float(vx), 0.0), self.VX_MAX)
        if self._relax:
            vr = max(vx, self.V_RELAX_MIN)
            return vr / self._sigma + math.sqrt(self._kt / self._sigma) + self.LAM_MECH
        return self._kt / max(vx, self.V_SLIP_MIN) + self.LAM_MECH

    # ------------------------------------------------------------------ inputs
    def _note(self, key, active, msg):
        if active:
            if key not in self._flags:
                self._flags.add(key)
                self.events.append(("warning", msg()))
        else:
            self._flags.discard(key)

    def _clamp_inputs(self, u, warn: bool):
        out = []
        for name in ("rider_torque", "vx"):
            try:
                x = float(u[name])
            except (KeyError, TypeError, ValueError):
                x = math.nan
            if not math.isfinite(x):
                held = self._valid[name]
                if warn:
                    self._note(name + "_nf", True, lambda: f"MotorcyclePlant: input {name} = {u.get(name)!r} is "
                                                           f"not finite: its last valid value {held} is held")
                x = held
            else:
                if warn:
                    self._flags.discard(name + "_nf")
                    self._valid[name] = x
            out.append(x)
        tau, vx = out
        if not warn:
            return (min(max(tau, -self.TAU_MAX), self.TAU_MAX), min(max(vx, 0.0), self.VX_MAX))
        self._note("tau", abs(tau) > self.TAU_MAX,
                   lambda: f"MotorcyclePlant: |rider_torque| = {abs(tau)} N m clamped to {self.TAU_MAX} N m")
        tau = min(max(tau, -self.TAU_MAX), self.TAU_MAX)
        self._note("vx<0", vx < 0.0, lambda: f"MotorcyclePlant: vx = {vx} m/s < 0 clamped to 0 (forward only)")
        self._note("vx>max", vx > self.VX_MAX, lambda: f"MotorcyclePlant: vx = {vx} m/s clamped to {self.VX_MAX} m/s")
        vx = min(max(vx, 0.0), self.VX_MAX)
        self._note("vx<min", vx < self.V_WARN,
                   lambda: f"MotorcyclePlant: vx = {vx} m/s below {self.V_WARN} m/s: slip angles and relaxation "
                           f"use a {self.V_SLIP_MIN} m/s floor (model meant for vx >= 5 m/s)")
        return tau, vx

    # ------------------------------------------------------------------ public API
    def derivatives(self, x, u) -> list:
        """d/dt of the 8 states (STATE_NAMES order) at ``x`` for inputs ``u`` = {rider_torque, vx}
        (clamped as in ``step``, silently; a non-finite input takes its last valid value)."""
        tau, vx = self._clamp_inputs(u, warn=False)
        return list(self._make_rhs(tau, vx)([float(v) for v in x]))

    def tyre_state(self, x=None, u=None) -> dict:
        """Tyre quantities at state ``x`` (default: current) and inputs ``u`` (default: last step's):
        Ff, Fr (the forces acting), Gamma_f, Gamma_r, alpha_f, alpha_r."""
        tau, vx = self._u if u is None else self._clamp_inputs(u, warn=False)
        xs = [float(v) for v in (self.x if x is None else x)]
        Ff, Fr, Gf, Gr, af, ar = self._make_rhs(tau, vx)(xs, aux=True)
        return {"Ff": Ff, "Fr": Fr, "Gamma_f": Gf, "Gamma_r": Gr, "alpha_f": af, "alpha_r": ar}

    def initialize(self, u) -> None:
        """Inputs of the initialisation mode: the outputs at the start time use them."""
        self._u = self._clamp_inputs(u, warn=True)
        self._update_outputs()

    def step(self, h: float, u: dict) -> None:
        """Advance ``h`` seconds with ``u`` = {rider_torque, vx} held (RK4, see Numerics)."""
        h = float(h)
        tau, vx = self._clamp_inputs(u, warn=True)
        self._u = (tau, vx)
        if not h > 0.0 or not math.isfinite(h):
            if not h >= 0.0 or not math.isfinite(h):
                self.events.append(("warning", f"MotorcyclePlant: step size h = {h} s ignored"))
            self._update_outputs()
            return
        n = max(math.ceil(h / self.H_MAX - 1e-9), math.ceil(h * self.lam_est(vx) / self.LAM_DT - 1e-9), 1)
        dt = h / n
        f = self._make_rhs(tau, vx)
        s = list(self.x)
        h2 = 0.5 * dt
        h6 = dt / 6.0
        rng = range(8)
        for _ in range(n):
            k1 = f(s)
            k2 = f([s[i] + h2 * k1[i] for i in rng])
            k3 = f([s[i] + h2 * k2[i] for i in rng])
            k4 = f([s[i] + dt * k3[i] for i in rng])
            s = [s[i] + h6 * (k1[i] + 2.0 * (k2[i] + k3[i]) + k4[i]) for i in rng]
        if not all(math.isfinite(v) for v in s):
            self.events.append(("error", "MotorcyclePlant: state became non-finite; step undone"))
        else:
            self.x = s
        self._update_outputs(f)

    def _update_outputs(self, f=None) -> None:
        x = self.x
        if f is None:
            f = self._make_rhs(*self._u)
        Ff, Fr, Gf, Gr, af, ar = f(x, aux=True)
        if not self._relax:
            x[6], x[7] = Ff, Fr   # algebraic tyres: report the current forces as states
        y = self.y
        y["roll_angle"] = x[0]
        y["steer_angle"] = x[1]
        y["vy"] = x[2]
        y["yaw_rate"] = x[3]
        y["roll_rate"] = x[4]
        y["steer_rate"] = x[5]
        y["Ff"] = Ff
        y["Fr"] = Fr
        y["Gamma_f"] = Gf
        y["Gamma_r"] = Gr
        y["alpha_f"] = af
        y["alpha_r"] = ar
        self._note("fallen", abs(x[0]) > self.ROLL_WARN,
                   lambda: f"MotorcyclePlant: |roll_angle| = {abs(x[0]):.3g} rad > {self.ROLL_WARN} rad: the "
                           f"motorcycle has fallen over; results are outside the model's validity")
