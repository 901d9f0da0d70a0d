"""SideslipKalmanFilter, paper 002's baseline peer (the MBDS authors' linear bicycle-model Kalman
filter): design file + independent certificate, and the FMU equal to the numpy filter
``sideslip_kalman_filter.run_kalman(..., estimate="predicted")`` on the whole MBDS record.

Timing: the replay (``latobs.validation.replay.drive``) initialises the FMU with row 0 and
records the outputs after doStep(t_k, dt) with row k's inputs at t_{k+1}; the FMU then outputs
x_{k+1|k} converted with v_k, exactly ``run_kalman``'s "predicted" row k + 1. The FMU steps with
the record's uniform step dt (``uniform_step``), so the numpy filter is given t_k = t_0 + k dt
(the record's own t deviates from that grid by < 1e-6 dt; the RMS figures use the record's t).
"""
from __future__ import annotations

import copy
import dataclasses
import math

import numpy as np
import pytest
import scipy.linalg
from fmpy import read_model_description

from latobs import packaging
from latobs.fmu_src.sideslip_kalman_filter import KalmanObserver
from latobs.synthesis import certificate, design_file, tables
from latobs.synthesis import sideslip_kalman_filter as kb
from latobs.synthesis.tables import sideslip_kalman_filter as kft
from latobs.synthesis.certificate.sideslip_kalman_filter import _kalman_force_model
from latobs.synthesis.params import VehicleParameterError, load_vehicle
from latobs.validation import replay as rp
from latobs.validation.harness import FmuInstance

INPUTS = ("delta", "vx", "yaw_rate", "ay")
OUTPUTS = ("beta_hat", "vy_hat", "yaw_rate_hat", "beta_filtered", "vy_filtered", "yaw_rate_filtered")


@pytest.fixture(scope="module")
def design(built_fmus):
    return built_fmus.design("SideslipKalmanFilter")     # the session build (conftest.py)


@pytest.fixture(scope="module")
def mbds():
    cols = rp.load_csv(rp.MBDS_CSV)
    return cols, kb.vehicle_dict(load_vehicle("mbds_250lm"))


@pytest.fixture(scope="module")
def built(built_fmus):
    return built_fmus.path("SideslipKalmanFilter")


@pytest.fixture(scope="module")
def fmu_run(built, mbds):
    """The FMU driven through fmpy by the whole MBDS record (as ``latobs replay`` does)."""
    cols, _ = mbds
    return rp.drive(built, cols, source="MBDS record")


@pytest.fixture(scope="module")
def reference(mbds, fmu_run):
    """run_kalman's predicted estimate on the FMU's time grid, with the design's (TUNED) noise."""
    cols, vals = mbds
    grid = dict(cols, t=cols["t"][0] + fmu_run.dt * np.arange(cols["t"].size))
    return kb.run_kalman(grid, vals, kb.TUNED["q"], kb.TUNED["r_meas"], estimate="predicted", return_states=True)


# -- design and certificate -------------------------------------------------------------------
def test_design_file_is_certified_and_complete(design, tmp_path):
    d = design
    assert d["certified"] is True and d["paper"] == "002" and d["kind"] == "kalman_baseline"
    assert d["name"] == d["design"] == "SideslipKalmanFilter"
    names = [c["name"] for c in d["checks"]]
    for part in ("Q positive semidefinite", "R positive definite", "P0 positive definite",
                 "observable from [ay, r]", "Schur stable", "stored model coefficients equal the force-balance model",
                 "stored gamma"):
        assert sum(part in n for n in names) == 1, part
    assert all(c["passed"] for c in d["checks"])
    # the certified grid: the vehicle's speed range (15..63 m/s), 50 speeds, at the MBDS rate
    mode = d["modes"][0]
    assert mode["scheduling"]["range"] == [15.0, 63.0] and len(mode["scheduling"]["certified_speeds"]) == 50
    assert d["certificate"] == {"step_s": 0.01, "n_speeds": 50}
    rho = mode["steady_state"]["spectral_radius"]
    assert d["gamma"] == max(rho) and 0.5 < d["gamma"] < 1.0
    schur = next(c for c in d["checks"] if "Schur stable" in c["name"])
    assert schur["value"] == pytest.approx(d["gamma"], rel=1e-9) and schur["limit"] == 1.0
    # CONTRACT keys; the vehicle with its name and the six parameters the filter uses
    for key in ("name", "paper", "vehicle", "modes", "gamma", "certified", "checks", "solver"):
        assert key in d
    assert set(d["solver"]) >= {"name", "status", "seconds"}
    assert d["vehicle"]["name"] == "mbds_250lm"
    assert set(d["vehicle"]["parameters"]) == set(kb.VEHICLE_KEYS)
    assert mode["gains"]["Q"] == [[0.1, 0.0], [0.0, 1e-4]] and mode["gains"]["R"] == [[10.0, 0.0], [0.0, 1e-4]]
    # written and read back, it certifies again; the runtime reads it like to_data_dict's dict
    back = design_file.read(design_file.write(d, tmp_path))
    assert certificate.certify(back)[0]
    flat_data = kb.to_data_dict(kb.vehicle_dict(load_vehicle("mbds_250lm")), kb.TUNED["q"], kb.TUNED["r_meas"])
    flat = KalmanObserver({**flat_data, "tables": kft.compute(flat_data)}, {})
    assert KalmanObserver(back, {}).model(20.0) == flat.model(20.0)


