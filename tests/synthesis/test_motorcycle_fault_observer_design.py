"""Paper 003: existence conditions, the LMI design (20)-(23) with ERRATA's corrections, its
independent certificate, the beta trade-off and the average dwell time."""
from __future__ import annotations

import copy
import dataclasses
import math

import numpy as np
import pytest
import scipy.linalg

from latobs.synthesis import certificate, design_file, designs, hinf
from latobs.synthesis import motorcycle_fault_observer as ps
from latobs.synthesis.params import load_vehicle

VEHICLE = load_vehicle("sharp_motorcycle")


@pytest.fixture(scope="module")
def d003() -> dict:
    """The catalogue design (LMIs + certificate; designs.run raises if it is not certified)."""
    return designs.run("MotorcycleFaultObserverPaper")


@pytest.fixture(scope="module")
def modes() -> list[ps.ModeModel]:
    return ps.mode_models(VEHICLE, ps.DesignOptions(name="t"))


def _failed(data: dict) -> set[str]:
    ok, checks = certificate.certify(data)
    assert not ok
    return {c.name for c in checks if not c.passed}


# -- the design file ------------------------------------------------------------------------------
def test_design_file_has_the_contract_keys(d003):
    assert d003["paper"] == "003" and d003["name"] == "MotorcycleFaultObserverPaper" and d003["certified"] is True
    assert d003["vehicle"]["name"] == "sharp_motorcycle" and "parameters" in d003["vehicle"]
    assert {"name", "status", "seconds"} <= set(d003["solver"]) and d003["solver"]["status"] == "optimal"
    assert all({"name", "value", "limit", "passed"} <= set(c) for c in d003["checks"])
    assert [m["vx"] for m in d003["modes"]] == [10.0, 15.0, 20.0, 25.0, 30.0]
    assert d003["switching"]["edges"] == [7.5, 12.5, 17.5, 22.5, 27.5, 32.5]
    for m in d003["modes"]:
        assert {"index", "vx", "band", "gains", "P", "U", "model", "gamma"} <= set(m)
        assert np.shape(m["gains"]["L_P"]) == (5, 3) and np.shape(m["gains"]["L_I"]) == (2, 3)
        assert np.shape(m["P"]) == (7, 7) and np.shape(m["U"]) == (7, 3)
        assert np.allclose(m["model"]["F_d"], 0) and np.allclose(m["model"]["F_f"], 0)   # y = states
    assert d003["gamma"] == max(m["gamma"] for m in d003["modes"])
    assert design_file.dumps(d003)          # plain, finite JSON


# -- existence conditions (24) and detectability ----------------------------------------------------------
def test_rank_condition_and_detectability_hold_for_every_mode(modes):
    for mm in modes:
        cond = ps.check_conditions(mm)
        assert cond["rank_24"]["ok"] and cond["detectability"]["ok"]
        assert min(p["margin"] for p in cond["rank_24"]["points"]) > 1e-6
        assert cond["rank_24"]["points"][0]["s"] == 0     # s = 0 (the integrators of f) is always tested
        # (24) is the PBH matrix of (A~, C~): full column rank also at arbitrary s in the RHP
        At, Ct, *_ = ps.augmented(mm)
        for s in (0.3, 2.0 + 5.0j, 1e-3j):
            assert np.linalg.matrix_rank(np.vstack([s * np.eye(7) - At, Ct])) == 7


def test_conditions_fail_with_a_clear_error_for_counter_examples(modes):
    mm = modes[2]
    # only the steer angle measured: at s = 0, rank [[-A, -E_f], [C, 0]] <= 5 + 1 < 7
    blind = dataclasses.replace(mm, C=mm.C[:1], F_d=np.zeros((1, 2)), F_f=np.zeros((1, 2)))
    assert not ps.rank_condition_24(blind.A, blind.E_f, blind.C)["ok"]
    with pytest.raises(ps.ConditionError, match=r"mode 3 \(vx = 20 m/s\): rank condition \(24\) fails at s = 0"):
        ps.check_conditions(blind, name="X")
    # the roll angle has no effect on the model (E_phi = 0): (24) with rank(E_f) = 1 holds, but the
    # augmented pair is not detectable (phi is invisible at s = 0)
    deaf = dataclasses.replace(mm, E_f=np.column_stack([np.zeros(5), mm.E_f[:, 1]]))
    assert ps.rank_condition_24(deaf.A, deaf.E_f, deaf.C)["ok"]
    with pytest.raises(ps.ConditionError, match=r"mode 3 .*detectability of \(A~, C~\) .*fails at s = 0"):
        ps.check_conditions(deaf, name="X")
    # and design() refuses before any LMI is posed
    from latobs.synthesis.motorcycle_model import reduced_model

    def no_roll(vehicle, vx):
        m = reduced_model(vehicle, vx)
        return dataclasses.replace(m, E_phi=np.zeros(5)) if dataclasses.is_dataclass(m) else m._replace(E_phi=np.zeros(5))
    with pytest.raises(ps.ConditionError, match="mode 1"):
        ps.design(VEHICLE, ps.DesignOptions(name="X"), model=no_roll)


