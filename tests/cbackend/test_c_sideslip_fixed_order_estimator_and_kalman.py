"""The native C models of paper 002 (``fmu_src/c/sideslip_fixed_order_estimator.c``: the fixed-order sideslip
estimator, one or speed-scheduled; ``fmu_src/c/sideslip_kalman_filter.c``: the Kalman baseline) against
their Python runtimes, FMU against FMU.

1. Equivalence, every validation scenario that drives these FMUs (taken from ``latobs.demo``, so a
   new one is covered automatically): ``RUNS`` pairs paper 002's estimators with CarPlant (vehicle
   delibasi) on three manoeuvres; ``REPLAYS_002`` drives each estimator with the MBDS record
   (``latobs replay``). Both backends see the same inputs in one harness run (resp. the same
   record), and every output must agree to 1e-9 relative to its range (integers exactly) at the
   FMU's default step 0.005 s (the emitter's step maps, the Python FMU's own) and at another step
   (the maps computed in C: la_zoh_map against fmu_src/linalg.py).
2. ModelExchange against co-simulation at 1 ms (the tolerance is derived in :func:`_check_me`).
3. What is specific to the C models: estimators of order 2 and 0 and a schedule with excursions
   below and above the grid (the warnings, once per excursion), the Kalman speed clamp, a refused
   step at an absurd h, and the emitters' checks.
"""
from __future__ import annotations

import copy
import math

import numpy as np
import pytest
import scipy.linalg
import scipy.signal
from fmpy import read_model_description, simulate_fmu

from latobs import demo, packaging
from latobs.cbackend import build_c_fmu
from latobs.cbackend import sideslip_kalman_filter as kalman_emitter
from latobs.cbackend import sideslip_fixed_order_estimator as tf_emitter
from latobs.fmu_src.framework import DEFAULT_STEP
from latobs.fmu_src.sideslip_fixed_order_estimator import TfEstimator
from latobs.native_guard import find_compiler
from latobs.pipeline import PLANT_NOISE
from latobs.synthesis import design_file, designs, tables
from latobs.synthesis.tables import sideslip_fixed_order_estimator as tft
from latobs.validation import harness
from latobs.validation import replay as rp
from latobs.validation.scenarios import get_scenario

from conftest import HOST_ONLY

pytestmark = pytest.mark.skipif(find_compiler() is None, reason="no C compiler (set CC, or install cc/gcc)")

OTHER_DT = 0.002              # s, a step with no precomputed map
REL = 1e-9
ME_STEP = 0.001               # s, the ModelExchange comparison's communication step
ME_RTOL = 1e-8                # CVode's relative tolerance there
SLOW_DESIGNS = {"SideslipFixedOrderEstimatorScheduled"}     # ~40 s to design (shared with the session)
#: paper 002's CarPlant runs of the demo: (scenario, plant parameters, noise, observers, plant vehicle)
RUNS_002 = [(s, p, n, o, v) for s, _tag, p, n, o, v in demo.RUNS if o == demo.P002]
REPLAYS = [pytest.param(name, vehicle, id=designs.artefact_name(name, vehicle),
                        marks=[pytest.mark.slow] if name in SLOW_DESIGNS else [])
           for _label, name, vehicle in demo.REPLAYS_002]


class Pairs:
    """(pythonfmu FMU, C FMU) of an artefact NAME or NAME_VEHICLE: the session build's for a
    default vehicle, else designed (and certified) once per test run (``built_fmus.design``: the
    run's cache, which the demo's runs share) and packaged here by both backends."""

    def __init__(self, built_fmus, out):
        self.built, self.out, self._made = built_fmus, out, {}

    def __call__(self, artefact: str):
        name, vehicle = designs.parse_artefact(artefact)
        if vehicle is None:
            return self.built.path(name), self.built.c_path(name)
        if artefact not in self._made:
            path = design_file.write(self.built.design(name, vehicle), self.out)
            self._made[artefact] = (packaging.package_design(path, self.out / "py"),
                                    packaging.package_design(path, self.out / "c", backend="c", platforms=HOST_ONLY))
        return self._made[artefact]


