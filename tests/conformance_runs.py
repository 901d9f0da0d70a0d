"""Subprocess runner of tests/integration/test_conformance.py and tests/integration/test_fmu_properties.py.

Two modes, each meant to run in a fresh process so that a host crash is a return code, not the end
of the pytest process:

``python conformance_runs.py libcosim SPECS.json``
    Runs, one after the other in this one process, the co-simulations of the list SPECS in
    libcosim (libcosimpy) and prints one JSON line ``{"results": [{"outputs": {slave: {output:
    [value after step 1, ..., after step n]}}}, ...]}``. Each SPEC::

        {"dt": 0.005, "n": 400,
         "slaves": [{"name": "plant", "path": "CarPlant.fmu",
                     "initial": {input: value},          # set before initialisation (t0)
                     "inputs": {input: [u_0, ..., u_{n-1}]}}, ...],   # overridden before step k
         "connections": [[from_slave, output, to_slave, input], ...]}

    Timing: libcosim's fixed-step algorithm sets the overridden inputs u_k and the connected
    inputs (the source's outputs after the previous step, i.e. at t_k) before every slave steps
    from t_k to t_k + dt: the harness's convention (an observer at step k sees the plant outputs at
    t_k). libcosim records after each step: there is no t0 sample. libcosim counts time in integer
    nanoseconds and hands the FMU t_k = k dt_ns / 1e9 and the step t_{k+1} - t_k, which differs
    from dt by a few ulps (the tests reproduce that grid in fmpy). Each FMU is copied into a fresh
    folder, deleted after the execution is released.

``python conformance_runs.py serve FMU``
    The property tests' worker: reads one JSON program per line on stdin, runs it on the FMU
    (extracted once) through fmpy's FMU2Slave, prints one JSON line per program. A program is a
    list of calls ``[op, args...]`` (see :func:`run_program`); every call's fmi2Status is
    recorded. No call of a program can reach a freed instance (that would be the host's bug).
    If the FMU crashes the host, the worker dies and the test sees it (the return code and the
    last program).
"""
from __future__ import annotations

import json
import os
import time
import shutil
import sys
import tempfile
from pathlib import Path


# ---------------------------------------------------------------------------------------------
# libcosim
# ---------------------------------------------------------------------------------------------
def run_libcosim(spec: dict) -> dict:
    from fmpy import read_model_description
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimManipulator import CosimManipulator
    from libcosimpy.CosimObserver import CosimObserver
    from libcosimpy.CosimSlave import CosimLocalSlave

    log_output_level(CosimLogLevel.DEBUG if os.environ.get("LCDEBUG") else CosimLogLevel.ERROR)
    dt, n = float(spec["dt"]), int(spec["n"])
    folder = Path(tempfile.mkdtemp(prefix="latobs_conformance_"))
    out: dict[str, dict[str, list[float]]] = {}
    try:
        ex = CosimExecution.from_step_size(step_size=int(round(dt * 1e9)))
        obs = CosimObserver.create_last_value()
        ex.add_observer(obs)
        man = CosimManipulator.create_override()
        ex.add_manipulator(man)
        slaves = {}
        for s in spec["slaves"]:
            src = Path(s["path"])
            (folder / s["name"]).mkdir()
            copy = folder / s["name"] / src.name
            shutil.copy(src, copy)
            md = read_model_description(str(copy))
            var = {v.name: v for v in md.modelVariables}
            idx = ex.add_local_slave(CosimLocalSlave(fmu_path=str(copy), instance_name=s["name"]))
            real_out = [v for v in md.modelVariables if v.causality == "output" and v.type == "Real"]
            int_out = [v for v in md.modelVariables if v.causality == "output" and v.type == "Integer"]
            slaves[s["name"]] = (idx, var, real_out, int_out)
            for name, value in s.get("initial", {}).items():
                ex.real_initial_value(idx, var[name].valueReference, float(value))
            out[s["name"]] = {v.name: [] for v in [*real_out, *int_out]}
        for a, y, b, u in spec.get("connections", []):
            ia, va = slaves[a][0], slaves[a][1][y].valueReference
            ib, vb = slaves[b][0], slaves[b][1][u].valueReference
            ex.connect_real_variables(ia, va, ib, vb)
        driven = []
        for s in spec["slaves"]:
            idx, var, _, _ = slaves[s["name"]]
            names = list(s.get("inputs", {}))
            if names:
                driven.append((idx, [var[x].valueReference for x in names], [s["inputs"][x] for x in names]))
        for k in range(n):
            for idx, vrs, series in driven:
                man.slave_real_values(idx, vrs, [float(v[k]) for v in series])
            if not ex.step():
                raise RuntimeError(f"libcosim step {k} failed")
            for name, (idx, _, real_out, int_out) in slaves.items():
                rec = out[name]
                if real_out:
                    for v, x in zip(real_out, obs.last_real_values(idx, [v.valueReference for v in real_out])):
                        rec[v.name].append(float(x))
                if int_out:
                    for v, x in zip(int_out, obs.last_integer_values(idx, [v.valueReference for v in int_out])):
                        rec[v.name].append(float(x))
        ex = obs = man = None  # unload the FMUs before their folder is deleted
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    return {"outputs": out}