def test_design_names_the_missing_vehicle_parameter():
    veh = load_vehicle("mbds_250lm")
    no_cf = dataclasses.replace(veh, parameters={k: p for k, p in veh.parameters.items() if k != "Cf"})
    with pytest.raises(VehicleParameterError, match=r"'mbds_250lm' lacks parameter\(s\) Cf needed by the Kalman"):
        kb.design(no_cf, kb.DesignOptions(name="SideslipKalmanFilter"))
    with pytest.raises(kb.DesignError, match="r_meas must be positive definite"):
        kb.design(veh, kb.DesignOptions(name="X", r_meas=(10.0, 0.0)))
    # a vehicle without a speed range is certified on the default 5..60 m/s
    bare = dataclasses.replace(veh, ranges={})
    d = kb.design(bare, kb.DesignOptions(name="X"))
    assert d["modes"][0]["scheduling"]["range"] == list(kb.DEFAULT_SPEED_RANGE)
    assert not certificate.certify(d)[0]          # its runtime's tables are attached when it is built
    assert certificate.certify(tables.attach(d))[0]


def _failed(d):
    ok, checks = certificate.certify(d)
    assert not ok
    return [c.name for c in checks if not c.passed]


@pytest.mark.parametrize("corrupt, failing", [
    # a negative measurement variance: no stabilising Riccati solution either
    (lambda d: d["noise"].__setitem__("r", [[-1.0, 0.0], [0.0, 1e-4]]),
     ("R positive definite", "Schur stable", "Riccati equation", "Kalman filter tables: Q, R, P0")),
    (lambda d: d["noise"].__setitem__("q", [[0.1, 0.0], [0.0, -1e-4]]), ("Q positive semidefinite",)),
    (lambda d: d["initial"].__setitem__("P0", [[1.0, 2.0], [2.0, 0.01]]), ("P0 positive definite",)),
    (lambda d: d["noise"].__setitem__("r", [[10.0, 1e-3], [0.0, 1e-4]]), ("symmetric", "Kalman filter tables: Q, R, P0")),
    (lambda d: d.__setitem__("gamma", 0.5), ("stored gamma",)),
    # the vehicle edited after the design: the stored model no longer matches its derivation
    (lambda d: d["vehicle"]["parameters"]["Cf"].__setitem__("value", 0.8 * d["vehicle"]["parameters"]["Cf"]["value"]),
     ("stored model coefficients equal the force-balance model",)),
    (lambda d: d["runtime"].__setitem__("vx_min", 20.0), ("inside the runtime's clamp",)),
])
def test_corrupted_design_fails_the_certificate_naming_the_check(design, corrupt, failing):
    d = copy.deepcopy(design)
    corrupt(d)
    names = _failed(d)
    for part in failing:
        assert any(part in n for n in names), (part, names)


def test_filter_and_runtime_models_are_the_force_balance_model(design):
    """kalman_baseline.model (the numpy filter's) and the runtime's model(v) equal the certificate's
    force-balance derivation over the certified speeds and beyond."""
    vals = kb.vehicle_dict(load_vehicle("mbds_250lm"))
    rt = KalmanObserver(design, {})
    for v in np.linspace(1.0, 80.0, 41):
        want = _kalman_force_model(vals, float(v))
        for got in ([M[0] for M in kb.model(vals, v)], rt.model(float(v))):
            for g, w in zip(got, want):
                assert np.max(np.abs(np.asarray(g, float) - w)) <= 1e-12 * max(1.0, np.max(np.abs(w)))