# -- the LMIs ----------------------------------------------------------------------------------------
def test_printed_lmi22_is_infeasible_and_the_corrected_one_solves(modes):
    mm = modes[0]
    with pytest.raises(ps.DesignError, match=r"\(22\) printed"):
        ps.solve_mode(mm, ps.DesignOptions(name="X", lmi22="printed"))
    # why: its diagonal block -I can never be >= 0, whatever P and alpha_bar
    P = np.eye(7)
    assert np.min(np.linalg.eigvalsh(ps.lmi_22(P, 10.0, printed=True))) <= -1.0
    for opts in (ps.DesignOptions(name="X"), ps.DesignOptions(name="X", alpha=None, radius=None)):  # + the
        sol = ps.solve_mode(mm, opts)                                                              # paper's alone
        assert sol.status == "optimal"
        ev = np.linalg.eigvalsh(sol.P)
        assert ev[0] >= 1.0 and ev[-1] ** 2 <= sol.alpha_bar * (1 + 1e-6)      # (23), (22): P^2 <= alpha_bar I


def test_lmi_gamma_bounds_the_independent_hinf_norm(d003):
    """The certificate's H-inf (Hamiltonian, no P) of d~ -> r against the LMI's gamma_i = sqrt(gamma_bar),
    and the gain L = -P^-1 U (ERRATA 003: C~'U', not C~'U) making P (A~ - L C~) = P A~ + U C~."""
    sc = ps.scaling(d003["options"])
    names = {c["name"]: c for c in d003["checks"]}
    for mode, mm in zip(d003["modes"], ps.mode_models(VEHICLE, ps.DesignOptions(name="t"))):
        Acl, Ed, It, Ct, _ = ps.closed_loop_normalised(mm, mode["gains"]["L_P"], mode["gains"]["L_I"], sc)
        B = np.hstack([Ed, It])
        hn = hinf.hinf_norm(Acl, B, Ct).norm
        sweep, _ = hinf.frequency_sweep_peak(Acl, B, Ct)
        assert hn == pytest.approx(sweep, rel=1e-3)
        assert 0 < hn <= mode["gamma"] * (1 + 1e-6)
        where = f"mode {mode['index']} (vx = {mode['vx']:g} m/s)"
        stored = names[f"H-inf d~ -> residual r (16), Hamiltonian, normalised <= gamma_i, {where}"]
        assert stored["passed"] and stored["value"] == pytest.approx(hn, rel=1e-6)
        P, U = np.asarray(mode["P"]), np.asarray(mode["U"])
        At, Ct_n, *_ = ps.normalised(*ps.augmented(mm), sc)
        Ln = -np.linalg.solve(P, U)
        assert np.allclose(P @ (At - Ln @ Ct_n), P @ At + U @ Ct_n, atol=1e-8 * np.abs(P @ At).max())


def test_beta_trades_alpha_bar_against_gamma_bar(modes):
    mm = modes[2]
    sols = [ps.solve_mode(mm, ps.DesignOptions(name="X", beta=b)) for b in (0.2, 0.5, 0.8)]
    ab = [s.alpha_bar for s in sols]
    gb = [s.gamma_bar for s in sols]
    assert ab[0] >= ab[1] * (1 - 1e-6) and ab[1] >= ab[2] * (1 - 1e-6) and ab[0] > ab[2]
    assert gb[0] <= gb[1] * (1 + 1e-6) and gb[1] <= gb[2] * (1 + 1e-6) and gb[0] < gb[2]


