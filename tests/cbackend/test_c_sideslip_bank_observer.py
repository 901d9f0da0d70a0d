"""Native C model of paper 000's switched PI observer (``fmu_src/c/sideslip_bank_observer.c``) against its
Python twin (``fmu_src/sideslip_bank_observer.py``), for the four FMUs of the model file
``sideslip_bank_observer``: SideslipBankObserver (speed bands, models at the measured speed,
validity with integral freeze), ...Tire (tire-slip modes with hysteresis), ...Paper (speed bands
at fixed grid speeds) and ...TirePaper; all four with the first-order input hold.

1. Co-simulation equivalence, bit for bit (the Python runtime evaluates the same tables and maps
   with C's operations in C's order; the 1e-9 relative bound is checked first, to report the size
   of a difference), on every scenario on which ``latobs validate`` runs these observers by default (every CarPlant
   scenario; the stiffness sweeps on the plant vehicle they need, delibasi) and ``latobs demo``'s
   noisy bank-braking run: the four Python and the four C FMUs in one harness run per scenario (so
   all see the same inputs), at the default step (the emitter's tables) and at 2 ms (maps and RK4
   substeps computed by the C model).
2. ModelExchange against co-simulation at 1 ms, fmpy CVode: see
   ``test_model_exchange_equals_co_simulation`` for the inputs and the tolerances.
3. The C specifics: steps of changing size (the tables, the RK4 substeps, the maps computed for
   another step) through the hold, the grid excursions and the rate-limited validity messages,
   against the Python FMU message for message; the design options no built FMU has (zero-order
   hold, no validity, mixed fixed and measured model speeds, no freeze, the RK4 substeps at the
   default step) against the Python runtime; the start at the first step; a refused absurd step;
   the ME derivatives against the Python runtime's matrices; the ME state events at the band
   edges and at vx_hold.
"""
from __future__ import annotations

import json
import math
from ctypes import c_double

import numpy as np
import pytest
from fmpy import extract, instantiate_fmu, read_model_description, simulate_fmu

from latobs import cbackend, packaging
from latobs.fmu_src.sideslip_bank_observer import SwitchedPIObserver
from latobs.native_guard import find_compiler
from latobs.pipeline import PLANT_NOISE
from latobs.synthesis import design_file, tables
from latobs.validation import harness
from latobs.validation.harness import FmuInstance, NoiseSpec
from latobs.validation.scenarios import SCENARIOS, StiffnessSweep

from c_models import assert_equivalent, run_cs
from conformance_runs import declared_max_step
from conftest import HOST_ONLY

pytestmark = [pytest.mark.slow,
              pytest.mark.skipif(find_compiler() is None, reason="no C compiler (set CC, or install cc/gcc)")]

NAMES = [n for n, k in packaging.OBSERVERS.items() if k.model_module == "sideslip_bank_observer"]
PLANT = "CarPlant"
SCENARIOS_000 = [n for n, sc in SCENARIOS.items() if sc.plant == PLANT]
SWEEP_VEHICLE = "delibasi"     # the stiffness sweeps need a vehicle with a stiffness box
INPUTS = ("delta", "vx", "yaw_rate", "roll_angle", "roll_rate")
ESTIMATES = ("beta_hat", "yaw_rate_hat", "roll_angle_hat", "roll_rate_hat", "bank_angle_hat")


@pytest.fixture(scope="module")
def sweep_plant(built_fmus, tmp_path_factory):
    """CarPlant for the stiffness sweeps' vehicle (``latobs validate --plant-vehicle delibasi``)."""
    return packaging.package_plant(PLANT, SWEEP_VEHICLE, tmp_path_factory.mktemp("plant_000"))


# ---------------------------------------------------------------------------------------------
# 1. co-simulation equivalence with the Python runtime
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("scenario, dt, noise", [(s, 0.005, False) for s in SCENARIOS_000]
                         + [("bank-braking", 0.005, True), ("sine-with-dwell", 0.002, False)])
