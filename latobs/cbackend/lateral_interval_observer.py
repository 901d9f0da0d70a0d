"""Emitter of the native C model of paper 001's switched interval observer
(``fmu_src/c/lateral_interval_observer.c``): writes the design's tables (``synthesis.tables.
lateral_interval_observer``, stored in the design file under "tables") as C data in model_data.h
(IV_*: the model, the structured stiffness bound, each mode's gains and step maps at the default
step, the tuning, the longest communication step). Reads nothing but the design data.
"""
from __future__ import annotations

from ..fmu_src.spec import Var
from .emit import CModel, c_array, c_define, nonzero, structure

SOURCE = "lateral_interval_observer.c"

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
    tb = data.get("tables")
    if not tb:
        raise ValueError(f"design {data.get('name')!r}: no tables (build them with synthesis.tables.attach)")
    md, sk, tu = tb["model"], tb["stiffness"], tb["tuning"]
    if tb["meas"] != [1, 2]:
        raise ValueError("the C interval observer needs the measurements [r, ay] (states 2, 3)")
    if tb["max_communication_step"] is None:
        raise ValueError("design file lacks runtime.max_communication_step (the synthesis decides it)")
    mode = lambda key: [m[key] for m in tb["modes"]]  # noqa: E731
    header = "".join([
        "/* paper 001, eq. (23): the interval observer's design (latobs/cbackend/lateral_interval_observer.py) */\n",
        c_define("IV_N_MODES", len(tb["modes"])),
        c_define("IV_H0", float(tb["h0"])),
        c_define("IV_CONSISTENCY_TOL", float(tu["consistency_tol"])),
        c_define("IV_ENCLOSURE_TRIES", int(tu["enclosure_tries"])),
        c_define("IV_ENCLOSURE_GROW", float(tu["enclosure_grow"])),
        c_define("IV_ENCLOSURE_MULT", float(tu["enclosure_mult"])),
        c_define("IV_SUBSTEP_RHO_H", float(tu["substep_rho_h"])),
        c_define("IV_MAX_COMM_STEP", float(tb["max_communication_step"])),
        c_define("IV_SAMPLED", bool(tu["sampled"])),
        c_define("IV_SAMPLED_SUBSTEP", float(tu["sampled_substep"])),
        c_define("IV_SAMPLED_MIN_STEP", float(tu["sampled_min_step"])),
        c_define("IV_SAMPLED_MAX_SUBSTEPS", int(tu["sampled_max_substeps"])),
        c_define("IV_SAMPLED_DV", float(tu["sampled_dv"])),
        c_define("IV_SAMPLED_MAX_NORM", float(tu["sampled_max_norm"])),
        c_define("IV_M", md["m"]), c_define("IV_IZ", md["Iz"]), c_define("IV_LF", md["lf"]),
        c_define("IV_LR", md["lr"]),
        c_define("IV_K3", sk["k3"]), c_define("IV_K4F", sk["k4f"]), c_define("IV_K4R", sk["k4r"]),
        c_define("IV_STIFF_SYMMETRIC", bool(sk["symmetric"])),
        c_array("IV_DCF", list(sk["dcf"])), c_array("IV_DCR", list(sk["dcr"])),
        c_array("IV_A0", md["A0"]), c_array("IV_A1", md["A1"]), c_array("IV_B1", md["B1"]),
        c_array("IV_DA_LO", md["dA_lower"]), c_array("IV_DA_UP", md["dA_upper"]),
        c_array("IV_DB1_LO", md["dB1_lower"]), c_array("IV_DB1_UP", md["dB1_upper"]),
        c_array("IV_W", md["w"]),
        c_array("IV_DAMPED", [int(i in tb["damped"]) for i in range(4)], "int"),
        c_array("IV_SMOOTH", [int(i in tb["smooth"]) for i in range(4)], "int"),
        c_array("IV_X0_HALFWIDTH", tb["x0_halfwidth"]),
        c_array("IV_EDGES", tb["edges"]),
        c_array("IV_MODE_VX", mode("vx")), c_array("IV_ETA", mode("eta")), c_array("IV_RHO", mode("rho")),
        c_array("IV_N", mode("N")), c_array("IV_P", mode("P")), c_array("IV_E", mode("E")),
        c_array("IV_J", mode("J")), c_array("IV_H", mode("H")),
        c_array("IV_MAPS_H0", mode("maps_h0")),
        c_array("IV_MAPS_H0_ERROR", mode("maps_h0_error")),   # each entry's error bound (their bracket)
        c_array("IV_RESIDUAL", mode("residual")),             # bounds of the design residuals R1, R2, R3
    ])
    return CModel(header=header, states=STATES, n_event_indicators=N_EVENT_INDICATORS,
                  dependencies=_dependencies(tb))


