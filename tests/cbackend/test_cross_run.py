"""Every native FMU runs, not only links, on the platforms it ships for: its win64 binary under Wine
and its aarch64-linux binary under qemu give its linux64 outputs.

One portable C host (``latobs/native/fmu_runner.c``, :mod:`latobs.cbackend.runner`) is compiled for
each platform and loads the FMU's own binary of that platform. For each FMU of the session build
(``C_NAMES``) the inputs of its own validation scenario (2.5 s at the FMU's step) are recorded from
a coupled run with fmpy (an observer's: what it received beside its plant; a plant's: the
scenario's driver inputs), and

* on linux64 the host gives fmpy's outputs bit for bit: fmpy's own ``simulate_fmu`` (steps
  t_(k+1) - t_k) and the validation harness (fixed step), two independent hosts;
* on win64 (Wine) and aarch64-linux (qemu) it gives the linux64 outputs bit for bit, unless the
  FMU calls a C math function that the platform's C library computes otherwise: then within
  1e-12 relative (|y - y_linux| <= 1e-12 (|y_linux| + max|y_linux|), per output; Integer outputs
  exactly), the functions named. Which functions differ is measured here, not assumed
  (``tests/c_host/libm_probe.c`` on 100000 arguments each). Measured so: Wine 8.0's C runtime
  (Debian; its ucrtbase maths is not Microsoft's) gives other last bits than glibc 2.36 for sin,
  cos, tan, atan, atan2, exp, expm1, log2 and pow (sqrt: the same); aarch64 glibc gives x86-64
  glibc's bits for all of them.

The tests skip only where the emulator is missing and cannot be installed (no apt-get, or not
root); ``.ci/run`` installs Wine, qemu-user and the aarch64 C library when it can.
"""
from __future__ import annotations

import os
import re
import shutil
import tempfile
import zipfile
from dataclasses import dataclass
from pathlib import Path
from xml.etree import ElementTree

import numpy as np
import pytest
from fmpy import read_model_description, simulate_fmu

from conftest import C_NAMES
from latobs import packaging, pipeline
from latobs.cbackend import runner, toolchain
from latobs.validation import harness
from latobs.validation.scenarios import get_scenario

pytestmark = pytest.mark.slow

CROSS = ("win64", "aarch64-linux")
SECONDS = 2.5
RELATIVE = 1e-12
PROBE = Path(__file__).resolve().parents[1] / "c_host" / "libm_probe.c"
#: each FMU's own validation scenario: the reference experiment latobs build embeds
#: (``pipeline.REFERENCE_EXPERIMENTS``), run a little longer here
SCENARIO = pipeline.REFERENCE_EXPERIMENTS
#: the C99 <math.h> functions whose results may differ between C libraries (the probe measures
#: them); the others used by the FMUs (fabs, sqrt, floor, ceil, fmod, ...) are exact by IEEE 754
PROBED = ("sin", "cos", "tan", "atan", "atan2", "exp", "expm1", "log2", "pow")
UNPROBED = ("acos", "asin", "acosh", "asinh", "atanh", "cbrt", "cosh", "erf", "erfc", "exp2", "hypot", "lgamma",
            "log", "log10", "log1p", "logb", "sinh", "tanh", "tgamma")


def _need(platform: str) -> None:
    why = runner.available(platform)
    if why is None:
        return
    if shutil.which("apt-get") and hasattr(os, "geteuid") and os.geteuid() == 0:
        pytest.fail(f"{why}: .ci/run installs it (apt-get install wine64 qemu-user libc6-arm64-cross)")
    pytest.skip(f"{why}, and it cannot be installed here (no apt-get, or not root)")