def test_observers_equal_python_runtime(built_fmus, sweep_plant, scenario, dt, noise):
    sweep = isinstance(SCENARIOS[scenario], StiffnessSweep)
    fmus = {f"{k}:{n}": (built_fmus.path(n) if k == "py" else built_fmus.c_path(n)) for n in NAMES for k in ("py", "c")}
    res = harness.run(scenario, sweep_plant if sweep else built_fmus.path(PLANT), fmus, dt=dt,
                      vehicle=SWEEP_VEHICLE if sweep else "sedan",
                      noise=NoiseSpec(signals=PLANT_NOISE[PLANT]) if noise else None)
    for n in NAMES:
        py, c = res.observers[f"py:{n}"], res.observers[f"c:{n}"]
        assert_equivalent(py, c, f"{n} on {scenario} dt={dt} noise={noise}")
        # the Python runtime evaluates the same tables and maps with C's operations in C's order
        assert all(np.array_equal(py[k], c[k]) for k in (*ESTIMATES, "mode", "valid")), f"{n}: not bit-identical"


# ---------------------------------------------------------------------------------------------
# 2. ModelExchange against co-simulation
# ---------------------------------------------------------------------------------------------
ME_H, ME_T = 1e-3, 8.0          # s: the comparison's sample step and duration
ME_RTOL = 1e-10                 # CVode's relative tolerance
KNOTS = {                       # piecewise constant inputs: (from time s, value)
    "vx": [(0, 24.0), (1.5, 17.0), (3.0, 10.0), (4.0, 0.5), (4.6, 12.0), (6.0, 30.0), (7.0, 22.0)],
    "delta": [(0, 0.0), (0.5, 0.03), (2.0, -0.05), (3.5, 0.02), (5.0, -0.04), (6.5, 0.01)],
    "yaw_rate": [(0, 0.0), (0.5, 0.2), (2.0, -0.25), (3.5, 0.1), (5.0, -0.3), (6.5, 0.05)],
    "roll_angle": [(0, 0.0), (0.5, 0.02), (2.0, -0.03), (3.5, 0.01), (5.0, -0.03), (6.5, 0.0)],
    "roll_rate": [(0, 0.0), (0.5, 0.05), (2.0, -0.05), (3.5, 0.02), (5.2, 0.0)],
}
JUMPS = sorted({ts for knots in KNOTS.values() for ts, _ in knots if ts > 0})


def _knot_inputs(t: float) -> dict:
    return {k: [v for ts, v in knots if ts <= t + 1e-12][-1] for k, knots in KNOTS.items()}


def _cs_knots(fmu) -> dict:
    """Co-simulation of the KNOTS inputs at ME_H; at each jump a 1 us step first, so that the
    first-order hold's slope over the rest of that step and the next is 0: the inputs the
    observer integrates are the piecewise constant KNOTS, as in the ME run (the 1 us ramp moves
    the state by ~1e-9 of the jump's effect)."""
    f = FmuInstance("cs", fmu)
    try:
        rows = [f.start(_knot_inputs(0.0))]
        grid = np.arange(round(ME_T / ME_H) + 1) * ME_H
        jumps = set(np.round(JUMPS, 9))
        for t0 in grid[:-1]:
            u = _knot_inputs(t0)
            f.set_inputs(u)
            for h in ((1e-6, ME_H - 1e-6) if round(t0, 9) in jumps else (ME_H,)):
                f.slave.doStep(t0, h)
            rows.append(f.get_outputs())
        return {k: np.array([r[k] for r in rows]) for k in rows[0]} | {"time": grid}
    finally:
        f.close()


def _me_knots(fmu, log: list) -> np.ndarray:
    rows = [(0.0, *_knot_inputs(0.0).values())]
    for tj in JUMPS:
        rows += [(tj, *_knot_inputs(tj - 1e-9).values()), (tj, *_knot_inputs(tj).values())]
    rows.append((ME_T, *_knot_inputs(ME_T).values()))
    u = np.array(rows, dtype=[("time", float)] + [(k, float) for k in KNOTS])
    return simulate_fmu(str(fmu), fmi_type="ModelExchange", solver="CVode", input=u, start_time=0.0, stop_time=ME_T,
                        output_interval=ME_H, relative_tolerance=ME_RTOL, record_events=True,
                        output=[*ESTIMATES, "mode", "valid"],
                        logger=lambda c, name, status, cat, msg: log.append(msg.decode()))


