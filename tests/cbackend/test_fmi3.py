"""The FMI 3.0 native FMUs (``latobs build --fmi 3``: ``fmu_src/c/fmi3_layer.c``, ``latobs.cbackend.fmi3``).

Each is held against its FMI 2.0 twin of the session build (the same model file, data and
compiler): it validates; its reference results (made at build time by running it beside the FMI
3.0 plant) are the twin's bit for bit; fmpy's ModelExchange run gives the twin's bit for bit; its
win64 (Wine) and aarch64-linux (qemu) binaries give the twin's binaries' outputs bit for bit; its
gain arrays are the design file's gains; its terminals group every input and output once. The
misuse contract of the FMI 2.0 layer (``test_c_backend.py``) holds in both interfaces.
"""
from __future__ import annotations

import json
import math
import struct
import zipfile
from ctypes import c_double, c_void_p
from pathlib import Path

import numpy as np
import pytest
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException

from conftest import C_NAMES, bits
from latobs import packaging, reference
from latobs.cbackend import fmi3, runner, toolchain

CROSS = ("win64", "aarch64-linux")
ME_SECONDS = 1.0      # ModelExchange runs on the first second of the reference inputs (a variable-step solver)
DT = 0.005
FOLDERS = [f for fs in fmi3.FOLDERS.values() for f in fs]
#: where each gain array's values are in an observer's design file: an evaluation of the design
#: file independent of the emitters' ``gains``
DESIGN_GAINS = {
    "K_P": lambda d: [m["gains"]["K_P"] for m in d["modes"]],
    "K_I": lambda d: [m["gains"]["K_I"] for m in d["modes"]],
    "K": lambda d: [m["K"] for m in d["modes"]],
    "E": lambda d: [m["E"] for m in d["modes"]],
    "L_P": lambda d: [m["gains"]["L_P"] for m in d["modes"]],
    "L_I": lambda d: [m["gains"]["L_I"] for m in d["modes"]],
    "L": lambda d: [m["gains"]["L"] for m in d["modes"]],
    "estimator_num": lambda d: [m["estimator"]["num"] for m in d["modes"]],
    "estimator_den": lambda d: [m["estimator"]["den"] for m in d["modes"]],
    "Q": lambda d: d["modes"][0]["gains"]["Q"], "R": lambda d: d["modes"][0]["gains"]["R"],
    "P0": lambda d: d["modes"][0]["gains"]["P0"],
}


pytestmark = pytest.mark.usefixtures("fmi3_host")


def _members(fmu: Path) -> dict[str, bytes]:
    with zipfile.ZipFile(fmu) as z:
        return {n: z.read(n) for n in z.namelist()}