@pytest.fixture(scope="module")
def libm_differs():
    """{platform: the probed functions whose bits differ from the host platform's}."""
    host = toolchain.host_platform()
    out: dict[str, set[str]] = {}

    def hashes(platform: str) -> dict[str, str]:
        with tempfile.TemporaryDirectory(prefix="latobs-probe-") as tmp:
            exe = Path(tmp) / ("probe.exe" if platform == "win64" else "probe")
            exe.write_bytes(toolchain.compile_for(platform, {"probe.c": PROBE.read_bytes()},
                                                  ["probe.c"], exe.name, shared=False))
            exe.chmod(0o755)
            code, text, _ = runner.execute(platform, exe, [], timeout=120)
        assert code == 0, text
        return dict(line.split() for line in text.splitlines() if re.fullmatch(r"\w+ [0-9a-f]{16}", line))

    ref = hashes(host)
    assert set(ref) == {*PROBED, "sqrt"}
    for platform in CROSS:
        if runner.available(platform) is None:
            got = hashes(platform)
            assert got["sqrt"] == ref["sqrt"], "sqrt is correctly rounded (IEEE 754): the probe itself is broken"
            out[platform] = {f for f in PROBED if got[f] != ref[f]}
    return out


def _calls(fmu: Path) -> set[str]:
    """The C math functions the FMU's sources call."""
    with zipfile.ZipFile(fmu) as z:
        text = "\n".join(z.read(n).decode() for n in z.namelist() if re.fullmatch(r"sources/.*\.[ch]", n))
    return set(re.findall(r"\b([a-z][a-z0-9]*)\s*\(", text)) & {*PROBED, *UNPROBED}


@dataclass
class Case:
    fmu: Path
    time: np.ndarray
    step: float
    inputs: dict[str, np.ndarray]
    expected: dict[str, np.ndarray]        # the harness's outputs (fmpy, fixed step)
    linux: runner.RunResult                # the host on linux64, fixed step


_CASES: dict[str, Case] = {}
_PLANTS: dict[tuple[str, str], tuple[Path, str]] = {}


def _plant_for(built_fmus, name: str) -> tuple[Path, str]:
    """(the native plant FMU beside which observer ``name`` runs its reference experiment, its
    vehicle), as ``pipeline.reference_plant`` chooses them."""
    plant, vehicle = pipeline.reference_plant(name, None)
    if (plant, vehicle) not in _PLANTS:
        if vehicle is None:
            found = (built_fmus.c_path(plant), packaging.PLANTS[plant].default_vehicle)
        else:
            found = (packaging.package_plant(plant, vehicle, built_fmus.out / "c" / vehicle, backend="c"), vehicle)
        _PLANTS[(plant, vehicle)] = found
    return _PLANTS[(plant, vehicle)]


def _case(built_fmus, name: str) -> Case:
    if name not in _CASES:
        fmu = built_fmus.c_path(name)
        md = read_model_description(str(fmu))
        step = float(md.defaultExperiment.stepSize)
        spec = SCENARIO[name]
        sc = get_scenario(spec.scenario, duration=SECONDS, **dict(spec.overrides))
        if name in packaging.PLANTS:
            res = harness.run(sc, fmu, {}, dt=step, vehicle=packaging.PLANTS[name].default_vehicle)
            inputs = {k: res.bus[k] for k in res.inputs[harness.PLANT_LABEL]}
            expected = {v.name: res.bus[v.name] for v in md.modelVariables if v.causality == "output"}
        else:
            plant, vehicle = _plant_for(built_fmus, name)
            res = harness.run(sc, plant, {"obs": fmu}, dt=step, vehicle=vehicle)
            inputs = {k: res.measured[k] for k in res.inputs["obs"]}
            expected = res.observers["obs"]
        linux = runner.run(fmu, toolchain.host_platform(), res.time, inputs, step=step)
        assert linux.ok, linux.failure()
        _CASES[name] = Case(fmu, res.time, step, inputs, expected, linux)
    return _CASES[name]


def test_every_native_fmu_has_a_scenario():
    assert set(C_NAMES) <= set(SCENARIO), set(C_NAMES) - set(SCENARIO)


