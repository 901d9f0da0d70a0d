"""Small dense linear algebra for the FMU runtimes (standard library only; lists of rows).

Shared by the runtimes that discretise a linear ODE exactly at the FMU's step
(``tf_estimator.py``, ``motorcycle_observer.py``): the matrix exponential by scaling and squaring
and the Van Loan block form of the zero-order-hold map.
"""
from __future__ import annotations

import math


def matmul(A, B):
    """A B; products summed with math.fsum (correctly rounded dot products)."""
    cols = list(zip(*B))
    return [[math.fsum(a * b for a, b in zip(row, col)) for col in cols] for row in A]


def norm_inf(A) -> float:
    """Induced infinity norm (largest row sum of |a|); 0 for an empty matrix."""
    return max(sum(abs(a) for a in row) for row in A) if A else 0.0


def expm(M) -> list[list[float]]:
    """exp(M) of a square matrix by scaling and squaring with a Taylor series.

    s = the least integer >= 0 with ||M||_inf 2^-s <= 1/2; E = sum_k (M 2^-s)^k / k!, summed
    until ||term||_inf <= 1e-18 ||E||_inf (at most 60 terms; every later term is at least 2x
    smaller than its predecessor, so the remainder is below ~2e-18 relative); exp(M) = E^(2^s).
    Raises OverflowError/ValueError for a non-finite norm (the callers turn that into a refused
    step)."""
    n = len(M)
    norm = norm_inf(M)
    s = max(0, math.ceil(math.log2(norm / 0.5))) if norm > 0.5 else 0
    scale = 2.0 ** -s
    X = [[x * scale for x in row] for row in M]
    E = [[1.0 if i == j else 0.0 for j in range(n)] for i in range(n)]
    term = [row[:] for row in E]
    for k in range(1, 60):
        term = [[x / k for x in row] for row in matmul(term, X)]
        E = [[e + t for e, t in zip(re, rt)] for re, rt in zip(E, term)]
        if norm_inf(term) <= 1e-18 * norm_inf(E):
            break
    for _ in range(s):
        E = matmul(E, E)
    return E


def zoh_map(A, B, h: float):
    """Exact zero-order-hold map of x' = A x + B u over h (u held), by Van Loan's block form
    [[Phi, Gam], [0, I]] = expm(h [[A, B], [0, 0]]). A: n x n, B: n x m (lists of rows).
    Returns the top n rows [Phi | Gam] (each of length n + m)."""
    n, m = len(A), len(B[0]) if B else 0
    big = [[h * a for a in A[i]] + [h * b for b in B[i]] for i in range(n)] + [[0.0] * (n + m) for _ in range(m)]
    return expm(big)[:n]


def matrix(x, rows: int, cols: int, what: str):
    """A rows x cols matrix of finite floats from a design file's nested lists, or a ValueError
    naming ``what``."""
    try:
        M = [[float(v) for v in row] for row in x]
    except (TypeError, ValueError) as exc:
        raise ValueError(f"design file: {what} must be a {rows}x{cols} matrix of numbers ({exc})") from exc
    if len(M) != rows or any(len(r) != cols for r in M):
        raise ValueError(f"design file: {what} must be {rows}x{cols}, got {len(M)}x{len(M[0]) if M else 0}")
    if not all(math.isfinite(v) for r in M for v in r):
        raise ValueError(f"design file: {what} has a non-finite entry")
    return M
