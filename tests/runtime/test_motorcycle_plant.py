"""Checks of the nonlinear motorcycle plant (latobs.fmu_src.motorcycle_plant) and its FMU.

Its linearisation must be the derived linear model (full, or reduced with algebraic tyres), its
FMU's small-input response must be scipy's solution of that linear model, its tyres must have the
paper's linear part with a real saturating remainder Gamma, and it must stay finite and upright on
paper 003's manoeuvre while reaching the tyres' saturation zone.
"""
from __future__ import annotations

import functools
import math
from pathlib import Path

import numpy as np
import pytest

from latobs import packaging
from latobs.fmu_src.motorcycle_plant import G, MotorcyclePlantModel
from latobs.synthesis import motorcycle_model as mm
from latobs.synthesis import params as params_mod
from latobs.validation.harness import FmuInstance
from latobs.validation.scenarios import get_scenario



@functools.cache
def _data() -> dict:
    """The plant data (its equations derived with sympy, ~2 s: when a test first needs them, not
    while the run collects its tests)."""
    return packaging.plant_data("sharp_motorcycle")


H = 0.005  # s, communication step
CONTRACT_OUTPUTS = {"steer_angle", "steer_rate", "yaw_rate", "roll_angle", "roll_rate", "vy", "Ff", "Fr"}


def plant(**params) -> MotorcyclePlantModel:
    return MotorcyclePlantModel(_data(), params)


def jacobian(p: MotorcyclePlantModel, vx: float):
    u0 = {"rider_torque": 0.0, "vx": vx}
    J = np.zeros((8, 8))
    for j in range(8):
        e = 1e-6 if j < 6 else 1e-3
        xp, xm = [0.0] * 8, [0.0] * 8
        xp[j], xm[j] = e, -e
        J[:, j] = (np.array(p.derivatives(xp, u0)) - np.array(p.derivatives(xm, u0))) / (2 * e)
    b = (np.array(p.derivatives([0.0] * 8, {"rider_torque": 1.0, "vx": vx}))
         - np.array(p.derivatives([0.0] * 8, {"rider_torque": -1.0, "vx": vx}))) / 2
    return J, b


def run_runtime(p: MotorcyclePlantModel, scenario, h: float = H):
    t = scenario.time_grid(h)
    sig = scenario.signals(t)
    p.initialize({k: float(v[0]) for k, v in sig.items()})
    out = {k: [v] for k, v in p.y.items()}
    for k in range(len(t) - 1):
        p.step(h, {n: float(v[k]) for n, v in sig.items()})
        for n, v in p.y.items():
            out[n].append(v)
    return t, sig, {k: np.array(v) for k, v in out.items()}


# ------------------------------------------------------------------------------------------
# linearisation == derived model
# ------------------------------------------------------------------------------------------
def test_constants():
    assert G == params_mod.G
    assert MotorcyclePlantModel.parameter_defaults(_data())["sigma"] == pytest.approx(0.2438)


