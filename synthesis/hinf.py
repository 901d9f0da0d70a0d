"""Independent verification primitives for the certificates, from state-space matrices alone with
dense numpy/scipy (no Lyapunov matrix, no solver): H-infinity norm by Hamiltonian bisection
(Boyd-Balakrishnan, Bruinsma-Steinbuch), a frequency-sweep cross-check, pole regions (Chilali &
Gahinet 1996) and the slowest pole a transfer sees."""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
import scipy.linalg as sla
from scipy.optimize import minimize_scalar

__all__ = [
    "HinfResult",
    "hinf_norm",
    "frequency_sweep_peak",
    "sigma_max_at",
    "pole_region",
    "slowest_pole_seen_by",
]


class HinfResult(NamedTuple):
    """Result of :func:`hinf_norm`.

    norm
        The H-infinity norm (midpoint of ``[lower, upper]``; relative width ``<= 2 tol``).
    peak_frequency_rad_s
        Angular frequency (rad/s) where the gain ``lower`` was attained; ``inf`` when the
        supremum is the feedthrough ``sigma_max(D)`` approached as ``w -> inf``; ``nan`` for
        the zero transfer function.
    method
        Short description of how the value was obtained.
    lower
        A gain actually attained, ``sigma_max(G(j peak_frequency_rad_s))`` (a guaranteed lower
        bound up to rounding).
    upper
        A level ``gamma`` at which the Hamiltonian had no imaginary-axis eigenvalue
        (upper bound).
    iterations
        Number of Hamiltonian eigenvalue problems solved.
    """

    norm: float
    peak_frequency_rad_s: float
    method: str
    lower: float = math.nan
    upper: float = math.nan
    iterations: int = 0


# --------------------------------------------------------------------------------------------
# helpers
# --------------------------------------------------------------------------------------------
def _as_system(A, B, C, D):
    A = np.atleast_2d(np.asarray(A, dtype=float))
    B = np.asarray(B, dtype=float)
    C = np.asarray(C, dtype=float)
    n = A.shape[0]
    if A.ndim != 2 or A.shape != (n, n):
        raise ValueError(f"A must be square, got shape {A.shape}")
    if B.ndim == 1:
        B = B.reshape(n, 1)
    if C.ndim == 1:
        C = C.reshape(1, n)
    if B.ndim != 2 or B.shape[0] != n:
        raise ValueError(f"B must have {n} rows, got shape {B.shape}")
    if C.ndim != 2 or C.shape[1] != n:
        raise ValueError(f"C must have {n} columns, got shape {C.shape}")
    p, m = C.shape[0], B.shape[1]
    if D is None:
        D = np.zeros((p, m))
    else:
        D = np.asarray(D, dtype=float)
        if D.ndim == 0:
            D = D.reshape(1, 1)
        if D.shape != (p, m):
            raise ValueError(f"D must have shape {(p, m)}, got {D.shape}")
    for name, M in (("A", A), ("B", B), ("C", C), ("D", D)):
        if not np.all(np.isfinite(M)):
            raise ValueError(f"{name} contains non-finite entries")
    return A, B, C, D


def _gains(A, B, C, D, w) -> np.ndarray:
    """sigma_max(C (j w I - A)^{-1} B + D) for an array of frequencies (batched solves)."""
    w = np.atleast_1d(np.asarray(w, dtype=float))
    n = A.shape[0]
    out = np.empty(w.shape[0])
    if n == 0:
        out[:] = np.linalg.norm(D, 2) if D.size else 0.0
        return out
    eye = np.eye(n)
    Bc = B.astype(complex)
    chunk = 512
    for i in range(0, w.shape[0], chunk):
        wc = w[i:i + chunk]
        M = 1j * wc[:, None, None] * eye[None] - A[None]
        X = np.linalg.solve(M, np.broadcast_to(Bc, (wc.shape[0],) + Bc.shape))
        G = C[None] @ X + D[None]
        if G.shape[1] == 0 or G.shape[2] == 0:
            out[i:i + chunk] = 0.0
        else:
            out[i:i + chunk] = np.linalg.svd(G, compute_uv=False)[:, 0]
    return out


def sigma_max_at(A, B, C, D=None, w=0.0) -> float | np.ndarray:
    """Largest singular value of ``G(j w)`` (``w`` in rad/s; scalar or array)."""
    A, B, C, D = _as_system(A, B, C, D)
    g = _gains(A, B, C, D, w)
    return float(g[0]) if np.ndim(w) == 0 else g


