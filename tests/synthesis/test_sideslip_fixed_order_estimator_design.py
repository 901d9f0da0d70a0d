"""Paper 002 (Delibasi 2014): plant, coefficient polytope, Lemma 5 design, independent evaluation."""
from __future__ import annotations

import numpy as np
import numpy.polynomial.polynomial as P
import pytest
import scipy.signal

from latobs.synthesis import sideslip_fixed_order_estimator as f

REL = 0.005                                 # the paper's gamma within 0.5 %


@pytest.fixture(scope="module")
def boxes():
    return f.boxes()


@pytest.fixture(scope="module")
def paper_design(boxes):
    return f.design(boxes["paper"], order=1, central=f.C31, n_grid=5)


def test_transfer_functions_match_the_state_space_model():
    rng = np.random.default_rng(2)
    for _ in range(5):
        m, Iz, lf, lr = 1500.0, 2535.0, 1.4, 1.7
        Cf, Cr, v = rng.uniform(5e2, 1e5), rng.uniform(5e2, 1e5), rng.uniform(3, 40)
        A, B = f.state_space(m, Iz, lf, lr, Cf, Cr, v)
        num, den = scipy.signal.ss2tf(A, B.reshape(2, 1), np.eye(2), np.zeros((2, 1)))
        b1, b2, a = f.bicycle_tf(m, Iz, lf, lr, Cf, Cr, v)
        assert np.allclose(den[::-1], a, rtol=1e-10)
        assert np.allclose(num[0][::-1][:2], b1, rtol=1e-10)
        assert np.allclose(num[1][::-1][:2], b2, rtol=1e-10)
        # eq. (2) term by term
        assert A[0, 1] == pytest.approx(-1 + (-lf * Cf + lr * Cr) / (m * v ** 2))
        assert A[1, 1] == pytest.approx(-(lf ** 2 * Cf + lr ** 2 * Cr) / (Iz * v))


def test_boxes_follow_errata(boxes):
    ph, pa = boxes["physical"], boxes["paper"]
    k = 2 * 180 / np.pi
    assert ph.cf == pytest.approx((590 * k, 610 * k)) and ph.cr == pytest.approx((550 * k, 650 * k))
    assert pa.cf == (590.0, 610.0) and pa.cr == (550.0, 650.0)
    for b in (ph, pa):
        assert b.v == pytest.approx((20 / 3.6, 40 / 3.6))
        assert (b.m, b.lf, b.lr) == (1500.0, 1.4, 1.7) and b.Iz == pytest.approx(1500 * 1.3 ** 2)
    # vehicles.md: physical per-axle box 63.0...74.5 kN/rad rear, 67.6...69.9 front
    assert ph.cr[0] == pytest.approx(63.0e3, rel=1e-3) and ph.cr[1] == pytest.approx(74.5e3, rel=1e-3)
    assert ph.cf[0] == pytest.approx(67.6e3, rel=1e-3) and ph.cf[1] == pytest.approx(69.9e3, rel=1e-3)


@pytest.mark.parametrize("name", ["paper", "physical"])
def test_polytope_contains_the_true_plants(boxes, name):
    box = boxes[name]
    poly = f.polytope(box)
    assert len(poly.vertices) == 64
    rng = np.random.default_rng(7)
    pts = [(rng.uniform(*box.cf), rng.uniform(*box.cr), rng.uniform(*box.v)) for _ in range(2000)]
    pts += box.corners()
    for p in pts:
        assert poly.contains(*box.tf(*p)), p
    # and the intervals are tight: each end is attained by a corner of the box
    for k, (lo, hi) in poly.intervals.items():
        vals = []
        for p in box.corners():
            b1, b2, a = box.tf(*p)
            vals.append(dict(zip(f.COEFS, (b1[0], b1[1], b2[0], b2[1], a[0], a[1])))[k])
        assert min(vals) == lo and max(vals) == hi


def test_projected_region_is_the_region_form_times_the_lyapunov_form():
    rng = np.random.default_rng(3)
    n = 4
    Q = rng.normal(size=(n, n)); Q = Q + Q.T
    for region in (f.LHP, f.alpha_region(0.7), f.disk_region(-2.0, 1.5)):
        M = f.projected_region(Q, region, n)
        for s in (0.3 + 2j, -1 + 0.5j):
            v = s ** np.arange(n + 1)
            nu = v[:n]
            lhs = np.conj(v) @ M @ v
            d11, d12, d22 = region
            assert lhs == pytest.approx((d11 + 2 * d12 * s.real + d22 * abs(s) ** 2) * (np.conj(nu) @ Q @ nu))


