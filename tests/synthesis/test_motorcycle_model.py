"""Mathematical checks of the derived Sharp (1971) motorcycle model (latobs.synthesis.motorcycle_model).

The derivation (Kane's method, sympy) is only trusted because it reproduces the published modal
behaviour of this motorcycle (vehicles.md, section sharp_motorcycle): weave, wobble and capsize.
The reduced model of paper 003 (sigma -> 0, roll angle as an input) must be the sigma -> 0 limit of
the full one, and the derived equations must have the structure of paper 003's eq. (1)-(2).
"""
from __future__ import annotations

import json
import math
import random

import numpy as np
import pytest

from latobs.synthesis import motorcycle_model as mm
from latobs.synthesis.params import G, load_vehicle

VEH = load_vehicle("sharp_motorcycle")
P = {n: VEH.value(n) for n in mm.PARAMETERS}
EPS = P["epsilon"]
LF = (P["a"] - P["an"]) / math.cos(EPS)


# ------------------------------------------------------------------------------------------
# known behaviour (vehicles.md): the proof that the derivation is right
# ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("vx", [20.0, 25.0, 30.0, 40.0, 50.0])
def test_weave_frequency_at_speed(vx):
    """vehicles.md: weave ~16-21 rad/s at 20-50 m/s (stable there)."""
    w = mm.modes(VEH, vx)["weave"]
    assert 15.5 <= w.imag <= 21.5, w
    assert w.real < 0, w


def test_weave_unstable_at_low_speed():
    """vehicles.md: weave unstable below ~7 m/s. Measured: the real part crosses 0 at 5.94 m/s."""
    for vx in (3.0, 4.0, 5.0):
        assert mm.modes(VEH, vx)["weave"].real > 0, vx
    for vx in (7.0, 8.0, 10.0, 15.0):
        assert mm.modes(VEH, vx)["weave"].real < 0, vx
    assert 5.5 <= mm.weave_critical_speed(VEH) <= 7.5


@pytest.mark.parametrize("vx", [10.0, 15.0, 20.0, 30.0, 40.0, 50.0])
def test_wobble_frequency(vx):
    """vehicles.md: wobble ~54-58 rad/s."""
    w = mm.modes(VEH, vx)["wobble"]
    assert 53.5 <= w.imag <= 58.5, w
    assert w.real < 0, w


def test_wobble_damping_falls_as_speed_rises():
    re = [mm.modes(VEH, v)["wobble"].real for v in (15.0, 20.0, 30.0, 40.0, 50.0)]
    assert all(a < b for a, b in zip(re, re[1:])), re          # less negative with speed
    assert re[0] < -5.0 and -2.0 < re[-1] < 0.0


@pytest.mark.parametrize("vx", [15.0, 20.0, 30.0, 40.0, 50.0])
def test_capsize_slightly_unstable(vx):
    """vehicles.md: capsize slightly unstable, real part ~ +0.05 ... +0.09 1/s."""
    c = mm.modes(VEH, vx)["capsize"]
    assert 0.04 <= c <= 0.10, c


def test_modal_table_at_20_mps():
    """The numbers of the report (full model, sigma = 0.2438 m)."""
    m = mm.modes(VEH, 20.0)
    assert m["weave"] == pytest.approx(complex(-4.840, 16.129), abs=2e-3)
    assert m["wobble"] == pytest.approx(complex(-5.759, 53.990), abs=2e-3)
    assert m["capsize"] == pytest.approx(0.0929, abs=2e-4)


# ------------------------------------------------------------------------------------------
# structure of paper 003's eq. (1)-(2) and the derived geometry
# ------------------------------------------------------------------------------------------
def _paper_matrices(c: dict, p: dict):
    """Eq. (1)-(2) of paper 003 with the signs of the derivation, from the coefficients c."""
    gyro = p["ify"] / p["rf"]
    se, ce = math.sin(p["epsilon"]), math.cos(p["epsilon"])
    M = np.array([[c["M"], c["mf_k"], c["mf_j_mr_h"], c["mf_e"]],
                  [c["mf_k"], c["a3"], c["a2"], c["a1"]],
                  [c["mf_j_mr_h"], c["a2"], c["b2"], c["b1"]],
                  [c["mf_e"], c["a1"], c["b1"], c["c1"]]])
    C1 = np.array([[0, c["M"], 0, 0],
                   [0, c["mf_k"], -c["a4"], -gyro * se],
                   [0, c["b5"], 0, gyro * ce],
                   [0, c["c3"], -gyro * ce, 0]])
    C0 = np.diag([0, 0, 0, c["K"]])
    K = np.array([[0, 0], [0, 0], [-c["b4"], c["b3"]], [c["b3"], c["c2"]]])
    BF = np.array([[1, 1], [c["lf"], -c["lr"]], [0, 0], [-p["an"], 0]])
    return M, C0, C1, K, BF


