"""Emitter of the native C model of paper 001's switched interval observer
(``fmu_src/c/interval_observer.c``).

Mirrors ``fmu_src/interval_observer.py``: the design file is checked and preprocessed by that
runtime itself (a design it refuses raises its ValueError here), so the C file gets bit-for-bit the
Python runtime's data:

    IV_A0, IV_A1, IV_B1          the model x' = (A0 + vx A1 + dA) x + vx (B1 + dB1) delta (eq. 9)
    IV_DA_LO/UP, IV_DB1_LO/UP    the elementwise bounds of dA, dB1 over the stiffness box (eq. 18)
    IV_W                         runtime.disturbance_bound (units of x')
    IV_M, IV_IZ, IV_LF, IV_LR    the vehicle (kg, kg m^2, m, m): eq. (8) inverted, the slip angles
    IV_K3, IV_K4F, IV_K4R, IV_DCF, IV_DCR, IV_STIFF_SYMMETRIC
                                 the structured stiffness bound (the runtime's model["stiff"])
    IV_DAMPED, IV_SMOOTH         the rows with an exactly known diagonal (``_damped_rows``) and the
                                 measured rows with a known derivative (``_smooth_rows``)
    IV_EDGES, IV_MODE_VX         the speed bands (eq. 44) and the modes' grid speeds (m/s)
    IV_N, IV_P, IV_E, IV_J, IV_H the gains of eq. (23)/(30)/(33) per mode (N with its rounding-level
                                 negative off-diagonal entries set to 0, as the runtime does)
    IV_ETA, IV_RHO               per mode: the shift with N + eta I >= 0, and the spectral radius
                                 bound that sets the enclosure's substeps (``_core``)
    IV_NU, IV_X0_HALFWIDTH       runtime.y_error_bound, runtime.x0_halfwidth
    IV_MAPS_H0[mode]             (Phi, Gam, Gam1, Gam2) = ``phi_gamma(N, IV_H0, eta, order=3)``, the
                                 runtime's own maps at the default step IV_H0 = 0.005 s; for another
                                 step the C model computes them by the same algorithm
and the runtime's tuning constants (CONSISTENCY_TOL, ENCLOSURE_*, SUBSTEP_RHO_H, and SAMPLED,
SAMPLED_SUBSTEP, SAMPLED_MIN_STEP, SAMPLED_MAX_SUBSTEPS, SAMPLED_DV of the sampled-measurement correction, whose maps
the C model computes per speed and step by the runtime's algorithm, ``sampled_maps``), and

    IV_MAX_COMM_STEP             the longest communication step the design accepts (s): the runtime's
                                 ``max_communication_step()`` (runtime.max_communication_step, which
                                 the synthesis decides by running the runtime); both refuse a longer one

The C model implements the runtime's default bounds (``STIFFNESS = "structured"``, ``PRODUCT =
"hull"``); the emitter refuses the others.
"""
from __future__ import annotations

from ..fmu_src.framework import DEFAULT_STEP
from ..fmu_src.interval_observer import SAMPLED_MAX_NORM, IntervalObserver, _damped_rows, _smooth_rows, phi_gamma
from ..fmu_src.spec import Var
from .emit import CModel, c_array, c_define, nonzero, structure

SOURCE = "interval_observer.c"

_STATE_UNITS = ("m/s", "rad/s", "m/s2", "rad/s2")
_STATE_NAMES = ("vy", "yaw rate", "ay", "yaw acceleration")
#: ModelExchange states: the bounds of xi = P_sigma x of eq. (23), lower then upper
STATES = tuple(
    Var(f"xi_{side}_{k + 1}", unit, f"{side} bound of xi_{k + 1} = (P x)_{k + 1} of the active mode (eq. 23; "
                                    f"units of {name})")
    for side in ("lower", "upper") for k, (unit, name) in enumerate(zip(_STATE_UNITS, _STATE_NAMES)))