def test_hinf_norm_of_a_resonance():
    for zeta in (0.05, 0.3, 0.6):
        g, w = f.hinf_norm([1.0], [1.0, 2 * zeta, 1.0])
        assert g == pytest.approx(1 / (2 * zeta * np.sqrt(1 - zeta ** 2)), rel=1e-8)
        assert w == pytest.approx(np.sqrt(1 - 2 * zeta ** 2), rel=1e-4)


def test_lemma2_self_test_of_errata():
    """Stable d with c = d is feasible; an unstable d is not (with a stable c)."""
    import cvxpy as cp
    from latobs.synthesis import lmi

    def feasible(c, d):
        n = len(c) - 1
        Q = cp.Variable((n, n), symmetric=True)
        cc, dd = np.reshape(c, (-1, 1)), np.reshape(d, (-1, 1))
        M = cc @ dd.T + dd @ cc.T - 1e-6 * cc @ cc.T - f.projected_region(Q, f.LHP, n)
        return lmi.solved(lmi.solve(cp.Problem(cp.Minimize(0), [(M + M.T) / 2 >> 0]))[0])

    stable = P.polyfromroots([-1, -2, -0.5 + 1j, -0.5 - 1j]).real
    unstable = P.polyfromroots([-1, 0.3, -0.5 + 1j, -0.5 - 1j]).real
    assert feasible(stable, stable)
    assert not feasible(stable, unstable)


def test_paper_box_design_reproduces_gamma(paper_design):
    d = paper_design
    assert d.status == "optimal"
    assert d.gamma_lmi == pytest.approx(f.PAPER_GAMMA, rel=REL)
    ev = d.evaluation
    assert ev["stable"] and ev["grid_stable"]
    # independent evaluation agrees with the LMI (and the LMI gamma is a bound: never below it)
    assert ev["gamma"] == pytest.approx(d.gamma_lmi, rel=1e-5)
    assert ev["gamma"] <= d.gamma_lmi * (1 + 1e-6)
    assert ev["grid_gamma"] <= ev["gamma"]
    # the optimum is the DC floor of the over-bounded polytope
    floor, k = f.dc_floor(f.polytope(d.box))
    assert d.gamma_lmi == pytest.approx(floor, rel=1e-6)
    assert d.y[0] / d.x[0] == pytest.approx(k, rel=1e-4)


def test_paper_box_second_central_polynomial(boxes):
    d = f.design(boxes["paper"], order=1, central=f.C33)
    assert d.gamma_lmi == pytest.approx(f.PAPER_GAMMA, rel=REL)
    assert d.evaluation["stable"] and d.gamma == pytest.approx(d.gamma_lmi, rel=1e-5)


def test_paper_central_polynomials_are_the_described_poles():
    r31 = P.polyfromroots([-4.4429 + 4.4429j, -4.4429 - 4.4429j, -0.1210 + 0.2598j, -0.1210 - 0.2598j,
                           -0.1 + 0.01j, -0.1 - 0.01j]).real
    assert np.allclose(r31, f.C31, rtol=2e-3, atol=2e-4)


@pytest.mark.parametrize("est", [f.EST32, f.EST33], ids=["eq32", "eq33"])
def test_printed_estimators_certify_about_the_paper_gamma(boxes, est):
    ev = f.evaluate_estimator(boxes["paper"], *est, box_grid=5)
    assert ev["stable"] and ev["grid_stable"]
    assert ev["gamma"] == pytest.approx(f.PAPER_GAMMA, rel=REL)        # 3.791
    assert ev["gamma"] >= f.dc_floor(f.polytope(boxes["paper"]))[0]


def test_printed_estimators_are_poor_on_the_physical_box(boxes):
    for est in (f.EST32, f.EST33):
        assert f.evaluate_estimator(boxes["physical"], *est)["gamma"] > 10


def test_physical_box_design_with_the_nominal_central_polynomial(boxes):
    box = boxes["physical"]
    c = f.nominal_central(box, 1)
    assert np.all(np.roots(c[::-1]).real < 0)
    d = f.design(box, order=1, n_grid=4)
    ev = d.evaluation
    assert ev["stable"] and ev["grid_stable"]
    assert ev["gamma"] == pytest.approx(d.gamma_lmi, rel=1e-4)
    assert ev["gamma"] == pytest.approx(f.dc_floor(f.polytope(box))[0], rel=1e-4)     # ~1.470
    assert ev["grid_gamma"] < ev["gamma"]


def test_paper_central_polynomial_fails_on_the_physical_box(boxes):
    with pytest.raises(f.DesignError):
        f.lemma5(f.polytope(boxes["physical"]), f.C31, order=1)