#: constant, realistic inputs (SI; any other input 0): a steady turn at 15 m/s
STEADY = {"delta": 0.02, "vx": 15.0, "yaw_rate": 0.1, "ay": 1.0, "roll_angle": 0.01, "roll_rate": 0.0,
          "bank_angle": 0.0, "steer_angle": 0.01, "rider_torque": 5.0, "stiffness_scale_f": 1.0,
          "stiffness_scale_r": 1.0}
#: issue 47, item 2 (None: the FMU's longest step, at most 1 s): doStep(5e-324) returned OK and every
#: estimate of the paper-000 observers stayed NaN for good; then 1e-310 s (where 1/h overflows),
#: tiny and long steps alternating, a step of 1e300 s (refused) and a tiny one after it
SUBNORMAL_STEPS = [0.005, 5e-324, 0.005, 0.005, 1e-310, 0.005, 5e-324, 5e-324, 2.0 ** -30, 0.005, 1e-300, None,
                   5e-324, None, 1e-310, None, 5e-324, 0.005, 1e300, 5e-324, 0.005]


def declared_max_step(path) -> float:
    """The longest communication step an FMU accepts (s), from its model description (inf if it
    declares none)."""
    import zipfile
    from xml.etree import ElementTree

    with zipfile.ZipFile(path) as z:
        root = ElementTree.fromstring(z.read("modelDescription.xml"))
    el = root.find("VendorAnnotations/Tool[@name='latobs']/CommunicationStep")
    return float("inf") if el is None else float(el.get("max"))


# ---------------------------------------------------------------------------------------------
# property worker
# ---------------------------------------------------------------------------------------------
class _Worker:
    """One FMU, extracted once; instances created and freed by the programs."""

    def __init__(self, path: Path):
        from fmpy import extract, read_model_description

        self.path = path
        self.md = read_model_description(str(path))
        self.unzipdir = extract(str(path))
        self.vars = {v.name: v for v in self.md.modelVariables}
        self.inputs = [v for v in self.md.modelVariables if v.causality == "input"]
        self.real_out = [v for v in self.md.modelVariables if v.causality == "output" and v.type == "Real"]
        self.int_out = [v for v in self.md.modelVariables if v.causality == "output" and v.type == "Integer"]
        self.count = 0

    def close(self):
        shutil.rmtree(self.unzipdir, ignore_errors=True)

    def new_instance(self):
        from latobs.validation.harness import FmuInstance

        self.count += 1
        fmu = FmuInstance(f"p{self.count}", self.path, self.unzipdir)
        fmu.instantiate()
        return fmu


def _status(fn, *args) -> int:
    """fmi2Status of one raw FMI call (fmpy returns it up to fmi2Warning and raises above)."""
    try:
        return int(fn(*args))
    except Exception as exc:          # fmpy's FMICallException carries the status
        st = getattr(exc, "status", None)
        if st is None:
            raise
        return int(st)


