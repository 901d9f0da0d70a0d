"""Tests of the validation stage (latobs.validation): scenarios, fmpy harness, metrics, plots, report.

Two tiny FMUs are built here with pythonfmu (a fake plant and a fake observer with known
input/output relations), so the harness is tested on real FMI 2.0 co-simulation FMUs without the
project's own FMUs. Each script has a unique module name (pythonfmu shares one Python module
between FMUs whose scripts have the same name).
"""
from __future__ import annotations

import json
import math
import textwrap
from dataclasses import dataclass

import numpy as np
import pytest

from latobs.synthesis.params import G, load_vehicle
from latobs.validation import metrics, plots, report, validate
from latobs.validation.harness import CoSimulationError, NoiseSpec, SimResult, WiringError, run
from latobs.validation.scenarios import (
    SCENARIOS,
    SPEED_BANDS_KMH,
    Scenario,
    get_scenario,
)

DEG = math.pi / 180

# ------------------------------------------------------------------------------------------------
# fake FMUs
# ------------------------------------------------------------------------------------------------
PLANT_SRC = '''
from pythonfmu import Fmi2Slave, Fmi2Causality, Fmi2Variability, Real
from pythonfmu.enums import Fmi2Status


class LatobsValtestPlant(Fmi2Slave):
    description = "fake plant for the latobs validation tests"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.delta = 0.0
        self.vx = 0.0
        self.bank_angle = 0.0
        self.k_beta = 0.1
        self.beta = 0.0
        self.yaw_rate = 0.0
        self.roll_angle = 0.0
        for n in ("delta", "vx", "bank_angle"):
            self.register_variable(Real(n, causality=Fmi2Causality.input))
        self.register_variable(Real("k_beta", causality=Fmi2Causality.parameter,
                                    variability=Fmi2Variability.tunable))
        for n in ("beta", "yaw_rate", "roll_angle"):
            self.register_variable(Real(n, causality=Fmi2Causality.output))

    def _update(self):
        self.beta = self.k_beta * self.delta
        self.yaw_rate = 0.01 * self.vx * self.delta
        self.roll_angle = 0.2 * self.bank_angle

    def exit_initialization_mode(self):
        self._update()
        self.log("plant initialised", Fmi2Status.ok)

    def do_step(self, current_time, step_size):
        self._update()
        return True
'''

OBSERVER_SRC = '''
from pythonfmu import Fmi2Slave, Fmi2Causality, Fmi2Variability, Integer, Real
from pythonfmu.enums import Fmi2Status


class LatobsValtestObserver(Fmi2Slave):
    description = "fake observer for the latobs validation tests"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.beta = 0.0
        self.yaw_rate = 0.0
        self.bank_angle = 0.0
        self.roll_angle = 0.0
        for n in ("beta", "yaw_rate", "bank_angle", "roll_angle"):
            self.register_variable(Real(n, causality=Fmi2Causality.input))
        self.beta_hat = 0.0
        self.yaw_rate_hat = 0.0
        self.bank_angle_hat = 0.0
        self.beta_lower = 0.0
        self.beta_upper = 0.0
        self.yaw_rate_lower = 0.0
        self.yaw_rate_upper = 0.0
        self.residual_norm = 0.0
        self.mode = 1
        for n in ("beta_hat", "yaw_rate_hat", "bank_angle_hat", "beta_lower", "beta_upper",
                  "yaw_rate_lower", "yaw_rate_upper", "residual_norm"):
            self.register_variable(Real(n, causality=Fmi2Causality.output))
        self.register_variable(Integer("mode", causality=Fmi2Causality.output,
                                       variability=Fmi2Variability.discrete))
        self.fail_after = 1e9
        self.register_variable(Real("fail_after", causality=Fmi2Causality.parameter,
                                    variability=Fmi2Variability.tunable))

    def _update(self, t_next):
        self.beta_hat = self.beta + 0.01          # known offset
        self.yaw_rate_hat = self.yaw_rate         # exact
        self.bank_angle_hat = self.bank_angle
        self.beta_lower = self.beta - 0.05        # always encloses
        self.beta_upper = self.beta + 0.05
        self.yaw_rate_lower = self.yaw_rate + 0.001   # never encloses
        self.yaw_rate_upper = self.yaw_rate + 0.002
        self.residual_norm = abs(self.roll_angle)
        self.mode = 1 if t_next < 0.505 else 2

    def exit_initialization_mode(self):
        self._update(0.0)

    def do_step(self, current_time, step_size):
        if current_time >= self.fail_after:
            self.log("deliberate failure", Fmi2Status.error)
            return False
        self._update(current_time + step_size)
        return True
'''