@pytest.mark.parametrize("linear", [0.0, 1.0])
@pytest.mark.parametrize("vx", [5.0, 10.0, 20.0, 30.0, 45.0])
def test_linearisation_equals_full_model(vx, linear):
    J, b = jacobian(plant(linear_tires=linear), vx)
    f = mm.full_model("sharp_motorcycle", vx)
    np.testing.assert_allclose(J, f.A, rtol=1e-6, atol=1e-8 * np.abs(f.A).max())
    np.testing.assert_allclose(b, f.B_tau, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("vx", [5.0, 15.0, 30.0])
def test_algebraic_tyres_linearise_to_the_reduced_model(vx):
    J, b = jacobian(plant(sigma=0.0), vx)
    r = mm.reduced_model("sharp_motorcycle", vx)
    idx = [mm.STATE_FULL.index(n) for n in mm.STATE_REDUCED]
    phi = mm.STATE_FULL.index("roll_angle")
    np.testing.assert_allclose(J[np.ix_(idx, idx)], r.A, rtol=1e-6, atol=1e-8 * np.abs(r.A).max())
    np.testing.assert_allclose(J[idx, phi], r.E_phi, rtol=1e-6, atol=1e-8 * np.abs(r.E_phi).max())
    np.testing.assert_allclose(b[idx], r.B_tau, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("sigma", [0.0, 0.01, 0.05, 0.2438, 1.0, 5.0])
def test_substep_estimate_bounds_the_spectral_radius(sigma):
    p = plant(sigma=sigma)
    for vx in (0.0, 0.5, 1.0, 3.0, 10.0, 20.0, 30.0, 45.0, 60.0):
        if sigma == 0.0:
            rho = np.abs(np.linalg.eigvals(mm.reduced_model("sharp_motorcycle", max(vx, 1.0)).A)).max()
        else:
            rho = np.abs(np.linalg.eigvals(jacobian(p, vx)[0])).max()
        assert rho <= p.lam_est(vx), (vx, rho, p.lam_est(vx))
    # the default data at 1 ms: |lambda| dt <= 0.25 up to 60 m/s (module docstring)
    assert plant().lam_est(60.0) * 1e-3 < 0.41 and np.abs(np.linalg.eigvals(mm.full_model(
        "sharp_motorcycle", 60.0).A)).max() * 1e-3 < 0.26


# ------------------------------------------------------------------------------------------
# tyre: linear part of the paper, saturation at mu Fz, Gamma real and zero at small slip
# ------------------------------------------------------------------------------------------
def _state_for(alpha_f=0.0, alpha_r=0.0, phi=0.0, vx=20.0):
    """A state whose slips are alpha_f, alpha_r (via vy and yaw rate) and roll phi, delta = 0."""
    tyres = _data()["structure"]["tyres"]
    lf, lr = tyres["front"]["slip_velocity"][1], -tyres["rear"]["slip_velocity"][1]
    # alpha_f = -(vy + lf r)/vx, alpha_r = -(vy - lr r)/vx
    r = -(alpha_f - alpha_r) * vx / (lf + lr)
    vy = -alpha_r * vx + lr * r
    return [phi, 0.0, vy, r, 0.0, 0.0, 0.0, 0.0]


@pytest.mark.parametrize("mu", [1.0, 0.5])
def test_tyre_slope_at_zero_is_paper_stiffness(mu):
    p = plant(mu=mu, sigma=0.0)
    t = _data()["structure"]["tyres"]
    u = {"rider_torque": 0.0, "vx": 20.0}
    a = 1e-6
    d = p.tyre_state(_state_for(alpha_f=a, alpha_r=a), u)
    assert d["alpha_f"] == pytest.approx(a) and d["alpha_r"] == pytest.approx(a)
    assert d["Ff"] / a == pytest.approx(t["front"]["C1"], rel=1e-6)
    assert d["Fr"] / a == pytest.approx(t["rear"]["C1"], rel=1e-6)
    d = p.tyre_state(_state_for(phi=a), u)
    assert d["Ff"] / a == pytest.approx(t["front"]["C2"], rel=1e-6)
    assert d["Fr"] / a == pytest.approx(t["rear"]["C2"], rel=1e-6)
    assert abs(d["Gamma_f"]) < 1e-12 and abs(d["Gamma_r"]) < 1e-12


@pytest.mark.parametrize("mu", [1.0, 0.3])
def test_tyre_saturates_at_mu_times_static_load(mu):
    p = plant(mu=mu, sigma=0.0)
    t = _data()["structure"]["tyres"]
    u = {"rider_torque": 0.0, "vx": 20.0}
    peak = [0.0, 0.0]
    for a in np.linspace(-0.6, 0.6, 241):
        for phi in (-0.5, 0.0, 0.5):
            d = p.tyre_state(_state_for(alpha_f=a, alpha_r=a, phi=phi), u)
            lin_f = d["Ff"] - d["Gamma_f"]
            assert abs(d["Ff"]) <= mu * t["front"]["Fz"] * (1 + 1e-12)
            assert abs(d["Fr"]) <= mu * t["rear"]["Fz"] * (1 + 1e-12)
            assert d["Ff"] * lin_f >= 0            # the force never reverses (0 < C < 2)
            assert d["Gamma_f"] * lin_f <= 0       # Gamma works against the linear part
            peak = [max(peak[0], abs(d["Ff"])), max(peak[1], abs(d["Fr"]))]
    assert peak[0] == pytest.approx(mu * t["front"]["Fz"], rel=1e-3)
    assert peak[1] == pytest.approx(mu * t["rear"]["Fz"], rel=1e-3)
    # Gamma is O(x^3): tiny at 0.5 deg of slip, ~10 % of the force at ~3 deg (front, mu = 1)
    d = p.tyre_state(_state_for(alpha_f=0.01 * mu), u)   # B ~ 1/mu: the same B x for any mu
    assert abs(d["Gamma_f"]) < 0.01 * abs(d["Ff"])


def test_linear_tyres_have_no_gamma():
    p = plant(linear_tires=1, sigma=0.0)
    d = p.tyre_state(_state_for(alpha_f=0.3, alpha_r=-0.2, phi=0.4), {"rider_torque": 0.0, "vx": 20.0})
    front = _data()["structure"]["tyres"]["front"]
    assert d["Gamma_f"] == 0.0 and d["Gamma_r"] == 0.0 and abs(d["Ff"]) > 2 * front["Fz"]


# ------------------------------------------------------------------------------------------
# the runtime on paper 003's manoeuvre and at extremes
# ------------------------------------------------------------------------------------------
def test_counter_steering():
    p = plant()
    for k in range(200):   # 1 s of +10 N m at 20 m/s
        p.step(H, {"rider_torque": 10.0, "vx": 20.0})
        if k == 9:
            assert p.y["steer_angle"] > 0            # steers right first ...
    assert p.y["roll_angle"] < -0.05 and p.y["yaw_rate"] < 0   # ... then leans and turns left


@pytest.mark.parametrize("speeds", [(12.0, 20.0, 10.0), (20.0, 30.0, 25.0), (10.0, 30.0, 10.0)])
def test_scenario_bounded_over_10_to_30_mps(speeds):
    """The manoeuvre (45 N m pulses) at speed profiles spanning paper 003's grid 10-30 m/s: the
    motorcycle stays upright (|roll| < 0.6 rad), finite, without warnings."""
    sc = get_scenario("motorcycle-lane-change", v_start=speeds[0], v_high=speeds[1], v_end=speeds[2])
    p = plant()
    _, sig, y = run_runtime(p, sc)
    assert all(np.all(np.isfinite(v)) for v in y.values())
    assert np.abs(y["roll_angle"]).max() < 0.6
    assert np.abs(y["roll_angle"][-200:]).max() < 0.2            # the last second: no capsize run-away
    assert np.abs(y["steer_angle"]).max() < 0.1
    assert not p.events
    assert sig["vx"].min() == pytest.approx(min(speeds)) and sig["vx"].max() == pytest.approx(max(speeds))


def test_near_zero_speed_is_finite_and_warned():
    p = plant()
    for vx in (20.0, 5.0, 0.5, 0.0, -3.0, 0.0, 100.0, 20.0):
        for _ in range(20):
            p.step(H, {"rider_torque": 5.0, "vx": vx})
            assert all(math.isfinite(v) for v in p.y.values())
    msgs = [m for _, m in p.events]
    assert any("below 1.0 m/s" in m for m in msgs)
    assert any("< 0 clamped to 0" in m for m in msgs)
    assert any("clamped to 60.0 m/s" in m for m in msgs)
    assert sum("below 1.0 m/s" in m for m in msgs) == 1          # once per entry into the clamp range


def test_vx_floor_regularises_slip_and_relaxation():
    p = plant()
    x = [0.01, 0.002, 0.1, 0.05, 0.02, 0.01, 20.0, -15.0]
    d0 = p.derivatives(x, {"rider_torque": 1.0, "vx": 0.0})
    d1 = p.derivatives(x, {"rider_torque": 1.0, "vx": 1.0})
    # slip and relaxation use max(vx, 1): only the vx-proportional mechanics (C1 terms) differ
    assert d0[6:] == pytest.approx(d1[6:], rel=1e-12)
    assert all(math.isfinite(v) for v in d0)


def test_torque_clamp_and_nonfinite_inputs_hold_last_valid():
    p = plant()
    p.step(H, {"rider_torque": 1e4, "vx": 20.0})
    assert any("clamped to 200.0 N m" in m for _, m in p.events)
    p.events.clear()
    y0 = dict(p.y)
    p.step(H, {"rider_torque": math.nan, "vx": math.inf})
    assert all(math.isfinite(v) for v in p.y.values()) and p.y != y0
    msgs = [m for _, m in p.events]
    assert any("rider_torque" in m and "not finite" in m for m in msgs)
    assert any("vx" in m and "not finite" in m for m in msgs)


def test_fallen_motorcycle_warns_once_and_stays_finite():
    p = plant()
    for _ in range(1200):   # a steady 60 N m at 8 m/s throws it over
        p.step(H, {"rider_torque": 60.0, "vx": 8.0})
        assert all(math.isfinite(v) for v in p.y.values())
    assert sum("fallen over" in m for _, m in p.events) == 1


@pytest.mark.parametrize("params, name", [({"mu": 0.0}, "mu"), ({"mu": math.nan}, "mu"),
                                          ({"sigma": 0.001}, "sigma"), ({"sigma": -1.0}, "sigma"),
                                          ({"linear_tires": 0.5}, "linear_tires"), ({"mf_C": 2.0}, "mf_C"),
                                          ({"mf_E": 1.5}, "mf_E"), ({"bogus": 1.0}, "bogus")])
def test_invalid_parameters_raise_naming_them(params, name):
    with pytest.raises(ValueError, match=name):
        plant(**params)


def test_refuses_data_without_structure():
    with pytest.raises(ValueError, match="structure"):
        MotorcyclePlantModel({"vehicle": _data()["vehicle"]}, {})
    with pytest.raises(ValueError, match="structure"):
        MotorcyclePlantModel(packaging.plant_data("sedan"), {})


# ------------------------------------------------------------------------------------------
# the FMU
# ------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def fmu_path(tmp_path_factory):
    return packaging.package_plant("MotorcyclePlant", None, tmp_path_factory.mktemp("moto"))


def open_fmu(path, params=None, u0=None) -> FmuInstance:
    fmu = FmuInstance("moto", Path(path))
    fmu.start(u0 or {"rider_torque": 0.0, "vx": 20.0}, params)
    return fmu


def test_fmu_interface(fmu_path):
    fmu = FmuInstance("moto", fmu_path)
    try:
        assert {v.name for v in fmu.inputs} == {"rider_torque", "vx"}
        outs = {v.name for v in fmu.outputs}
        assert CONTRACT_OUTPUTS <= outs
        assert outs - CONTRACT_OUTPUTS == {"Gamma_f", "Gamma_r", "alpha_f", "alpha_r"}
        params = {v.name: v for v in fmu.md.modelVariables if v.causality == "parameter"}
        assert float(params["sigma"].start) == pytest.approx(0.2438)
    finally:
        fmu.close()


def test_fmu_small_input_matches_solve_ivp_of_the_linear_model(fmu_path):
    """FMU with linear tyres, a 1 N m sin^2 torque pulse at 20 m/s (roll < 0.02 rad), against
    scipy's solve_ivp of full_model's linear equations with the same input held over each 5 ms
    step. Differences: sin(phi) - phi (relative phi^2/6 < 1e-4) and RK4's error (~1e-9): the
    tolerance is 5e-4 of each signal's peak."""
    from scipy.integrate import solve_ivp

    vx, T = 20.0, 3.0
    n = int(round(T / H))
    tau = [1.0 * math.sin(math.pi * min(max(k * H - 0.2, 0.0), 1.0)) ** 2 for k in range(n)]
    fmu = open_fmu(fmu_path, {"linear_tires": 1.0}, {"rider_torque": 0.0, "vx": vx})
    got = []
    try:
        for k in range(n):
            fmu.set_inputs({"rider_torque": tau[k], "vx": vx})
            fmu.slave.doStep(k * H, H)
            got.append(fmu.get_outputs())
    finally:
        fmu.close()
    f = mm.full_model("sharp_motorcycle", vx)
    x = np.zeros(8)
    ref = []
    for k in range(n):
        sol = solve_ivp(lambda t, s, u=tau[k]: f.A @ s + f.B_tau * u, (0.0, H), x, method="DOP853",
                        rtol=1e-11, atol=1e-13)
        x = sol.y[:, -1]
        ref.append(x)
    ref = np.array(ref)
    assert np.abs(ref[:, 0]).max() < 0.02
    for j, name in enumerate(mm.STATE_FULL):
        g = np.array([o[name] for o in got])
        peak = np.abs(ref[:, j]).max()
        assert peak > 0
        np.testing.assert_allclose(g, ref[:, j], atol=5e-4 * peak, rtol=0, err_msg=name)


def test_fmu_on_paper_003_scenario_reaches_saturation_and_stays_upright(fmu_path):
    sc = get_scenario("motorcycle-lane-change")
    t = sc.time_grid(H)
    sig = sc.signals(t, "sharp_motorcycle")
    fmu = open_fmu(fmu_path, None, {k: float(v[0]) for k, v in sig.items()})
    out = []
    try:
        for k in range(len(t) - 1):
            fmu.set_inputs({n: float(v[k]) for n, v in sig.items()})
            fmu.slave.doStep(float(t[k]), H)
            out.append(fmu.get_outputs())
    finally:
        fmu.close()
    y = {k: np.array([o[k] for o in out]) for k in out[0]}
    assert all(np.all(np.isfinite(v)) for v in y.values())
    roll = y["roll_angle"]
    assert 0.4 < np.abs(roll).max() < 0.55                          # upright: ~28 deg peak
    t_out = t[1:]
    assert roll.min() < -0.4 and roll.max() < 0.05                  # counter-steered: leans LEFT first
    assert np.abs(roll[t_out > 7.5]).max() < 0.15                  # the negative pulse straightens it
    assert np.abs(roll[-200:]).max() < 0.15                          # stable at the end (10 m/s)
    ratio_f = np.abs(y["Gamma_f"]).max() / np.abs(y["Ff"]).max()
    ratio_r = np.abs(y["Gamma_r"]).max() / np.abs(y["Fr"]).max()
    assert ratio_f > 0.1 and ratio_r > 0.1, (ratio_f, ratio_r)      # the saturation zone is reached
    Fz = _data()["structure"]["tyres"]
    assert np.abs(y["Ff"]).max() < Fz["front"]["Fz"] and np.abs(y["Fr"]).max() < Fz["rear"]["Fz"]
    # the speed visits three of paper 003's grid modes (nearest of 10, 15, ..., 30 m/s)
    modes = {int(round(v / 5.0)) * 5 for v in sig["vx"]}
    assert {10, 15, 20} <= modes
    assert not [m for m in fmu.logs if "WARNING" in m or "ERROR" in m]


def test_fmu_nan_input_is_refused_not_a_crash(fmu_path):
    fmu = open_fmu(fmu_path)
    try:
        for k in range(10):
            fmu.set_inputs({"rider_torque": 5.0, "vx": 20.0})
            fmu.slave.doStep(k * H, H)
        before = fmu.get_outputs()
        fmu.set_inputs({"rider_torque": math.nan, "vx": 20.0})
        with pytest.raises(Exception, match="discard"):
            fmu.slave.doStep(10 * H, H)
        assert fmu.get_outputs() == before                           # state held
        for k in range(11, 20):                                       # recovers, and clamps near 0 m/s
            fmu.set_inputs({"rider_torque": 5.0, "vx": 0.0})
            fmu.slave.doStep(k * H, H)
        assert all(math.isfinite(v) for v in fmu.get_outputs().values())
    finally:
        fmu.close()
    assert any("non-finite input(s) rider_torque" in m for m in fmu.logs)
    assert any("below 1.0 m/s" in m for m in fmu.logs)