@pytest.mark.parametrize("name", C_NAMES)
def test_the_linux64_host_gives_fmpys_outputs_bit_for_bit(built_fmus, name):
    case = _case(built_fmus, name)
    assert set(case.linux.outputs) == set(case.expected)
    for k, ref in case.expected.items():      # the validation harness: fmpy's FMU2Slave, fixed step
        assert np.array_equal(case.linux[k], np.asarray(ref, dtype=float), equal_nan=True), k
    # fmpy's simulate_fmu: its own loop, input interpolation and step sizes t_(k+1) - t_k
    names = list(case.inputs)
    signals = np.array(list(zip(case.time, *(case.inputs[n] for n in names))),
                       dtype=[("time", float)] + [(n, float) for n in names])
    sim = simulate_fmu(str(case.fmu), fmi_type="CoSimulation", start_time=0.0, stop_time=float(case.time[-1]),
                       output_interval=case.step, input=signals, output=list(case.expected))
    ours = runner.run(case.fmu, toolchain.host_platform(), case.time, case.inputs)
    assert ours.ok, ours.failure()
    assert np.array_equal(sim["time"], ours.time)
    for k in case.expected:
        assert np.array_equal(ours[k], np.asarray(sim[k], dtype=float), equal_nan=True), k


@pytest.mark.parametrize("platform", CROSS)
@pytest.mark.parametrize("name", C_NAMES)
def test_the_binary_of_another_platform_gives_the_linux64_outputs(built_fmus, libm_differs, name, platform):
    _need(platform)
    case = _case(built_fmus, name)
    got = runner.run(case.fmu, platform, case.time, case.inputs, step=case.step)
    assert got.ok, got.failure()
    assert np.array_equal(got.time, case.linux.time)
    unprobed = _calls(case.fmu) & set(UNPROBED)
    assert not unprobed, f"{name} calls {', '.join(sorted(unprobed))}: add them to tests/c_host/libm_probe.c"
    differing = sorted(_calls(case.fmu) & libm_differs[platform])
    types = {v.name: v.type for v in read_model_description(str(case.fmu)).modelVariables}
    for k, ref in case.linux.outputs.items():
        if not differing or types[k] != "Real":
            assert np.array_equal(got[k], ref, equal_nan=True), \
                f"{name} {k} on {platform}: not the linux64 bits (max |diff| {np.nanmax(np.abs(got[k] - ref)):.3g})"
        else:       # a math function of this platform's C library gives other last bits
            err = np.abs(got[k] - ref)
            bound = RELATIVE * (np.abs(ref) + np.nanmax(np.abs(ref)))
            assert np.array_equal(np.isnan(got[k]), np.isnan(ref)) and np.all(err[~np.isnan(ref)] <= bound[~np.isnan(ref)]), \
                (f"{name} {k} on {platform} (its C library's {', '.join(differing)} differ from glibc's): "
                 f"max relative difference {np.nanmax(err / np.nanmax(np.abs(ref))):.3g} > {RELATIVE:g}")


def test_a_missing_binary_or_emulator_is_named(built_fmus, tmp_path):
    fmu = built_fmus.c_path("CarPlant")
    stripped = tmp_path / "CarPlant.fmu"
    with zipfile.ZipFile(fmu) as src, zipfile.ZipFile(stripped, "w") as dst:
        for item in src.infolist():
            if not item.filename.startswith("binaries/win64/"):
                dst.writestr(item, src.read(item))
    t = np.arange(3) * 0.005
    with pytest.raises(runner.RunnerError, match=r"CarPlant\.fmu.*win64"):
        runner.run(stripped, "win64", t, {})
    assert "cannot run" in runner.available("darwin64")
    with pytest.raises(runner.RunnerError, match=r"CarPlant\.fmu on darwin64"):
        runner.run(fmu, "darwin64", t, {})