@pytest.mark.parametrize("name", C_NAMES)
def test_the_fmi3_fmu_is_its_fmi2_twin_in_fmi3(built_fmus, name):
    """fmpy validates it; the same interfaces, variables, units and display units as the twin; the
    five FMI 3.0 platform folders (darwin: two thin libraries of the right architecture); the twin's
    model file and data byte for byte; its datasheet; its reference results the twin's bit for
    bit, and ``latobs check`` passes on them."""
    from fmpy.validation import validate_fmu

    from latobs.check import check

    f2, f3 = built_fmus.c_path(name), built_fmus.c3_path(name)
    assert validate_fmu(str(f3)) == []
    md2, md3 = read_model_description(str(f2)), read_model_description(str(f3))
    assert md3.fmiVersion == "3.0" and md3.coSimulation is not None
    assert (md3.modelExchange is None) == (md2.modelExchange is None)
    v2 = {v.name: v for v in md2.modelVariables}
    v3 = {v.name: v for v in md3.modelVariables if not v.dimensions}
    for n, v in v2.items():
        w = v3[n]
        assert (w.valueReference, w.causality, w.unit, w.displayUnit, w.start, w.min, w.max) == \
            (v.valueReference, v.causality, v.unit, v.displayUnit, v.start, v.min, v.max), n
        assert {"Real": "Float64", "Integer": "Int32"}[v.type] == w.type, n
    m2, m3 = _members(f2), _members(f3)
    assert sorted({n.split("/")[1] for n in m3 if n.startswith("binaries/")}) == sorted(FOLDERS)
    for folder, cpu in (("x86_64-darwin", 0x01000007), ("aarch64-darwin", 0x0100000C)):   # thin, one each
        assert struct.unpack("<Ii", m3[f"binaries/{folder}/{name}.dylib"][:8]) == (0xFEEDFACF, cpu), folder
    for src in (n for n in m2 if n.startswith("sources/") and n not in (
            "sources/fmi2_layer.c", "sources/buildDescription.xml", "sources/fmu_tables.h")
            and not n.startswith("sources/fmi2")):
        assert m3[src] == m2[src], src                       # the model file and its data unchanged
    assert "sources/fmi3_layer.c" in m3 and "sources/fmi2_layer.c" not in m3
    assert b'name="fmi3_layer.c"' in m3["sources/buildDescription.xml"]
    assert b"FMI 3.0" in m3["documentation/index.html"] and b"fmi3Error" in m3["documentation/index.html"]
    (e2,), (e3,) = reference.read(f2), reference.read(f3)
    assert e3.platform == fmi3.host_folder() and e2.platform == toolchain.host_platform()
    assert bits(e3.time) == bits(e2.time)
    assert all(bits(e3.inputs[k]) == bits(e2.inputs[k]) for k in e2.inputs) and e3.inputs.keys() == e2.inputs.keys()
    assert e3.outputs.keys() == e2.outputs.keys()
    assert [k for k in e2.outputs if bits(e3.outputs[k]) != bits(e2.outputs[k])] == []
    results, _ = check(f3, "host")
    assert results and all(r.passed and r.comparison.exact for r in results), [r.line() for r in results]


@pytest.mark.parametrize("name", C_NAMES)
def test_terminals_group_every_input_and_output_once_with_an_icon(built_fmus, name):
    import fmpy
    from lxml import etree

    f3 = built_fmus.c3_path(name)
    m = _members(f3)
    schema = etree.XMLSchema(file=str(Path(fmpy.__file__).parent / "schema" / "fmi3" / "fmi3TerminalsAndIcons.xsd"))
    xml = etree.fromstring(m[fmi3.TERMINALS_FILE])
    assert schema.validate(xml), schema.error_log
    assert m[fmi3.ICON_FILE] == m["model.png"] and m[fmi3.ICON_FILE][:8] == b"\x89PNG\r\n\x1a\n"
    md = read_model_description(str(f3))
    members = [(t.get("name"), t.get("terminalKind"), v.get("variableName")) for t in xml.iter("Terminal")
               for v in t.iter("TerminalMemberVariable")]
    names = [v for _, _, v in members]
    assert sorted(names) == sorted(v.name for v in md.modelVariables if v.causality in ("input", "output"))
    observer = name in packaging.OBSERVERS
    kinds = {v: k for _, k, v in members}
    for v in md.modelVariables:
        if v.causality == "input":
            assert kinds[v.name] == ("org.latobs.sensor" if observer else "org.latobs.source"), v.name
        elif v.causality == "output":
            assert kinds[v.name] in ("org.latobs.estimate", "org.latobs.status"), v.name