def _is_zero_transfer(A, B, C, D) -> bool:
    """True when G(s) == 0: D == 0 and every Markov parameter C A^k B (k < n) vanishes."""
    if np.any(D != 0.0):
        return False
    nb, nc = np.linalg.norm(B), np.linalg.norm(C)
    if nb == 0.0 or nc == 0.0:
        return True
    na = max(np.linalg.norm(A, 2), 1e-300)
    X = B / nb
    eps = 1e3 * np.finfo(float).eps * max(A.shape[0], 1)
    for _ in range(A.shape[0]):
        if np.linalg.norm(C @ X) / nc > eps:
            return False
        X = (A @ X) / na
        nx = np.linalg.norm(X)
        if nx == 0.0:
            return True
        X = X / nx
    return True


def _hamiltonian(A, B, C, D, gamma):
    """Hamiltonian whose imaginary eigenvalues j w are exactly the w with gamma in sv(G(jw)).

    H(gamma) = [[A + B R^-1 D^T C,            B R^-1 B^T            ],
                [-C^T (I + D R^-1 D^T) C,    -(A + B R^-1 D^T C)^T ]],
    R = gamma^2 I - D^T D  (positive definite for gamma > sigma_max(D)).
    """
    m = B.shape[1]
    p = C.shape[0]
    R = gamma * gamma * np.eye(m) - D.T @ D
    RinvDt = np.linalg.solve(R, D.T)          # R^-1 D^T
    RinvBt = np.linalg.solve(R, B.T)          # R^-1 B^T
    Ah = A + B @ RinvDt @ C
    S = np.eye(p) + D @ RinvDt                # (I - D D^T / gamma^2)^-1
    S = 0.5 * (S + S.T)
    G12 = B @ RinvBt
    G12 = 0.5 * (G12 + G12.T)
    G21 = -(C.T @ S @ C)
    return np.block([[Ah, G12], [G21, -Ah.T]])


def _imaginary_axis_frequencies(H, rel_tol) -> np.ndarray:
    """Non-negative w such that j w is (numerically) an eigenvalue of H.

    An eigenvalue counts as purely imaginary when |Re lambda| <= rel_tol * max(|lambda|,
    floor), floor = 1e-8 * ||H||_1 (guards eigenvalues near 0). Spurious candidates are harmless
    for the bisection (they only add test frequencies); missed ones would stop it early, so
    the tolerance errs on the loose side.
    """
    lam = sla.eigvals(H)
    hn = np.linalg.norm(H, 1)
    scale = np.maximum(np.abs(lam), 1e-8 * hn)
    mask = np.abs(lam.real) <= rel_tol * scale
    w = np.abs(lam.imag[mask])
    return np.unique(w)