@pytest.fixture(scope="module")
def pairs(built_fmus, tmp_path_factory):
    return Pairs(built_fmus, tmp_path_factory.mktemp("p002"))


@pytest.fixture(scope="module")
def plants(tmp_path_factory):
    """CarPlant FMUs (pythonfmu) by vehicle, built on first use."""
    out, made = tmp_path_factory.mktemp("plants"), {}

    def plant(vehicle):
        if vehicle not in made:
            made[vehicle] = packaging.package_plant("CarPlant", vehicle, out)
        return made[vehicle]
    return plant


@pytest.fixture(scope="module")
def mbds():
    return rp.load_csv(rp.MBDS_CSV)


def _assert_equal(py: dict, c: dict, what: str) -> dict:
    """Every output of c within REL of py (relative to the output's range; integers exactly);
    returns {output: max relative difference}."""
    assert set(py) == set(c), what
    rel = {}
    for k in py:
        a, b = np.asarray(py[k]), np.asarray(c[k])
        if a.dtype.kind in "iu":
            assert np.array_equal(a, b), f"{what}: {k} differs"
            rel[k] = 0.0
            continue
        scale = max(float(np.abs(a).max()), 1e-300)
        rel[k] = float(np.abs(b - a).max()) / scale
        assert rel[k] <= REL, f"{what}: {k} differs by {rel[k]:.3g} relative"
    print(f"\n{what}: max relative difference {rel}")
    return rel


def _messages(logs) -> list[str]:
    """The text of every warning and error, without the category (the backends' logs agree)."""
    return [m.split(": ", 1)[1] for m in logs if m.startswith(("[WARNING]", "[ERROR]", "[DISCARD]"))]


# ---------------------------------------------------------------------------------------------
# 1. equivalence on every validation scenario
# ---------------------------------------------------------------------------------------------
def test_the_demo_pairs_paper_002_with_these_fmus():
    models = {designs.parse_artefact(n)[0] for *_, obs, _v in RUNS_002 for n in obs}
    models |= {name for _label, name, _v in demo.REPLAYS_002}
    assert RUNS_002 and models == {"SideslipFixedOrderEstimator", "SideslipFixedOrderEstimatorScheduled",
                                   "SideslipKalmanFilter"}


def _carplant_run(pairs, plants, scenario, params, noise, observers, vehicle, dt):
    obs = {}
    for n in observers:
        obs[f"py:{n}"], obs[f"c:{n}"] = pairs(n)
    sc = get_scenario(scenario)
    res = harness.run(sc, plants(vehicle), obs, dt=dt, vehicle=vehicle, plant_parameters=params,
                      noise=harness.NoiseSpec(signals=PLANT_NOISE[sc.plant]) if noise else None)
    for n in observers:
        _assert_equal(res.observers[f"py:{n}"], res.observers[f"c:{n}"], f"{scenario} dt {dt} {n}")
        assert _messages(res.logs[f"c:{n}"]) == _messages(res.logs[f"py:{n}"])


@pytest.mark.parametrize("run", RUNS_002, ids=[r[0] for r in RUNS_002])
def test_carplant_scenarios_equal_the_python_fmus(pairs, plants, run):
    _carplant_run(pairs, plants, *run, dt=DEFAULT_STEP)


def test_carplant_scenario_at_another_step(pairs, plants):
    run = min(RUNS_002, key=lambda r: get_scenario(r[0]).duration)
    _carplant_run(pairs, plants, *run, dt=OTHER_DT)


def _replay(pairs, data, name, vehicle):
    py, c = pairs(designs.artefact_name(name, vehicle))
    a, b = rp.drive(py, data), rp.drive(c, data)
    _assert_equal(a.outputs, b.outputs, f"MBDS replay dt {a.dt:.3g} {b.label}")
    assert _messages(b.logs) == _messages(a.logs)


@pytest.mark.slow
@pytest.mark.parametrize("name, vehicle", REPLAYS)
def test_mbds_replay_equals_the_python_fmu(pairs, mbds, name, vehicle):
    """The whole record at its own step, 0.01 s, as ``latobs replay`` drives it (55 000 steps:
    the pythonfmu Kalman filter alone takes 7 s)."""
    _replay(pairs, mbds, name, vehicle)


