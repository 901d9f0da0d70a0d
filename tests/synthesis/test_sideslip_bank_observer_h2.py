"""The robust-H2 gains of paper 000's default observer (``synthesis.sideslip_bank_observer_h2``): its
[x; e_a] system is the one a simulation of the paper's observer equations beside an independent car
gives; the certificate re-evaluates the H2 bound and refuses tampered numbers; bad options are named."""
from __future__ import annotations

import copy

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import linear_plant_000 as lp
from latobs.synthesis import certificate
from latobs.synthesis import sideslip_bank_observer_h2 as h2
from latobs.synthesis.params import load_vehicle


@pytest.fixture(scope="module")
def solved() -> h2.H2Design:
    return h2.design(load_vehicle("sedan"), h2.H2Options(name="SideslipBankObserver", switching="speed"))


def _failed(d: dict) -> list[str]:
    ok, checks = certificate.certify(d)
    return [c.name for c in checks if not c.passed]


@pytest.mark.parametrize("vx, scale", [(9.0, (0.9, 1.1)), (17.0, (1.1, 0.9)), (26.0, (1.05, 1.0))])
def test_the_error_system_is_the_observer_beside_an_independent_car(solved, vx, scale):
    """The design's [x; e_a] system (``closed_loop``) against a direct simulation of the paper's observer
    (x^ = z + N y, z' = T (A x^ + B delta + F w^) + K_P (y - C x^), w^' = K_I (y - C x^), eq. 5-7 and 17)
    reading y = C x + n from the sympy-derived car of ``linear_plant_000`` (its axle forces relaxed, as
    the design's model) with its stiffnesses scaled:
    the beta and bank errors agree along the whole run (steering, a bank ramp and smooth sensor
    'noise' as inputs, the inputs the system's B names)."""
    veh = load_vehicle("sedan")
    i = [k for k, m in enumerate(solved.modes) if m.model_range[0] <= vx <= m.model_range[1]][0]
    params = veh.require(("m", "Iz", "Ix", "lf", "lr", "hr", "Kr", "br", "sigma"), "test")
    car = lp.relaxed_model({**params, "Cf": scale[0] * veh.Cf, "Cr": scale[1] * veh.Cr}, vx)
    A, B, F = h2._at(solved.modes[i].coeffs, (vx, 1 / vx, 1 / vx**2))
    n = A.shape[0]
    T, N, C = solved.T, solved.N, solved.C
    KP, KI = solved.K_P[i], solved.K_I[i]
    wd, wo, *wn = solved.options.h2_input_weights
    steer = lambda t: 0.02 * np.sin(2.1 * t) + 0.01 * np.sin(5.3 * t)       # rad
    bank_rate = lambda t: 0.02 * np.cos(0.7 * t)                             # rad/s
    noise = lambda t: np.array([2e-3 * np.sin(9 * t), 1e-3 * np.cos(4 * t), 3e-3 * np.sin(13 * t)])

    def direct(t, s):
        x, bank, z, wh = s[:n], s[n], s[n + 1:2 * n + 1], s[2 * n + 1]
        y = C @ x + noise(t)
        xh = z + N @ y
        return np.concatenate([car[0] @ x + car[1][:, 0] * steer(t) + car[2][:, 0] * bank, [bank_rate(t)],
                               T @ (A @ xh + B[:, 0] * steer(t) + F[:, 0] * wh) + KP @ (y - C @ xh), KI @ (y - C @ xh)])

    Abig, Bbig, Cz = h2.closed_loop(solved, i, h2.brm.relaxed_lpv_coefficients(veh, scale[0] * veh.Cf,
                                                                                scale[1] * veh.Cr),
                                    (vx, 1 / vx, 1 / vx**2))
    u = lambda t: np.concatenate([[steer(t) / wd, bank_rate(t) / wo], noise(t) / np.asarray(wn)])
    x0 = np.array([0.01, 0.05, 0.01, 0.0, 0.02, 0.03])
    s0 = np.concatenate([x0, [0.02], T @ x0 - np.array([0.005, 0.01, -0.002, 0.003, 0.004, -0.002]), [0.0]])  # e_a(0) != 0
    t_eval = np.linspace(0.0, 6.0, 601)
    sim = solve_ivp(direct, (0, 6), s0, t_eval=t_eval, rtol=1e-10, atol=1e-12)
    x, bank, z, wh = sim.y[:n], sim.y[n], sim.y[n + 1:2 * n + 1], sim.y[2 * n + 1]
    xh = z + N @ (C @ x + np.array([noise(t) for t in t_eval]).T)
    beta_err, bank_err = x[0] - xh[0], bank - wh
    # the design's system, from e_a(0) = [T x0 - z0; bank0 - w^0]; the bank acts on the car only through
    # F phi_r, which the design leaves out of the car (w_scale 0): drive x with the simulated bank there
    e0 = np.concatenate([T @ x0 - s0[n + 1:2 * n + 1], [s0[n] - s0[2 * n + 1]]])

    def lin(t, s):
        bk = np.interp(t, t_eval, bank)
        ds = Abig @ s + Bbig @ u(t)
        ds[:n] += car[2][:, 0] * bk
        return ds
    ref = solve_ivp(lin, (0, 6), np.concatenate([x0, e0]), t_eval=t_eval, rtol=1e-10, atol=1e-12)
    # the design's model of the car (brm) and the sympy car agree, so the car states agree too
    assert np.max(np.abs(ref.y[:n] - x)) < 1e-6 * np.max(np.abs(x))
    z_lin = Cz @ ref.y
    scale_b = np.max(np.abs(beta_err))
    assert np.max(np.abs(z_lin[0] - beta_err)) < 1e-6 * scale_b
    assert np.max(np.abs(z_lin[1] / solved.options.h2_bank_weight - bank_err)) < 1e-6 * np.max(np.abs(bank_err))


