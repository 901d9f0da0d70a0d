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


_U = 2.0 ** -53                 # unit roundoff of doubles (round to nearest)
_ETA = 2.0 ** -1074             # the smallest subnormal: the absolute floor of a rounding error


def _up(x: float) -> float:
    """The next double above x: above the exact value of an operation that x rounds to nearest."""
    return math.nextafter(x, math.inf)


def expm_taylor(M, with_error: bool = False):
    """exp(M): scaling X = M / 2^s with ||X||_inf <= 1/2, Horner's Taylor series of degree 16
    (truncation < 0.5^17/17! ~ 2e-20 relative), s squarings, products summed from the left: the
    interval observer's step maps (its tables at the default step and the runtime at any other).
    ValueError if ||M||_inf is not finite or above 1e300.

    ``with_error``: also returns a bound e >= ||E - exp(M)||_inf (so >= every entry's error) for the
    doubles M given, a running bound of the evaluation (Higham, Accuracy and Stability, 2nd ed.,
    eq. 3.13: a dot product of m terms added from the left is within gamma_m = m u / (1 - m u) of
    sum |a_k b_k|): Horner step k, E' = I + (X E)/k, adds (gamma_m + 2 u) ||X|| ||E|| / k + u ||E'||
    to ||X|| e / k; the series remainder is ||X||^17 / 17! / (1 - ||X|| / 18); a squaring
    E' = E E turns e into e (2 ||E|| + e) + gamma_m ||E||^2. The bound is evaluated in doubles
    and multiplied by 1 + 2^-20 (far above the ~100 u of its own roundings) and rounded up; norms
    of E by row sums, also inflated. Underflow adds at most m eta per product (counted)."""
    m = len(M)
    norm = max(total(map(abs, row)) for row in M)
    if not norm <= 1e300:
        raise ValueError(f"no finite step map (||M h|| = {norm!r})")
    s = max(0, math.ceil(math.log2(norm / 0.5))) if norm > 0.5 else 0
    scale = 0.5 ** s
    X = [[x * scale for x in row] for row in M]
    E = [[1.0 if i == j else 0.0 for j in range(m)] for i in range(m)]
    if with_error:
        nx = max(total(map(abs, row)) for row in X) * (1.0 + 2.0 ** -40) + m * _ETA
        gam = (m + 2) * _U * 1.01          # gamma_m + 2 u (m u << 1)
        nE, err = 1.0, 0.0
    for k in range(16, 0, -1):
        XE = _matmul_left(X, E)
        E = [[(1.0 if i == j else 0.0) + XE[i][j] / k for j in range(m)] for i in range(m)]
        if with_error:
            nE1 = max(total(map(abs, row)) for row in E) * (1.0 + 2.0 ** -40)
            err = (nx * err + gam * nx * nE + m * _ETA) / k + _U * nE1
            nE = nE1
    if not with_error:
        for _ in range(s):
            E = _matmul_left(E, E)
        return E
    # the series remainder: sum_{j >= 17} nx^j / j!, nx <= 1/2
    err += nx ** 17 / math.factorial(17) / (1.0 - nx / 18.0)
    gm = m * _U * 1.01
    for _ in range(s):
        err = err * (2.0 * nE + err) + gm * nE * nE + m * _ETA
        E = _matmul_left(E, E)
        nE = max(total(map(abs, row)) for row in E) * (1.0 + 2.0 ** -40)
    return E, _up(err * (1.0 + 2.0 ** -20))


def phi_gamma(N, h: float, eta: float, order: int = 1, with_error: bool = False):
    """(Phi, Gam[, Gam1, Gam2]) = (exp(N h), int_0^h exp(N s) ds, int_0^h exp(N (h - s)) s ds,
    int_0^h exp(N (h - s)) s^2/2 ds) for a Metzler N with N + eta I >= 0: the top blocks of the
    exponential of the nonnegative block matrix [[N + eta I, I, ..], [0, eta I, I, ..], ..] h
    times exp(-eta h), so every entry is >= 0 in floating point too (Lemma 2: order preserving).

    ``with_error``: the maps and then e >= the error of every entry, for the exact N, h, eta
    (the maps' bracket [map - e, map + e]): ``expm_taylor``'s bound for the doubles of the block
    matrix, plus the rounding of those doubles (each entry of M >= 0 within 2 u of its exact value:
    |exp(M') - exp(M)| <= 2u M exp(M (1 + 2u)) for |M' - M| <= 2u M, M >= 0, so in norm at most
    2u ||M|| e^(2u ||M||) (||E|| + e)), times exp(-eta h) and its rounding (its argument within u,
    libm's exp within 2 ulps, the product within u). An infinite e: no useful bound."""
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
    damp = math.exp(-eta * h)
    if not with_error:
        E = expm_taylor(M)
        return tuple([[E[i][b * n + j] * damp for j in range(n)] for i in range(n)] for b in range(nb))
    nM = max(total(row) for row in M) * (1.0 + 2.0 ** -40)
    E, err = expm_taylor(M, with_error=True)
    nE = max(total(map(abs, row)) for row in E) * (1.0 + 2.0 ** -40)
    eps = 2.01 * _U
    err += eps * nM * math.exp(eps * nM) * (nE + err)
    eh = eta * h
    err = _up((err * (1.0 + 8.0 * _U) + nE * (6.0 * _U + 2.0 * _U * eh)) * damp * (1.0 + 2.0 ** -20))
    if not math.isfinite(err):
        err = math.inf
    maps = tuple([[E[i][b * n + j] * damp for j in range(n)] for i in range(n)] for b in range(nb))
    return maps + (err,)