NEEDY_SRC = '''
from pythonfmu import Fmi2Slave, Fmi2Causality, Real


class LatobsValtestNeedy(Fmi2Slave):
    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.beta = 0.0
        self.tire_temperature = 0.0
        self.beta_hat = 0.0
        self.register_variable(Real("beta", causality=Fmi2Causality.input))
        self.register_variable(Real("tire_temperature", causality=Fmi2Causality.input))
        self.register_variable(Real("beta_hat", causality=Fmi2Causality.output))

    def do_step(self, current_time, step_size):
        self.beta_hat = self.beta
        return True
'''


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    pytest.importorskip("pythonfmu")
    from pythonfmu import FmuBuilder

    if not FmuBuilder.has_binary():
        pytest.skip("pythonfmu has no binary for this platform")
    src = tmp_path_factory.mktemp("fmu_src")
    out = tmp_path_factory.mktemp("fmus")
    paths = {}
    for key, module, code in (("plant", "latobs_valtest_plant", PLANT_SRC),
                              ("observer", "latobs_valtest_observer", OBSERVER_SRC),
                              ("needy", "latobs_valtest_needy", NEEDY_SRC)):
        script = src / f"{module}.py"
        script.write_text(textwrap.dedent(code))
        paths[key] = FmuBuilder.build_FMU(script, dest=out)
    return paths


@dataclass(frozen=True)
class ConstScenario(Scenario):
    name: str = "test-const"
    description: str = "constant inputs"
    duration: float = 1.0
    settle_time: float = 0.3

    def signals(self, t, vehicle="sedan"):
        t = np.asarray(t, float)
        return {"delta": np.full_like(t, 0.05), "vx": np.full_like(t, 20.0), "bank_angle": np.full_like(t, 0.02)}


@dataclass(frozen=True)
class RampScenario(Scenario):
    name: str = "test-ramp"
    description: str = "ramping inputs"
    duration: float = 1.0
    settle_time: float = 0.3

    def signals(self, t, vehicle="sedan"):
        t = np.asarray(t, float)
        return {"delta": 0.05 + 0.1 * t, "vx": 20.0 + 2.0 * t, "bank_angle": 0.02 * np.sin(3 * t)}


def _sim(fmus, scenario=None, **kw) -> SimResult:
    return run(scenario or ConstScenario(), fmus["plant"], {"obs": fmus["observer"]}, dt=0.01, **kw)


# ------------------------------------------------------------------------------------------------
# harness
# ------------------------------------------------------------------------------------------------
@pytest.mark.slow
def test_wiring_by_name_and_timing(fmus):
    r = _sim(fmus, RampScenario())
    n = len(r.time)
    assert n == 101 and r.time[-1] == pytest.approx(1.0)
    assert set(r.bus) == {"delta", "vx", "bank_angle", "beta", "yaw_rate", "roll_angle"}
    assert r.inputs["obs"] == ["beta", "yaw_rate", "bank_angle", "roll_angle"]
    delta = r.bus["delta"]
    beta = r.bus["beta"]
    # plant: output at t_{k+1} from the input held over [t_k, t_{k+1}); at t_0 from u(t_0)
    assert beta[0] == pytest.approx(0.1 * delta[0])
    np.testing.assert_allclose(beta[1:], 0.1 * delta[:-1], rtol=0, atol=1e-15)
    # observer receives the plant's outputs by name: beta_hat(t_{k+1}) = beta(t_k) + 0.01
    bh = r.observers["obs"]["beta_hat"]
    assert bh[0] == pytest.approx(beta[0] + 0.01)
    np.testing.assert_allclose(bh[1:], beta[:-1] + 0.01, rtol=0, atol=1e-15)
    # a scenario signal reaches the observer too (bank_angle is not a plant output)
    np.testing.assert_allclose(r.observers["obs"]["bank_angle_hat"][1:], r.bus["bank_angle"][:-1], atol=1e-15)
    # Integer output recorded as int
    assert r.observers["obs"]["mode"].dtype.kind == "i"
    # logs collected per FMU through the fmpy logger callback
    assert any("plant initialised" in m for m in r.logs["plant"])
    assert r.scenario == "test-ramp" and r.dt == 0.01