def test_the_comparison_sees_a_binary_built_without_the_floating_point_contract(built_fmus, monkeypatch, tmp_path):
    """Bit for bit means something: the same FMU's aarch64-linux binary compiled from its own
    sources with fused multiply-adds allowed (fp_contract.h emptied, -ffp-contract=fast) gives
    other last bits under qemu, which the comparison above would reject."""
    _need("aarch64-linux")
    case = _case(built_fmus, "SideslipBankObserver")
    with zipfile.ZipFile(case.fmu) as z:
        src = {n[len("sources/"):]: z.read(n) for n in z.namelist() if n.startswith("sources/") and n[-1] != "/"}
        members = {i.filename: z.read(i) for i in z.infolist()}
    build = ElementTree.fromstring(src["buildDescription.xml"])
    ident = build.find("BuildConfiguration").get("modelIdentifier")
    src["fp_contract.h"] = b"/* no floating-point contract */\n"
    monkeypatch.setattr(toolchain, "COMMON_FLAGS", tuple(
        "-ffp-contract=fast" if f == "-ffp-contract=off" else f for f in toolchain.COMMON_FLAGS))
    members[f"binaries/aarch64-linux/{ident}.so"] = toolchain.compile_for(
        "aarch64-linux", src, [f.get("name") for f in build.iter("SourceFile")], f"{ident}.so")
    fused = tmp_path / case.fmu.name
    with zipfile.ZipFile(fused, "w") as z:
        for name, raw in members.items():
            z.writestr(name, raw)
    got = runner.run(fused, "aarch64-linux", case.time, case.inputs, step=case.step)
    assert got.ok, got.failure()
    differ = [k for k, ref in case.linux.outputs.items() if not np.array_equal(got[k], ref, equal_nan=True)]
    assert differ, "fused multiply-adds gave the same bits: the comparison would not see them"
    for k in differ:    # the last bits only
        assert np.nanmax(np.abs(got[k] - case.linux[k])) <= RELATIVE * np.nanmax(np.abs(case.linux[k])), k


@pytest.mark.parametrize("platform", ["linux64", *CROSS])
def test_a_refused_step_is_recorded_not_hidden(built_fmus, platform):
    """A NaN input at t_2: the FMU refuses that step (fmi2Error, its message logged); the host
    records the status at the point the step would reach and stops there, on every platform."""
    if platform != toolchain.host_platform():
        _need(platform)
    fmu = built_fmus.c_path("SideslipBankObserver")
    inputs = {"delta": [0.01, 0.01, np.nan, 0.01, 0.01], "vx": 20.0, "yaw_rate": 0.1, "roll_angle": 0.0,
              "roll_rate": 0.0}
    got = runner.run(fmu, platform, np.arange(5) * 0.005, inputs, step=0.005)
    assert not got.ok
    assert list(got.status) == [0, 0, 0, 3]
    assert np.all(np.isfinite(got["beta_hat"][:3])) and np.isnan(got["beta_hat"][3])
    assert "delta = nan" in got.log and "fmi2Error at t = 0.015" in got.failure()


def test_a_silent_wine_failure_is_run_once_more_and_a_real_one_is_not(monkeypatch, tmp_path):
    """Wine's client exits 1 without output when the server it reaches is shutting down: the host is
    run again once; a failure that says something (the host's own errors) is returned at once."""
    import subprocess

    monkeypatch.setattr(runner, "_emulator", lambda platform: (["wine"], None))
    monkeypatch.setattr(runner.toolchain, "host_platform", lambda: "linux64")
    monkeypatch.setattr(runner, "cache_dir", lambda: tmp_path)
    (tmp_path / "wine").mkdir()
    (tmp_path / "wine" / ".latobs-ready").write_text("")
    monkeypatch.setattr(runner.shutil, "which", lambda name: None)
    calls = []

    def fake(outcomes):
        def run(cmd, stdout=None, **kw):
            code, text = outcomes[len(calls)]
            calls.append(cmd)
            stdout.write(text.encode())
            return subprocess.CompletedProcess(cmd, code)
        return run

    monkeypatch.setattr(runner.subprocess, "run", fake([(1, ""), (0, "ok")]))
    assert runner.execute("win64", Path("host.exe"), [])[:2] == (0, "ok") and len(calls) == 2
    calls.clear()
    monkeypatch.setattr(runner.subprocess, "run", fake([(1, "fmu_runner: cannot load the binary"), (0, "")]))
    assert runner.execute("win64", Path("host.exe"), [])[:2] == (1, "fmu_runner: cannot load the binary")
    assert len(calls) == 1
