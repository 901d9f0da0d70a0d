"""The ModelStructure ``dependencies`` of every FMU against finite-difference probing of the FMU itself.

Native FMUs with ModelExchange declare, per Real output and per derivative, the inputs and
states it depends on directly (``latobs.cbackend.emit.CModel.dependencies``, from each model's
data at build time). The probe: at ``N_POINTS`` random operating points (inputs drawn around
their start values; the speed within 10 % of its start, inside the design grid and one mode;
states a little off the values initialisation gave them) and at one reversing point (vx = -start,
where the model accepts it), each input (``fmi2SetReal``) and each continuous state
(``fmi2SetContinuousStates``) is perturbed alone and the outputs and derivatives are compared with
the unperturbed ones, bit for bit:

* an output or derivative that changes must list the perturbed variable in its ``dependencies``
  (no undeclared dependency: what makes an importer's algebraic-loop analysis safe);
* every declared dependency must change the unknown at one point at least (none is declared that
  the model does not have). Some dependencies are structurally present but vanish at some
  operating points: the interval observer's bounds read the lower or the upper bound of a box
  according to the sign of a coefficient that changes with vx - vx_mode, its sideslip bounds the
  other vy bound when reversing, the plants' loads the lagged speed only below the ax clamp. They
  are caught at other points (the speed varied about the mode's, the reversing point, small state
  offsets); an entry seen at no point fails the test.

Mode switches happen at events: the probe stays within a mode (a perturbation of 1e-4 relative),
so it sees a speed's continuous (in-mode) influence only, as ``dependencies`` state it.

Co-simulation-only FMUs (every pythonfmu FMU, and native ones without continuous states) declare
that no output depends on an input: after a step, setting any input changes no output until the
next ``fmi2DoStep``.
"""
from __future__ import annotations

import subprocess
import sys
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

import numpy as np
import pytest

from conftest import C_NAMES, FMU_NAMES, fmpy_callbacks

pytestmark = pytest.mark.slow

N_POINTS = 4          # random operating points per FMU
REL = 1e-4            # relative perturbation (of max(|value|, its scale))
SEED = 20


def _structure(path):
    """(variables {vr: (name, causality, type)}, {section: {unknown vr: [vr] or None}})."""
    with zipfile.ZipFile(path) as z:
        root = ET.fromstring(z.read("modelDescription.xml"))
    variables, ordered = {}, []
    for sv in root.find("ModelVariables"):
        typ = next(iter(sv)).tag
        deriv = next(iter(sv)).get("derivative")
        entry = (sv.get("name"), sv.get("causality"), typ, deriv)
        variables[int(sv.get("valueReference"))] = entry
        ordered.append(int(sv.get("valueReference")))
    sections = {}
    for sec in root.find("ModelStructure"):
        out = {}
        for u in sec:
            deps = u.get("dependencies")
            out[ordered[int(u.get("index")) - 1]] = (None if deps is None else
                                                     [ordered[int(i) - 1] for i in deps.split()])
        sections[sec.tag] = out
    return root, variables, ordered, sections


def test_cs_outputs_have_no_direct_feedthrough(built_fmus):
    """Every co-simulation FMU: outputs declare empty dependencies and setting an input changes none."""
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    variants = [(n, "python") for n in FMU_NAMES] + [(n, "c") for n in C_NAMES]
    checked = 0
    for name, backend in variants:
        path = built_fmus.get(name, backend)
        root, variables, ordered, sections = _structure(path)
        if root.find("ModelExchange") is not None:
            continue                      # probed in ModelExchange below (its outputs are shared)
        outs = sections["Outputs"]
        assert outs and all(d == [] for d in outs.values()), f"{name}[{backend}]: {outs}"
        md = read_model_description(str(path))
        s = FMU2Slave(guid=md.guid, unzipDirectory=extract(str(path)), modelIdentifier=name,
                      instanceName="probe")
        s.instantiate(callbacks=fmpy_callbacks())
        s.setupExperiment(startTime=0.0)
        s.enterInitializationMode()
        s.exitInitializationMode()
        step = float(md.defaultExperiment.stepSize)
        inputs = [v for v in md.modelVariables if v.causality == "input"]
        outputs = [v.valueReference for v in md.modelVariables if v.causality == "output" and v.type == "Real"]
        for k in range(3):
            s.doStep(k * step, step)          # raises on an error status
        before = s.getReal(outputs)
        for v in inputs:
            x = float(v.start)
            s.setReal([v.valueReference], [x + max(abs(x), 1.0) * 1e-2 * (1 if x < float(v.max or np.inf) else -1)])
            assert s.getReal(outputs) == before, f"{name}[{backend}]: outputs changed on setting {v.name}"
        s.terminate()
        s.freeInstance()
        checked += 1
    assert checked >= len(FMU_NAMES)


