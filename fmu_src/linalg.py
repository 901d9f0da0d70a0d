"""Small dense linear algebra for the FMU runtimes (standard library only; lists of rows).

Shared by the runtimes that discretise a linear ODE exactly at the FMU's step and by the
build-time tables that store those maps at the default step (``synthesis.tables``): the matrix
exponential by scaling and squaring, the Van Loan block form of the zero-order-hold map, and the
interval observer's order-preserving step maps (``phi_gamma``).
"""
from __future__ import annotations

import math
from operator import mul

# Sums of floats add from the left (``dot``, ``total``), never through a bare sum(): from Python 3.12
# on, sum() of floats is compensated (Neumaier), so the same runtime would give other bits on
# another interpreter than on 3.11 and than the C models, which add from the left. Where sum() does
# add from the left (CPython before 3.12; checked on import), it is that very loop at C speed (the
# tables' ~5 million dot products).
def _dot_loop(a, b, start: float = 0.0) -> float:
    s = start
    for x, y in zip(a, b):
        s += x * y
    return s


def _total_loop(xs, start: float = 0.0) -> float:
    s = start
    for x in xs:
        s += x
    return s


def _dot_sum(a, b, start: float = 0.0) -> float:
    return _left_sum(map(mul, a, b), start)


def _total_sum(xs, start: float = 0.0) -> float:
    return _left_sum(xs, start)


def _matvec_loop(A, v) -> list[float]:
    return [_dot_loop(row, v) for row in A]


def _matvec_sum(A, v) -> list[float]:
    return [_left_sum(map(mul, row, v), 0.0) for row in A]


_left_sum = sum
_SUM_ADDS_FROM_THE_LEFT = sum([1.0, 1e100, 1.0, -1e100]) == 0.0     # compensated: 2.0
dot = _dot_sum if _SUM_ADDS_FROM_THE_LEFT else _dot_loop
dot.__doc__ = "start + a[0] b[0] + a[1] b[1] + ..., added from the left in double precision."
total = _total_sum if _SUM_ADDS_FROM_THE_LEFT else _total_loop
total.__doc__ = "start + xs[0] + xs[1] + ..., added from the left in double precision."
matvec = _matvec_sum if _SUM_ADDS_FROM_THE_LEFT else _matvec_loop
matvec.__doc__ = "A v: each row's products added from the left (``dot``)."


def matmul(A, B):
    """A B; products summed with math.fsum (correctly rounded dot products)."""
    cols = list(zip(*B))
    return [[math.fsum(a * b for a, b in zip(row, col)) for col in cols] for row in A]


def _matmul_left(A, B):
    """A B; products summed from the left (the interval observer's arithmetic, as its C model)."""
    cols = list(zip(*B))
    return [[dot(row, col) for col in cols] for row in A]


def norm_inf(A) -> float:
    """Induced infinity norm (largest row sum of |a|); 0 for an empty matrix."""
    return max(total(map(abs, row)) for row in A) if A else 0.0


def matmul_left(A, B):
    """A B; each product summed from the left from 0.0 (``dot``): the C models' ``la_matmul``."""
    return _matmul_left(A, B)


def expm(M, mm=matmul) -> list[list[float]]:
    """exp(M) of a square matrix by scaling and squaring with a Taylor series.

    s = the least integer >= 0 with ||M||_inf 2^-s <= 1/2; E = sum_k (M 2^-s)^k / k!, summed
    until ||term||_inf <= 1e-18 ||E||_inf (at most 60 terms; every later term is at least 2x
    smaller than its predecessor, so the remainder is below ~2e-18 relative); exp(M) = E^(2^s).
    Raises OverflowError/ValueError for a non-finite norm (the callers turn that into a refused
    step). ``mm`` multiplies: ``matmul`` (fsum, correctly rounded dot products: the build-time
    tables) or ``matmul_left`` (the C models' ``la_expm`` operation for operation: a runtime that
    computes its maps at every step gives the C model's bits)."""
    n = len(M)
    norm = norm_inf(M)
    s = max(0, math.ceil(math.log2(norm / 0.5))) if norm > 0.5 else 0
    scale = 2.0 ** -s
    X = [[x * scale for x in row] for row in M]
    E = [[1.0 if i == j else 0.0 for j in range(n)] for i in range(n)]
    term = [row[:] for row in E]
    for k in range(1, 60):
        term = [[x / k for x in row] for row in mm(term, X)]
        E = [[e + t for e, t in zip(re, rt)] for re, rt in zip(E, term)]
        if norm_inf(term) <= 1e-18 * norm_inf(E):
            break
    for _ in range(s):
        E = mm(E, E)
    return E


