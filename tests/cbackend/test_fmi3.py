"""The FMI 3.0 native FMUs (``latobs.cbackend.fmi3``, ``fmu_src/c/fmi3_layer.c``): built from the data
of the session's FMI 2.0 native FMU, they validate, and fmpy simulating them on that FMU's reference
inputs (CoSimulation and, with states, ModelExchange) gives the FMI 2.0 FMU's outputs bit for bit."""
from __future__ import annotations

import json
import zipfile
from pathlib import Path

import numpy as np
import pytest

from latobs import cbackend, packaging

#: every FMU of ``latobs build`` that has a C model (CarPlant and SideslipBankObserver among them)
NAMES = [n for n in [*packaging.OBSERVERS, *packaging.PLANTS]
         if cbackend.emitter((packaging.OBSERVERS.get(n) or packaging.PLANTS[n]).model_module)]
ME_SECONDS = 2.0     # ModelExchange runs on the first seconds of the reference inputs (a variable-step solver)


def _kind(name: str):
    return packaging.OBSERVERS.get(name) or packaging.PLANTS[name]


@pytest.fixture(scope="module")
def fmi3_fmus(built_fmus, tmp_path_factory) -> dict[str, tuple[Path, Path]]:
    """{name: (FMI 2.0 native FMU of the session, the FMI 3.0 FMU built from its data file)}."""
    from latobs.cbackend import fmi3

    if fmi3.host_platform() is None:
        pytest.skip("this machine is none of the FMI 3.0 platforms")
    out = tmp_path_factory.mktemp("fmi3")
    fmus = {}
    for name in NAMES:
        fmi2 = built_fmus.c_path(name)
        kind = _kind(name)
        with zipfile.ZipFile(fmi2) as z:
            data = json.loads(z.read(f"resources/{name}.{kind.data_kind}.json"))
        fmus[name] = (fmi2, fmi3.build_c_fmu3(kind, name, data, out))
    return fmus


def _signals(e, stop: float) -> np.ndarray:
    """fmpy's input array of the reference experiment ``e`` up to ``stop``."""
    keep = e.time <= stop + 1e-12
    dtype = [("time", np.float64)] + [(n, np.float64) for n in e.inputs]
    sig = np.zeros(int(keep.sum()), dtype=dtype)
    sig["time"] = e.time[keep]
    for n, v in e.inputs.items():
        sig[n] = np.asarray(v, dtype=float)[keep]
    return sig


def _simulate(fmu: Path, e, fmi_type: str, stop: float) -> np.ndarray:
    from fmpy import read_model_description, simulate_fmu

    md = read_model_description(str(fmu))
    outputs = [v.name for v in md.modelVariables if v.causality == "output"]
    return simulate_fmu(str(fmu), start_time=e.start, stop_time=stop, step_size=e.step, output_interval=e.step,
                        input=_signals(e, stop), output=outputs, fmi_type=fmi_type, validate=False)


def _same_bits(a: np.ndarray, b: np.ndarray) -> list[str]:
    """The columns of two fmpy results that differ in any bit (or in length)."""
    assert a.dtype.names == b.dtype.names, (a.dtype.names, b.dtype.names)
    if len(a) != len(b):
        return [f"length {len(a)} != {len(b)}"]
    return [n for n in a.dtype.names if np.ascontiguousarray(a[n]).tobytes() != np.ascontiguousarray(b[n]).tobytes()]


@pytest.mark.parametrize("name", NAMES)
def test_fmi3_fmu_validates(fmi3_fmus, name):
    from fmpy import read_model_description
    from fmpy.validation import validate_fmu

    _, fmu = fmi3_fmus[name]
    assert validate_fmu(str(fmu)) == []
    md = read_model_description(str(fmu))
    assert md.fmiVersion == "3.0" and md.coSimulation is not None
    with zipfile.ZipFile(fmu) as z:
        names = z.namelist()
    assert any(n.startswith("binaries/x86_64-linux/") for n in names) or \
        any(n.startswith("binaries/aarch64-linux/") for n in names)
    assert "sources/fmi3_layer.c" in names and "sources/fmi2_layer.c" not in names


