"""Paper 000's certificate (``certificate.sideslip_bank_observer``): what it checks, that tampering fails the
right named check, that its closed loop is the one an independent plant gives, and that the
frozen-integral growth factor mu bounds simulated freezes."""
from __future__ import annotations

import copy
import math

import numpy as np
import pytest
import scipy.linalg

import linear_plant_000 as lp
from latobs.synthesis import certificate, designs
from latobs.synthesis.params import parse_vehicle


@pytest.fixture(scope="module")
def faithful_speed() -> dict:
    return designs.run("SideslipBankObserverPaper")


@pytest.fixture(scope="module")
def faithful_tire() -> dict:
    return designs.run("SideslipBankObserverTire", faithful=True)


ALL = ["design_speed", "design_tire", "faithful_speed", "faithful_tire"]


def _failed(d: dict) -> list[str]:
    ok, checks = certificate.certify(d)
    failed = [c.name for c in checks if not c.passed]
    assert ok == (not failed)
    return failed


def _check(checks, *parts: str):
    """The one check whose name contains every part."""
    found = [c for c in checks if all(p in c.name for p in parts)]
    assert len(found) == 1, (parts, [c.name for c in found])
    return found[0]


@pytest.mark.parametrize("which", ALL)
def test_every_paper_000_design_certifies(which, request):
    """The two default (robust, LPV) designs and the two paper-faithful ones pass every check; the
    checks the issue asks for are present (both channels and the frozen integral where claimed)."""
    d = request.getfixturevalue(which)
    ok, checks = certificate.certify(d)
    assert ok, [(c.name, c.value, c.limit) for c in checks if not c.passed]
    names = [c.name for c in checks]
    robust = d["model_error"]["gamma"] is not None     # Theorem 2 with the model-error channel (tire modes)
    lpv = not d["options"]["faithful"]                 # the defaults: model at the measured speed, freeze
    assert ("robust_h2" in d) == (lpv and not robust)  # the speed modes' robust-H2 gains
    for mode in d["modes"]:
        i = mode["index"]
        mine = [n for n in names if n.endswith(f"mode {i}")]
        for key in ("LMI (20)", "alpha-stability LMI", "disk LMI", "pole region: max Re", "pole region: max |eig|",
                    "common P decreases", "H-inf bank->beta error", "runtime RK4 step"):
            assert sum(key in n for n in mine) == 1, (key, i)
        assert sum("model-error H-inf LMI" in n for n in mine) == robust
        assert sum("gamma2 of the band" in n for n in mine) == robust
        assert sum("frozen integral: x~-block" in n for n in mine) == lpv
        assert sum("robust H2" in n for n in mine) == 4 * ("robust_h2" in d)
        cover = [n for n in mine if "LMI vert" in n or "an LMI vertex" in n]
        assert len(cover) == 1
        kind = mode["model_speed"]["kind"]
        expect = ("fixed model speed" if kind == "fixed" else "both ends" if not lpv else "cover the model speeds")
        assert expect in cover[0]
    assert sum("growth factor mu" in n for n in names) == lpv
    for key in ("model equals the model re-derived", "model-error input E", "largest gain entry", "cond(P)",
                "P symmetric as stored", "P positive definite"):
        assert sum(key in n for n in names) == 1, key


def test_faithful_tire_modes_are_tested_between_the_grid_speeds(faithful_tire):
    """The paper's tire modes hold their LMIs at 36/63/90 km/h only while the runtime evaluates the
    model at the measured speed: the dense grid (41 speeds) tests P decrease and H-inf <= gamma."""
    checks = certificate.certify(faithful_tire)[1]
    for mode in faithful_tire["modes"]:
        i = mode["index"]
        for key in ("common P decreases", "H-inf bank->beta error"):
            c = _check(checks, key, f"mode {i}")
            assert "41 speeds over 36 km/h..90 km/h" in c.name and c.passed
    assert not any("cover the model speeds" in c.name for c in checks)