# --------------------------------------------------------------------------------------------
# H-infinity norm
# --------------------------------------------------------------------------------------------
def hinf_norm(A, B, C, D=None, tol: float = 1e-9, *, imag_tol: float = 1e-6,
              max_iter: int = 100) -> HinfResult:
    """H-infinity norm of ``G(s) = C (sI - A)^{-1} B + D`` for Hurwitz ``A``.

    Computes ``||G||_inf = sup_{w >= 0} sigma_max(G(j w))`` (w in rad/s) with the quadratically
    convergent two-sided algorithm of Bruinsma & Steinbuch (1990) and Boyd & Balakrishnan
    (1990), built on the Hamiltonian test of Boyd, Balakrishnan & Kabamba (1989):
    for ``gamma > sigma_max(D)``, ``gamma`` is a singular value of ``G(j w)`` if and only if
    ``j w`` is an eigenvalue of the Hamiltonian

        H(gamma) = [[A + B R^-1 D^T C,  B R^-1 B^T], [-C^T (I + D R^-1 D^T) C, -(A + B R^-1 D^T C)^T]],
        R = gamma^2 I - D^T D.

    Algorithm:

    1. lower bound ``gamma_lb = max(sigma_max(D), sigma_max(G(0)), sigma_max(G(j w_p)))`` with
       ``w_p`` ranging over the imaginary parts and the moduli of the poles;
    2. ``gamma = (1 + 2 tol) gamma_lb``; if ``H(gamma)`` has no imaginary eigenvalue, stop
       (``gamma`` is an upper bound);
    3. otherwise sort the imaginary-axis frequencies ``w_1 < ... < w_k`` and set
       ``gamma_lb = max_i sigma_max(G(j (w_i + w_{i+1}) / 2))`` (also evaluated at the ``w_i``);
       go to 2.

    Eigenvalues of ``H`` count as imaginary with the relative tolerance ``imag_tol``.
    If an iteration finds candidate frequencies but no test frequency above ``gamma`` (only
    possible for spurious, numerically-imaginary eigenvalues near a tangency), ``gamma`` is
    accepted as the upper bound.

    Parameters
    ----------
    A, B, C, D : array_like
        State-space matrices (``D`` defaults to zero).
    tol : float
        Relative accuracy: on return ``upper <= (1 + 2 tol) lower``.

    Returns
    -------
    HinfResult
        ``(norm, peak_frequency_rad_s, method, lower, upper, iterations)``.

    Raises
    ------
    ValueError
        If ``A`` is not Hurwitz (message gives the max real part) or shapes are inconsistent.
    RuntimeError
        If the iteration does not converge within ``max_iter`` Hamiltonian eigenproblems.
    """
    A, B, C, D = _as_system(A, B, C, D)
    if not (tol > 0):
        raise ValueError(f"tol must be positive, got {tol}")
    n = A.shape[0]
    poles = np.linalg.eigvals(A) if n else np.zeros(0, complex)
    if n:
        max_re = float(np.max(poles.real))
        if not max_re < 0.0:
            raise ValueError(
                f"A is not Hurwitz: max real part of its eigenvalues is {max_re:.6g} (>= 0); "
                "the H-infinity norm is defined here only for asymptotically stable A")

    if _is_zero_transfer(A, B, C, D):
        return HinfResult(0.0, math.nan, "zero transfer function", 0.0, 0.0, 0)

    sd = float(np.linalg.norm(D, 2)) if D.size else 0.0
    if n == 0:
        return HinfResult(sd, math.inf, "static gain", sd, sd, 0)

    # --- step 1: initial lower bound -------------------------------------------------------
    cand = np.concatenate(([0.0], np.abs(poles.imag), np.abs(poles)))
    cand = np.unique(cand)
    g = _gains(A, B, C, D, cand)
    k = int(np.argmax(g))
    gamma_lb, w_peak = float(g[k]), float(cand[k])
    if sd >= gamma_lb:
        gamma_lb, w_peak = sd, math.inf
    if gamma_lb <= 0.0:
        # Non-zero transfer vanishing at all test frequencies (non-generic): coarse sweep.
        ws = np.logspace(-6, 6, 241) * max(float(np.max(np.abs(poles))), 1e-12)
        gs = _gains(A, B, C, D, ws)
        k = int(np.argmax(gs))
        gamma_lb, w_peak = float(gs[k]), float(ws[k])
        if gamma_lb <= 0.0:
            return HinfResult(0.0, math.nan, "zero transfer function (numerically)", 0.0, 0.0, 0)

    # --- steps 2-3: two-sided iteration ----------------------------------------------------
    for it in range(1, max_iter + 1):
        gamma = (1.0 + 2.0 * tol) * gamma_lb
        H = _hamiltonian(A, B, C, D, gamma)
        if not np.all(np.isfinite(H)):
            raise RuntimeError(f"hinf_norm: Hamiltonian not finite at gamma={gamma:.6g}")
        wi = _imaginary_axis_frequencies(H, imag_tol)
        if wi.size == 0:
            return HinfResult(0.5 * (gamma_lb + gamma), w_peak,
                              "Hamiltonian two-sided (Bruinsma-Steinbuch / Boyd-Balakrishnan)",
                              gamma_lb, gamma, it)
        test_w = wi if wi.size == 1 else np.concatenate((0.5 * (wi[:-1] + wi[1:]), wi))
        gt = _gains(A, B, C, D, test_w)
        k = int(np.argmax(gt))
        if gt[k] <= gamma:
            # Only spurious / tangent imaginary eigenvalues: nothing above gamma anywhere.
            if gt[k] > gamma_lb:
                gamma_lb, w_peak = float(gt[k]), float(test_w[k])
            return HinfResult(0.5 * (gamma_lb + gamma), w_peak,
                              "Hamiltonian two-sided (Bruinsma-Steinbuch / Boyd-Balakrishnan); "
                              "stopped at a tangency", gamma_lb, gamma, it)
        gamma_lb, w_peak = float(gt[k]), float(test_w[k])
    raise RuntimeError(
        f"hinf_norm did not converge in {max_iter} iterations (last lower bound {gamma_lb:.12g} "
        f"at {w_peak:.6g} rad/s); the system may be badly scaled: try balancing the realization "
        "or a looser tol")