def test_wrong_central_degree_is_refused(boxes):
    with pytest.raises(ValueError, match="degree"):
        f.lemma5(f.polytope(boxes["paper"]), f.C31, order=2)


def test_pole_region_on_top_of_the_performance_lmi(boxes):
    """alpha-stability (Re s < -0.009; the weight W2 fixes a pole at -0.01) via stability_region."""
    box = boxes["paper"]
    d = f.design(box, order=1, central=f.C31, stability_region=f.alpha_region(0.009))
    assert d.evaluation["stable"] and d.evaluation["max_real_pole"] < -0.009
    assert d.gamma == pytest.approx(d.gamma_lmi, rel=1e-5)
    # an unreachable region (the fixed weight pole -0.01 cannot move) is refused
    with pytest.raises(f.DesignError):
        c = P.polyfromroots([-4.4429 + 4.4429j, -4.4429 - 4.4429j, -0.2, -0.3, -0.4, -0.5]).real
        f.lemma5(f.polytope(box), c, 1, stability_region=f.alpha_region(0.05))


# ---------------------------------------------------------------------------------------------
# Issue 7: certificate (vertices and the true-plant grid), polish
# ---------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def physical_order1(boxes):
    return f.design(boxes["physical"], order=1)


def test_certify_analytic_single_plant(boxes):
    """A degenerate box (one plant): the exact inverse y/x = b1/b2 is first order and gives zero
    error; y/x = b1/b2 + eps gives G = -eps W1 W2 p2, whose norm is eps ||W1 W2 p2||."""
    ph = boxes["physical"]
    Cf, Cr, v = ph.centre()
    pt = f.Box("point", ph.m, ph.Iz, ph.lf, ph.lr, (Cf, Cf), (Cr, Cr), (v, v))
    b1, b2, a = pt.tf(Cf, Cr, v)
    y, x = b1 / b2[1], b2 / b2[1]
    c = f.certify_002(y, x, pt, grid=(3, 3, 3))
    assert c["stable"] and c["vertex_gamma"] < 1e-12 and c["grid_gamma"] < 1e-12
    ref, wref = f.hinf_norm(P.polymul(f._WN, b2), P.polymul(f._WD, a))
    for eps in (1e-3, 0.1):
        c = f.certify_002(y + eps * x, x, pt, grid=(2, 2, 2))
        assert c["grid_gamma"] == pytest.approx(eps * ref, rel=1e-8)
        assert c["vertex_gamma"] == pytest.approx(eps * ref, rel=1e-8)
        assert c["grid_w"] == pytest.approx(wref, rel=1e-3, abs=1e-9)
    # an unstable estimator pole is flagged at the vertices and on the grid
    c = f.certify_002([1.0, 0.0], [-0.5, 1.0], pt, grid=(2, 2, 2))
    assert not c["vertex_stable"] and not c["grid_stable"] and c["grid_gamma"] == float("inf")
    assert c["grid_max_real_pole"] == pytest.approx(0.5)


def test_certify_agrees_with_evaluate(boxes, physical_order1):
    d = physical_order1
    c = f.certify_002(d.y, d.x, d.box, grid=(4, 4, 4))
    ev = f.evaluate(f.polytope(d.box), d.y, d.x, box_grid=4)
    assert c["vertex_gamma"] == pytest.approx(ev["gamma"], rel=1e-7)
    assert c["grid_gamma"] == pytest.approx(ev["grid_gamma"], rel=1e-7)


@pytest.mark.parametrize("name", ["paper", "physical"])
def test_grid_worst_case_below_vertex_worst_case(boxes, name):
    """The polytope over-bounds the true plants, so the grid worst case never exceeds it."""
    box = boxes[name]
    rng = np.random.default_rng(11)
    ests = [f.EST32, ([0.19], [1.0])]
    for _ in range(4):
        ests.append((rng.uniform(-2, 2, 2), np.array([10 ** rng.uniform(-2, 2), 1.0])))
    for y, x in ests:
        c = f.certify_002(y, x, box, grid=(5, 5, 5))
        assert c["stable"]
        assert c["grid_gamma"] <= c["vertex_gamma"] * (1 + 1e-9)
        assert f.grid_dc_floor(box, (5, 5, 5))[0] <= c["grid_gamma"] * (1 + 1e-9)


