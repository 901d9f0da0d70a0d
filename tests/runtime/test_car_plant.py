"""Mathematical checks of the nonlinear car plant (latobs.fmu_src.car_plant).

The plant is the truth model of the car observers: its linearisation at straight driving must be
exactly the paper-000 design model, its steady states must be the linear ones for small inputs,
its tire forces must saturate at mu * load, and it must stay finite over the whole speed range.
"""
from __future__ import annotations

import math
import time

import numpy as np
import pytest

from latobs.fmu_src.car_plant import G, CarPlantModel
from latobs.synthesis import params as params_mod
from latobs.synthesis.bicycle_roll_model import evaluate, model, relaxed_lpv_coefficients
from latobs.synthesis.params import load_vehicle

VEH = load_vehicle("sedan")
DATA = {"vehicle": VEH.as_dict()}
P = {k: VEH.value(k) for k in ("m", "Iz", "Ix", "lf", "lr", "hr", "Kr", "br", "Cf", "Cr",
                               "track", "h_rc", "roll_share_f", "mf_C", "mf_E")}


def plant(**params) -> CarPlantModel:
    return CarPlantModel(DATA, params)


def simulate(p: CarPlantModel, T: float, u_of_t, h: float = 0.005):
    """Run ``p`` for T seconds; returns (t, dict of output arrays)."""
    n = int(round(T / h))
    out = {k: np.empty(n) for k in p.y}
    t = np.arange(1, n + 1) * h
    for i in range(n):
        p.step(h, u_of_t(i * h))
        for k, v in p.y.items():
            out[k][i] = v
    return t, out


def linearise(p: CarPlantModel, vx: float):
    """Central-difference Jacobians of p.derivatives at straight driving, in beta coordinates."""
    u0 = {"delta": 0.0, "vx": vx, "bank_angle": 0.0}
    x0 = [0.0] * 4
    A = np.zeros((4, 4))
    scales = (1e-6 * vx, 1e-6, 1e-6, 1e-6)
    for j in range(4):
        e = scales[j]
        xp, xm = list(x0), list(x0)
        xp[j], xm[j] = e, -e
        A[:, j] = (np.array(p.derivatives(xp, u0)) - np.array(p.derivatives(xm, u0))) / (2 * e)
    cols = []
    for key in ("delta", "bank_angle"):
        e = 1e-6
        up, um = dict(u0), dict(u0)
        up[key], um[key] = e, -e
        cols.append((np.array(p.derivatives(x0, up)) - np.array(p.derivatives(x0, um))) / (2 * e))
    T = np.diag([vx, 1.0, 1.0, 1.0])          # x_plant = T x_design (vy = vx beta)
    Ti = np.linalg.inv(T)
    return Ti @ A @ T, (Ti @ cols[0])[:, None], (Ti @ cols[1])[:, None]


def linearise_relaxed(p: CarPlantModel, vx: float):
    """Central-difference Jacobians of p.derivatives (all 8 states, the wheel forces relaxed) at
    straight driving: J and the columns of delta and bank_angle, in the plant's coordinates."""
    u0 = {"delta": 0.0, "vx": vx, "bank_angle": 0.0}
    J = np.zeros((8, 8))
    for j in range(8):
        e = 1e-4 if j < 4 else 1.0
        xp, xm = [0.0] * 8, [0.0] * 8
        xp[j], xm[j] = e, -e
        J[:, j] = (np.array(p.derivatives(xp, u0)) - np.array(p.derivatives(xm, u0))) / (2 * e)
    cols = []
    for key in ("delta", "bank_angle"):
        up, um = dict(u0), dict(u0)
        up[key], um[key] = 1e-5, -1e-5
        cols.append((np.array(p.derivatives([0.0] * 8, up)) - np.array(p.derivatives([0.0] * 8, um))) / 2e-5)
    return J, cols[0], cols[1]


def assert_close(M, R, rtol=1e-5):
    atol = 1e-9 * max(1.0, np.abs(R).max())
    np.testing.assert_allclose(M, R, rtol=rtol, atol=atol)