@pytest.mark.parametrize("name", [n for n in C_NAMES if n not in ("CarPlant", "MotorcyclePlant")])
def test_the_gain_arrays_are_the_design_files_gains(built_fmus, name, tmp_path):
    """Each array constant: declared with its dimensions, its start values and what
    fmi3GetFloat64 returns right after instantiation equal to the gains of the design file."""
    from fmpy.fmi3 import FMU3Slave

    f3 = built_fmus.c3_path(name)
    design = json.loads(_members(f3)[f"resources/{name}.design.json"])
    md = read_model_description(str(f3))
    arrays = [v for v in md.modelVariables if v.dimensions]
    assert arrays, "an observer FMU shows its gains"
    s = FMU3Slave(guid=md.guid, unzipDirectory=extract(str(f3), unzipdir=str(tmp_path / "u")),
                  modelIdentifier=md.coSimulation.modelIdentifier, instanceName="gains")
    s.instantiate()
    try:
        for v in arrays:
            want = np.asarray(DESIGN_GAINS[v.name](design), dtype=float)
            assert v.variability == "constant" and v.causality == "local"
            assert [int(d.start) for d in v.dimensions] == list(want.shape), v.name
            assert [float(x) for x in str(v.start).split()] == want.ravel().tolist(), v.name
            assert s.getFloat64([v.valueReference], nValues=want.size) == want.ravel().tolist(), v.name
        both = arrays[:2]
        sizes = [int(np.prod([int(d.start) for d in v.dimensions])) for v in both]
        got = s.getFloat64([v.valueReference for v in both], nValues=sum(sizes))
        assert got == sum((np.asarray(DESIGN_GAINS[v.name](design), dtype=float).ravel().tolist() for v in both), [])
        with pytest.raises(FMICallException):                  # nValues must count the elements
            s.getFloat64([arrays[0].valueReference])
        with pytest.raises(FMICallException):                  # a constant
            s.setFloat64([arrays[0].valueReference], [0.0] * sizes[0])
    finally:
        s.freeInstance()


def _signals(e, stop: float) -> np.ndarray:
    keep = e.time <= stop + 1e-12
    sig = np.zeros(int(keep.sum()), dtype=[("time", np.float64)] + [(n, np.float64) for n in e.inputs])
    sig["time"] = e.time[keep]
    for n, v in e.inputs.items():
        sig[n] = np.asarray(v, dtype=float)[keep]
    return sig


@pytest.mark.parametrize("name", C_NAMES)
def test_model_exchange_is_the_fmi2_twins_bit_for_bit(built_fmus, name):
    from fmpy import simulate_fmu

    f2, f3 = built_fmus.c_path(name), built_fmus.c3_path(name)
    if read_model_description(str(f2)).modelExchange is None:
        pytest.skip(f"{name} is co-simulation only (its FMI 3.0 twin too: checked above)")
    e, = reference.read(f2)
    stop = e.start + ME_SECONDS
    outputs = [v.name for v in read_model_description(str(f2)).modelVariables if v.causality == "output"]
    runs = [simulate_fmu(str(f), start_time=e.start, stop_time=stop, step_size=e.step, output_interval=e.step,
                         input=_signals(e, stop), output=outputs, fmi_type="ModelExchange", validate=False)
            for f in (f2, f3)]
    assert len(runs[0]) == len(runs[1]) > 100
    assert [n for n in outputs if bits(runs[0][n]) != bits(runs[1][n])] == []


@pytest.mark.slow
@pytest.mark.parametrize("platform", ["linux64", *CROSS])
@pytest.mark.parametrize("name", C_NAMES)
def test_the_binaries_of_every_platform_give_their_fmi2_twins_outputs_in_a_plain_c_host(built_fmus, name, platform):
    """The FMI 3.0 linux64, win64 (Wine) and aarch64-linux (qemu) binaries, run by the plain C host
    (``latobs/native/fmu_runner.c``) on the reference experiment, give the FMI 2.0 twin's binary of
    the same platform bit for bit (each platform's C library as it is: a difference between
    platforms is test_cross_run's business); on linux64 also the reference results (fmpy's)."""
    from test_cross_run import _need

    if platform != toolchain.host_platform():
        _need(platform)
    elif platform != "linux64":
        pytest.skip("linux64 runs here only on x86-64 Linux")
    f2, f3 = built_fmus.c_path(name), built_fmus.c3_path(name)
    e, = reference.read(f3)
    runs = [runner.run(f, platform, e.time, e.inputs, list(e.outputs), step=e.step) for f in (f2, f3)]
    assert all(r.ok for r in runs), [r.failure() for r in runs]
    assert [k for k in e.outputs if bits(runs[0][k]) != bits(runs[1][k])] == []
    if platform == "linux64":
        assert [k for k in e.outputs if bits(runs[1][k]) != bits(e.outputs[k])] == []


