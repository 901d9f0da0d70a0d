"""CarPlant additions for paper 001 (switched interval observer of vy and the tire forces).

* ``linear_tires = 1``: each wheel's steady-state force is the Magic Formula's slope at zero slip
  times the slip, Fy_ss = mu Fz B C alpha, without saturation (E6).
* outputs at the CG: ``vy_cg = vy - hr phidot cos(phi)``, ``beta_cg = atan(vy_cg / vx)``.
* the plant with linear tires, relaxation and hr -> 0 linearises at straight driving to paper
  001's design model (bicycle model with tire relaxation, linear tires, no roll).
"""
from __future__ import annotations

import copy
import math

import numpy as np
import pytest

from latobs.fmu_src.car_plant import CarPlantModel
from latobs.fmu_src.models.car_plant import SPEC
from latobs.packaging import plant_data

DATA = plant_data("sedan")
VP = {k: (v["value"] if isinstance(v, dict) else v) for k, v in DATA["vehicle"]["parameters"].items()}


def data_with(**overrides) -> dict:
    d = copy.deepcopy(DATA)
    for k, v in overrides.items():
        d["vehicle"]["parameters"][k]["value"] = v
    return d


# ------------------------------------------------------------------------------------------
# parameter and interface
# ------------------------------------------------------------------------------------------
def test_linear_tires_parameter_declared_and_validated():
    assert CarPlantModel.PARAMETERS["linear_tires"] == 0.0
    assert CarPlantModel.PARAMETER_INFO["linear_tires"][0] == "1"
    assert CarPlantModel.parameter_defaults(DATA)["linear_tires"] == 0.0
    (var,) = [v for v in SPEC.parameters if v.name == "linear_tires"]
    assert (var.unit, var.start, var.min, var.max) == ("1", 0.0, 0.0, 1.0)
    assert CarPlantModel(DATA, {"linear_tires": 1}).params["linear_tires"] == 1.0
    for bad in (0.5, 2.0, -1.0, float("nan")):
        with pytest.raises(ValueError, match="linear_tires"):
            CarPlantModel(DATA, {"linear_tires": bad})


def test_cg_outputs_declared_after_the_existing_ones():
    names = [v.name for v in SPEC.outputs]
    assert names[-2:] == ["vy_cg", "beta_cg"]
    assert list(CarPlantModel.OUTPUTS)[-2:] == ["vy_cg", "beta_cg"]
    assert set(CarPlantModel(DATA).y) == set(names)
    units = {v.name: v.unit for v in SPEC.outputs}
    assert units["vy_cg"] == "m/s" and units["beta_cg"] == "rad"


# ------------------------------------------------------------------------------------------
# (a) linear tires: no saturation
# ------------------------------------------------------------------------------------------
def axle_forces(p: CarPlantModel, alpha_deg: float, vx: float = 20.0):
    """Body-y axle forces (front, rear) at the constant state vy = -vx tan(alpha), r = 0, no roll,
    delta = 0: every wheel has slip angle alpha. Algebraic tires: tire_state's forces are the
    steady-state ones (load transfer included)."""
    a = math.radians(alpha_deg)
    ts = p.tire_state([-vx * math.tan(a), 0.0, 0.0, 0.0], {"delta": 0.0, "vx": vx, "bank_angle": 0.0})
    F1, F2, F3, F4 = ts["F"]
    return F1 + F2, F3 + F4, ts


def test_linear_tires_are_linear_at_large_slip_and_mf_saturates():
    lin = CarPlantModel(DATA, {"sigma": 0.0, "linear_tires": 1})
    f1, r1, _ = axle_forces(lin, 1.0)
    f10, r10, ts = axle_forces(lin, 10.0)
    assert f10 == pytest.approx(10.0 * f1, rel=1e-9) and r10 == pytest.approx(10.0 * r1, rel=1e-9)
    # the load transfer acted (left/right loads differ) and the axle stiffness is exactly C_axle
    Fz = ts["Fz"]
    assert Fz[1] - Fz[0] > 100.0
    assert f10 == pytest.approx(VP["Cf"] * math.radians(10.0), rel=1e-12)
    assert r10 == pytest.approx(VP["Cr"] * math.radians(10.0), rel=1e-12)
    # beyond mu Fz: no saturation
    assert f10 > VP["mu"] * (Fz[0] + Fz[1])

    mf = CarPlantModel(DATA, {"sigma": 0.0})
    g1, s1, _ = axle_forces(mf, 1.0)
    g10, s10, ts = axle_forces(mf, 10.0)
    assert g1 == pytest.approx(f1, rel=0.05) and s1 == pytest.approx(r1, rel=0.05)   # same slope at 0
    assert g10 < 0.6 * f10 and s10 < 0.6 * r10                                      # saturates
    Fz = ts["Fz"]
    assert g10 <= VP["mu"] * (Fz[0] + Fz[1]) * (1 + 1e-12)


