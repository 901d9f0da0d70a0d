"""Tables of the nonlinear motorcycle plant (Sharp 1971, Magic Formula tyres; paper 003).

From the derived equations in the plant file (``data["structure"]``): the inverse mass matrix of
(E1) and the tyre-spring bound kt of the substep rule (docs/runtime/motorcycle_plant.md).
"""
from __future__ import annotations

from ...fmu_src.linalg import matrix, total


def _mat(obj, rows: int, cols: int, name: str) -> list:
    return matrix(obj, rows, cols, f"structure {name!r}", source="MotorcyclePlant")


def inverse(a) -> list:
    """Inverse of a small square matrix (Gauss-Jordan with partial pivoting), lists of floats."""
    n = len(a)
    m = [list(row) + [1.0 if i == j else 0.0 for j in range(n)] for i, row in enumerate(a)]
    for c in range(n):
        p = max(range(c, n), key=lambda i: abs(m[i][c]))
        if abs(m[p][c]) < 1e-12:
            raise ValueError("MotorcyclePlant: structure 'M' (mass matrix) is singular")
        m[c], m[p] = m[p], m[c]
        piv = m[c][c]
        m[c] = [x / piv for x in m[c]]
        for i in range(n):
            if i != c and m[i][c] != 0.0:
                f = m[i][c]
                m[i] = [x - f * y for x, y in zip(m[i], m[c])]
    return [row[n:] for row in m]


def compute(data: dict) -> dict:
    """{"Minv": M^-1 (4x4), "kt": max over the tyres of the row sum of |C1 S M^-1 B_F| (m/s^2),
    S the tyre's slip-velocity row}; kt / vx and sqrt(kt / sigma) bound the tyres' rates."""
    try:
        s = data["structure"]
        Mi = inverse(_mat(s["M"], 4, 4, "M"))
        BF = _mat(s["B_F"], 4, 2, "B_F")
        tyres = [(_mat([s["tyres"][key]["slip_velocity"]], 1, 4, f"{key} slip_velocity")[0],
                  float(s["tyres"][key]["C1"])) for key in ("front", "rear")]
    except (KeyError, TypeError) as exc:
        raise ValueError(f"MotorcyclePlant data lacks {exc} of the derived 'structure' of a motorcycle") from exc
    MiBF = [[total(Mi[i][k] * BF[k][j] for k in range(4)) for j in range(2)] for i in range(4)]
    kt = max(total(abs(total(c1 * sl[k] * MiBF[k][j] for k in range(4))) for j in range(2)) for sl, c1 in tyres)
    return {"Minv": Mi, "kt": kt}
