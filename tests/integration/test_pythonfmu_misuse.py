"""pythonfmu FMUs under misuse: the FMU state functions and instantiate/free cycles.

* The FMUs do not declare ``canGetAndSetFMUstate`` / ``canSerializeFMUstate``; pythonfmu 0.7.0
  answers ``fmi2GetFMUstate`` with fmi2OK and a non-null pointer and ``fmi2SetFMUstate`` with
  fmi2OK without restoring anything. The native guard refuses all six state functions with a
  logged fmi2Error and leaves the instance running; without the guard (no C compiler at build
  time) the framework logs the error and a "restored" instance refuses every later step.
* pythonfmu 0.7.0 leaks Python objects at every instantiation and for every logged message
  (about 1.2 KB per cycle); the guard releases them (fmi2_guard.c). RSS stays flat over 2000
  instantiate/free cycles, with the library unloaded between cycles (fmpy's freeInstance) and
  with it kept loaded.

Every host runs in its own process: this file, run as a script, is that host.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from latobs import native_guard

pytestmark = pytest.mark.slow
needs_cc = pytest.mark.skipif(native_guard.find_compiler() is None, reason="no C compiler: no native guard")

STATE_CALLS = ("getFMUstate", "setFMUstate", "freeFMUstate", "serializedFMUstateSize", "serializeFMUstate",
               "deSerializeFMUstate")


def _host(*args: str, timeout: float = 300) -> dict:
    proc = subprocess.run([sys.executable, __file__, *args], capture_output=True, text=True, timeout=timeout)
    assert proc.returncode == 0, f"host {args[0]} died ({proc.returncode}):\n{proc.stdout[-2000:]}{proc.stderr[-3000:]}"
    return json.loads(proc.stdout.strip().splitlines()[-1])


# ---- the FMU state -------------------------------------------------------------------------------

@needs_cc
def test_guarded_fmu_refuses_every_state_call_and_keeps_running(built_fmus):
    fmu = built_fmus.path("MotorcycleFaultObserver")
    out = _host("state", str(fmu))
    for call in STATE_CALLS:
        assert out["status"][call] == 3, (call, out)          # fmi2Error, not pythonfmu's fmi2OK
        fn = "fmi2" + call[0].upper() + call[1:]
        assert any(s == 3 and m.startswith(f"{fn}: ") and "cannot get, set or serialize its state" in m
                   for s, m in out["log"]), (fn, out["log"])
    assert out["state_pointer"] == 0                          # no bogus state handed out
    assert out["free_null_state"] == 0                        # freeing a null state is allowed (ignored)
    assert out["step_after"] == 0 and out["outputs_finite"]   # the instance is unharmed


def test_unguarded_fmu_logs_the_refusal_and_refuses_to_step_after_a_false_restore(built_fmus, tmp_path,
                                                                                 monkeypatch):
    """Without the guard pythonfmu's fmi2OK cannot be changed: the refusal is logged as an error and
    an instance the host believes restored refuses every later step (fmi2Discard), state kept."""
    from latobs import packaging

    monkeypatch.setattr(native_guard, "find_compiler", lambda: None)
    built_fmus.path("MotorcycleFaultObserver")
    with pytest.warns(UserWarning, match="no native guard"):
        fmu = packaging.package_design(built_fmus.out / "MotorcycleFaultObserver.design.json", tmp_path)
    out = _host("state", str(fmu))
    assert out["status"]["getFMUstate"] == 0                  # pythonfmu's, out of the framework's hands
    assert any(s == 3 and "fmi2GetFMUstate" in m and "cannot" in m for s, m in out["log"]), out["log"]
    assert any(s == 3 and "fmi2SetFMUstate" in m and "cannot restore" in m for s, m in out["log"]), out["log"]
    assert out["step_after"] == 2, out                        # fmi2Discard: refused, not a silent OK
    assert out["outputs_finite"]


# ---- instantiate/free cycles ---------------------------------------------------------------------

# 2000 cycles; RSS read (after gc.collect()) at every quarter; growth judged after the warm-up
# (cycle 500). Measured from cycle 500 to 2000 (library unloaded every cycle): before the fix
# 5.4-5.7 MB (MotorcycleFaultObserver, CarPlant); after it 0-80 KB; the native C FMUs 80-180 KB.
CYCLES = 2000
MAX_GROWTH_KB = 512


@needs_cc
@pytest.mark.parametrize("name, unload", [("MotorcycleFaultObserver", True), ("CarPlant", False)],
                         ids=["MotorcycleFaultObserver-unload", "CarPlant-keep-loaded"])
def test_instantiate_free_cycles_keep_rss_flat(built_fmus, name, unload):
    fmu = built_fmus.path(name)
    out = _host("cycles", str(fmu), str(CYCLES), "unload" if unload else "keep")
    rss = {int(k): v for k, v in out["rss_kb"].items()}
    growth = rss[CYCLES] - rss[CYCLES // 4]
    assert growth < MAX_GROWTH_KB, f"{name}: RSS grew {growth} KB from cycle {CYCLES // 4} to {CYCLES}: {rss}"


# ---- the hosts -----------------------------------------------------------------------------------

def _slave(fmu: str):
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    md = read_model_description(fmu)
    folder = extract(fmu)
    variables = md.modelVariables
    info = {"inputs": [v.valueReference for v in variables if v.causality == "input"],
            "starts": [float(v.start) for v in variables if v.causality == "input"],
            "outputs": [v.valueReference for v in variables if v.causality == "output" and v.type == "Real"]}
    return (lambda: FMU2Slave(guid=md.guid, unzipDirectory=folder, modelIdentifier=md.coSimulation.modelIdentifier,
                              instanceName="misuse")), info


def _callbacks(log: list | None):
    from fmpy import calloc, free
    from fmpy.fmi2 import (fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE, fmi2CallbackFunctions,
                           fmi2CallbackLoggerTYPE)

    def logger(env, instance, status, category, message):
        if log is not None:
            log.append((status, message.decode("utf-8", "replace")))

    cb = fmi2CallbackFunctions()
    cb.logger = fmi2CallbackLoggerTYPE(logger)
    cb.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
    cb.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
    return cb


def _start(slave, cb, info, logging: bool = False) -> None:
    slave.instantiate(callbacks=cb, loggingOn=logging)   # pythonfmu drops every message unless on
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    slave.exitInitializationMode()
    slave.setReal(info["inputs"], info["starts"])


def state_host(fmu: str) -> dict:
    """Every FMU state function on a running instance, then one more step. Raw statuses."""
    import ctypes
    import math

    from fmpy.fmi2 import fmi2FMUstate

    make, info = _slave(fmu)
    log: list = []
    cb = _callbacks(log)
    slave = make()
    _start(slave, cb, info, logging=True)
    slave.doStep(currentCommunicationPoint=0.0, communicationStepSize=0.005)
    c = slave.component
    raw = {name: slave._functions["fmi2" + name[0].upper() + name[1:]] for name in STATE_CALLS}
    state = fmi2FMUstate()
    status = {"getFMUstate": raw["getFMUstate"](c, ctypes.byref(state))}
    guarded = status["getFMUstate"] != 0
    state_pointer = state.value or 0
    status["setFMUstate"] = raw["setFMUstate"](c, state)
    size = ctypes.c_size_t(0)
    status["serializedFMUstateSize"] = raw["serializedFMUstateSize"](c, state, ctypes.byref(size))
    buf = (ctypes.c_char * 16)()
    n = len(buf) if guarded else size.value                 # pythonfmu copies `n` bytes of its own
    status["serializeFMUstate"] = raw["serializeFMUstate"](c, state, buf, n)
    other = fmi2FMUstate()
    status["deSerializeFMUstate"] = raw["deSerializeFMUstate"](c, buf, n, ctypes.byref(other))
    if guarded:                                             # pythonfmu would dereference it
        bogus = fmi2FMUstate(0x1000)                        # a state this FMU never handed out
        status["freeFMUstate"] = raw["freeFMUstate"](c, ctypes.byref(bogus))
    else:                                                   # pythonfmu's own objects
        status["freeFMUstate"] = raw["freeFMUstate"](c, ctypes.byref(state))
        raw["freeFMUstate"](c, ctypes.byref(other))
    free_null = raw["freeFMUstate"](c, ctypes.byref(fmi2FMUstate()))
    slave.setReal(info["inputs"], info["starts"])
    step_after = slave._functions["fmi2DoStep"](c, 0.005, 0.005, 1)
    y = slave.getReal(info["outputs"])
    slave.terminate()
    slave.freeInstance()
    return {"status": status, "state_pointer": state_pointer,
            "free_null_state": free_null, "step_after": step_after,
            "outputs_finite": all(map(math.isfinite, y)), "log": log}


def cycles_host(fmu: str, n: int, unload: bool) -> dict:
    """n x (instantiate, setup, init, set, doStep, get, terminate, free); RSS (KB) after gc at every
    quarter of n.
    ``unload``: fmpy's freeInstance (the library is unloaded and loaded again every cycle);
    else fmi2FreeInstance with the library kept loaded."""
    import gc

    make, info = _slave(fmu)
    cb = _callbacks(None)
    page_kb = os.sysconf("SC_PAGE_SIZE") // 1024
    rss = {}
    slave = None if unload else make()
    for i in range(1, n + 1):
        if unload:
            slave = make()
        _start(slave, cb, info)
        slave.doStep(currentCommunicationPoint=0.0, communicationStepSize=0.005)
        slave.getReal(info["outputs"])
        slave.terminate()
        if unload:
            slave.freeInstance()
        else:
            slave.fmi2FreeInstance(slave.component)
        if i % max(n // 4, 1) == 0:
            gc.collect()
            with open("/proc/self/statm") as fh:
                rss[i] = int(fh.read().split()[1]) * page_kb
    if not unload:
        slave.freeLibrary()
    return {"rss_kb": rss}


if __name__ == "__main__":
    if len(sys.argv) == 3 and sys.argv[1] == "state":
        result = state_host(sys.argv[2])
    elif len(sys.argv) == 5 and sys.argv[1] == "cycles":
        result = cycles_host(sys.argv[2], int(sys.argv[3]), sys.argv[4] == "unload")
    else:
        sys.exit(f"usage: {sys.argv[0]} state FMU | cycles FMU N unload|keep")
    print(json.dumps(result), flush=True)
