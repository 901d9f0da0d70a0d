"""The native C backend (issue 11): what holds for every C FMU, whatever its model.

Per-model equivalence with the Python runtime (1e-9 relative on every validation scenario) and
ModelExchange against co-simulation are in ``test_c_<model>.py``; the interop checks (fmpy
validate, fmutool, libcosim) and the hypothesis fuzz run on the C FMUs too (``test_conformance.py``,
``test_fmu_properties.py``). Here:

* the shared object needs only libc and libm, and no symbol version newer than GLIBC_2.17;
* the FMU carries its sources and a build description from which a foreign tool compiles it (the
  test does, from those files alone, and the result runs identically);
* a plain C host (``latobs/native/fmu_runner.c``) loads it with dlopen and runs a scenario: the
  same outputs as fmpy, bit for bit;
* misuse gets real fmi2Error statuses with the culprit named, the state kept: a wrong guid, calls
  out of order, unknown value references, setting an output, NaN inputs, a bad step, a parameter
  outside its range; fmi2Reset and the FMU state (get/set/serialise) restore a run exactly;
* the build is reproducible and the guid follows the content.
"""
from __future__ import annotations

import math
import re
import shutil
import subprocess
import zipfile
from pathlib import Path
from xml.etree import ElementTree

import numpy as np
import pytest
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException

from conftest import fmpy_callbacks
from latobs import cbackend, packaging
from latobs.cbackend import host
from latobs.native_guard import find_compiler
from latobs.validation import harness

pytestmark = [pytest.mark.slow,
              pytest.mark.skipif(find_compiler() is None, reason="no C compiler (set CC, or install cc/gcc)")]
FMU_NAMES = [*packaging.OBSERVERS, *packaging.PLANTS]
C_NAMES = [n for n in FMU_NAMES if cbackend.emitter((packaging.OBSERVERS.get(n) or packaging.PLANTS[n]).model_module)]
ALLOWED_LIBS = ("linux-vdso.so", "libc.so.6", "libm.so.6", "ld-linux")
DT = 0.005


def _tool(name: str) -> str:
    path = shutil.which(name)
    if path is None:
        pytest.skip(f"{name} not found")
    return path


def _library(fmu: Path, tmp: Path) -> Path:
    folder = Path(extract(str(fmu), unzipdir=str(tmp / fmu.stem)))
    return folder / "binaries" / "linux64" / f"{fmu.stem}.so"


# ---------------------------------------------------------------------------------------------
# the binary and the sources
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", C_NAMES)
def test_library_needs_only_libc_and_libm_and_glibc_2_17(built_fmus, name, tmp_path):
    lib = _library(built_fmus.c_path(name), tmp_path)
    ldd = subprocess.run([_tool("ldd"), str(lib)], capture_output=True, text=True, check=True).stdout
    needed = [Path(line.split()[0]).name for line in ldd.splitlines() if line.strip()]
    assert needed and all(n.startswith(ALLOWED_LIBS) for n in needed), f"{name} needs {needed}"
    assert not any("python" in n for n in needed)
    symbols = subprocess.run([_tool("objdump"), "-T", str(lib)], capture_output=True, text=True, check=True).stdout
    versions = {tuple(map(int, v.split("."))) for v in re.findall(r"GLIBC_([0-9.]+)", symbols)}
    assert versions and max(versions) <= (2, 17), f"{name}: GLIBC versions {sorted(versions)}"
    exported = {line.split()[-1] for line in symbols.splitlines() if " .text" in line and "DF" in line}
    assert {"fmi2Instantiate", "fmi2DoStep", "fmi2GetDerivatives"} <= exported
    assert all(s.startswith("fmi2") for s in exported), f"{name} exports more than the FMI API: {exported}"


