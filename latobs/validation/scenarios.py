"""Validation manoeuvres: the input signals that drive a plant FMU.

A :class:`Scenario` gives, on any time grid ``t`` (s), the plant's input signals keyed by the
FMU variable name. For the car plant (``CarPlant``) these are

* ``delta``      road-wheel steering angle, rad, > 0 steers left,
* ``vx``         longitudinal speed, m/s,
* ``bank_angle`` road bank angle, rad (sign convention of ERRATA.md: it enters the sideslip
  equation as -g/Vx * bank_angle).

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
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from latobs.synthesis.params import G, Vehicle, load_vehicle

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

    def signals(self, t: np.ndarray, vehicle: Vehicle | str = "sedan") -> dict[str, np.ndarray]:
        """Plant input signals on the time grid t (s): {FMU variable name: array}, SI units."""
        raise NotImplementedError

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
        gain = np.array([steer_for_ay(vehicle, float(v), self.max_ay) for v in vx])
        return {"delta": gain * shape, "vx": vx, "bank_angle": np.zeros_like(t)}

    def _derived(self, vehicle):
        v0, v1, freqs, _, _ = self._draw()
        return {"seed": self.seed, "v_from_mps": float(v0), "v_to_mps": float(v1),
                "steer_freqs_hz": [float(f) for f in freqs], "max_ay_mps2": self.max_ay}


# --------------------------------------------------------------------------------------------
# registry
# --------------------------------------------------------------------------------------------
class UnknownScenarioError(KeyError):
    """Asked for a scenario that is not registered (the message lists the known ones)."""

    def __str__(self) -> str:  # KeyError would print the message in quotes
        return str(self.args[0]) if self.args else ""


SCENARIOS: dict[str, Scenario] = {
    s.name: s for s in (
        BankBraking(), DoubleLaneChange(), SineWithDwell(), Fishhook(),
        # paper 001's operating range (speed modes 11.5/14.5/18 m/s): the same lane change at 15 m/s
        DoubleLaneChange(name="double-lane-change-15",
                         description="The double lane change at 15 m/s (paper 001's speed range): open-loop "
                                     "road-wheel steering for a 4 m/s^2 steady-state lateral acceleration.",
                         speed=15.0),
        RandomManoeuvre(),
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