@pytest.mark.parametrize("which", ["design_speed", "design_tire"])
def test_summary_reports_the_band_gammas_and_the_dwell_time(which, request):
    d = request.getfixturevalue(which)
    s = certificate.summary(d)
    checks = certificate.certify(d)[1]
    assert len(s["bands"]) == len(d["modes"])
    for b in s["bands"]:
        c1 = _check(checks, "H-inf bank->beta error", f"mode {b['mode']}")
        assert b["gamma_band"] == c1.value <= d["gamma"] * (1 + 1e-6)
        if d["model_error"]["gamma"] is None:          # the robust-H2 gains: no model-error channel
            assert b["gamma2_band"] is None
            continue
        c2 = _check(checks, "gamma2 of the band", f"mode {b['mode']}")
        assert b["gamma2_band"] == c2.value <= d["model_error"]["gamma"] * (1 + 1e-6)
    for m in s["per_mode"]:              # a design speed's norm never exceeds its band's worst
        assert m["hinf"] <= m["gamma_band"] * (1 + 1e-9)
        if m["hinf_model_error"] is not None:
            assert m["hinf_model_error"] <= m["gamma2_band"] * (1 + 1e-9)
    fr = s["frozen_integral"]
    assert 1.0 < fr["mu"] < 10 and fr["lambda"] >= 2 * d["region"]["alpha"] * (1 - 1e-9)
    assert fr["tau_s"] == pytest.approx(math.log(fr["mu"]) / fr["lambda"], rel=1e-12)
    mu_check = _check(checks, "growth factor mu")
    assert mu_check.value == fr["mu"] and f"{fr['tau_s']:.4g} s" in mu_check.detail


# -- tampering: each fails the check named for it -----------------------------------------------------
def _halve_gamma2(d):
    d["model_error"]["gamma"] *= 0.5
    return ["model-error H-inf LMI"]


def _scale_E(d):
    d["model_error"]["E"] = [1.05 * np.asarray(E) for E in d["model_error"]["E"]]
    return ["model-error input E equals"]


def _widen_range(d):
    lo, hi = d["modes"][0]["model_speed"]["range"]
    d["modes"][0]["model_speed"]["range"] = [0.9 * lo, hi]
    return ["LMI vertices cover the model speeds", "mode 1"]


def _corrupt_gain(d):
    K = np.array(d["modes"][1]["gains"]["K_P"], float)
    K[1, 0] = -K[1, 0]                   # yaw row, yaw-rate measurement
    d["modes"][1]["gains"]["K_P"] = K
    return ["LMI (20)", "mode 2"]


def _asymmetric_P(d):
    P = np.array(d["P"], float)
    eps = 1e-6 * np.max(np.abs(P))
    P[0, 1] += eps                       # an antisymmetric change: the symmetric part (the proofs') is
    P[1, 0] -= eps                       # unchanged, only the stored-file check can see it
    d["P"] = P
    return ["P symmetric as stored"]


def _remove_vertex(d):
    corner = next(x for x in d["lmi_vertices"] if x["mode"] == 2 and x["label"].startswith("tangent corner"))
    d["lmi_vertices"].remove(corner)
    return ["LMI vertices cover the model speeds", "mode 2"]


@pytest.mark.parametrize("tamper", [_halve_gamma2, _scale_E, _widen_range, _corrupt_gain, _asymmetric_P, _remove_vertex])
def test_tampering_fails_the_named_check(tamper, design_speed, design_tire):
    d = copy.deepcopy(design_tire if tamper is _halve_gamma2 else design_speed)   # the speed modes: no gamma2
    parts = tamper(d)
    failed = _failed(d)
    assert any(all(p in n for p in parts) for n in failed), (parts, failed)
    if tamper is _asymmetric_P:
        assert failed == ["P symmetric as stored: max |P - P'| / max |P|"]
    if tamper is _corrupt_gain:          # only mode 2's checks, and mu (max over the modes: at mode 2)
        assert all("mode 2" in n or "growth factor mu" in n for n in failed), failed
    if tamper is _remove_vertex:
        assert len(d["lmi_vertices"]) == len(design_speed["lmi_vertices"]) - 1


def test_a_redundant_vertex_may_go(design_speed):
    """The coverage test is exact, not a sample: the middle knot of a mode lies on the segment
    between its two tangent corners (equal pieces in 1/Vx), so the hull is the same without it."""
    d = copy.deepcopy(design_speed)
    mid = [x for x in d["lmi_vertices"] if x["mode"] == 2 and not x["label"].startswith("tangent")][1]
    d["lmi_vertices"].remove(mid)
    assert _failed(d) == []


def test_faithful_tire_range_must_start_and_end_at_a_grid_speed(faithful_tire):
    d = copy.deepcopy(faithful_tire)
    lo, hi = d["modes"][1]["model_speed"]["range"]
    d["modes"][1]["model_speed"]["range"] = [lo, 1.1 * hi]
    assert any("both ends" in n and "mode 2" in n for n in _failed(d))


