"""Mathematical checks of latobs.synthesis.hinf (independent verification primitives)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from latobs.synthesis.hinf import (
    HinfResult,
    frequency_sweep_peak,
    hinf_norm,
    pole_region,
    slowest_pole_seen_by,
)


# ------------------------------------------------------------------------------------------
# helpers
# ------------------------------------------------------------------------------------------
def random_stable_system(rng, n, m, p, lightly_damped=False, with_d=False):
    """Stable (A, B, C, D): a real modal form (real poles and complex pairs) in random
    well-conditioned coordinates. lightly_damped puts at least one pair at zeta in [0.01, 0.05]."""
    blocks = []
    k = 0
    first = True
    while k < n:
        if n - k >= 2 and (rng.random() < 0.6 or (lightly_damped and first)):
            wn = 10 ** rng.uniform(-1, 1.5)
            zeta = rng.uniform(0.01, 0.05) if (lightly_damped and first) else rng.uniform(0.1, 0.9)
            sig, wd = zeta * wn, wn * math.sqrt(1 - zeta ** 2)
            blocks.append(np.array([[-sig, wd], [-wd, -sig]]))
            k += 2
            first = False
        else:
            blocks.append(np.array([[-(10 ** rng.uniform(-1, 1.5))]]))
            k += 1
    Am = np.zeros((n, n))
    i = 0
    for blk in blocks:
        s = blk.shape[0]
        Am[i:i + s, i:i + s] = blk
        i += s
    T = np.eye(n) + 0.4 * rng.standard_normal((n, n))
    while np.linalg.cond(T) > 50:
        T = np.eye(n) + 0.4 * rng.standard_normal((n, n))
    A = T @ Am @ np.linalg.inv(T)
    B = rng.standard_normal((n, m))
    C = rng.standard_normal((p, n))
    D = rng.standard_normal((p, m)) * 0.3 if with_d else np.zeros((p, m))
    return A, B, C, D


def brl_gamma(A, B, C, D):
    """H-infinity norm by the bounded-real-lemma (KYP) LMI, min gamma^2 (test-only)."""
    cp = pytest.importorskip("cvxpy")
    n, m = B.shape
    p = C.shape[0]
    P = cp.Variable((n, n), symmetric=True)
    g2 = cp.Variable()
    M = cp.bmat([
        [A.T @ P + P @ A + C.T @ C, P @ B + C.T @ D],
        [B.T @ P + D.T @ C, D.T @ D - g2 * np.eye(m)],
    ])
    prob = cp.Problem(cp.Minimize(g2), [0.5 * (M + M.T) << 0, P >> 0])
    prob.solve(solver=cp.CLARABEL)
    assert prob.status == cp.OPTIMAL, prob.status
    return math.sqrt(g2.value)


def _systems():
    rng = np.random.default_rng(20240611)
    out = []
    for i in range(30):
        n = int(rng.integers(2, 9))
        m = int(rng.integers(1, 4))
        p = int(rng.integers(1, 4))
        out.append(random_stable_system(rng, n, m, p, lightly_damped=(i % 3 == 0),
                                        with_d=(i % 5 == 4)))
    return out


SYSTEMS = _systems()


# ------------------------------------------------------------------------------------------
# analytic cases
# ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("k,a", [(1.0, 1.0), (3.0, 0.5), (-2.0, 40.0)])
def test_first_order(k, a):
    res = hinf_norm([[-a]], [[1.0]], [[k]])
    assert isinstance(res, HinfResult)
    assert res.norm == pytest.approx(abs(k) / a, rel=1e-8)
    assert res.peak_frequency_rad_s == pytest.approx(0.0, abs=1e-12)
    assert res.lower <= abs(k) / a * (1 + 1e-12) <= res.upper * (1 + 1e-12)


@pytest.mark.parametrize("wn", [0.3, 1.0, 25.0])
def test_second_order_resonance(wn):
    zeta = 0.1
    A = np.array([[0.0, 1.0], [-wn ** 2, -2 * zeta * wn]])
    B = np.array([[0.0], [wn ** 2]])
    C = np.array([[1.0, 0.0]])
    res = hinf_norm(A, B, C)
    peak = 1.0 / (2 * zeta * math.sqrt(1 - zeta ** 2))
    w_r = wn * math.sqrt(1 - 2 * zeta ** 2)
    assert res.norm == pytest.approx(peak, rel=1e-8)
    assert res.peak_frequency_rad_s == pytest.approx(w_r, rel=1e-4)
    g, w = frequency_sweep_peak(A, B, C)
    assert g == pytest.approx(peak, rel=1e-9)
    assert w == pytest.approx(w_r, rel=1e-4)


def test_feedthrough_nonzero():
    # G(s) = 1/(s+1) + d: with d > 0 the peak |1 + d| is at w = 0; with d < 0 and |d| large
    # (d = -3) |G(jw)| increases to |d| = 3 as w -> inf, the norm is sigma_max(D).
    r = hinf_norm([[-1.0]], [[1.0]], [[1.0]], [[0.5]])
    assert r.norm == pytest.approx(1.5, rel=1e-8)
    r = hinf_norm([[-1.0]], [[1.0]], [[1.0]], [[-3.0]])
    assert r.norm == pytest.approx(3.0, rel=1e-8)
    assert math.isinf(r.peak_frequency_rad_s)
    # resonant second order plus D: compare with the sweep
    wn, zeta = 2.0, 0.05
    A = np.array([[0.0, 1.0], [-wn ** 2, -2 * zeta * wn]])
    B = np.array([[0.0, 1.0], [wn ** 2, 0.0]])
    C = np.array([[1.0, 0.0], [0.0, 1.0]])
    D = np.array([[0.4, -0.2], [0.1, 0.3]])
    r = hinf_norm(A, B, C, D)
    g, _ = frequency_sweep_peak(A, B, C, D)
    assert r.norm == pytest.approx(g, rel=1e-7)
    assert r.norm >= np.linalg.norm(D, 2)


def test_unstable_raises():
    with pytest.raises(ValueError, match="max real part"):
        hinf_norm([[0.5, 0.0], [0.0, -1.0]], [[1.0], [1.0]], [[1.0, 1.0]])
    with pytest.raises(ValueError, match="Hurwitz"):
        hinf_norm([[0.0, 1.0], [-1.0, 0.0]], [[0.0], [1.0]], [[1.0, 0.0]])  # poles on the axis


def test_zero_system():
    A = np.array([[-1.0, 0.0], [0.0, -2.0]])
    assert hinf_norm(A, np.zeros((2, 1)), [[1.0, 1.0]]).norm == 0.0
    assert hinf_norm(A, [[1.0], [1.0]], np.zeros((2, 2))).norm == 0.0
    # non-trivial B and C but the transfer is zero (B excites mode 1, C sees mode 2 only)
    assert hinf_norm(A, [[1.0], [0.0]], [[0.0, 1.0]]).norm == 0.0


# ------------------------------------------------------------------------------------------
# random MIMO systems
# ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("idx", range(len(SYSTEMS)))
def test_random_against_sweep(idx):
    A, B, C, D = SYSTEMS[idx]
    r = hinf_norm(A, B, C, D)
    g, w = frequency_sweep_peak(A, B, C, D)
    assert r.norm == pytest.approx(g, rel=1e-6)
    # the sweep is a lower bound, the Hamiltonian upper bound must dominate it
    assert g <= r.upper * (1 + 1e-12)
    assert r.lower <= r.upper <= r.lower * (1 + 2.1e-9)


@pytest.mark.parametrize("idx", [0, 1, 4, 7, 12])
def test_random_against_brl_lmi(idx):
    A, B, C, D = SYSTEMS[idx]
    r = hinf_norm(A, B, C, D)
    assert r.norm == pytest.approx(brl_gamma(A, B, C, D), rel=1e-4)


# ------------------------------------------------------------------------------------------
# pole region and slowest visible pole
# ------------------------------------------------------------------------------------------
def test_pole_region_known_matrix():
    # eigenvalues -1 +- 2j (modulus sqrt 5) and -4
    A = np.array([[-1.0, 2.0, 0.0], [-2.0, -1.0, 0.0], [0.0, 0.0, -4.0]])
    r = pole_region(A, alpha=0.5, radius=5.0)
    lam = np.sort_complex(r["eigenvalues"])
    np.testing.assert_allclose(lam, np.sort_complex(np.array([-4, -1 - 2j, -1 + 2j])), atol=1e-12)
    assert r["max_real_part"] == pytest.approx(-1.0)
    assert r["max_modulus"] == pytest.approx(4.0)
    assert r["alpha_stable"] and r["in_disk"]
    assert not pole_region(A, alpha=1.0, radius=5.0)["alpha_stable"]   # Re = -1 not < -1
    assert not pole_region(A, alpha=0.5, radius=4.0)["in_disk"]        # |-4| not < 4
    assert pole_region(A, alpha=0.5, radius=3.0)["radius_margin"] == pytest.approx(-1.0)


def test_slowest_pole_observable_vs_unobservable():
    rng = np.random.default_rng(3)
    # modes: -0.05 (slow, unobservable), -0.2 (slow, observable), -3 +- 4j, -10
    Am = np.zeros((5, 5))
    Am[0, 0] = -0.05
    Am[1, 1] = -0.2
    Am[2:4, 2:4] = [[-3.0, 4.0], [-4.0, -3.0]]
    Am[4, 4] = -10.0
    Bm = np.ones((5, 2))
    Cm = np.array([[0.0, 1.0, 1.0, 0.0, 1.0]])       # zero on mode 0: unobservable
    T = np.eye(5) + 0.3 * rng.standard_normal((5, 5))
    A = T @ Am @ np.linalg.inv(T)
    B = T @ Bm
    C = Cm @ np.linalg.inv(T)
    pole, weight = slowest_pole_seen_by(A, B, C)
    assert pole == pytest.approx(-0.2, abs=1e-9)
    assert 1e-6 <= weight <= 1.0
    # once mode 1 becomes uncontrollable as well, the complex pair is the slowest seen
    Bm2 = Bm.copy()
    Bm2[1] = 0.0
    pole2, _ = slowest_pole_seen_by(A, T @ Bm2, C)
    assert pole2.real == pytest.approx(-3.0, abs=1e-9)
    assert pole2.imag == pytest.approx(4.0, abs=1e-9)
    # with an observable C the unobservable mode shows up again
    pole3, _ = slowest_pole_seen_by(A, B, np.ones((1, 5)) @ np.linalg.inv(T))
    assert pole3 == pytest.approx(-0.05, abs=1e-9)
    # zero transfer
    with pytest.raises(ValueError):
        slowest_pole_seen_by(A, np.zeros((5, 1)), C)
