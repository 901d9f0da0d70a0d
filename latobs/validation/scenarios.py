"""Validation manoeuvres: the input signals that drive a plant FMU.

A :class:`Scenario` gives, on any time grid ``t`` (s), the plant's input signals keyed by the
FMU variable name. For the car plant (``CarPlant``) these are

* ``delta``      road-wheel steering angle, rad, > 0 steers left,
* ``vx``         longitudinal speed, m/s,
* ``bank_angle`` road bank angle, rad (sign convention of ERRATA.md: it enters the sideslip
  equation as -g/Vx * bank_angle).

and, from :meth:`Scenario.parameter_signals`, time-varying plant parameters that the plant takes
as OPTIONAL inputs (:attr:`Scenario.optional_plant_inputs`; a scenario that does not provide one
leaves it at the FMU's start value):

* ``stiffness_scale_f``, ``stiffness_scale_r`` (1): CarPlant's front / rear cornering stiffness
  multipliers (start 1.0), used by the ``*-varying-stiffness`` scenarios of paper 002.

Angles are in rad and speeds in m/s everywhere; degrees and km/h appear only in names that say
so (``*_deg``, ``*_kmh``). Amplitudes that depend on the vehicle use the linear bicycle model of
the vehicle's parameters (m, lf, lr, Cf, Cr) as the standards do with a slowly increasing steer:

    steady-state lateral acceleration per rad of road-wheel steer
        G_ss(vx) = vx^2 / (L + K_us * vx^2)   [(m/s^2)/rad]
    with L = lf + lr (m) and the understeer gradient K_us = m/L * (lr/Cf - lf/Cr)  [rad/(m/s^2)].

All steering inputs are OPEN LOOP (no driver model, no path following): the manoeuvres
approximate the standards' steering traces, they do not track a course.
"""
from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from latobs.synthesis.params import G, Vehicle, VehicleParameterError, load_vehicle

KMH = 1.0 / 3.6  # m/s per km/h
MPH = 0.44704  # m/s per mph
DEG = math.pi / 180.0  # rad per degree

#: Paper 000's speed modes (km/h) and their scheduling bands [lo, hi) in km/h.
SPEED_MODES_KMH = (36.0, 63.0, 90.0)
SPEED_BANDS_KMH = ((22.5, 49.5), (49.5, 76.5), (76.5, 103.5))


# --------------------------------------------------------------------------------------------
# helpers
# --------------------------------------------------------------------------------------------
def _vehicle(vehicle: Vehicle | str) -> Vehicle:
    return load_vehicle(vehicle) if isinstance(vehicle, str) else vehicle


def understeer_gradient(vehicle: Vehicle | str) -> float:
    """Understeer gradient K_us = m/L * (lr/Cf - lf/Cr) of the linear bicycle model, rad/(m/s^2)."""
    v = _vehicle(vehicle)
    p = v.require(["m", "lf", "lr", "Cf", "Cr"], "the linear bicycle model of the validation scenarios")
    L = p["lf"] + p["lr"]
    return p["m"] / L * (p["lr"] / p["Cf"] - p["lf"] / p["Cr"])


def steady_state_ay_gain(vehicle: Vehicle | str, vx_mps: float) -> float:
    """Steady-state lateral acceleration per rad of road-wheel steer, (m/s^2)/rad, at vx (m/s)."""
    v = _vehicle(vehicle)
    p = v.require(["lf", "lr"], "the linear bicycle model of the validation scenarios")
    L = p["lf"] + p["lr"]
    k = understeer_gradient(v)
    den = L + k * vx_mps**2
    if den <= 0:
        raise ValueError(
            f"vehicle {v.name!r} is beyond its critical speed at {vx_mps:.2f} m/s "
            f"(L + K_us*vx^2 = {den:.3g} <= 0): no steady-state steer exists"
        )
    return vx_mps**2 / den


def steer_for_ay(vehicle: Vehicle | str, vx_mps: float, ay_mps2: float) -> float:
    """Road-wheel angle (rad) giving a steady-state lateral acceleration ay (m/s^2) at vx (m/s)."""
    return ay_mps2 / steady_state_ay_gain(vehicle, vx_mps)


#: CarPlant parameters its flat-road steady state depends on (the inertias, the roll damping and
#: the relaxation length do not enter a steady state)
_CARPLANT_STEADY = ("m", "lf", "lr", "hr", "Kr", "Cf", "Cr", "track", "h_rc", "roll_share_f",
                    "mf_C", "mf_E", "mu")
_CARPLANT_V_SLIP_MIN = 1.0  # m/s, CarPlant's floor of the wheel's longitudinal velocity (E4)


def carplant_steady_turn(vehicle: Vehicle | str, vx_mps: float, ay_mps2: float) -> dict[str, Any]:
    """Steady turn of the NONLINEAR CarPlant on a flat road: the road-wheel angle (rad) that holds
    its output ``ay`` (sum of the tire forces / m) at ``ay_mps2`` (m/s^2) at the constant speed
    ``vx_mps`` (m/s), with the plant's default parameters for the vehicle (mu = the vehicle's mu,
    stiffness scales 1, Magic Formula tires, relaxation length = the vehicle's sigma > 0: in the
    steady state the relaxed forces see the exact ay = S/m in the load transfer; with algebraic
    tires, sigma <= 0, the plant's one-pass load-transfer loop shifts ay slightly).

    The validation stage never imports the plant's runtime (package docstring): this solves the
    algebraic steady state of the equations DOCUMENTED in ``fmu_src/car_plant.py`` (E1-E6, flat
    road, ax = 0, forces at their relaxed values) on its own; tests/test_vehicles_000.py holds it
    against the runtime. In a steady turn vy' = r' = phi' = phi'' = 0, so E2 gives
    ay = S/m = vx r: the yaw rate is r = ay/vx. E1 (roll, S = m ay) is solved for phi by Newton;
    then two equations remain, S(vy, delta) = m ay and the yaw moment Mz(vy, delta) = 0, solved
    by Newton with a central-difference Jacobian from the linear bicycle's steady state. The
    two-track slip angles (E4), the lateral load transfer with the roll moment Kr phi (E5) and
    the Magic Formula (E6, B per axle from the static wheel load) are those of the plant.

    Returns {delta, vy, beta, yaw_rate, roll_angle, ay, alpha_f, alpha_r, Fyf, Fyr, iterations}
    (SI units; beta = atan(vy/vx) at the roll axis, alpha_* the axle means as the plant reports
    them). Raises ValueError when no steady turn exists (ay beyond the tires' grip). Cached per
    (parameter values, vx, ay): deterministic, computed once.
    """
    v = _vehicle(vehicle)
    p = v.require(_CARPLANT_STEADY, "the CarPlant steady-turn calibration of the validation scenarios")
    if not (math.isfinite(vx_mps) and vx_mps > _CARPLANT_V_SLIP_MIN):
        raise ValueError(f"a steady turn needs a speed > {_CARPLANT_V_SLIP_MIN} m/s, got {vx_mps}")
    if not math.isfinite(ay_mps2):
        raise ValueError(f"a steady turn needs a finite lateral acceleration, got {ay_mps2}")
    key = tuple(float(p[k]) for k in _CARPLANT_STEADY)
    return dict(_carplant_steady_turn(key, float(vx_mps), float(ay_mps2)))