# ------------------------------------------------------------------------------------------
# linearisation == design model
# ------------------------------------------------------------------------------------------
def test_gravity_constant_matches_design_code():
    assert G == params_mod.G


@pytest.mark.parametrize("vx", [5.0, 10.0, 20.0, 40.0, 60.0])
def test_linearisation_equals_design_model(vx):
    A, B, F = linearise(plant(sigma=0.0, mu=1.0), vx)
    ref = model(VEH, vx)
    assert_close(A, ref.A)
    assert_close(B, ref.B)
    assert_close(F, ref.F)


@pytest.mark.parametrize("mu", [1.0, 0.3])
@pytest.mark.parametrize("vx", [5.0, 20.0, 60.0])
def test_linearisation_with_stiffness_scales(vx, mu):
    """scale_f/scale_r scale the axle stiffness; mu does not change the linear stiffness."""
    A, B, F = linearise(plant(sigma=0.0, mu=mu, scale_f=0.8, scale_r=1.2), vx)
    ref = model(VEH, vx, Cf=0.8 * P["Cf"], Cr=1.2 * P["Cr"])
    assert_close(A, ref.A)
    assert_close(B, ref.B)
    assert_close(F, ref.F)


def test_linearisation_with_relaxation_reduces_to_design_model():
    """With relaxation the tire states are fast first-order lags of the algebraic forces: the
    reduced (quasi-steady) model, A11 - A12 A22^-1 A21, is the design model again."""
    vx = 20.0
    J, Bf, _ = linearise_relaxed(plant(), vx)  # sigma = 0.5 m
    A11, A12, A21, A22 = J[:4, :4], J[:4, 4:], J[4:, :4], J[4:, 4:]
    Ared = A11 - A12 @ np.linalg.solve(A22, A21)
    Bred = Bf[:4] - A12 @ np.linalg.solve(A22, Bf[4:])
    T = np.diag([vx, 1.0, 1.0, 1.0])
    ref = model(VEH, vx)
    assert_close(np.linalg.inv(T) @ Ared @ T, ref.A, rtol=1e-6)
    assert_close(np.linalg.inv(T) @ Bred, ref.B[:, 0], rtol=1e-6)
    # tire lag: dF/dt = (vx/sigma)(F_ss - F): diagonal -vx/sigma
    np.testing.assert_allclose(np.diag(A22), -vx / 0.5, rtol=1e-9)


@pytest.mark.parametrize("vx, scale_f, scale_r, sigma", [(8.0, 1.0, 1.0, 0.5), (20.0, 0.8, 1.2, 0.5),
                                                       (35.0, 1.1, 0.9, 0.3)])
def test_linearisation_with_relaxation_equals_the_relaxed_design_model(vx, scale_f, scale_r, sigma):
    """CarPlant's 8 states (four relaxed wheel forces) at straight driving, aggregated to the axles
    (beta = vy / vx, Ff = (Fy_fl + Fy_fr) / (m g), Fr = (Fy_rl + Fy_rr) / (m g)), are paper 000's model with relaxed axle
    forces (``relaxed_lpv_coefficients``): the aggregation is exact (the two wheels of an axle obey
    the same equation there), so Pi J = A Pi, Pi b = B for the Jacobians J, b of the plant."""
    J, *cols = linearise_relaxed(plant(sigma=sigma, scale_f=scale_f, scale_r=scale_r), vx)
    Pi = np.zeros((6, 8))
    Pi[0, 0] = 1.0 / vx
    Pi[1, 1] = Pi[2, 2] = Pi[3, 3] = 1.0
    Pi[4, 4] = Pi[4, 5] = Pi[5, 6] = Pi[5, 7] = 1.0 / (P["m"] * G)    # the model's forces per m g
    ref = evaluate(relaxed_lpv_coefficients(VEH.with_values(sigma=sigma), scale_f * P["Cf"], scale_r * P["Cr"]), vx)
    R = np.linalg.pinv(Pi)                       # x_plant = R x_model on the aggregated subspace
    assert_close(Pi @ J @ R, ref.A, rtol=1e-6)
    # exact aggregation (to the central differences' error, ~1e-8 of the largest entry)
    assert np.max(np.abs(Pi @ J - ref.A @ Pi)) <= 1e-7 * np.max(np.abs(ref.A))
    assert_close(Pi @ cols[0], ref.B[:, 0], rtol=1e-6)
    assert_close(Pi @ cols[1], ref.F[:, 0], rtol=1e-6)


