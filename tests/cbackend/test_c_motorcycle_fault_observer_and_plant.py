"""Native C models of paper 003 (motorcycle): the switched PI observer of eq. (13)
(``fmu_src/c/motorcycle_fault_observer.c``) and the nonlinear Sharp motorcycle
(``fmu_src/c/motorcycle_plant.c``) against their Python twins (``fmu_src/motorcycle_fault_observer.py``,
``fmu_src/motorcycle_plant.py``).

1. Co-simulation equivalence, max |c - py| <= 1e-9 max |py| per output (integers equal), on every
   validation scenario of MotorcyclePlant (``motorcycle-lane-change``), paired as ``latobs demo``
   does (plant vehicle sharp_motorcycle; noise-free and with ``latobs validate --noise``):
   the observer in one harness run beside its Python twin (so both see the same inputs), at the
   default step (the emitter's precomputed maps) and at 2 ms (maps computed by the C model); the
   plant in one harness run with each plant and the same observer (bus and observer outputs
   compared), at the default step and at other steps with algebraic / linear tyres.
2. ModelExchange against co-simulation at 1 ms, fmpy CVode: see ``test_model_exchange_equals_
   co_simulation`` for the tolerance and why the inputs are given held.
3. The C specifics: the map cache under changing step sizes, the hold / grid / clamp warnings
   message for message, the refused absurd steps, the ME derivatives against the Python runtime
   at arbitrary states, the ME state events at the band edges widened by the hysteresis and at
   vx_hold, the plant's warnings as ME events.
"""
from __future__ import annotations

import math
from ctypes import c_double

import numpy as np
import pytest
from fmpy import extract, instantiate_fmu, read_model_description, simulate_fmu

from latobs.fmu_src.motorcycle_plant import MotorcyclePlantModel
from latobs.native_guard import find_compiler
from latobs.packaging import plant_data
from latobs.pipeline import PLANT_NOISE
from latobs.validation import harness
from latobs.validation.harness import NoiseSpec
from latobs.validation.scenarios import SCENARIOS, get_scenario

from c_models import REL, assert_equivalent, held_inputs, run_cs

pytestmark = [pytest.mark.slow,
              pytest.mark.skipif(find_compiler() is None, reason="no C compiler (set CC, or install cc/gcc)")]

OBS, PLANT = "MotorcycleFaultObserverPaper", "MotorcyclePlant"
VEHICLE = "sharp_motorcycle"
SCENARIOS_003 = [name for name, sc in SCENARIOS.items() if sc.plant == PLANT]
ME_DT = 1e-3        # s, the ModelExchange comparison's sample step
ME_RTOL = 1e-8      # CVode's relative tolerance there



# ---------------------------------------------------------------------------------------------
# 1. co-simulation equivalence with the Python runtimes
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("scenario", SCENARIOS_003)
@pytest.mark.parametrize("dt, noise", [(0.005, False), (0.005, True), (0.002, False)])
def test_observer_equals_python_runtime(built_fmus, scenario, dt, noise):
    res = harness.run(scenario, built_fmus.path(PLANT), {"py": built_fmus.path(OBS), "c": built_fmus.c_path(OBS)},
                      dt=dt, vehicle=VEHICLE, noise=NoiseSpec(signals=PLANT_NOISE[PLANT]) if noise else None)
    assert len(set(res.observers["py"]["mode"])) >= 3          # the scenario switches modes
    assert_equivalent(res.observers["py"], res.observers["c"], f"{scenario} dt={dt} noise={noise}")
    assert res.logs["c"] == res.logs["py"]


@pytest.mark.parametrize("scenario", SCENARIOS_003)
@pytest.mark.parametrize("dt, params", [(0.005, {}),
                                        (0.01, {"sigma": 0.0, "mu": 0.6, "mf_C": 1.6, "mf_E": -0.5}),
                                        (0.004, {"linear_tires": 1.0})])
def test_plant_equals_python_runtime(built_fmus, scenario, dt, params):
    obs = {"obs": built_fmus.c_path(OBS)}
    py = harness.run(scenario, built_fmus.path(PLANT), obs, dt=dt, vehicle=VEHICLE, plant_parameters=params)
    c = harness.run(scenario, built_fmus.c_path(PLANT), obs, dt=dt, vehicle=VEHICLE, plant_parameters=params)
    what = f"{scenario} dt={dt} {params}"
    assert_equivalent(py.bus, c.bus, what)
    assert_equivalent(py.observers["obs"], c.observers["obs"], what)