@pytest.mark.parametrize("name, vehicle", REPLAYS)
def test_mbds_replay_at_the_default_step(pairs, mbds, name, vehicle):
    """The record's first 100 s (50 band switches for the scheduled estimator) on the default
    step's grid: the same samples, one per 0.005 s."""
    head = {k: v[:10001] for k, v in mbds.items()}
    _replay(pairs, dict(head, t=head["t"][0] + DEFAULT_STEP * np.arange(head["t"].size)), name, vehicle)


# ---------------------------------------------------------------------------------------------
# 2. ModelExchange against co-simulation
# ---------------------------------------------------------------------------------------------
def _kernel(systems, h: float) -> np.ndarray:
    """K(j h), j = 0, 1, ..: a bound of the output effect of a unit state error after j h s,
    max_i ||C_i||_1 max_i ||e^(A_i j h)||_inf, up to 40 slowest time constants (beyond, < e^-40).
    For first-order bands (the designs) it bounds the switched system too: |e(t)| decays at least
    as fast as the slowest band's exp(-a_0 t)."""
    A = [np.array(s[0]) for s in systems]
    c = max(np.abs(s[2]).sum() for s in systems)
    slowest = min(min(-np.linalg.eigvals(a).real) for a in A)
    step = [scipy.linalg.expm(a * h) for a in A]
    power = [np.eye(len(a)) for a in A]
    out = []
    for _ in range(int(40.0 / (slowest * h)) + 2):
        out.append(c * max(np.abs(p).sum(axis=1).max() for p in power))
        power = [p @ s_ for p, s_ in zip(power, step)]
    return np.array(out)


def _check_me(fmu, data: dict, t: np.ndarray, inputs: dict, cs: dict) -> list[str]:
    """fmpy's CVode run of the ModelExchange interface, fed the samples the co-simulation run saw
    (linearly interpolated by fmpy), against that run at the same communication step h = ME_STEP.
    Returns the warnings the ME run logged. Asserts max |ME - CS| after the feedthrough
    correction below within

        tol = h sum_j K(j h) max_k e_k + max_m sum_(switches k<m) K(t_m - t_(k+1)) dz_k + 10 rtol max |beta|,

    with K the kernel of :func:`_kernel` (the output effect of a unit state error, decaying), term
    by term:
    * the input: CS holds r_k over [t_k, t_(k+1)). fmpy sets the inputs only at the communication
      points and at root-function calls (the end of each internal CVode step), and the solver's
      right-hand side uses the last value set, also for the part of its last internal step beyond
      the communication point. At rtol = 1e-8 CVode's internal steps are shorter than h here
      (but for its first step from the steady start, while the yaw rate has hardly moved), so the
      yaw rate the solver uses in [t_k, t_(k+1)) is a value of the linear interpolation on
      [t_(k-1), t_(k+1)]: within e_k = max(|r_k - r_(k-1)|, |r_(k+1) - r_k|) of r_k. It enters
      the state through B = e_n, and beta^ through the impulse response, whose L1 norm is at
      most h sum_j K(j h);
    * the feedthrough: the ME output at t_k is C z + D r_k, the CS output C z + D r_(k-1) (the
      step's held input): that difference, D (r_k - r_(k-1)), is removed exactly;
    * the band: ME switches at the crossing of the edge, CS at the next communication point (it
      holds vx over the step), so the ME band at t_k is the CS band at t_(k+1) (asserted) and those
      samples are skipped; for less than h at a switch k the state follows the other band's field:
      a state error of at most dz_k = h ||A_from - A_to||_inf max |z| (B = e_n in every band),
      decaying like K afterwards;
    * CVode's local error control (rtol; the nominals scale the absolute tolerance).
    """
    names = ["time", *inputs]
    sig = np.rec.fromarrays([t, *inputs.values()], names=names)
    systems = TfEstimator(data if "tables" in data else {**data, "tables": tft.compute(data)}).systems
    n = len(systems[0][0])
    warnings = []

    def logger(_component, _instance, status, _category, message):
        if status > 0:
            warnings.append(message.decode())
    me = simulate_fmu(str(fmu), fmi_type="ModelExchange", solver="CVode", input=sig, output_interval=ME_STEP,
                      stop_time=float(t[-1]), relative_tolerance=ME_RTOL, record_events=False, logger=logger,
                      output=["beta_hat", *(["mode"] if "mode" in cs else []), *(f"z{k}" for k in range(1, n + 1))])
    assert me["time"].size == t.size and np.allclose(me["time"], t, rtol=0, atol=1e-9)
    D = np.array([s[3] for s in systems])
    A = [np.array(s[0]) for s in systems]
    me_mode = me["mode"] - 1 if "mode" in cs else np.zeros(t.size, dtype=int)
    cs_mode = cs["mode"] - 1 if "mode" in cs else me_mode
    assert np.array_equal(me_mode[:-1], cs_mode[1:])
    dr = np.abs(np.diff(inputs["yaw_rate"]))
    err = me["beta_hat"] - cs["beta_hat"]
    err[1:] -= D[me_mode[1:]] * np.diff(inputs["yaw_rate"])
    K = _kernel(systems, ME_STEP)
    zmax = max(np.abs(me[f"z{k}"]).max() for k in range(1, n + 1))
    dz = np.zeros(t.size - 1)                                   # dz_k, a switch within [t_k, t_(k+1))
    for k in np.nonzero(np.diff(cs_mode))[0]:
        dz[k] = ME_STEP * np.abs(A[cs_mode[k]] - A[cs_mode[k + 1]]).sum(axis=1).max() * zmax
    terms = (ME_STEP * K.sum() * dr.max(),                     # max_k e_k = max_k |r_(k+1) - r_k|
             scipy.signal.fftconvolve(dz, K)[:t.size - 1].max(),
             10 * ME_RTOL * np.abs(cs["beta_hat"]).max())
    worst = float(np.abs(err[me_mode == cs_mode]).max())
    print(f"\nME vs CS at {ME_STEP} s: max |error| {worst:.3g} rad, tolerance {sum(terms):.3g} (input "
          f"{terms[0]:.3g}, {np.count_nonzero(dz)} band switches {terms[1]:.3g}, solver {terms[2]:.3g}); max |beta| "
          f"{np.abs(cs['beta_hat']).max():.3g}")
    assert worst <= sum(terms)
    return warnings


