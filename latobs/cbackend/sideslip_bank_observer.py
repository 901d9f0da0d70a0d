"""Emitter of the native C model of paper 000's switched PI observer (``fmu_src/c/sideslip_bank_observer.c``).

Writes the design's tables (``data["tables"]``, ``synthesis.tables.sideslip_bank_observer``) as C
data, nothing else computed here. With s = [z; w^] (eq. 5) and w = [y; delta], s' = M(v) s + G(v) w,
v = 1/vx:

    PI_MC[idx][k], PI_GC[idx][k]   the coefficient of v**(k + PI_P0) of M, G for map index idx (the
                                   mode; with a frozen integral, idx = n_modes + mode: w^'s row zero);
                                   PI_P0 = -1 for the model with relaxed axle forces (a term in vx)
    PI_N                           x^ = z + N y
    PI_EDGES                       speed bands: the band edges (eq. 25); tire modes: the design grid
    PI_FIXED_V, PI_VX_LO/HI        per mode: v of a fixed model speed (0 if measured), the measured
                                   speed's clamp range (m/s)
    PI_TAB_*                       the step maps over the tables' step PI_H0 (the FMU's default
                                   step): per map index PI_TAB_K intervals of v, each the Taylor
                                   polynomial in d = v - center of [Phi | Gam (| Gam_e)] (a fixed-
                                   speed index: one interval, degree 0). PI_TAB_COEF[t][j][c][r]: the
                                   coefficient of d**j in row r, column c of interval t (columns: s,
                                   w, and with the first-order hold the increments e; zero beyond
                                   the interval's degree, up to PI_DEG, the largest). PI_TAB_RK4[t]:
                                   the interval runs the RK4 substeps.
Also the switching (PI_SLIP_*: lf, lr (m), alpha* +- hysteresis (rad); zeros for speed bands), the
validity limits (PI_A_MAX, PI_AY_MAX, their release values, lf, lr; zeros without validity), the
design grid, max_step and the ModelExchange event indicators' count (see sideslip_bank_observer.c).
"""
from __future__ import annotations

from ..fmu_src.spec import Var
from .emit import CModel, c_array, c_define, nonzero, structure

SOURCE = "sideslip_bank_observer.c"

#: ModelExchange states: s = [z (4, or 6 with the relaxed axle forces); w^ (1)] (eq. 5), the order of
#: the runtime's state vector
STATES = (
    Var("x_z_beta", "rad", "observer state z, sideslip row (x^ = z + N y)"),
    Var("x_z_yaw_rate", "rad/s", "observer state z, yaw rate row (x^ = z + N y)"),
    Var("x_z_roll_angle", "rad", "observer state z, roll angle row (x^ = z + N y)"),
    Var("x_z_roll_rate", "rad/s", "observer state z, roll rate row (x^ = z + N y)"),
    Var("x_bank_hat", "rad", "observer state w^: road bank angle estimate (integral action)"),
)
RELAXED_STATES = STATES[:4] + (
    Var("x_z_front_axle_force", "N", "observer state z, front axle force row (relaxed tire force, x^ = z + N y)"),
    Var("x_z_rear_axle_force", "N", "observer state z, rear axle force row (relaxed tire force, x^ = z + N y)"),
) + STATES[4:]


def _event_indicators(tab: dict) -> int:
    """vx - vx_hold; vx - edge per speed-band edge or design-grid end; the tire premise; the two
    validity limits (see sideslip_bank_observer.c)."""
    bands = tab["switching"]["kind"] == "speed_bands"
    edges = len(tab["switching"]["edges"]) if bands else 2
    return 1 + edges + (0 if bands else 1) + (2 if tab["validity"] is not None else 0)


def _coef_block(kept, ns: int, ncol: int, deg: int) -> list[list[list[float]]]:
    """[j][c][r] of one interval (zeros beyond its degree)."""
    block = [[[0.0] * ns for _ in range(ncol)] for _ in range(deg + 1)]
    for j, P in enumerate(kept or ()):
        for r in range(ns):
            for c in range(ncol):
                block[j][c][r] = P[r][c]
    return block