# ---------------------------------------------------------------------------------------------
# 2. ModelExchange against co-simulation
# ---------------------------------------------------------------------------------------------
@pytest.fixture
def bisected_input_events(monkeypatch):
    """fmpy 0.3's ``Input.nextEvent`` scans the input's event list from its start at every call:
    quadratic in the number of samples (~2 s per 1 000 held samples here). The same search by
    bisection (the first event time after ``time`` that is not close to it)."""
    from fmpy import simulation

    def next_event(self, time):
        if self.t is None:
            return math.inf
        events = self.t_events
        i = int(np.searchsorted(events, time, side="right"))
        while i < len(events) and simulation.isclose(events[i], time):
            i += 1
        return float(events[i]) if i < len(events) else math.inf

    monkeypatch.setattr(simulation.Input, "nextEvent", next_event)


def _me_run(fmu, t, signals, outputs):
    return simulate_fmu(str(fmu), fmi_type="ModelExchange", solver="CVode", input=held_inputs(t, signals),
                        start_time=0.0, stop_time=float(t[-1]), output_interval=ME_DT,
                        relative_tolerance=ME_RTOL, output=outputs, record_events=False)


@pytest.mark.usefixtures("bisected_input_events")
def test_model_exchange_equals_co_simulation(built_fmus):
    """fmpy CVode runs of both ME FMUs with the inputs a 1 ms co-simulation harness run of the C
    FMUs recorded, on the lane change compressed to 5.5 s (both pulses, modes 1-2-3 up and down,
    the tyres 10 % into saturation; fmpy's event handling costs ~0.5 ms per sample).

    Why held inputs: fmpy's CVode callback does not set the inputs at the time it evaluates the
    derivatives (only the root function does), and CVode steps up to 0.11 s here over quiet
    stretches, so linearly interpolated inputs reach the ME FMU late by up to a step (measured on
    the plant: 2 % of the roll angle's peak, 200 % of the steer rate's, an artefact of the host
    that a solver without that lag would not show). Held inputs with an
    event at each sample make the ME problem the co-simulation's: the same held inputs over each
    1 ms and the same discrete update at the start of each (mode, hold). The difference is then
    the integration error alone: the observer's co-simulation map is exact, the plant's RK4 at
    1 ms is within 7e-8 of CVode at rtol 1e-12 (measured), and CVode keeps each internal step's
    local error near rtol |x| + rtol * nominal (fmpy's atol) while restarting at each of the
    5 500 samples: its global error may add up over the internal steps, i.e. ~1e4 rtol. Asserted:
    5e4 rtol = 5e-4 of each signal's peak. Measured at rtol 1e-8: <= 8e-6 (observer), <= 9e-5
    (the plant's steer rate, <= 2e-5 for its other states); all 50-100x smaller at rtol 1e-10.
    The outputs with direct feedthrough (mode, forces, residual; the plant's slip angles and
    Gamma) are compared with the ME's own states and inputs, since fmpy records them after the
    event at a sample (inputs of that sample) and the co-simulation before it."""
    sc = get_scenario("motorcycle-lane-change", t_rise=0.2, rise=1.5, hold=2.0, fall=1.5, t_first=1.8,
                      t_second=2.8, pulse=0.8, duration=5.5)
    cs = harness.run(sc, built_fmus.c_path(PLANT), {"obs": built_fmus.c_path(OBS)}, dt=ME_DT, vehicle=VEHICLE)
    t = cs.time
    tol = 5e4 * ME_RTOL

    # the observer
    obs_in = {k: cs.measured[k] for k in cs.inputs["obs"]}
    states = ["xhat_vy", "xhat_yaw_rate", "xhat_roll_rate", "xhat_steer_angle", "xhat_steer_rate",
              "fhat_roll_angle", "fhat_rider_torque"]
    ref = cs.observers["obs"]
    me = _me_run(built_fmus.c_path(OBS), t, obs_in, [*ref, *states])
    assert np.allclose(me["time"], t, rtol=0, atol=1e-9)
    assert set(ref["mode"]) == {1, 2, 3}
    assert np.array_equal(me["mode"][:-1], ref["mode"][1:])   # cs row k+1: the mode chosen at t_k
    for name in ("roll_angle_hat", "rider_torque_hat", "vy_hat", "steer_rate_hat"):
        err, scale = np.max(np.abs(me[name] - ref[name])), np.max(np.abs(ref[name]))
        assert err <= tol * scale, f"observer {name}: {err:.3g} vs peak {scale:.3g}"
    s = np.stack([me[k] for k in states], axis=1)
    y = np.stack([obs_in[k] for k in ("steer_angle", "yaw_rate", "roll_rate")], axis=1)
    design = built_fmus.design(OBS)
    for i, mode in enumerate(design["modes"]):
        rows = me["mode"] == i + 1
        C, Hx, Hphi = (np.asarray(mode["model"][k], float) for k in ("C", "H_x", "H_phi"))
        forces = s[rows, :5] @ Hx.T + np.outer(s[rows, 5], Hphi)
        np.testing.assert_allclose(me["Ff_hat"][rows], forces[:, 0], rtol=1e-12, atol=1e-9)
        np.testing.assert_allclose(me["Fr_hat"][rows], forces[:, 1], rtol=1e-12, atol=1e-9)
        np.testing.assert_allclose(me["residual_norm"][rows], np.linalg.norm(y[rows] - s[rows, :5] @ C.T, axis=1),
                                   rtol=1e-9, atol=1e-15)

    # the plant
    plant_in = {k: cs.bus[k] for k in cs.inputs[harness.PLANT_LABEL]}
    names = ["roll_angle", "steer_angle", "vy", "yaw_rate", "roll_rate", "steer_rate", "Ff", "Fr"]
    me = _me_run(built_fmus.c_path(PLANT), t, plant_in, [*names, "Gamma_f", "Gamma_r", "alpha_f", "alpha_r"])
    for name in names:
        err, scale = np.max(np.abs(me[name] - cs.bus[name])), np.max(np.abs(cs.bus[name]))
        assert err <= tol * scale, f"plant {name}: {err:.3g} vs peak {scale:.3g}"
    assert np.max(np.abs(cs.bus["Gamma_f"])) > 0.05 * np.max(np.abs(cs.bus["Ff"]))    # saturation reached
    rt = MotorcyclePlantModel(plant_data(VEHICLE))
    for k in range(0, len(t), 50):
        x = [me[n][k] for n in names]
        want = rt.tyre_state(x, {n: plant_in[n][k] for n in plant_in})
        for n in ("Gamma_f", "Gamma_r", "alpha_f", "alpha_r"):
            assert me[n][k] == pytest.approx(want[n], rel=1e-12, abs=1e-12), (n, t[k])