#: the measurement inputs y (measurements() in lateral_interval_observer.c)
MEASURED = ("yaw_rate", "ay")
#: each output's box bounds (side, column of x) and whether it divides by vx (outputs_of)
OUTPUT_BOUNDS = {"vy_lower": ("l0",), "vy_upper": ("u0",), "yaw_rate_lower": ("l1",), "yaw_rate_upper": ("u1",),
                 "Fyf_lower": ("l2", "l3"), "Fyf_upper": ("u2", "u3"), "Fyr_lower": ("l2", "u3"),
                 "Fyr_upper": ("u2", "l3"),
                 # atan(vy / vx): the lower vy bound when vx > 0, the upper one when vx < 0 (reversing)
                 "beta_lower": ("l0", "u0", "vx"), "beta_upper": ("l0", "u0", "vx")}


def _dependencies(tb: dict) -> dict:
    """ModelExchange (model_me_derivatives, me_box, omega, stiffness, outputs_of), in every mode.
    The box X = xi + E y -/+ |E| nu; the bounds' derivatives N xi + J y + H delta + P omega -/+ rad
    (eq. 23), omega's row i reading the box's columns where A1 is nonzero (times vx - vx_mode), B1
    (times (vx - vx_mode) delta) and, in the stiffness rows (eq. 9), columns vy and r with vx delta;
    the centre and radius of a column read both of its bounds."""
    md, modes, n = tb["model"], tb["modes"], len(STATES) // 2
    lower, upper = [s.name for s in STATES[:n]], [s.name for s in STATES[n:]]

    def box(side: str, j: int) -> set:
        return {(lower if side == "l" else upper)[j]} | nonzero(MEASURED, *(m["E"][j] for m in modes))

    def column(j: int) -> set:
        return box("l", j) | box("u", j)

    def omega(i: int) -> set:
        d = set()
        if any(float(a) != 0.0 for a in md["A1"][i]):
            d |= {"vx"}.union(*(column(j) for j in range(n) if float(md["A1"][i][j]) != 0.0))
        if float(md["B1"][i]) != 0.0:
            d |= {"vx", "delta"}
        if i in (2, 3):                       # the stiffness rows (x3', x4') read vy and r (eq. 9)
            d |= {"vx", "delta"}.union(*(column(j) for j in (0, 1)))
        return d

    deps = {}
    for side, names in (("l", lower), ("u", upper)):
        for i, name in enumerate(names):
            d = nonzero(names, *(m["N"][i] for m in modes)) | nonzero(MEASURED, *(m["J"][i] for m in modes))
            if any(float(m["H"][i]) != 0.0 for m in modes):
                d.add("delta")
            d = d.union(*(omega(k) for k in range(n) if any(float(m["P"][i][k]) != 0.0 for m in modes)))
            deps[f"der({name})"] = d
    for out, parts in OUTPUT_BOUNDS.items():
        deps[out] = set().union(*({p} if p == "vx" else box(p[0], int(p[1])) for p in parts))
    return structure(deps)


def gains(data: dict) -> list:
    """The certified gains as the FMI 3.0 FMU's array constants (``latobs.cbackend.fmi3``): per mode
    the observer gain K and the unknown-input matrix E (the design file's ``modes[i]``)."""
    modes = data["modes"]
    return [("K", "observer gain K of each mode (modes x states x measurements, SI)", [m["K"] for m in modes]),
            ("E", "gain E of each mode (modes x states x measurements, SI)", [m["E"] for m in modes])]
