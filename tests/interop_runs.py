"""Run latobs FMUs one after another in ONE process, as a user would, in fmpy or in libcosim.

Used by tests/integration/test_fmu_interop.py in fresh subprocesses:

    python interop_runs.py fmpy|libcosim FMU [FMU ...]   ->  JSON {"runs": [{fmu, outputs}]}

Each FMU is copied into its own fresh folder (and, for fmpy, extracted there), simulated for 1 s
at 5 ms with inputs defined on the grid, and the folder is deleted before the next FMU is
loaded, as fmpy's and libcosim's own unloading does. Only the built FMUs are used.
"""
from __future__ import annotations

import json
import math
import shutil
import sys
import tempfile
from pathlib import Path

H = 0.005
N = 200


def signals(k: int) -> dict[str, float]:
    """Every input any latobs car FMU has, at t_k = k H: speeds crossing the paper-000 modes."""
    t = k * H
    return {"delta": 0.01 * math.sin(3.0 * t), "vx": 27.0 - 8.0 * t, "bank_angle": 0.02 * (t > 0.3),
            "yaw_rate": 0.08 * math.sin(3.0 * t + 0.2), "roll_angle": 0.01 * math.sin(3.0 * t + 0.4),
            "roll_rate": 0.03 * math.cos(3.0 * t + 0.4),
            "stiffness_scale_f": 1.0 + 0.05 * math.sin(2.0 * t), "stiffness_scale_r": 1.0 - 0.05 * math.sin(2.0 * t)}


def run_fmpy(path: Path) -> dict[str, list[float]]:
    import numpy as np
    from fmpy import extract, read_model_description, simulate_fmu

    md = read_model_description(str(path))
    inputs = [v.name for v in md.modelVariables if v.causality == "input"]
    outputs = [v.name for v in md.modelVariables if v.causality == "output"]
    sig = np.array([tuple([k * H] + [signals(k)[n] for n in inputs]) for k in range(N + 1)],
                   dtype=[("time", float)] + [(n, float) for n in inputs])
    unzipdir = extract(str(path))
    try:
        res = simulate_fmu(unzipdir, start_time=0.0, stop_time=N * H, step_size=H, output_interval=H,
                           input=sig, output=outputs, model_description=md)
    finally:
        shutil.rmtree(unzipdir)
    assert not Path(unzipdir).exists()
    return {n: [float(x) for x in res[n]] for n in outputs}


def run_libcosim(path: Path) -> dict[str, list[float]]:
    from fmpy import read_model_description
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimManipulator import CosimManipulator
    from libcosimpy.CosimObserver import CosimObserver
    from libcosimpy.CosimSlave import CosimLocalSlave

    md = read_model_description(str(path))
    inputs = {v.name: v.valueReference for v in md.modelVariables if v.causality == "input"}
    real_out = {v.name: v.valueReference for v in md.modelVariables if v.causality == "output" and v.type == "Real"}
    int_out = {v.name: v.valueReference for v in md.modelVariables if v.causality == "output" and v.type == "Integer"}
    log_output_level(CosimLogLevel.ERROR if not __import__("os").environ.get("LCDEBUG") else CosimLogLevel.DEBUG)
    folder = Path(tempfile.mkdtemp(prefix="latobs_libcosim_"))
    copy = folder / path.name
    shutil.copy(path, copy)
    out = {n: [] for n in [*real_out, *int_out]}
    try:
        ex = CosimExecution.from_step_size(step_size=int(H * 1e9))
        idx = ex.add_local_slave(CosimLocalSlave(fmu_path=str(copy), instance_name=path.stem))
        obs = CosimObserver.create_last_value()
        ex.add_observer(obs)
        man = CosimManipulator.create_override()
        ex.add_manipulator(man)
        for n, vr in inputs.items():
            ex.real_initial_value(idx, vr, signals(0)[n])

        def record():
            for n, x in zip(real_out, obs.last_real_values(idx, list(real_out.values()))):
                out[n].append(float(x))
            if int_out:
                for n, x in zip(int_out, obs.last_integer_values(idx, list(int_out.values()))):
                    out[n].append(float(x))

        for k in range(N):
            u = signals(k)
            man.slave_real_values(idx, list(inputs.values()), [u[n] for n in inputs])
            assert ex.step(), f"libcosim step {k} failed"
            record()
        ex = obs = man = None  # unload the FMU before its folder is deleted
    finally:
        shutil.rmtree(folder)
    return out


def main(argv: list[str]) -> int:
    importer, paths = argv[0], [Path(p) for p in argv[1:]]
    run = {"fmpy": run_fmpy, "libcosim": run_libcosim}[importer]
    runs = [{"fmu": str(p), "outputs": run(p)} for p in paths]
    print(json.dumps({"runs": runs}))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