# ---------------------------------------------------------------------------------------------
# 3. specifics of the C models
# ---------------------------------------------------------------------------------------------
def _outputs_equal(ref: list, got: list, rel: float = REL):
    assert len(ref) == len(got)
    for a, b in zip(ref, got):
        for name, x in a.items():
            assert abs(b[name] - x) <= rel * max(abs(x), 1.0), (name, x, b[name])


def test_observer_steps_of_changing_size_and_every_warning_equal_python(built_fmus):
    """The C map cache (the default step precomputed, one other step cached per mode) under
    alternating step sizes, through the hold (|vx| < vx_hold), a reverse excursion, the speed grid
    left on both sides and the modes skipped over in one step: outputs within 1e-9 and the
    very same warnings, in the same order."""
    rng = np.random.default_rng(3)
    speeds = [14.0, 14.2, 19.0, 0.5, -0.5, -4.0, 0.0, 3.0, 9.0, 40.0, 31.0, 12.4, 12.6, 26.0, 8.0]
    steps = []
    for k, vx in enumerate(speeds * 3):
        y = 0.05 * rng.standard_normal(3)
        h = (0.005, 0.003, 0.005, 0.0125)[k % 4]
        steps.append((h, {"vx": vx, "steer_angle": y[0], "yaw_rate": y[1], "roll_rate": y[2]}))
    u0 = {"vx": 14.0, "steer_angle": 0.01, "yaw_rate": 0.1, "roll_rate": -0.05}
    py, py_log = run_cs(built_fmus.path(OBS), "py", u0, steps)
    c, c_log = run_cs(built_fmus.c_path(OBS), "c", u0, steps)
    assert {o["mode"] for o in py} == {1, 2, 3, 4, 5}
    _outputs_equal(py, c)
    assert c_log == py_log
    assert sum("frozen" in m for m in c_log) == 6 and sum("outside the design grid" in m for m in c_log) == 6