# ------------------------------------------------------------------------------------------
# tire, loads and geometry
# ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("mu", [1.0, 0.8, 0.3, 0.1])
def test_tire_linear_stiffness_is_half_axle_stiffness_for_any_mu(mu):
    p = plant(mu=mu, sigma=0.0, scale_f=0.9, scale_r=1.1)
    a = 1e-6
    # straight driving, pure lateral velocity: slip -atan(vy/vx) on every wheel, nominal loads
    vx = 20.0
    d = p.tire_state(x=[-a * vx, 0.0, 0.0, 0.0], u={"delta": 0.0, "vx": vx, "bank_angle": 0.0})
    F = np.array(d["F"])
    # the lateral load transfer of the resulting ay moves load left/right; Fy is proportional
    # to Fz at a given slip, so the axle sum is the nominal-load value: 2 * (C_axle/2) * slip
    np.testing.assert_allclose((F[0] + F[1]) / math.atan(a), 0.9 * P["Cf"], rtol=1e-6)
    np.testing.assert_allclose((F[2] + F[3]) / math.atan(a), 1.1 * P["Cr"], rtol=1e-6)
    # and per wheel at exactly nominal load (relaxation plant, force states 0 -> no transfer)
    q = plant(mu=mu, scale_f=0.9, scale_r=1.1)
    eps = 1e-7
    for j, Ca in ((4, 0.9 * P["Cf"]), (5, 0.9 * P["Cf"]), (6, 1.1 * P["Cr"]), (7, 1.1 * P["Cr"])):
        dp = q.derivatives([-eps * vx, 0, 0, 0, 0, 0, 0, 0], {"delta": 0.0, "vx": vx, "bank_angle": 0.0})
        k = vx / 0.5                     # relaxation rate: dF/dt = k (Fy_ss - F), F = 0
        assert dp[j] / k / math.atan(eps) == pytest.approx(Ca / 2, rel=1e-6)


@pytest.mark.parametrize("mu", [1.0, 0.3])
def test_tire_force_peak_is_mu_times_load(mu):
    p = plant(mu=mu, sigma=0.0)
    vx = 20.0
    peaks = np.zeros(4)
    for beta in np.linspace(0.0, 0.6, 601):
        d = p.tire_state(x=[-math.tan(beta) * vx, 0.0, 0.0, 0.0],
                         u={"delta": 0.0, "vx": vx, "bank_angle": 0.0})
        peaks = np.maximum(peaks, np.array(d["F"]) / np.array(d["Fz"]))
    # C = 1.3 >= 1: the sine reaches 1, so the peak is mu (to the slip grid resolution)
    np.testing.assert_allclose(peaks, mu, rtol=1e-4)