def emit(data: dict) -> CModel:
    tab = data.get("tables") or {}
    if "maps" not in tab:
        raise ValueError(f"design {data.get('name')!r} lacks the paper-000 observer's tables (data['tables'])")
    N, Mc, Gc, modes = tab["N"], tab["M"], tab["G"], tab["modes"]
    nm, foh, val = len(modes), tab["input_hold"] == "first_order", tab["validity"]
    n, ny = len(N), len(N[0]) if N else 0
    p0 = int(tab.get("first_power", 0))
    if (n, ny, p0) not in ((4, 3, 0), (6, 3, -1)) or any(len(row) != 3 for row in N):
        raise ValueError(f"paper-000 observer: the C model needs 4 states and 3 measurements (N 4 x 3), or 6 "
                         f"states with the relaxed axle forces and a term in vx (first_power -1), got n = {n}, "
                         f"ny = {ny}, first_power = {p0}")
    states = STATES if n == 4 else RELAXED_STATES
    ns, nw = n + 1, ny + 1
    ncol = ns + nw + (nw if foh else 0)
    nv = max(len(c) for c in Mc)
    zero_m, zero_g = [[0.0] * ns for _ in range(ns)], [[0.0] * nw for _ in range(ns)]
    mc = [list(c) + [zero_m] * (nv - len(c)) for c in Mc]
    gc = [list(c) + [zero_g] * (nv - len(c)) for c in Gc]
    for idx, (M, G) in enumerate(zip(mc, gc)):
        if any(len(P) != ns or any(len(row) != ns for row in P) for P in M) or \
                any(len(P) != ns or any(len(row) != nw for row in P) for P in G):
            raise ValueError(f"paper-000 observer: mode {idx % nm + 1}'s model A, B, F must be {n} x {n}, {n} x 1, "
                             f"{n} x 1")
    sw = tab["switching"]
    bands = sw["kind"] == "speed_bands"
    deg = max((len(iv["coef"]) - 1 for m in tab["maps"] for iv in m["intervals"] if iv["coef"] is not None),
              default=0)
    first, centers, rk4, coef = [], [], [], []
    for m in tab["maps"]:
        first.append(len(centers))
        for iv in m["intervals"]:
            centers.append(iv["center"])
            rk4.append(0 if iv["coef"] is not None else 1)
            coef.append(_coef_block(iv["coef"], ns, ncol, deg))

    fixed_v = [m["fixed_v"] if m["fixed_v"] is not None else 0.0 for m in modes]
    vx_lo = [m["vx_range"][0] if m["vx_range"] is not None else 0.0 for m in modes]
    vx_hi = [m["vx_range"][1] if m["vx_range"] is not None else 0.0 for m in modes]
    lo, hi = tab["grid"]
    edges = sw["edges"] if bands else [lo, hi]
    lf, lr, up, down = (0.0,) * 4 if bands else (sw["lf"], sw["lr"], sw["up"], sw["down"])
    a_max, ay_max, a_rel, ay_rel, val_lf, val_lr = (0.0,) * 6 if val is None else (
        val["alpha_max"], val["ay_max"], val["alpha_release"], val["ay_release"], val["lf"], val["lr"])
    header = "".join([
        "/* paper 000, eq. (5): s' = M(v) s + G(v) w, s = [z; w^], w = [y; delta], v = 1/vx */\n",
        c_define("PI_N_MODES", nm), c_define("PI_NMAP", len(Mc)), c_define("PI_NS", ns),
        c_define("PI_NY", ny), c_define("PI_NW", nw), c_define("PI_NV", nv), c_define("PI_P0", p0),
        c_define("PI_FOH", foh), c_define("PI_NCOL", ncol),
        c_define("PI_SPEED_BANDS", bands), c_define("PI_NEDGES", len(edges)),
        c_define("PI_VALIDITY", val is not None), c_define("PI_FREEZE", bool(val and val["freeze_integral"])),
        c_define("PI_MAX_STEP", tab["max_step"]), c_define("PI_H0", float(tab["step"])),
        c_define("PI_GRID_LO", lo), c_define("PI_GRID_HI", hi),
        c_define("PI_SLIP_LF", float(lf)), c_define("PI_SLIP_LR", float(lr)),
        c_define("PI_SLIP_UP", float(up)), c_define("PI_SLIP_DOWN", float(down)),
        c_define("PI_A_MAX", a_max), c_define("PI_AY_MAX", ay_max),
        c_define("PI_A_REL", a_rel), c_define("PI_AY_REL", ay_rel),
        c_define("PI_VAL_LF", val_lf), c_define("PI_VAL_LR", val_lr),
        c_define("PI_NEI", _event_indicators(tab)),
        c_define("PI_DEG", deg), c_define("PI_NTAB", len(centers)),
        c_array("PI_N", N),
        c_array("PI_MC", mc), c_array("PI_GC", gc),
        c_array("PI_EDGES", edges),
        c_array("PI_FIXED_V", fixed_v), c_array("PI_VX_LO", vx_lo), c_array("PI_VX_HI", vx_hi),
        c_array("PI_TAB_FIRST", first, "int"),
        c_array("PI_TAB_K", [len(m["intervals"]) for m in tab["maps"]], "int"),
        c_array("PI_TAB_VLO", [m["v_lo"] for m in tab["maps"]]),
        c_array("PI_TAB_SCALE", [m["scale"] for m in tab["maps"]]),
        c_array("PI_TAB_CENTER", centers),
        c_array("PI_TAB_RK4", rk4, "int"),
        c_array("PI_TAB_COEF", coef),
    ])
    return CModel(header=header, states=states, n_event_indicators=_event_indicators(tab),
                  dependencies=_dependencies(tab, mc, gc, states, p0))