@pytest.mark.slow
def test_plant_parameters(fmus):
    r = _sim(fmus, plant_parameters={"k_beta": 0.2})
    np.testing.assert_allclose(r.bus["beta"], 0.2 * 0.05, atol=1e-15)
    with pytest.raises(WiringError, match="no parameter 'nope'.*k_beta"):
        _sim(fmus, plant_parameters={"nope": 1.0})


@pytest.mark.slow
def test_missing_input_names_fmu_and_variable(fmus):
    with pytest.raises(WiringError) as exc:
        run(ConstScenario(), fmus["plant"], {"needy": fmus["needy"]}, dt=0.01)
    msg = str(exc.value)
    assert "'tire_temperature'" in msg and "'needy'" in msg
    # a plant input the scenario does not provide
    with pytest.raises(WiringError, match="'beta'"):
        run(ConstScenario(), fmus["observer"], {}, dt=0.01)
    with pytest.raises(WiringError, match="reserved"):
        run(ConstScenario(), fmus["plant"], {"plant": fmus["observer"]}, dt=0.01)


@pytest.mark.slow
def test_fmu_failure_is_reported(fmus):
    with pytest.raises(CoSimulationError) as exc:
        _sim(fmus, observer_parameters={"obs": {"fail_after": 0.5}})
    msg = str(exc.value)
    assert "'obs'" in msg and "doStep" in msg and "t = 0.5 s" in msg
    assert "deliberate failure" in msg  # the FMU's own log message is quoted
    with pytest.raises(WiringError, match="no parameter 'nope'"):
        _sim(fmus, observer_parameters={"obs": {"nope": 1.0}})
    # the harness recovers: a fresh run afterwards works
    assert _sim(fmus).observers["obs"]["beta_hat"][-1] == pytest.approx(0.015)


@pytest.mark.slow
def test_noise_reproducible_and_truth_clean(fmus):
    clean = _sim(fmus, RampScenario())
    spec = NoiseSpec({"beta": (1e-3, 0.0), "yaw_rate": (2e-3, 1e-4)})
    a = _sim(fmus, RampScenario(), noise=spec, seed=1)
    b = _sim(fmus, RampScenario(), noise=spec, seed=1)
    c = _sim(fmus, RampScenario(), noise=spec, seed=2)
    for name in ("beta_hat", "yaw_rate_hat"):
        np.testing.assert_array_equal(a.observers["obs"][name], b.observers["obs"][name])
        assert not np.allclose(a.observers["obs"][name], c.observers["obs"][name])
    # truth untouched
    for name in clean.bus:
        np.testing.assert_array_equal(a.bus[name], clean.bus[name])
        np.testing.assert_array_equal(c.bus[name], clean.bus[name])
    # what the observer received is truth + noise, and it acted on that
    nb = a.measured["beta"] - a.bus["beta"]
    assert 0.5e-3 < nb.std() < 1.5e-3
    np.testing.assert_allclose(a.observers["obs"]["beta_hat"][1:], a.measured["beta"][:-1] + 0.01, atol=1e-15)
    np.testing.assert_array_equal(a.measured["bank_angle"], a.bus["bank_angle"])  # no noise requested
    # NoiseSpec.seed overrides the run seed; a plain dict is accepted
    d = _sim(fmus, RampScenario(), noise=NoiseSpec(spec.signals, seed=1), seed=99)
    np.testing.assert_array_equal(d.observers["obs"]["beta_hat"], a.observers["obs"]["beta_hat"])
    # bias only: a known offset
    e = _sim(fmus, noise={"beta": (0.0, 0.003)})
    np.testing.assert_allclose(e.observers["obs"]["beta_hat"] - e.bus["beta"], 0.013, atol=1e-15)
    with pytest.raises(WiringError, match="'not_a_signal'"):
        _sim(fmus, noise={"not_a_signal": (1.0, 0.0)})
    with pytest.raises(ValueError):
        NoiseSpec({"beta": (-1.0, 0.0)})