@functools.lru_cache(maxsize=256)
def _carplant_steady_turn(key: tuple[float, ...], vx: float, ay: float) -> dict[str, Any]:
    m, lf, lr, hr, Kr, Cf, Cr, track, h_rc, share_f, C, E, mu = key
    L = lf + lr
    t2 = 0.5 * track
    Wf = m * G * lr / (2.0 * L)          # static wheel loads (N), flat road
    Wr = m * G * lf / (2.0 * L)
    Bf = Cf / (2.0 * mu * Wf * C)        # E6: mu Fz_static B C = C_axle / 2
    Br = Cr / (2.0 * mu * Wr * C)
    r = ay / vx
    S_target = m * ay
    # E1 with phi'' = phidot = 0 and S = m ay: hr S cos(phi) + m g hr sin(phi) - Kr phi = 0
    phi = hr * S_target / (Kr - m * G * hr)
    for _ in range(50):
        g = hr * S_target * math.cos(phi) + m * G * hr * math.sin(phi) - Kr * phi
        dg = -hr * S_target * math.sin(phi) + m * G * hr * math.cos(phi) - Kr
        step = g / dg
        phi -= step
        if abs(step) < 1e-15:
            break
    # E5: lateral load transfer with ay_eff = S/m = ay (relaxed forces), clamped to the axle load
    Mroll = Kr * phi

    def clamp(x, lim):
        return min(max(x, -lim), lim)

    df = clamp(mu * ((m * lr / L * h_rc / track) * ay + share_f / track * Mroll), mu * Wf)
    dr = clamp(mu * ((m * lf / L * h_rc / track) * ay + (1.0 - share_f) / track * Mroll), mu * Wr)
    loads = (mu * Wf - df, mu * Wf + df, mu * Wr - dr, mu * Wr + dr)   # mu Fz of fl, fr, rl, rr

    def mf(alpha, B):
        x = B * alpha
        return math.sin(C * math.atan(x - E * (x - math.atan(x))))

    def wheel_alpha(u_body, v_body, steer):
        # E4: along / across the wheel, the along component floored at V_SLIP_MIN
        u = u_body * math.cos(steer) + v_body * math.sin(steer)
        w = v_body * math.cos(steer) - u_body * math.sin(steer)
        return -math.atan(w / max(u, _CARPLANT_V_SLIP_MIN))

    def forces(vy, delta):
        vf, vr = vy + r * lf, vy - r * lr
        a = (wheel_alpha(vx - r * t2, vf, delta), wheel_alpha(vx + r * t2, vf, delta),
             wheel_alpha(vx - r * t2, vr, 0.0), wheel_alpha(vx + r * t2, vr, 0.0))
        F = [loads[i] * mf(a[i], Bf if i < 2 else Br) for i in range(4)]
        cd, sd = math.cos(delta), math.sin(delta)
        S = (F[0] + F[1]) * cd + F[2] + F[3]
        Mz = lf * cd * (F[0] + F[1]) + t2 * sd * (F[0] - F[1]) - lr * (F[2] + F[3])
        return S, Mz, a, F

    def residual(z):
        S, Mz, _, _ = forces(z[0], z[1])
        return np.array([(S - S_target) / (m * G), Mz / (m * G * L)])

    # start: the linear bicycle's steady state (rear axle: Cr (lr r / vx - beta) = m ay lf / L)
    k_us = m / L * (lr / Cf - lf / Cr)
    z = np.array([vx * (lr * r / vx - m * ay * lf / (L * Cr)), ay * (L + k_us * vx**2) / vx**2])
    iterations = 0
    res = residual(z)
    for iterations in range(1, 60):
        J = np.empty((2, 2))
        for j, h in enumerate((1e-6 * max(vx, 1.0), 1e-7)):
            e = np.zeros(2)
            e[j] = h
            J[:, j] = (residual(z + e) - residual(z - e)) / (2 * h)
        dz = np.linalg.solve(J, -res)
        lam = 1.0
        while True:   # damped Newton: never accept a step that makes the residual larger
            trial = residual(z + lam * dz)
            if np.max(np.abs(trial)) < np.max(np.abs(res)) or lam < 1e-6:
                break
            lam *= 0.5
        z = z + lam * dz
        res = trial
        if np.max(np.abs(res)) < 1e-14:
            break
    S, Mz, a, F = forces(z[0], z[1])
    if not (np.all(np.isfinite(z)) and abs(S - S_target) <= 1e-9 * m * G and abs(Mz) <= 1e-9 * m * G * L):
        raise ValueError(f"CarPlant has no steady turn at vx = {vx} m/s, ay = {ay} m/s^2 "
                         f"(residual S - m ay = {S - S_target:.3g} N, Mz = {Mz:.3g} N m): beyond the tires' grip?")
    cd = math.cos(z[1])
    return {"delta": float(z[1]), "vy": float(z[0]), "beta": math.atan(z[0] / vx), "yaw_rate": r,
            "roll_angle": phi, "ay": S / m, "alpha_f": 0.5 * (a[0] + a[1]), "alpha_r": 0.5 * (a[2] + a[3]),
            "Fyf": (F[0] + F[1]) * cd, "Fyr": F[2] + F[3], "iterations": iterations}


def _cosine_blend(x: np.ndarray) -> np.ndarray:
    """0 for x <= 0, 1 for x >= 1, (1 - cos(pi x))/2 in between (C1-smooth step)."""
    x = np.clip(x, 0.0, 1.0)
    return 0.5 * (1.0 - np.cos(np.pi * x))


def _piecewise_linear(t: np.ndarray, knots: list[tuple[float, float]]) -> np.ndarray:
    """Linear interpolation through (time s, value) knots; a repeated time makes a step
    (the later value applies from that time on). Constant outside the knots."""
    out = np.full_like(t, knots[0][1], dtype=float)
    for (t0, y0), (t1, y1) in zip(knots[:-1], knots[1:]):
        if t1 == t0:
            out = np.where(t >= t1, y1, out)
        else:
            seg = (t >= t0) & (t <= t1)
            out = np.where(seg, y0 + (y1 - y0) * (t - t0) / (t1 - t0), out)
            out = np.where(t > t1, y1, out)
    return out


# --------------------------------------------------------------------------------------------
# Scenario base class
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Scenario:
    """One manoeuvre.

    name         registry key (``latobs validate NAME``)
    description  one-paragraph explanation (what, why, what is approximated)
    duration     total simulated time, s
    plant        the plant FMU the scenario drives ("CarPlant")
    settle_time  time (s) from which the "after settle" metrics are computed
    """

    name: str = ""
    description: str = ""
    duration: float = 10.0
    plant: str = "CarPlant"
    settle_time: float = 3.0

    #: names of the signals :meth:`signals` returns (plant input names)
    signal_names: tuple[str, ...] = field(default=("delta", "vx", "bank_angle"), repr=False)

    #: plant inputs that may stay at the plant FMU's declared start value when the scenario does
    #: not provide them (the harness leaves them untouched); every other plant input must be a
    #: scenario signal. CarPlant's stiffness multipliers (start 1.0 = the nominal plant).
    optional_plant_inputs: ClassVar[tuple[str, ...]] = ("stiffness_scale_f", "stiffness_scale_r")

    def signals(self, t: np.ndarray, vehicle: Vehicle | str = "sedan") -> dict[str, np.ndarray]:
        """Plant input signals on the time grid t (s): {FMU variable name: array}, SI units."""
        raise NotImplementedError

    def parameter_signals(self, t: np.ndarray, vehicle: Vehicle | str = "sedan") -> dict[str, np.ndarray]:
        """Time-varying plant parameters driven through optional plant inputs (e.g. CarPlant's
        ``stiffness_scale_f``/``_r``), on the time grid t (s): {FMU variable name: array}. The
        harness puts them on the bus beside :meth:`signals`. Default: none."""
        return {}

    def sampled(self, t: np.ndarray, vehicle: Vehicle | str = "sedan") -> dict[str, np.ndarray]:
        """:meth:`signals` and :meth:`parameter_signals` on the grid t, as float arrays; raises
        ValueError naming the signal when both give it, or when one is not a finite array on t."""
        sig = {k: np.asarray(v, dtype=float) for k, v in self.signals(t, vehicle).items()}
        extra = {k: np.asarray(v, dtype=float) for k, v in self.parameter_signals(t, vehicle).items()}
        clash = sorted(set(extra) & set(sig))
        if clash:
            raise ValueError(f"scenario {self.name!r}: signal(s) {', '.join(clash)} given by both signals() and "
                             "parameter_signals()")
        sig.update(extra)
        for k, v in sig.items():
            if v.shape != t.shape:
                raise ValueError(f"scenario {self.name!r}: signal {k!r} has shape {v.shape}, expected {t.shape}")
            if not np.all(np.isfinite(v)):
                raise ValueError(f"scenario {self.name!r}: signal {k!r} is not finite everywhere")
        return sig

    def time_grid(self, dt: float) -> np.ndarray:
        """Communication points 0, dt, ..., duration (s); duration is rounded to whole steps."""
        if not dt > 0:
            raise ValueError(f"communication step must be > 0 s, got {dt}")
        n = int(round(self.duration / dt))
        if n < 1:
            raise ValueError(f"scenario {self.name!r}: duration {self.duration} s is shorter than one step {dt} s")
        return np.arange(n + 1) * dt

    def info(self, vehicle: Vehicle | str = "sedan") -> dict[str, Any]:
        """JSON-serialisable summary: the fields and the derived amplitudes (SI units)."""
        d = {"name": self.name, "description": self.description, "duration_s": self.duration,
             "plant": self.plant, "settle_time_s": self.settle_time}
        d.update(self._derived(_vehicle(vehicle)))
        return d

    def _derived(self, vehicle: Vehicle) -> dict[str, Any]:
        return {}


