"""Emitter of the native C model of paper 002's fixed-order sideslip estimator
(``fmu_src/c/sideslip_fixed_order_estimator.c``), one estimator or one per speed band.

Writes the design file's tables (``synthesis/tables/sideslip_fixed_order_estimator.py``: per band
the controllable canonical form and its exact ZOH map at the default step) as C data: TF_A, TF_B,
TF_C, TF_D, TF_A0, TF_PHI_H0, TF_GAM_H0, TF_EDGES (an unscheduled estimator: one band
(-inf, inf)), TF_NOMINAL (ModelExchange). n = 0 (a static gain) keeps one padding entry per array.
"""
from __future__ import annotations

import math

from ..fmu_src.spec import Var
from .emit import CModel, nonzero, structure, c_array, c_define

SOURCE = "sideslip_fixed_order_estimator.c"

#: la_zoh_map's limit (fmu_src/c/linalg.h LA_MAX = 16): n states + 1 input
MAX_ORDER = 15
#: z0, z1: the active band's lower and upper edge; z2, z3: the grid's ends (the out-of-grid warning)
N_EVENT_INDICATORS_SCHEDULED = 4


def _unit(k: int, n: int) -> str:
    """Unit of z_k (1-based): z_n' = .. + r gives z_n in rad, and z_k = z_(k+1) s before it."""
    p = n - k
    return "rad" if p == 0 else "rad.s" if p == 1 else f"rad.s{p}"


def states(n: int) -> tuple[Var, ...]:
    """The ModelExchange states z_1 .. z_n of the controllable canonical form."""
    return tuple(Var(f"z{k}", _unit(k, n),
                     f"estimator state z_{k} of the controllable canonical form"
                     + (f" (z_{k}' = z_{k + 1})" if k < n else " (z_n' = -a_0 z_1 - .. - a_(n-1) z_n + r)"))
                 for k in range(1, n + 1))


def nominals(bands, n: int) -> list[float]:
    """Nominal magnitude of z_k per rad/s of yaw rate: with w = a_0^(1/n) (the geometric mean of
    the poles' magnitudes), z_1 ~ r / a_0 (its steady state) and z_k = d^(k-1) z_1 / dt^(k-1) ~
    w^(k-1) / a_0;
    the largest over the bands."""
    return [max(b["a0"] ** ((k - 1 - n) / n) for b in bands) for k in range(1, n + 1)]


def _pad(v, n: int, dim: int) -> list[float]:
    """A vector of length n padded with zeros to dim (n = 0: the one padding entry)."""
    return list(v) + [0.0] * (dim - n)


def _pad2(M, n: int, dim: int) -> list[list[float]]:
    """An n x n matrix padded with zeros to dim x dim."""
    return [_pad(row, n, dim) for row in M] + [[0.0] * dim for _ in range(dim - n)]


def emit(data: dict) -> CModel:
    t = data["tables"]
    n, bands = t["n"], t["bands"]
    if n > MAX_ORDER:
        raise ValueError(f"data file: estimator order {n} exceeds the native C backend's limit {MAX_ORDER} "
                         "(fmu_src/c/linalg.h LA_MAX)")
    dim = max(n, 1)
    edges = t["edges"] if t["edges"] is not None else [-math.inf, math.inf]
    header = "".join([
        "/* paper 002: beta^ = (y(s)/x(s)) r per speed band, z' = A z + B r, beta^ = C z + D r */\n",
        c_define("TF_N", n), c_define("TF_DIM", dim), c_define("TF_N_MODES", len(bands)),
        c_define("TF_H0", float(t["h0"])),
        c_array("TF_EDGES", edges),
        c_array("TF_A", [_pad2(b["A"], n, dim) for b in bands]),
        c_array("TF_B", [_pad(b["B"], n, dim) for b in bands]),
        c_array("TF_C", [_pad(b["C"], n, dim) for b in bands]),
        c_array("TF_D", [b["D"] for b in bands]),
        c_array("TF_A0", [b["a0"] for b in bands]),
        c_array("TF_PHI_H0", [_pad2(b["Phi_h0"], n, dim) for b in bands]),
        c_array("TF_GAM_H0", [_pad(b["Gam_h0"], n, dim) for b in bands]),
        c_array("TF_NOMINAL", nominals(bands, n)) if n else "",       # ModelExchange only (n >= 1)
    ])
    return CModel(header=header, states=states(n),
                  n_event_indicators=N_EVENT_INDICATORS_SCHEDULED if t["edges"] is not None and n else 0,
                  dependencies=_dependencies(bands, n) if n else None)


def _dependencies(bands, n: int) -> dict:
    """ModelExchange: z' = A z + B r, beta^ = C z + D r in every band (model_me_derivatives,
    outputs_of); the speed selects the band at events only."""
    z = [s.name for s in states(n)]
    deps = {f"der({z[i]})": nonzero(z, *(b["A"][i] for b in bands))
            | nonzero(["yaw_rate"], *([b["B"][i]] for b in bands)) for i in range(n)}
    deps["beta_hat"] = nonzero(z, *(b["C"] for b in bands)) | nonzero(["yaw_rate"], *([b["D"]] for b in bands))
    return structure(deps)


def gains(data: dict) -> list:
    """The certified estimator(s) as the FMI 3.0 FMU's array constants (``latobs.cbackend.fmi3``):
    each band's transfer function beta^(s) / r(s), its numerator and denominator coefficients in
    ascending powers of s (the design file's ``modes[i].estimator``)."""
    modes = data["modes"]
    return [("estimator_num", "numerator of each band's estimator beta^/r, ascending powers of s (bands x coefficients)",
             [m["estimator"]["num"] for m in modes]),
            ("estimator_den", "denominator of each band's estimator beta^/r, ascending powers of s "
                              "(bands x coefficients)", [m["estimator"]["den"] for m in modes])]