def test_the_start_takes_the_band_of_the_initial_speed_as_python(built_fmus):
    """A start within the hysteresis above each interior band edge: the C FMU takes that band at
    the start and keeps it over its first steps, as the Python FMU does."""
    tables = built_fmus.design(OBS)["tables"]
    rng = np.random.default_rng(5)
    for k, e in enumerate(tables["edges"][1:-1]):
        vx = e + 0.5 * tables["hysteresis"]
        steps = []
        for _ in range(3):
            y = 0.05 * rng.standard_normal(3)
            steps.append((0.005, {"vx": vx, "steer_angle": y[0], "yaw_rate": y[1], "roll_rate": y[2]}))
        u0 = {"vx": vx, "steer_angle": 0.01, "yaw_rate": 0.1, "roll_rate": -0.05}
        py, _ = run_cs(built_fmus.path(OBS), "py", u0, steps)
        c, _ = run_cs(built_fmus.c_path(OBS), "c", u0, steps)
        assert [o["mode"] for o in c] == [k + 2] * 4, (e, vx)
        _outputs_equal(py, c)


def test_plant_clamps_and_warnings_equal_python(built_fmus):
    """Torque beyond +-200 N m, vx below 0, below 1 m/s and above 60 m/s, the fall: outputs within
    1e-9 and the same warnings in the same order (the numbers are printed with %g in C, with
    Python's repr in the runtime: compared up to the first '=')."""
    steps = [(0.005, {"rider_torque": tau, "vx": vx})
             for tau, vx in [(0, 12), (250, 12), (-300, 12), (20, -3), (20, 0.5), (20, 75), (0, 80), (0, 30)] * 6]
    steps += [(0.05, {"rider_torque": 150.0, "vx": 3.0})] * 40          # falls over
    u0 = {"rider_torque": 0.0, "vx": 12.0}
    py, py_log = run_cs(built_fmus.path(PLANT), "py", u0, steps)
    c, c_log = run_cs(built_fmus.c_path(PLANT), "c", u0, steps)
    _outputs_equal(py, c)
    assert max(abs(o["roll_angle"]) for o in c) > 1.0
    assert [m.split("=")[0] for m in c_log] == [m.split("=")[0] for m in py_log]
    assert sum("fallen" in m for m in c_log) == 1
    for what in ("clamped to 200", "< 0 clamped", "below 1", "clamped to 60"):   # once per entry
        assert sum(what in m for m in c_log) == 6, what


def test_absurd_steps_are_refused_with_the_state_kept(built_fmus):
    """A step whose map or substep count is not representable (h = 1e300 s for the observer, 1e6 s
    for the plant: 1e9 RK4 substeps) is refused with an error; the next normal step proceeds as if
    it had not been asked (the Python runtimes would raise or loop for hours)."""
    for name, u, big in ((OBS, {"vx": 15.0, "steer_angle": 0.01, "yaw_rate": 0.1, "roll_rate": 0.0}, 1e300),
                         (PLANT, {"rider_torque": 10.0, "vx": 15.0}, 1e6)):
        ref, _ = run_cs(built_fmus.c_path(name), "ref", u, [(0.005, u)] * 3)
        got, log = run_cs(built_fmus.c_path(name), "c", u, [(0.005, u), (big, u), (0.005, u), (0.005, u)])
        assert got[2] is None and any(m.startswith("[ERROR]") and "refused" in m for m in log), log
        assert [got[0], got[1], got[3], got[4]] == ref


