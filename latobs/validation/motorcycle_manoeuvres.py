"""The motorcycle manoeuvre of paper 003: a double lane change driving ``MotorcyclePlant``."""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np


from .scenario_base import (Scenario, _cosine_blend)


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
    bounded and finite over the whole run (tests/runtime/test_motorcycle_plant.py). With 40 N m the
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