def _probe_me(path, name):
    """{(unknown vr, known vr): observed} over N_POINTS points, the unknowns being the Real
    outputs and the derivatives, the knowns the inputs and states."""
    from fmpy import extract, read_model_description
    from ctypes import POINTER

    from fmpy.fmi2 import FMU2Model, fmi2Real
    from fmpy.fmi1 import FMICallException

    md = read_model_description(str(path))
    m = FMU2Model(guid=md.guid, unzipDirectory=extract(str(path)), modelIdentifier=name, instanceName="probe")
    rng = np.random.default_rng(SEED)
    inputs = [v for v in md.modelVariables if v.causality == "input"]
    outputs = [v.valueReference for v in md.modelVariables if v.causality == "output" and v.type == "Real"]
    nx = md.numberOfContinuousStates
    states = [v.valueReference for v in md.modelVariables if v.causality == "local" and v.derivative is None]
    derivs = [v.valueReference for v in md.modelVariables if v.derivative is not None]
    assert len(states) == len(derivs) == nx
    observed = {}
    messages = []

    def logger(env, instance, status, category, message):
        messages.append(message.decode("utf-8", "replace"))

    buf = np.zeros(nx)
    ptr = buf.ctypes.data_as(POINTER(fmi2Real))

    def get_states():
        m.getContinuousStates(ptr, nx)
        return buf.copy()

    def set_states(x):
        buf[:] = x
        m.setContinuousStates(ptr, nx)

    def evaluate():
        m.getDerivatives(ptr, nx)
        return np.array(m.getReal(outputs)), buf.copy()

    def probe(point: int, speed_sign: float) -> dict:
        seen = {}
        if point:
            m.reset()             # (fmpy's freeInstance unloads the library)
        m.setupExperiment(startTime=0.0)
        u0 = {}
        for v in inputs:
            x = float(v.start)
            if v.name == "vx":           # within 10 % of its start (inside the grid), or reversing
                x *= speed_sign * (1.0 + 0.1 * rng.uniform(-1.0, 1.0))
            else:
                lo = float(v.min) if v.min is not None else -np.inf
                hi = float(v.max) if v.max is not None else np.inf
                x = float(np.clip(x + rng.normal(0.0, 0.05 if v.unit == "rad" or "rate" in v.name else 0.5), lo, hi))
            u0[v.valueReference] = x
            m.setReal([v.valueReference], [x])
        m.enterInitializationMode()
        m.exitInitializationMode()
        while m.newDiscreteStates()[0]:
            pass
        m.enterContinuousTimeMode()
        x0 = get_states()
        # small state noise: away from the symmetric start, inside the clamps (e.g. a lagged speed's
        # derivative, whose clamp would hide its dependencies)
        x0 = x0 + rng.normal(0.0, 1.0, nx) * np.maximum(1e-3 * np.abs(x0), 1e-4)
        set_states(x0)
        y0, d0 = evaluate()
        for v in inputs:
            x = u0[v.valueReference]
            hi = float(v.max) if v.max is not None else np.inf
            dx = REL * max(abs(x), 1.0)
            m.setReal([v.valueReference], [x + dx if x + dx <= hi else x - dx])
            y1, d1 = evaluate()
            m.setReal([v.valueReference], [x])
            for vr, a, b in zip(outputs + derivs, np.r_[y0, d0], np.r_[y1, d1]):
                seen[(vr, v.valueReference)] = bool(a != b)
        for j, svr in enumerate(states):
            x1 = x0.copy()
            x1[j] += REL * max(abs(x0[j]), 1.0)
            set_states(x1)
            y1, d1 = evaluate()
            set_states(x0)
            for vr, a, b in zip(outputs + derivs, np.r_[y0, d0], np.r_[y1, d1]):
                seen[(vr, svr)] = bool(a != b)
        m.terminate()
        return seen

    m.instantiate(callbacks=fmpy_callbacks(logger))
    # N_POINTS points at the start speed, then one reversing (vx = -start), where a model accepts it
    for point, sign in enumerate([1.0] * N_POINTS + [-1.0]):
        try:
            seen = probe(point, sign)
        except FMICallException:
            assert sign < 0, f"{name}: the probe failed at its start speed: {messages[-3:]}"
            continue
        for key, changed in seen.items():
            observed[key] = observed.get(key, False) or changed
    m.freeInstance()
    return md, observed


