"""Emitter of the native C model of paper 000's switched PI observer (``fmu_src/c/pi_observer.c``).

Mirrors ``fmu_src/pi_observer.py`` (its module docstring defines the behaviour): the design file is
checked and preprocessed by that runtime itself (a design it refuses raises its ValueError here),
so the C file gets bit-for-bit the Python runtime's matrices and step maps. With s = [z; w^]
(eq. (5), ERRATA 000 form) and w = [y; delta], s' = M(v) s + G(v) w, v = 1/vx:

    PI_MC[idx][k], PI_GC[idx][k]   the coefficient of v**k of M, G for map index idx (the mode; with
                                   a frozen integral, idx = n_modes + mode: w^'s row zero)
    PI_N                           x^ = z + N y
    PI_EDGES                       speed bands: the band edges (eq. 25); tire modes: the design grid
    PI_FIXED_V, PI_VX_LO/HI        per mode: v of a fixed model speed (0 if measured), the measured
                                   speed's clamp range (m/s)
    PI_TAB_*                       the step maps over the FMU's default step PI_H0 = 0.005 s
                                   (``framework.DEFAULT_STEP``), n = ceil(h / max_step) RK4 substeps
                                   composed: per map index a table of PI_TAB_K intervals of v, each
                                   the Taylor polynomial in d = v - center of [Phi | Gam (| Gam_e)]
                                   with the kept coefficients of the runtime's ``_TireTable`` (a
                                   fixed-speed index: one interval, the exact composite map of
                                   ``_fixed_map``, degree 0). PI_TAB_COEF[t][j][c][r]: the
                                   coefficient of d**j in row r, column c of interval t (columns:
                                   s, w, and with the first-order hold the increments e; zero
                                   beyond the interval's degree, up to PI_DEG, the largest).
                                   PI_TAB_RK4[t]: no polynomial meets the runtime's bound there (the
                                   interval runs the RK4 substeps).
Also the switching (PI_SLIP_*: lf, lr (m), alpha* +- hysteresis (rad); zeros for speed bands), the
validity limits (PI_A_MAX, PI_AY_MAX, their release values, lf, lr; zeros without validity), the
design grid, max_step and the ModelExchange event indicators' count (see pi_observer.c).
Emitting costs ~10 ms of the runtime's series arithmetic per table interval: 1.5 s for the default
speed design (146 intervals), 3 s for the tire design (272).
"""
from __future__ import annotations

from ..fmu_src.framework import DEFAULT_STEP
from ..fmu_src.pi_observer import SwitchedPIObserver
from ..fmu_src.spec import Var
from .emit import CModel, c_array, c_define, nonzero, structure

SOURCE = "pi_observer.c"

#: ModelExchange states: s = [z (4); w^ (1)] (eq. 5), the order of the runtime's state vector
STATES = (
    Var("x_z_beta", "rad", "observer state z, sideslip row (x^ = z + N y)"),
    Var("x_z_yaw_rate", "rad/s", "observer state z, yaw rate row (x^ = z + N y)"),
    Var("x_z_roll_angle", "rad", "observer state z, roll angle row (x^ = z + N y)"),
    Var("x_z_roll_rate", "rad/s", "observer state z, roll rate row (x^ = z + N y)"),
    Var("x_bank_hat", "rad", "observer state w^: road bank angle estimate (integral action)"),
)


def _event_indicators(rt: SwitchedPIObserver) -> int:
    """vx - vx_hold; vx - edge per speed-band edge or design-grid end; the tire premise; the two
    validity limits (see pi_observer.c)."""
    edges = len(rt._edges) if rt._speed_bands else 2
    return 1 + edges + (0 if rt._speed_bands else 1) + (2 if rt._val is not None else 0)


def _tables(rt: SwitchedPIObserver, h: float):
    """Per map index (vlo, scale, [(center, kept or None), ...]) at step h: the runtime's own
    maps, fixed-speed indices as one interval of degree 0."""
    out = []
    for idx in range(len(rt._Mc)):
        v = rt._fixed_v[idx % rt._nm]
        if v is not None:
            out.append((v, 0.0, [(v, rt._fixed_map(idx, h)[:1])]))
        else:
            tab = rt._table(idx, h)
            out.append((tab.v_lo, tab.scale, [tab.coefficients(k) for k in range(tab.K)]))
    return out


def _coef_block(kept, ns: int, ncol: int, deg: int) -> list[list[list[float]]]:
    """[j][c][r] of one interval (zeros beyond its degree)."""
    block = [[[0.0] * ns for _ in range(ncol)] for _ in range(deg + 1)]
    for j, P in enumerate(kept or ()):
        for r in range(ns):
            for c in range(ncol):
                block[j][c][r] = P[r][c]
    return block