def _formula_values(p: dict) -> dict:
    """The closed forms of motorcycle_model._PAPER_FORMULAS evaluated independently (floats)."""
    import sympy as sp

    D = mm.derivation()
    subs = {D.symbols[n]: sp.Rational(repr(v)) for n, v in p.items() if n in D.symbols}
    subs[D.symbols["g"]] = sp.Rational(repr(G))
    return {k: float(sp.N(expr.subs(subs), 30)) for k, expr in mm.paper_formulas().items()}


def _random_vehicle(seed: int):
    rng = random.Random(seed)
    vals = {n: v * rng.uniform(0.6, 1.4) for n, v in P.items()}
    vals["epsilon"] = rng.uniform(0.2, 0.6)
    vals["Crxz"] = rng.uniform(-3.0, 3.0)
    return VEH.with_values(**vals)


@pytest.mark.parametrize("seed", [None, 1, 2])
def test_derived_equations_have_the_structure_of_eq_1(seed):
    """Derived (E1) == paper 003's eq. (1)-(2) with the closed-form coefficients, for the vehicle
    and for random parameter sets (so the formulas, not just numbers, agree)."""
    veh = VEH if seed is None else _random_vehicle(seed)
    p = {n: veh.value(n) for n in mm.PARAMETERS}
    m = mm.mechanics(veh)
    c = _formula_values(p)
    M, C0, C1, K, BF = _paper_matrices(c, p)
    for name, got, ref in (("M", m.M, M), ("C0", m.C0, C0), ("C1", m.C1, C1), ("K", m.K, K), ("B_F", m.B_F, BF)):
        np.testing.assert_allclose(got, ref, rtol=1e-11, atol=1e-11 * max(1.0, np.abs(ref).max()), err_msg=name)
    np.testing.assert_allclose(m.B_tau, [0, 0, 0, 1], atol=1e-15)
    # paper_coefficients reads the same numbers off the derivation
    pc = mm.paper_coefficients(veh)
    for k, v in c.items():
        assert pc[k] == pytest.approx(v, rel=1e-11, abs=1e-11), k
    np.testing.assert_allclose(m.M, m.M.T, atol=1e-12)              # Lagrangian mass matrix
    assert m.K[2, 1] == pytest.approx(m.K[3, 0], rel=1e-14)         # conservative load/gravity


def test_sign_facts_and_derived_lengths():
    c = mm.paper_coefficients(VEH)
    k = (P["a"] + P["e"]) * math.cos(EPS) + P["f"] * math.sin(EPS)
    j = (P["a"] + P["e"]) * math.sin(EPS) - P["f"] * math.cos(EPS)
    assert k == pytest.approx(0.8796, abs=1e-4) and j == pytest.approx(0.4167, abs=1e-4)   # vehicles.md
    assert c["lf"] == pytest.approx(0.9347, abs=1e-4) and c["lr"] == P["b"]
    assert c["b3"] < 0 and c["c2"] < 0          # load behind / mass ahead of the axis: destabilising
    assert c["b4"] > 0 and c["K"] == P["C_delta"]
    assert c["a4"] == pytest.approx(P["ify"] / P["rf"] + P["iry"] / P["rr"])


def test_pitch_inertias_and_yaw_angle_drop_out():
    D = mm.derivation()
    for mat in (D.M, D.C0, D.C1, D.K, D.B_F, D.B_tau):
        assert not ({D.symbols["Iry"], D.symbols["Ify"]} & mat.free_symbols)
    assert D.symbols["vx"] not in (D.M.free_symbols | D.K.free_symbols | D.C1.free_symbols)


