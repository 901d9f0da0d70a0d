"""Paper-003 observer runtime (pure Python, eq. (13)) against independent scipy integrations."""
from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.linalg
from scipy.integrate import solve_ivp

from latobs.fmu_src.motorcycle_fault_observer import MotorcycleFaultObserver, step_map
from latobs.synthesis.tables import motorcycle_fault_observer as mft
from latobs.synthesis import motorcycle_fault_observer as ps
from latobs.synthesis.params import load_vehicle
from latobs.validation.scenarios import SCENARIOS

H = 0.01  # s, communication step
VEHICLE = load_vehicle("sharp_motorcycle")


@pytest.fixture(scope="module")
def d003(built_fmus) -> dict:
    return built_fmus.design("MotorcycleFaultObserverPaper")   # the session build's design (conftest.py)


def _observer_matrices(mode: dict):
    """Eq. (13) as s' = M s + G y, s = [x^; f^], written from the design file's matrices here."""
    A, Ef, C = (np.asarray(mode["model"][k], float) for k in ("A", "E_f", "C"))
    LP, LI = (np.asarray(mode["gains"][k], float) for k in ("L_P", "L_I"))
    M = np.block([[A - LP @ C, Ef], [-LI @ C, np.zeros((2, 2))]])
    return M, np.vstack([LP, LI])


def _u(vx, y):
    return {"vx": float(vx), "steer_angle": float(y[0]), "yaw_rate": float(y[1]), "roll_rate": float(y[2])}


def _measurements(t):
    """Arbitrary smooth signals for y = [steer angle, yaw rate, roll rate] (the runtime is linear in y)."""
    return np.array([0.01 * math.sin(1.1 * t) + 0.004 * math.sin(5.3 * t), 0.2 * math.sin(0.7 * t + 0.3),
                     0.3 * math.cos(1.9 * t)])


def test_runtime_equals_solve_ivp_of_eq13_through_mode_switches(d003):
    """The runtime against solve_ivp (Radau, tight tolerances) of eq. (13) with y held over each
    step and the mode of the speed (paper profile 12 -> 20 -> 10 m/s, three modes)."""
    rt = MotorcycleFaultObserver(d003)
    mats = [_observer_matrices(m) for m in d003["modes"]]
    ts = np.arange(0.0, 16.0, H)
    speed = SCENARIOS["motorcycle-lane-change"].speed        # the paper's profile, 12 -> 20 -> 10 m/s
    seq = ps.modes_of_speed(d003, ts, speed(ts))
    y0 = _measurements(0.0)
    rt.initialize(_u(float(speed(np.array([0.0]))[0]), y0))
    s = np.concatenate([np.asarray(d003["modes"][0]["model"]["C"]).T @ y0, np.zeros(2)])   # x^(0) = C' y(0)
    err, scale, modes_seen = 0.0, 0.0, set()
    for k, (t, mode) in enumerate(seq):
        y = _measurements(t)
        rt.step(H, _u(float(speed(np.array([t]))[0]), y))
        assert rt.y["mode"] == mode
        modes_seen.add(mode)
        M, G = mats[mode - 1]
        if k < 200 or k % 20 == 0:       # solve_ivp on part of the steps, the exact map (scipy) on all
            sol = solve_ivp(lambda _t, x: M @ x + G @ y, (0.0, H), s, method="Radau", rtol=1e-11, atol=1e-13)
            s_ref = sol.y[:, -1]
        E = scipy.linalg.expm(np.block([[M * H, G * H], [np.zeros((3, 10))]]))
        s_exact = E[:7, :7] @ s + E[:7, 7:] @ y
        if k < 200 or k % 20 == 0:
            assert np.allclose(s_exact, s_ref, rtol=1e-7, atol=1e-9 * max(1.0, np.abs(s_ref).max()))
        s = s_exact
        got = np.array([rt.y[n] for n in ("vy_hat", "steer_rate_hat", "roll_angle_hat", "rider_torque_hat")])
        want = s[[0, 4, 5, 6]]
        err = max(err, float(np.max(np.abs(got - want))))
        scale = max(scale, float(np.max(np.abs(want))))
        C = np.asarray(d003["modes"][mode - 1]["model"]["C"])
        assert rt.y["residual_norm"] == pytest.approx(float(np.linalg.norm(y - C @ s[:5])), rel=1e-6, abs=1e-12)
        Hx, Hphi = (np.asarray(d003["modes"][mode - 1]["model"][k_], float) for k_ in ("H_x", "H_phi"))
        assert rt.y["Ff_hat"] == pytest.approx(float(Hx[0] @ s[:5] + Hphi[0] * s[5]), rel=1e-8, abs=1e-8)
        assert rt.y["Fr_hat"] == pytest.approx(float(Hx[1] @ s[:5] + Hphi[1] * s[5]), rel=1e-8, abs=1e-8)
    assert modes_seen == {1, 2, 3}
    assert err <= 1e-9 * max(scale, 1.0)