def emit(data: dict) -> CModel:
    rt = SwitchedPIObserver(data, {})          # the runtime's checks: ValueError naming the culprit
    n, ny, nm = rt.n, rt.ny, rt._nm
    if (n, ny) != (4, 3) or len(rt.N) != 4 or any(len(row) != 3 for row in rt.N):
        raise ValueError(f"paper-000 observer: the C model needs 4 states and 3 measurements (N 4 x 3), "
                         f"got n = {n}, ny = {ny}")
    ns, nw = n + 1, ny + 1
    ncol = ns + nw + (nw if rt._foh else 0)
    nv = max(len(c) for c in rt._Mc)
    zero_m, zero_g = [[0.0] * ns for _ in range(ns)], [[0.0] * nw for _ in range(ns)]
    mc = [list(c) + [zero_m] * (nv - len(c)) for c in rt._Mc]
    gc = [list(c) + [zero_g] * (nv - len(c)) for c in rt._Gc]
    for idx, (M, G) in enumerate(zip(mc, gc)):
        if any(len(P) != ns or any(len(row) != ns for row in P) for P in M) or \
                any(len(P) != ns or any(len(row) != nw for row in P) for P in G):
            raise ValueError(f"paper-000 observer: mode {idx % nm + 1}'s model A, B, F must be 4 x 4, 4 x 1, 4 x 1")

    if rt._speed_bands and (len(rt._edges) != nm + 1 or any(b <= a for a, b in zip(rt._edges, rt._edges[1:]))):
        raise ValueError(f"paper-000 observer: switching.edges must be {nm + 1} increasing speeds (one band per "
                         f"mode), got {rt._edges}")
    h0 = float(DEFAULT_STEP)
    tables = _tables(rt, h0)
    deg = max((len(kept) - 1 for _, _, pieces in tables for _, kept in pieces if kept is not None), default=0)
    first, centers, rk4, coef = [], [], [], []
    for _, _, pieces in tables:
        first.append(len(centers))
        for center, kept in pieces:
            centers.append(center)
            rk4.append(0 if kept is not None else 1)
            coef.append(_coef_block(kept, ns, ncol, deg))

    fixed_v = [v if v is not None else 0.0 for v in rt._fixed_v]
    vx_lo = [r[0] if r is not None else 0.0 for r in rt._vx_range]
    vx_hi = [r[1] if r is not None else 0.0 for r in rt._vx_range]
    edges = rt._edges if rt._speed_bands else [rt._lo, rt._hi]
    lf, lr, up, down = rt._slip if not rt._speed_bands else (0.0, 0.0, 0.0, 0.0)
    a_max, ay_max, a_rel, ay_rel, val_lf, val_lr = rt._val if rt._val is not None else (0.0,) * 6
    header = "".join([
        "/* paper 000, eq. (5): s' = M(v) s + G(v) w, s = [z; w^], w = [y; delta], v = 1/vx */\n",
        c_define("PI_N_MODES", nm), c_define("PI_NMAP", len(rt._Mc)), c_define("PI_NS", ns),
        c_define("PI_NY", ny), c_define("PI_NW", nw), c_define("PI_NV", nv),
        c_define("PI_FOH", rt._foh), c_define("PI_NCOL", ncol),
        c_define("PI_SPEED_BANDS", rt._speed_bands), c_define("PI_NEDGES", len(edges)),
        c_define("PI_VALIDITY", rt._val is not None), c_define("PI_FREEZE", rt._freeze),
        c_define("PI_MAX_STEP", rt.max_step), c_define("PI_H0", h0),
        c_define("PI_GRID_LO", rt._lo), c_define("PI_GRID_HI", rt._hi),
        c_define("PI_SLIP_LF", float(lf)), c_define("PI_SLIP_LR", float(lr)),
        c_define("PI_SLIP_UP", float(up)), c_define("PI_SLIP_DOWN", float(down)),
        c_define("PI_A_MAX", a_max), c_define("PI_AY_MAX", ay_max),
        c_define("PI_A_REL", a_rel), c_define("PI_AY_REL", ay_rel),
        c_define("PI_VAL_LF", val_lf), c_define("PI_VAL_LR", val_lr),
        c_define("PI_NEI", _event_indicators(rt)),
        c_define("PI_DEG", deg), c_define("PI_NTAB", len(centers)),
        c_array("PI_N", rt.N),
        c_array("PI_MC", mc), c_array("PI_GC", gc),
        c_array("PI_EDGES", edges),
        c_array("PI_FIXED_V", fixed_v), c_array("PI_VX_LO", vx_lo), c_array("PI_VX_HI", vx_hi),
        c_array("PI_TAB_FIRST", first, "int"),
        c_array("PI_TAB_K", [len(pieces) for _, _, pieces in tables], "int"),
        c_array("PI_TAB_VLO", [t[0] for t in tables]),
        c_array("PI_TAB_SCALE", [t[1] for t in tables]),
        c_array("PI_TAB_CENTER", centers),
        c_array("PI_TAB_RK4", rk4, "int"),
        c_array("PI_TAB_COEF", coef),
    ])
    return CModel(header=header, states=STATES, n_event_indicators=_event_indicators(rt),
                  dependencies=_dependencies(rt, mc, gc))


#: w = [y; delta] (measurements() in pi_observer.c), y = the first three
MEASURED = ("yaw_rate", "roll_angle", "roll_rate", "delta")
#: x^ = z + N y, row by row (OUT_X in pi_observer.c); bank_angle_hat = w^ (the last state)
ESTIMATES = ("beta_hat", "yaw_rate_hat", "roll_angle_hat", "roll_rate_hat")


def _dependencies(rt: SwitchedPIObserver, mc, gc) -> dict:
    """ModelExchange (model_me_derivatives, me_estimates): s' = M(v) s + G(v) w with M(v) =
    sum_k Mc_k v^k, v = 1/vx for the modes whose model speed follows vx (fixed-speed modes: k = 0
    only), in every map (the modes, and the frozen maps when validity freezes); x^ = z + N y."""
    names = [s.name for s in STATES]
    scheduled = [idx for idx in range(len(mc)) if rt._fixed_v[idx % rt._nm] is None]
    deps = {}
    for i, name in enumerate(names):
        d = nonzero(names, *(P[i] for c in mc for P in c)) | nonzero(MEASURED, *(P[i] for c in gc for P in c))
        if any(float(x) != 0.0 for idx in scheduled for c in (mc[idx][1:], gc[idx][1:]) for P in c for x in P[i]):
            d.add("vx")
        deps[f"der({name})"] = d
    for i, out in enumerate(ESTIMATES):
        deps[out] = {names[i]} | nonzero(MEASURED[:3], rt.N[i])
    deps["bank_angle_hat"] = {names[-1]}
    return structure(deps)