# ------------------------------------------------------------------------------------------------
# metrics
# ------------------------------------------------------------------------------------------------
@pytest.mark.slow
def test_metrics_hand_computed_constant(fmus, tmp_path):
    r = _sim(fmus)
    m = metrics.compute(r)
    o = m["observers"]["obs"]
    assert m["settle_time_s"] == 0.3 and m["n_samples"] == 101
    b = o["estimates"]["beta_hat"]
    assert b["truth"] == "beta"
    for k in ("rms", "max_abs", "rms_after_settle", "max_abs_after_settle"):
        assert b[k] == pytest.approx(0.01, rel=1e-12)
    assert o["estimates"]["yaw_rate_hat"]["rms"] == pytest.approx(0.0, abs=1e-15)
    assert o["estimates"]["bank_angle_hat"]["max_abs"] == pytest.approx(0.0, abs=1e-15)
    bi = o["intervals"]["beta"]
    assert bi["enclosure_violations"] == 0 and bi["mean_width"] == pytest.approx(0.1)
    yi = o["intervals"]["yaw_rate"]
    assert yi["enclosure_violations"] == 101          # every sample
    assert yi["enclosure_violations_after_settle"] == 71  # t = 0.30 ... 1.00
    assert yi["mean_width"] == pytest.approx(0.001)
    assert yi["max_violation"] == pytest.approx(0.001)
    # paper 000 eq. (26): ||0.01|| / ||0.02|| with the same support
    assert o["beta_error_to_bank_l2_ratio"] == pytest.approx(0.5, rel=1e-12)
    assert o["beta_error_to_bank_l2_ratio_after_settle"] == pytest.approx(0.5, rel=1e-12)
    # mode 1 while t < 0.505 (samples 0..50), zero-order hold over [t_k, t_k+1)
    assert o["mode_occupancy"] == pytest.approx({"1": 0.51, "2": 0.49})
    assert o["mode_switches"] == 1
    assert o["unscored_outputs"] == []
    rn = np.asarray(r.observers["obs"]["residual_norm"], dtype=float)
    assert o["residual_norm"]["rms"] == pytest.approx(float(np.sqrt(np.mean(rn ** 2))), rel=1e-12)
    assert o["residual_norm"]["max"] == pytest.approx(float(np.max(np.abs(rn))), rel=1e-12)
    # metrics.json: strict JSON, written atomically
    path = metrics.write(m, tmp_path / "scen")
    assert path.name == "metrics.json"
    loaded = json.loads(path.read_text())
    assert loaded["observers"]["obs"]["intervals"]["yaw_rate"]["enclosure_violations"] == 101
    assert not list(path.parent.glob("*.tmp"))


@pytest.mark.slow
def test_metrics_hand_computed_ramp(fmus):
    r = _sim(fmus, RampScenario())
    m = metrics.compute(r, settle_time=0.5)
    o = m["observers"]["obs"]
    e = r.observers["obs"]["beta_hat"] - r.bus["beta"]
    after = r.time >= 0.5
    assert o["estimates"]["beta_hat"]["rms"] == pytest.approx(math.sqrt(sum(x * x for x in e) / len(e)))
    assert o["estimates"]["beta_hat"]["max_abs"] == pytest.approx(max(abs(x) for x in e))
    ea = e[after]
    assert o["estimates"]["beta_hat"]["rms_after_settle"] == pytest.approx(math.sqrt(sum(x * x for x in ea) / len(ea)))
    ratio = math.sqrt(sum(x * x for x in e) * 0.01) / math.sqrt(sum(x * x for x in r.bus["bank_angle"]) * 0.01)
    assert o["beta_error_to_bank_l2_ratio"] == pytest.approx(ratio)


def test_metrics_json_sanitises_nonfinite(tmp_path):
    t = np.arange(5) * 0.1
    r = SimResult(time=t, bus={"beta": np.zeros(5), "bank_angle": np.zeros(5)},
                  observers={"o": {"beta_hat": np.array([0, np.nan, 0, 0, 0.0])}}, logs={}, scenario="x", dt=0.1,
                  info={"weird": float("inf")})
    m = metrics.compute(r)
    o = m["observers"]["o"]
    assert o["estimates"]["beta_hat"]["rms"] is None and o["estimates"]["beta_hat"]["nonfinite_samples"] == 1
    assert o["beta_error_to_bank_l2_ratio"] is None  # zero bank: undefined
    loaded = json.loads(metrics.write(m, tmp_path).read_text())
    assert loaded["info"]["weird"] is None