def test_physical_first_order_design_certifies_on_the_grid(physical_order1):
    d = physical_order1
    c = f.certify_002(d.y, d.x, d.box)                     # 9 x 9 x 9 true plants
    assert c["stable"] and c["grid_stable"] and c["vertex_stable"]
    floor = f.dc_floor(f.polytope(d.box))[0]
    assert floor * (1 - 1e-9) <= c["vertex_gamma"] <= floor * (1 + 1e-3)     # floor-limited
    assert f.grid_dc_floor(d.box)[0] <= c["grid_gamma"] < c["vertex_gamma"]


def test_polish_never_increases_and_reaches_the_grid_floor(physical_order1):
    d = physical_order1
    c0 = f.certify_002(d.y, d.x, d.box)
    y, x, c1 = f.polish(d.box, d.y, d.x)
    assert c1["stable"] and c1["grid_gamma"] <= c0["grid_gamma"]
    # the grid DC floor is a lower bound for every order; the polished first order attains it
    floor = f.grid_dc_floor(d.box)[0]
    assert c1["grid_gamma"] == pytest.approx(floor, rel=1e-5)
    # polishing an optimum (or any start) returns nothing worse
    y2, x2, c2 = f.polish(d.box, y, x, rounds=1, maxiter=200)
    assert c2["grid_gamma"] <= c1["grid_gamma"]
    y3, x3, c3 = f.polish(d.box, [0.5], [1.0], rounds=1, maxiter=200)
    assert c3["grid_gamma"] <= f.certify_002([0.5], [1.0], d.box)["grid_gamma"]


def test_full_order_hinfsyn_is_certified_above_the_grid_floor():
    """Issue 7.4: python-control's hinfsyn (slycot) on the nominal plant, certified like the
    fixed-order designs: stable over the box, and no better than the proven grid DC floor that
    the polished first-order estimator reaches (orders compared on the same set)."""
    box = f.boxes()["physical"]
    y, x, gam, _ = f.full_order_hinfsyn(box)
    assert len(x) - 1 >= 4                                # full order: the generalised plant's
    c = f.certify_002(y, x, box)
    floor = f.grid_dc_floor(box)[0]
    assert c["stable"] and c["grid_gamma"] >= floor * (1 - 1e-9)
    assert c["grid_gamma"] <= c["vertex_gamma"]           # the polytope contains the grid plants
    assert gam < 0.01 < c["grid_gamma"]                   # nominal gamma says nothing about the box


def test_clarabel_fallback_settings_solve_after_a_numerical_failure(monkeypatch):
    """ERRATA 002: when Clarabel stops on a numerical error, the solve is retried with
    equilibration and chordal decomposition off, and that solve's answer is used."""
    from latobs.synthesis import lmi
    calls = []
    real = lmi._attempt

    def flaky(prob, settings):
        calls.append(dict(settings))
        return "solver_error" if not settings else real(prob, settings)
    monkeypatch.setattr(lmi, "_attempt", flaky)
    box = f.boxes()["paper"]
    info = {}
    y, x, g, status, _ = f.lemma5(f.polytope(box), f.nominal_central(box, 1), 1)
    assert calls == [{}, lmi.FALLBACK_SETTINGS] and lmi.solved(status)      # (optimal_inaccurate here)
    ev = f.evaluate(f.polytope(box), y, x)
    assert ev["stable"] and ev["gamma"] == pytest.approx(f.PAPER_GAMMA, rel=5e-3)
    import cvxpy as cp
    v = cp.Variable()
    lmi.solve(cp.Problem(cp.Minimize(v), [v >= 1]), info)
    assert info["attempts"][0][1] == "solver_error" and info["attempts"][-1][1] == "optimal"


def test_a_problems_own_clarabel_settings_are_its_first_attempt_and_only_clarabels(monkeypatch):
    """``lmi.solve(prob, clarabel=...)``: those settings make the first attempt with Clarabel (the
    fallback after a numerical failure is still FALLBACK_SETTINGS); with SCS they are not passed."""
    import cvxpy as cp

    from latobs.synthesis import lmi
    v = cp.Variable()
    prob = cp.Problem(cp.Minimize(v), [v >= 1])
    own = {"iterative_refinement_enable": False}
    info = {}
    assert lmi.solve(prob, info, clarabel=own)[0] == "optimal" and info["attempts"] == [(own, "optimal")]
    calls = []
    real = lmi._attempt
    monkeypatch.setattr(lmi, "_attempt", lambda p, s: calls.append(dict(s)) or ("solver_error" if s == own
                                                                               else real(p, s)))
    assert lmi.solved(lmi.solve(prob, clarabel=own)[0]) and calls == [own, lmi.FALLBACK_SETTINGS]
    calls.clear()
    with lmi.using("SCS"):
        lmi.solve(prob, clarabel=own)
    assert calls == [{}]