def test_vertical_loads():
    p = plant()
    m, lf, lr, t = P["m"], P["lf"], P["lr"], P["track"]
    L = lf + lr
    u = {"delta": 0.0, "vx": 20.0, "bank_angle": 0.1}
    # static, on the bank: m g cos(phi_r) l_other / (2L)
    d = p.tire_state(x=[0.0] * 8, u=u)
    np.testing.assert_allclose(d["Fz"], np.array([lr, lr, lf, lf]) * m * G * math.cos(0.1) / (2 * L))
    # braking loads the front axle: m ax h_cg / (2L) per wheel
    d = p.tire_state(x=[0.0] * 8, u=u, ax=-5.0)
    dx = m * 5.0 * (P["h_rc"] + P["hr"]) / (2 * L)
    np.testing.assert_allclose(d["Fz"], np.array([lr, lr, lf, lf]) * m * G * math.cos(0.1) / (2 * L)
                               + np.array([dx, dx, -dx, -dx]))
    # roll to the right (phi > 0) and left forces: the right wheels gain load
    F = [1000.0, 1000.0, 800.0, 800.0]
    phi, phid = 0.02, 0.1
    d = p.tire_state(x=[0.0, 0.0, phi, phid] + F, u={"delta": 0.0, "vx": 20.0, "bank_angle": 0.0})
    ay = sum(F) / m
    Mroll = P["Kr"] * phi + P["br"] * phid
    dFf = (m * lr / L * ay * P["h_rc"] + P["roll_share_f"] * Mroll) / t
    dFr = (m * lf / L * ay * P["h_rc"] + (1 - P["roll_share_f"]) * Mroll) / t
    Wf, Wr = m * G * lr / (2 * L), m * G * lf / (2 * L)
    np.testing.assert_allclose(d["Fz"], [Wf - dFf, Wf + dFf, Wr - dFr, Wr + dFr])
    # extreme roll: loads clamped at 0, total weight conserved
    d = p.tire_state(x=[0.0, 0.0, 0.5, 5.0] + F, u={"delta": 0.0, "vx": 20.0, "bank_angle": 0.2},
                     ax=-15.0)
    assert min(d["Fz"]) >= 0.0
    assert d["Fz"][0] == 0.0 and d["Fz"][2] == 0.0
    np.testing.assert_allclose(sum(d["Fz"]), m * G * math.cos(0.2))


def test_two_track_yaw_moment_and_lateral_force():
    """Front forces rotate with delta; moment = x Fy_body - y Fx_body summed over the wheels."""
    p = plant()  # relaxation: the forces are states
    delta = 0.3
    F = [3000.0, 1000.0, 2000.0, 2500.0]
    lf, lr, t2 = P["lf"], P["lr"], P["track"] / 2
    pos = [(lf, t2), (lf, -t2), (-lr, t2), (-lr, -t2)]
    ang = [delta, delta, 0.0, 0.0]
    Mz = Sy = 0.0
    for (xw, yw), a, f in zip(pos, ang, F):
        fx, fy = -f * math.sin(a), f * math.cos(a)
        Mz += xw * fy - yw * fx
        Sy += fy
    u = {"delta": delta, "vx": 20.0, "bank_angle": 0.0}
    d = p.derivatives([0.0] * 4 + F, u)
    assert d[1] == pytest.approx(Mz / P["Iz"], rel=1e-12)
    aux = p.tire_state(x=[0.0] * 4 + F, u=u)
    assert aux["S"] == pytest.approx(Sy, rel=1e-12)
    # roll first, then lateral: phi'' = hr S / Ix at phi = 0; vy' = S/m + hr phi''
    assert d[3] == pytest.approx(P["hr"] * Sy / P["Ix"], rel=1e-12)
    assert d[0] == pytest.approx(Sy / P["m"] + P["hr"] ** 2 * Sy / P["Ix"], rel=1e-12)


def test_slip_angles_two_track():
    p = plant(sigma=0.0)
    vy, r, vx, delta = 0.3, 0.2, 15.0, 0.05
    lf, lr, t2 = P["lf"], P["lr"], P["track"] / 2
    d = p.tire_state(x=[vy, r, 0.0, 0.0], u={"delta": delta, "vx": vx, "bank_angle": 0.0})
    af = [delta - math.atan2(vy + r * lf, vx - r * yw) for yw in (t2, -t2)]
    ar = [-math.atan2(vy - r * lr, vx - r * yw) for yw in (t2, -t2)]
    assert d["alpha_f"] == pytest.approx(sum(af) / 2, rel=1e-12)
    assert d["alpha_r"] == pytest.approx(sum(ar) / 2, rel=1e-12)


