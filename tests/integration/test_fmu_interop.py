"""FMUs as users load them: many in one process (fmpy and libcosim), identity, model description.

Sequences run in fresh subprocesses (``interop_runs.py``) so that a crash or a leaked module of
one FMU cannot hide behind the test process's own state, and so that the reference result of
each FMU is the one it gives alone in a fresh process.
"""
from __future__ import annotations

import hashlib
import json
import math
import subprocess
import sys
import textwrap
import zipfile
from pathlib import Path
from xml.etree import ElementTree

import pytest
from fmpy import extract, read_model_description

from latobs import native_guard, packaging
from latobs.synthesis import design_file
from latobs.validation.harness import FmuInstance

pytestmark = pytest.mark.slow
RUNS = Path(__file__).resolve().parents[1] / "interop_runs.py"
H = 0.005


def _runs(importer: str, paths: list[Path]) -> list[dict]:
    proc = subprocess.run([sys.executable, str(RUNS), importer, *map(str, paths)], capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0, f"{importer} run of {[p.name for p in paths]} died ({proc.returncode}): " \
                                 f"{proc.stderr[-2000:]}"
    return json.loads(proc.stdout.strip().splitlines()[-1])["runs"]


@pytest.fixture(scope="module")
def fmus(fmu_dir, tmp_path_factory, design_speed, design_speed_other_gains, built_fmus):
    """The three FMUs, plus a SideslipBankObserver with other gains and one 'from another latobs
    version' (same class name, same gains, other runtime package and guid), and the native C
    builds of the three (same model identifiers and file names as the pythonfmu ones)."""
    other_dir = tmp_path_factory.mktemp("other_gains")
    other = design_speed_other_gains
    other_fmu = packaging.package_design(design_file.write(other, other_dir), other_dir)
    old_dir = tmp_path_factory.mktemp("other_version")
    mp = pytest.MonkeyPatch()
    mp.setattr(packaging, "__version__", "0.0.1")
    try:
        old_fmu = packaging.package_design(design_file.write(design_speed, old_dir), old_dir)
    finally:
        mp.undo()
    out = {"plant": fmu_dir / "CarPlant.fmu", "speed": fmu_dir / "SideslipBankObserver.fmu",
           "tire": fmu_dir / "SideslipBankObserverTire.fmu", "other_gains": other_fmu, "old_version": old_fmu}
    if native_guard.find_compiler() is not None:
        out.update(c_plant=built_fmus.c_path("CarPlant"), c_speed=built_fmus.c_path("SideslipBankObserver"),
                   c_tire=built_fmus.c_path("SideslipBankObserverTire"))
    return out


@pytest.fixture(scope="module")
def references(fmus):
    """Each FMU's outputs when simulated alone in a fresh process (fmpy)."""
    return {k: _runs("fmpy", [p])[0]["outputs"] for k, p in fmus.items()}


def _assert_same(got: dict, ref: dict, label: str, shift: int = 0, tol: float = 1e-9):
    assert set(got) == set(ref), label
    for name, values in got.items():
        r = ref[name][shift:]
        assert len(values) == len(r), (label, name)
        worst = max(abs(a - b) / max(1.0, abs(b)) for a, b in zip(values, r))
        assert worst <= tol, f"{label}: {name} differs from its reference by {worst:.3g}"


SEQUENCES = [
    ["plant", "speed", "tire", "plant"],                       # the order of the issue report
    ["tire", "speed", "plant", "tire", "speed"],               # the reverse, and reloads
    ["speed", "other_gains", "old_version", "speed", "plant", "other_gains"],  # same name, other content
    # native C and pythonfmu FMUs of the same model identifiers side by side, unloaded and reloaded
    ["c_plant", "speed", "c_speed", "plant", "c_tire", "tire", "c_speed", "c_plant"],
]
#: the libcosim sequences (each a fresh process)
LIBCOSIM = [SEQUENCES[0], SEQUENCES[1], SEQUENCES[3]]


def _available(fmus, seq) -> None:
    missing = [k for k in seq if k not in fmus]
    if missing:
        pytest.skip(f"no native C FMUs here (no C compiler): {', '.join(missing)}")


@pytest.mark.parametrize("seq", SEQUENCES, ids=["-".join(s) for s in SEQUENCES])
def test_any_sequence_of_fmus_in_one_fmpy_process(fmus, references, seq):
    _available(fmus, seq)
    runs = _runs("fmpy", [fmus[k] for k in seq])
    for k, run in zip(seq, runs):
        _assert_same(run["outputs"], references[k], f"fmpy {'-'.join(seq)}: {k}", tol=0.0)


@pytest.mark.parametrize("seq", LIBCOSIM, ids=["-".join(s) for s in LIBCOSIM])
def test_any_sequence_of_fmus_in_one_libcosim_process(fmus, references, seq):
    """libcosim records after each step (no t0 sample): compared with fmpy's from t1 on."""
    _available(fmus, seq)
    runs = _runs("libcosim", [fmus[k] for k in seq])
    for k, run in zip(seq, runs):
        _assert_same(run["outputs"], references[k], f"libcosim {'-'.join(seq)}: {k}", shift=1, tol=1e-12)


def test_other_gains_give_other_results(references):
    """The sequences above would pass trivially if all observers computed the same thing."""
    a, b = references["speed"]["bank_angle_hat"], references["other_gains"]["bank_angle_hat"]
    assert max(abs(x - y) for x, y in zip(a, b)) > 1e-4


# ---------------------------------------------------------------------------------------------
# identity
# ---------------------------------------------------------------------------------------------
def _md_root(path: Path) -> ElementTree.Element:
    with zipfile.ZipFile(path) as z:
        return ElementTree.fromstring(z.read("modelDescription.xml"))


def test_two_builds_are_byte_identical(tmp_path, design_speed):
    a, b = tmp_path / "a", tmp_path / "b"
    for out in (a, b):
        packaging.package_design(design_file.write(design_speed, out), out)
        packaging.package_plant("CarPlant", None, out)
    for name in ("SideslipBankObserver.fmu", "CarPlant.fmu"):
        da, db = (hashlib.sha256((d / name).read_bytes()).hexdigest() for d in (a, b))
        assert da == db, name
    with zipfile.ZipFile(a / "CarPlant.fmu") as z:
        assert {i.date_time for i in z.infolist()} == {packaging.ZIP_DATE}
        assert [i.filename for i in z.infolist()] == sorted(i.filename for i in z.infolist())


def test_guid_follows_the_content(fmus, fmu_dir):
    guid = {k: _md_root(p).get("guid") for k, p in fmus.items()}
    assert len(set(guid.values())) == len(guid)                 # other gains, version, model: other guid
    assert all(g.startswith("{") and len(g) == 38 for g in guid.values())
    # the same sources and design give the same guid (the byte-identical test covers the rest)
    assert guid["speed"] == read_model_description(str(fmu_dir / "SideslipBankObserver.fmu")).guid


def test_model_description_identifies_latobs(fmus):
    from latobs import __version__

    for k, p in fmus.items():
        root = _md_root(p)
        assert root.get("generationTool").startswith("latobs "), k
        assert root.get("license") == "MIT" and root.get("copyright") and root.get("author") == "latobs"
        assert root.get("generationDateAndTime") is None            # reproducible
        if k != "old_version":
            assert root.get("version") == __version__
    descriptions = {k: _md_root(fmus[k]).get("description") for k in ("speed", "tire", "plant")}
    assert "speed modes" in descriptions["speed"] and "tire modes" in descriptions["tire"]
    assert len(set(descriptions.values())) == 3


@pytest.mark.skipif(native_guard.find_compiler() is None, reason="no C compiler: FMUs carry no native guard")
def test_an_instantiation_with_a_wrong_guid_is_refused(fmus, tmp_path):
    path = fmus["speed"]
    md = read_model_description(str(path))
    unzipdir = extract(str(path), unzipdir=str(tmp_path / "x"))
    for guid, ok in (("{00000000-0000-5000-0000-000000000000}", False), (md.guid, True)):
        fmu = FmuInstance("guid", path, unzipdir)
        fmu.md.guid = guid
        if ok:
            fmu.instantiate()
            fmu.close()
            continue
        with pytest.raises(Exception, match="instantiate"):
            fmu.instantiate()
        assert any(m.startswith("[ERROR]") and "guid" in m.lower() and md.guid in m for m in fmu.logs), fmu.logs
        fmu.slave.freeLibrary()


# ---------------------------------------------------------------------------------------------
# model description a tool can use
# ---------------------------------------------------------------------------------------------
def test_outputs_declare_no_direct_feedthrough_and_it_is_true(fmus):
    """Outputs change only in doStep: declared with empty dependencies, and perturbing every input
    (and leaving it perturbed) without stepping leaves every output as it was."""
    for k in ("plant", "speed", "tire"):
        path = fmus[k]
        root = _md_root(path)
        unknowns = root.find("ModelStructure/Outputs").findall("Unknown")
        assert unknowns and all(u.get("dependencies") == "" for u in unknowns), k
        fmu = FmuInstance(k, path)
        names = [v.name for v in fmu.inputs]
        fmu.start({n: {"vx": 20.0}.get(n, 0.01) for n in names})
        try:
            base = {"vx": 20.0, "stiffness_scale_f": 1.0, "stiffness_scale_r": 1.0}    # inside the declared ranges
            for i in range(20):
                fmu.set_inputs({n: base.get(n, 0.0) + 0.02 * math.sin(i + len(n)) for n in names})
                fmu.slave.doStep(i * H, H)
                before = fmu.get_outputs()
                for scale in (10.0, -3.0, 0.0):
                    fmu.set_inputs({n: {"vx": 5.0 + abs(scale)}.get(n, scale * 0.1) for n in names})
                    assert fmu.get_outputs() == before, (k, i, scale)
        finally:
            fmu.close()


def test_model_description_bounds_units_and_experiment(fmus):
    md = {k: read_model_description(str(fmus[k])) for k in ("plant", "speed", "tire")}
    var = {k: {v.name: v for v in m.modelVariables} for k, m in md.items()}
    plant, speed, tire = var["plant"], var["speed"], var["tire"]
    assert float(plant["mu"].min) > 0 and float(plant["scale_f"].min) > 0 and float(plant["sigma"].min) >= 0
    assert float(speed["vx_hold"].min) > 0 and float(tire["vx_hold"].min) > 0
    assert (int(speed["mode"].min), int(speed["mode"].max)) == (1, 3)
    assert (int(tire["mode"].min), int(tire["mode"].max)) == (1, 2)
    for name in ("mu", "scale_f", "scale_r"):
        assert plant[name].unit == "1", name
    assert plant["sigma"].unit == "m"
    assert speed["beta_hat"].unit == "rad" and speed["beta_hat"].displayUnit == "deg"
    assert speed["yaw_rate"].displayUnit == "deg/s" and speed["vx"].displayUnit == "km/h"
    units = {u.name: u for u in md["speed"].unitDefinitions}
    assert {d.name: d.factor for d in units["m/s"].displayUnits} == {"km/h": 3.6}
    assert abs(units["rad"].displayUnits[0].factor - 180 / math.pi) < 1e-12
    for k, m in md.items():
        assert m.defaultExperiment.stopTime and float(m.defaultExperiment.stopTime) > 0, k
        assert float(m.defaultExperiment.stepSize) == H


def test_a_parameter_outside_its_declared_range_is_refused(fmus):
    path = fmus["plant"]
    fmu = FmuInstance("mu", path)
    fmu.start(parameters={"mu": -1.0})
    try:
        fmu.set_inputs({"delta": 0.0, "vx": 10.0, "bank_angle": 0.0})
        with pytest.raises(Exception, match="discard"):
            fmu.slave.doStep(0.0, H)
    finally:
        fmu.close()
    assert any("'mu'" in m and "outside its declared range" in m for m in fmu.logs), fmu.logs


# ---------------------------------------------------------------------------------------------
# misuse never crashes the host
# ---------------------------------------------------------------------------------------------
BAD_CALLS = textwrap.dedent("""
    import sys
    from pathlib import Path
    from fmpy.fmi2 import fmi2ValueReference, fmi2Real
    from latobs.validation.harness import FmuInstance
    path = Path(sys.argv[1])
    fmu = FmuInstance("bad", path)
    fmu.instantiate()
    s = fmu.slave
    s.setupExperiment(startTime=0.0)
    s.enterInitializationMode()
    s.exitInitializationMode()
    vr = (fmi2ValueReference * 1)(9999)
    buf = (fmi2Real * 1)(1.0)
    statuses = []
    def status(fn):
        try:
            return fn(s.component, vr, 1, buf)
        except Exception as e:            # fmpy raises on a status above fmi2Warning
            return e.status
    for i in range(10):
        statuses.append(status(s.fmi2GetReal))
        statuses.append(status(s.fmi2SetReal))
    ins = [v for v in fmu.inputs]
    s.setReal([v.valueReference for v in ins], [20.0 if v.name == "vx" else 0.01 for v in ins])
    s.doStep(0.0, 0.005)
    outs = s.getReal([v.valueReference for v in fmu.outputs if v.type == "Real"])
    fmu.initialized = True
    fmu.close()
    errors = sum(m.startswith("[ERROR]") and "9999" in m for m in fmu.logs)
    print("alive", sorted(set(statuses)), all(abs(x) < 1e9 for x in outs), errors)
""")


@pytest.mark.parametrize("guarded", [True, False], ids=["native-guard", "python-only"])
def test_ten_unknown_value_references_leave_the_host_alive(tmp_path, design_speed, guarded, monkeypatch):
    if guarded and native_guard.find_compiler() is None:
        pytest.skip("no C compiler: FMUs carry no native guard")
    if not guarded:
        monkeypatch.setattr(native_guard, "find_compiler", lambda: None)
    with pytest.warns(UserWarning, match="no native guard") if not guarded else _nothing():
        path = packaging.package_design(design_file.write(design_speed, tmp_path), tmp_path)
    with zipfile.ZipFile(path) as z:
        assert (f"binaries/linux64/{path.stem}_pythonfmu.so" in z.namelist()) == guarded
    proc = subprocess.run([sys.executable, "-P", "-c", BAD_CALLS, str(path)], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, f"host died ({proc.returncode}): {proc.stderr[-2000:]}"
    line = proc.stdout.strip().splitlines()[-1]
    # the guard answers fmi2Error (3); without it pythonfmu can only say fmi2OK (0) and the
    # framework logs the error instead of raising into pythonfmu
    assert line == ("alive [3] True 20" if guarded else "alive [0] True 20"), line


class _nothing:
    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False


# ---------------------------------------------------------------------------------------------
# what an importing machine needs (the README's section says exactly this)
# ---------------------------------------------------------------------------------------------
def _glibc_versions(lib: Path) -> set[tuple[int, ...]]:
    out = subprocess.run(["objdump", "-T", str(lib)], capture_output=True, text=True, check=True).stdout
    found = set()
    for token in out.replace("(", " ").replace(")", " ").split():
        if token.startswith("GLIBC_") and token[6:].replace(".", "").isdigit():
            found.add(tuple(int(x) for x in token[6:].split(".")))
    return found


def _needed(lib: Path) -> set[str]:
    out = subprocess.run(["objdump", "-p", str(lib)], capture_output=True, text=True, check=True).stdout
    return {ln.split()[1] for ln in out.splitlines() if ln.strip().startswith("NEEDED")}


@pytest.mark.skipif(subprocess.run(["which", "objdump"], capture_output=True).returncode != 0,
                    reason="objdump (binutils) not installed")
def test_linux_binaries_need_glibc_2_32_and_no_libpython(fmus, tmp_path):
    with zipfile.ZipFile(fmus["speed"]) as z:
        z.extractall(tmp_path)
    binaries = tmp_path / "binaries" / "linux64"
    real = binaries / ("SideslipBankObserver_pythonfmu.so" if (binaries / "SideslipBankObserver_pythonfmu.so").exists()
                       else "SideslipBankObserver.so")
    assert max(_glibc_versions(real)) == (2, 32)
    assert not any("python" in n for n in _needed(real))      # the host must provide libpython
    guard = binaries / "SideslipBankObserver.so"
    if guard != real:
        assert max(_glibc_versions(guard)) <= (2, 17)
        assert _needed(guard) <= {"libc.so.6", "libdl.so.2"}
