"""Truncated matrix power series: the exact RK4 step maps of s' = M s + G w over a step, and
their Taylor tables in v = 1/vx with a rigorous truncation bound (design time, plain floats).

Matrices are lists of rows; a series is a list of matrices, index = the power of the variable.
The runtimes evaluate what these build (``synthesis.tables``); nothing here runs inside an FMU.
"""
from __future__ import annotations

import math

import numpy as np

from ...fmu_src.linalg import dot, total   # sums from the left, as the runtimes' (not sum(): compensated from Python 3.12)


# -- dense matrices as lists of rows ---------------------------------------------------------
def floats(M) -> list[list[float]]:
    return [[float(x) for x in row] for row in M]


def matmul(A, B):
    cols = list(zip(*B))
    return [[dot(row, col) for col in cols] for row in A]


def add(A, B):
    return [[a + b for a, b in zip(ra, rb)] for ra, rb in zip(A, B)]


def scale(A, s):
    return [[a * s for a in row] for row in A]


def zeros(r, c):
    return [[0.0] * c for _ in range(r)]


def norm_inf(A) -> float:
    """Induced infinity norm (largest row sum of |a|)."""
    return max(total(map(abs, row)) for row in A)


# -- matrix power series in d (list of matrices, index = power of d), truncated at degree J ----
# Inside the series the matrices are numpy arrays, multiplied by ``_mm``: each entry's products
# added from the left from 0.0, exactly the doubles of ``matmul`` (``fmu_src.linalg.dot``), one
# column of A at a time (numpy neither fuses a multiply and an add nor reorders elementwise sums).
def _mm(A, B):
    out = np.zeros((A.shape[0], B.shape[1]))
    for j in range(A.shape[1]):
        out += A[:, j:j + 1] * B[j:j + 1, :]
    return out


def _norm(A) -> float:
    """``norm_inf`` of an array: each row's |a| added from the left."""
    s = np.zeros(A.shape[0])
    for j in range(A.shape[1]):
        s += np.abs(A[:, j])
    return float(max(s.tolist()))


def _arrays(series_):
    return [np.array(P, dtype=float) for P in series_]


def smul(P, Q, J):
    out = [None] * min(len(P) + len(Q) - 1, J + 1)
    for a, Pa in enumerate(P):
        for b, Qb in enumerate(Q):
            if a + b > J:
                break
            prod = _mm(Pa, Qb)
            out[a + b] = prod if out[a + b] is None else out[a + b] + prod
    return out


def sadd(P, Q):
    if len(P) < len(Q):
        P, Q = Q, P
    return [Pa + Q[j] if j < len(Q) else Pa for j, Pa in enumerate(P)]


def shift(coeffs, v0):
    """Coefficients in d of sum_k coeffs[k] (v0 + d)**k (arrays)."""
    coeffs = _arrays(coeffs)
    out = []
    for j in range(len(coeffs)):
        acc = None
        for k in range(j, len(coeffs)):
            term = coeffs[k] * (math.comb(k, j) * v0 ** (k - j))
            acc = term if acc is None else acc + term
        out.append(acc)
    return out


def substep(Ms, Gs, hs, J):
    """One RK4 substep with held inputs as a series of affine maps [R | S G] in d."""
    n = Ms[0].shape[0]
    I = np.eye(n)
    X = [M * hs for M in Ms]
    Q = [I]
    for c in (4.0, 3.0, 2.0):                       # Q = I + X/2 (I + X/3 (I + X/4))
        Q = sadd([I], [P * (1.0 / c) for P in smul(X, Q, J)])
    R = sadd([I], smul(X, Q, J))                # R = I + X Q
    SG = [P * hs for P in smul(Q, Gs, J)]         # S G = hs Q G
    m = Gs[0].shape[1]
    R += [np.zeros((n, n))] * (len(SG) - len(R))
    SG += [np.zeros((n, m))] * (len(R) - len(SG))
    return [np.hstack([A, B]) for A, B in zip(R, SG)]