# ------------------------------------------------------------------------------------------------
# plots and report (end to end on a real scenario)
# ------------------------------------------------------------------------------------------------
@pytest.mark.slow
def test_validate_plots_and_report(fmus, tmp_path):
    out = tmp_path / "report" / "bank-braking"
    result, m, paths = validate("bank-braking", fmus["plant"], {"obs": fmus["observer"]}, out, dt=0.05)
    assert paths[0] == out / "metrics.json"
    names = {p.name for p in paths}
    assert {"metrics.json", "estimates.png", "modes.png", "bank_angle.png", "inputs.png"} <= names
    for p in paths[1:]:
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and p.stat().st_size > 5000
    assert json.loads((out / "metrics.json").read_text())["scenario"] == "bank-braking"
    assert m["observers"]["obs"]["beta_error_to_bank_l2_ratio"] > 0
    assert m["info"]["scenario"]["name"] == "bank-braking"

    sec = report.section_from_dir(out)
    index = report.write_index(tmp_path / "report", [
        "## Design certificates\n\nall certified (test)", sec,
        {"title": "extra", "markdown": "free text", "images": [str(out / "modes.png")]},
    ])
    text = index.read_text()
    assert "## Design certificates" in text and "## bank-braking" in text and "free text" in text
    assert "](bank-braking/estimates.png)" in text and "](bank-braking/modes.png)" in text
    assert "| obs | beta_hat | beta |" in text
    assert "/tmp" not in text.split("## bank-braking")[1].split("\n\n")[0]
    tt = report.text_table(m)
    assert "beta_hat" in tt and "obs" in tt


def test_display_units():
    assert plots.display_scale("beta") == (pytest.approx(180 / math.pi), "deg")
    assert plots.display_scale("yaw_rate")[1] == "deg/s"
    assert plots.display_scale("vx") == (1.0, "m/s")
    assert plots.display_scale("x", {"x": "rad"})[1] == "deg"


# ------------------------------------------------------------------------------------------------
# scenarios
# ------------------------------------------------------------------------------------------------
def _ss_gain(veh, vx):
    """(m/s^2)/rad, linear bicycle, computed independently of the module."""
    L = veh.lf + veh.lr
    K = veh.m / L * (veh.lr / veh.Cf - veh.lf / veh.Cr)
    return vx**2 / (L + K * vx**2)


def _delta_0p3g(veh, vx=80 / 3.6):
    return 0.3 * G / _ss_gain(veh, vx)


def test_registry_and_errors():
    assert {"bank-braking", "double-lane-change", "sine-with-dwell", "fishhook"} <= set(SCENARIOS)
    with pytest.raises(KeyError) as exc:
        get_scenario("no-such-manoeuvre")
    msg = str(exc.value)
    assert "no-such-manoeuvre" in msg
    for name in SCENARIOS:
        assert name in msg
    with pytest.raises(TypeError, match="no field"):
        get_scenario("fishhook", bogus=1)
    inputs = {"CarPlant": ({"delta", "vx", "bank_angle"}, "sedan"),
              "MotorcyclePlant": ({"rider_torque", "vx"}, "sharp_motorcycle")}
    for s in SCENARIOS.values():
        names, vehicle = inputs[s.plant]            # the plant's required inputs, nothing else
        sig = s.signals(s.time_grid(0.01), vehicle)
        assert set(sig) == names == set(s.signal_names)
        assert all(np.all(np.isfinite(v)) for v in sig.values())