def test_latobs_check_runs_every_platform_it_can_here(built_fmus):
    """``latobs check --platform all`` on an FMI 3.0 FMU: its x86_64-linux binary bit for bit (fmpy),
    x86_64-windows (Wine) and aarch64-linux (qemu) in the C host within the reference tolerance; the
    darwin folders skipped, saying why."""
    from test_cross_run import _need

    from latobs.check import check

    for platform in CROSS:
        _need(platform)
    results, skipped = check(built_fmus.c3_path("CarPlant"), "all")
    assert [r.platform for r in results] == ["x86_64-linux", "x86_64-windows", "aarch64-linux"]
    assert all(r.passed for r in results) and results[0].comparison.exact, [r.line() for r in results]
    assert [p for p, _ in skipped] == ["x86_64-darwin", "aarch64-darwin"]


# ---------------------------------------------------------------------------------------------
# misuse: the FMI 2.0 layer's contract (test_c_backend.py) in both FMI 3.0 interfaces
# ---------------------------------------------------------------------------------------------
INPUTS = {"delta": 0.02, "vx": 20.0, "yaw_rate": 0.1, "roll_angle": 0.01, "roll_rate": 0.0}


class Logged:
    def __init__(self):
        self.messages: list[tuple[int, str]] = []

    def __call__(self, env, status, category, message):
        self.messages.append((status, message.decode()))

    def errors(self) -> list[str]:
        return [m for s, m in self.messages if s >= 3]


def _status(call) -> int:
    try:
        call()
    except FMICallException as exc:
        return int(exc.status)
    return 0


def _vr(md, name: str) -> int:
    return next(v.valueReference for v in md.modelVariables if v.name == name)


@pytest.fixture(scope="module")
def observer3(built_fmus):
    return built_fmus.c3_path("SideslipBankObserver")


def _slave(fmu: Path, tmp: Path, log: Logged, token: str | None = None):
    from fmpy.fmi3 import FMU3Slave

    md = read_model_description(str(fmu))
    s = FMU3Slave(guid=token or md.guid, unzipDirectory=extract(str(fmu), unzipdir=str(tmp / f"u{len(list(tmp.iterdir()))}")),
                  modelIdentifier=md.coSimulation.modelIdentifier, instanceName="test")
    s.instantiate(loggingOn=True, logMessage=log)
    return md, s


def _start(md, s, inputs=INPUTS):
    s.enterInitializationMode(startTime=0.0)
    s.setFloat64([_vr(md, k) for k in inputs], list(inputs.values()))
    s.exitInitializationMode()


def _outputs(md, s) -> list[float]:
    return s.getFloat64([v.valueReference for v in md.modelVariables if v.causality == "output" and v.type == "Float64"])


def _run(md, s, steps: int, start: int = 0) -> list[list[float]]:
    out = []
    for k in range(start, start + steps):
        s.setFloat64([_vr(md, "delta"), _vr(md, "yaw_rate")], [0.02 * math.sin(k * DT), 0.1 * math.sin(k * DT)])
        s.doStep(k * DT, DT)
        out.append(_outputs(md, s))
    return out


def test_a_wrong_token_or_a_missing_interface_is_refused_with_a_message(observer3, built_fmus, tmp_path):
    from fmpy.fmi3 import FMU3Model

    log = Logged()
    with pytest.raises(Exception):
        _slave(observer3, tmp_path, log, token="{00000000-0000-5000-0000-000000000000}")
    assert any("token" in m for m in log.errors()), log.messages
    kalman = built_fmus.c3_path("SideslipKalmanFilter")
    md = read_model_description(str(kalman))
    assert md.modelExchange is None
    m = FMU3Model(guid=md.guid, unzipDirectory=extract(str(kalman), unzipdir=str(tmp_path / "k")),
                  modelIdentifier=md.coSimulation.modelIdentifier, instanceName="k")
    log = Logged()
    with pytest.raises(Exception):
        m.instantiate(logMessage=log)
    assert any("ModelExchange" in msg for msg in log.errors()), log.messages


