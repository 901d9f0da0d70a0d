"""What paper 000's switched PI observer evaluates (eq. 5), computed once from its design file.

With s = [z; w^] and w = [y; delta], s' = M(v) s + G(v) w, M and G polynomials in v = 1/vx (with the
model's relaxed axle forces, Laurent polynomials from v**-1: ``first_power``).
``compute`` returns the coefficient matrices of M, G per map index (the mode; with a frozen integral
n_modes + mode, w^'s rows zero), N, the switching, clamp and validity constants, and the step maps
over the FMU's default step ``STEP``: per map index the exact composite map of the RK4 substeps
(fixed model speed) or a table of Taylor polynomials in v - center on equal intervals of the mode's
clamped range of v (measured model speed; ``series.interval_coefficients``; a model with a term in vx
has no table: the runtimes take the RK4 substeps at every step). Plain JSON data; the
behaviour the runtimes give these numbers: ``docs/runtime/sideslip_bank_observer.md``.
"""
from __future__ import annotations

import math

from . import series
from .series import add, floats, matmul, scale, zeros

#: s, the FMU's default communication step (the model description's): the step the maps are for
STEP = 0.005
#: measured-speed modes: the degree the interval count aims at, the truncation bound relative to
#: ||[Phi | Gam]||_inf (below the map's own rounding; 1e-13 was measured to accumulate to 2e-12
#: through the slow bank integrator), the intervals per map at most, and the longest step (in RK4
#: substeps) given a table (longer: the RK4 substeps)
TAYLOR_DEGREE = 4
TAYLOR_TOL = 1e-16
MAX_INTERVALS = 512
TAYLOR_MAX_SUBSTEPS = 64
INPUT_HOLDS = ("zero_order", "first_order")


def _number(x, what: str, lo: float = -math.inf, hi: float = math.inf, open_lo: bool = False) -> float:
    """float(x), finite and in [lo, hi] (or (lo, hi]), else a ValueError naming ``what``."""
    if isinstance(x, bool):
        raise ValueError(f"design {what} must be a number, got {x!r}")
    x = float(x)
    if not (math.isfinite(x) and (x > lo if open_lo else x >= lo) and x <= hi):
        raise ValueError(f"design {what} must be finite and in {'(' if open_lo else '['}{lo:g}, {hi:g}], got {x!r}")
    return x


def _model_speed(i: int, ms: dict) -> dict:
    """Mode i's model speed: "fixed": v = 1/value; "measured": the range [lo, hi] (m/s) the measured
    speed is clamped to."""
    if ms["kind"] == "fixed":
        return {"fixed_v": 1.0 / _number(ms["value"], f"modes[{i}].model_speed.value", 0.0, open_lo=True),
                "vx_range": None}
    if ms["kind"] == "measured":
        lo, hi = ms["range"]
        lo = _number(lo, f"modes[{i}].model_speed.range[0]", 0.0, open_lo=True)
        hi = _number(hi, f"modes[{i}].model_speed.range[1]", lo)
        return {"fixed_v": None, "vx_range": [lo, hi]}
    raise ValueError(f"design modes[{i}].model_speed.kind must be 'fixed' or 'measured', got {ms['kind']!r}")


def _switching(sw: dict) -> dict:
    if sw["kind"] == "speed_bands":
        return {"kind": "speed_bands", "edges": [float(e) for e in sw["edges"]]}
    # departure from eq. (27): a hysteresis band of +-hysteresis around alpha* (up, down)
    return {"kind": "tire_slip", "lf": float(sw["lf"]), "lr": float(sw["lr"]),
            "up": sw["alpha_star"] + sw["hysteresis"], "down": sw["alpha_star"] - sw["hysteresis"]}


def _grid(switching: dict, modes: list[dict]) -> list[float]:
    """The design grid (m/s): the band edges' ends, or the union of the modes' measured ranges."""
    if switching["kind"] == "speed_bands":
        return [switching["edges"][0], switching["edges"][-1]]
    ranges = [m["vx_range"] for m in modes if m["vx_range"] is not None]
    if not ranges:
        raise ValueError("design: the tire-switched observer needs modes with a measured model speed")
    return [min(r[0] for r in ranges), max(r[1] for r in ranges)]


