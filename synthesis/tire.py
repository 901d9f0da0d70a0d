"""The vehicle's lateral tire curve at static load (the simplified Magic Formula of CarPlant), and
paper 000's two tire-mode stiffnesses on it (``mode_stiffness``: C1 linear, C2 a secant slope
above alpha*)."""
from __future__ import annotations

import math

import numpy as np

from .params import G, Vehicle

MF_PARAMS = ("m", "lf", "lr", "Cf", "Cr", "mf_C", "mf_E", "mu")


def axle_force(vehicle: Vehicle, axle: str, alpha: np.ndarray) -> np.ndarray:
    """Lateral force (N) of the front (``"f"``) or rear (``"r"``) axle at slip angles ``alpha`` (rad)."""
    p = vehicle.require(MF_PARAMS, "the Magic Formula tire curve")
    L = p["lf"] + p["lr"]
    Fz = p["m"] * G * (p["lr"] if axle == "f" else p["lf"]) / L / 2.0     # N per wheel, static
    c_wheel = (p["Cf"] if axle == "f" else p["Cr"]) / 2.0
    C, E, mu = p["mf_C"], p["mf_E"], p["mu"]
    B = c_wheel / (C * mu * Fz)
    x = B * np.asarray(alpha, dtype=float)
    return 2.0 * mu * Fz * np.sin(C * np.arctan(x - E * (x - np.arctan(x))))


def mode_stiffness(vehicle: Vehicle, alpha_star: float, alpha_fit: float, n: int = 200) -> tuple[float, float]:
    """(C2f/Cf, C2r/Cr): secant-slope ratios of the tire curve over [alpha_star, alpha_fit] (rad)."""
    if not 0 < alpha_star < alpha_fit < math.pi / 2:
        raise ValueError(f"need 0 < alpha* < alpha_fit < 90 deg, got alpha* = {math.degrees(alpha_star):g} deg, "
                         f"alpha_fit = {math.degrees(alpha_fit):g} deg")
    a = np.linspace(alpha_star, alpha_fit, n)
    out = []
    for axle, c in (("f", vehicle.Cf), ("r", vehicle.Cr)):
        F = axle_force(vehicle, axle, a)
        out.append(float(np.dot(a, F) / np.dot(a, a)) / c)
    return out[0], out[1]
