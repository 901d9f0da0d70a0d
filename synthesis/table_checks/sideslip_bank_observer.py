"""Independent checks of paper 000's runtime tables (``synthesis.tables.sideslip_bank_observer``).

From the design's T, N, C, gains and model alone (numpy, not the series arithmetic that built the
tables): M(v), G(v) of eq. (5) at sample speeds against the tables' coefficients, and every step map
against one classical RK4 substep matrix raised to the number of substeps, at both ends and the
center of every Taylor interval. The limits are stated below; a corrupted table fails them.
"""
from __future__ import annotations

import math

import numpy as np

#: |table - numpy| / ||map||_inf: the tables' truncation bound (1e-16) plus the rounding of two
#: differently ordered computations of the composite map (measured below 1e-15 on the designs)
MAP_LIMIT = 1e-13
#: |table - numpy| / ||[M | G]||_inf for the model coefficients (both a few products of the design)
MODEL_LIMIT = 1e-13


def _model(d: dict, i: int, v: float, frozen: bool):
    """M(v), G(v) of mode i, eq. (5): s = [z; w^], w = [y; delta], x^ = z + N y,
    z' = T A x^ + T B delta + T F w^ + K_P (y - C x^), w^' = K_I (y - C x^) (0 if frozen)."""
    st, mode = d["structure"], d["modes"][i]
    T, N, C = (np.asarray(st[k], dtype=float) for k in ("T", "N", "C"))
    p0 = int(st.get("first_power", 0))          # the model's powers of v start at p0 (-1: a term in vx)
    A, B, F = (sum(np.asarray(P, dtype=float) * v**(k + p0) for k, P in enumerate(mode["model"][key]))
               for key in "ABF")
    KP, KI = (np.asarray(mode["gains"][k], dtype=float) for k in ("K_P", "K_I"))
    n, ny = N.shape
    Pi = T @ A - KP @ C
    M = np.zeros((n + 1, n + 1))
    G = np.zeros((n + 1, ny + 1))
    M[:n, :n], M[:n, n] = Pi, (T @ F)[:, 0]
    G[:n, :ny], G[:n, ny] = Pi @ N + KP, (T @ B)[:, 0]
    if not frozen:
        M[n, :n], G[n, :ny] = -(KI @ C)[0], (KI @ (np.eye(ny) - C @ N))[0]
    return M, G


def _step_map(M, G, h: float, max_step: float, foh: bool) -> np.ndarray:
    """Top rows (those of s) of the composite affine map of ceil(h / max_step) RK4 substeps of
    s' = M s + G w: [Phi | Gam], or with the first-order hold (w a ramp, increment e over h)
    [Phi | Gam | Gam_e], as the nsub-th power of one substep's (augmented) matrix."""
    ns, nw = G.shape
    if foh:                            # [s; w]' = [[M, G], [0, 0]] [s; w] + [[0], [I / h]] e
        M, G = np.block([[M, G], [np.zeros((nw, ns + nw))]]), np.vstack([np.zeros((ns, nw)), np.eye(nw) / h])
    na = M.shape[0]
    nsub = max(1, math.ceil(h / max_step - 1e-9))
    X = M * (h / nsub)
    R = np.eye(na) + X + X @ X / 2 + X @ X @ X / 6 + X @ X @ X @ X / 24
    S = (h / nsub) * (np.eye(na) + X / 2 + X @ X / 6 + X @ X @ X / 24)
    E = np.block([[R, S @ G], [np.zeros((nw, na)), np.eye(nw)]])
    return np.linalg.matrix_power(E, nsub)[:ns]


def _norm(P: np.ndarray) -> float:
    return float(np.max(np.sum(np.abs(P), axis=1)))


def _constants_mismatch(d: dict, tab: dict, foh: bool) -> float:
    """Sum of |table - design| over the runtime's constants (0: all equal; the model's first power of v
    among them)."""
    sw, val, rt = d["switching"], d.get("validity"), d["runtime"]
    want = [np.asarray(d["structure"]["N"], dtype=float), float(rt["max_step"]), float(rt.get("vx_hold", 1.0)),
            float(d["structure"].get("first_power", 0))]
    got = [np.asarray(tab["N"], dtype=float), tab["max_step"], tab["vx_hold"], float(tab.get("first_power", 0))]
    if sw["kind"] == "speed_bands":
        want += [np.asarray(sw["edges"], dtype=float), sw["edges"][0], sw["edges"][-1]]
        got += [np.asarray(tab["switching"].get("edges", np.nan)), *tab["grid"]]
    else:
        ranges = np.array([m["model_speed"]["range"] for m in d["modes"] if m["model_speed"]["kind"] == "measured"])
        want += [sw["lf"], sw["lr"], sw["alpha_star"] + sw["hysteresis"], sw["alpha_star"] - sw["hysteresis"],
                 ranges[:, 0].min(), ranges[:, 1].max()]
        got += [tab["switching"].get(k, np.nan) for k in ("lf", "lr", "up", "down")] + list(tab["grid"])
    tv = tab["validity"]
    if (val is None) != (tv is None):
        return math.inf
    if val is not None:
        want += [val["alpha_max"], val["ay_max"], val["release"] * val["alpha_max"], val["release"] * val["ay_max"],
                 val.get("lf", sw.get("lf")), val.get("lr", sw.get("lr")), bool(val.get("freeze_integral", False))]
        got += [tv[k] for k in ("alpha_max", "ay_max", "alpha_release", "ay_release", "lf", "lr", "freeze_integral")]
    pairs = [(np.asarray(a, dtype=float), np.asarray(b, dtype=float)) for a, b in zip(want, got)]
    mismatch = sum(float(np.max(np.abs(a - b), initial=0.0)) if a.shape == b.shape else math.inf for a, b in pairs)
    return mismatch + (tab["input_hold"] != ("first_order" if foh else "zero_order"))