# --------------------------------------------------------------------------------------------
# bank-braking (paper 000)
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class BankBraking(Scenario):
    """Paper 000: braking from 90 to 36 km/h on a road whose bank steps and ramps.

    Speed: ``v_start`` (m/s) for ``t_brake`` s, then a deceleration whose magnitude is blended in
    and out with a half-cosine of ``blend`` s and is ``decel`` (m/s^2) in between, down to
    ``v_end`` (m/s), held to the end. The speed crosses all three 000 speed-mode bands
    (SPEED_BANDS_KMH). Bank (deg in the knots, rad in the signal): 0, step to +2 deg at 2 s, ramp to
    +5 deg over 8-12 s, hold, step to -2 deg at 18 s, hold, ramp to 0 over 22-26 s.
    Steering: ``steer_amplitude`` (rad) road-wheel sine at ``steer_freq`` (Hz) to excite yaw/roll.
    """

    name: str = "bank-braking"
    description: str = (
        "Paper 000: braking from 90 km/h to 36 km/h (speed falls through the 36/63/90 km/h speed "
        "modes) on a road whose bank angle steps and ramps between -2 and +5 deg, with a gentle "
        "1 deg 0.2 Hz road-wheel sine to excite yaw and roll. Open-loop steering."
    )
    duration: float = 30.0
    settle_time: float = 3.0
    v_start: float = 90.0 * KMH  # m/s
    v_end: float = 36.0 * KMH  # m/s
    t_brake: float = 4.0  # s, braking starts
    decel: float = 0.75  # m/s^2, plateau deceleration
    blend: float = 1.0  # s, half-cosine blend at each end of the deceleration
    steer_amplitude: float = 1.0 * DEG  # rad
    steer_freq: float = 0.2  # Hz
    bank_knots_deg: tuple[tuple[float, float], ...] = (
        (0.0, 0.0), (2.0, 0.0), (2.0, 2.0), (8.0, 2.0), (12.0, 5.0), (18.0, 5.0), (18.0, -2.0),
        (22.0, -2.0), (26.0, 0.0),
    )  # (time s, bank deg)

    def __post_init__(self):
        if not (self.decel > 0 and self.blend >= 0 and self.v_start > self.v_end > 0):
            raise ValueError("bank-braking needs decel > 0, blend >= 0 and v_start > v_end > 0")
        if (self.v_start - self.v_end) / self.decel < self.blend:
            raise ValueError("bank-braking: the blends are longer than the deceleration; lower blend or decel")

    @property
    def t_brake_end(self) -> float:
        """End of the deceleration, s: the speed drop is decel * (T - blend)."""
        return self.t_brake + (self.v_start - self.v_end) / self.decel + self.blend

    def _speed(self, t: np.ndarray) -> np.ndarray:
        # a(t) = -decel * w(t), w = blend-in, 1, blend-out; v = v_start + integral (closed form)
        T = self.t_brake_end - self.t_brake
        b = self.blend
        s = np.clip(t - self.t_brake, 0.0, T)
        if b > 0:
            # integral of the weight: int_0^s w
            def ramp_int(x):  # int_0^x (1 - cos(pi u/b))/2 du, x in [0, b]
                return 0.5 * (x - b / math.pi * np.sin(np.pi * x / b))

            w_int = np.where(
                s <= b, ramp_int(np.minimum(s, b)),
                np.where(s <= T - b, b / 2 + (s - b),
                         b / 2 + (T - 2 * b) + (b / 2 - ramp_int(np.clip(T - s, 0.0, b)))),
            )
        else:
            w_int = s
        return self.v_start - self.decel * w_int

    def signals(self, t, vehicle="sedan"):
        t = np.asarray(t, dtype=float)
        bank = _piecewise_linear(t, list(self.bank_knots_deg)) * DEG
        return {
            "delta": self.steer_amplitude * np.sin(2 * np.pi * self.steer_freq * t),
            "vx": self._speed(t),
            "bank_angle": bank,
        }

    def _derived(self, vehicle):
        return {"v_start_mps": self.v_start, "v_end_mps": self.v_end, "decel_mps2": self.decel,
                "braking_s": [self.t_brake, self.t_brake_end], "steer_amplitude_rad": self.steer_amplitude,
                "speed_bands_kmh": [list(b) for b in SPEED_BANDS_KMH]}