@pytest.mark.parametrize("name", C_NAMES)
def test_model_description_declares_both_interfaces_and_the_sources(built_fmus, name):
    fmu = built_fmus.c_path(name)
    md = read_model_description(str(fmu), validate=True)
    assert md.coSimulation is not None and md.coSimulation.needsExecutionTool is False
    states = [v for v in md.modelVariables if v.derivative is not None]
    if states:
        assert md.modelExchange is not None and len(md.derivatives) == len(states)
    else:
        assert md.modelExchange is None      # a co-simulation-only model (documented in its C file)
    with zipfile.ZipFile(fmu) as z:
        names = set(z.namelist())
        build = ElementTree.fromstring(z.read("sources/buildDescription.xml"))
    listed = [f.get("name") for f in build.iter("SourceFile")]
    assert listed == md.buildConfigurations[0].sourceFileSets[0].sourceFiles   # the model description's list
    for f in listed + ["fmu_config.h", "fmu_tables.h", "model_data.h", "model.h", "fmi2Functions.h"]:
        assert f"sources/{f}" in names
    assert f"resources/{name}.{'plant' if name in packaging.PLANTS else 'design'}.json" in names
    assert not any(n.endswith(".py") for n in names)


@pytest.mark.parametrize("name", C_NAMES)
def test_sources_compile_without_a_warning(built_fmus, name, tmp_path):
    """-Wall -Wextra -Werror on the FMU's own sources/, as generated for it (its sizes, its data)."""
    folder = Path(extract(str(built_fmus.c_path(name)), unzipdir=str(tmp_path / "x"))) / "sources"
    c_files = [f.get("name") for f in ElementTree.parse(folder / "buildDescription.xml").iter("SourceFile")]
    proc = subprocess.run([find_compiler(), "-std=c99", "-O2", "-fsyntax-only", "-Wall", "-Wextra", "-Werror",
                           "-include", "glibc_compat.h", "-I.", *c_files], cwd=folder, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr


def test_an_fmu_larger_than_the_layers_buffers_is_refused_naming_the_limit():
    """The FMI layers hold each FMU's values in buffers of fixed size (LAYER_MAX_* of
    layer_config.h, which layer_config.c also checks at compile time): a model beyond them is
    refused before compiling, naming what is too large and the limit."""
    from types import SimpleNamespace

    from latobs.cbackend.emit import CModel

    limits = cbackend.layer_limits()
    assert limits == {"VARS": 64, "STATES": 32, "EVENT_INDICATORS": 64}
    small = SimpleNamespace(parameters=[1], inputs=[1] * 64, outputs=[1], integer_outputs=[])
    cbackend.check_layer_limits("Fits", small, CModel(header="", states=[None] * 32, n_event_indicators=64))
    with pytest.raises(cbackend.NativeBuildError, match="Big: 65 inputs, more than the FMI layers hold \\(64: "
                                                        "LAYER_MAX_VARS"):
        cbackend.check_layer_limits("Big", SimpleNamespace(**{**vars(small), "inputs": [1] * 65}),
                                    CModel(header="", states=[], n_event_indicators=0))
    with pytest.raises(cbackend.NativeBuildError, match="33 continuous states.*LAYER_MAX_STATES"):
        cbackend.check_layer_limits("Big", small, CModel(header="", states=[None] * 33, n_event_indicators=0))


def _compile_from_sources(fmu: Path, tmp: Path) -> Path:
    """What a foreign tool does with the FMU alone: compile sources/ as buildDescription.xml says,
    into a copy of the FMU whose binary is replaced."""
    folder = Path(extract(str(fmu), unzipdir=str(tmp / "foreign")))
    build = ElementTree.parse(folder / "sources" / "buildDescription.xml").getroot()
    config = build.find("BuildConfiguration")
    sfs = config.find("SourceFileSet")
    cmd = [find_compiler(), "-shared", "-fPIC", "-O1", *sfs.get("compilerOptions", "").split(),
           *[f"-I{folder / 'sources' / d.get('name')}" for d in sfs.iter("IncludeDirectory")],
           *[str(folder / "sources" / s.get("name")) for s in sfs.iter("SourceFile")],
           "-o", str(folder / "binaries" / "linux64" / f"{config.get('modelIdentifier')}.so"),
           *[f"-l{lib.get('name')}" for lib in config.iter("Library")]]
    subprocess.run(cmd, check=True, capture_output=True, text=True)
    out = tmp / fmu.name
    with zipfile.ZipFile(out, "w") as z:
        for p in sorted(folder.rglob("*")):
            if p.is_file():
                z.write(p, p.relative_to(folder).as_posix())
    return out


def _scenario_run(built_fmus, name: str):
    """The harness run of the C observer ``name`` beside the C CarPlant on bank-braking (4 s)."""
    from latobs.validation.scenarios import get_scenario

    sc = get_scenario("bank-braking", duration=4.0)
    return harness.run(sc, built_fmus.c_path("CarPlant"), {"obs": built_fmus.c_path(name)}, dt=DT)


def test_a_foreign_build_from_the_sources_runs_identically(built_fmus, tmp_path):
    name = "SideslipBankObserver"
    res = _scenario_run(built_fmus, name)
    n = len(res.time) - 1
    inputs = {k: res.measured[k][:n] for k in res.inputs["obs"]}
    foreign = _compile_from_sources(built_fmus.c_path(name), tmp_path)
    got = host.run(foreign, inputs, DT)
    for k, ref in res.observers["obs"].items():
        np.testing.assert_allclose(got[k], ref, rtol=1e-12, atol=1e-15, err_msg=k)


def test_a_c_host_runs_the_scenario_like_fmpy_bit_for_bit(built_fmus):
    """A plain C host (dlopen, no Python in the process) gives fmpy's outputs to the bit."""
    res = _scenario_run(built_fmus, "SideslipBankObserver")
    n = len(res.time) - 1
    got = host.run(built_fmus.c_path("SideslipBankObserver"), {k: res.measured[k][:n] for k in res.inputs["obs"]},
                   DT)
    assert set(got) == set(res.observers["obs"])
    for k, ref in res.observers["obs"].items():
        assert np.array_equal(got[k], ref), f"{k}: max |diff| {np.max(np.abs(got[k] - ref)):.3g}"
    plant_in = {k: res.bus[k][:n] for k in res.inputs[harness.PLANT_LABEL]}
    plant = host.run(built_fmus.c_path("CarPlant"), plant_in, DT)
    for k in ("beta", "yaw_rate", "roll_angle"):
        assert np.array_equal(plant[k], res.bus[k]), k


def test_two_builds_are_byte_identical_and_the_guid_follows_the_content(built_fmus, tmp_path):
    design = built_fmus.out / "SideslipBankObserver.design.json"
    a = packaging.package_design(design, tmp_path / "a", backend="c").read_bytes()
    b = packaging.package_design(design, tmp_path / "b", backend="c").read_bytes()
    assert a == b
    other = packaging.package_plant("CarPlant", "compact", tmp_path / "c", backend="c")
    guids = {read_model_description(str(p)).guid for p in (tmp_path / "a" / "SideslipBankObserver.fmu", other,
                                                          built_fmus.c_path("CarPlant"))}
    assert len(guids) == 3


# ---------------------------------------------------------------------------------------------
# misuse: real fmi2Error statuses, the culprit named, the state kept
# ---------------------------------------------------------------------------------------------
class Logged:
    def __init__(self):
        self.messages: list[tuple[int, str]] = []

    def __call__(self, component, instance, status, category, message):
        self.messages.append((status, message.decode() if isinstance(message, bytes) else str(message)))

    def errors(self) -> list[str]:
        return [m for s, m in self.messages if s >= 3]


def _slave(fmu: Path, tmp: Path, log: Logged, guid: str | None = None):
    md = read_model_description(str(fmu))
    if guid is not None:
        md.guid = guid
    from fmpy.fmi2 import FMU2Slave

    unzipped = extract(str(fmu), unzipdir=str(tmp / f"u{len(list(tmp.iterdir()))}"))
    slave = FMU2Slave(guid=md.guid, unzipDirectory=unzipped, modelIdentifier=md.coSimulation.modelIdentifier,
                      instanceName="test")
    slave.instantiate(callbacks=fmpy_callbacks(log))
    return md, slave


def _vr(md, name: str) -> int:
    return next(v.valueReference for v in md.modelVariables if v.name == name)


def _status(call) -> int:
    try:
        call()
    except FMICallException as exc:
        return int(exc.status)
    return 0


@pytest.fixture(scope="module")
def observer(built_fmus):
    return built_fmus.c_path("SideslipBankObserver")


INPUTS = {"delta": 0.02, "vx": 20.0, "yaw_rate": 0.1, "roll_angle": 0.01, "roll_rate": 0.0}


def _start(md, fmu, inputs=INPUTS):
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.setReal([_vr(md, k) for k in inputs], list(inputs.values()))
    fmu.exitInitializationMode()


def _outputs(md, fmu) -> list[float]:
    return fmu.getReal([v.valueReference for v in md.modelVariables if v.causality == "output" and v.type == "Real"])


def test_a_wrong_guid_or_a_missing_interface_is_refused_with_a_message(observer, built_fmus, tmp_path):
    log = Logged()
    with pytest.raises(Exception):
        _slave(observer, tmp_path, log, guid="{00000000-0000-5000-0000-000000000000}")
    assert any("guid" in m for m in log.errors()), log.messages
    kalman = built_fmus.c_path("SideslipKalmanFilter")   # co-simulation only (see sideslip_kalman_filter.c)
    md = read_model_description(str(kalman))
    assert md.modelExchange is None
    from fmpy.fmi2 import FMU2Model
    m = FMU2Model(guid=md.guid, unzipDirectory=extract(str(kalman), unzipdir=str(tmp_path / "k")),
                  modelIdentifier=md.coSimulation.modelIdentifier, instanceName="k")
    log = Logged()
    with pytest.raises(Exception):           # fmpy raises when fmi2Instantiate returns NULL
        m.instantiate(callbacks=fmpy_callbacks(log))
    assert any("no ModelExchange interface" in msg for msg in log.errors()), log.messages


def test_calls_out_of_order_unknown_references_and_outputs_are_fmi2error(observer, tmp_path):
    log = Logged()
    md, fmu = _slave(observer, tmp_path, log)
    assert _status(lambda: fmu.doStep(0.0, DT)) == 3                       # before initialisation
    assert "fmi2ExitInitializationMode" in log.errors()[-1]
    _start(md, fmu)
    assert _status(lambda: fmu.getReal([9999])) == 3
    assert "9999" in log.errors()[-1]
    assert _status(lambda: fmu.setReal([_vr(md, "beta_hat")], [1.0])) == 3
    assert "beta_hat" in log.errors()[-1]
    assert _status(lambda: fmu.getInteger([_vr(md, "beta_hat")])) == 3
    assert _status(lambda: fmu.setReal([_vr(md, "vx_hold")], [2.0])) == 0   # fmi2Warning: fmpy does not raise
    assert "vx_hold" in log.messages[-1][1] and log.messages[-1][0] == 1      # ignored, with a warning
    assert fmu.getReal([_vr(md, "vx_hold")]) == [1.0]
    fmu.doStep(0.0, DT)
    before = _outputs(md, fmu)
    fmu.setReal([_vr(md, "yaw_rate")], [math.nan])
    assert _status(lambda: fmu.doStep(DT, DT)) == 3
    assert "yaw_rate" in log.errors()[-1]
    assert _outputs(md, fmu) == before                                      # state kept
    for h in (0.0, -DT, math.inf, math.nan):
        assert _status(lambda: fmu.doStep(DT, h)) == 3
    fmu.setReal([_vr(md, "yaw_rate")], [0.1])
    fmu.doStep(DT, DT)                                                      # finite again: proceeds
    assert _outputs(md, fmu) != before
    fmu.terminate()
    fmu.freeInstance()


def test_a_parameter_outside_its_range_fails_initialisation_until_reset(observer, tmp_path):
    log = Logged()
    md, fmu = _slave(observer, tmp_path, log)
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.setReal([_vr(md, "vx_hold")], [100.0])
    assert _status(fmu.exitInitializationMode) == 3
    assert "vx_hold" in log.errors()[-1]
    assert _status(lambda: fmu.doStep(0.0, DT)) == 3
    fmu.reset()
    _start(md, fmu)
    fmu.doStep(0.0, DT)
    fmu.freeInstance()


def _run(md, fmu, steps: int, start: int = 0) -> list[list[float]]:
    out = []
    for k in range(start, start + steps):
        fmu.setReal([_vr(md, "delta"), _vr(md, "yaw_rate")], [0.02 * math.sin(k * DT), 0.1 * math.sin(k * DT)])
        fmu.doStep(k * DT, DT)
        out.append(_outputs(md, fmu))
    return out


def test_reset_and_the_fmu_state_restore_a_run_exactly(observer, tmp_path):
    md, fmu = _slave(observer, tmp_path, Logged())
    _start(md, fmu)
    fresh = _run(md, fmu, 200)
    fmu.reset()
    _start(md, fmu)
    assert _run(md, fmu, 200) == fresh
    fmu.reset()
    _start(md, fmu)
    _run(md, fmu, 100)
    state = fmu.getFMUState()
    blob = fmu.serializeFMUState(state)
    tail = _run(md, fmu, 100, 100)
    assert tail == fresh[100:]
    fmu.setFMUState(state)
    assert _run(md, fmu, 100, 100) == tail
    fmu.setFMUState(fmu.deSerializeFMUstate(blob))
    assert _run(md, fmu, 100, 100) == tail
    fmu.freeFMUState(state)
    fmu.freeInstance()


def test_model_exchange_calls_out_of_order_or_with_wrong_sizes_are_fmi2error(observer, tmp_path):
    """The layer's ModelExchange state machine: derivatives before initialisation, a state vector
    of the wrong size or with a NaN, a discrete update outside event mode, a co-simulation call on
    a ModelExchange instance: fmi2Error with the call named, and the instance still works."""
    from ctypes import c_double, c_void_p

    from fmpy.fmi2 import FMU2Model

    md = read_model_description(str(observer))
    n = len(md.derivatives)
    m = FMU2Model(guid=md.guid, unzipDirectory=extract(str(observer), unzipdir=str(tmp_path / "me")),
                  modelIdentifier=md.modelExchange.modelIdentifier, instanceName="me")
    log = Logged()
    m.instantiate(callbacks=fmpy_callbacks(log))
    x, dx = (c_double * n)(), (c_double * n)()
    assert _status(lambda: m.getDerivatives(dx, n)) == 3
    assert "never initialised" in log.errors()[-1] or "fmi2GetDerivatives" in log.errors()[-1]
    m.setupExperiment(startTime=0.0)
    m.enterInitializationMode()
    m.setReal([_vr(md, k) for k in INPUTS], list(INPUTS.values()))
    m.exitInitializationMode()
    m.newDiscreteStates()
    m.enterContinuousTimeMode()
    assert _status(lambda: m.newDiscreteStates()) == 3                     # not in event mode
    assert "fmi2NewDiscreteStates" in log.errors()[-1]
    assert _status(lambda: m.setContinuousStates(x, n - 1)) == 3
    assert f"this FMU has {n}" in log.errors()[-1]
    m.getContinuousStates(x, n)
    bad = (c_double * n)(*x)
    bad[0] = math.nan
    assert _status(lambda: m.setContinuousStates(bad, n)) == 3
    m.getDerivatives(dx, n)                                                 # the state was kept
    before = list(dx)
    m.setContinuousStates(x, n)
    m.getDerivatives(dx, n)
    assert list(dx) == before and all(math.isfinite(v) for v in before)
    m.setReal([_vr(md, "yaw_rate")], [math.nan])
    assert _status(lambda: m.getDerivatives(dx, n)) == 3 and "yaw_rate" in log.errors()[-1]
    do_step = m.dll.fmi2DoStep                                              # a co-simulation call
    assert do_step(c_void_p(m.component), c_double(0.0), c_double(0.005), 1) == 3
    assert "CoSimulation" in log.errors()[-1]
    m.terminate()
    m.freeInstance()
