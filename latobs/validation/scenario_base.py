"""The base class of the validation manoeuvres (:class:`Scenario`: input signals of a plant FMU on
any time grid, SI units) and the linear bicycle's steady-state gain that scales the car
manoeuvres' steering amplitudes. docs/validation.md lists the signals and the conventions.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from latobs.synthesis.params import Vehicle, load_vehicle

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