# --------------------------------------------------------------------------------------------
# steady turn on a flat road (paper 000, issue 9: the bank estimate must not see the turn)
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class SteadyTurn(Scenario):
    """A steady turn on a FLAT road (bank 0) at constant speed: what a bank estimator must not
    mistake for a bank (paper 000, issue 9).

    Speed ``speed`` (m/s, default 50 km/h) throughout. Road-wheel steer: 0 for ``t_start`` s, a
    cosine blend (C1-smooth, :func:`_cosine_blend`) over ``ramp`` s to the angle delta_ss, held to
    the end. delta_ss is the angle at which the NONLINEAR CarPlant of the vehicle (its default
    parameters: Magic Formula tires, the vehicle's mu) settles at the lateral acceleration
    ``ay_g`` x g (output ``ay`` = sum of the tire forces / m; > 0 turns left): the algebraic
    steady state of the plant's equations (:func:`carplant_steady_turn`), not the linear
    bicycle's angle (:func:`steer_for_ay`, ~0.2 % smaller at 0.19 g; both in :meth:`info`).
    The settle time leaves the last ``duration - settle_time`` = 10 s for the "after settle"
    metrics (CarPlant's ay and roll angle are within 0.1 % of the steady state < 1 s after the
    end of the ramp for sedan, compact and suv; the observers get 12 s). Open loop.

    Calibration figures at 50 km/h, 0.19 g (tests/test_vehicles_000.py): steer 0.032627 rad
    (sedan), 0.029633 rad (compact), 0.032086 rad (suv); the CarPlant FMU settles at
    ay = 1.8639 m/s^2 to 1e-9. The linear bicycle's angles (0.2 % smaller) would give 0.1896 g.
    """

    name: str = "steady-turn"
    description: str = (
        "Paper 000: steady left turn on a flat road (bank 0) at 50 km/h: straight 1 s, road-wheel "
        "steer blended in (cosine, 2 s) to the angle holding 0.19 g on the nonlinear CarPlant, held to 25 s; "
        "metrics over the last 10 s. A bank estimate should stay at 0. Open loop."
    )
    duration: float = 25.0
    settle_time: float = 15.0
    speed: float = 50.0 * KMH  # m/s
    ay_g: float = 0.19  # 1, steady lateral acceleration in units of g (> 0: left turn)
    t_start: float = 1.0  # s, steering starts
    ramp: float = 2.0  # s, cosine blend to the steady angle

    def __post_init__(self):
        if not (math.isfinite(self.speed) and self.speed > 1.0):
            raise ValueError(f"steady-turn needs a speed > 1 m/s, got {self.speed}")
        if not math.isfinite(self.ay_g):
            raise ValueError(f"steady-turn needs a finite ay_g, got {self.ay_g}")
        if not (self.t_start >= 0 and self.ramp >= 0 and math.isfinite(self.t_start + self.ramp)):
            raise ValueError("steady-turn needs t_start >= 0 s and ramp >= 0 s")
        if not self.t_start + self.ramp <= self.settle_time <= self.duration:
            raise ValueError("steady-turn needs t_start + ramp <= settle_time <= duration")

    @property
    def ay_target(self) -> float:
        """Steady lateral acceleration, m/s^2."""
        return self.ay_g * G

    def steady_state(self, vehicle) -> dict[str, Any]:
        """CarPlant's steady turn at this speed and ay (:func:`carplant_steady_turn`), SI units."""
        return carplant_steady_turn(vehicle, self.speed, self.ay_target)

    def steer(self, vehicle) -> float:
        """Road-wheel angle held in the turn, rad."""
        return self.steady_state(vehicle)["delta"]

    def signals(self, t, vehicle="sedan"):
        t = np.asarray(t, dtype=float)
        d = self.steer(vehicle)
        if self.ramp > 0:
            w = _cosine_blend((t - self.t_start) / self.ramp)
        else:
            w = (t >= self.t_start).astype(float)
        return {"delta": d * w, "vx": np.full_like(t, self.speed), "bank_angle": np.zeros_like(t)}

    def _derived(self, vehicle):
        ss = self.steady_state(vehicle)
        return {"speed_mps": self.speed, "ay_target_mps2": self.ay_target, "ay_g": self.ay_g,
                "steer_rad": ss["delta"], "steer_linear_bicycle_rad": steer_for_ay(vehicle, self.speed, self.ay_target),
                "steer_calibration": "steady state of the nonlinear CarPlant (default parameters) at ay_target",
                "steady_state": {k: ss[k] for k in ("yaw_rate", "beta", "roll_angle", "alpha_f", "alpha_r", "ay")},
                "steer_ramp_s": [self.t_start, self.t_start + self.ramp], "bank_angle_rad": 0.0,
                "open_loop": True}


# --------------------------------------------------------------------------------------------
# double lane change (ISO 3888-2 like)
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class DoubleLaneChange(Scenario):
    """ISO 3888-2-like double lane change at constant speed, OPEN LOOP (no driver model).

    Road-wheel steer: ``t_start`` s straight, a full sine +A*sin(2 pi (t - t_start)/T) (left lane
    change), a straight section of ``straight_length`` m (ISO 3888-2 section 3: 11 m), the
    opposite full sine (back), then straight. A = peak_ay / G_ss(vx) so the steady-state lateral
    acceleration peaks at ``peak_ay`` (m/s^2) on the linear bicycle model. The period is set by the
    lateral offset: a full-sine lateral acceleration of amplitude a over T moves the car sideways
    by a T^2 / (2 pi), so T = sqrt(2 pi * lane_offset / peak_ay). At 4 m/s^2 and 3.5 m this takes
    ~2.3 s (~52 m at 80 km/h), longer than the ISO gate sections (12/13.5/11/12.5/12 m): the gates
    are tighter than a 4 m/s^2 open-loop sine can follow; the peak acceleration is what is kept.
    """

    name: str = "double-lane-change"
    description: str = (
        "ISO 3888-2-like double lane change at 80 km/h, open-loop road-wheel steering (no driver "
        "model): a full-sine lane change left, an 11 m straight, a full-sine lane change back; "
        "amplitude for a 4 m/s^2 steady-state lateral acceleration on the linear bicycle model."
    )
    duration: float = 9.0
    settle_time: float = 1.0
    speed: float = 80.0 * KMH  # m/s
    peak_ay: float = 4.0  # m/s^2
    lane_offset: float = 3.5  # m
    straight_length: float = 11.0  # m
    t_start: float = 1.0  # s

    @property
    def period(self) -> float:
        """Duration of each full-sine lane change, s."""
        return math.sqrt(2 * math.pi * self.lane_offset / self.peak_ay)

    def amplitude(self, vehicle) -> float:
        """Road-wheel steer amplitude, rad."""
        return steer_for_ay(vehicle, self.speed, self.peak_ay)

    def signals(self, t, vehicle="sedan"):
        t = np.asarray(t, dtype=float)
        A, T = self.amplitude(vehicle), self.period
        t1 = self.t_start
        t2 = t1 + T + self.straight_length / self.speed
        delta = np.zeros_like(t)
        for t0, sign in ((t1, 1.0), (t2, -1.0)):
            seg = (t >= t0) & (t <= t0 + T)
            delta = np.where(seg, sign * A * np.sin(2 * np.pi * (t - t0) / T), delta)
        return {"delta": delta, "vx": np.full_like(t, self.speed), "bank_angle": np.zeros_like(t)}

    def _derived(self, vehicle):
        return {"speed_mps": self.speed, "peak_ay_mps2": self.peak_ay, "lane_change_period_s": self.period,
                "steer_amplitude_rad": self.amplitude(vehicle), "open_loop": True}


# --------------------------------------------------------------------------------------------
# sine with dwell (FMVSS 126)
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class SineWithDwell(Scenario):
    """FMVSS 126 sine with dwell at 80 km/h, open loop, on road-wheel angle.

    delta = A sin(2 pi f t') for the first 3/4 period (ends at -A), hold -A for ``dwell`` s, then
    the last quarter period back to 0; ``t_start`` s straight before. A = amplitude_factor x the
    road-wheel angle giving 0.3 g steady state at 80 km/h on the linear bicycle model (the
    standard's slowly increasing steer); amplitude_factor in [1.5, 6.5] as in FMVSS 126.
    """

    name: str = "sine-with-dwell"
    description: str = (
        "FMVSS 126 sine with dwell at 80 km/h: 0.7 Hz road-wheel sine, 0.5 s dwell at the second "
        "peak, amplitude 5 x the 0.3 g steady-state angle of the linear bicycle model. Open loop."
    )
    duration: float = 6.0
    settle_time: float = 1.0
    speed: float = 80.0 * KMH  # m/s
    freq: float = 0.7  # Hz
    dwell: float = 0.5  # s
    amplitude_factor: float = 5.0  # 1, x the 0.3 g angle
    reference_ay: float = 0.3 * G  # m/s^2
    t_start: float = 1.0  # s

    def __post_init__(self):
        if not 1.5 <= self.amplitude_factor <= 6.5:
            raise ValueError(
                f"sine-with-dwell amplitude_factor must be within 1.5 ... 6.5 (FMVSS 126), got {self.amplitude_factor}"
            )

    def amplitude(self, vehicle) -> float:
        """Road-wheel steer amplitude A, rad."""
        return self.amplitude_factor * steer_for_ay(vehicle, self.speed, self.reference_ay)

    def signals(self, t, vehicle="sedan"):
        t = np.asarray(t, dtype=float)
        A = self.amplitude(vehicle)
        w = 2 * np.pi * self.freq
        P = 1.0 / self.freq
        t0 = self.t_start
        t1 = t0 + 0.75 * P  # end of the first 3/4 period (delta = -A)
        t2 = t1 + self.dwell  # end of the dwell
        t3 = t2 + 0.25 * P  # end of the last quarter period
        delta = np.zeros_like(t)
        delta = np.where((t >= t0) & (t < t1), A * np.sin(w * (t - t0)), delta)
        delta = np.where((t >= t1) & (t < t2), -A, delta)
        delta = np.where((t >= t2) & (t < t3), A * np.sin(w * (t - t2) + 1.5 * np.pi), delta)
        return {"delta": delta, "vx": np.full_like(t, self.speed), "bank_angle": np.zeros_like(t)}

    def _derived(self, vehicle):
        return {"speed_mps": self.speed, "amplitude_factor": self.amplitude_factor,
                "steer_0p3g_rad": steer_for_ay(vehicle, self.speed, self.reference_ay),
                "steer_amplitude_rad": self.amplitude(vehicle), "dwell_s": self.dwell, "open_loop": True}