@pytest.mark.parametrize("h", [0.001, 0.01, 0.2, 5.0])
def test_runtime_step_is_the_kalman_update_and_scipys_zero_order_hold(design, h):
    """One runtime step from P0 = the update with y = [ay, r], then the prediction over h with the
    exact zero-order hold of the force-balance model (scipy's expm of the Van Loan block)."""
    vals = kb.vehicle_dict(load_vehicle("mbds_250lm"))
    rt = KalmanObserver(design, {})
    u = {"delta": 0.03, "vx": 23.0, "yaw_rate": 0.12, "ay": 2.5}
    rt.initialize(u)
    A, B, C, D = _kalman_force_model(vals, 23.0)
    Q, R, P = (np.asarray(x, float) for x in (design["noise"]["q"], design["noise"]["r"], design["initial"]["P0"]))
    x = np.array([0.0, u["yaw_rate"]])
    K = P @ C.T @ np.linalg.inv(C @ P @ C.T + R)
    x = x + K @ (np.array([u["ay"], u["yaw_rate"]]) - C @ x - D * u["delta"])
    P = (np.eye(2) - K @ C) @ P
    E = scipy.linalg.expm(np.block([[A, B[:, None]], [np.zeros((1, 3))]]) * h)
    Phi, Gam = E[:2, :2], E[:2, 2]
    x = Phi @ x + Gam * u["delta"]
    P = Phi @ P @ Phi.T + Q * h
    rt.step(h, u)
    assert np.max(np.abs(np.array(rt.x) - x)) <= 1e-12 * max(1.0, np.max(np.abs(x)))
    assert np.max(np.abs(np.array(rt.P) - P)) <= 1e-12 * max(1.0, np.max(np.abs(P)))


def test_runtime_refuses_what_the_certificate_refuses(design):
    """A negative or asymmetric measurement covariance fails the certificate and the runtime."""
    for r in ([[-1.0, 0.0], [0.0, 1e-4]], [[10.0, 1e-3], [0.0, 1e-4]]):
        d = copy.deepcopy(design)
        d["noise"]["r"] = r
        d["tables"] = tables.compute(d)          # the runtime reads R from its tables
        with pytest.raises(ValueError, match="noise.r"):
            KalmanObserver(d, {})


def test_uncertified_design_is_not_packaged(design, tmp_path):
    d = copy.deepcopy(design)
    d["noise"]["r"] = [[-1.0, 0.0], [0.0, 1e-4]]
    with pytest.raises(packaging.PackagingError, match="R positive definite"):
        packaging.package_design(design_file.write(d, tmp_path), tmp_path)


# -- the FMU ----------------------------------------------------------------------------------
@pytest.mark.slow
def test_fmu_interface(built):
    md = read_model_description(str(built))
    v = {x.name: x for x in md.modelVariables}
    assert [x.name for x in md.modelVariables if x.causality == "input"] == list(INPUTS)
    assert [x.name for x in md.modelVariables if x.causality == "output"] == list(OUTPUTS)
    assert not [x for x in md.modelVariables if x.causality == "parameter"]
    assert [v[n].unit for n in INPUTS] == ["rad", "m/s", "rad/s", "m/s2"]
    assert [v[n].unit for n in OUTPUTS] == ["rad", "m/s", "rad/s"] * 2
    assert "Leanza, Reina, Blanco-Claraco" in md.description and "paper 002" in md.description
    assert "vehicle mbds_250lm" in md.description
    assert all(u.dependencies == [] for u in md.outputs)