def test_step_map_equals_scipy_expm(d003):
    for mode in d003["modes"]:
        M, G = _observer_matrices(mode)
        for h in (1e-4, 1e-3, 0.01, 0.05):
            E = scipy.linalg.expm(np.block([[M * h, G * h], [np.zeros((3, 10))]]))
            W = np.asarray(step_map(M.tolist(), G.tolist(), h))
            assert np.max(np.abs(W - E[:7])) <= 1e-11 * max(1.0, np.abs(E[:7]).max())


def _truth(vx: float, f_of_t, T: float):
    """The reduced model (Gamma = 0) at the grid speed, driven by phi(t), tau(t), sampled every H."""
    from latobs.synthesis.motorcycle_model import reduced_model

    m = reduced_model(VEHICLE, vx)
    A, Ef = np.asarray(m.A), np.column_stack([np.ravel(m.E_phi), np.ravel(m.B_tau)])
    ts = np.arange(0.0, T + 1e-12, H)
    sol = solve_ivp(lambda t, x: A @ x + Ef @ f_of_t(t), (0.0, T), np.zeros(5), t_eval=ts, method="Radau",
                    rtol=1e-10, atol=1e-12, max_step=0.05)
    return ts, sol.y.T, np.asarray(m.C), np.asarray(m.H_x), np.ravel(m.H_phi)


@pytest.mark.parametrize("mode_index", [1, 3, 5])
def test_constant_roll_and_torque_are_estimated_without_bias(d003, mode_index):
    """On the design model itself (Gamma = 0, xi = 0), constant phi and tau: x~ -> 0 (eq. 15), so the
    estimates converge to the truth with zero bias, at the speed of the slowest observer pole."""
    vx = d003["modes"][mode_index - 1]["vx"]
    phi, tau = 0.15, 8.0
    T = 12.0
    ts, X, C, Hx, Hphi = _truth(vx, lambda t: np.array([phi, tau]), T)
    rt = MotorcycleFaultObserver(d003)
    for t, x in zip(ts, X):
        rt.step(H, _u(vx, C @ x))
    slow = max(d003["modes"][mode_index - 1]["poles"]["re"])
    decay = math.exp(slow * (T - 1.0))           # what is left of the initial error, with margin
    assert rt.y["mode"] == mode_index
    assert rt.y["roll_angle_hat"] == pytest.approx(phi, abs=max(1e-6, 50 * decay * phi))
    assert rt.y["rider_torque_hat"] == pytest.approx(tau, abs=max(1e-4, 50 * decay * tau))
    x_end = X[-1]
    assert rt.y["vy_hat"] == pytest.approx(x_end[0], abs=1e-3 + 50 * decay)
    F = Hx @ x_end + Hphi * phi
    assert rt.y["Ff_hat"] == pytest.approx(F[0], abs=1e-3 * abs(F[0]) + 1.0)
    assert rt.y["Fr_hat"] == pytest.approx(F[1], abs=1e-3 * abs(F[1]) + 1.0)
    assert rt.y["residual_norm"] < 1e-4


