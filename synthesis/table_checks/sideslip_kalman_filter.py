"""Independent checks of the Kalman peer's tables: the model coefficients from the tyre forces'
slip Jacobian (numpy), the covariances and the speed clamp against the design file."""
from __future__ import annotations

import numpy as np

from ..design_file import KALMAN_P0_DEFAULT, KALMAN_VX_RANGE_DEFAULT
from .sideslip_fixed_order_estimator import absent, bounded, rel_err


def _force_model(p: dict):
    """(a, b): v [vy', r'] per [vy, r] and [vy', r'] per delta, from Fy_i = C_i alpha_i with
    alpha_i = delta_i - (vy + x_i r) / v at the axles x = [lf, -lr] (the -v r of vy' excluded)."""
    C = np.array([p["Cf"], p["Cr"]])
    x = np.array([p["lf"], -p["lr"]])
    J = -np.column_stack([np.ones(2), x])            # v d(alpha_i)/d[vy, r]
    rows = np.vstack([np.ones(2) / p["m"], x / p["Iz"]])   # [vy', r'] per axle force
    return (rows * C) @ J, (rows * C) @ np.array([1.0, 0.0])


def checks(data: dict) -> list:
    if absent(data, "Kalman filter"):
        return absent(data, "Kalman filter")
    from ..params import parse_vehicle

    t = data["tables"]
    veh = parse_vehicle(data["vehicle"], f"design file {data.get('name')}")
    p = veh.require(("m", "lf", "lr", "Iz", "Cf", "Cr"), "the Kalman filter's table checks")
    A, B = _force_model(p)
    rt = data.get("runtime", {}) or {}
    want = {"Q": data["noise"]["q"], "R": data["noise"]["r"], "P0": data.get("initial", {}).get("P0", KALMAN_P0_DEFAULT),
            "vx_min": rt.get("vx_min", KALMAN_VX_RANGE_DEFAULT[0]), "vx_max": rt.get("vx_max", KALMAN_VX_RANGE_DEFAULT[1])}
    return [
        bounded("Kalman filter tables: model coefficients a, b = the tyre forces' slip Jacobian (max rel. error)",
                lambda: max(rel_err(np.reshape(t["a"], (2, 2)), A), rel_err(t["b"], B)), 1e-12),
        bounded("Kalman filter tables: Q, R, P0 and the speed clamp = the design file's (difference)",
                lambda: max(rel_err(t[k], v) for k, v in want.items()), 0.0),
    ]