def zoh_map(A, B, h: float, mm=matmul):
    """Exact zero-order-hold map of x' = A x + B u over h (u held), by Van Loan's block form
    [[Phi, Gam], [0, I]] = expm(h [[A, B], [0, 0]]). A: n x n, B: n x m (lists of rows).
    Returns the top n rows [Phi | Gam] (each of length n + m). ``mm``: as in ``expm``."""
    n, m = len(A), len(B[0]) if B else 0
    big = [[h * a for a in A[i]] + [h * b for b in B[i]] for i in range(n)] + [[0.0] * (n + m) for _ in range(m)]
    return expm(big, mm)[:n]


def matrix(x, rows: int, cols: int, what: str, source: str = "design file"):
    """A rows x cols matrix of finite floats from a data file's nested lists, or a ValueError
    naming ``source`` and ``what``."""
    try:
        M = [[float(v) for v in row] for row in x]
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{source}: {what} must be a {rows}x{cols} matrix of numbers ({exc})") from exc
    if len(M) != rows or any(len(r) != cols for r in M):
        raise ValueError(f"{source}: {what} must be {rows}x{cols}, got {len(M)}x{len(M[0]) if M else 0}")
    if not all(math.isfinite(v) for r in M for v in r):
        raise ValueError(f"{source}: {what} has a non-finite entry")
    return M


def expm_taylor(M):
    """exp(M): scaling X = M / 2^s with ||X||_inf <= 1/2, Horner's Taylor series of degree 16
    (truncation < 0.5^17/17! ~ 2e-20 relative), s squarings, products summed from the left: the
    interval observer's step maps (its tables at the default step and the runtime at any other).
    ValueError if ||M||_inf is not finite or above 1e300."""
    m = len(M)
    norm = max(total(map(abs, row)) for row in M)
    if not norm <= 1e300:
        raise ValueError(f"no finite step map (||M h|| = {norm!r})")
    s = max(0, math.ceil(math.log2(norm / 0.5))) if norm > 0.5 else 0
    scale = 0.5 ** s
    X = [[x * scale for x in row] for row in M]
    E = [[1.0 if i == j else 0.0 for j in range(m)] for i in range(m)]
    for k in range(16, 0, -1):
        XE = _matmul_left(X, E)
        E = [[(1.0 if i == j else 0.0) + XE[i][j] / k for j in range(m)] for i in range(m)]
    for _ in range(s):
        E = _matmul_left(E, E)
    return E


def phi_gamma(N, h: float, eta: float, order: int = 1):
    """(Phi, Gam[, Gam1, Gam2]) = (exp(N h), int_0^h exp(N s) ds, int_0^h exp(N (h - s)) s ds,
    int_0^h exp(N (h - s)) s^2/2 ds) for a Metzler N with N + eta I >= 0: the top blocks of the
    exponential of the nonnegative block matrix [[N + eta I, I, ..], [0, eta I, I, ..], ..] h
    times exp(-eta h), so every entry is >= 0 in floating point too (Lemma 2: order preserving)."""
    n = len(N)
    if not (h > 0 and math.isfinite(h)):
        raise ValueError(f"step size must be finite and > 0 s, got {h!r}")
    nb = order + 1
    m = nb * n
    M = [[0.0] * m for _ in range(m)]
    for i in range(n):
        for j in range(n):
            M[i][j] = (N[i][j] + (eta if i == j else 0.0)) * h
    for b in range(1, nb):
        for i in range(n):
            M[(b - 1) * n + i][b * n + i] = h
            M[b * n + i][b * n + i] = eta * h
    if min(min(row) for row in M) < 0:
        raise ValueError("phi_gamma needs N + eta I >= 0 elementwise (N Metzler, eta large enough)")
    E = expm_taylor(M)
    damp = math.exp(-eta * h)
    return tuple([[E[i][b * n + j] * damp for j in range(n)] for i in range(n)] for b in range(nb))