def compose(W2, W1, n, J):
    """Series of the affine map W2 after W1, each [A | b] (n rows)."""
    out = smul([P[:, :n] for P in W2], W1, J)
    for j, P in enumerate(W2):
        out[j][:, n:] += P[:, n:]
    return out


def power(W, k, n, J):
    """W composed k >= 1 times (binary powering; all factors commute)."""
    result = None
    while True:
        if k & 1:
            result = W if result is None else compose(W, result, n, J)
        k >>= 1
        if not k:
            return result
        W = compose(W, W, n, J)


def augment(Ms, Gs, h):
    """First-order hold as a held input: series (in v or d) of M, G -> those of
    [s; w]' = [[M, G], [0, 0]] [s; w] + [[0], [I / h]] e, e = the hold's increment over the step,
    so that w(t + tau) = w_k + (tau / h) e is a state. RK4 on this system evaluates w exactly at
    the stage times (w is linear in time), so its maps ARE the RK4 substeps with that input."""
    n1, nw = Ms[0].shape[0], Gs[0].shape[1]
    Ma = []
    for k in range(max(len(Ms), len(Gs))):
        M = Ms[k] if k < len(Ms) else np.zeros((n1, n1))
        G = Gs[k] if k < len(Gs) else np.zeros((n1, nw))
        Ma.append(np.vstack([np.hstack([M, G]), np.zeros((nw, n1 + nw))]))
    return Ma, [np.vstack([np.zeros((n1, nw)), np.eye(nw) * (1.0 / h)])]


def truncation_bound(coeffs, D, delta, E1, alpha, nsub):
    """Rigorous bound of ||sum_{j > D} coeffs_j d^j||_inf for |d| <= delta, where the map is
    E(d)^nsub (top rows), E(d) = E_0 + sum_{j>=1} E_j d^j the augmented substep map.

    Degrees D < j <= J = len(coeffs) - 1: the exact coefficients. Degrees > J: every coefficient
    of E^nsub = sum over words in E_0 and H = E - E_0 is bounded (coefficientwise) by those of
    f(t) = alpha (1 + alpha eta(t))^nsub, alpha = max_{a <= nsub} ||E_0^a||, eta(t) = sum_j
    ||E_j|| t^j (E1 = [||E_1||, ||E_2||, ...]); for nonnegative coefficients sum_{j > J} f_j
    delta^j <= f(rho) (delta / rho)^(J + 1) for any rho > delta (minimised over a grid of rho).
    """
    J = len(coeffs) - 1
    exact = total(_norm(coeffs[j]) * delta**j for j in range(D + 1, J + 1))
    best = math.inf
    for k in range(1, 60):
        rho = delta * 1.25**k
        eta = total(e * rho ** (j + 1) for j, e in enumerate(E1))
        log_f = math.log(alpha) + nsub * math.log1p(alpha * eta)
        log_tail = log_f + (J + 1) * math.log(delta / rho)
        best = min(best, math.exp(log_tail) if log_tail < 700 else math.inf)
    return exact + best



# -- Taylor tables in v = 1/vx of a measured-speed mode's step map ---------------------------------
def step_series(Mc, Gc, v0, nsub, hs, J, h=None):
    """Exact Taylor coefficients (degree <= J) in d = v - v0 of the nsub-substep RK4 map of
    s' = M(v) s + G(v) w (Mc, Gc: the coefficient matrices of M, G in v; ``h`` given: the
    first-order hold's augmented map, see ``augment``), and what the truncation bound needs:
    ||E_j|| (j >= 1) and max_{a <= nsub} ||E_0^a|| of the substep map E."""
    Ms, Gs = shift(Mc, v0), shift(Gc, v0)
    if h is not None:
        Ms, Gs = augment(Ms, Gs, h)
    n = Ms[0].shape[0]
    W = substep(Ms, Gs, hs, 4 * (len(Ms) - 1) + len(Gs) - 1)   # all its degrees in d
    E1 = [_norm(P) for P in W[1:]]
    # powers of E_0 = [[R0, b0], [0, I]]: ||E_0^a|| = max(1, ||[R0^a | sum_{k<a} R0^k b0]||)
    P, alpha = None, 1.0
    for _ in range(nsub):
        P = W[:1] if P is None else compose(W[:1], P, n, 0)
        alpha = max(alpha, _norm(P[0]))
    coeffs = power(W[: J + 1], nsub, n, J)
    coeffs += [np.zeros((n, W[0].shape[1]))] * (J + 1 - len(coeffs))
    return coeffs, E1, alpha