def test_cosimulation_calls_out_of_order_unknown_references_and_nan_are_fmi3error_the_state_kept(observer3, tmp_path):
    log = Logged()
    md, s = _slave(observer3, tmp_path, log)
    assert _status(lambda: s.doStep(0.0, DT)) == 3                      # before initialisation
    assert "fmi3DoStep" in log.errors()[-1]
    _start(md, s)
    assert _status(lambda: s.getFloat64([9999])) == 3 and "9999" in log.errors()[-1]
    assert _status(lambda: s.getFloat64([_vr(md, "beta_hat")], nValues=2)) == 3
    assert _status(lambda: s.setFloat64([_vr(md, "beta_hat")], [1.0])) == 3 and "beta_hat" in log.errors()[-1]
    assert _status(lambda: s.getInt32([_vr(md, "beta_hat")])) == 3
    assert _status(lambda: s.getBoolean([_vr(md, "beta_hat")])) == 3
    assert _status(lambda: s.setFloat64([_vr(md, "vx_hold")], [2.0])) == 0     # a warning: ignored
    assert "vx_hold" in log.messages[-1][1] and log.messages[-1][0] == 1
    assert s.getFloat64([_vr(md, "vx_hold")]) == [1.0]
    s.doStep(0.0, DT)
    before = _outputs(md, s)
    s.setFloat64([_vr(md, "yaw_rate")], [math.nan])
    assert _status(lambda: s.doStep(DT, DT)) == 3 and "yaw_rate" in log.errors()[-1]
    assert _outputs(md, s) == before                                     # state kept
    for h in (0.0, -DT, math.inf, math.nan, 1e300):
        assert _status(lambda: s.doStep(DT, h)) == 3
    assert _outputs(md, s) == before
    s.setFloat64([_vr(md, "yaw_rate")], [0.1])
    s.doStep(DT, DT)                                                     # finite again: proceeds
    assert _outputs(md, s) != before
    s.terminate()
    s.freeInstance()


def test_a_parameter_outside_its_range_fails_initialisation_until_reset(observer3, tmp_path):
    log = Logged()
    md, s = _slave(observer3, tmp_path, log)
    s.enterInitializationMode(startTime=0.0)
    s.setFloat64([_vr(md, "vx_hold")], [100.0])
    assert _status(s.exitInitializationMode) == 3 and "vx_hold" in log.errors()[-1]
    assert _status(lambda: s.doStep(0.0, DT)) == 3
    s.reset()
    _start(md, s)
    s.doStep(0.0, DT)
    s.freeInstance()


def test_reset_reinstantiation_and_the_fmu_state_restore_a_run_exactly(observer3, tmp_path):
    md, s = _slave(observer3, tmp_path, Logged())
    _start(md, s)
    fresh = _run(md, s, 200)
    s.reset()
    _start(md, s)
    assert _run(md, s, 200) == fresh
    s.reset()
    _start(md, s)
    _run(md, s, 100)
    state = s.getFMUState()
    blob = s.serializeFMUState(state)
    tail = _run(md, s, 100, 100)
    assert tail == fresh[100:]
    s.setFMUState(state)
    assert _run(md, s, 100, 100) == tail
    s.setFMUState(s.deserializeFMUState(blob))
    assert _run(md, s, 100, 100) == tail
    s.freeFMUState(state)
    s.terminate()
    s.freeInstance()
    for _ in range(2):                       # instantiated again, twice, in the same process: the same run
        md, s = _slave(observer3, tmp_path, Logged())
        _start(md, s)
        assert _run(md, s, 200) == fresh
        s.terminate()
        s.freeInstance()


