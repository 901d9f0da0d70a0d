"""The SSP signal source (ScenarioSignals): a native C model on the one FMI layer, playing back a
scenario's samples bit for bit with a zero-order hold on the host's communication points."""
from __future__ import annotations

import math
import zipfile

import numpy as np
import pytest
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave

from latobs import ssp as S
from latobs.validation import get_scenario

DT = S.DEFAULT_DT


@pytest.fixture(scope="module")
def source(tmp_path_factory):
    sc = get_scenario("fishhook-varying-stiffness", duration=1.0)
    t = sc.time_grid(DT)
    signals = S.scenario_signals(sc, t, "delibasi")
    units = {"delta": "rad", "vx": "m/s", "bank_angle": "rad"}
    fmu = S.build_source_fmu(sc.name, t, signals, units, tmp_path_factory.mktemp("source"), ["linux64"])
    return fmu, t, signals


def _run(fmu, steps, start=0.0):
    """[(time, outputs)] of one instance: after initialisation, then after each step of ``steps``."""
    md = read_model_description(str(fmu))
    vrs = [v.valueReference for v in md.modelVariables]
    s = FMU2Slave(guid=md.guid, unzipDirectory=extract(str(fmu)), modelIdentifier="ScenarioSignals",
                  instanceName="signals")
    s.instantiate()
    s.setupExperiment(startTime=start)
    s.enterInitializationMode()
    s.exitInitializationMode()
    out, tc = [(start, s.getReal(vrs))], start
    for h in steps:
        s.doStep(currentCommunicationPoint=tc, communicationStepSize=h)
        tc += h
        out.append((tc, s.getReal(vrs)))
    s.terminate()
    s.freeInstance()
    return out


def test_it_is_a_native_model_of_the_fmi_layer(source):
    fmu, _, signals = source
    md = read_model_description(str(fmu))
    assert [v.name for v in md.modelVariables] == list(signals)
    assert all(v.causality == "output" for v in md.modelVariables)
    assert not md.coSimulation.needsExecutionTool and md.modelExchange is None
    with zipfile.ZipFile(fmu) as z:
        names = set(z.namelist())
    assert {"sources/fmi2_layer.c", "sources/signal_source.c", "binaries/linux64/ScenarioSignals.so"} <= names
    assert not any(n.endswith(".py") for n in names)              # no Python inside


@pytest.mark.parametrize("pattern", ["uniform", "irregular", "long", "late-start"])
def test_it_plays_back_the_samples_bit_for_bit(source, pattern):
    """After a step ending at t the outputs are exactly the sample at or before t (the first before
    the grid, the last after it), whatever the steps; the start time's sample after initialisation."""
    fmu, t, signals = source
    rng = np.random.default_rng(1)
    steps = {"uniform": [DT] * (len(t) + 3), "irregular": list(rng.uniform(1e-4, 0.02, 150)),
             "long": [0.3, 1e-9, 2.0, 1e6, 1e300], "late-start": [DT] * 20}[pattern]
    start = 0.4 if pattern == "late-start" else 0.0
    table = np.column_stack([signals[n] for n in signals])
    for time, y in _run(fmu, steps, start):
        k = min(max(math.floor(time / DT + 1e-6), 0), len(t) - 1)
        assert np.array_equal(np.array(y), table[k]), (pattern, time, k)