def interval_count(Mc, Gc, v_lo, v_hi, nsub, hs, degree, tol, max_intervals, h=None):
    """K equal intervals of [v_lo, v_hi]: probing the coefficients at the middle of the range, K
    such that the degrees degree + 1 and degree + 2 contribute about tol / 4 there (each interval
    is then checked on its own by ``interval_coefficients``)."""
    width = v_hi - v_lo
    if width <= 0:
        return 1
    n1 = len(Mc[0])
    coeffs, *_ = step_series(Mc, Gc, 0.5 * (v_lo + v_hi), nsub, hs, degree + 3, h)
    goal = tol * _norm(coeffs[0][:n1]) / 4
    half = min((goal / max(_norm(coeffs[j]), 1e-300)) ** (1.0 / j) for j in (degree + 1, degree + 2))
    return max(1, min(max_intervals, math.ceil(width / (2 * half))))


def interval_coefficients(Mc, Gc, v_lo, v_hi, K, k, nsub, hs, degree, tol, h=None):
    """(center, kept) of interval k of K: its center in v and the Taylor coefficients kept, kept[j]
    the top n + 1 rows (those of s = [z; w^]) of the map's coefficient of (v - center)**j
    (trailing all-zero degrees removed). Per row, the terms c d^j (j >= 1) are dropped, smallest
    |c| delta^j first, while their sum plus the bound of all terms beyond degree J = degree + 3
    stays within tol ||[Phi | Gam]||_inf: a rigorous bound of the row's truncation error per unit
    ||[s; w]||_inf (first-order hold: [s; w; e] and the top rows of the augmented map). kept is
    None if the terms beyond J alone exceed it (the interval runs the RK4 substeps)."""
    J = degree + 3
    n1 = len(Mc[0])
    width = v_hi - v_lo
    center = v_lo + (k + 0.5) * width / K
    delta = 0.5 * width / K * (1 + 1e-6) + 1e-300   # slack for the rounding of k
    coeffs, E1, alpha = step_series(Mc, Gc, center, nsub, hs, J, h)
    budget = tol * _norm(coeffs[0][:n1]) - truncation_bound(coeffs, J, delta, E1, alpha, nsub)
    if budget < 0:
        return center, None
    kept = [P[:n1].tolist() for P in coeffs]
    for i in range(n1):
        terms = sorted((abs(c) * delta**j, j, col) for j in range(1, len(kept))
                       for col, c in enumerate(kept[j][i]))
        dropped = 0.0
        for w, j, col in terms:
            dropped += w
            if dropped > budget:
                break
            kept[j][i][col] = 0.0
    while len(kept) > 1 and not any(any(row) for row in kept[-1]):
        kept.pop()
    return center, kept


def fixed_map(M, G, nsub, hs, h=None):
    """The composite map of nsub RK4 substeps of s' = M s + G w at a fixed speed, exact: [Phi | Gam]
    (first-order hold, ``h`` given: the augmented map, whose top rows are [Phi | Gam | Gam_e])."""
    Ms, Gs = _arrays([M]), _arrays([G])
    if h is not None:
        Ms, Gs = augment(Ms, Gs, h)
    return power(substep(Ms, Gs, hs, 0), nsub, Ms[0].shape[0], 0)[0].tolist()
