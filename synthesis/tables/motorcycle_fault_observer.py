"""Tables of paper 003's switched PI observer (motorcycle roll angle and rider torque), eq. (13).

Per mode the observer as one linear ODE s' = M s + G y in s = [x^; f^] (M = [[A - L_P C, E_f],
[-L_I C, 0]], G = [L_P; L_I]), the measurement matrix C, the force rows F = [H_x | H_phi | 0] and
the exact zero-order-hold map [Phi | Gam] at the FMU's default step; the speed bands and the
hysteresis (docs/runtime/motorcycle_fault_observer.md).

A measured-speed design (``synthesis.motorcycle_fault_observer_lpv``: the roll angle a state, a PMI
torque) has per band M(v) = M + v M_vx + M_ivx / v, G(v) and F(v) likewise, the model speed v the
measured one clamped to ``vx_range``; no stored map (it depends on v).
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


def _measured_mode(k: int, mode: dict, model: dict, n: int, nt: int) -> dict:
    """{M, M_vx, M_ivx, G, G_vx, G_ivx, C, F, F_vx, F_ivx, vx_range} of band k (0-based): per basis
    function b in (1, vx, 1/vx), M_b = A_b - L_b C (the observer is linear in the coefficients),
    G_b = L_b, F_b = [H_b | 0] (forces from x^ only)."""
    what = f"band {k + 1}"
    na, ny = n + nt, len(MEASUREMENTS)
    C = matrix(model["C"][0], ny, na, "model C")
    out = {"C": [row[:n] for row in C]}
    for b, suffix in enumerate(("", "_vx", "_ivx")):
        A = matrix(model["A"][b], na, na, f"model A[{b}]")
        L = matrix(mode["gains"]["L"][b], na, ny, f"{what} L[{b}]")
        LC = matmul(L, C)
        out["M" + suffix] = [[A[i][j] - LC[i][j] for j in range(na)] for i in range(na)]
        out["G" + suffix] = L
        H = matrix(model["H"][b], 2, n, f"model H[{b}]")
        out["F" + suffix] = [H[r] + [0.0] * nt for r in range(2)]
    lo, hi = (float(x) for x in mode["band"])
    if not (0 < lo < hi < float("inf")):
        raise ValueError(f"design file: {what} range [{lo}, {hi}] must satisfy 0 < lo < hi")
    out["vx_range"] = [lo, hi]
    return out


def compute(data: dict) -> dict:
    """{"h0", "measurements", "edges", "hysteresis", "modes": [{M, G, C, F, map_h0}]}, or a ValueError naming
    the culprit (mode, matrix, switching)."""
    try:
        st = data["structure"]
        if list(st["measurements"]) != list(MEASUREMENTS):
            raise ValueError(f"design file: measurements {st['measurements']} are not {list(MEASUREMENTS)}")
        sw = data["switching"]
        edges = [float(e) for e in sw["edges"]]
        hyst = float(sw.get("hysteresis", 0.0))
        measured = data.get("method") == "measured_speed"
        if measured:
            n, nt = len(STATES) + 1, len(st["faults"])
            if list(st["states"]) != list(STATES) + ["roll_angle"]:
                raise ValueError(f"design file: states {st['states']} are not {list(STATES) + ['roll_angle']}")
            modes = [_measured_mode(k, mode, data["model"], n, nt) for k, mode in enumerate(data["modes"])]
        else:
            if list(st["states"]) != list(STATES):
                raise ValueError(f"design file: states {st['states']} are not {list(STATES)}")
            modes = [_mode(k, mode) for k, mode in enumerate(data["modes"])]
    except (KeyError, TypeError, IndexError) as exc:
        raise ValueError(f"design file lacks {exc!r} needed by the paper-003 observer") from exc
    if len(edges) != len(modes) + 1 or edges != sorted(edges):
        raise ValueError(f"design file: switching edges {edges} do not bound {len(modes)} modes")
    if not (hyst >= 0 and hyst != float("inf")):
        raise ValueError(f"design file: switching hysteresis must be >= 0, got {hyst}")
    return {"h0": DEFAULT_STEP, "measurements": list(MEASUREMENTS), "edges": edges, "hysteresis": hyst,
            "measured": measured, "modes": modes}
