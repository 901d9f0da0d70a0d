"""Independent checks of the motorcycle plant's tables: M^-1 against the mass matrix (numpy) and
kt recomputed with numpy's solve."""
from __future__ import annotations

import numpy as np

from .sideslip_fixed_order_estimator import absent, bounded, rel_err


def checks(data: dict) -> list:
    if absent(data, "motorcycle plant"):
        return absent(data, "motorcycle plant")
    t, s = data["tables"], data["structure"]
    M, BF = np.asarray(s["M"], float), np.asarray(s["B_F"], float)

    def kt():
        X = np.linalg.solve(M, BF)                      # M^-1 B_F without the stored inverse
        want = max(float(np.sum(np.abs(float(s["tyres"][k]["C1"]) * np.asarray(s["tyres"][k]["slip_velocity"],
                                                                                 float) @ X)))
                   for k in ("front", "rear"))
        return abs(float(t["kt"]) - want) / want

    return [
        bounded("motorcycle plant tables: M^-1 M = I (max |error|)",
                lambda: rel_err(np.asarray(t["Minv"], float) @ M, np.eye(4)), 1e-12),
        bounded("motorcycle plant tables: kt = max_tyre sum |C1 S M^-1 B_F| (numpy solve; rel. error)", kt, 1e-12),
    ]