# ------------------------------------------------------------------------------------------
# steady states
# ------------------------------------------------------------------------------------------
def test_small_step_steer_steady_state_matches_linear_model():
    vx, delta = 20.0, 0.005
    p = plant()  # relaxation on
    t, y = simulate(p, 8.0, lambda t: {"delta": delta, "vx": vx, "bank_angle": 0.0})
    ref = model(VEH, vx)
    xss = -np.linalg.solve(ref.A, ref.B[:, 0] * delta)
    assert y["yaw_rate"][-1] == pytest.approx(xss[1], rel=0.01)
    assert y["beta"][-1] == pytest.approx(xss[0], rel=0.02)
    assert y["roll_angle"][-1] == pytest.approx(xss[2], rel=0.02)
    # steady turn: ay = vx r exactly (E2 with vy' = phi'' = 0), left turn rolls right
    assert y["ay"][-1] == pytest.approx(vx * y["yaw_rate"][-1], rel=1e-4)
    assert y["roll_angle"][-1] > 0 and y["yaw_rate"][-1] > 0
    # understeer gradient form of the same steady state
    m, lf, lr, Cf, Cr = P["m"], P["lf"], P["lr"], P["Cf"], P["Cr"]
    K = m * (lr * Cr - lf * Cf) / ((lf + lr) * Cf * Cr)
    assert xss[1] == pytest.approx(vx * delta / (lf + lr + K * vx ** 2), rel=1e-9)


@pytest.mark.parametrize("mu", [0.3, 1.0])
@pytest.mark.parametrize("sigma", [0.5, 0.0])
def test_saturation_bounds_lateral_acceleration(mu, sigma):
    p = plant(mu=mu, sigma=sigma)
    t, y = simulate(p, 5.0, lambda t: {"delta": 0.25, "vx": 20.0, "bank_angle": 0.0})
    peak = np.abs(y["ay"]).max()
    assert peak <= mu * G * 1.02
    assert peak >= 0.8 * mu * G          # the test really reaches the limit
    assert np.all(np.isfinite(np.column_stack(list(y.values()))))


def test_bank_straight_driving_settles_where_physics_says():
    """delta = 0 on a constant bank phi_r: gravity pushes the car down the slope (-y). The tires
    take up the push, and at steady state (vy' = r' = phi'' = 0) E2 gives
    S/m = g sin(phi_r) + vx r: the accelerometer reads g sin(phi_r) plus the centripetal part of
    the yaw the push induces. The sedan understeers (lr Cr > lf Cf): the push acts ahead of the
    neutral steer point, so the car yaws down the slope (r < 0) and ay < g sin(phi_r). Its
    steady state is the design model's -A^-1 F phi_r. A neutral-steer car (lf Cf = lr Cr)
    drifts without yawing and reads ay = g sin(phi_r) exactly."""
    vx, phir = 20.0, 0.05
    u = lambda t: {"delta": 0.0, "vx": vx, "bank_angle": phir}
    p = plant()
    t, y = simulate(p, 10.0, u)
    ref = model(VEH, vx)
    xss = -np.linalg.solve(ref.A, ref.F[:, 0] * phir)
    r = y["yaw_rate"][-1]
    assert r < 0 and y["beta"][-1] < 0                        # downhill drift and yaw
    assert r == pytest.approx(xss[1], rel=0.01)
    assert y["beta"][-1] == pytest.approx(xss[0], rel=0.01)
    d = p.derivatives(p.x, {"delta": 0.0, "vx": vx, "bank_angle": phir})
    assert max(abs(v) for v in d[:4]) < 1e-6                   # settled
    assert y["ay"][-1] == pytest.approx(G * math.sin(phir) + vx * r, rel=1e-6)
    assert 0 < y["ay"][-1] < G * math.sin(phir)

    neutral = plant(scale_r=P["lf"] * P["Cf"] / (P["lr"] * P["Cr"]))
    t, y = simulate(neutral, 10.0, u)
    assert abs(y["yaw_rate"][-1]) < 1e-3 * abs(r)
    assert y["ay"][-1] == pytest.approx(G * math.sin(phir), rel=1e-3)
    # the drift: total stiffness times the slip balances the gravity component
    Ca0 = P["Cf"] + P["lf"] * P["Cf"] / P["lr"]
    assert y["beta"][-1] == pytest.approx(-P["m"] * G * math.sin(phir) / Ca0, rel=0.01)


# ------------------------------------------------------------------------------------------
# robustness
# ------------------------------------------------------------------------------------------
def _delta_for_ay(vx, ay=4.0):
    m, lf, lr, Cf, Cr = P["m"], P["lf"], P["lr"], P["Cf"], P["Cr"]
    K = m * (lr * Cr - lf * Cf) / ((lf + lr) * Cf * Cr)
    return ay * (lf + lr + K * vx ** 2) / vx ** 2