# -- average dwell time ------------------------------------------------------------------------------------
def test_dwell_time_recomputed_and_reported(d003):
    dw = d003["dwell_time"]
    assert 0 < dw["tau_a_adjacent"] <= dw["tau_a"] < math.inf and dw["lambda_0"] > 0 and dw["mu"] > 1
    sc = ps.scaling(d003["options"])
    Ps = [np.asarray(m["P"]) for m in d003["modes"]]
    for m, mm, P, lam in zip(d003["modes"], ps.mode_models(VEHICLE, ps.DesignOptions(name="t")), Ps,
                             dw["lambda_0_per_mode"]):
        Acl = ps.closed_loop_normalised(mm, m["gains"]["L_P"], m["gains"]["L_I"], sc)[0]
        # lambda_0 is the exact decay: A*'P + P A* + lambda_0 P <= 0 with equality in some direction
        top = np.max(scipy.linalg.eigh(Acl.T @ P + P @ Acl + lam * P, P, eigvals_only=True))
        assert abs(top) < 1e-8
    for i, Pi in enumerate(Ps):              # x'P_j x <= mu x'P_i x for every pair
        for Pj in Ps:
            assert np.min(np.linalg.eigvalsh(dw["mu"] * Pi - Pj)) >= -1e-9 * np.abs(Pj).max()
    assert dw["tau_a"] == pytest.approx(math.log(dw["mu"]) / dw["lambda_0"], rel=1e-12)
    # switching signals: switches every 2 tau_a respect it, chattering does not
    tau = dw["tau_a"]
    slow = [(k * 0.5 * tau, 1 + (k // 4) % 2) for k in range(40)]
    fast = [(k * 0.01, 1 + k % 2) for k in range(40)]
    assert ps.dwell_report(d003, slow)["satisfied"]
    rep = ps.dwell_report(d003, fast)
    assert not rep["satisfied"] and rep["switches"] == 39 and rep["worst_margin"] < 0
    # the paper's speed profile (the motorcycle-lane-change scenario's) through the runtime's rule:
    # what the demo's design section reports
    from latobs.validation.scenarios import SCENARIOS
    t = np.arange(0, 16, 0.01)
    seq = ps.modes_of_speed(d003, t, SCENARIOS["motorcycle-lane-change"].speed(t))
    assert sorted({m for _, m in seq}) == [1, 2, 3]
    rep = ps.dwell_report(d003, seq)
    assert rep["switches"] == 4 and rep["satisfied"] and rep["min_interval"] > 1.5


# -- the certificate against corrupted files --------------------------------------------------------------
def test_certificate_rejects_corrupted_designs(d003):
    where = "mode 2 (vx = 15 m/s)"
    bad = copy.deepcopy(d003)
    bad["modes"][1]["gains"]["L_I"] = (10 * np.asarray(bad["modes"][1]["gains"]["L_I"])).tolist()
    assert f"gains = D (-P^-1 U) Y^-1 of the stored P, U (corrected from the print: L = -P^-1 U), rel. error, {where}" in _failed(bad)

    bad = copy.deepcopy(d003)
    hn = next(c["value"] for c in d003["checks"] if c["name"].startswith("H-inf d~ -> residual") and where in c["name"])
    bad["modes"][1]["gamma"] = 0.5 * hn
    failed = _failed(bad)
    assert f"H-inf d~ -> residual r (16), Hamiltonian, normalised <= gamma_i, {where}" in failed
    assert f"gamma_i = sqrt(gamma_bar) (corrected from the print), relative error, {where}" in failed

    bad = copy.deepcopy(d003)
    bad["modes"][1]["P"] = (0.5 * np.asarray(bad["modes"][1]["P"])).tolist()
    assert f"LMI (23) P >= I: min eig(P) - 1, {where}" in _failed(bad)

    bad = copy.deepcopy(d003)
    bad["modes"][1]["alpha_bar"] = 1.0
    assert f"LMI (22) [[alpha_bar I, P], [P, I]] (sign corrected from the print): min eig, {where}" in _failed(bad)

    bad = copy.deepcopy(d003)
    bad["modes"][1]["gamma_bar"] *= 1e-3
    assert f"LMI (21) on the stored P, U, gamma_bar: max eig, {where}" in _failed(bad)

    bad = copy.deepcopy(d003)
    bad["dwell_time"]["tau_a"] *= 0.5
    assert any(n.startswith("average dwell time tau_a =") for n in _failed(bad))

    bad = copy.deepcopy(d003)
    bad["modes"][1]["gains"]["L_P"] = np.zeros((5, 3)).tolist()
    bad["modes"][1]["gains"]["L_I"] = np.zeros((2, 3)).tolist()
    assert f"closed loop A~ - L C~ Hurwitz: max Re(eig), {where}" in _failed(bad)

    bad = copy.deepcopy(d003)
    bad["modes"][1]["model"]["A"][0][0] += 1.0
    failed = _failed(bad)
    assert f"model equals the reduced model re-derived from the vehicle parameters, {where}" in failed