# -- the certificate's closed loop against an independent plant ---------------------------------------
def _independent_closed_loop(d, mode, vx):
    """A_cl, F_a, E_a from tests/linear_plant_000.py (sympy, first principles; its car with relaxed axle
    forces for a design whose model has them), [T N] = pinv([I; C]), E from the formulas of
    bicycle_roll_model.model_error_coefficients' docstring, typed here (0 on the relaxed forces' rows)."""
    veh = parse_vehicle(d["vehicle"], "test")
    p = {k: veh.value(k) for k in lp.PARAMETERS}
    kf, kr = mode["stiffness_scale"]
    p["Cf"], p["Cr"] = kf * p["Cf"], kr * p["Cr"]
    n = len(d["structure"]["states"])
    A, B, F = lp.relaxed_model({**p, "sigma": veh.value("sigma")}, vx) if n == 6 else lp.model(p, vx)
    C = np.eye(n)[1:4]
    TN = np.linalg.pinv(np.vstack([np.eye(n), C]))
    T = TN[:, :n]
    K_P, K_I = np.asarray(mode["gains"]["K_P"]), np.asarray(mode["gains"]["K_I"])
    m, Ix, Iz, hr, lf, lr = (p[k] for k in ("m", "Ix", "Iz", "hr", "lf", "lr"))
    g = lp.G
    Ieq = Ix + m * hr**2
    E = np.zeros((n, 3))             # columns: lateral force / (m g), yaw moment / (m g L), roll moment / (m g hr)
    E[0, 0], E[3, 0] = Ieq / (Ix * m * vx) * m * g, hr / Ix * m * g
    E[1, 1] = m * g * (lf + lr) / Iz
    E[0, 2], E[3, 2] = hr / (Ix * vx) * m * g * hr, m * g * hr / Ix
    Acl = np.block([[T @ A - K_P @ C, T @ F], [-K_I @ C, np.zeros((1, 1))]])
    return Acl, np.vstack([-T @ F, [[0.0]]]), np.vstack([-T @ E, np.zeros((1, 3))])


@pytest.mark.parametrize("which", ["design_speed", "design_tire"])
def test_closed_loop_equals_an_independent_construction(which, request):
    d = request.getfixturevalue(which)
    worst = 0.0
    for mode in d["modes"]:
        lo, hi = mode["model_speed"]["range"]
        for vx in np.linspace(lo, hi, 5):
            cl = certificate.closed_loop_000(d, mode, 1.0 / vx)
            for mine, theirs in zip((cl["Acl"], cl["Fa"], cl["Ea"]), _independent_closed_loop(d, mode, vx)):
                worst = max(worst, float(np.max(np.abs(mine - theirs)) / np.max(np.abs(theirs))))
            n = len(d["structure"]["states"])
            assert np.array_equal(cl["Afr"][:n], cl["Acl"][:n]) and not np.any(cl["Afr"][n])
    assert worst <= 1e-12


def test_vertex_models_are_the_affine_extension(design_speed):
    """At a tangent corner (off the curve w = v^2, or u = 1/v with the relaxed forces) the model is
    A0 + v A1 + w A2 (or u A_-1 + A0 + v A1): the coefficients recovered from the independent plant at
    three speeds give the same closed loop."""
    d = design_speed
    mode = d["modes"][1]
    relaxed = d["structure"].get("first_power") == -1
    na = len(d["structure"]["states"]) + 1
    speeds = np.array([12.0, 17.5, 24.0])
    mats = [_independent_closed_loop(d, mode, vx)[0] for vx in speeds]
    V = np.vander(1.0 / speeds, 3, increasing=True)               # rows [1, v, v^2]
    if relaxed:
        V = np.column_stack([speeds, np.ones(3), 1.0 / speeds])   # rows [u, 1, v]
    coef = np.linalg.solve(V, np.stack([M.ravel() for M in mats]))
    for x in d["lmi_vertices"]:
        if x["mode"] != 2:
            continue
        basis = (x["u"], 1.0, x["v"]) if relaxed else (1.0, x["v"], x["w"])
        theirs = sum(b * c for b, c in zip(basis, coef)).reshape(na, na)
        mine = certificate.closed_loop_000(d, mode, x["v"], x["w"], x.get("u"))["Acl"]
        assert np.max(np.abs(mine - theirs)) <= 1e-9 * np.max(np.abs(theirs))


