"""How the reports show a signal: its unit and scale (angles in degrees, SI otherwise) and its
label. Plain data, no plotting library: the tables of a report without figures need only this."""
from __future__ import annotations

import math

RAD2DEG = 180.0 / math.pi

#: preferred order of the estimated signals; others follow alphabetically
PREFERRED = ("beta", "yaw_rate", "roll_angle", "roll_rate", "bank_angle")

_ANGLES = {"beta", "roll_angle", "bank_angle", "delta", "alpha_f", "alpha_r", "steer_angle"}
_RATES = {"yaw_rate", "roll_rate", "steer_rate"}
_SI = {"vx": "m/s", "vy": "m/s", "ay": "m/s^2", "Fyf": "N", "Fyr": "N", "Ff": "N", "Fr": "N",
       "rider_torque": "N*m"}
_LABELS = {"beta": "sideslip beta", "yaw_rate": "yaw rate", "roll_angle": "roll angle",
           "roll_rate": "roll rate", "bank_angle": "bank angle", "delta": "road-wheel angle delta",
           "vx": "speed vx", "vy": "lateral speed vy", "ay": "lateral acceleration ay"}


def display_scale(name: str, units: dict[str, str] | None = None) -> tuple[float, str]:
    """(factor, unit label) to draw signal ``name``: rad -> deg, rad/s -> deg/s, else SI."""
    u = (units or {}).get(name) or (units or {}).get(name + "_hat")
    if u in ("rad",) or (u is None and name in _ANGLES):
        return RAD2DEG, "deg"
    if u in ("rad/s",) or (u is None and name in _RATES):
        return RAD2DEG, "deg/s"
    return 1.0, u or _SI.get(name, "SI")