def test_derived_tyre_geometry_is_paper_eq_7_8():
    import sympy as sp

    D = mm.derivation()
    S = D.symbols
    lf = (S["a"] - S["an"]) / sp.cos(S["epsilon"])
    (wf, hf), (wr, hr) = D.slip["front"], D.slip["rear"]
    assert [sp.simplify(x - y) for x, y in zip(wf, [1, lf, 0, -S["an"]])] == [0] * 4
    assert sp.simplify(hf - sp.cos(S["epsilon"])) == 0
    assert [sp.simplify(x - y) for x, y in zip(wr, [1, -S["b"], 0, 0])] == [0] * 4 and hr == 0
    assert sp.simplify(D.camber["front"][0] - 1) == 0 and sp.simplify(D.camber["front"][1] - sp.sin(S["epsilon"])) == 0
    assert list(D.camber["rear"]) == [1, 0]


# ------------------------------------------------------------------------------------------
# full and reduced models
# ------------------------------------------------------------------------------------------
def _paper_slips(vx):
    """alpha_f, gamma_f, alpha_r, gamma_r of eqs. (7)-(8) as rows over STATE_FULL."""
    i = {n: k for k, n in enumerate(mm.STATE_FULL)}
    af, gf, ar, gr = (np.zeros(8) for _ in range(4))
    af[i["vy"]], af[i["yaw_rate"]], af[i["steer_rate"]] = -1 / vx, -LF / vx, P["an"] / vx
    af[i["steer_angle"]] = math.cos(EPS)
    gf[i["roll_angle"]], gf[i["steer_angle"]] = 1.0, math.sin(EPS)
    ar[i["vy"]], ar[i["yaw_rate"]] = -1 / vx, P["b"] / vx
    gr[i["roll_angle"]] = 1.0
    return af, gf, ar, gr