def _runs(x) -> list:
    """[(value, first row), ...] of the runs of equal values of x."""
    starts = [0, *(np.flatnonzero(np.diff(x)) + 1)]
    return [(int(x[i]), int(i)) for i in starts]


@pytest.mark.parametrize("name", NAMES)
def test_model_exchange_equals_co_simulation(built_fmus, name):
    """fmpy CVode (rtol 1e-10) against a 1 ms co-simulation of the C FMU, on piecewise constant
    inputs that visit every mode, leave the design grid, stop (vx < vx_hold) and resume, and make
    the estimates cross the tire-mode and validity thresholds.

    Why piecewise constant inputs: fmpy's CVode callback does not set the inputs where it
    evaluates the derivatives (only its root function does), so a continuously varying input
    reaches the ME FMU late by up to an internal step; and the co-simulation's first-order hold
    extrapolates a jump over the next step, which no ME input reproduces. With constant inputs
    between jumps (fmpy input events; the co-simulation takes a 1 us step at each jump, see
    ``_cs_knots``) both integrate the same ODE. The ME samples are fmpy's before the event at
    a sample (the co-simulation row k holds the step decided at t_{k-1}).
    Asserted:
      * until the first switch caused by the states (tire premise, validity from the estimates):
        mode and valid equal, the estimates within 1e-5 of each output's peak: the two integrators
        alone, RK4 at 1 ms on the fastest observer pole (|lambda| <= 110 /s: local error
        (h lambda)^5 / 120 <= 1.3e-7 per step, over the ~10 steps of a transient) and CVode at
        1e-10 (its global error ~1e4 rtol); measured <= 1.0e-6 (TirePaper), <= 1.5e-7 for the rest;
      * afterwards the co-simulation, deciding at its step starts, switches up to a step after the
        crossing that CVode locates; the states then differ by up to h |f_new - f_old| per such
        switch, and a later borderline decision (the premise or the validity grazing a threshold)
        may differ: mode and valid disagree on at most 20 of the 8 000 samples (measured <= 5), the
        estimates stay within 5e-3 of the peak (measured <= 1.5e-3, TirePaper's mode switches)."""
    fmu = built_fmus.c_path(name)
    log: list = []
    cs = _cs_knots(fmu)
    me = _me_knots(fmu, log)
    t = cs["time"]
    idx = np.searchsorted(np.round(me["time"], 9), np.round(t, 9), side="left")   # first sample at t_k
    assert np.allclose(me["time"][idx], t, rtol=0, atol=1e-9)
    by_input = set(np.round(np.array(JUMPS) + ME_H, 9))           # rows of input-triggered switches
    switches = [i for k in ("mode", "valid") for i in np.flatnonzero(np.diff(cs[k])) + 1]
    # the last row before the first switch caused by the states (the ME may have switched there)
    quiet = min([i for i in switches if round(t[i], 9) not in by_input], default=len(t) + 1) - 1
    for k in ("mode", "valid"):
        a, b = me[k][idx], cs[k]
        assert np.array_equal(a[:quiet], b[:quiet]), f"{name} {k}: ME {_runs(a)}, CS {_runs(b)}"
        assert np.sum(a != b) <= 20, f"{name} {k}: ME {_runs(a)}, CS {_runs(b)}"
    for k in ESTIMATES:
        err, scale = np.abs(me[k][idx] - cs[k]), np.max(np.abs(cs[k]))
        assert np.max(err[:quiet]) <= 1e-5 * scale, (name, k, t[np.argmax(err[:quiet])])
        assert np.max(err) <= 5e-3 * scale, (name, k, t[np.argmax(err)])
    assert {1, 2} <= set(cs["mode"]) and set(cs["valid"]) == {0, 1}
    assert sum("observer frozen" in m for m in log) == 1 and sum("resumes" in m for m in log) == 1
    assert sum("outside the design grid" in m for m in log) >= 1