@pytest.mark.parametrize("vx", [5.0, 30.0, 60.0])
@pytest.mark.parametrize("kind", ["step", "sine", "severe"])
def test_stable_over_speed_range(vx, kind):
    d0 = _delta_for_ay(vx)
    if kind == "step":
        u = lambda t: {"delta": d0 if t >= 0.5 else 0.0, "vx": vx, "bank_angle": 0.0}
    elif kind == "sine":
        u = lambda t: {"delta": d0 * math.sin(2 * math.pi * 0.7 * t), "vx": vx, "bank_angle": 0.02}
    else:  # far beyond the friction limit, alternating
        u = lambda t: {"delta": 0.15 * (1 if int(t) % 4 < 2 else -1), "vx": vx, "bank_angle": 0.0}
    p = plant()
    t, y = simulate(p, 10.0, u)
    Y = np.column_stack(list(y.values()))
    assert np.all(np.isfinite(Y))
    assert np.abs(y["ay"]).max() <= 1.05 * G
    assert np.abs(y["roll_angle"]).max() < 0.3
    assert np.abs(y["yaw_rate"]).max() < 3.0
    spun = np.abs(y["alpha_r"]).max() > CarPlantModel.ALPHA_SPIN
    assert spun == any("spun out" in msg for _, msg in p.events)
    if kind == "severe":
        # beyond the limit the car may spin; with prescribed vx it then slides on (documented
        # validity limit): vy grows at most like (mu g + vx |r|) t
        assert np.abs(y["vy"]).max() < (G + vx * 3.0) * 10.0
    else:
        # |beta| <= the kinematic sideslip lr ay / vx^2 of the turn plus the tire part
        assert not spun and np.abs(y["beta"]).max() < P["lr"] * 4.0 / vx ** 2 + 0.05
    if kind == "step":  # settles to the nonlinear steady state: ay close to the 4 m/s^2 target
        assert y["ay"][-1] == pytest.approx(4.0, rel=0.15)
        assert abs(y["ay"][-1] - y["ay"][-200]) < 1e-3


@pytest.mark.parametrize("vx", [0.0, 0.01, 0.5])
def test_near_zero_speed_is_finite(vx):
    p = plant()
    q = plant(sigma=0.0)
    for pl in (p, q):
        t, y = simulate(pl, 3.0, lambda t: {"delta": 0.3 * math.sin(3 * t), "vx": vx, "bank_angle": 0.05})
        assert np.all(np.isfinite(np.column_stack(list(y.values()))))
        assert np.abs(y["vy"]).max() < 2.0
        assert np.abs(y["yaw_rate"]).max() < 2.0
    assert any("below" in msg for level, msg in p.events)


@pytest.mark.parametrize("sigma", [0.5, 0.0])
def test_standstill_on_a_bank_with_steered_wheels(sigma):
    """vx = 0: steered wheels must not make the car yaw, the tires hold it on the bank
    (ay = g sin(phi_r): the road-plane accelerometer reads the gravity component), and it
    creeps downhill only at about m g sin(phi_r) V_SLIP_MIN / (Cf + Cr)."""
    phir = 0.05
    p = plant(sigma=sigma)
    t, y = simulate(p, 5.0, lambda t: {"delta": 0.3, "vx": 0.0, "bank_angle": phir})
    creep = P["m"] * G * math.sin(phir) * CarPlantModel.V_SLIP_MIN / (P["Cf"] + P["Cr"])
    assert abs(y["yaw_rate"][-1]) < 0.005
    assert -3 * creep < y["vy"][-1] < 0
    assert y["ay"][-1] == pytest.approx(G * math.sin(phir), rel=0.02)