def test_model_exchange_matches_co_simulation_on_w1_steer(pairs, plants, built_fmus):
    """The estimator on CarPlant (delibasi), w1-steer's first 10 s: the CS harness run of the C FMU
    gives the yaw rate samples the ME run is fed."""
    _, c = pairs("SideslipFixedOrderEstimator")
    res = harness.run(get_scenario("w1-steer", duration=10.0), plants("delibasi"), {"c": c}, dt=ME_STEP,
                      vehicle="delibasi")
    assert _check_me(c, built_fmus.design("SideslipFixedOrderEstimator"), res.time,
                     {"yaw_rate": res.measured["yaw_rate"]}, res.observers["c"]) == []


def _record_window(mbds, t0: float, t1: float) -> dict:
    """The MBDS record's yaw rate and speed on [t0, t1] s, linearly interpolated to ME_STEP."""
    t = np.arange(0.0, t1 - t0 + ME_STEP / 2, ME_STEP)
    return {"t": t, "yaw_rate": np.interp(t0 + t, mbds["t"], mbds["yaw_rate"]),
            "vx": np.interp(t0 + t, mbds["t"], mbds["vx"])}


@pytest.mark.slow
def test_model_exchange_matches_co_simulation_with_band_switches(pairs, built_fmus, mbds):
    """The speed-scheduled estimator on 20 s of the MBDS record (9 band switches, up and down)."""
    _, c = pairs("SideslipFixedOrderEstimatorScheduled")
    data = _record_window(mbds, 200.0, 220.0)
    cs = rp.drive(c, data).outputs
    assert np.count_nonzero(np.diff(cs["mode"])) >= 6
    assert _check_me(c, built_fmus.design("SideslipFixedOrderEstimatorScheduled"), data["t"],
                     {"yaw_rate": data["yaw_rate"], "vx": data["vx"]}, cs) == []


