"""Emitter of the native C model of paper 002's transfer-function sideslip estimator
(``fmu_src/c/tf_estimator.c``), one estimator or one per speed band.

Mirrors ``fmu_src/tf_estimator.py``: the data file is checked and realised by that runtime itself
(a file it refuses raises its ValueError here), so the C file gets bit-for-bit the Python
runtime's controllable canonical form of beta^ = (y(s)/x(s)) r per band i:

    TF_A[i], TF_B[i]      z' = A z + B r (companion A, B = e_n)
    TF_C[i], TF_D[i]      beta^ = C z + D r
    TF_A0[i]              a_0 of the monic x(s): the steady state z = [r / a_0, 0, .., 0]
    TF_PHI_H0[i], TF_GAM_H0[i]
                          the exact zero-order-hold map over the FMU's default step TF_H0 =
                          0.005 s (``framework.DEFAULT_STEP``), computed by the runtime's own
                          ``zoh`` (Van Loan, ``linalg.expm``): at the default step the C model
                          steps with exactly the Python FMU's maps
    TF_NOMINAL            the states' nominal magnitudes (ModelExchange; :func:`nominals`)
    TF_EDGES              the band edges (m/s), increasing; an unscheduled estimator is one band
                          (-inf, inf), which selects it at every finite speed and never warns

The order n may be 0 (a static gain beta^ = D r): the arrays then keep one padding entry
(TF_DIM = max(n, 1)) that the C model never reads, and the FMU is co-simulation only.
"""
from __future__ import annotations

import math

from ..fmu_src.framework import DEFAULT_STEP
from ..fmu_src.spec import Var
from ..fmu_src.tf_estimator import TfEstimator, zoh
from .emit import CModel, nonzero, structure, c_array, c_define

SOURCE = "tf_estimator.c"

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


def nominals(systems, n: int) -> list[float]:
    """Nominal magnitude of z_k per rad/s of yaw rate: with w = a_0^(1/n) (the geometric mean of
    the poles' magnitudes), z_1 ~ r / a_0 (its steady state) and z_k = d^(k-1) z_1 / dt^(k-1) ~
    w^(k-1) / a_0;
    the largest over the bands."""
    return [max(a[0] ** ((k - 1 - n) / n) for *_, a in systems) for k in range(1, n + 1)]


def _pad(v, n: int, dim: int) -> list[float]:
    """A vector of length n padded with zeros to dim (n = 0: the one padding entry)."""
    return list(v) + [0.0] * (dim - n)


def _pad2(M, n: int, dim: int) -> list[list[float]]:
    """An n x n matrix padded with zeros to dim x dim."""
    return [_pad(row, n, dim) for row in M] + [[0.0] * dim for _ in range(dim - n)]


def emit(data: dict) -> CModel:
    rt = TfEstimator(data)                  # the runtime's checks: ValueError naming the culprit
    n, n_modes = rt.n, len(rt.systems)
    if n > MAX_ORDER:
        raise ValueError(f"data file: estimator order {n} exceeds the native C backend's limit {MAX_ORDER} "
                         "(fmu_src/c/linalg.h LA_MAX)")
    dim = max(n, 1)
    A, B, C, D, A0, PHI, GAM = [], [], [], [], [], [], []
    for Ai, Bi, Ci, Di, ai in rt.systems:
        A.append(_pad2(Ai, n, dim))
        B.append(_pad(Bi, n, dim))
        C.append(_pad(Ci, n, dim))
        D.append(Di)
        A0.append(ai[0] if n else 1.0)
        Phi, Gam = zoh(Ai, Bi, DEFAULT_STEP) if n else ([], [])
        PHI.append(_pad2(Phi, n, dim))
        GAM.append(_pad(Gam, n, dim))
    nominal = nominals(rt.systems, n)
    edges = rt.edges if rt.edges is not None else [-math.inf, math.inf]
    header = "".join([
        "/* paper 002: beta^ = (y(s)/x(s)) r per speed band, z' = A z + B r, beta^ = C z + D r */\n",
        c_define("TF_N", n), c_define("TF_DIM", dim), c_define("TF_N_MODES", n_modes),
        c_define("TF_H0", float(DEFAULT_STEP)),
        c_array("TF_EDGES", edges),
        c_array("TF_A", A), c_array("TF_B", B), c_array("TF_C", C), c_array("TF_D", D), c_array("TF_A0", A0),
        c_array("TF_PHI_H0", PHI), c_array("TF_GAM_H0", GAM),
        c_array("TF_NOMINAL", nominal) if n else "",       # ModelExchange only (n >= 1)
    ])
    return CModel(header=header, states=states(n),
                  n_event_indicators=N_EVENT_INDICATORS_SCHEDULED if rt.edges is not None and n else 0,
                  dependencies=_dependencies(rt.systems, n) if n else None)


def _dependencies(systems, n: int) -> dict:
    """ModelExchange: z' = A z + B r, beta^ = C z + D r in every band (model_me_derivatives,
    outputs_of); the speed selects the band at events only."""
    z = [s.name for s in states(n)]
    deps = {f"der({z[i]})": nonzero(z, *(A[i] for A, *_ in systems))
            | nonzero(["yaw_rate"], *([B[i]] for _, B, *_ in systems)) for i in range(n)}
    deps["beta_hat"] = nonzero(z, *(C for _, _, C, *_ in systems)) | nonzero(["yaw_rate"], *([D] for *_, D, _ in systems))
    return structure(deps)