def _me_instance(fmu, tmp_path, inputs: dict, log: list, params: dict | None = None):
    md = read_model_description(str(fmu))
    unzipped = extract(str(fmu), unzipdir=str(tmp_path / f"me{len(list(tmp_path.iterdir()))}"))
    m = instantiate_fmu(unzipped, md, fmi_type="ModelExchange",
                        logger=lambda c, name, status, cat, msg: log.append((status, msg.decode())))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    m.setupExperiment(startTime=0.0)
    if params:
        m.setReal([vr[k] for k in params], list(params.values()))
    m.enterInitializationMode()
    m.setReal([vr[k] for k in inputs], list(inputs.values()))
    m.exitInitializationMode()
    m.newDiscreteStates()
    m.enterContinuousTimeMode()
    return md, m, vr


def _me_derivatives(m, vr, md, x, inputs: dict) -> np.ndarray:
    n = len(md.derivatives)
    m.setReal([vr[k] for k in inputs], list(inputs.values()))
    m.setContinuousStates((c_double * n)(*x), n)
    dx = (c_double * n)()
    m.getDerivatives(dx, n)
    return np.array(dx[:])


def test_me_derivatives_equal_the_python_runtimes(built_fmus, tmp_path):
    """model_me_derivatives at arbitrary states and inputs (clamped ones too): the plant's equal
    MotorcyclePlantModel.derivatives (the same formulas, to rounding), with relaxation, with
    algebraic tyres (sigma = 0: the force states are inert, derivative 0) and with linear tyres;
    the observer's eq. (13) s' = M_s s + G_s y of its active mode, and 0 while frozen."""
    rng = np.random.default_rng(7)
    log: list = []
    scale = np.array([0.5, 0.05, 0.5, 0.5, 1.0, 1.0, 800.0, 800.0])
    for params in ({}, {"sigma": 0.0, "mu": 0.7}, {"linear_tires": 1.0, "sigma": 0.5}):
        md, m, vr = _me_instance(built_fmus.c_path(PLANT), tmp_path, {"rider_torque": 0.0, "vx": 12.0}, log, params)
        rt = MotorcyclePlantModel(plant_data(VEHICLE), params)
        for tau, vx in [(30.0, 12.0), (-250.0, 25.0), (5.0, 0.3), (5.0, -2.0), (60.0, 70.0)]:
            x = scale * rng.standard_normal(8)
            u = {"rider_torque": tau, "vx": vx}
            got = _me_derivatives(m, vr, md, x, u)
            np.testing.assert_allclose(got, rt.derivatives(x, u), rtol=1e-12, atol=1e-9, err_msg=str(params))
            assert params.get("sigma") != 0.0 or not np.any(got[6:])
        m.terminate()
        m.freeInstance()

    md, m, vr = _me_instance(built_fmus.c_path(OBS), tmp_path, {"vx": 16.0, "steer_angle": 0.0, "yaw_rate": 0.0,
                                                               "roll_rate": 0.0}, log)
    design = built_fmus.design(OBS)
    mode = design["modes"][1]                                   # 16 m/s: the 15 m/s mode
    A, Ef, C = (np.asarray(mode["model"][k], float) for k in ("A", "E_f", "C"))
    LP, LI = (np.asarray(mode["gains"][k], float) for k in ("L_P", "L_I"))
    for _ in range(3):
        s, y = rng.standard_normal(7), 0.1 * rng.standard_normal(3)
        u = {"vx": 16.0, "steer_angle": y[0], "yaw_rate": y[1], "roll_rate": y[2]}
        want = np.concatenate([A @ s[:5] + LP @ (y - C @ s[:5]) + Ef @ s[5:], LI @ (y - C @ s[:5])])
        np.testing.assert_allclose(_me_derivatives(m, vr, md, s, u), want, rtol=1e-10, atol=1e-9)
    m.enterEventMode()
    m.setReal([vr["vx"]], [0.2])
    m.newDiscreteStates()                                       # |vx| < vx_hold: frozen
    m.enterContinuousTimeMode()
    assert not np.any(_me_derivatives(m, vr, md, rng.standard_normal(7), u | {"vx": 0.2}))
    m.terminate()
    m.freeInstance()
    assert any("observer frozen" in msg for _, msg in log)


def _crossings(times, values, level):
    """Times where the piecewise-linear (times, values) crosses ``level``, in order."""
    out = []
    for t0, t1, v0, v1 in zip(times, times[1:], values, values[1:]):
        if (v0 - level) * (v1 - level) < 0:
            out.append(t0 + (level - v0) / (v1 - v0) * (t1 - t0))
    return out