# --------------------------------------------------------------------------------------------
# fishhook (NHTSA)
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Fishhook(Scenario):
    """NHTSA fishhook with a fixed 0.25 s first dwell (no roll-rate feedback timing), open loop.

    Entry speed 45 mph (20.1 m/s) held constant (no throttle release modelled). Road-wheel steer
    ramps to +A at the road-wheel rate equivalent to ``handwheel_rate`` (rad/s) through
    ``steering_ratio``, holds ``dwell`` s, counter-steers to -A at the same rate, holds
    ``hold`` s, returns to 0 at the same rate. A = amplitude_factor (6.5) x the road-wheel angle
    giving 0.3 g steady state at ``reference_speed`` (80 km/h ~ NHTSA's 50 mph slowly increasing
    steer, as for the sine with dwell) on the linear bicycle model.
    """

    name: str = "fishhook"
    description: str = (
        "NHTSA fishhook at 45 mph: steer to 6.5 x the 0.3 g angle at 720 deg/s handwheel (16:1), "
        "hold 0.25 s, counter-steer to the opposite amplitude, hold 3 s, return to 0. Open loop."
    )
    duration: float = 8.0
    settle_time: float = 1.0
    speed: float = 45.0 * MPH  # m/s
    amplitude_factor: float = 6.5  # 1
    reference_speed: float = 80.0 * KMH  # m/s, where the 0.3 g angle is characterised
    reference_ay: float = 0.3 * G  # m/s^2
    handwheel_rate: float = 720.0 * DEG  # rad/s at the handwheel
    steering_ratio: float = 16.0  # 1
    dwell: float = 0.25  # s
    hold: float = 3.0  # s
    t_start: float = 1.0  # s

    @property
    def road_wheel_rate(self) -> float:
        """Road-wheel steer rate, rad/s."""
        return self.handwheel_rate / self.steering_ratio

    def amplitude(self, vehicle) -> float:
        """Road-wheel steer amplitude A, rad."""
        return self.amplitude_factor * steer_for_ay(vehicle, self.reference_speed, self.reference_ay)

    def signals(self, t, vehicle="sedan"):
        t = np.asarray(t, dtype=float)
        A = self.amplitude(vehicle)
        tr = A / self.road_wheel_rate  # s to go 0 -> A
        t0 = self.t_start
        knots = [(0.0, 0.0), (t0, 0.0), (t0 + tr, A), (t0 + tr + self.dwell, A)]
        t_cs = knots[-1][0] + 2 * tr
        knots += [(t_cs, -A), (t_cs + self.hold, -A), (t_cs + self.hold + tr, 0.0)]
        return {"delta": _piecewise_linear(t, knots), "vx": np.full_like(t, self.speed),
                "bank_angle": np.zeros_like(t)}

    def _derived(self, vehicle):
        return {"speed_mps": self.speed, "steer_0p3g_rad": steer_for_ay(vehicle, self.reference_speed, self.reference_ay),
                "steer_amplitude_rad": self.amplitude(vehicle), "road_wheel_rate_radps": self.road_wheel_rate,
                "open_loop": True}


# --------------------------------------------------------------------------------------------
# random manoeuvre across paper 001's speed modes (enclosure campaigns)
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class RandomManoeuvre(Scenario):
    """A seeded random manoeuvre inside the linear tire range, for enclosure campaigns.

    Speed: a smooth (half-cosine) sweep over the whole duration between a low speed drawn in
    [``v_min``, 12] m/s and a high speed drawn in [17, ``v_max``] m/s, up or down (drawn), so that
    every run crosses all three of paper 001's speed bands (10-13-16-20 m/s). Steering: the sum of three sines, frequencies drawn in [0.2, 1.5] Hz and phases
    drawn, scaled so that the steady-state lateral acceleration of the linear bicycle model at
    the current speed stays below ``max_ay`` (m/s^2; 3 m/s^2 keeps the slip angles within a few
    degrees, the linear range of the sedan's tires). No bank. Everything derives from ``seed``
    (numpy default_rng), so a run is reproducible from its seed alone.
    """

    name: str = "random-manoeuvre"
    description: str = ("Seeded random manoeuvre: a speed sweep across paper 001's speed bands and a "
                        "three-sine steering within the linear tire range (enclosure campaigns).")
    duration: float = 6.0
    settle_time: float = 0.0
    seed: int = 0
    v_min: float = 10.2  # m/s
    v_max: float = 19.8  # m/s
    max_ay: float = 3.0  # m/s^2

    def _draw(self):
        g = np.random.default_rng(self.seed)
        lo, hi = g.uniform(self.v_min, 12.0), g.uniform(17.0, self.v_max)
        v0, v1 = (lo, hi) if g.uniform() < 0.5 else (hi, lo)
        freqs = g.uniform(0.2, 1.5, size=3)
        phases = g.uniform(0.0, 2 * np.pi, size=3)
        weights = g.uniform(0.2, 1.0, size=3)
        return v0, v1, freqs, phases, weights / weights.sum()

    def signals(self, t, vehicle="sedan"):
        t = np.asarray(t, dtype=float)
        v0, v1, freqs, phases, w = self._draw()
        vx = v0 + (v1 - v0) * _cosine_blend(t / self.duration)
        shape = sum(wi * np.sin(2 * np.pi * f * t + ph) for wi, f, ph in zip(w, freqs, phases))
        shape = shape * _cosine_blend(t / 0.5)          # start from straight driving
        veh = _vehicle(vehicle)                          # loaded once, not once per sample
        gain = np.array([steer_for_ay(veh, float(v), self.max_ay) for v in vx])
        return {"delta": gain * shape, "vx": vx, "bank_angle": np.zeros_like(t)}

    def _derived(self, vehicle):
        v0, v1, freqs, _, _ = self._draw()
        return {"seed": self.seed, "v_from_mps": float(v0), "v_to_mps": float(v1),
                "steer_freqs_hz": [float(f) for f in freqs], "max_ay_mps2": self.max_ay}


# --------------------------------------------------------------------------------------------
# paper 002 (Delibasi 2014): band-limited random steering and a swept stiffness box
# --------------------------------------------------------------------------------------------
#: Paper 002's steering weight W1(s) = 39.4784 / (s^2 + 8.8858 s + 39.4784) (vehicles.md,
#: section delibasi): a 2nd-order Butterworth low-pass, wn = 2 pi rad/s (1 Hz), zeta = 0.7071.
#: Numerator and denominator in DESCENDING powers of s (scipy's convention).
W1_NUM = (39.4784,)
W1_DEN = (1.0, 8.8858, 39.4784)


def w1_gain_squared(f_hz) -> np.ndarray:
    """|W1(j 2 pi f)|^2 at the frequencies f (Hz): the power gain of paper 002's steering weight."""
    s = 2j * np.pi * np.asarray(f_hz, dtype=float)
    return np.abs(np.polyval(W1_NUM, s) / np.polyval(W1_DEN, s)) ** 2