@pytest.mark.slow
def test_fmu_equals_the_numpy_filter_on_the_mbds_record(fmu_run, reference, mbds):
    cols, _ = mbds
    beta, states = reference
    out = fmu_run.outputs
    assert fmu_run.dt == pytest.approx(0.01, rel=1e-9)
    assert np.abs(out["beta_hat"] - beta).max() < 1e-9                      # rad
    assert np.abs(out["vy_hat"] - states[:, 0]).max() < 1e-8                # m/s
    assert np.abs(out["yaw_rate_hat"] - states[:, 1]).max() < 1e-9          # rad/s
    assert not fmu_run.logs                                                   # 16.5..61 m/s: no clamp
    fmu = kb.split_rms(cols, out["beta_hat"])
    ref = kb.split_rms(cols, beta)
    print(f"\nSideslipKalmanFilter FMU on MBDS: beta RMS t<425 {fmu['before_split']:.4f} deg, "
          f"t>=425 {fmu['after_split']:.4f} deg, all {fmu['all']:.4f} deg")
    for k in ("before_split", "after_split", "all"):
        assert fmu[k] == pytest.approx(ref[k], abs=1e-9)
    # the figures of kalman_baseline's docstring/tests (predicted estimate, TUNED covariances)
    assert fmu["before_split"] == pytest.approx(0.436, abs=1e-3)
    assert fmu["after_split"] == pytest.approx(0.647, abs=1e-3)


@pytest.mark.slow
def test_replay_scores_the_same_figures(fmu_run, reference, mbds):
    cols, _ = mbds
    m = rp.score(fmu_run, split=425.0, vehicle="mbds_250lm")
    est = m["observers"][fmu_run.label]["estimates"]
    assert est["beta_hat"]["truth"] == "beta" and est["vy_hat"]["truth"] == "vy"
    ref = kb.split_rms(cols, reference[0])
    for seg in ("before_split", "after_split", "all"):
        assert math.degrees(est["beta_hat"][seg]["rms"]) == pytest.approx(ref[seg], abs=1e-9)


def _u(k: int, **over) -> dict:
    t = 0.01 * k
    u = {"delta": 0.02 * math.sin(2.0 * t), "vx": 20.0, "yaw_rate": 0.1 * math.sin(2.0 * t - 0.2),
         "ay": 2.0 * math.sin(2.0 * t - 0.3)}
    u.update(over)
    return u


@pytest.mark.slow
def test_fmu_refuses_nan_input_and_clamps_zero_speed(built, design):
    fmu = FmuInstance("K", built)
    rt = KalmanObserver(design, {})
    try:
        fmu.start(_u(0))
        rt.initialize(_u(0))
        for k in range(20):
            fmu.set_inputs(_u(k))
            fmu.slave.doStep(0.01 * k, 0.01)
            rt.step(0.01, _u(k))
        before = fmu.get_outputs()
        fmu.set_inputs(_u(20, ay=math.nan))
        with pytest.raises(Exception, match="discard"):
            fmu.slave.doStep(0.2, 0.01)
        assert fmu.get_outputs() == before                                  # state held
        assert any("non-finite input(s) ay" in m for m in fmu.logs)
        # the next finite step goes on from the held state; vx = 0 is evaluated at vx_min
        n_logs = len(fmu.logs)
        for k in range(20, 40):
            u = _u(k, vx=0.0) if k >= 30 else _u(k)
            fmu.set_inputs(u)
            fmu.slave.doStep(0.01 * k, 0.01)
            rt.step(0.01, u)
            got = fmu.get_outputs()
            assert all(math.isfinite(got[n]) for n in OUTPUTS)
            assert max(abs(got[n] - rt.y[n]) for n in OUTPUTS) <= 1e-12
        warned = [m for m in fmu.logs[n_logs:] if "outside [1, 200] m/s" in m]
        assert len(warned) == 1 and "Warning" in warned[0]
        # beta_hat at vx = 0 is atan(vy_hat / vx_min)
        assert got["beta_hat"] == pytest.approx(math.atan(got["vy_hat"] / 1.0), rel=1e-12)
    finally:
        fmu.close()


def test_runtime_never_raises_on_non_finite_input(design):
    rt = KalmanObserver(design, {})
    rt.initialize({"delta": 0.0, "vx": math.nan, "yaw_rate": math.inf, "ay": 0.0})
    assert rt.x == [0.0, 0.0] and any("non-finite initial input" in m for _, m in rt.events)
    rt.events.clear()
    y0 = dict(rt.y)
    for bad in ({"vx": math.nan}, {"ay": math.inf}, {"delta": -math.inf}, {"yaw_rate": math.nan}):
        rt.step(0.01, _u(0, **bad))
        assert rt.y == y0
    assert len(rt.events) == 4 and all(lvl == "warning" and "non-finite input" in m for lvl, m in rt.events)
    rt.step(math.nan, _u(0))
    assert rt.y == y0 and "not finite" in rt.events[-1][1]