def test_model_exchange_calls_out_of_order_or_with_wrong_sizes_are_fmi3error(observer3, tmp_path):
    """The ModelExchange state machine: derivatives before initialisation, a state vector of the
    wrong size or with a NaN, a discrete update outside event mode, a co-simulation call on a
    ModelExchange instance: fmi3Error with the call named, and the instance still works."""
    from fmpy.fmi3 import FMU3Model

    md = read_model_description(str(observer3))
    n = len(md.derivatives)
    m = FMU3Model(guid=md.guid, unzipDirectory=extract(str(observer3), unzipdir=str(tmp_path / "me")),
                  modelIdentifier=md.modelExchange.modelIdentifier, instanceName="me")
    log = Logged()
    m.instantiate(loggingOn=True, logMessage=log)
    assert m.getNumberOfContinuousStates() == n
    x, dx = (c_double * n)(), (c_double * n)()
    assert _status(lambda: m.getContinuousStateDerivatives(dx, n)) == 3
    m.enterInitializationMode(startTime=0.0)
    m.setFloat64([_vr(md, k) for k in INPUTS], list(INPUTS.values()))
    m.exitInitializationMode()
    m.updateDiscreteStates()
    m.enterContinuousTimeMode()
    assert _status(lambda: m.updateDiscreteStates()) == 3                # not in event mode
    assert "fmi3UpdateDiscreteStates" in log.errors()[-1]
    assert _status(lambda: m.setContinuousStates(x, n - 1)) == 3
    assert str(n) in log.errors()[-1]
    m.getContinuousStates(x, n)
    bad = (c_double * n)(*x)
    bad[0] = math.nan
    assert _status(lambda: m.setContinuousStates(bad, n)) == 3
    m.getContinuousStateDerivatives(dx, n)                               # the state was kept
    before = list(dx)
    m.setContinuousStates(x, n)
    m.getContinuousStateDerivatives(dx, n)
    assert list(dx) == before and all(math.isfinite(v) for v in before)
    m.setFloat64([_vr(md, "yaw_rate")], [math.nan])
    assert _status(lambda: m.getContinuousStateDerivatives(dx, n)) == 3 and "yaw_rate" in log.errors()[-1]
    m.setFloat64([_vr(md, "yaw_rate")], [0.1])
    m.getContinuousStateDerivatives(dx, n)
    assert all(math.isfinite(v) for v in dx)
    from latobs.validation.instance import _DOSTEP3

    do_step = _DOSTEP3(("fmi3DoStep", m.dll))                            # a co-simulation call
    assert do_step(c_void_p(m.component), 0.0, DT, True, None, None, None, None) == 3
    assert "fmi3DoStep" in log.errors()[-1]
    m.terminate()
    m.freeInstance()




@pytest.mark.parametrize("name", C_NAMES)
def test_a_subnormal_step_keeps_every_output_finite_in_fmi3(built_fmus, name, tmp_path):
    """Issue 47, item 2 in FMI 3.0: doStep(5e-324), (1e-310), tiny steps between the longest ones:
    accepted with every output finite; 1e300 s refused (fmi3Error) with the outputs kept."""
    from conformance_runs import STEADY, SUBNORMAL_STEPS, declared_max_step

    fmu = built_fmus.c3_path(name)
    longest = min(declared_max_step(built_fmus.c_path(name)), 1.0)
    log = Logged()
    md, s = _slave(fmu, tmp_path, log)
    inputs = {v.name: STEADY[v.name] for v in md.modelVariables if v.causality == "input" and v.name in STEADY}
    _start(md, s, inputs)
    t, last = 0.0, None
    for k, h in enumerate(SUBNORMAL_STEPS):
        h = longest if h is None else h
        status = _status(lambda: s.doStep(t, h))
        out = _outputs(md, s)
        if h == 1e300:
            assert status == 3 and out == last, (name, status, log.messages[-2:])
        else:
            assert status <= 1, (name, k, h, log.messages[-3:])
            t += h
        assert all(math.isfinite(x) for x in out), f"{name}: outputs {out} after doStep({h!r}) (step {k})"
        last = out
    s.terminate()
    s.freeInstance()