def test_extreme_inputs_never_raise_and_warn_once():
    p = plant()
    for u in ({"delta": 1e6, "vx": -5.0, "bank_angle": -1e3}, {"delta": -3.0, "vx": 1e9, "bank_angle": 2.0},
              {"delta": 0.0, "vx": 20.0, "bank_angle": 0.0}, {"delta": 2.0, "vx": 20.0, "bank_angle": 0.0},
              {"delta": 0.0, "vx": 20.0, "bank_angle": 0.0}):
        for _ in range(20):
            p.step(0.01, u)
            assert all(math.isfinite(v) for v in p.y.values())
    levels = [lvl for lvl, _ in p.events]
    assert "error" not in levels
    msgs = [msg for _, msg in p.events]
    assert sum("delta" in m for m in msgs) == 2      # edge-triggered: once per entry into the clamp
    assert any("vx = -5.0" in m for m in msgs) and any("clamped to 100" in m for m in msgs)
    p.step(0.0, {"delta": 0.0, "vx": 20.0, "bank_angle": 0.0})   # h = 0 is a no-op


def test_substeps_and_ax_from_vx_inputs():
    """step(h) = n Heun substeps of h/n with n = ceil(h/1 ms); ax is the vx finite difference."""
    u = {"delta": 0.02, "vx": 20.0, "bank_angle": 0.01}
    a, b = plant(), plant()
    a.step(0.0047, u)
    for _ in range(5):
        b.step(0.0047 / 5, u)  # same substep (0.94 ms) -> same result, up to the ax of step 1
    np.testing.assert_allclose(a.x, b.x, rtol=1e-12, atol=1e-15)
    c = plant()
    c.step(0.01, {"delta": 0.0, "vx": 20.0, "bank_angle": 0.0})
    c.step(0.01, {"delta": 0.0, "vx": 19.9, "bank_angle": 0.0})
    assert c.ax == pytest.approx(-10.0)
    c.step(0.01, {"delta": 0.0, "vx": 10.0, "bank_angle": 0.0})
    assert c.ax == -CarPlantModel.AX_MAX


# ------------------------------------------------------------------------------------------
# construction
# ------------------------------------------------------------------------------------------
def test_defaults_and_initial_outputs():
    p = plant()
    assert p.params == {"mu": 1.0, "scale_f": 1.0, "scale_r": 1.0, "sigma": 0.5, "linear_tires": 0.0}
    assert CarPlantModel.parameter_defaults(DATA) == p.params
    assert set(p.y) == {"beta", "vy", "yaw_rate", "ay", "roll_angle", "roll_rate", "Fyf", "Fyr",
                        "alpha_f", "alpha_r", "vy_cg", "beta_cg"}
    assert all(v == 0.0 for v in p.y.values())
    assert p.x == [0.0] * 8 and len(CarPlantModel.STATE_NAMES) == 8


@pytest.mark.parametrize("params, name", [({"mu": 0.0}, "mu"), ({"mu": float("nan")}, "mu"),
                                          ({"scale_f": -1.0}, "scale_f"), ({"scale_r": 0.0}, "scale_r"),
                                          ({"sigma": float("inf")}, "sigma"), ({"foo": 1.0}, "foo")])
def test_invalid_parameters_raise_naming_them(params, name):
    with pytest.raises(ValueError, match=name):
        CarPlantModel(DATA, params)


def test_invalid_vehicle_data_raise_naming_the_parameter():
    d = VEH.as_dict()
    del d["parameters"]["h_rc"]
    with pytest.raises(ValueError, match="h_rc"):
        CarPlantModel({"vehicle": d}, {})
    d = VEH.as_dict()
    d["parameters"]["Kr"]["value"] = float("nan")
    with pytest.raises(ValueError, match="Kr"):
        CarPlantModel({"vehicle": d}, {})
    with pytest.raises(ValueError):
        CarPlantModel({}, {})


def test_speed_of_one_step():
    """Informational: CPU time of one 5 ms step (5 Heun substeps); not asserted."""
    p = plant()
    u = {"delta": 0.02, "vx": 20.0, "bank_angle": 0.0}
    t0 = time.process_time()
    for _ in range(200):
        p.step(0.005, u)
    per = (time.process_time() - t0) / 200
    print(f"CarPlant: {per * 1e6:.0f} us CPU per 5 ms step")