def test_me_state_events_at_the_band_edges_and_the_hold(built_fmus):
    """The fixed-speed design (its derivatives do not depend on vx, so fmpy's late inputs do not
    matter): a continuous speed ramp through every band, out of the grid on both sides and through
    vx_hold; the mode changes exactly where vx crosses an edge (CVode's root finding), the
    estimates are held while vx < vx_hold, and the warnings are those of a co-simulation."""
    name = "SideslipBankObserverPaper"
    edges = built_fmus.design(name)["switching"]["edges"]
    knots_t, knots_v = [0.0, 2.0, 4.0, 5.0, 6.0], [8.0, 32.0, 10.0, 0.0, 5.0]
    u = np.array([(t, 0.01, v, 0.02, 0.01, 0.0) for t, v in zip(knots_t, knots_v)],
                 dtype=[("time", float)] + [(k, float) for k in INPUTS])
    log: list = []
    res = simulate_fmu(str(built_fmus.c_path(name)), fmi_type="ModelExchange", solver="CVode", input=u,
                       start_time=0.0, stop_time=6.0, output_interval=0.01, relative_tolerance=1e-8,
                       record_events=True, output=["mode", "valid", *ESTIMATES],
                       logger=lambda c, n, status, cat, msg: log.append(msg.decode()))

    def crossings(level):
        return [t0 + (level - v0) / (v1 - v0) * (t1 - t0) for t0, t1, v0, v1 in
                zip(knots_t, knots_t[1:], knots_v, knots_v[1:]) if (v0 - level) * (v1 - level) < 0]

    want = sorted(t for e in edges[1:-1] for t in crossings(e))
    changes = [(res["time"][i], res["mode"][i] - res["mode"][i - 1]) for i in range(1, len(res))
               if res["mode"][i] != res["mode"][i - 1]]
    assert len(changes) == len(want) == 4                          # up through both edges, down again
    for (t_got, step), t_want, way in zip(changes, want, (1, 1, -1, -1)):
        assert t_got == pytest.approx(t_want, abs=1e-9) and step == way
    t_in, t_out = crossings(1.0)                                   # vx_hold = 1 m/s
    frozen = (res["time"] > t_in + 1e-9) & (res["time"] < t_out - 1e-9)
    # frozen entered from below the grid (vx falls from 10 to 0 m/s): valid = 0 since the grid's end
    assert frozen.sum() > 10 and np.all(res["valid"][frozen] == 0)
    grid = (res["time"] > 1e-9) & np.array([edges[0] < float(np.interp(t, knots_t, knots_v)) < edges[-1]
                                             for t in res["time"]])
    assert np.all(res["valid"][grid & (res["time"] < 3.0)] == 1)
    for k in ESTIMATES:
        held = res[k][frozen]
        assert np.all(held == held[0]) and held[0] != 0.0, k
    assert sum("observer frozen" in m for m in log) == 1 and sum("observer resumes" in m for m in log) == 1
    assert sum("clamped to the nearest" in m for m in log) == 2