#: the active band's two edges (eq. 44), freeze / resume (|vx| against vx_hold), the design grid's
#: two ends (the out-of-grid warning): see model_me_event_indicators in the C file
N_EVENT_INDICATORS = 5


def emit(data: dict) -> CModel:
    rt = IntervalObserver(data)               # the runtime's checks: ValueError naming the culprit
    if rt.STIFFNESS != "structured" or rt.PRODUCT != "hull":
        raise ValueError(f"the C interval observer implements STIFFNESS = 'structured' and PRODUCT = 'hull', "
                         f"got {rt.STIFFNESS!r}, {rt.PRODUCT!r}")
    md, sk = rt.model, rt.model["stiff"]
    if rt.meas != [1, 2] or tuple(sk["rows"]) != (2, 3) or tuple(sk["cols"]) != (0, 1):
        raise ValueError("the C interval observer needs the measurements [r, ay] (states 2, 3) and the "
                         "stiffness in rows 3, 4, columns 1, 2 (eq. 9)")
    if not (isinstance(rt.ENCLOSURE_TRIES, int) and rt.ENCLOSURE_TRIES >= 1):
        raise ValueError(f"ENCLOSURE_TRIES must be an integer >= 1, got {rt.ENCLOSURE_TRIES!r}")
    damped, smooth = _damped_rows(md), _smooth_rows(md, rt.meas)
    maps = [[[list(row) for row in blk] for blk in phi_gamma(m["N"], DEFAULT_STEP, m["eta"], order=3)]
            for m in rt.modes]
    mode = lambda key: [m[key] for m in rt.modes]  # noqa: E731
    header = "".join([
        "/* paper 001, eq. (23): the interval observer's design (latobs/cbackend/interval_observer.py) */\n",
        c_define("IV_N_MODES", len(rt.modes)),
        c_define("IV_H0", float(DEFAULT_STEP)),
        c_define("IV_CONSISTENCY_TOL", float(rt.CONSISTENCY_TOL)),
        c_define("IV_ENCLOSURE_TRIES", rt.ENCLOSURE_TRIES),
        c_define("IV_ENCLOSURE_GROW", float(rt.ENCLOSURE_GROW)),
        c_define("IV_ENCLOSURE_MULT", float(rt.ENCLOSURE_MULT)),
        c_define("IV_SUBSTEP_RHO_H", float(rt.SUBSTEP_RHO_H)),
        c_define("IV_MAX_COMM_STEP", float(rt.max_communication_step())),
        c_define("IV_SAMPLED", bool(rt.SAMPLED)),
        c_define("IV_SAMPLED_SUBSTEP", float(rt.SAMPLED_SUBSTEP)),
        c_define("IV_SAMPLED_MIN_STEP", float(rt.SAMPLED_MIN_STEP)),
        c_define("IV_SAMPLED_MAX_SUBSTEPS", int(rt.SAMPLED_MAX_SUBSTEPS)),
        c_define("IV_SAMPLED_DV", float(rt.SAMPLED_DV)),
        c_define("IV_SAMPLED_MAX_NORM", float(SAMPLED_MAX_NORM)),
        c_define("IV_M", md["m"]), c_define("IV_IZ", md["Iz"]), c_define("IV_LF", md["lf"]),
        c_define("IV_LR", md["lr"]),
        c_define("IV_K3", sk["k3"]), c_define("IV_K4F", sk["k4f"]), c_define("IV_K4R", sk["k4r"]),
        c_define("IV_STIFF_SYMMETRIC", bool(sk["symmetric"])),
        c_array("IV_DCF", list(sk["dcf"])), c_array("IV_DCR", list(sk["dcr"])),
        c_array("IV_A0", md["A0"]), c_array("IV_A1", md["A1"]), c_array("IV_B1", md["B1"]),
        c_array("IV_DA_LO", md["dA_lower"]), c_array("IV_DA_UP", md["dA_upper"]),
        c_array("IV_DB1_LO", md["dB1_lower"]), c_array("IV_DB1_UP", md["dB1_upper"]),
        c_array("IV_W", md["w"]),
        c_array("IV_DAMPED", [int(i in damped) for i in range(4)], "int"),
        c_array("IV_SMOOTH", [int(i in smooth) for i in range(4)], "int"),
        c_array("IV_NU", rt.nu), c_array("IV_X0_HALFWIDTH", rt.w0),
        c_array("IV_EDGES", rt.edges),
        c_array("IV_MODE_VX", mode("vx")), c_array("IV_ETA", mode("eta")), c_array("IV_RHO", rt._rho),
        c_array("IV_N", mode("N")), c_array("IV_P", mode("P")), c_array("IV_E", mode("E")),
        c_array("IV_J", mode("J")), c_array("IV_H", mode("H")),
        c_array("IV_MAPS_H0", maps),
    ])
    return CModel(header=header, states=STATES, n_event_indicators=N_EVENT_INDICATORS,
                  dependencies=_dependencies(rt))