def _zoh_filter(num, den, h: float, u: np.ndarray) -> np.ndarray:
    """Exact zero-order-hold discretisation (step h, s) of the strictly proper num/den (descending
    powers of s) driven by ``u`` held over each step: y_k at t_k = k h from zero state (y_0 = 0).
    (scipy's ``cont2discrete`` 'zoh': the state-space matrix exponential, then ``lfilter``.)"""
    from scipy.signal import cont2discrete, lfilter

    numd, dend, _ = cont2discrete((np.asarray(num, float), np.asarray(den, float)), h, method="zoh")
    numd = np.atleast_2d(numd)[0]
    if abs(numd[0]) > 1e-12 * np.max(np.abs(numd)):
        raise ValueError("_zoh_filter needs a strictly proper transfer function")
    return lfilter(numd, dend, np.asarray(u, dtype=float))


@dataclass(frozen=True)
class W1Steer(Scenario):
    """Paper 002: band-limited random road-wheel steering, the spectrum of its steering weight W1.

    delta(t) = scale * (W1 * e)(t): seeded white noise e (``numpy.random.default_rng(seed)``,
    N(0, 1) samples held over steps of ``noise_dt`` s on an internal grid 0, noise_dt, ...)
    filtered by W1(s) = 39.4784 / (s^2 + 8.8858 s + 39.4784) (W1_NUM/W1_DEN) with the EXACT
    zero-order-hold discretisation of W1 on that grid (from zero state, so delta(0) = 0 and the
    run starts from straight driving), then scaled so that the RMS of delta over [0, duration]
    is exactly

        delta_rms = ay_rms / G_ss(vx)   rad,

    with G_ss the steady-state lateral acceleration gain of the linear bicycle model (module
    docstring). ay_rms = 1 m/s^2: for a Gaussian signal of this bandwidth the peaks over 30 s are
    about 3x the RMS, i.e. |ay| peaks near 3 m/s^2, inside the linear tire range. For delibasi
    at 30 km/h: G_ss = 21.4 (m/s^2)/rad, delta_rms = 0.0468 rad (2.7 deg road wheel); with the
    default seed the steady-state |ay| peak G_ss*max|delta| is 2.89 m/s^2 (``info``), and
    CarPlant (delibasi, Magic Formula tires) gives a peak |ay| of 3.27 m/s^2, 1.3 % below the
    same run with linear tires (sideslip within 0.05 deg of it): the linear range.
    The signal on the scenario's time grid is the internal one interpolated linearly (exact at
    multiples of noise_dt), so it is the same for every communication step that divides noise_dt
    (reproducible from seed and noise_dt alone). White noise held over 5 ms is flat within 0.2 %
    (sinc^2) up to 5 Hz, where |W1|^2 is already below 1/600: the spectrum is |W1|^2 up to
    a constant. Constant speed 30 km/h, the middle of paper 002's 20-40 km/h box; no bank.
    Open loop (no driver model): the heading wanders.
    """

    name: str = "w1-steer"
    description: str = (
        "Paper 002: band-limited random road-wheel steering at 30 km/h, seeded white noise filtered by the "
        "steering weight W1(s) = 39.4784/(s^2 + 8.8858 s + 39.4784) (1 Hz Butterworth), RMS for 1 m/s^2 "
        "steady-state lateral acceleration on the linear bicycle model (peaks ~3 m/s^2). Open loop."
    )
    duration: float = 30.0
    settle_time: float = 3.0
    speed: float = 30.0 * KMH  # m/s, inside paper 002's 20-40 km/h box
    seed: int = 0
    ay_rms: float = 1.0  # m/s^2, steady-state lateral acceleration RMS on the linear bicycle model
    noise_dt: float = 0.005  # s, hold time of the white-noise samples (internal grid)

    def __post_init__(self):
        if not (self.ay_rms > 0 and self.noise_dt > 0 and self.speed > 0 and self.duration > 0):
            raise ValueError("w1-steer needs ay_rms > 0, noise_dt > 0, speed > 0 and duration > 0")

    def steer_rms(self, vehicle) -> float:
        """RMS road-wheel angle over [0, duration], rad."""
        return steer_for_ay(vehicle, self.speed, self.ay_rms)

    def _internal(self, vehicle) -> tuple[np.ndarray, np.ndarray]:
        """(internal time grid s, delta rad on it); the grid covers [0, duration + noise_dt]."""
        n = int(math.ceil(self.duration / self.noise_dt - 1e-9)) + 1
        tg = np.arange(n + 1) * self.noise_dt
        e = np.random.default_rng(self.seed).standard_normal(n + 1)
        y = _zoh_filter(W1_NUM, W1_DEN, self.noise_dt, e)
        inside = tg <= self.duration + 1e-9 * self.noise_dt
        rms = float(np.sqrt(np.mean(y[inside] ** 2)))
        return tg, y * (self.steer_rms(vehicle) / rms)

    def signals(self, t, vehicle="sedan"):
        t = np.asarray(t, dtype=float)
        tg, d = self._internal(vehicle)
        return {"delta": np.interp(t, tg, d), "vx": np.full_like(t, self.speed), "bank_angle": np.zeros_like(t)}

    def _derived(self, vehicle):
        tg, d = self._internal(vehicle)
        peak = float(np.max(np.abs(d[tg <= self.duration + 1e-9 * self.noise_dt])))
        return {"speed_mps": self.speed, "seed": self.seed, "noise_dt_s": self.noise_dt,
                "w1_num": list(W1_NUM), "w1_den": list(W1_DEN), "ay_rms_mps2": self.ay_rms,
                "steer_rms_rad": self.steer_rms(vehicle), "steer_peak_rad": peak,
                "ay_ss_peak_mps2": peak * steady_state_ay_gain(vehicle, self.speed), "open_loop": True}