def test_time_varying_inputs_are_tracked(d003):
    """A rider-torque pulse and a slowly varying roll angle at 20 m/s: the PI observer (f assumed
    constant) tracks them with a lag; errors stay a fraction of the signals."""
    vx = 20.0
    phi = lambda t: 0.1 * math.sin(0.4 * t)
    tau = lambda t: 10.0 * math.exp(-((t - 6.0) / 1.0) ** 2)
    ts, X, C, *_ = _truth(vx, lambda t: np.array([phi(t), tau(t)]), 12.0)
    rt = MotorcycleFaultObserver(d003)
    e_phi, e_tau = [], []
    for t, x in zip(ts, X):
        rt.step(H, _u(vx, C @ x))
        if t > 3.0:
            e_phi.append(rt.y["roll_angle_hat"] - phi(t + H))
            e_tau.append(rt.y["rider_torque_hat"] - tau(t + H))
    # measured with the default design (alpha = 5, radius = 150): max |e_phi| ~ 0.007 rad, max |e_tau| ~ 1.25 N m
    assert max(map(abs, e_phi)) < 0.2 * 0.1
    assert max(map(abs, e_tau)) < 0.25 * 10.0


def test_mode_switch_keeps_the_state_and_hysteresis(d003):
    rt = MotorcycleFaultObserver(d003)
    y = np.array([0.01, 0.1, -0.05])
    for _ in range(50):
        rt.step(H, _u(10.0, y))
    assert rt.y["mode"] == 1
    before = list(rt.s)
    rt.step(H, _u(15.0, y))                           # switch to mode 2: same state, mode 2's map
    M, G = _observer_matrices(d003["modes"][1])
    E = scipy.linalg.expm(np.block([[M * H, G * H], [np.zeros((3, 10))]]))
    assert rt.y["mode"] == 2
    assert np.allclose(rt.s, E[:7, :7] @ before + E[:7, 7:] @ y, rtol=1e-10, atol=1e-12)
    # hysteresis 0.5 m/s around the band edge 12.5 m/s
    for vx, want in ((12.2, 2), (12.01, 2), (11.99, 1), (12.9, 1), (13.01, 2), (7.0, 1), (40.0, 5), (27.2, 5),
                     (26.9, 4)):
        rt.step(H, _u(vx, y))
        assert rt.y["mode"] == want, vx


def test_the_start_takes_the_band_of_the_initial_speed(d003):
    """At the start no mode is active, so no hysteresis applies: a start just above a band edge
    (within the hysteresis of the band below) takes the band it is in, as the first step does, and
    the first step runs that mode's map (the bug was: 12.5-13 m/s took the 10 m/s mode)."""
    edges = d003["tables"]["edges"]
    hyst = d003["tables"]["hysteresis"]
    y = np.array([0.01, 0.1, -0.05])
    for k, e in enumerate(edges[1:-1]):
        for vx in (e, e + 0.5 * hyst, math.nextafter(e, -math.inf), e - 0.5 * hyst):
            want = k + 2 if vx >= e else k + 1
            rt = MotorcycleFaultObserver(d003)
            rt.initialize(_u(vx, y))
            assert rt.y["mode"] == want, (e, vx)
            first = MotorcycleFaultObserver(d003)
            first.step(H, _u(vx, y))                   # started by its first step
            assert first.y["mode"] == want, (e, vx)
            M, G = _observer_matrices(d003["modes"][want - 1])
            E = scipy.linalg.expm(np.block([[M * H, G * H], [np.zeros((3, 10))]]))
            assert np.allclose(first.s, E[:7, :7] @ rt.s + E[:7, 7:] @ y, rtol=1e-10, atol=1e-12)


