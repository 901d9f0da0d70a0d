"""Paper 002's steering input: band-limited random road-wheel steering shaped by the weight W1."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


from .scenario_base import (KMH, Scenario, steady_state_ay_gain, steer_for_ay)


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