def test_bank_braking_profile():
    s = get_scenario("bank-braking")
    assert s.duration == 30.0 and s.settle_time == 3.0
    t = s.time_grid(0.005)
    sig = s.signals(t)
    vx, bank, delta = sig["vx"], sig["bank_angle"], sig["delta"]
    assert np.all(vx[t <= 4.0] == 25.0) and vx[-1] == pytest.approx(10.0)
    kmh = vx * 3.6
    for lo, hi in SPEED_BANDS_KMH:  # passes through all three speed modes
        assert np.any((kmh >= lo) & (kmh < hi)), (lo, hi)
    acc = np.diff(vx) / 0.005
    assert np.all(acc <= 1e-9)  # never speeds up
    assert -acc.max() < 1e-9 and acc.min() == pytest.approx(-0.75, abs=1e-3)
    assert np.max(np.abs(np.diff(acc))) < 0.01  # cosine blends: no jump in deceleration
    at = lambda x: bank[int(round(x / 0.005))] / DEG  # noqa: E731
    assert at(1.0) == pytest.approx(0) and at(3.0) == pytest.approx(2) and at(10.0) == pytest.approx(3.5)
    assert at(15.0) == pytest.approx(5) and at(19.0) == pytest.approx(-2) and at(24.0) == pytest.approx(-1)
    assert at(28.0) == pytest.approx(0)
    assert np.max(np.abs(delta)) == pytest.approx(1 * DEG, rel=1e-3)
    assert delta[int(round(1.25 / 0.005))] == pytest.approx(1 * DEG)  # 0.2 Hz: peak at 1.25 s


def test_double_lane_change_profile():
    s = get_scenario("double-lane-change")
    veh = load_vehicle("sedan")
    t = s.time_grid(0.001)
    sig = s.signals(t, veh)
    assert np.all(sig["vx"] == pytest.approx(80 / 3.6)) and np.all(sig["bank_angle"] == 0)
    d = sig["delta"]
    assert np.max(np.abs(d)) * _ss_gain(veh, 80 / 3.6) == pytest.approx(4.0, rel=1e-3)
    # left first, then the full sine back; ends straight
    first = np.argmax(np.abs(d) > 1e-6)
    assert d[first] > 0 and d[-1] == 0 and np.all(d[t < 1.0] == 0)
    assert abs(np.sum(d)) * 0.001 < 1e-4  # the two full sines cancel
    assert s.info(veh)["open_loop"] is True


def test_sine_with_dwell_profile():
    s = get_scenario("sine-with-dwell")
    veh = load_vehicle("sedan")
    dt = 0.0005
    t = s.time_grid(dt)
    d = s.signals(t, veh)["delta"]
    A = 5.0 * _delta_0p3g(veh)
    assert np.max(d) == pytest.approx(A, rel=1e-4) and np.min(d) == pytest.approx(-A, rel=1e-12)
    dwell = np.sum(np.abs(d + A) < 1e-12) * dt
    assert dwell == pytest.approx(0.5, abs=2 * dt)
    assert np.all(d[t < 1.0] == 0)
    t_end = 1.0 + 1 / 0.7 + 0.5
    assert np.all(np.abs(d[t > t_end + dt]) < 1e-12) and np.any(np.abs(d[t < t_end - 0.01]) > 0)
    assert s.duration == pytest.approx(6.0)
    assert np.all(s.signals(t, veh)["vx"] == pytest.approx(80 / 3.6))
    s3 = get_scenario("sine-with-dwell", amplitude_factor=3.0)
    assert np.max(s3.signals(t, veh)["delta"]) == pytest.approx(3.0 * _delta_0p3g(veh), rel=1e-4)
    for bad in (1.0, 7.0):
        with pytest.raises(ValueError, match="1.5"):
            get_scenario("sine-with-dwell", amplitude_factor=bad)


def test_fishhook_profile():
    s = get_scenario("fishhook")
    veh = load_vehicle("sedan")
    dt = 0.0005
    t = s.time_grid(dt)
    sig = s.signals(t, veh)
    d = sig["delta"]
    A = 6.5 * _delta_0p3g(veh)
    assert np.max(d) == pytest.approx(A) and np.min(d) == pytest.approx(-A)
    rate = np.max(np.abs(np.diff(d))) / dt
    assert rate == pytest.approx(720 * DEG / 16, rel=1e-6)  # 720 deg/s handwheel, 16:1
    assert np.sum(np.abs(d + A) < 1e-12) * dt == pytest.approx(3.0, abs=2 * dt)
    assert np.sum(np.abs(d - A) < 1e-12) * dt == pytest.approx(0.25, abs=2 * dt)
    assert np.argmax(d) < np.argmin(d)  # steer left first, then counter-steer
    assert d[-1] == 0 and s.duration == pytest.approx(8.0)
    assert np.all(sig["vx"] == pytest.approx(45 * 0.44704)) and np.all(sig["bank_angle"] == 0)