def _validity(val, sw: dict):
    """data["validity"]: the domain where the estimates are declared valid; None: valid = 1 always."""
    if val is None:
        return None
    a_max = _number(val["alpha_max"], "validity.alpha_max", 0.0, open_lo=True)
    ay_max = _number(val["ay_max"], "validity.ay_max", 0.0, open_lo=True)
    release = _number(val["release"], "validity.release", 0.0, 1.0, open_lo=True)
    if release >= 1.0:
        raise ValueError(f"design validity.release must be in (0, 1), got {release!r}")
    return {"alpha_max": a_max, "ay_max": ay_max, "alpha_release": release * a_max, "ay_release": release * ay_max,
            "lf": _number(val["lf"] if "lf" in val else sw["lf"], "validity.lf"),
            "lr": _number(val["lr"] if "lr" in val else sw["lr"], "validity.lr"),
            "freeze_integral": bool(val.get("freeze_integral", False))}


def coefficients(mode: dict, T, N, C, first_power: int = 0):
    """Coefficient matrices (in v = 1/vx) of M(v), G(v) with s' = M s + G [y; u] for one mode: eq. (5)
    in the form z' = T A x^ + T B u + T F w^ + K_P (y - C x^), w^' = K_I (y - C x^), x^ = z + N y
    (= eq. (5) with Pi = T A - K_P C, K_p = K_P + Pi N). Coefficient k multiplies v**(k + first_power)
    (-1 for the model with relaxed axle forces: a term in vx)."""
    model = {k: [floats(P) for P in mode["model"][k]] for k in ("A", "B", "F")}
    KP, KI = floats(mode["gains"]["K_P"]), floats(mode["gains"]["K_I"])
    n, ny = len(T), len(C)
    CN = matmul(C, N)
    I_CN = [[(1.0 if r == c else 0.0) - CN[r][c] for c in range(ny)] for r in range(ny)]
    Mc, Gc = [], []
    for k in range(max(len(v) for v in model.values())):
        A = model["A"][k] if k < len(model["A"]) else zeros(n, n)
        B = model["B"][k] if k < len(model["B"]) else zeros(n, 1)
        F = model["F"][k] if k < len(model["F"]) else zeros(n, 1)
        TA, TB, TF = matmul(T, A), matmul(T, B), matmul(T, F)
        TAN = matmul(TA, N)
        if k + first_power == 0:
            # y enters through T A N y + K_P (I - C N) y (z rows) and K_I (I - C N) y (w row)
            TA, TAN = add(TA, scale(matmul(KP, C), -1.0)), add(TAN, matmul(KP, I_CN))
            w_M, w_G = [-x for x in matmul(KI, C)[0]] + [0.0], matmul(KI, I_CN)[0] + [0.0]
        else:
            w_M, w_G = [0.0] * (n + 1), [0.0] * (ny + 1)
        Mc.append([TA[r] + [TF[r][0]] for r in range(n)] + [w_M])
        Gc.append([TAN[r] + [TB[r][0]] for r in range(n)] + [w_G])
    return Mc, Gc


def substeps(h: float, max_step: float) -> tuple[int, float]:
    """RK4 substeps of a step h: n = ceil(h / max_step) (less a hair for rounding), hs = h / n."""
    nsub = max(1, math.ceil(h / max_step - 1e-9))
    return nsub, h / nsub