# ---------------------------------------------------------------------------------------------
# 3. what is specific to the C models
# ---------------------------------------------------------------------------------------------
#: an order-2 schedule, three bands (one with a leading coefficient 2, one strictly proper)
ORDER_2 = {"estimators": [
    {"num": [0.9, 0.2, 0.05], "den": [8.0, 5.0, 1.0], "vx_band": [10.0, 20.0]},
    {"num": [0.7, -0.1, 0.03], "den": [12.0, 6.0, 2.0], "vx_band": [20.0, 30.0]},
    {"num": [0.5, 0.1], "den": [20.0, 9.0, 1.0], "vx_band": [30.0, 40.0]}]}
STATIC_GAIN = {"estimator": {"num": [0.3], "den": [2.0]}}        # n = 0: beta^ = 0.15 r


@pytest.fixture(scope="module")
def synthetic(tmp_path_factory):
    """(pythonfmu FMU, C FMU) of a data file, built directly (no design, no certificate)."""
    out, made = tmp_path_factory.mktemp("synthetic"), {}

    def build(model: str, name: str, data: dict):
        if name not in made:
            kind = packaging.OBSERVERS[model]
            data = {**data, "tables": tft.compute(data)}       # what designs.run attaches
            made[name] = (packaging.build_fmu(kind, name, data, out / "py"), build_c_fmu(kind, name, data, out / "c", platforms=HOST_ONLY))
        return made[name]
    return build


def _excursions(dt: float, duration: float = 12.0) -> dict:
    """Yaw rate (rad/s) and a speed (m/s) that crosses the ORDER_2 bands, leaves the grid below
    (5 m/s) and above (45 m/s), and comes back each time."""
    t = np.arange(0.0, duration + dt / 2, dt)
    vx = 25.0 + 20.0 * np.sin(2 * np.pi * t / duration) - 16.0 * np.sin(4 * np.pi * t / duration) ** 2
    return {"t": t, "yaw_rate": 0.3 * np.sin(1.3 * t) + 0.1 * np.sin(5.0 * t + 0.4), "vx": vx}


def test_order_2_schedule_with_grid_excursions_equals_python(synthetic):
    py, c = synthetic("SideslipFixedOrderEstimatorScheduled", "TfOrder2", ORDER_2)
    for dt in (DEFAULT_STEP, OTHER_DT, 0.01):
        data = _excursions(dt)
        a, b = rp.drive(py, data), rp.drive(c, data)
        _assert_equal(a.outputs, b.outputs, f"order-2 schedule dt {dt}")
        assert set(b.outputs["mode"]) == {1, 2, 3}
        warned = _messages(b.logs)
        assert warned == _messages(a.logs) and len(warned) == 2            # one per excursion
        assert all("outside the scheduling grid [10, 40] m/s" in m for m in warned)


def test_order_2_model_exchange_matches_co_simulation(synthetic):
    """Band switches both ways and the grid left below and above: the events at the crossings,
    one warning per excursion as in co-simulation."""
    _, c = synthetic("SideslipFixedOrderEstimatorScheduled", "TfOrder2", ORDER_2)
    data = _excursions(ME_STEP, duration=6.0)
    run = rp.drive(c, data)
    warned = _check_me(c, ORDER_2, data["t"], {"yaw_rate": data["yaw_rate"], "vx": data["vx"]}, run.outputs)
    assert len(warned) == len(_messages(run.logs)) == 2
    assert all("outside the scheduling grid [10, 40] m/s" in m for m in warned)


def test_static_gain_is_co_simulation_only_and_equals_python(synthetic):
    py, c = synthetic("SideslipFixedOrderEstimator", "TfStaticGain", STATIC_GAIN)
    assert read_model_description(str(c)).modelExchange is None
    data = {k: v for k, v in _excursions(OTHER_DT, duration=2.0).items() if k != "vx"}
    a, b = rp.drive(py, data), rp.drive(c, data)
    _assert_equal(a.outputs, b.outputs, "static gain")
    assert np.allclose(b.outputs["beta_hat"][1:], 0.15 * data["yaw_rate"][:-1], rtol=1e-15, atol=0)