# --------------------------------------------------------------------------------------------
# frequency sweep cross-check
# --------------------------------------------------------------------------------------------
def frequency_sweep_peak(A, B, C, D=None, w=None, n: int = 4000) -> tuple[float, float]:
    """Peak gain ``max_w sigma_max(G(jw))`` by a dense sweep plus local refinement.

    ``G(jw) = C (jwI - A)^{-1} B + D`` is evaluated with linear solves (no inverse) and its
    largest singular value by SVD. Default grid: ``n`` logarithmically spaced frequencies from
    ``1e-4 * min|pole|`` to ``1e4 * max|pole|`` (rad/s), together with ``w = 0``, the pole moduli
    and the pole imaginary parts. The best few local maxima of the grid are then refined with
    ``scipy.optimize.minimize_scalar`` (bounded Brent) on ``log w`` between the neighbouring grid
    points. This is a lower bound on the H-infinity norm, used to cross-check :func:`hinf_norm`.

    Returns
    -------
    (peak_gain, w_peak)
        ``w_peak`` in rad/s.
    """
    A, B, C, D = _as_system(A, B, C, D)
    if w is None:
        poles = np.linalg.eigvals(A) if A.shape[0] else np.zeros(0, complex)
        mods = np.abs(poles)
        mods = mods[mods > 0]
        if mods.size:
            lo, hi = 1e-4 * float(mods.min()), 1e4 * float(mods.max())
        else:
            lo, hi = 1e-4, 1e4
        grid = np.logspace(np.log10(lo), np.log10(hi), int(n))
        extra = np.concatenate((mods, np.abs(poles.imag)))
        extra = extra[(extra > lo) & (extra < hi)]
        grid = np.unique(np.concatenate((grid, extra)))
        include_zero = True
    else:
        grid = np.unique(np.asarray(w, dtype=float).ravel())
        include_zero = bool(grid.size and grid[0] == 0.0)
        grid = grid[grid > 0]
    best_g, best_w = -np.inf, math.nan
    if include_zero:
        best_g, best_w = float(_gains(A, B, C, D, [0.0])[0]), 0.0
    if grid.size == 0:
        return best_g, best_w
    g = _gains(A, B, C, D, grid)
    # candidate local maxima (including end points), best first
    left = np.concatenate(([-np.inf], g[:-1]))
    right = np.concatenate((g[1:], [-np.inf]))
    idx = np.flatnonzero((g >= left) & (g >= right))
    idx = idx[np.argsort(g[idx])[::-1]][:8]
    lg = np.log(grid)
    for i in idx:
        if g[i] > best_g:
            best_g, best_w = float(g[i]), float(grid[i])
        a = lg[max(i - 1, 0)]
        b = lg[min(i + 1, grid.size - 1)]
        if b <= a:
            continue
        res = minimize_scalar(lambda t: -_gains(A, B, C, D, [math.exp(t)])[0],
                              bounds=(a, b), method="bounded",
                              options={"xatol": 1e-12, "maxiter": 500})
        if -res.fun > best_g:
            best_g, best_w = float(-res.fun), float(math.exp(res.x))
    return best_g, best_w