def step_map(Mc, Gc, mode: dict, nrow: int, max_step: float, h: float, foh: bool, first_power: int = 0) -> dict:
    """The step map of one map index over h: {"v_lo", "scale", "intervals": [{"center", "coef"}]};
    coef[j][r][c] the coefficient of (v - center)**j in row r (of s), column c (of [s; w], first-order
    hold [s; w; e]), None where the RK4 substeps run. Fixed model speed: one interval, degree 0.
    A model with a term in vx (``first_power`` < 0): one interval, the RK4 substeps (the series
    arithmetic and its truncation bound are for polynomials in v)."""
    nsub, hs = substeps(h, max_step)
    hold = h if foh else None
    if first_power < 0:
        if mode["fixed_v"] is not None or mode["vx_range"] is None:
            raise ValueError("design: a model with a term in vx needs modes with a measured model speed")
        lo, hi = mode["vx_range"]
        v_lo, v_hi = 1.0 / hi, 1.0 / lo
        return {"v_lo": v_lo, "scale": 1.0 / (v_hi - v_lo) if v_hi > v_lo else 0.0,
                "intervals": [{"center": 0.5 * (v_lo + v_hi), "coef": None}]}
    if mode["fixed_v"] is not None:
        v = mode["fixed_v"]
        M, G = series.shift(Mc, v)[0], series.shift(Gc, v)[0]
        return {"v_lo": v, "scale": 0.0, "intervals": [{"center": v, "coef": [series.fixed_map(M, G, nsub, hs, hold)[:nrow]]}]}
    lo, hi = mode["vx_range"]
    v_lo, v_hi = 1.0 / hi, 1.0 / lo
    taylor = nsub <= TAYLOR_MAX_SUBSTEPS
    K = series.interval_count(Mc, Gc, v_lo, v_hi, nsub, hs, TAYLOR_DEGREE, TAYLOR_TOL, MAX_INTERVALS, hold) \
        if taylor else 1
    width = v_hi - v_lo
    intervals = []
    for k in range(K):
        center, kept = series.interval_coefficients(Mc, Gc, v_lo, v_hi, K, k, nsub, hs, TAYLOR_DEGREE, TAYLOR_TOL,
                                                    hold) if taylor else (v_lo + 0.5 * width, None)
        intervals.append({"center": center, "coef": kept})
    return {"v_lo": v_lo, "scale": K / width if width > 0 else 0.0, "intervals": intervals}


def compute(data: dict) -> dict:
    """The tables of a paper-000 design dict (ValueError naming the culprit for a design it refuses)."""
    try:
        st, modes, rt = data["structure"], data["modes"], data["runtime"]
        T, N, C = floats(st["T"]), floats(st["N"]), floats(st["C"])
        max_step = float(rt["max_step"])
        vx_hold = float(rt.get("vx_hold", 1.0))
        input_hold = rt.get("input_hold", "zero_order")
        switching = _switching(data["switching"])
        speeds = [_model_speed(i, m["model_speed"]) for i, m in enumerate(modes)]
        grid = _grid(switching, speeds)
        validity = _validity(data.get("validity"), data["switching"])
        first_power = st.get("first_power", 0)
        if isinstance(first_power, bool) or first_power not in (0, -1):
            raise ValueError(f"design structure.first_power must be 0 or -1, got {first_power!r}")
        Mc, Gc = map(list, zip(*(coefficients(m, T, N, C, first_power) for m in modes)))
    except (KeyError, TypeError) as exc:
        raise ValueError(f"design file lacks {exc} needed by the paper-000 observer runtime") from exc
    if input_hold not in INPUT_HOLDS:
        raise ValueError(f"design runtime.input_hold must be one of {', '.join(INPUT_HOLDS)}, got {input_hold!r}")
    if not (0 < max_step <= 0.01):
        raise ValueError(f"design runtime.max_step must be in (0, 0.01] s, got {max_step}")
    if not (math.isfinite(vx_hold) and vx_hold > 0):        # 0 would reach 1/vx at vx = 0
        raise ValueError(f"design runtime.vx_hold must be finite and > 0 m/s, got {vx_hold}")
    if switching["kind"] == "speed_bands":
        edges = switching["edges"]
        if len(edges) != len(modes) + 1 or any(b <= a for a, b in zip(edges, edges[1:])):
            raise ValueError(f"design switching.edges must be {len(modes) + 1} increasing speeds (one band per "
                             f"mode), got {edges}")
    if validity is not None and validity["freeze_integral"]:
        # map indices n_modes + i: mode i with the integral action frozen (w^ rows of M and G zero)
        Mc += [[P[:-1] + [[0.0] * len(P[-1])] for P in c] for c in Mc[: len(modes)]]
        Gc += [[P[:-1] + [[0.0] * len(P[-1])] for P in c] for c in Gc[: len(modes)]]
    foh = input_hold == "first_order"
    nrow = len(T) + 1
    maps = [step_map(Mc[idx], Gc[idx], speeds[idx % len(modes)], nrow, max_step, STEP, foh, first_power)
            for idx in range(len(Mc))]
    extra = {"first_power": first_power} if first_power else {}      # (absent: 0, the files before it)
    return {**extra, "step": STEP, "max_step": max_step, "vx_hold": vx_hold, "input_hold": input_hold, "N": N,
            "M": Mc, "G": Gc, "modes": speeds, "switching": switching, "grid": grid, "validity": validity,
            "maps": maps}