#: w = [y; delta] (measurements() in sideslip_bank_observer.c), y = the first three
MEASURED = ("yaw_rate", "roll_angle", "roll_rate", "delta")
#: x^ = z + N y, row by row (OUT_X in sideslip_bank_observer.c); bank_angle_hat = w^ (the last state)
ESTIMATES = ("beta_hat", "yaw_rate_hat", "roll_angle_hat", "roll_rate_hat")


def _dependencies(tab: dict, mc, gc, states, p0: int) -> dict:
    """ModelExchange (model_me_derivatives, me_estimates): s' = M(v) s + G(v) w with M(v) =
    sum_k Mc_k v^(k + p0), v = 1/vx for the modes whose model speed follows vx (fixed-speed modes: the
    power 0 only), in every map (the modes, and the frozen maps when validity freezes); x^ = z + N y."""
    names = [s.name for s in states]
    scheduled = [idx for idx in range(len(mc)) if tab["modes"][idx % len(tab["modes"])]["fixed_v"] is None]
    deps = {}
    for i, name in enumerate(names):
        d = nonzero(names, *(P[i] for c in mc for P in c)) | nonzero(MEASURED, *(P[i] for c in gc for P in c))
        if any(float(x) != 0.0 for idx in scheduled for c in (mc[idx], gc[idx]) for k, P in enumerate(c)
               if k + p0 != 0 for x in P[i]):
            d.add("vx")
        deps[f"der({name})"] = d
    for i, out in enumerate(ESTIMATES):
        deps[out] = {names[i]} | nonzero(MEASURED[:3], tab["N"][i])
    deps["bank_angle_hat"] = {names[-1]}
    return structure(deps)


def gains(data: dict) -> list:
    """The certified gains as the FMI 3.0 FMU's array constants (``latobs.cbackend.fmi3``): per mode
    the proportional K_P and integral K_I gains of the PI observer (the design file's ``modes[i].gains``)."""
    modes = data["modes"]
    return [("K_P", "proportional gain K_P of each mode (modes x observer states x measurements, SI)",
             [m["gains"]["K_P"] for m in modes]),
            ("K_I", "integral gain K_I of each mode (modes x estimated inputs x measurements, SI)",
             [m["gains"]["K_I"] for m in modes])]