# ---------------------------------------------------------------------------------------------
# 3. specifics of the C model
# ---------------------------------------------------------------------------------------------
def _lockstep_steps() -> list:
    """Steps of 5, 2, 12.5 and 1 ms (the tables, the RK4 substeps, the maps computed for another
    step) through every band, the grid left on both sides, vx_hold = 2 m/s (parameter) crossed
    and reversing, yaw-rate pulses entering valid = 0 every 80 ms (rate-limited messages)."""
    speeds = [20.0, 24.0, 31.0, 17.0, 1.5, -3.0, 12.0, 5.0, 9.0, 22.0, 27.0, 15.0]
    hs = (0.005, 0.002, 0.005, 0.0125, 0.005, 0.001)
    steps = []
    for k in range(480):
        pulse = (k % 16) < 4
        steps.append((hs[k % len(hs)], {"vx": speeds[(k // 10) % len(speeds)], "delta": 0.02 * np.sin(k / 7),
                                        "yaw_rate": 0.3 if pulse else 0.02, "roll_angle": 0.01 * np.sin(k / 5),
                                        "roll_rate": 0.02 * np.cos(k / 5)}))
    return steps


@pytest.mark.parametrize("name", NAMES)
def test_steps_of_changing_size_and_every_warning_equal_python(built_fmus, name):
    u0 = {"vx": 20.0, "delta": 0.0, "yaw_rate": 0.05, "roll_angle": 0.0, "roll_rate": 0.0}
    longest = declared_max_step(built_fmus.path(name))     # (the paper-faithful tire design: 5 ms)
    steps, params = [(min(h, longest), u) for h, u in _lockstep_steps()], {"vx_hold": 2.0}
    py, py_log = run_cs(built_fmus.path(name), "py", u0, steps, params)
    c, c_log = run_cs(built_fmus.c_path(name), "c", u0, steps, params)
    assert_equivalent({k: [o[k] for o in py] for k in py[0]}, {k: [o[k] for o in c] for k in c[0]}, name)
    assert c_log == py_log
    assert sum("observer frozen" in m for m in c_log) == 4 and sum("resumes" in m for m in c_log) == 4
    assert sum("outside the design grid" in m for m in c_log) >= 8
    assert any("more entries since the last message not logged" in m for m in c_log)
    assert len({o["mode"] for o in c}) >= 2 and {o["valid"] for o in c} == {0, 1}


VARIANTS = {   # the runtime's other options, on designs of the session build: (FMU, change, steps)
    "zero-order hold, no validity, a measured-speed mode among fixed ones": (
        "SideslipBankObserverPaper",
        lambda d: (d["runtime"].update(input_hold="zero_order"), d.pop("validity"),
                   d["modes"][1].update(model_speed={"kind": "measured", "range": d["modes"][1]["scheduling"]["range"]})),
        _lockstep_steps()),
    "zero-order hold, tire modes, validity without the freeze": (
        "SideslipBankObserverTirePaper",
        lambda d: (d["runtime"].update(input_hold="zero_order"), d["validity"].update(freeze_integral=False)),
        _lockstep_steps()),
    "first-order hold, validity with the freeze, fixed-speed modes": (
        "SideslipBankObserverPaper", lambda d: d["validity"].update(freeze_integral=True), _lockstep_steps()),
    "max_step 50 us: 100 RK4 substeps at the default step (too many for a Taylor table)": (
        "SideslipBankObserverTirePaper", lambda d: d["runtime"].update(max_step=5e-5),
        [(0.005, u) for _, u in _lockstep_steps()[:240]]),
}


@pytest.mark.parametrize("variant", VARIANTS)
def test_design_variants_equal_the_python_runtime(built_fmus, tmp_path, variant):
    """The design options no FMU of ``latobs build`` has: the C FMU built from the changed design
    against the Python runtime itself, step for step, outputs and warnings."""
    name, change, steps = VARIANTS[variant]
    data = json.loads(design_file.dumps(built_fmus.design(name)))          # a copy, as plain data
    change(data)
    data["tables"] = tables.compute(data)                                 # the changed design's tables
    fmu = cbackend.build_c_fmu(packaging.OBSERVERS[name], name, data, tmp_path, platforms=HOST_ONLY)
    u0 = {"vx": 20.0, "delta": 0.0, "yaw_rate": 0.05, "roll_angle": 0.0, "roll_rate": 0.0}
    steps = [(min(h, declared_max_step(fmu)), u) for h, u in steps]
    c, c_log = run_cs(fmu, "c", u0, steps)
    rt = SwitchedPIObserver(data, {})
    rt.initialize(u0)
    py = [dict(rt.y)]
    for h, u in steps:
        rt.step(h, u)
        py.append(dict(rt.y))
    assert_equivalent({k: [o[k] for o in py] for k in py[0]}, {k: [o[k] for o in c] for k in py[0]}, variant)
    assert [o[k] for o in py for k in ESTIMATES] == [o[k] for o in c for k in ESTIMATES]   # bit for bit
    assert [m.split(": ", 1)[1] for m in c_log] == [msg for _, msg in rt.events]
    assert len({o["mode"] for o in c}) >= 2


def test_initialisation_without_finite_inputs_starts_at_the_first_step(built_fmus):
    """NaN inputs at initialisation: no start there (a warning of the FMI layer); the first step
    starts from its own inputs, with the first-order hold's slope 0, as the Python FMU does."""
    name = "SideslipBankObserver"
    u0 = {"vx": 20.0, "delta": 0.0, "yaw_rate": float("nan"), "roll_angle": 0.0, "roll_rate": 0.0}
    steps = _lockstep_steps()[:60]
    py, _ = run_cs(built_fmus.path(name), "py", u0, steps)
    c, c_log = run_cs(built_fmus.c_path(name), "c", u0, steps)
    assert_equivalent({k: [o[k] for o in py[1:]] for k in py[1]}, {k: [o[k] for o in c[1:]] for k in c[1]}, name)
    assert any("non-finite inputs at initialisation" in m for m in c_log)


def test_absurd_step_is_refused_with_the_state_kept(built_fmus):
    """h = 1e300 s (1e303 RK4 substeps; the Python runtime would loop for ever) is refused with
    an error naming it; the next steps proceed as if it had not been asked."""
    name = "SideslipBankObserver"
    u = {"vx": 15.0, "delta": 0.01, "yaw_rate": 0.1, "roll_angle": 0.01, "roll_rate": 0.0}
    u2 = u | {"yaw_rate": 0.12, "delta": 0.012}
    ref, _ = run_cs(built_fmus.c_path(name), "ref", u, [(0.005, u), (0.005, u2), (0.005, u)])
    got, log = run_cs(built_fmus.c_path(name), "c", u, [(0.005, u), (1e300, u2), (0.005, u2), (0.005, u)])
    assert got[2] is None and any(m.startswith("[ERROR]") and "communication step 1e+300 s exceeds" in m
                                  for m in log), log
    assert [got[0], got[1], got[3], got[4]] == ref


#: steps below the first-order hold's FOH_MIN_BASE (2^-30 s; the smallest subnormal, 1e-310, where 1/h
#: overflows), alternating with ordinary and long ones (issue 47, item 2)
TINY_STEPS = [0.005, 0.005, 5e-324, 0.005, 1e-310, 0.005, 1e-12, 1e-12, 0.002, 5e-324, 5e-324, 0.005, 0.1,
              5e-324, 0.1, 2.0 ** -30, 0.005, 1e-300, 0.002]


@pytest.mark.parametrize("name", NAMES)
def test_subnormal_and_alternating_tiny_steps_stay_finite_and_equal_python(built_fmus, name):
    """doStep(5e-324), (1e-310), tiny steps between ordinary and long ones: every step accepted, every
    estimate finite, in both backends bit for bit (the first-order hold used to divide by the
    previous step, 5e-324 s, and 1/h overflowed in the fixed-speed maps: NaN for good, status OK);
    the steps after the last tiny one as if the tiny ones had been a single sample of the hold."""
    longest = declared_max_step(built_fmus.path(name))
    u0 = {"vx": 15.0, "delta": 0.01, "yaw_rate": 0.1, "roll_angle": 0.01, "roll_rate": 0.0}
    steps = [(min(h, longest), u0 | {"delta": 0.01 + 0.002 * (k % 3), "yaw_rate": 0.1 + 0.01 * (k % 4)})
             for k, h in enumerate(TINY_STEPS)]
    py, py_log = run_cs(built_fmus.path(name), "py", u0, steps)
    c, c_log = run_cs(built_fmus.c_path(name), "c", u0, steps)
    assert None not in py and None not in c, (py_log, c_log)
    for out in (py, c):
        assert all(np.isfinite(o[k]) for o in out for k in ESTIMATES), (name, out)
    assert [o[k] for o in py for k in ESTIMATES] == [o[k] for o in c for k in ESTIMATES]   # bit for bit
    rt = SwitchedPIObserver(built_fmus.design(name), {})
    rt.initialize(u0)
    for h, u in steps:
        rt.step(h, u)
    assert [rt.y[k] for k in ESTIMATES] == [py[-1][k] for k in ESTIMATES]


def test_the_hold_keeps_its_sample_over_tiny_steps(built_fmus):
    """The first-order hold's rule below FOH_MIN_BASE in both runtimes (their constants equal): a
    tiny step extrapolates nothing and keeps the previous sample, so that the next slope is taken
    over the real interval; with steps >= FOH_MIN_BASE nothing changes."""
    from pathlib import Path
    import re

    import latobs.fmu_src.sideslip_bank_observer as rtmod

    c_src = (Path(rtmod.__file__).parent / "c" / "sideslip_bank_observer.c").read_text()
    assert float.fromhex(re.search(r"#define FOH_MIN_BASE (\S+)", c_src).group(1)) == rtmod.FOH_MIN_BASE
    data = built_fmus.design("SideslipBankObserver")
    u = {"vx": 15.0, "delta": 0.01, "yaw_rate": 0.1, "roll_angle": 0.01, "roll_rate": 0.0}
    a, b = SwitchedPIObserver(data, {}), SwitchedPIObserver(data, {})
    for rt in (a, b):
        rt.initialize(u)
        rt.step(0.005, u)
    a.step(1e-12, u | {"yaw_rate": 0.5})            # a tiny step: a sample the hold does not take
    assert a._prev[0] == b._prev[0] and a._prev[1] == 0.005 + 1e-12
    a.step(0.005, u | {"yaw_rate": 0.11})
    assert all(math.isfinite(a.y[k]) for k in ESTIMATES)


def _me_instance(fmu, tmp_path, inputs: dict, log: list):
    md = read_model_description(str(fmu))
    m = instantiate_fmu(extract(str(fmu), unzipdir=str(tmp_path / fmu.stem)), md, fmi_type="ModelExchange",
                        logger=lambda c, name, status, cat, msg: log.append(msg.decode()))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    m.setupExperiment(startTime=0.0)
    m.enterInitializationMode()
    m.setReal([vr[k] for k in inputs], list(inputs.values()))
    m.exitInitializationMode()
    m.newDiscreteStates()
    m.enterContinuousTimeMode()
    return m, vr


def _me_event(m, vr, inputs: dict):
    m.enterEventMode()
    m.setReal([vr[k] for k in inputs], list(inputs.values()))
    m.newDiscreteStates()
    m.enterContinuousTimeMode()


def _me_derivatives(m, vr, s, inputs: dict) -> np.ndarray:
    """The derivatives at the states s (5, or 7 with the relaxed axle forces)."""
    ns = len(s)
    m.setReal([vr[k] for k in inputs], list(inputs.values()))
    m.setContinuousStates((c_double * ns)(*s), ns)
    dx = (c_double * ns)()
    m.getDerivatives(dx, ns)
    return np.array(dx[:])


@pytest.mark.parametrize("name", ["SideslipBankObserver", "SideslipBankObserverTire", "SideslipBankObserverPaper"])
def test_me_derivatives_equal_the_python_runtimes_matrices(built_fmus, tmp_path, name):
    """s' = M s + G [y; delta] of the active map index (the mode, the frozen-integral map while
    valid = 0 with the freeze) at the model speed of the runtime (fixed, or vx clamped to the
    mode's range; vx out of the grid too), at random states; 0 while vx < vx_hold."""
    design = built_fmus.design(name)
    rt = SwitchedPIObserver(design, {})
    rng = np.random.default_rng(11)
    log: list = []
    m, vr = _me_instance(built_fmus.c_path(name), tmp_path, dict(zip(INPUTS, (0.0, 20.0, 0.0, 0.0, 0.0))), log)
    seen = set()
    for vx, yaw in [(20.0, 0.05), (8.0, 0.05), (14.0, 0.05), (26.0, 0.05), (40.0, 0.05), (3.0, 0.05), (20.0, 0.5)]:
        w = [yaw, 0.01, 0.02, 0.01]                          # y = [yaw rate, roll angle, roll rate], delta
        u = dict(zip(INPUTS, (w[3], vx, *w[:3])))
        _me_event(m, vr, u)                                  # the discrete state of these inputs
        mode, valid = m.getInteger([vr["mode"], vr["valid"]])
        idx = mode - 1 + (rt.nm if rt.freeze and not valid else 0)
        seen.add(idx)
        M, G = rt.system(idx, rt.model_v(mode - 1, vx))
        for _ in range(3):
            s = 0.05 * rng.standard_normal(rt.n + 1)
            want = np.array(M) @ s + np.array(G) @ np.array(w)
            np.testing.assert_allclose(_me_derivatives(m, vr, s, u), want, rtol=0, atol=1e-12 * np.max(np.abs(want)))
    assert len(seen) >= 2 and (not rt.freeze or max(seen) >= rt.nm)
    _me_event(m, vr, dict(zip(INPUTS, (0.01, 0.4, 0.1, 0.0, 0.0))))
    assert not np.any(_me_derivatives(m, vr, rng.standard_normal(rt.n + 1), dict(zip(INPUTS, (0.01, 0.4, 0.1, 0.0, 0.0)))))
    m.terminate()
    m.freeInstance()
    assert sum("observer frozen" in msg for msg in log) == 1
