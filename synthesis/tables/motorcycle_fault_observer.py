"""Tables of paper 003's switched PI observer (motorcycle roll angle and rider torque), eq. (13).

Per mode the observer as one linear ODE s' = M s + G y in s = [x^; f^] (M = [[A - L_P C, E_f],
[-L_I C, 0]], G = [L_P; L_I]), the measurement matrix C, the force rows F = [H_x | H_phi | 0] and
the exact zero-order-hold map [Phi | Gam] at the FMU's default step; the speed bands and the
hysteresis (docs/runtime/motorcycle_fault_observer.md).
"""
from __future__ import annotations

from ...fmu_src.spec import DEFAULT_STEP
from ...fmu_src.linalg import matmul, matrix, zoh_map

MEASUREMENTS = ("steer_angle", "yaw_rate", "roll_rate")
STATES = ("vy", "yaw_rate", "roll_rate", "steer_angle", "steer_rate")
N, NF, NY = 5, 2, 3


def _mode(k: int, mode: dict) -> dict:
    """{M, G, C, F, map_h0} of mode k (0-based) from its model and gains, validated."""
    what = f"mode {k + 1}"
    mod, g = mode["model"], mode["gains"]
    A = matrix(mod["A"], N, N, f"{what} A")
    Ef = matrix(mod["E_f"], N, NF, f"{what} E_f")
    C = matrix(mod["C"], NY, N, f"{what} C")
    Hx = matrix(mod["H_x"], 2, N, f"{what} H_x")
    Hphi = matrix([mod["H_phi"]], 1, 2, f"{what} H_phi")[0]
    LP = matrix(g["L_P"], N, NY, f"{what} L_P")
    LI = matrix(g["L_I"], NF, NY, f"{what} L_I")
    LPC, LIC = matmul(LP, C), matmul(LI, C)
    # eq. (13): s' = [[A - L_P C, E_f], [-L_I C, 0]] s + [L_P; L_I] y
    M = [[A[i][j] - LPC[i][j] for j in range(N)] + Ef[i] for i in range(N)]
    M += [[-LIC[i][j] for j in range(N)] + [0.0] * NF for i in range(NF)]
    G = LP + LI
    return {"M": M, "G": G, "C": C,
            # forces [Ff, Fr] = H_x x^ + H_phi phi^ (phi^ = s[N]; the non-linear parts are not estimated)
            "F": [Hx[r] + [Hphi[r], 0.0] for r in range(2)],
            "map_h0": zoh_map(M, G, DEFAULT_STEP)}


def compute(data: dict) -> dict:
    """{"h0", "measurements", "edges", "hysteresis", "modes": [{M, G, C, F, map_h0}]}, or a ValueError naming
    the culprit (mode, matrix, switching)."""
    try:
        st = data["structure"]
        if list(st["measurements"]) != list(MEASUREMENTS):
            raise ValueError(f"design file: measurements {st['measurements']} are not {list(MEASUREMENTS)}")
        if list(st["states"]) != list(STATES):
            raise ValueError(f"design file: states {st['states']} are not {list(STATES)}")
        sw = data["switching"]
        edges = [float(e) for e in sw["edges"]]
        hyst = float(sw.get("hysteresis", 0.0))
        modes = [_mode(k, mode) for k, mode in enumerate(data["modes"])]
    except (KeyError, TypeError, IndexError) as exc:
        raise ValueError(f"design file lacks {exc!r} needed by the paper-003 observer") from exc
    if len(edges) != len(modes) + 1 or edges != sorted(edges):
        raise ValueError(f"design file: switching edges {edges} do not bound {len(modes)} modes")
    if not (hyst >= 0 and hyst != float("inf")):
        raise ValueError(f"design file: switching hysteresis must be >= 0, got {hyst}")
    return {"h0": DEFAULT_STEP, "measurements": list(MEASUREMENTS), "edges": edges, "hysteresis": hyst,
            "modes": modes}