# --------------------------------------------------------------------------------------------
# pole region
# --------------------------------------------------------------------------------------------
def pole_region(A, alpha: float, radius: float) -> dict:
    """Eigenvalues of ``A`` against the Chilali-Gahinet (1996) LMI regions of the designs.

    The regions are the half plane ``{s : Re(s) < -alpha}`` (decay rate ``alpha`` in 1/s,
    i.e. rad/s) and the open disk ``{s : |s| < radius}`` centred at the origin (bounds the
    natural frequency, rad/s). The eigenvalues are computed directly (no Lyapunov matrix).

    Returns a dict with
    ``eigenvalues`` (complex ndarray), ``max_real_part``, ``max_modulus``,
    ``alpha_stable`` (all ``Re(lambda) < -alpha``), ``in_disk`` (all ``|lambda| < radius``),
    ``alpha_margin`` (``-alpha - max_real_part``, > 0 when satisfied),
    ``radius_margin`` (``radius - max_modulus``), and the ``alpha`` and ``radius`` tested.
    """
    A = np.atleast_2d(np.asarray(A, dtype=float))
    if A.ndim != 2 or A.shape[0] != A.shape[1]:
        raise ValueError(f"A must be square, got shape {A.shape}")
    lam = np.linalg.eigvals(A)
    max_re = float(np.max(lam.real)) if lam.size else -math.inf
    max_mod = float(np.max(np.abs(lam))) if lam.size else 0.0
    return {
        "eigenvalues": lam,
        "max_real_part": max_re,
        "max_modulus": max_mod,
        "alpha_stable": bool(max_re < -alpha),
        "in_disk": bool(max_mod < radius),
        "alpha_margin": float(-alpha - max_re),
        "radius_margin": float(radius - max_mod),
        "alpha": float(alpha),
        "radius": float(radius),
    }


# --------------------------------------------------------------------------------------------
# slowest visible pole
# --------------------------------------------------------------------------------------------
def slowest_pole_seen_by(A, B, C, negligible: float = 1e-6) -> tuple[complex, float]:
    """Slowest pole of ``A`` that actually appears in the transfer ``C (sI - A)^{-1} B``.

    With the eigendecomposition ``A = V diag(lambda) V^{-1}`` (right eigenvectors ``v_k`` = the
    columns of ``V``, left eigenvectors ``w_k^H`` = the rows of ``V^{-1}``, so that
    ``w_k^H v_k = 1``), the transfer is the modal sum

        C (sI - A)^{-1} B = sum_k (C v_k)(w_k^H B) / (s - lambda_k),

    and the step response of the output contains ``exp(lambda_k t)`` with the rank-one residue
    ``(C v_k)(w_k^H B)``. The weight of mode ``k`` is

        weight_k = ||C v_k|| * ||w_k^H B|| / max_j ||C v_j|| * ||w_j^H B||

    (invariant to eigenvector scaling). Modes with ``weight_k < negligible`` (default 1e-6)
    are uncontrollable from ``B`` or unobservable from ``C`` to working precision and are
    ignored. Among the others, the eigenvalue with the largest real part is returned: it sets
    the asymptotic rate ``exp(Re(lambda) t)`` at which the output converges after an input step
    (time constant ``-1/Re(lambda)`` s). For a complex pair the member with ``Im >= 0`` is
    returned.

    The weights are only meaningful for diagonalizable ``A`` with a reasonably conditioned
    eigenvector matrix; for (nearly) defective ``A`` the modal decomposition is ill-posed.

    Returns
    -------
    (pole, residue_weight)
        ``pole`` complex (rad/s), ``residue_weight`` in ``(0, 1]``.

    Raises
    ------
    ValueError
        If the transfer ``C (sI - A)^{-1} B`` is zero (no mode has a non-zero residue).
    """
    A, B, C, _ = _as_system(A, B, C, None)
    n = A.shape[0]
    if n == 0:
        raise ValueError("A is empty: no poles")
    lam, V = sla.eig(A)
    Wh = np.linalg.solve(V, np.eye(n))           # rows: left eigenvectors, w_k^H v_k = 1
    cv = np.linalg.norm(C @ V, axis=0)           # ||C v_k||
    wb = np.linalg.norm(Wh @ B, axis=1)          # ||w_k^H B||
    raw = cv * wb
    top = float(np.max(raw)) if raw.size else 0.0
    if not top > 0.0 or not np.isfinite(top):
        raise ValueError("the transfer C (sI - A)^-1 B is zero: no pole is seen by the output")
    weight = raw / top
    seen = np.flatnonzero(weight >= negligible)
    re = lam.real[seen]
    best_re = np.max(re)
    # ties (complex pair / repeated pole): prefer Im >= 0, then the heavier residue
    tie = seen[np.abs(re - best_re) <= 1e-12 * max(1.0, abs(best_re))]
    tie = sorted(tie, key=lambda k: (lam[k].imag < 0, -weight[k]))
    k = tie[0]
    return complex(lam[k]), float(weight[k])
