"""Property-based tests (hypothesis) of every FMU ``latobs build`` makes (issue 10, item 6).

Parametrised over ``latobs.packaging.OBSERVERS`` and ``PLANTS``: a new FMU gets them automatically.
Hypothesis draws, per FMU, FMI call programs: random input values (realistic ones, and extreme but
finite ones: up to +-1e300, +-1e-300, 0, the smallest subnormal, jumps between them from one step
to the next; now and then a non-finite one), random communication steps (log-uniform over every
positive double up to 1e300 s, the smallest subnormal 5e-324 s included, and runs alternating tiny
and long steps; now and then a zero, negative or non-finite one), parameters inside and outside
their declared range, and calls out of order (doStep or get before initialisation, exitInitializationMode without enter,
double initialisation, set/step/get after terminate, fmi2Reset anywhere). Asserted:

* the host never crashes (the program ends and the host process is alive), never hangs: every
  call returns within ``CALL_SECONDS``;
* no call to get returns a non-finite output, or an Integer output outside its declared
  [min, max], unless the doStep just before it returned fmi2Discard or worse; a get after a
  refused doStep returns the outputs of the get before it (the state kept);
* a step with an input outside its declared [min, max] or longer than the FMU's declared longest
  step is refused (fmi2Discard or worse), and the state is kept: the run then continues exactly as
  if the step had not been asked;
* after fmi2Reset, anywhere in a program, a run is bit-identical (every status and every output)
  to the same run on a freshly instantiated FMU;
* (not random) run unconnected from its start values, every FMU steps with fmi2OK throughout; the
  longest step is refused identically (same messages) by both backends; at its declared longest
  step every FMU's outputs stay within 10 % of their peak of a 1 ms run (the measure behind each
  ModelSpec.max_step; not LateralIntervalObserver's bounds, see ``ACCURACY_NOT_COMPARED``);
* (not random) with constant realistic inputs, a 0.1 s communication step keeps the outputs within
  10 times those at 10 ms, or refuses the step (LateralIntervalObserver refuses steps longer
  than its max_communication_step(); an FMU that fails it goes in ``UNBOUNDED_AT_LONG_STEPS``, a strict xfail).

Each FMU runs in a worker process (``conformance_runs.py serve``, the FMU extracted once, one
fresh instance per program): a crash kills the worker, never pytest, and is reported with the
program that caused it (the worker is restarted for the next example). Hypothesis runs in the
test process (derandomized: the same examples on every run; no example database), so shrinking
works as usual across the worker boundary.
"""
from __future__ import annotations

import functools
import json
import math
import os
import select
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest
from fmpy import read_model_description, simulate_fmu
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from latobs import packaging