def checks(data: dict) -> list:
    from ..certificate import Check

    def le(name, value, limit, detail=""):
        return Check(name, float(value), float(limit), bool(value <= limit), "<=", detail)

    tab = data.get("tables") or {}
    if "maps" not in tab:
        return [le("tables: present in the design file", 1.0, 0.0, "the runtime's tables are missing")]
    modes, nm = data["modes"], len(data["modes"])
    freeze = bool((data.get("validity") or {}).get("freeze_integral", False))
    foh = data["runtime"].get("input_hold", "zero_order") == "first_order"
    h, max_step = float(tab["step"]), float(data["runtime"]["max_step"])
    nmap = nm * (2 if freeze else 1)
    out = [le("tables: map indices (modes, frozen-integral maps)", abs(len(tab["maps"]) - nmap)
              + abs(len(tab["M"]) - nmap) + abs(len(tab["G"]) - nmap), 0.0),
           le("tables: N, switching, grid, validity, vx_hold, max_step, input hold and first power of v are the design's",
              _constants_mismatch(data, tab, foh), 0.0)]
    p0 = int(tab.get("first_power", 0))
    if len(tab["maps"]) != nmap:
        return out
    for idx in range(nmap):
        i = idx % nm
        what = f"mode {i + 1}" + (" (integral frozen)" if idx >= nm else "")
        ms = modes[i]["model_speed"]
        tm = tab["modes"][i]
        if ms["kind"] == "fixed":
            speeds = [float(ms["value"])]
            layout = abs(tm["fixed_v"] - 1.0 / speeds[0])
        else:
            lo, hi = (float(x) for x in ms["range"])
            speeds = [lo, 0.5 * (lo + hi), hi]
            layout = abs(tm["vx_range"][0] - lo) + abs(tm["vx_range"][1] - hi)
        model_err = 0.0
        for vx in speeds:
            M, G = _model(data, i, 1.0 / vx, idx >= nm)
            Mt = sum(np.asarray(P) * (1.0 / vx) ** (k + p0) for k, P in enumerate(tab["M"][idx]))
            Gt = sum(np.asarray(P) * (1.0 / vx) ** (k + p0) for k, P in enumerate(tab["G"][idx]))
            model_err = max(model_err, _norm(np.hstack([Mt - M, Gt - G])) / _norm(np.hstack([M, G])))
        out.append(le(f"tables: M(v), G(v) of eq. (5) from the design's model and gains, {what}", model_err,
                      MODEL_LIMIT, f"at {len(speeds)} model speed(s)"))
        m = tab["maps"][idx]
        K = len(m["intervals"])
        if ms["kind"] == "fixed":
            points = [(m["intervals"][0], 1.0 / speeds[0])]
        else:
            v_lo, v_hi = 1.0 / hi, 1.0 / lo
            width = v_hi - v_lo
            layout += abs(m["v_lo"] - v_lo) + abs(m["scale"] * width - K if width > 0 else m["scale"])
            points = []
            for k, iv in enumerate(m["intervals"]):
                a, b = v_lo + k * width / K, v_lo + (k + 1) * width / K
                layout += abs(iv["center"] - 0.5 * (a + b)) / max(v_hi, 1e-300)
                points += [(iv, v) for v in (a, iv["center"], b)]
        out.append(le(f"tables: model speed and Taylor intervals cover the range of {what}", layout, 1e-12))
        err = 0.0
        for iv, v in points:
            if iv["coef"] is None:     # this interval runs the RK4 substeps themselves: nothing stored
                continue
            ref = _step_map(*_model(data, i, v, idx >= nm), h, max_step, foh)
            d = v - iv["center"]
            poly = sum(np.asarray(P) * d**j for j, P in enumerate(iv["coef"]))
            err = max(err, _norm(poly - ref) / _norm(ref) if poly.shape == ref.shape else math.inf)
        out.append(le(f"tables: step map {what} at h = {h:g} s equals the RK4 substeps", err, MAP_LIMIT,
                      f"{K} interval(s), {len(points)} points in v = 1/vx"))
    return out
