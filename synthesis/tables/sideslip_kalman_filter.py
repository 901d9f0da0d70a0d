"""Tables of the Kalman peer of paper 002 (linear bicycle model, x = [vy, r], y = [ay, r]).

The model at the speed v is A = [[a00/v, a01/v - v], [a10/v, a11/v]], B = [b0, b1] (the ay row
of C is A's first row without -v, D = [b0, 0]); its speed-free coefficients a, b come from the
vehicle here. No step map: the model changes with the measured speed at every step
(docs/runtime/sideslip_kalman_filter.md).
"""
from __future__ import annotations

from ..design_file import KALMAN_P0_DEFAULT, KALMAN_VX_RANGE_DEFAULT

import math

VEHICLE = ("m", "lf", "lr", "Iz", "Cf", "Cr")


def vehicle_values(data: dict) -> dict:
    """{m, lf, lr, Iz, Cf, Cr} (SI, finite > 0) from ``data["vehicle"]`` (flat numbers, or a
    vehicle set {"parameters": {k: {"value": ...}}}), or a ValueError naming the parameter."""
    try:
        veh = data["vehicle"]
        where = "vehicle"
        if isinstance(veh.get("parameters"), dict):      # a vehicle set as in design files
            veh, where = veh["parameters"], "vehicle.parameters"
    except (KeyError, TypeError, AttributeError) as exc:
        raise ValueError(f"data file lacks {exc} needed by the Kalman filter") from exc
    vals = {}
    for k in VEHICLE:
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
    return vals


def compute(data: dict) -> dict:
    """{"a": [a00, a01, a10, a11], "b": [b0, b1], "Q", "R", "P0", "vx_min", "vx_max"}:
    a00 = -(Cf + Cr)/m, a01 = -(lf Cf - lr Cr)/m, a10 = -(lf Cf - lr Cr)/Iz,
    a11 = -(lf^2 Cf + lr^2 Cr)/Iz, b0 = Cf/m, b1 = lf Cf/Iz; the noise covariances, the initial
    covariance and the speed clamp of the design file with their defaults."""
    m, lf, lr, Iz, Cf, Cr = (vehicle_values(data)[k] for k in VEHICLE)
    try:
        rt = data.get("runtime", {}) or {}
        settings = {"Q": _floats(data["noise"]["q"]), "R": _floats(data["noise"]["r"]),
                    "P0": _floats(data.get("initial", {}).get("P0", KALMAN_P0_DEFAULT)),
                    "vx_min": float(rt.get("vx_min", KALMAN_VX_RANGE_DEFAULT[0])),
                    "vx_max": float(rt.get("vx_max", KALMAN_VX_RANGE_DEFAULT[1]))}
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise ValueError(f"data file: noise.q, noise.r (2x2), initial.P0 (2x2) and runtime.vx_min/vx_max "
                         f"needed by the Kalman filter: {exc!r}") from exc
    return {"a": [-(Cf + Cr) / m, -(lf * Cf - lr * Cr) / m, -(lf * Cf - lr * Cr) / Iz, -(lf**2 * Cf + lr**2 * Cr) / Iz],
            "b": [Cf / m, lf * Cf / Iz], **settings}


def _floats(M) -> list:
    return [[float(x) for x in row] for row in M]