def test_the_certificate_rechecks_the_h2_bound_and_refuses_tampering(design_speed):
    d = design_speed
    assert "robust_h2" in d and d["certified"]
    names = [c["name"] for c in d["checks"] if "robust H2" in c["name"]]
    assert len(names) == 2 + 4 * len(d["modes"]), names
    tight = copy.deepcopy(d)
    tight["robust_h2"]["bound"] *= 0.9
    failed = _failed(tight)
    assert any("robust H2 bound" in n for n in failed), failed
    gains = copy.deepcopy(d)
    gains["modes"][1]["gains"]["K_P"] = (1.6 * np.asarray(gains["modes"][1]["gains"]["K_P"])).tolist()
    assert any("robust H2" in n and "mode 2" in n for n in _failed(gains))
    corners = copy.deepcopy(d)
    corners["robust_h2"]["stiffness_box"] = [0.8, 1.2]
    assert any("stiffness corners" in n for n in _failed(corners))


def test_the_certificate_refuses_vertices_that_miss_the_relaxed_models_speeds(design_speed):
    """The model with relaxed axle forces is affine in (Vx, 1/Vx): without a band's tangent corners the
    vertices no longer hold the curve (Vx, 1/Vx) (it bulges below the chords), and the coverage check of
    that band fails; read as eq. (1)'s (no first_power), its matrices are refused by their sizes."""
    d = copy.deepcopy(design_speed)
    assert d["structure"]["first_power"] == -1 and all("u" in x for x in d["lmi_vertices"])
    d["lmi_vertices"] = [x for x in d["lmi_vertices"] if not (x["mode"] == 2 and x["label"].startswith("tangent"))]
    failed = _failed(d)
    assert any(n.startswith("LMI vertices cover the model speeds: (Vx, 1/Vx)") and n.endswith("mode 2") for n in failed)
    eq1 = copy.deepcopy(design_speed)
    del eq1["structure"]["first_power"]           # the same numbers read as eq. (1)'s coefficients
    assert "design file's matrices have the sizes of its model (count wrong)" in _failed(eq1)


def test_a_vehicle_without_a_relaxation_length_is_named():
    from latobs.synthesis.params import Vehicle

    sedan = load_vehicle("sedan")
    veh = Vehicle("norelax", sedan.kind, sedan.description, sedan.source,
                  {k: v for k, v in sedan.parameters.items() if k != "sigma"}, sedan.ranges)
    with pytest.raises(ValueError, match="lacks parameter.*sigma"):
        h2.design(veh, h2.H2Options(name="SideslipBankObserver_norelax", switching="speed"))


@pytest.mark.parametrize("option, value", [("stiffness_box", (1.1, 1.2)), ("stiffness_box", (0.0, 1.0)),
                                           ("h2_input_weights", (0.05, 1.0, 0.05)),
                                           ("h2_input_weights", (0.0, 0.0, 0.0, 0.0, 0.0)),
                                           ("h2_bank_weight", float("nan")), ("faithful", True)])
def test_bad_options_are_named(option, value):
    with pytest.raises(ValueError, match=option if option != "faithful" else "faithful"):
        h2.H2Options(name="X", switching="speed", **{option: value}).validate()