@dataclass(frozen=True)
class StiffnessSweep:
    """Mix-in (put it BEFORE the manoeuvre's class; it adds fields and no Scenario defaults, so
    the manoeuvre's own defaults stay): CarPlant's ``stiffness_scale_f``/``_r`` swept smoothly through a stiffness box.

    rear   s_r(t) = r_lo + (r_hi - r_lo) (1 - cos(2 pi c t / T)) / 2   (from r_lo up to r_hi, back)
    front  s_f(t) = f_hi - (f_hi - f_lo) (1 - cos(2 pi c t / T)) / 2   (antiphase: from f_hi down)

    with T = duration (s) and c = ``stiffness_cycles``: with c = 1 each scale starts at one end
    of its range, reaches the other at T/2 and returns. The ranges (1, multipliers of the
    vehicle's Cf, Cr) are ``scale_f_range``/``scale_r_range`` if given, else the vehicle's
    stiffness box divided by its Cf, Cr: the "physical" box of paper 002 for delibasi (per axle
    2 x 590..610 N/deg x 180/pi = 67.6..69.9 kN/rad front, 2 x 550..650 N/deg = 63.0..74.5
    kN/rad rear; with Cf = Cr = 68.755 kN/rad the ranges 0.98333..1.01667 front and
    0.91667..1.08333 rear), a vehicle's [ranges] Cf, Cr otherwise
    (``latobs.synthesis.fixed_order_002.vehicle_box``). A vehicle with neither is an error
    (VehicleParameterError, e.g. the default plant vehicle sedan: run with delibasi).
    """

    scale_f_range: tuple[float, float] | None = None  # 1, (min, max) of stiffness_scale_f
    scale_r_range: tuple[float, float] | None = None  # 1, (min, max) of stiffness_scale_r
    stiffness_cycles: float = 1.0  # full cosine cycles over the duration

    def stiffness_ranges(self, vehicle) -> tuple[tuple[float, float], tuple[float, float]]:
        """((front min, max), (rear min, max)) of the stiffness multipliers, 1."""
        if self.scale_f_range is not None and self.scale_r_range is not None:
            rf, rr = tuple(map(float, self.scale_f_range)), tuple(map(float, self.scale_r_range))
        else:
            from latobs.synthesis.fixed_order_002 import vehicle_box

            v = _vehicle(vehicle)
            p = v.require(["Cf", "Cr"], f"scenario {self.name!r} (stiffness multipliers of Cf, Cr)")
            try:
                box = vehicle_box(v, "physical")
            except (ValueError, KeyError) as exc:   # a user error (VehicleParameterError), not a bug
                raise VehicleParameterError(f"scenario {self.name!r}: vehicle {v.name!r} has no cornering stiffness box "
                                 f"({exc}); use vehicle 'delibasi' (latobs validate --plant-vehicle delibasi) or "
                                 f"give scale_f_range and scale_r_range") from None
            rf = (box.cf[0] / p["Cf"], box.cf[1] / p["Cf"])
            rr = (box.cr[0] / p["Cr"], box.cr[1] / p["Cr"])
            rf = tuple(self.scale_f_range) if self.scale_f_range is not None else rf
            rr = tuple(self.scale_r_range) if self.scale_r_range is not None else rr
        for label, (lo, hi) in (("front", rf), ("rear", rr)):
            if not (0 < lo <= hi and math.isfinite(hi)):
                raise ValueError(f"scenario {self.name!r}: {label} stiffness range must satisfy 0 < min <= max, "
                                 f"got {(lo, hi)}")
        return rf, rr

    def parameter_signals(self, t, vehicle="sedan"):
        t = np.asarray(t, dtype=float)
        (f_lo, f_hi), (r_lo, r_hi) = self.stiffness_ranges(vehicle)
        w = 0.5 * (1.0 - np.cos(2 * np.pi * self.stiffness_cycles * t / self.duration))
        return {"stiffness_scale_f": f_hi - (f_hi - f_lo) * w, "stiffness_scale_r": r_lo + (r_hi - r_lo) * w}

    def _derived(self, vehicle):
        d = super()._derived(vehicle)
        (f_lo, f_hi), (r_lo, r_hi) = self.stiffness_ranges(vehicle)
        v = _vehicle(vehicle)
        d.update({"stiffness_scale_f_range": [f_lo, f_hi], "stiffness_scale_r_range": [r_lo, r_hi],
                  "Cf_range_Nprad": [f_lo * v.Cf, f_hi * v.Cf], "Cr_range_Nprad": [r_lo * v.Cr, r_hi * v.Cr],
                  "stiffness_cycles": self.stiffness_cycles})
        return d


@dataclass(frozen=True)
class SineWithDwellVaryingStiffness(StiffnessSweep, SineWithDwell):
    """The sine with dwell (:class:`SineWithDwell`) at 35 km/h while the axle cornering stiffnesses
    sweep paper 002's box (:class:`StiffnessSweep`: rear up 63.0 -> 74.5 kN/rad and back, front
    in antiphase 69.9 -> 67.6 kN/rad and back, one cosine cycle over the 6 s run).

    Departures from FMVSS 126 (stated): speed 35 km/h instead of 80 km/h, because paper 002's
    estimator is designed for 20-40 km/h only (the standard's speed is outside its box); the
    0.3 g reference angle is characterised at that same speed (as the standard does at its test
    speed), from the NOMINAL Cf, Cr (box centre); amplitude factor 2.5 (inside the standard's
    1.5 ... 6.5): on CarPlant (delibasi, dry road, this stiffness sweep) the peak |ay| is
    7.5 m/s^2, 12 % below the same run with linear tires (front slip up to 7.9 deg, past the
    linear range), while the rear slip stays at 4.9 deg (no spin; the understeering car
    saturates at the front). Larger factors hardly raise |ay| (8.3 m/s^2 at 4, nominal
    stiffness) and need road-wheel angles over 20 deg.
    """

    name: str = "sine-with-dwell-varying-stiffness"
    description: str = (
        "Paper 002: the sine with dwell at 35 km/h (inside the estimator's 20-40 km/h box; FMVSS 126's "
        "80 km/h is outside it), 2.5 x the 0.3 g angle at 35 km/h (nonlinear, no spin), while CarPlant's "
        "cornering stiffnesses sweep the delibasi box: rear 63.0 -> 74.5 -> 63.0 kN/rad, front "
        "69.9 -> 67.6 -> 69.9 kN/rad (one cosine over the run). Open loop."
    )
    speed: float = 35.0 * KMH  # m/s
    amplitude_factor: float = 2.5  # 1, x the 0.3 g angle at 35 km/h


@dataclass(frozen=True)
class FishhookVaryingStiffness(StiffnessSweep, Fishhook):
    """The NHTSA fishhook (:class:`Fishhook`) at 35 km/h while the axle cornering stiffnesses sweep
    paper 002's box (:class:`StiffnessSweep`: rear up 63.0 -> 74.5 kN/rad and back, front in
    antiphase 69.9 -> 67.6 kN/rad and back, one cosine cycle over the 8 s run).

    Departures from the NHTSA fishhook (stated): speed 35 km/h instead of 35-50 mph (56-80 km/h),
    because paper 002's estimator is designed for 20-40 km/h only; the 0.3 g reference angle is
    characterised at 35 km/h (``reference_speed``, the manoeuvre's own speed, instead of 80 km/h)
    from the NOMINAL Cf, Cr; amplitude factor 2.5 instead of 6.5: on CarPlant (delibasi, dry
    road, this stiffness sweep) the peak |ay| is 7.4 m/s^2, 11 % below the linear-tire run
    (front slip up to 8.7 deg), rear slip 5.0 deg (no spin); 6.5 x would need a 38 deg
    road-wheel angle.
    """

    name: str = "fishhook-varying-stiffness"
    description: str = (
        "Paper 002: the fishhook at 35 km/h (inside the estimator's 20-40 km/h box; NHTSA's 35-50 mph is "
        "outside it), 2.5 x the 0.3 g angle at 35 km/h (nonlinear, no spin), while CarPlant's cornering "
        "stiffnesses sweep the delibasi box: rear 63.0 -> 74.5 -> 63.0 kN/rad, front "
        "69.9 -> 67.6 -> 69.9 kN/rad (one cosine over the run). Open loop."
    )
    speed: float = 35.0 * KMH  # m/s
    reference_speed: float = 35.0 * KMH  # m/s, the 0.3 g angle is characterised at the test speed
    amplitude_factor: float = 2.5  # 1


