"""Golden reference outputs: every FMU of ``latobs build``, both backends, reproduces its stored
reference experiment bit for bit.

``tests/integration/golden/`` holds, per FMU, the inputs and outputs of the reference experiment it carries
(FMI-LS-REF, ``latobs check``): one CSV (``time``, the inputs, the outputs; every value as the
shortest text that reads back as the same double) shared by both backends when their results are
the same bits, else one per backend (``NAME.c.csv``, ``NAME.python.csv``); ``golden.json`` says
which columns are inputs and outputs, which file each backend reads, and the platform they were
made on, the solver stack they were made with (numpy, scipy, cvxpy, clarabel, sympy, and the SIMD
kernels numpy dispatches to on that CPU) and, per
observer, its design (``NAME.design.json``, without the tables the build computes from it). Each
FMU of the session build must (1) carry exactly that experiment and (2) give those outputs when run
here on the golden inputs by a plain fmpy master. One ulp anywhere fails. With another solver stack
the LMI solutions move (1e-5 relative seen with numpy 2.5 and scipy 1.18; up to 1e-2 between an AVX2
and an AVX-512 CPU with the same packages): there the observer FMUs
checked are the golden designs packaged here, so that the runtimes and tables are still held to
the bit. Off the recording platform a libm may differ in the last bit: there the FMI-LS-REF
tolerance applies.

Regenerate (only when a change of the outputs is intended, from FMUs built by ``latobs build`` with
their design files beside them):
``PYTHONPATH=tests python tests/integration/test_golden.py C_FOLDER PYTHON_FOLDER``.
"""
from __future__ import annotations

import builtins
import copy
import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest

GOLDEN = Path(__file__).with_name("golden")
INDEX = GOLDEN / "golden.json"
BACKENDS = ("c", "python")


def _num(x: float) -> str:
    """The shortest text that reads back as the same double (integers as integers)."""
    x = float(x)
    return str(int(x)) if x.is_integer() and abs(x) < 2 ** 53 and not (x == 0 and np.signbit(x)) else repr(x)


def _csv(time, columns: dict[str, np.ndarray]) -> str:
    names = list(columns)
    rows = [",".join(["time", *names])]
    rows += [",".join(_num(v) for v in (t, *(columns[n][k] for n in names))) for k, t in enumerate(time)]
    return "\n".join(rows) + "\n"


def _read_csv(path: Path) -> tuple[list[str], np.ndarray]:
    head, *rows = path.read_text(encoding="utf-8").splitlines()
    return head.split(",")[1:], np.array([[float(x) for x in r.split(",")] for r in rows])


def golden(name: str, backend: str) -> dict:
    """{"time", "step", "platform", "inputs": {name: values}, "outputs": {name: values}} of ``name``'s
    golden experiment for ``backend``."""
    index = json.loads(INDEX.read_text(encoding="utf-8"))
    entry = index["fmus"][name]
    cols, data = _read_csv(GOLDEN / entry["files"][backend])
    assert cols == entry["inputs"] + entry["outputs"], f"{entry['files'][backend]}: columns"
    col = {n: data[:, j + 1] for j, n in enumerate(cols)}
    return {"time": data[:, 0], "step": entry["step"], "platform": index["platform"], "experiment": entry["experiment"],
            "inputs": {n: col[n] for n in entry["inputs"]}, "outputs": {n: col[n] for n in entry["outputs"]}}


#: the packages whose versions decide the LMI solutions (and so the observers' gains)
STACK = ("numpy", "scipy", "cvxpy", "clarabel", "sympy")


def solver_stack() -> dict[str, str]:
    """The versions of STACK and the SIMD extensions numpy dispatches to on this CPU (its kernels,
    and OpenBLAS's chosen by the same CPU, round differently: the LMI solutions move in the last
    bits between an AVX2 and an AVX-512 machine with the same packages)."""
    from importlib.metadata import version

    try:
        from numpy._core import _multiarray_umath as umath
    except ImportError:                       # numpy 1.x
        from numpy.core import _multiarray_umath as umath

    found = sorted(k for k, v in umath.__cpu_features__.items() if v and k in umath.__cpu_dispatch__)
    return {**{p: version(p) for p in STACK}, "cpu": " ".join(found)}


def golden_design(name: str) -> dict:
    return json.loads((GOLDEN / f"{name}.design.json").read_text(encoding="utf-8"))


_PACKAGED: dict[tuple[str, str], Path] = {}