#: the measurement inputs y (measurements() in interval_observer.c)
MEASURED = ("yaw_rate", "ay")
#: each output's box bounds (side, column of x) and whether it divides by vx (outputs_of)
OUTPUT_BOUNDS = {"vy_lower": ("l0",), "vy_upper": ("u0",), "yaw_rate_lower": ("l1",), "yaw_rate_upper": ("u1",),
                 "Fyf_lower": ("l2", "l3"), "Fyf_upper": ("u2", "u3"), "Fyr_lower": ("l2", "u3"),
                 "Fyr_upper": ("u2", "l3"),
                 # atan(vy / vx): the lower vy bound when vx > 0, the upper one when vx < 0 (reversing)
                 "beta_lower": ("l0", "u0", "vx"), "beta_upper": ("l0", "u0", "vx")}


def _dependencies(rt: IntervalObserver) -> dict:
    """ModelExchange (model_me_derivatives, me_box, omega, stiffness, outputs_of), in every mode.
    The box X = xi + E y -/+ |E| nu; the bounds' derivatives N xi + J y + H delta + P omega -/+ rad
    (eq. 23), omega's row i reading the box's columns where A1 is nonzero (times vx - vx_mode), B1
    (times (vx - vx_mode) delta) and, in the stiffness rows (eq. 9), columns vy and r with vx delta;
    the centre and radius of a column read both of its bounds."""
    md, n = rt.model, len(STATES) // 2
    lower, upper = [s.name for s in STATES[:n]], [s.name for s in STATES[n:]]

    def box(side: str, j: int) -> set:
        return {(lower if side == "l" else upper)[j]} | nonzero(MEASURED, *(m["E"][j] for m in rt.modes))

    def column(j: int) -> set:
        return box("l", j) | box("u", j)

    def omega(i: int) -> set:
        d = set()
        if any(float(a) != 0.0 for a in md["A1"][i]):
            d |= {"vx"}.union(*(column(j) for j in range(n) if float(md["A1"][i][j]) != 0.0))
        if float(md["B1"][i]) != 0.0:
            d |= {"vx", "delta"}
        if i in md["stiff"]["rows"]:
            d |= {"vx", "delta"}.union(*(column(j) for j in md["stiff"]["cols"]))
        return d

    deps = {}
    for side, names in (("l", lower), ("u", upper)):
        for i, name in enumerate(names):
            d = nonzero(names, *(m["N"][i] for m in rt.modes)) | nonzero(MEASURED, *(m["J"][i] for m in rt.modes))
            if any(float(m["H"][i]) != 0.0 for m in rt.modes):
                d.add("delta")
            d = d.union(*(omega(k) for k in range(n) if any(float(m["P"][i][k]) != 0.0 for m in rt.modes)))
            deps[f"der({name})"] = d
    for out, parts in OUTPUT_BOUNDS.items():
        deps[out] = set().union(*({p} if p == "vx" else box(p[0], int(p[1])) for p in parts))
    return structure(deps)