@pytest.mark.parametrize("scale_f, scale_r, mu", [(1.0, 1.0, 1.0), (0.7, 1.3, 0.4)])
def test_linear_tires_with_relaxation_steady_state(scale_f, scale_r, mu):
    """Relaxation on: the steady-state force is Fy_ss = F + F' / k (E7); linear in slip,
    per axle scale * C_axle * alpha at any mu."""
    p = CarPlantModel(DATA, {"linear_tires": 1, "scale_f": scale_f, "scale_r": scale_r, "mu": mu})
    vx = 20.0
    k = vx / p.params["sigma"]
    for deg in (1.0, 10.0, 25.0):
        a = math.radians(deg)
        d = p.derivatives([-vx * math.tan(a), 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
                          {"delta": 0.0, "vx": vx, "bank_angle": 0.0})
        Fss = [v / k for v in d[4:]]
        assert Fss[0] + Fss[1] == pytest.approx(scale_f * VP["Cf"] * a, rel=1e-12)
        assert Fss[2] + Fss[3] == pytest.approx(scale_r * VP["Cr"] * a, rel=1e-12)


# ------------------------------------------------------------------------------------------
# (b) vy_cg: E2 is Newton's law for the CG's lateral velocity
# ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("linear_tires", [0, 1])
def test_vy_cg_satisfies_lateral_newton_for_the_cg(linear_tires):
    """Finite differences of the stepped outputs: d(vy_cg)/dt + vx r = S/m (flat road), while the
    roll-axis vy does not satisfy it (the roll motion's contribution is visible)."""
    p = CarPlantModel(DATA, {"linear_tires": linear_tires})
    h, vx = 1e-3, 20.0
    n = 3000
    ys = {k: np.empty(n) for k in ("vy", "vy_cg", "beta_cg", "yaw_rate", "ay", "roll_angle", "roll_rate")}
    for i in range(n):
        t = i * h
        p.step(h, {"delta": 0.06 * math.sin(2 * math.pi * 1.0 * t) * (t < 1.5), "vx": vx, "bank_angle": 0.0})
        for k in ys:
            ys[k][i] = p.y[k]
    np.testing.assert_allclose(ys["vy_cg"], ys["vy"] - VP["hr"] * ys["roll_rate"] * np.cos(ys["roll_angle"]),
                               rtol=0, atol=1e-15)
    np.testing.assert_allclose(ys["beta_cg"], np.arctan(ys["vy_cg"] / vx), rtol=0, atol=1e-15)
    rhs = ys["ay"][1:-1] - vx * ys["yaw_rate"][1:-1]
    scale = np.abs(ys["ay"]).max()
    assert scale > 3.0
    err_cg = np.abs((ys["vy_cg"][2:] - ys["vy_cg"][:-2]) / (2 * h) - rhs).max()
    err_axis = np.abs((ys["vy"][2:] - ys["vy"][:-2]) / (2 * h) - rhs).max()
    assert err_cg < 1e-4 * scale
    assert err_axis > 1e-2 * scale


def test_vy_cg_sign_against_a_roll_only_motion():
    """Pure roll (vy = 0 at the axis): the CG's offset is -hr sin(phi), so phidot > 0 moves it to -y."""
    p = CarPlantModel(DATA, {"sigma": 0.0})
    p.x = [0.0, 0.0, 0.0, 0.2, 0.0, 0.0, 0.0, 0.0]
    p._update_outputs()
    assert p.y["vy_cg"] == pytest.approx(-VP["hr"] * 0.2, rel=1e-15)
    assert p.y["vy"] == 0.0 and p.y["beta_cg"] < 0.0


# ------------------------------------------------------------------------------------------
# (c) linearisation == paper 001's design model (bicycle, relaxation, linear tires, no roll)
# ------------------------------------------------------------------------------------------
def design_model(vx, m, Iz, lf, lr, cf, cr, s):
    A = np.array([[0.0, -vx, 1.0, 0.0],
                  [0.0, 0.0, 0.0, 1.0],
                  [-(cf + cr) / (m * s), (cr * lr - cf * lf) / (m * s), -vx / s, 0.0],
                  [(cr * lr - cf * lf) / (Iz * s), -(cf * lf ** 2 + cr * lr ** 2) / (Iz * s), 0.0, -vx / s]])
    B = np.array([0.0, 0.0, cf * vx / (m * s), cf * lf * vx / (Iz * s)])
    return A, B


def plant_to_design_map(m, Iz, lf, lr):
    """x = M z for the plant state z = (vy, r, phi, phidot, Fy_fl, Fy_fr, Fy_rl, Fy_rr):
    x = [vy, r, (Fy_fl + Fy_fr + Fy_rl + Fy_rr)/m, (lf (Fy_fl + Fy_fr) - lr (Fy_rl + Fy_rr))/Iz].
    (Axle sums in body y: the front wheels' cos(delta) is 1 to first order at delta = 0.)
    P is the right inverse with phi = phidot = 0 and equal left/right forces; the kernel of M
    (roll and the left/right force differences) is spanned by K."""
    M = np.zeros((4, 8))
    M[0, 0] = 1.0
    M[1, 1] = 1.0
    M[2, 4:] = 1.0 / m
    M[3, 4:] = np.array([lf, lf, -lr, -lr]) / Iz
    # Ff, Fr from x3, x4: [[1, 1], [lf, -lr]] [Ff, Fr] = [m x3, Iz x4]
    Ginv = np.linalg.inv(np.array([[1.0, 1.0], [lf, -lr]]))
    P = np.zeros((8, 4))
    P[0, 0] = 1.0
    P[1, 1] = 1.0
    for j, scale in ((2, m), (3, Iz)):
        Ff, Fr = Ginv[:, j - 2] * scale
        P[4:, j] = [Ff / 2, Ff / 2, Fr / 2, Fr / 2]
    K = np.zeros((8, 4))
    K[2, 0] = K[3, 1] = 1.0
    K[4:, 2] = [1.0, -1.0, 0.0, 0.0]
    K[4:, 3] = [0.0, 0.0, 1.0, -1.0]
    return M, P, K


def numerical_jacobians(p: CarPlantModel, vx: float):
    u0 = {"delta": 0.0, "vx": vx, "bank_angle": 0.0}
    z0 = np.zeros(8)
    steps = np.array([1e-6 * vx, 1e-6, 1e-6, 1e-6, 1.0, 1.0, 1.0, 1.0])   # m/s, rad/s, rad, rad/s, N
    J = np.zeros((8, 8))
    for j in range(8):
        zp, zm = z0.copy(), z0.copy()
        zp[j], zm[j] = steps[j], -steps[j]
        J[:, j] = (np.array(p.derivatives(list(zp), u0)) - np.array(p.derivatives(list(zm), u0))) / (2 * steps[j])
    e = 1e-6
    Bu = (np.array(p.derivatives(list(z0), dict(u0, delta=e)))
          - np.array(p.derivatives(list(z0), dict(u0, delta=-e)))) / (2 * e)
    return J, Bu


@pytest.mark.parametrize("vx", [15.0, 5.0, 40.0])
@pytest.mark.parametrize("scale_f, scale_r, mu", [(1.0, 1.0, 1.0), (0.8, 1.2, 0.5)])
def test_linearisation_equals_paper_001_design_model(vx, scale_f, scale_r, mu):
    data = data_with(hr=1e-6)
    p = CarPlantModel(data, {"linear_tires": 1, "scale_f": scale_f, "scale_r": scale_r, "mu": mu})
    m, Iz, lf, lr, s = VP["m"], VP["Iz"], VP["lf"], VP["lr"], p.params["sigma"]
    cf, cr = scale_f * VP["Cf"], scale_r * VP["Cr"]
    A_ref, B_ref = design_model(vx, m, Iz, lf, lr, cf, cr, s)
    J, Bu = numerical_jacobians(p, vx)
    M, P, K = plant_to_design_map(m, Iz, lf, lr)
    np.testing.assert_allclose(M @ P, np.eye(4), atol=1e-15)
    A_num, B_num = M @ J @ P, M @ Bu
    np.testing.assert_allclose(A_num, A_ref, rtol=1e-5, atol=1e-9 * np.abs(A_ref).max())
    np.testing.assert_allclose(B_num, B_ref, rtol=1e-5, atol=1e-9 * np.abs(B_ref).max())
    # the reduction is exact: roll and the left/right force differences do not drive x
    # (roll only through hr = 1e-6: |d vy'/d phi| = hr Kr / Ix ~ 1e-4 1/s^2)
    leak = M @ J @ K
    assert np.abs(leak[:, 2:]).max() <= 1e-9 * np.abs(A_ref).max()
    assert np.abs(leak[:, :2]).max() <= 1e-5 * np.abs(A_ref).max()


def test_vy_cg_equals_vy_when_hr_vanishes():
    p = CarPlantModel(data_with(hr=1e-6), {"linear_tires": 1})
    for i in range(400):
        p.step(0.005, {"delta": 0.03 * math.sin(3.0 * i * 0.005), "vx": 15.0, "bank_angle": 0.0})
        assert abs(p.y["vy_cg"] - p.y["vy"]) <= 1e-6 * abs(p.y["roll_rate"]) + 1e-15