@pytest.mark.parametrize("name", C_NAMES)
def test_me_dependencies_match_probing(built_fmus, name):
    path = built_fmus.c_path(name)
    root, variables, ordered, sections = _structure(path)
    if root.find("ModelExchange") is None:
        pytest.skip(f"{name}: co-simulation only (checked above)")
    md, observed = _probe_me(path, name)
    declared = {}
    for sec in ("Outputs", "Derivatives"):
        for vr, deps in sections[sec].items():
            assert deps is not None, f"{name}: {variables[vr][0]} declares no dependencies"
            declared[vr] = set(deps)
    undeclared, unseen = [], []
    for (unknown, known), seen in sorted(observed.items()):
        if variables[unknown][2] != "Real":
            continue
        if seen and known not in declared[unknown]:
            undeclared.append(f"{variables[unknown][0]} <- {variables[known][0]}")
        if not seen and known in declared[unknown]:
            unseen.append(f"{variables[unknown][0]} <- {variables[known][0]}")
    print(f"\n{name}: " + "; ".join(f"{variables[u][0]} <- {', '.join(variables[k][0] for k in sorted(d)) or '-'}"
                                   for u, d in declared.items()))
    assert not undeclared, f"{name}: undeclared dependencies found by probing: {undeclared}"
    assert not unseen, f"{name}: declared dependencies never observed by probing: {unseen}"
    # discrete (Integer) outputs change only at events: no continuous dependency
    for vr, deps in sections["Outputs"].items():
        if variables[vr][2] != "Real":
            assert deps == [], f"{name}: {variables[vr][0]} (discrete) declares {deps}"


#: run in a fresh process: fmpy's logger proxy left holding a logger freed since (the callbacks of a
#: ``simulate_fmu(logger=...)`` that has returned), then the probe, then fmpy's default callbacks
_FREED_LOGGER_HOST = """
import gc, sys
from fmpy import extract, read_model_description, simulate_fmu
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Slave
sys.path.insert(0, "cbackend")          # run from tests/: conftest there, this file in tests/cbackend
import conftest, test_model_structure

path, name = sys.argv[1], sys.argv[2]

def free_a_logger():
    simulate_fmu(path, stop_time=0.05, logger=lambda *args: None)
    gc.collect()

free_a_logger()
md, observed = test_model_structure._probe_me(path, name)
assert any(observed.values()), observed
free_a_logger()
conftest.restore_fmpy_logger()          # what every test starts with
s = FMU2Slave(guid=md.guid, unzipDirectory=extract(path), modelIdentifier=name, instanceName="default")
s.instantiate()                         # fmpy's default callbacks
s.setupExperiment(startTime=0.0)
s.enterInitializationMode()
s.exitInitializationMode()
try:
    s.setReal([10 ** 6], [1.0])         # an unknown value reference: the FMU logs an error
    sys.exit("fmi2SetReal accepted an unknown value reference")
except FMICallException:
    pass
s.terminate()
s.freeInstance()
print("survived")
"""


def test_probe_survives_a_logger_freed_before(built_fmus):
    """fmpy's native logger proxy forwards every message to the last logger registered: after a
    ``simulate_fmu(logger=...)`` has returned, that one is freed and the next message through the
    proxy crashed the process (SIGSEGV, in fmpy's ``logMessage``, when the probe ran after other
    test files). The probe registers callbacks of its own that stay alive, and every test starts
    with fmpy's printing logger registered again (``conftest.restore_fmpy_logger``)."""
    name = "SideslipBankObserver"        # logs at its mode switches: the probe crosses them
    path = built_fmus.c_path(name)
    r = subprocess.run([sys.executable, "-X", "faulthandler", "-c", _FREED_LOGGER_HOST, str(path), name],
                       cwd=Path(__file__).resolve().parents[1], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0 and "survived" in r.stdout, (r.returncode, r.stdout[-2000:], r.stderr[-2000:])