# --------------------------------------------------------------------------------------------
# paper 003 (Ichalal et al. 2017): the motorcycle double lane change (plant MotorcyclePlant)
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class MotorcycleLaneChange(Scenario):
    """Paper 003's manoeuvre (section IV, Fig. 1) on ``MotorcyclePlant``: a positive then a negative
    rider-torque pulse (double lane change) while the speed goes 12 -> 20 m/s, holds 4 s and
    falls to 10 m/s. Open loop (no rider model, no path following).

    Signals (MotorcyclePlant's inputs; Sharp's SAE axes, > 0 turns the handlebar to the right):

    * ``vx`` (m/s): ``v_start`` = 12 until ``t_rise`` = 1 s, a half-cosine rise over ``rise`` = 4 s
      to ``v_high`` = 20 (peak acceleration 8 pi / 8 = 3.1 m/s^2), held ``hold`` = 4 s (5-9 s), a
      half-cosine fall over ``fall`` = 5 s to ``v_end`` = 10 (peak deceleration 3.1 m/s^2), held to
      ``duration`` = 16 s. It crosses paper 003's grid modes 10, 15 and 20 m/s (nearest-mode bands
      7.5-12.5, 12.5-17.5, 17.5-22.5 m/s).
    * ``rider_torque`` (N m): +A sin^2(pi (t - t1)/T) on [t1, t1 + T], then -A sin^2(pi (t - t2)/T)
      on [t2, t2 + T] (C1-smooth pulses), A = ``torque_amplitude`` = 45 N m, T = ``pulse`` = 1 s,
      t1 = 5.0 s, t2 = 6.2 s: during the 20 m/s hold.

    Figures on MotorcyclePlant (sharp_motorcycle, dry road mu = 1, Magic Formula C = 1.3, E = 0,
    5 ms steps): the positive pulse counter-steers the motorcycle (steer right, lean and turn
    left) to a peak roll of -0.49 rad (28 deg) at ~20 m/s, the negative pulse brings it back near
    upright; peak |steer| 0.035 rad, peak |yaw rate| 0.33 rad/s; peak |Gamma_f| / peak |Ff| =
    73 / 548 N = 13 % and peak |Gamma_r| / peak |Fr| = 77 / 713 N = 11 % (the saturation zone
    is reached: the tyres at 55 % / 50 % of mu Fz, slip up to 0.014 / 0.012 rad). Open
    loop, a small left lean remains (-0.1 rad at the end: the capsize mode is slightly unstable at
    12-20 m/s and turns stable as the speed falls to 10 m/s); the motorcycle stays upright,
    bounded and finite over the whole run (tests/test_motorcycle_plant.py). With 40 N m the
    front tyre just reaches 10 % and the rear 8 %; 50 N m leans to 0.55 rad. Equal
    pulses (paper 003's "positive then negative torque") do not lean the motorcycle the other
    way: that would take a larger second pulse (x1.6 for a +0.4 rad lean).
    """

    name: str = "motorcycle-lane-change"
    description: str = (
        "Paper 003: motorcycle double lane change on MotorcyclePlant, a +45 N m then a -45 N m rider-torque "
        "pulse (1 s sin^2 each, at 5.0 and 6.2 s) during a speed profile 12 -> 20 m/s (4 s rise), 4 s at "
        "20 m/s, 20 -> 10 m/s (5 s fall): grid modes 10/15/20 m/s; counter-steered lean to ~0.49 rad and "
        "back, tyres into saturation (peak |Gamma|/|F| ~ 11-13 %). Open loop."
    )
    duration: float = 16.0
    settle_time: float = 2.0
    plant: str = "MotorcyclePlant"
    signal_names: tuple[str, ...] = field(default=("rider_torque", "vx"), repr=False)
    v_start: float = 12.0  # m/s
    v_high: float = 20.0  # m/s
    v_end: float = 10.0  # m/s
    t_rise: float = 1.0  # s, the speed starts rising
    rise: float = 4.0  # s
    hold: float = 4.0  # s at v_high
    fall: float = 5.0  # s
    torque_amplitude: float = 45.0  # N m
    pulse: float = 1.0  # s, duration of each torque pulse
    t_first: float = 5.0  # s, start of the positive pulse
    t_second: float = 6.2  # s, start of the negative pulse

    def __post_init__(self):
        if not (self.v_start > 0 and self.v_high > 0 and self.v_end > 0):
            raise ValueError("motorcycle-lane-change needs positive speeds")
        if not (self.rise > 0 and self.fall > 0 and self.hold >= 0 and self.pulse > 0 and self.t_rise >= 0):
            raise ValueError("motorcycle-lane-change needs rise, fall, pulse > 0 and hold, t_rise >= 0")
        if not self.t_second >= self.t_first + self.pulse:
            raise ValueError("motorcycle-lane-change: the negative pulse must start after the positive one ends")
        if not (math.isfinite(self.torque_amplitude) and self.torque_amplitude >= 0):
            raise ValueError("motorcycle-lane-change needs a finite torque_amplitude >= 0 (N m)")

    @property
    def t_fall(self) -> float:
        """Start of the speed decrease, s."""
        return self.t_rise + self.rise + self.hold

    def speed(self, t) -> np.ndarray:
        """Forward speed (m/s) on the time grid t (s)."""
        t = np.asarray(t, dtype=float)
        return (self.v_start + (self.v_high - self.v_start) * _cosine_blend((t - self.t_rise) / self.rise)
                + (self.v_end - self.v_high) * _cosine_blend((t - self.t_fall) / self.fall))

    def torque(self, t) -> np.ndarray:
        """Rider torque (N m) on the time grid t (s)."""
        t = np.asarray(t, dtype=float)
        out = np.zeros_like(t)
        for t0, sign in ((self.t_first, 1.0), (self.t_second, -1.0)):
            seg = (t >= t0) & (t <= t0 + self.pulse)
            out = np.where(seg, sign * self.torque_amplitude * np.sin(np.pi * (t - t0) / self.pulse) ** 2, out)
        return out

    def signals(self, t, vehicle="sharp_motorcycle"):
        # amplitudes in N m and m/s: the same for any motorcycle parameter set
        return {"rider_torque": self.torque(t), "vx": self.speed(t)}

    def _derived(self, vehicle):
        return {"speed_knots_mps": [self.v_start, self.v_high, self.v_end],
                "speed_phases_s": {"rise": [self.t_rise, self.t_rise + self.rise],
                                   "hold": [self.t_rise + self.rise, self.t_fall],
                                   "fall": [self.t_fall, self.t_fall + self.fall]},
                "torque_amplitude_Nm": self.torque_amplitude, "pulse_s": self.pulse,
                "pulses_start_s": [self.t_first, self.t_second], "grid_modes_mps": [10.0, 15.0, 20.0],
                "open_loop": True}


# --------------------------------------------------------------------------------------------
# registry
# --------------------------------------------------------------------------------------------
class UnknownScenarioError(KeyError):
    """Asked for a scenario that is not registered (the message lists the known ones)."""

    def __str__(self) -> str:  # KeyError would print the message in quotes
        return str(self.args[0]) if self.args else ""


SCENARIOS: dict[str, Scenario] = {
    s.name: s for s in (
        BankBraking(), SteadyTurn(), DoubleLaneChange(), SineWithDwell(), Fishhook(),
        # paper 001's operating range (speed modes 11.5/14.5/18 m/s): the same lane change at 15 m/s
        DoubleLaneChange(name="double-lane-change-15",
                         description="The double lane change at 15 m/s (paper 001's speed range): open-loop "
                                     "road-wheel steering for a 4 m/s^2 steady-state lateral acceleration.",
                         speed=15.0),
        RandomManoeuvre(),
        # paper 002 (Delibasi 2014), vehicle delibasi: W1-filtered steering, swept stiffness box
        W1Steer(), SineWithDwellVaryingStiffness(), FishhookVaryingStiffness(),
        # paper 003 (Ichalal 2017): the motorcycle double lane change, plant MotorcyclePlant
        MotorcycleLaneChange(),
    )
}


def scenario_names() -> list[str]:
    return sorted(SCENARIOS)


def get_scenario(name: str | Scenario, **overrides) -> Scenario:
    """The registered scenario ``name``; keyword overrides replace fields (validated).

    Raises UnknownScenarioError (a KeyError) naming the known scenarios when ``name`` is unknown, and TypeError naming the
    scenario's fields when an override is not one of them.
    """
    if isinstance(name, Scenario):
        base = name
    else:
        if name not in SCENARIOS:
            raise UnknownScenarioError(f"unknown scenario {name!r}; known scenarios: {', '.join(scenario_names())}")
        base = SCENARIOS[name]
    if not overrides:
        return base
    fields = {f.name for f in dataclasses.fields(base)}
    bad = sorted(set(overrides) - fields)
    if bad:
        raise TypeError(f"scenario {base.name!r} has no field(s) {', '.join(bad)}; fields: {', '.join(sorted(fields))}")
    return dataclasses.replace(base, **overrides)


def register(scenario: Scenario) -> Scenario:
    """Add (or replace) a scenario in the registry; returns it."""
    if not scenario.name:
        raise ValueError("a registered scenario needs a name")
    SCENARIOS[scenario.name] = scenario
    return scenario