def fmu_under_test(name: str, backend: str, built_fmus, tmp_path_factory) -> Path:
    """The FMU held against the golden file: the session build's, on the recording's solver stack
    (its design must then be the golden one); with another stack an observer's golden design
    packaged here (once per run), a plant as built."""
    from latobs import packaging, pipeline

    recorded = json.loads(INDEX.read_text(encoding="utf-8"))["stack"]
    if name not in packaging.OBSERVERS or solver_stack() == recorded:
        return built_fmus.get(name, backend)
    if (name, backend) not in _PACKAGED:
        out = tmp_path_factory.mktemp(f"golden-{name}-{backend}")
        _PACKAGED[name, backend] = pipeline.package_design_data(golden_design(name), out, backend)
    return _PACKAGED[name, backend]


def run_fmpy(fmu: Path, time: np.ndarray, step: float, inputs: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The reference run rule with fmpy alone: setupExperiment(t0, t_end), the inputs of row 0 set in
    initialisation mode, then at each t_k the inputs of row k and doStep(t_k, step); output row 0
    after initialisation, row k+1 after step k."""
    import shutil

    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    from conftest import fmpy_callbacks

    md = read_model_description(str(fmu))
    var = {v.name: v for v in md.modelVariables}
    outs = [v for v in md.modelVariables if v.causality == "output"]
    vr_in = [var[n].valueReference for n in inputs]
    real = [v.valueReference for v in outs if v.type == "Real"]
    integer = [v.valueReference for v in outs if v.type != "Real"]
    names = [v.name for v in outs if v.type == "Real"] + [v.name for v in outs if v.type != "Real"]
    assert all(var[n].type == "Real" for n in inputs)
    rows = np.column_stack(list(inputs.values()))
    result = np.zeros((len(time), len(names)))

    def sample(k: int):
        result[k] = [*s.getReal(real), *(s.getInteger(integer) if integer else [])]

    unzipdir = extract(str(fmu))
    s = FMU2Slave(guid=md.guid, unzipDirectory=unzipdir, modelIdentifier=md.coSimulation.modelIdentifier,
                  instanceName="golden")
    try:
        s.instantiate(callbacks=fmpy_callbacks(lambda *a: None))
        s.setupExperiment(startTime=float(time[0]), stopTime=float(time[-1]))
        s.enterInitializationMode()
        s.setReal(vr_in, [float(x) for x in rows[0]])
        s.exitInitializationMode()
        sample(0)
        for k in range(len(time) - 1):
            s.setReal(vr_in, [float(x) for x in rows[k]])
            s.doStep(float(time[k]), step)
            sample(k + 1)
        s.terminate()
        s.freeInstance()
    finally:
        shutil.rmtree(unzipdir, ignore_errors=True)
    return {n: result[:, j] for j, n in enumerate(names)}


def _bits(a) -> np.ndarray:
    return np.ascontiguousarray(np.asarray(a, dtype=np.float64)).view(np.uint64)


def assert_same(got: dict, want: dict, what: str, platform: str, time: np.ndarray):
    """Bit for bit on the recording platform; elsewhere the FMI-LS-REF tolerance (1e-12 of the value
    plus 1e-12 of the signal's peak)."""
    from latobs.cbackend.toolchain import host_platform

    assert sorted(got) == sorted(want), f"{what}: variables {sorted(got)} != {sorted(want)}"
    exact = host_platform() == platform
    for n, ref in want.items():
        y = np.asarray(got[n], dtype=np.float64)
        assert y.shape == ref.shape, f"{what}: {n}: {y.shape} rows != {ref.shape}"
        if exact:
            bad = np.flatnonzero(_bits(y) != _bits(ref))
        else:
            rel = 1e-12
            bad = np.flatnonzero(~(np.abs(y - ref) <= rel * np.abs(ref) + rel * np.max(np.abs(ref))))
        if bad.size:
            k = bad[0]
            pytest.fail(f"{what}: {n} differs at {bad.size} of {len(ref)} rows, first at t = {time[k]:.6g} s: "
                        f"{float(y[k])!r} vs golden {float(ref[k])!r}")


def _observer_names():
    from latobs import packaging

    return list(packaging.OBSERVERS)


def _variants():
    from conftest import C_NAMES, FMU_NAMES

    return ([pytest.param((n, "python"), id=n) for n in FMU_NAMES]
            + [pytest.param((n, "c"), id=f"{n}[c]") for n in C_NAMES])


def test_every_fmu_has_a_golden_file_for_each_backend():
    from conftest import C_NAMES, FMU_NAMES

    index = json.loads(INDEX.read_text(encoding="utf-8"))
    assert sorted(index["fmus"]) == sorted(FMU_NAMES)
    for name in FMU_NAMES:
        files = index["fmus"][name]["files"]
        assert set(files) == set(BACKENDS) if name in C_NAMES else {"python"} <= set(files), name
        for backend in files:
            g = golden(name, backend)
            assert len(g["time"]) > 100 and g["inputs"] and g["outputs"]
            assert np.array_equal(g["time"], g["time"][0] + np.arange(len(g["time"])) * g["step"]), name


@pytest.mark.parametrize("variant", _variants())
def test_fmu_reproduces_its_golden_reference_outputs(variant, built_fmus, tmp_path_factory, monkeypatch):
    """(2) runs a pythonfmu FMU with the compensated sum() of Python >= 3.12 in place of the built-in
    (the runtimes add from the left, ``fmu_src.linalg.dot``: their bits are any interpreter's)."""
    from latobs import reference

    name, backend = variant
    fmu = fmu_under_test(name, backend, built_fmus, tmp_path_factory)
    g = golden(name, backend)
    # (1) the experiment the FMU carries: the same run (for an observer, the inputs are its plant's
    # signals in the co-simulation: they check the plant of the same backend too)
    e, = reference.read(fmu)
    assert e.name == g["experiment"] and e.step == g["step"]
    assert np.array_equal(e.time, g["time"]), f"{name}[{backend}]: time"
    assert_same(e.inputs, g["inputs"], f"{name}[{backend}] carried inputs", g["platform"], g["time"])
    assert_same(e.outputs, g["outputs"], f"{name}[{backend}] carried outputs", g["platform"], g["time"])
    # (2) the FMU run here by a plain fmpy master on the golden inputs
    if backend == "python":
        monkeypatch.setattr(builtins, "sum", _compensated_sum)
    got = run_fmpy(fmu, g["time"], g["step"], g["inputs"])
    assert_same(got, g["outputs"], f"{name}[{backend}] run by fmpy", g["platform"], g["time"])


_builtin_sum = sum


def _compensated_sum(items, start=0):
    """The built-in sum() of Python >= 3.12 on floats (Neumaier's compensated summation; other
    items as the built-in does)."""
    items = list(items)
    if not all(type(x) is float for x in items) or type(start) not in (int, float):
        return _builtin_sum(items, start)
    s, c = float(start), 0.0
    for x in items:
        t = s + x
        c += (s - t) + x if abs(s) >= abs(x) else (x - t) + s
        s = t
    return s + c if c and math.isfinite(c) else s


def test_the_compensated_sum_is_not_the_sum_from_the_left():
    assert _compensated_sum([1e16, 1.0, -1e16, 1.0]) == 2.0 != ((1e16 + 1.0) - 1e16) + 1.0


@pytest.mark.parametrize("impl", ["loop", "sum"])
def test_dot_and_total_add_from_the_left(impl):
    """Both ways of ``fmu_src.linalg``'s sums (the loop, used where sum() is compensated; sum(),
    used where it adds from the left) are the left fold, start first, to the bit."""
    from functools import reduce

    from latobs.fmu_src import linalg

    if impl == "sum" and not linalg._SUM_ADDS_FROM_THE_LEFT:
        pytest.skip("this interpreter's sum() is compensated: the loop is used")
    dot, total = (linalg._dot_loop, linalg._total_loop) if impl == "loop" else (linalg._dot_sum, linalg._total_sum)
    rng = np.random.default_rng(7)
    for n in range(12):
        a = (rng.standard_normal(n) * 10.0 ** rng.integers(-20, 20, n)).tolist()
        b = (rng.standard_normal(n) * 10.0 ** rng.integers(-20, 20, n)).tolist()
        for start in (0.0, -0.0, 1e-300, -3.5):
            want = reduce(lambda s, p: s + p[0] * p[1], zip(a, b), start)
            assert _bits(dot(a, b, start)) == _bits(want)
            assert _bits(total(a, start)) == _bits(reduce(lambda s, x: s + x, a, start))
    assert dot([1.0, 1e100, 1.0, -1e100], [1.0] * 4) == total([1.0, 1e100, 1.0, -1e100]) == 0.0


@pytest.mark.parametrize("name", _observer_names())
def test_the_tables_do_not_depend_on_the_interpreters_sum(name, built_fmus, monkeypatch):
    """From Python 3.12 on the built-in sum() of floats is compensated: the tables add from the left
    (``fmu_src.linalg.dot``, ``total``) as the runtimes do, so a build gives the same tables on any
    interpreter. Here sum() is the compensated one."""
    from latobs.synthesis import tables

    design = built_fmus.design(name)
    data = copy.deepcopy(design)
    data.pop(tables.TABLES_KEY, None)
    monkeypatch.setattr(builtins, "sum", _compensated_sum)
    assert tables.compute(data) == design.get(tables.TABLES_KEY, {}), f"{name}: tables"


@pytest.mark.parametrize("name", _observer_names())
def test_on_the_recording_stack_the_design_solved_here_is_the_golden_design(name, built_fmus):
    """The designs behind the golden outputs are the designs this code solves (all but the wall-clock
    figures, the identity, which names the code, and the tables, which the build computes), when
    the solver stack is the recording's; with another one the LMI solutions may move."""
    from latobs.synthesis import design_file, tables

    recorded = json.loads(INDEX.read_text(encoding="utf-8"))["stack"]
    if solver_stack() != recorded:
        pytest.skip(f"solver stack {solver_stack()} is not the recording's {recorded}")
    strip = lambda d: {k: v for k, v in design_file.reproducible(d).items()      # noqa: E731
                       if k not in ("identity", tables.TABLES_KEY)}
    assert strip(built_fmus.design(name)) == strip(golden_design(name))


def test_a_one_ulp_change_fails():
    """The comparison catches one ulp in one value of one output."""
    g = golden("SideslipBankObserver", "c")
    got = {n: v.copy() for n, v in g["outputs"].items()}
    assert_same(got, g["outputs"], "unchanged", g["platform"], g["time"])
    got["beta_hat"][200] = np.nextafter(got["beta_hat"][200], np.inf)
    from latobs.cbackend.toolchain import host_platform

    if host_platform() != g["platform"]:
        pytest.skip("bit-for-bit comparison only on the recording platform")
    with pytest.raises(pytest.fail.Exception, match="beta_hat differs at 1 of"):
        assert_same(got, g["outputs"], "changed", g["platform"], g["time"])


def write(c_folder: Path, python_folder: Path) -> None:
    """Rewrite ``tests/integration/golden`` from the reference experiments of the FMUs in the two folders (built by
    ``latobs build --backend c`` / ``--backend python``), after checking that fmpy reproduces them."""
    from latobs import reference

    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))   # tests/: conftest
    from conftest import C_NAMES, FMU_NAMES

    GOLDEN.mkdir(exist_ok=True)
    for old in GOLDEN.glob("*.csv"):
        old.unlink()
    from latobs import packaging
    from latobs.synthesis import design_file, tables

    for old in GOLDEN.glob("*.design.json"):
        old.unlink()
    index = {"platform": None, "stack": solver_stack(), "fmus": {}}
    for name in FMU_NAMES:
        if name in packaging.OBSERVERS:
            data = design_file.reproducible(design_file.read(Path(python_folder) / f"{name}.design.json"))
            data.pop(tables.TABLES_KEY, None)
            (GOLDEN / f"{name}.design.json").write_text(design_file.dumps(data), encoding="utf-8")
        exps = {}
        for backend, folder in (("c", c_folder), ("python", python_folder)):
            if backend == "c" and name not in C_NAMES:
                continue
            e, = reference.read(Path(folder) / f"{name}.fmu")
            got = run_fmpy(Path(folder) / f"{name}.fmu", e.time, e.step, e.inputs)
            assert all(np.array_equal(_bits(got[n]), _bits(e.outputs[n])) for n in e.outputs), (name, backend)
            exps[backend] = e
            index["platform"] = index["platform"] or e.platform
            assert e.platform == index["platform"]
        texts = {b: _csv(e.time, {**e.inputs, **e.outputs}) for b, e in exps.items()}
        shared = len(set(texts.values())) == 1
        files = {b: f"{name}.csv" if shared else f"{name}.{b}.csv" for b in texts}
        for b, text in texts.items():
            (GOLDEN / files[b]).write_text(text, encoding="utf-8")
        e = next(iter(exps.values()))
        index["fmus"][name] = {"experiment": e.name, "step": e.step, "inputs": list(e.inputs),
                               "outputs": list(e.outputs), "files": files}
        print(name, files)
    INDEX.write_text(json.dumps(index, indent=1) + "\n", encoding="utf-8")


if __name__ == "__main__":
    write(Path(sys.argv[1]), Path(sys.argv[2]))