@pytest.mark.parametrize("name", NAMES)
def test_fmi3_cosimulation_is_fmi2_bit_for_bit(fmi3_fmus, name):
    from latobs import reference

    fmi2, fmu = fmi3_fmus[name]
    e, = reference.read(fmi2)
    want = _simulate(fmi2, e, "CoSimulation", e.stop)
    got = _simulate(fmu, e, "CoSimulation", e.stop)
    assert len(got) == len(e.time)
    assert _same_bits(want, got) == []
    assert any(np.any(got[n] != 0) for n in got.dtype.names[1:])     # something happened


@pytest.mark.parametrize("name", NAMES)
def test_fmi3_model_exchange_is_fmi2_bit_for_bit(fmi3_fmus, name):
    from fmpy import read_model_description

    from latobs import reference

    fmi2, fmu = fmi3_fmus[name]
    if read_model_description(str(fmi2)).modelExchange is None:
        assert read_model_description(str(fmu)).modelExchange is None
        pytest.skip(f"{name} is co-simulation only")
    e, = reference.read(fmi2)
    stop = min(e.stop, e.start + ME_SECONDS)
    want = _simulate(fmi2, e, "ModelExchange", stop)
    got = _simulate(fmu, e, "ModelExchange", stop)
    assert _same_bits(want, got) == []


def test_fmi3_misuse_is_refused_and_the_state_kept(fmi3_fmus):
    """The FMI 2.0 layer's contract: an out-of-order call, an unknown value reference, a wrong
    nValues, a non-finite input are refused with an error logged, the state kept; the FMU state
    round-trips through serialisation."""
    from fmpy import extract, read_model_description
    from fmpy.fmi1 import FMICallException
    from fmpy.fmi3 import FMU3Slave

    _, fmu = fmi3_fmus["CarPlant"]
    md = read_model_description(str(fmu))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    messages: list[tuple[int, str]] = []
    s = FMU3Slave(guid=md.guid, unzipDirectory=extract(str(fmu)), modelIdentifier=md.coSimulation.modelIdentifier,
                  instanceName="misuse")
    s.instantiate(logMessage=lambda env, status, category, message: messages.append((status, message.decode())))
    try:
        with pytest.raises(FMICallException):
            s.doStep(0.0, 0.01)
        assert "fmi3DoStep called in instantiated" in messages[-1][1]
        s.enterInitializationMode(startTime=0.0)
        s.exitInitializationMode()
        y = [vr["beta"], vr["yaw_rate"], vr["ay"]]
        s.setFloat64([vr["delta"]], [0.05])
        for k in range(20):
            s.doStep(k * 0.01, 0.01)
        state = s.getFMUState()
        before = s.getFloat64(y)
        assert any(before)
        with pytest.raises(FMICallException):
            s.getFloat64([10_000])
        assert "is not a variable of CarPlant" in messages[-1][1]
        with pytest.raises(FMICallException):
            s.getFloat64([vr["beta"]], nValues=2)
        assert "2 values for 1 value references" in messages[-1][1]
        with pytest.raises(FMICallException):
            s.getInt32([vr["beta"]])
        with pytest.raises(FMICallException):
            s.setFloat64([vr["beta"]], [1.0])              # an output
        s.setFloat64([vr["delta"]], [float("nan")])
        with pytest.raises(FMICallException):
            s.doStep(0.2, 0.01)
        assert "non-finite input(s) delta = nan" in messages[-1][1]
        assert s.getFloat64(y) == before                    # state held
        with pytest.raises(FMICallException):
            s.doStep(0.2, 1e3)                              # longer than the longest step
        s.setFloat64([vr["delta"]], [0.05])
        s.doStep(0.2, 0.01)
        after = s.getFloat64(y)
        assert after != before
        restored = s.deserializeFMUState(s.serializeFMUState(state))
        s.setFMUState(restored)
        assert s.getFloat64(y) == before
        s.doStep(0.2, 0.01)
        assert s.getFloat64(y) == after                     # the same step again, bit for bit
        s.freeFMUState(restored)
        s.freeFMUState(state)
        s.terminate()
    finally:
        s.freeInstance()
