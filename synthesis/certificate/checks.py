"""Shared pieces of the certificates: the :class:`Check` record and the numerical helpers that
more than one certificate uses (definiteness margins, relative errors, convex hulls in the
(1/Vx, 1/Vx^2) plane, transient growth factors). numpy/scipy only, never the LMI solver.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

REL_TOL = 1e-6


@dataclass(frozen=True)
class Check:
    """One named check of a certificate: ``value`` against ``limit`` in the ``sense`` given."""

    name: str
    value: float
    limit: float
    passed: bool
    sense: str = "<="          # value <= limit, or ">=" for a lower bound
    detail: str = ""


def _le(name, value, limit, detail=""):
    """The check value <= limit."""
    return Check(name, float(value), float(limit), bool(value <= limit), "<=", detail)


def _ge(name, value, limit, detail=""):
    """The check value >= limit (a lower bound)."""
    return Check(name, float(value), float(limit), bool(value >= limit), ">=", detail)


def _sym(M: np.ndarray) -> np.ndarray:
    return (M + M.T) / 2


def _neg_margin(M: np.ndarray) -> float:
    """Largest eigenvalue of the symmetric part of M after the congruence D M D, D = diag(|M_ii|^-1/2)
    (Jacobi scaling): by Sylvester's law of inertia M < 0 iff this value < 0, and the scaled matrix
    has unit diagonal, so the value is dimensionless (in (-1, 0) for a negative definite M) and its
    sign is not at the mercy of the LMI's units. A diagonal entry >= 0 already disproves M < 0:
    then the unscaled largest eigenvalue (>= 0) is returned."""
    M = _sym(np.asarray(M, float))
    if not np.all(np.isfinite(M)):
        return math.inf
    dg = np.diag(M)
    if np.any(dg >= 0):
        return float(np.max(np.linalg.eigvalsh(M)))
    s = 1.0 / np.sqrt(-dg)
    return float(np.max(np.linalg.eigvalsh(M * s[:, None] * s[None, :])))


def _hull_2d(points) -> list[tuple[float, float]]:
    """Convex hull (Andrew's monotone chain), counter-clockwise, collinear points dropped."""
    pts = sorted(set(points))
    if len(pts) < 3:
        return pts

    def cross(o, a, b):
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
    lower, upper = [], []
    for p in pts:
        while len(lower) >= 2 and cross(lower[-2], lower[-1], p) <= 0:
            lower.pop()
        lower.append(p)
    for p in reversed(pts):
        while len(upper) >= 2 and cross(upper[-2], upper[-1], p) <= 0:
            upper.pop()
        upper.append(p)
    return lower[:-1] + upper[:-1]


def _curve_outside_hull(points, v_lo: float, v_hi: float, reciprocal: bool = False) -> float:
    """max over v in [v_lo, v_hi] of the distance of (v, v^2) outside the convex hull of ``points``
    (<= 0: the whole arc is inside), exactly: for each hull edge with outward unit normal (a, b)
    through p, a (v - p_v) + b (v^2 - p_w) is a quadratic in v maximised at an end or its vertex.
    ``reciprocal``: the curve (1/v, v) instead (points (u, v)), where a (1/v - p_u) + b (v - p_v) is
    maximised at an end or where its derivative -a/v^2 + b vanishes, v = sqrt(a/b).
    A degenerate hull (fewer than 3 points not on a line) holds no arc: inf."""
    hull = _hull_2d([(float(p[0]), float(p[1])) for p in points])
    if len(hull) < 3:
        return math.inf
    worst = -math.inf
    for p, q in zip(hull, hull[1:] + hull[:1]):
        a, b = q[1] - p[1], -(q[0] - p[0])           # outward normal of a counter-clockwise edge
        nrm = math.hypot(a, b)
        a, b = a / nrm, b / nrm
        cand = [v_lo, v_hi]
        if reciprocal:
            if b != 0 and a / b > 0 and v_lo < math.sqrt(a / b) < v_hi:
                cand.append(math.sqrt(a / b))
            worst = max(worst, max(a * (1.0 / v - p[0]) + b * (v - p[1]) for v in cand))
            continue
        if b < 0:                                    # concave quadratic: interior maximum
            vs = -a / (2 * b)
            if v_lo < vs < v_hi:
                cand.append(vs)
        worst = max(worst, max(a * (v - p[0]) + b * (v * v - p[1]) for v in cand))
    return worst


def _growth_factor(Ah: np.ndarray) -> tuple[float, float]:
    """(mu, t*) with mu = sup_{t >= 0} ||exp(Ah t)||_2^2 for Ah = P^1/2 A_fr P^-1/2 (A_fr: one zero
    eigenvalue, the others Re < 0, so exp(Ah t) converges to the spectral projector of 0): sampled
    on 400 log-spaced times from 1e-3/|lambda|max to 60/|Re lambda|min (where the transient has
    decayed below e^-60), the largest sample refined by bounded Brent on log t, and the limit
    t -> inf included; inf when a non-zero eigenvalue has Re >= 0 or the samples do not converge."""
    import scipy.linalg
    from scipy.optimize import minimize_scalar

    if not np.all(np.isfinite(Ah)):
        return math.inf, math.nan
    lam, V = np.linalg.eig(Ah)
    k0 = int(np.argmin(np.abs(lam)))
    rest = np.delete(lam, k0)
    if np.max(rest.real) >= 0:
        return math.inf, math.nan
    fast, slow = float(np.max(np.abs(rest))), float(-np.max(rest.real))
    if np.linalg.cond(V) < 1e8:                      # modal form: exp(Ah t) = V exp(lambda t) V^-1
        Vi = np.linalg.inv(V)
        lam = lam.copy()
        lam[k0] = 0.0                                # exactly 0 (the last row of A_fr is zero)
        limit = float(np.linalg.norm(np.outer(V[:, k0], Vi[k0]), 2))

        def norms(ts):                               # ||M||_2 = sqrt(max eig M'M), M real
            Ms = np.einsum("ij,tj,jk->tik", V, np.exp(np.outer(ts, lam)), Vi).real
            return np.sqrt(np.maximum(np.linalg.eigvalsh(np.einsum("tji,tjk->tik", Ms, Ms))[:, -1], 0.0))
    else:                                            # (nearly) defective: scipy's expm per time
        def norms(ts):
            return np.array([np.linalg.norm(scipy.linalg.expm(Ah * t), 2) for t in ts])
        limit = float(norms([200.0 / slow])[0])
    ts = np.logspace(math.log10(1e-3 / fast), math.log10(60.0 / slow), 400)
    g = norms(ts)
    if abs(g[-1] - limit) > 1e-9 * max(limit, 1.0):
        return math.inf, math.nan
    i = int(np.argmax(g))
    best, t_best = float(g[i]), float(ts[i])
    lo, hi = math.log(ts[max(i - 1, 0)]), math.log(ts[min(i + 1, len(ts) - 1)])
    if hi > lo:
        res = minimize_scalar(lambda s: -norms(np.array([math.exp(s)]))[0], bounds=(lo, hi), method="bounded",
                              options={"xatol": 1e-10})
        if -res.fun > best:
            best, t_best = float(-res.fun), float(math.exp(res.x))
    return max(best, limit, 1.0) ** 2, t_best


def _rel_err(a, b) -> float:
    """max |a - b| relative to max(1, max |b|)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    return float(np.max(np.abs(a - b)) / max(1.0, float(np.max(np.abs(b)))))