def test_kalman_speed_clamp_warns_once_per_excursion_like_python(pairs):
    py, c = pairs("SideslipKalmanFilter")
    t = np.arange(0.0, 8.0 + DEFAULT_STEP / 2, DEFAULT_STEP)
    vx = np.select([t < 2, t < 4, t < 6], [20.0 - 10.0 * t, 20.0 * (t - 2), 40.0 + 100.0 * (t - 4)], 20.0)   # <= 240 m/s (declared max 250)
    data = {"t": t, "delta": 0.02 * np.sin(2 * t), "vx": vx, "yaw_rate": 0.1 * np.sin(2 * t - 0.2),
            "ay": 2.0 * np.sin(2 * t - 0.3)}
    a, b = rp.drive(py, data), rp.drive(c, data)
    _assert_equal(a.outputs, b.outputs, "Kalman filter, vx through 0 and 240 m/s")
    warned = _messages(b.logs)
    assert warned == _messages(a.logs) and len(warned) == 2
    assert all("outside [1, 200] m/s" in m for m in warned)


@pytest.mark.parametrize("artefact, inputs", [
    ("SideslipFixedOrderEstimator", {"yaw_rate": 0.2}),
    ("SideslipKalmanFilter", {"delta": 0.01, "vx": 20.0, "yaw_rate": 0.1, "ay": 1.0})])
def test_a_step_whose_map_is_not_finite_is_refused_like_python(pairs, artefact, inputs):
    """h = 1e308 s (it would overflow h A): both backends refuse the step, longer than the declared
    longest step, with the same error and hold the state; the next step goes on from it."""
    outs, logs = {}, {}
    for backend, path in zip(("py", "c"), pairs(artefact)):
        f = harness.FmuInstance(backend, path)
        try:
            f.start(inputs)
            f.slave.doStep(0.0, DEFAULT_STEP)
            held = f.get_outputs()
            with pytest.raises(Exception, match="DoStep"):
                f.slave.doStep(DEFAULT_STEP, 1e308)
            assert f.get_outputs() == held
            f.slave.doStep(DEFAULT_STEP, DEFAULT_STEP)
            outs[backend], logs[backend] = f.get_outputs(), _messages(f.logs)
        finally:
            f.close()
    assert outs["c"] == outs["py"] and logs["c"] == logs["py"] and len(logs["c"]) == 1
    assert "communication step 1e+308 s exceeds this FMU's longest step" in logs["c"][0]


@pytest.mark.parametrize("data, culprit", [
    ({"estimator": {"num": [1.0], "den": [-1.0, 1.0]}}, "not Hurwitz"),
    ({"estimator": {"num": [1.0], "den": [math.comb(16, k) for k in range(17)]}},      # (s + 1)^16
     "order 16 exceeds the native C backend's limit 15"),
    ({"estimators": [{"num": [1.0], "den": [1.0, 1.0], "vx_band": [0.0, 1.0]},
                     {"num": [1.0], "den": [1.0, 1.0], "vx_band": [2.0, 3.0]}]}, r"estimators\[1\].vx_band")])
def test_tf_emitter_refuses_what_the_runtime_refuses(data, culprit):
    with pytest.raises(ValueError, match=culprit):
        tf_emitter.emit({**data, "tables": tft.compute(data)})      # the tables' checks, then the C limit


def test_kalman_emitter_is_co_simulation_only_and_refuses_what_the_runtime_refuses(built_fmus, tmp_path):
    design = built_fmus.design("SideslipKalmanFilter")
    assert kalman_emitter.emit(design).states == ()
    bad = copy.deepcopy(design)
    bad["noise"]["r"] = [[1.0, 0.0], [0.0, -1.0]]
    bad["tables"] = tables.compute(bad)
    kind = packaging.OBSERVERS["SideslipKalmanFilter"]
    with pytest.raises(packaging.PackagingError, match="noise.r must be positive definite"):
        build_c_fmu(kind, "Bad", bad, tmp_path)           # refused before any C is written