def test_me_state_events_switch_at_the_widened_band_edges_and_hold(built_fmus):
    """A continuous speed ramp (constant y: fmpy's CVode applies the inputs only in its root
    function, harmless when only the events depend on them) through every mode up and down, out
    of the grid on both sides and into the hold: the mode changes exactly where vx crosses a band
    edge widened by the hysteresis (CVode's root finding, to 1e-9 s), x^ and f^ stay constant
    while |vx| < vx_hold, and the warnings are those of a co-simulation run."""
    design = built_fmus.design(OBS)
    edges, hyst = design["switching"]["edges"], design["switching"]["hysteresis"]
    knots_t, knots_v = [0.0, 2.0, 4.0, 5.0, 6.0], [11.0, 35.0, 14.0, 0.0, 9.0]
    signal = np.array(list(zip(knots_t, knots_v, [0.01] * 5, [0.1] * 5, [0.05] * 5)),
                      dtype=[("time", float), ("vx", float), ("steer_angle", float), ("yaw_rate", float),
                             ("roll_rate", float)])
    log: list = []
    res = simulate_fmu(str(built_fmus.c_path(OBS)), fmi_type="ModelExchange", solver="CVode", input=signal,
                       start_time=0.0, stop_time=6.0, output_interval=0.01, relative_tolerance=1e-8,
                       record_events=True, output=["mode", "fhat_roll_angle", "fhat_rider_torque", "xhat_vy"],
                       logger=lambda c, name, status, cat, msg: log.append(msg.decode()))
    up = [e + hyst for e in edges[1:-1]]                        # 13, 18, 23, 28 m/s
    down = [e - hyst for e in edges[1:-1]]                      # 12, 17, 22, 27 m/s
    want = sorted([(t, "up") for lv in up for t in _crossings(knots_t, knots_v, lv) if t < 2.0]
                  + [(t, "down") for lv in down for t in _crossings(knots_t, knots_v, lv) if t > 2.0])
    changes = [(res["time"][i], res["mode"][i] - res["mode"][i - 1]) for i in range(1, len(res))
               if res["mode"][i] != res["mode"][i - 1]]
    assert len(changes) == len(want) == 8
    for (t_got, step), (t_want, way) in zip(changes, want):
        assert t_got == pytest.approx(t_want, abs=1e-9) and step == (1 if way == "up" else -1)
    t_in, t_out = _crossings(knots_t, knots_v, 1.0)             # vx_hold = 1 m/s
    frozen = (res["time"] > t_in + 1e-9) & (res["time"] < t_out - 1e-9)
    assert frozen.sum() > 10
    for k in ("fhat_roll_angle", "fhat_rider_torque", "xhat_vy"):
        held = res[k][frozen]
        assert np.all(held == held[0]) and held[0] != 0.0, k
    assert sum("observer frozen" in m for m in log) == 1 and sum("observer resumes" in m for m in log) == 1
    assert sum("outside the design grid" in m for m in log) == 2


def test_plant_me_warnings_are_events(built_fmus):
    """The plant's warnings (torque clamp, vx above 60, below 1 and below 0 m/s) arrive in ME at
    the zero crossings of its event indicators, once per entry, as in co-simulation."""
    knots = [(0.0, 0.0, 10.0), (0.2, 0.0, 10.0), (0.3, 260.0, 10.0), (0.4, 0.0, 10.0), (1.0, 0.0, 70.0),
             (2.0, 0.0, 10.0), (2.5, 0.0, -2.0), (3.0, 0.0, 5.0)]
    signal = np.array(knots, dtype=[("time", float), ("rider_torque", float), ("vx", float)])
    log: list = []
    simulate_fmu(str(built_fmus.c_path(PLANT)), fmi_type="ModelExchange", solver="CVode", input=signal,
                 start_time=0.0, stop_time=3.0, output_interval=0.01, relative_tolerance=1e-6,
                 logger=lambda c, name, status, cat, msg: log.append(msg.decode()))
    for what in ("clamped to 200", "clamped to 60", "below 1", "< 0 clamped"):
        assert sum(what in m for m in log) == 1, (what, log)