pytestmark = pytest.mark.slow
RUNNER = Path(__file__).resolve().parents[1] / "conformance_runs.py"
FMU_NAMES = [*packaging.OBSERVERS, *packaging.PLANTS]
from conftest import C_NAMES, FMU_VARIANTS  # noqa: E402  (every FMU, pythonfmu and native C)
from conformance_runs import STEADY, SUBNORMAL_STEPS, declared_max_step  # noqa: E402
#: examples per FMU and property; LATOBS_PROPERTY_EXAMPLES=500 for a deeper (local) search
EXAMPLES = int(os.environ.get("LATOBS_PROPERTY_EXAMPLES", "25"))
SETTINGS = settings(max_examples=EXAMPLES, deadline=None, derandomize=True, database=None,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
#: s, the longest any single FMI call may take (a host must never hang on a step)
CALL_SECONDS = 1.0


# ---------------------------------------------------------------------------------------------
# the worker (one process per FMU)
# ---------------------------------------------------------------------------------------------
class HostCrash(RuntimeError):
    """The FMU took its host process down."""


class Worker:
    def __init__(self, path: Path):
        self.path = path
        self.proc = None
        md = read_model_description(str(path))
        self.inputs = [v.name for v in md.modelVariables if v.causality == "input"]
        self.params = {v.name: (v.min, v.max) for v in md.modelVariables
                       if v.causality == "parameter" and v.type == "Real"}
        self.int_range = {v.name: (v.min, v.max) for v in md.modelVariables
                          if v.causality == "output" and v.type == "Integer"}
        self.in_range = {v.name: (-math.inf if v.min is None else float(v.min), math.inf if v.max is None
                                  else float(v.max)) for v in md.modelVariables if v.causality == "input"}
        self.starts = {v.name: float(v.start) for v in md.modelVariables if v.causality == "input"}
        self.max_step = declared_max_step(path)

    def _start(self):
        self.stderr = tempfile.TemporaryFile(mode="w+")
        self.proc = subprocess.Popen([sys.executable, str(RUNNER), "serve", str(self.path)], stdin=subprocess.PIPE,
                                     stdout=subprocess.PIPE, stderr=self.stderr, text=True)

    def run(self, program: list) -> dict:
        if self.proc is None or self.proc.poll() is not None:
            self._start()
        try:
            self.proc.stdin.write(json.dumps(program) + "\n")
            self.proc.stdin.flush()
            # a hang is a failure, not a stuck test session: at most CALL_SECONDS per call (+ start-up)
            if not select.select([self.proc.stdout], [], [], 60.0 + CALL_SECONDS * len(program))[0]:
                self.proc.kill()
                self.proc.wait(timeout=60)
                self.proc = None
                raise AssertionError(f"{self.path.name}: the host hangs running {program}")
            line = self.proc.stdout.readline()
        except BrokenPipeError:
            line = ""
        if not line:
            rc = self.proc.wait(timeout=60)
            self.stderr.seek(0)
            tail = self.stderr.read()[-3000:]
            self.proc = None
            raise HostCrash(f"{self.path.name}: the host died (return code {rc}) running {program}\n{tail}")
        return json.loads(line)

    def close(self):
        if self.proc is not None and self.proc.poll() is None:
            self.proc.stdin.close()
            self.proc.wait(timeout=60)
        self.proc = None


@pytest.fixture(scope="module", params=FMU_VARIANTS)
def worker(request, built_fmus):
    """The worker of one FMU of the session build (pythonfmu or native C), shared by the properties
    of that FMU."""
    w = Worker(built_fmus.get(*request.param))
    yield w
    w.close()


# ---------------------------------------------------------------------------------------------
# strategies
# ---------------------------------------------------------------------------------------------
EXTREMES = [0.0, -0.0, 1e6, -1e6, 1e-300, -1e-300, 5e-324, 1e5, -1e5, 1e300, -1e300, 1e160, -1e160, 1e155,
            -1e155, 1e30, -1e30]
NON_FINITE = [math.nan, math.inf, -math.inf]
#: realistic ranges (SI) by input name; other names: [-1, 1]
REALISTIC = {"vx": (0.0, 70.0), "delta": (-0.5, 0.5), "steer_angle": (-0.5, 0.5), "bank_angle": (-0.3, 0.3),
             "roll_angle": (-0.8, 0.8), "yaw_rate": (-2.0, 2.0), "roll_rate": (-3.0, 3.0), "ay": (-15.0, 15.0),
             "rider_torque": (-100.0, 100.0), "stiffness_scale_f": (0.5, 2.0), "stiffness_scale_r": (0.5, 2.0)}


# The strategies are made once per input name (and per input list, parameter table): a strategy
# made anew at every draw (inside a flatmap) has its properties worked out again by hypothesis every
# time, ~half of the cost of drawing a program. The same strategies, so the same programs.
@functools.lru_cache(maxsize=None)
def finite_value(name: str):
    lo, hi = REALISTIC.get(name, (-1.0, 1.0))
    return st.one_of(st.floats(lo, hi), st.floats(lo, hi), st.sampled_from(EXTREMES),
                     st.floats(-1e6, 1e6, allow_nan=False), st.floats(-1e300, 1e300))


@functools.lru_cache(maxsize=None)
def any_value(name: str):
    """A finite value, or one time in 20 a non-finite one (it sticks until that input is set again)."""
    return st.integers(0, 19).flatmap(lambda i: NON_FINITE_VALUES if i == 0 else finite_value(name))


NON_FINITE_VALUES = st.sampled_from(NON_FINITE)
#: every positive double step up to 1e300 s, log-uniform: 2^e, e uniform in [-1074, log2(1e300)]
#: (2^-1074 = 5e-324, the smallest subnormal)
LOG_STEPS = st.floats(-1074.0, math.log2(1e300)).map(lambda e: 2.0 ** e)
#: steps where a runtime's 1/h overflows (below ~5.6e-309), the smallest normal, the first-order
#: hold's shortest baseline 2^-30 s and its neighbours (issue 47, item 2)
TINY_STEPS = [5e-324, 1e-323, 1e-320, 1e-310, 2.2250738585072014e-308, 1e-300, 1e-200, 2.0 ** -30,
              math.nextafter(2.0 ** -30, 0.0), 1e-12, 1e-9]
TINY = st.one_of(st.sampled_from(TINY_STEPS), st.floats(-1074.0, math.log2(1e-6)).map(lambda e: 2.0 ** e))
STEP_SIZES = st.one_of(st.sampled_from([1e-4, 0.005, 0.01, 0.1]), st.floats(1e-4, 0.1), TINY,
                       st.sampled_from([1e-6, 0.5, 1.0, 2.0, 1e4, 1e300]), LOG_STEPS)
BAD_STEP_SIZES = st.sampled_from([0.0, -0.005, math.nan, math.inf])


def input_sets(names: list[str], finite: bool = False):
    return _input_sets(tuple(names), finite)


@functools.lru_cache(maxsize=None)
def _input_sets(names: tuple[str, ...], finite: bool):
    value = finite_value if finite else any_value
    return st.lists(st.sampled_from(names), min_size=1, max_size=len(names), unique=True).flatmap(
        lambda chosen: _values(tuple(chosen), value))


@functools.lru_cache(maxsize=None)
def _values(chosen: tuple[str, ...], value):
    return st.fixed_dictionaries({n: value(n) for n in chosen})


def full_inputs(names: list[str]):
    return _values(tuple(names), finite_value)


def parameter_sets(params: dict):
    return _parameter_sets(tuple(sorted((k, tuple(v)) for k, v in params.items())))


@functools.lru_cache(maxsize=None)
def _parameter_sets(params: tuple):
    ranges = dict(params)

    @functools.lru_cache(maxsize=None)
    def one(name):
        lo, hi = ranges[name]
        lo = float(lo) if lo is not None else -1e3
        hi = float(hi) if hi is not None else 1e3
        return st.fixed_dictionaries({name: st.one_of(st.floats(lo, hi), st.sampled_from([lo - 1.0, hi + 1.0]))})
    return st.sampled_from(sorted(ranges)).flatmap(one)


@st.composite
def calls(draw, w: Worker, n_min: int, n_max: int):
    """A random call sequence (without "new"): initialisation done right or not, in any order."""
    out = []
    t = 0.0
    if draw(st.integers(0, 3)) > 0:                       # usually a proper start first
        out += [["setup", 0.0], ["enter"], ["set", draw(full_inputs(w.inputs))], ["exit"]]
    kinds = ["step", "step", "step", "set", "set", "get", "setup", "enter", "exit", "terminate", "reset",
             "badstep", "alternate"] + (["param"] if w.params else [])
    for _ in range(draw(st.integers(n_min, n_max))):
        k = draw(st.sampled_from(kinds))
        if k == "alternate":
            out += draw(alternating_steps(w, t))
            t = out[-2][1] + out[-2][2]
        elif k in ("step", "badstep"):
            h = draw(STEP_SIZES if k == "step" else BAD_STEP_SIZES)
            out += [["set", draw(input_sets(w.inputs))], ["step", t, h], ["get"]]
            t += h if math.isfinite(h) and h > 0 else 0.0
        elif k == "set":
            out.append(["set", draw(input_sets(w.inputs))])
        elif k == "param":
            out.append(["set", draw(parameter_sets(w.params))])
        elif k == "setup":
            out.append(["setup", t])
        else:
            out.append([k])
    return out


@st.composite
def alternating_steps(draw, w: Worker, t: float):
    """2..6 steps alternating one tiny (TINY) and one long step (1 ms up to just beyond the FMU's
    longest: a few refused), the same tiny and long size throughout, finite inputs."""
    tiny = draw(TINY)
    long = draw(st.one_of(st.floats(1e-3, min(w.max_step, 1.0)), st.sampled_from([min(w.max_step, 1.0), 0.05]),
                          st.floats(min(w.max_step, 1.0), 2.0 * min(w.max_step, 1.0))))
    first = draw(st.booleans())
    out = []
    for j in range(draw(st.integers(2, 6))):
        h = tiny if (j % 2 == 0) == first else long
        out += [["set", draw(input_sets(w.inputs, finite=True))], ["step", t, h], ["get"]]
        t += h
    return out


@st.composite
def clean_runs(draw, w: Worker):
    """A proper run: initialise with every input set, then steps (finite inputs, any size of
    STEP_SIZES), now and then a run of alternating tiny and long steps."""
    out = [["setup", 0.0], ["enter"], ["set", draw(full_inputs(w.inputs))], ["exit"], ["get"]]
    t = 0.0
    for _ in range(draw(st.integers(1, 12))):
        if draw(st.integers(0, 5)) == 0:
            out += draw(alternating_steps(w, t))
            t = out[-2][1] + out[-2][2]
            continue
        h = draw(STEP_SIZES)
        out += [["set", draw(input_sets(w.inputs, finite=True))], ["step", t, h], ["get"]]
        t += h
    return out


# ---------------------------------------------------------------------------------------------
# properties
# ---------------------------------------------------------------------------------------------
def check_outputs(w: Worker, program: list, result: dict):
    """Every get: status OK/warning; finite Reals and in-range Integers unless the step before it
    was refused (fmi2Discard or worse); after a refused step, the outputs of the get before it
    (only sets, gets and refused steps between them). Every call within CALL_SECONDS."""
    slow = max(result.get("seconds") or [0.0])
    assert slow < CALL_SECONDS, f"{w.path.name}: a call took {slow:.3g} s in {program}"
    last_step = None
    before = refused = None     # the last get's outputs; the doStep refused since (only sets between)
    for i, call in enumerate(result["calls"]):
        if call[0] == "step":
            last_step = call[1]
            refused = i if call[1] >= 2 and before is not None else None
            before = before if refused is not None else None
        elif call[0] == "get":
            status, values = call[1], call[2]
            assert status <= 1, f"{w.path.name}: get returned status {status} in {program}"
            bad = {k: v for k, v in values.items() if isinstance(v, float) and not math.isfinite(v)}
            for k, (lo, hi) in w.int_range.items():
                if (lo is not None and values[k] < int(lo)) or (hi is not None and values[k] > int(hi)):
                    bad[k] = values[k]
            if bad:
                assert last_step is not None and last_step >= 2, (
                    f"{w.path.name}: outputs {bad} returned after a doStep with status {last_step} "
                    f"(OK or warning); program {program}; FMU log {result['logs']}")
            if refused is not None:
                assert _same(values, before), (f"{w.path.name}: the doStep refused at call {refused} changed the "
                                               f"outputs {before} to {values}; program {program}")
            before, refused = values, None
        elif call[0] != "set":      # new, setup, enter, exit, terminate, reset: the outputs may change
            before = refused = None


@SETTINGS
@given(data=st.data())
def test_any_call_sequence_leaves_the_host_alive_and_outputs_finite(worker, data):
    w = worker
    program = [["new"], *data.draw(calls(w, 1, 40), label="calls")]
    result = w.run(program)
    assert len(result["calls"]) == len(program)
    check_outputs(w, program, result)


def _same(a, b) -> bool:
    """Equal calls: same statuses, outputs bit-identical (NaN equal to NaN of the same sign)."""
    return json.dumps(a) == json.dumps(b)


@SETTINGS
@given(data=st.data())
def test_reset_anywhere_then_a_run_equals_a_fresh_instance(worker, data):
    w = worker
    before = data.draw(calls(w, 0, 10), label="before reset")
    run = data.draw(clean_runs(w), label="run")
    after_reset = w.run([["new"], *before, ["reset"], *run])
    fresh = w.run([["new"], *run])
    got, want = after_reset["calls"][-len(run):], fresh["calls"][-len(run):]
    assert after_reset["calls"][len(before) + 1][1] == 0, f"fmi2Reset returned {after_reset['calls'][len(before) + 1]}"
    for i, (a, b) in enumerate(zip(got, want)):
        assert _same(a, b), (f"{w.path.stem}: call {i} of the run after reset {run[i]} gave {a}, a fresh instance {b} "
                             f"(before the reset: {before}); logs {after_reset['logs']}")
    check_outputs(w, run, fresh)


# ---------------------------------------------------------------------------------------------
# long communication steps
# ---------------------------------------------------------------------------------------------
#: FMUs known to fail the test below (issue 10, item 6): a strict xfail flips when they are fixed
UNBOUNDED_AT_LONG_STEPS: dict[str, str] = {}


def _steady_run(w: Worker, h: float, duration: float) -> dict:
    u = {n: STEADY.get(n, 0.0) for n in w.inputs}
    program = [["new"], ["setup", 0.0], ["enter"], ["set", u], ["exit"]]
    for k in range(int(round(duration / h))):
        program += [["step", k * h, h], ["get"]]
    return w.run(program)


@pytest.mark.parametrize("worker", [
    pytest.param(v.values[0], id=v.id, marks=pytest.mark.xfail(strict=True, raises=AssertionError,
                                                               reason=UNBOUNDED_AT_LONG_STEPS[v.values[0][0]]))
    if v.values[0][0] in UNBOUNDED_AT_LONG_STEPS else v for v in FMU_VARIANTS], indirect=True)
def test_outputs_stay_bounded_at_long_communication_steps(worker):
    """Constant realistic inputs for 10 s: at a 0.1 s step (the top of the range above) every step is
    either accepted with outputs within 10 times (plus 1) of the largest seen at 10 ms, or refused."""
    w = worker
    ref = _steady_run(w, 0.01, 10.0)
    peak = max(abs(v) for c in ref["calls"] if c[0] == "get" for v in c[2].values())
    long = _steady_run(w, 0.1, 10.0)
    last = None
    for c in long["calls"]:
        if c[0] == "step":
            last = c[1]
        elif c[0] == "get" and last == 0:
            worst = max(abs(v) for v in c[2].values())
            assert worst <= 10.0 * peak + 1.0, (f"{w.path.stem}: |output| {worst:.3g} at a 0.1 s step, "
                                                f"{peak:.3g} at 10 ms; logs {long['logs'][-3:]}")


# ---------------------------------------------------------------------------------------------
# refused steps keep the state; unconnected runs; the longest step in both backends
# ---------------------------------------------------------------------------------------------
HUGE = [1e300, -1e300, 1e160, -1e160, 1e155, -1e155, 1e6, -1e6]


@st.composite
def bad_steps(draw, w: Worker):
    """(inputs, h) of one step that must be refused: an input outside its declared range, or a
    communication step longer than the declared longest (up to 1e300 s)."""
    if draw(st.booleans()):
        name = draw(st.sampled_from(w.inputs))
        lo, hi = w.in_range[name]
        x = draw(st.one_of(st.sampled_from(HUGE), st.floats(hi, 1e300, exclude_min=True),
                           st.floats(-1e300, lo, exclude_max=True)).filter(lambda v: not lo <= v <= hi))
        return {name: x}, draw(st.sampled_from([1e-9, 0.001, 0.005]))
    m = min(w.max_step, 1e299) * (1.0 + 1e-8)        # beyond the layers' relative slack of 1e-9
    h = draw(st.one_of(st.sampled_from([1e300, 1e4, 2.0 * m]), st.floats(m, 1e300)))
    return {}, h


@SETTINGS
@given(data=st.data())
def test_a_refused_step_keeps_the_state(worker, data):
    """Realistic steps, then one step with an input outside its declared range or longer than the
    longest declared step: refused (fmi2Discard or worse, within CALL_SECONDS), and the run then
    continues bit-identically to the same run without it."""
    w = worker
    run = data.draw(clean_runs(w), label="run")
    u, h = data.draw(bad_steps(w), label="bad step")
    k = data.draw(st.integers(0, (len(run) - 5) // 3), label="where")
    cut = 5 + 3 * k                                   # after initialisation and k steps
    t = run[cut - 2][1] + run[cut - 2][2] if k else 0.0
    current: dict = {}
    for c in run[:cut]:
        if c[0] == "set":
            current.update(c[1])
    restore = {n: current[n] for n in u}
    bad = [["set", u], ["step", t, h], ["get"], ["set", restore]] if u else [["step", t, h], ["get"]]
    with_bad = w.run([["new"], *run[:cut], *bad, *run[cut:]])
    without = w.run([["new"], *run])
    calls = with_bad["calls"]
    step = calls[1 + cut + (1 if u else 0)]
    assert step[0] == "step" and step[1] >= 2, (f"{w.path.stem}: step {bad} accepted with status {step[1]}; "
                                                f"logs {with_bad['logs'][-3:]}")
    assert any("refused" in m for m in with_bad["logs"]), with_bad["logs"]
    before = [c for c in calls[:1 + cut] if c[0] == "get"]
    if before:
        assert calls[2 + cut + (1 if u else 0)] == before[-1], "a refused step changed the outputs"
    got = calls[1 + cut + len(bad):]
    want = without["calls"][1 + cut:]
    assert json.dumps(got) == json.dumps(want), (f"{w.path.stem}: after the refused step {bad} the run differs "
                                                 f"from the same run without it")
    check_outputs(w, run, with_bad)


@pytest.mark.parametrize("variant", FMU_VARIANTS)
def test_every_fmu_runs_unconnected_from_its_start_values_with_ok(variant, built_fmus):
    """A tool that connects nothing (fmusim, fmpy without inputs) runs the FMU from its start values
    to the default stop time: every call fmi2OK, nothing logged as a warning or an error (fmusim
    stops at the first warning)."""
    path = built_fmus.get(*variant)
    md = read_model_description(str(path))
    worst: list = []
    res = simulate_fmu(str(path), stop_time=float(md.defaultExperiment.stopTime),
                       output_interval=float(md.defaultExperiment.stepSize),
                       logger=lambda c, name, status, cat, msg: worst.append((status, msg.decode())))
    assert not [m for s, m in worst if s >= 1], f"{path.name}: {worst[:3]}"
    for v in md.modelVariables:
        if v.causality == "input":
            assert float(v.min) <= float(v.start) <= float(v.max), (v.name, v.start, v.min, v.max)
    assert all(math.isfinite(x) for row in res for x in row)


def test_a_subnormal_step_keeps_every_output_finite(worker):
    """Every FMU, both backends (FMI 2; FMI 3: tests/cbackend/test_fmi3.py): a step of the smallest
    subnormal, 1e-310 s and tiny steps between long ones are accepted (OK or warning) with every
    output finite, and the step of 1e300 s among them is refused with the outputs kept."""
    w = worker
    u = {n: STEADY.get(n, 0.0) for n in w.inputs}
    program = [["new"], ["setup", 0.0], ["enter"], ["set", u], ["exit"]]
    t = 0.0
    for h in SUBNORMAL_STEPS:
        h = min(w.max_step, 1.0) if h is None else h
        program += [["step", t, h], ["get"]]
        t += h if h < 1e300 else 0.0
    res = w.run(program)
    calls = res["calls"][5:]
    for k, h in enumerate(SUBNORMAL_STEPS):
        (_, status), (_, got, out) = calls[2 * k], calls[2 * k + 1]
        assert got <= 1 and (status >= 2 if h == 1e300 else status <= 1), (w.path.stem, k, h, status, res["logs"][-3:])
        bad = {n: v for n, v in out.items() if not math.isfinite(v)}
        assert not bad, f"{w.path.stem}: outputs {bad} after doStep({h!r}) (step {k}); logs {res['logs'][-3:]}"
        if h == 1e300:
            assert out == calls[2 * k - 1][2], f"{w.path.stem}: the refused step changed the outputs"
    check_outputs(w, program, res)


@pytest.mark.parametrize("name", C_NAMES)
def test_the_longest_step_is_declared_and_refused_alike_in_both_backends(name, built_fmus):
    """Both backends declare the same longest communication step, accept it, refuse anything
    longer (up to 1e300 s) and any input outside its declared range with the same messages, the
    outputs unchanged, within CALL_SECONDS, and then continue as if nothing had been asked."""
    results, logs = {}, {}
    for backend in ("python", "c"):
        w = Worker(built_fmus.get(name, backend))
        try:
            m = w.max_step
            assert m <= 1.0, f"{name} [{backend}]: declared longest step {m} s"
            first = w.inputs[0]
            lo, hi = w.in_range[first]
            program = [["new"], ["setup", 0.0], ["enter"], ["exit"], ["step", 0.0, 0.005], ["get"],
                       ["step", 0.005, 2.0 * m], ["get"], ["step", 0.005, 1e300], ["get"],
                       ["set", {first: hi * 2.0 + 1.0}], ["step", 0.005, 0.005], ["get"],
                       ["set", {first: w.starts[first]}], ["step", 0.005, m], ["get"]]
            res = w.run(program)
        finally:
            w.close()
        st_ = [c[1] for c in res["calls"] if c[0] == "step"]
        gets = [c[2] for c in res["calls"] if c[0] == "get"]
        assert st_[0] == 0 and st_[4] == 0, f"{name} [{backend}]: {res['calls']} {res['logs']}"
        assert all(s >= 2 for s in st_[1:4]), f"{name} [{backend}]: {res['calls']}"
        assert gets[1] == gets[0] and gets[2] == gets[0] and gets[3] == gets[0]
        assert max(res["seconds"]) < CALL_SECONDS
        results[backend] = (m, gets[4], w.in_range)
        logs[backend] = [l.split("] ", 1)[-1] for l in res["logs"] if "refused" in l]
        assert len(logs[backend]) == 3, logs[backend]
        assert "exceeds this FMU's longest step" in logs[backend][0]
        assert "outside the declared range" in logs[backend][2]
    assert results["python"][0] == results["c"][0] and results["python"][2] == results["c"][2]
    assert logs["python"] == logs["c"]


# ---------------------------------------------------------------------------------------------
# the declared longest step is accurate
# ---------------------------------------------------------------------------------------------
#: steering staircase (a fraction of 0.02 rad at 15 m/s), one level per second: every step size
#: that divides 1 s sees the same inputs, so a difference is the FMU's own, not the sampling's
STAIRS = [0, 1, 1, -0.5, -1, 0.3, 0.8, -0.7]
#: the measure of accuracy behind each declared longest step: every Real output at every whole
#: second within this fraction of its peak of the 1 ms run
STEP_TOLERANCE = 0.10
#: FMUs judged otherwise: the Kalman filter is discrete, its measurement noise R is per sample, so
#: its estimate depends on the sampling rate by design (18 % of the peak at 2 ms, 30 % at 5 ms, 27 %
#: at 1 s against 1 ms, measured): bounded, and not growing with the step
STEP_TOLERANCE_OF = {"SideslipKalmanFilter": 0.35}
#: FMUs whose outputs at a longer step legitimately differ more: guaranteed bounds tighten with each
#: measurement, so they are wider when measurements are rarer (judged by the enclosure tests)
ACCURACY_NOT_COMPARED = {"LateralIntervalObserver"}


def _segments(built_fmus, w: Worker) -> list[dict]:
    """The inputs of each 1 s segment: the car observers get CarPlant's outputs at the end of a
    1 s segment of the staircase (consistent measurements), the others scaled stairs."""
    vx = w.starts.get("vx", 15.0)
    car = bool({"yaw_rate"} & set(w.inputs)) and "steer_angle" not in w.inputs     # a car observer
    if car:
        key = ("segments", vx)
        if key not in _CACHE:
            p = Worker(built_fmus.get("CarPlant", "python"))
            try:
                prog = [["new"], ["setup", 0.0], ["enter"], ["set", {"vx": vx}], ["exit"]]
                for k, s in enumerate(STAIRS):
                    prog.append(["set", {"delta": 0.02 * s * 15.0 / vx}])
                    prog += [["step", k + j * 1e-3, 1e-3] for j in range(1000)] + [["get"]]
                gets = [c[2] for c in p.run(prog)["calls"] if c[0] == "get"]
            finally:
                p.close()
            _CACHE[key] = [{"delta": 0.02 * s * 15.0 / vx, "vx": vx, **{n: g[n] for n in ("yaw_rate", "ay",
                           "roll_angle", "roll_rate")}} for s, g in zip(STAIRS, gets)]
        return [{n: seg[n] for n in w.inputs} for seg in _CACHE[key]]
    amp = {"steer_angle": 0.01, "yaw_rate": 0.1, "roll_rate": 0.05, "rider_torque": 10.0, "delta": 0.02,
           "bank_angle": 0.05}
    return [{n: amp[n] * s if n in amp else w.starts[n] for n in w.inputs} for s in STAIRS]


_CACHE: dict = {}


@pytest.mark.parametrize("worker", [v for v in FMU_VARIANTS if v.values[0][0] not in ACCURACY_NOT_COMPARED],
                         indirect=True)
def test_the_declared_longest_step_keeps_the_outputs_close_to_1_ms(worker, built_fmus):
    """At its declared longest communication step, an FMU's outputs at every whole second of a
    steering staircase stay within STEP_TOLERANCE of their peak of a 1 ms run (bounded, accurate)."""
    w = worker
    segs = _segments(built_fmus, w)
    runs = {}
    for h in (1e-3, w.max_step):
        n = int(round(1.0 / h))
        assert abs(n * h - 1.0) < 1e-9, f"{w.path.stem}: longest step {h} s does not divide 1 s"
        prog = [["new"], ["setup", 0.0], ["enter"], ["set", segs[0]], ["exit"]]
        for k, u in enumerate(segs):
            prog += [["set", u], *[["step", k + j * h, h] for j in range(n)], ["get"]]
        res = w.run(prog)
        assert all(c[1] <= 1 for c in res["calls"] if c[0] == "step"), (h, res["logs"][-3:])
        runs[h] = [c[2] for c in res["calls"] if c[0] == "get"]
    ref, got = runs[1e-3], runs[w.max_step]
    for name in ref[0]:
        # an X_filtered output estimates X one communication step earlier (the Kalman filter's
        # x(k|k)): at a 1 s step, 1 s before the whole second, so not comparable here; its values
        # are held to an independent filter's in tests/runtime (the runtime) and to the bit in C
        if isinstance(ref[0][name], int) or name.endswith("_filtered"):
            continue
        peak = max(abs(r[name]) for r in ref) + 1e-9
        err = max(abs(a[name] - b[name]) for a, b in zip(got, ref))
        tol = STEP_TOLERANCE_OF.get(w.path.stem, STEP_TOLERANCE)
        assert err <= tol * peak, (f"{w.path.stem}: {name} differs by {err:.3g} at a {w.max_step} s step "
                                              f"from the 1 ms run (peak {peak:.3g})")