def run_program(w: _Worker, program: list) -> dict:
    """Run a list of calls; returns every call's fmi2Status and every read, and the last logs.

    Calls: ``["new"]`` (instantiate a new instance, freeing the previous one), ``["setup", t0]``,
    ``["enter"]``, ``["exit"]``, ``["set", {input: value}]``, ``["step", t, h]``, ``["get"]``
    (every Real and Integer output), ``["terminate"]``, ``["reset"]``. The last instance is freed
    at the end. Only these calls exist: a program cannot call into a freed instance. ``seconds``:
    the wall time of every call, in order."""
    from fmpy.fmi2 import fmi2False, fmi2Integer, fmi2Real, fmi2True, fmi2ValueReference

    fmu = None
    log = []
    messages: list[str] = []
    seconds: list[float] = []
    rvr = (fmi2ValueReference * len(w.real_out))(*[v.valueReference for v in w.real_out])
    ivr = (fmi2ValueReference * len(w.int_out))(*[v.valueReference for v in w.int_out])
    try:
        for call in program:
            op = call[0]
            t0 = time.perf_counter()
            if op == "new":
                if fmu is not None:
                    messages = list(fmu.logs)
                    fmu.slave.freeInstance()
                fmu = None
                fmu = w.new_instance()
                log.append(["new", 0])
                continue
            s = fmu.slave
            c = s.component
            if op == "setup":
                st = _status(s.fmi2SetupExperiment, c, fmi2False, 0.0, float(call[1]), fmi2False, 0.0)
            elif op == "enter":
                st = _status(s.fmi2EnterInitializationMode, c)
            elif op == "exit":
                st = _status(s.fmi2ExitInitializationMode, c)
            elif op == "set":
                names = list(call[1])
                vr = (fmi2ValueReference * len(names))(*[w.vars[x].valueReference for x in names])
                buf = (fmi2Real * len(names))(*[float(call[1][x]) for x in names])
                st = _status(s.fmi2SetReal, c, vr, len(names), buf)
            elif op == "step":
                st = _status(s.fmi2DoStep, c, float(call[1]), float(call[2]), fmi2True)
            elif op == "terminate":
                st = _status(s.fmi2Terminate, c)
            elif op == "reset":
                st = _status(s.fmi2Reset, c)
            elif op == "get":
                rbuf = (fmi2Real * len(w.real_out))()
                ibuf = (fmi2Integer * len(w.int_out))()
                st = _status(s.fmi2GetReal, c, rvr, len(w.real_out), rbuf)
                if w.int_out:
                    st = max(st, _status(s.fmi2GetInteger, c, ivr, len(w.int_out), ibuf))
                values = {v.name: float(x) for v, x in zip(w.real_out, rbuf)}
                values.update({v.name: int(x) for v, x in zip(w.int_out, ibuf)})
                log.append(["get", st, values])
                seconds.append(time.perf_counter() - t0)
                continue
            else:
                raise ValueError(f"unknown call {op!r}")
            log.append([op, st])
            seconds.append(time.perf_counter() - t0)
    finally:
        if fmu is not None:
            messages = list(fmu.logs)
            fmu.slave.freeInstance()
    return {"calls": log, "logs": messages[-20:], "seconds": seconds}


def serve(path: Path) -> int:
    w = _Worker(path)
    try:
        for line in sys.stdin:
            if not line.strip():
                continue
            res = run_program(w, json.loads(line))
            sys.stdout.write(json.dumps(res) + "\n")
            sys.stdout.flush()
    finally:
        w.close()
    return 0


def main(argv: list[str]) -> int:
    if argv[0] == "libcosim":
        specs = json.loads(Path(argv[1]).read_text())
        print(json.dumps({"results": [run_libcosim(spec) for spec in specs]}))
        return 0
    if argv[0] == "serve":
        return serve(Path(argv[1]))
    raise SystemExit(f"unknown mode {argv[0]!r}")


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