# -- the frozen integral ---------------------------------------------------------------------------------
@pytest.mark.parametrize("which", ["design_speed", "design_tire"])
def test_frozen_integral_growth_is_bounded_by_mu(which, request):
    """Simulated freezes (e' = A_fr e, exact matrix exponential steps) from random initial errors
    stay below V(t) <= mu V(0), the worst direction reaches mu (it is the supremum, not a loose
    bound), and a freeze of any length followed by tau = ln(mu)/lambda of valid time ends with
    V <= V(0)."""
    d = request.getfixturevalue(which)
    fr = certificate.summary(d)["frozen_integral"]
    mu, tau = fr["mu"], fr["tau_s"]
    P = np.asarray(d["P"])
    w, U = np.linalg.eigh(P)
    Ph, Phi = (U * np.sqrt(w)) @ U.T, (U / np.sqrt(w)) @ U.T
    rng = np.random.default_rng(9)
    dt, steps = 2e-4, 10000                       # 2 s: far beyond every peak (t* < 0.1 s)
    reached = 0.0
    for mode in d["modes"]:
        lo, hi = mode["model_speed"]["range"]
        for vx in (lo, 0.5 * (lo + hi), hi):
            cl = certificate.closed_loop_000(d, mode, 1.0 / vx)
            Step = scipy.linalg.expm(cl["Afr"] * dt)
            # random errors, and the direction that the certificate's mu is attained from at t*
            M = Ph @ scipy.linalg.expm(cl["Afr"] * max(fr["t_peak_s"], dt)) @ Phi
            worst_dir = Phi @ np.linalg.svd(M)[2][0]
            E0 = np.column_stack([rng.standard_normal((len(P), 30)), worst_dir])
            V0 = np.einsum("ij,ik,kj->j", E0, P, E0)
            E, ratio = E0.copy(), np.ones(E0.shape[1])
            for k in range(steps):
                E = Step @ E
                ratio = np.maximum(ratio, np.einsum("ij,ik,kj->j", E, P, E) / V0)
            assert np.all(ratio <= mu * (1 + 1e-9)), (mode["index"], vx, ratio.max(), mu)
            reached = max(reached, float(ratio.max()))
            # freeze (length t, the worst) then valid for tau: V back below V(0)
            for t_freeze in (0.5 * fr["t_peak_s"], fr["t_peak_s"], 1.0):
                cyc = scipy.linalg.expm(cl["Acl"] * tau) @ scipy.linalg.expm(cl["Afr"] * t_freeze)
                E1 = cyc @ E0
                assert np.all(np.einsum("ij,ik,kj->j", E1, P, E1) <= V0 * (1 + 1e-9))
    assert reached >= mu * (1 - 1e-4)


def test_a_certificate_is_made_again_only_for_other_content(design_speed, monkeypatch):
    """``certificate.certify`` evaluates a design's checks once per content in a process (a build
    certifies a design when solved and before packaging): the same content, as another dict, in
    another key order or with numpy arrays, gives the same checks without evaluating them again;
    one changed gain (or table entry) is certified anew, and fails; what a certificate wrote into
    the dict (``certified``, ``checks``) is not part of the content."""
    from latobs.synthesis.certificate import sideslip_bank_observer as family

    evaluated = []
    real = family.certify
    monkeypatch.setattr(family, "certify", lambda d: evaluated.append(1) or real(d))
    monkeypatch.setattr(certificate, "_MADE", {})
    d = copy.deepcopy(design_speed)
    ok, checks = certificate.certify(d)
    assert ok and len(evaluated) == 1
    same = dict(reversed(list(copy.deepcopy(d).items())))
    same["modes"][0]["gains"]["K_P"] = np.asarray(same["modes"][0]["gains"]["K_P"])
    same["certified"], same["checks"] = False, []
    assert certificate.certify(same) == (ok, checks) and len(evaluated) == 1
    bad = copy.deepcopy(d)
    bad["modes"][0]["gains"]["K_P"][0][0] *= 1.5
    ok_bad, _ = certificate.certify(bad)
    assert not ok_bad and len(evaluated) == 2
    tab = copy.deepcopy(d)
    tab["tables"]["M"][0][0][0][1] += 1e-6       # (the model's coefficients: every design has them)
    assert not certificate.certify(tab)[0] and len(evaluated) == 3