def test_clamps_and_warnings(d003):
    rt = MotorcycleFaultObserver(d003)
    y = np.array([0.0, 0.1, 0.0])
    rt.step(H, _u(40.0, y))
    assert rt.y["mode"] == 5 and len(rt.events) == 1 and "outside the design grid" in rt.events[0][1]
    rt.events.clear()
    rt.step(H, _u(41.0, y))
    assert not rt.events                              # one warning per excursion
    rt.step(H, _u(30.0, y))
    rt.step(H, _u(35.0, y))
    assert len(rt.events) == 1
    rt.events.clear()
    frozen = list(rt.s)
    rt.step(H, _u(0.3, y))
    rt.step(H, _u(-0.2, y))
    assert rt.s == frozen and len(rt.events) == 1 and "frozen" in rt.events[0][1]
    rt.step(H, _u(-20.0, y))                          # backwards: the nearest (first) mode, a warning
    assert rt.y["mode"] == 1 and any("resumes" in m for _, m in rt.events)
    assert all(math.isfinite(v) for v in rt.y.values())


def test_initialize_from_the_first_measurement(d003):
    rt = MotorcycleFaultObserver(d003, {"vx_hold": 2.0})
    y = np.array([0.02, 0.3, -0.1])
    rt.initialize(_u(21.0, y))
    assert rt.y["mode"] == 3 and rt.vx_hold == 2.0
    assert rt.s == pytest.approx([0.0, 0.3, -0.1, 0.02, 0.0, 0.0, 0.0])
    assert rt.y["residual_norm"] == 0.0 and rt.y["roll_angle_hat"] == 0.0


def test_bad_design_file_is_rejected(d003):
    import copy

    bad = copy.deepcopy(d003)
    bad["modes"][0]["gains"]["L_P"][0][0] = float("nan")
    with pytest.raises(ValueError, match="non-finite"):
        mft.compute(bad)
    bad = copy.deepcopy(d003)
    del bad["switching"]
    with pytest.raises(ValueError, match="switching"):
        mft.compute(bad)
    del bad["tables"]
    with pytest.raises(ValueError, match="tables"):
        MotorcycleFaultObserver(bad)


def test_fmu_equals_the_runtime_and_refuses_non_finite_inputs(d003, tmp_path):
    """The packaged FMU (fmpy) gives the runtime's numbers; a non-finite input is refused by the
    framework (fmi2Discard), the state is held and the FMU recovers."""
    from latobs import packaging
    from latobs.synthesis import design_file
    from latobs.validation.harness import FmuInstance

    path = packaging.package_design(design_file.write(d003, tmp_path), tmp_path)
    assert path.name == "MotorcycleFaultObserverPaper.fmu"

    def u_of(k):
        t = k * H
        return _u(12.0 + 2.0 * t, _measurements(t))

    rt = MotorcycleFaultObserver(d003)
    rt.initialize(u_of(0))
    fmu = FmuInstance("M", path)
    fmu.start(u_of(0))
    try:
        for k in range(400):                       # 12 -> 20 m/s: modes 1, 2, 3
            rt.step(H, u_of(k))
            fmu.set_inputs(u_of(k))
            fmu.slave.doStep(k * H, H)
            got = fmu.get_outputs()
            assert max(abs(got[n] - rt.y[n]) for n in rt.y) <= 1e-12 * max(1.0, max(abs(v) for v in rt.y.values()))
        assert got["mode"] == 3
        before = fmu.get_outputs()
        fmu.set_inputs(dict(u_of(400), roll_rate=math.nan))
        with pytest.raises(Exception, match="discard"):
            fmu.slave.doStep(400 * H, H)
        assert fmu.get_outputs() == before
        fmu.set_inputs(u_of(400))
        fmu.slave.doStep(400 * H, H)
        assert all(math.isfinite(v) for v in fmu.get_outputs().values())
    finally:
        fmu.close()
    assert any("non-finite input(s) roll_rate" in m for m in fmu.logs)