@pytest.mark.parametrize("vx", [10.0, 20.0, 30.0])
def test_full_model_tyre_rows_are_eq_3_to_8(vx):
    f = mm.full_model(VEH, vx)
    k = vx / P["sigma"]
    af, gf, ar, gr = _paper_slips(vx)
    ef, er = np.eye(8)[6], np.eye(8)[7]
    np.testing.assert_allclose(f.A[6], k * (P["Cf1"] * af + P["Cf2"] * gf - ef), rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(f.A[7], k * (P["Cr1"] * ar + P["Cr2"] * gr - er), rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(f.E_gamma, np.vstack([np.zeros((6, 2)), k * np.eye(2)]))
    assert f.A[0, 4] == 1 and f.A[1, 5] == 1 and f.B_tau[:2].tolist() == [0, 0] and f.B_tau[6:].tolist() == [0, 0]
    assert f.C.shape == (3, 8) and f.states == mm.STATE_FULL


@pytest.mark.parametrize("vx", [10.0, 20.0, 30.0])
def test_reduced_forces_are_eq_5_to_8_with_sigma_zero(vx):
    r = mm.reduced_model(VEH, vx)
    af, gf, ar, gr = _paper_slips(vx)
    sel = [mm.STATE_FULL.index(n) for n in mm.STATE_REDUCED]
    np.testing.assert_allclose(r.H_x[0], (P["Cf1"] * af + P["Cf2"] * gf)[sel], rtol=1e-12)
    np.testing.assert_allclose(r.H_x[1], (P["Cr1"] * ar + P["Cr2"] * gr)[sel], rtol=1e-12)
    np.testing.assert_allclose(r.H_phi, [P["Cf2"], P["Cr2"]], rtol=1e-12)
    x = np.array([0.3, -0.1, 0.05, 0.02, -0.4])
    Ff, Fr = r.forces(x, 0.1)
    assert Ff == pytest.approx(float(r.H_x[0] @ x + P["Cf2"] * 0.1))
    assert Fr == pytest.approx(float(r.H_x[1] @ x + P["Cr2"] * 0.1))
    assert r.states == mm.STATE_REDUCED
    np.testing.assert_array_equal(r.C, [[0, 0, 0, 1, 0], [0, 1, 0, 0, 0], [0, 0, 1, 0, 0]])
    assert r.A[3].tolist() == [0, 0, 0, 0, 1] and r.B_tau[3] == 0 and r.E_phi[3] == 0


def _augmented(r: mm.ReducedModel):
    """The reduced model with phi' = roll_rate appended (state [x; phi]): its inputs tau, Gamma."""
    A = np.zeros((6, 6))
    A[:5, :5] = r.A
    A[:5, 5] = r.E_phi
    A[5, 2] = 1.0
    B = np.append(r.B_tau, 0.0)
    E = np.vstack([r.E_gamma, np.zeros((1, 2))])
    C = np.hstack([r.C, np.zeros((3, 1))])
    return A, B, E, C


def _tf(A, B, C, w):
    return C @ np.linalg.solve(1j * w * np.eye(A.shape[0]) - A, B)


@pytest.mark.parametrize("vx", [10.0, 15.0, 20.0, 30.0])
def test_reduced_model_is_the_sigma_to_zero_limit(vx):
    """The full model with sigma = 1e-5 m has two fast tyre poles ~ -vx/sigma; its other poles and
    its frequency responses tau -> y and Gamma -> y are those of the reduced model with the roll
    angle integrated (phi' = roll_rate), to O(sigma)."""
    f = mm.full_model(VEH, vx, sigma=1e-5)
    r = mm.reduced_model(VEH, vx)
    A, B, E, C = _augmented(r)
    ev_f = np.linalg.eigvals(f.A)
    slow = np.sort_complex(ev_f[np.abs(ev_f) < 1e4])
    fast = ev_f[np.abs(ev_f) >= 1e4]
    assert len(slow) == 6 and len(fast) == 2
    np.testing.assert_allclose(fast.real, -vx / 1e-5, rtol=0.05)
    ev_r = np.sort_complex(np.linalg.eigvals(A))
    np.testing.assert_allclose(slow, ev_r, rtol=2e-3, atol=2e-4)
    for w in (0.3, 2.0, 10.0, 50.0):
        g_f, g_r = _tf(f.A, f.B_tau, f.C, w), _tf(A, B, C, w)
        np.testing.assert_allclose(g_f, g_r, rtol=1e-3, atol=1e-6 * np.abs(g_r).max())
        G_f, G_r = _tf(f.A, f.E_gamma, f.C, w), _tf(A, E, C, w)
        np.testing.assert_allclose(G_f, G_r, rtol=1e-3, atol=1e-6 * np.abs(G_r).max())


def test_reduced_model_is_stable_on_the_paper_grid():
    """Paper 003, section II.B: 'the considered model is stable for the speed range [10, 30] m/s'
    holds for the reduced 5-state A (roll angle as input); the full motorcycle's capsize mode is
    slightly unstable (test_capsize_slightly_unstable)."""
    for vx in (10.0, 15.0, 20.0, 25.0, 30.0):
        assert np.linalg.eigvals(mm.reduced_model(VEH, vx).A).real.max() < -0.5


def test_counter_steering_signs():
    """A positive (rightward) rider torque first steers right, then the motorcycle leans and turns
    LEFT: counter-steering, the signature of the derived signs."""
    from scipy.linalg import expm

    f = mm.full_model(VEH, 20.0)
    i = {n: k for k, n in enumerate(mm.STATE_FULL)}
    Ad = np.block([[f.A, f.B_tau[:, None]], [np.zeros((1, 9))]])
    x = lambda t: (expm(Ad * t) @ np.append(np.zeros(8), 1.0))[:8]  # noqa: E731  (unit torque step)
    assert x(0.05)[i["steer_angle"]] > 0
    x1 = x(1.0)
    assert x1[i["roll_angle"]] < 0 and x1[i["yaw_rate"]] < 0


def test_plant_structure_is_json_and_consistent():
    s = mm.plant_structure(VEH)
    s2 = json.loads(json.dumps(s))
    assert s2 == s
    m = mm.mechanics(VEH)
    np.testing.assert_allclose(s["M"], m.M)
    np.testing.assert_allclose(s["K_sin"], m.K)
    assert s["tyres"]["front"]["Fz"] == pytest.approx(-P["Zf"])
    assert s["tyres"]["rear"]["Fz"] == pytest.approx((P["mf"] + P["mr"]) * G + P["Zf"])
    assert s["g"] == G


def test_bad_inputs_raise():
    with pytest.raises(ValueError, match="vx > 0"):
        mm.full_model(VEH, 0.0)
    with pytest.raises(ValueError, match="sigma"):
        mm.full_model(VEH, 10.0, sigma=0.0)
    with pytest.raises(Exception, match="lacks parameter"):
        mm.full_model("sedan", 10.0)
