"""What `latobs build` (and every command that builds a missing FMU) writes, and when it reuses:

* an FMU is reused only when it carries the identity of what would be built now (vehicle file
  content, options, backend, code); an edited vehicle file rebuilds it, saying what changed;
* nothing run-dependent enters an FMU: two builds give byte-identical FMUs, every FMU, both
  backends;
* names are FMI modelIdentifiers: a vehicle ``name`` never makes a path outside --out, and a
  refused name leaves nothing behind;
* a design file and its FMU are written as one unit under the output folder's lock: a build
  killed mid-way, a failed packaging or two concurrent builds never leave a mismatched pair, and
  the temporaries of a killed build are removed by the next one;
* the FMUs of two backends never silently replace each other in one folder.
"""
from __future__ import annotations

import copy
import json
import os
import re
import signal
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import pytest

from latobs.packaging import complete_runtime_data
from latobs import cache, identity, packaging, pipeline
from latobs.atomic import LOCK_TIMEOUT_ENV, locked_folder, stale_temporaries
from latobs.cli import main
from latobs.native_guard import find_compiler
from latobs.pipeline import build, build_summary, ensure_plant
from latobs.synthesis import design_file, designs

from conftest import FMU_VARIANTS

SEDAN_TOML = Path(__file__).resolve().parents[2] / "synthesis" / "vehicles" / "sedan.toml"
needs_cc = pytest.mark.skipif(find_compiler() is None, reason="no C compiler: the native backend cannot build")


def _vehicle_file(folder: Path, name: str, file: str = "car.toml", **values) -> Path:
    """The sedan's TOML file with ``name`` (any string, TOML-quoted) and some values replaced."""
    text = SEDAN_TOML.read_text().replace('name = "sedan"', f"name = {json.dumps(name)}")
    for k, v in values.items():
        text, n = re.subn(rf"^{k}(\s*)= \{{ value = [^,]+,", rf"{k}\1= {{ value = {v},", text, flags=re.M)
        assert n == 1, k
    path = folder / file
    path.write_text(text)
    return path


def _inner(fmu: Path, member: str) -> dict:
    with zipfile.ZipFile(fmu) as z:
        return json.loads(z.read(member))


def _plain(data: dict) -> dict:
    """A design dict as its file holds it (numpy arrays as lists)."""
    return json.loads(design_file.dumps(data))


def _main(argv) -> int:
    """``main(argv)``'s exit code (argparse's errors exit by SystemExit)."""
    try:
        return main([str(a) for a in argv])
    except SystemExit as exc:
        return exc.code


def _tree(root: Path) -> dict[str, bytes]:
    return {p.relative_to(root).as_posix(): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def _latobs(*args, **kw) -> subprocess.Popen:
    """`python -m latobs ARGS` in a new process (-P: the installed package)."""
    return subprocess.Popen([sys.executable, "-P", "-m", "latobs", *map(str, args)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, **kw)


# ---------------------------------------------------------------------------------------------
# item 2: reuse only on an identical identity
# ---------------------------------------------------------------------------------------------
def test_a_design_identity_is_the_content_of_its_inputs(tmp_path):
    """The identity of a design is known before solving: the vehicle's content (not the file it
    came from), the options, the catalogue entry, the code; nothing run-dependent."""
    a = identity.of_design("LateralIntervalObserver", str(_vehicle_file(tmp_path, "mycar")))
    (tmp_path / "elsewhere").mkdir()
    same = identity.of_design("LateralIntervalObserver", str(_vehicle_file(tmp_path / "elsewhere", "mycar", "b.toml")))
    assert a.sha256 == same.sha256 and a.parts["artefact"] == "LateralIntervalObserver_mycar"
    edited = identity.of_design("LateralIntervalObserver", str(_vehicle_file(tmp_path, "mycar", "c.toml", lr=1.742)))
    assert edited.sha256 != a.sha256 and edited.changes(a) == "the vehicle parameters changed"
    boxed = identity.of_design("LateralIntervalObserver", str(_vehicle_file(tmp_path, "mycar")), {"box": (0.3, 0.3)})
    assert boxed.changes(a) == "the design options changed"
    fmu_c, fmu_py = identity.of_fmu(a, "c"), identity.of_fmu(a, "python")
    assert fmu_c.sha256 != fmu_py.sha256 and "the backend (python -> c)" in fmu_c.changes(fmu_py)
    assert identity.of_design("LateralIntervalObserver").sha256 == identity.of_design("LateralIntervalObserver").sha256


@pytest.mark.slow
@needs_cc
def test_an_edited_vehicle_file_rebuilds_its_fmus_and_says_so(tmp_path, capsys):
    """The issue's report: lr edited from 1.6 to 1.742 in a vehicle file gave the FMUs of the old
    file again (build, validate --plant-vehicle, replay --vehicle all reused NAME_V.fmu). (Native
    FMUs for this machine's platform only: what is checked does not depend on the platforms.)"""
    from latobs.cbackend import toolchain

    host = [toolchain.host_platform()] if toolchain.host_platform() else None
    out = tmp_path / "fmus"
    toml = _vehicle_file(tmp_path, "mycar")
    obs, plant = build(["LateralIntervalObserver", "CarPlant"], str(toml), out, backend="c", platforms=host)
    assert (obs.name, plant.name) == ("LateralIntervalObserver_mycar.fmu", "CarPlant_mycar.fmu")
    capsys.readouterr()
    # unchanged: reused, said so, nothing written
    before = {p: p.stat().st_mtime_ns for p in out.iterdir()}
    build(["LateralIntervalObserver", "CarPlant"], str(toml), out, platforms=host)
    assert ensure_plant("CarPlant", str(toml), out, host) == plant
    printed = capsys.readouterr().out
    assert "reusing LateralIntervalObserver_mycar.fmu (identical inputs)" in printed
    assert "reusing CarPlant_mycar.fmu (identical inputs)" in printed
    assert {p: p.stat().st_mtime_ns for p in out.iterdir()} == before
    # edited: rebuilt, said why, and the FMUs carry the new value
    _vehicle_file(tmp_path, "mycar", lr=1.742)
    assert ensure_plant("CarPlant", str(toml), out, host) == plant
    build(["LateralIntervalObserver"], str(toml), out, platforms=host)
    printed = capsys.readouterr().out
    assert "rebuilding CarPlant_mycar.fmu: the vehicle parameters changed" in printed
    assert "rebuilding LateralIntervalObserver_mycar.fmu: the vehicle parameters changed" in printed
    assert _inner(plant, "resources/CarPlant_mycar.plant.json")["vehicle"]["parameters"]["lr"]["value"] == 1.742
    inner = _inner(obs, "resources/LateralIntervalObserver_mycar.design.json")
    assert inner["vehicle"]["parameters"]["lr"]["value"] == 1.742
    assert design_file.reproducible(json.loads((out / "LateralIntervalObserver_mycar.design.json").read_text())) == inner
    # an FMU without an identity (another tool's, an older latobs's, a broken file) is rebuilt
    plant.write_bytes(plant.read_bytes()[:4000])
    assert ensure_plant("CarPlant", str(toml), out, host) == plant
    assert "rebuilding CarPlant_mycar.fmu: it carries no build identity" in capsys.readouterr().out
    assert identity.read_fmu(plant) is not None


def test_a_design_file_of_the_same_inputs_is_packaged_without_solving_again(tmp_path, monkeypatch, capsys):
    """A design is solved only when its inputs change: the FMU missing beside a current design
    file (e.g. a build killed after the design) is packaged from it."""
    out = tmp_path / "fmus"
    monkeypatch.setattr(pipeline, "_from_cache", lambda p, design: False)    # packaged here, not from the cache
    data = complete_runtime_data(designs.run("LateralIntervalObserver"))   # as `latobs design` writes it
    design_file.write(data, out)

    def no_solve(*a, **k):
        raise AssertionError("solved again")

    monkeypatch.setattr(designs, "run", no_solve)
    fmu, = build(["LateralIntervalObserver"], None, out, backend="python")
    assert "packaged without solving again" in capsys.readouterr().out
    assert _inner(fmu, "resources/LateralIntervalObserver.design.json") == _plain(design_file.reproducible(data))
    # another vehicle is another design: solved (without the cache, which may hold it)
    with cache.turned_off(), pytest.raises(AssertionError, match="solved again"):
        build(["LateralIntervalObserver"], "compact", out, backend="python")


# ---------------------------------------------------------------------------------------------
# item 4: reproducible builds
# ---------------------------------------------------------------------------------------------
@pytest.mark.slow
@pytest.mark.parametrize("backend", ["c", "python"])
def test_latobs_build_twice_gives_byte_identical_fmus(backend, tmp_path, built_fmus):
    """Two builds, each solving its designs: the same bytes. One is a `latobs build` process
    without the cache, the other this run's session build (solved and packaged in a test worker).
    The issue's case is the interval observer, whose design carried the solver's wall time into
    the FMU. Paper 000's tire-mode design, a second LMI design, is built in the pythonfmu variant
    only (a design is the same for both backends); the native variant adds the compilers'
    reproducibility, for every platform."""
    if backend == "c" and find_compiler() is None:
        pytest.skip("no C compiler")
    names = ["LateralIntervalObserver", *(["SideslipBankObserverTirePaper"] if backend == "python" else []), "CarPlant"]
    # without the cache (latobs.cache): the process solves and compiles everything itself
    proc = _latobs("build", *names, "--backend", backend, "--out", tmp_path / "run", "--no-cache")
    out, err = proc.communicate(timeout=600)
    assert proc.returncode == 0, err
    got = _tree(tmp_path / "run")
    assert sorted(n for n in got if n.endswith(".fmu")) == sorted(f"{n}.fmu" for n in names)
    assert [n for n in names if got[f"{n}.fmu"] != built_fmus.get(n, backend).read_bytes()] == []


@pytest.mark.slow
@pytest.mark.parametrize("variant", FMU_VARIANTS)
def test_every_fmu_built_twice_is_byte_identical(variant, built_fmus, tmp_path):
    """Every FMU of `latobs build`, both backends: packaged a second time from its design (whose
    wall-clock figures differ, as they do between two solves), the bytes of the session build.
    The designs themselves are solved once here (paper 002's scheduled design alone takes ~40 s):
    that two solves give the same numbers is checked by the no-cache build test above and by
    `latobs build` twice on every design (identical but for the wall-clock figures)."""
    name, backend = variant
    first = built_fmus.get(name, backend)
    again = tmp_path / "again"
    if name in packaging.OBSERVERS:
        data = copy.deepcopy(built_fmus.design(name))
        _perturb_wall_time(data)
        second = pipeline.package_design_data(data, again, backend)
        inner = _inner(second, f"resources/{name}.design.json")
        assert not _wall_time_keys(inner) and inner == _plain(design_file.reproducible(data))
    else:
        second = pipeline.package_plant(name, None, again, backend)
    assert second.read_bytes() == first.read_bytes()
    assert identity.read_fmu(second).parts["backend"] == backend


def _perturb_wall_time(data):
    if isinstance(data, dict):
        for k, v in data.items():
            if design_file.is_wall_time(k) and isinstance(v, (int, float)):
                data[k] = v + 1.2345
            else:
                _perturb_wall_time(v)
    elif isinstance(data, list):
        for v in data:
            _perturb_wall_time(v)


def _wall_time_keys(data, path="") -> list[str]:
    if isinstance(data, dict):
        return [p for k, v in data.items() for p in ([f"{path}/{k}"] if "seconds" in k else [])
                + _wall_time_keys(v, f"{path}/{k}")]
    if isinstance(data, list):
        return [p for i, v in enumerate(data) for p in _wall_time_keys(v, f"{path}[{i}]")]
    return []


def test_the_design_inside_an_fmu_has_no_wall_clock_figure():
    data = {"solver": {"name": "CLARABEL", "seconds": 1.0, "total_seconds": 2.0},
            "modes": [{"solver_seconds": 0.5, "gain": [1, 2]}], "runtime": {"time_constant_s": 0.1}}
    assert design_file.reproducible(data) == {"solver": {"name": "CLARABEL"}, "modes": [{"gain": [1, 2]}],
                                              "runtime": {"time_constant_s": 0.1}}


# ---------------------------------------------------------------------------------------------
# item 7: names
# ---------------------------------------------------------------------------------------------
BAD_NAMES = ["../../../X", "my car", 'my"car', "a/b", "caf\u00e9", ""]


@pytest.mark.parametrize("command", ["design", "build"])
@pytest.mark.parametrize("name", BAD_NAMES, ids=["dotdot", "space", "quote", "slash", "non-ascii", "empty"])
def test_a_vehicle_name_that_cannot_name_an_fmu_is_refused_before_anything_is_written(command, name, tmp_path,
                                                                                       capsys):
    """`name = "../../../X"` made `latobs design` write X.design.json three folders up (exit 0);
    a name with a space, slash or quote left a design file behind after `build` exited 2."""
    toml = _vehicle_file(tmp_path, name)
    out = tmp_path / "a" / "b" / "c" / "out"
    before = _tree(tmp_path)
    rc = _main([command, "LateralIntervalObserver", "--vehicle", toml, "--out", out])
    err = capsys.readouterr().err
    assert rc == 2 and len(err.splitlines()) == 1 and f"vehicle name {name!r}" in err, err
    assert _tree(tmp_path) == before and not (tmp_path / "a").exists()


def test_names_are_checked_where_files_are_written(tmp_path):
    """The library calls refuse too: a design file or an FMU never gets a name that is not an FMI
    modelIdentifier, whatever called them."""
    with pytest.raises(designs.ArtefactNameError, match="modelIdentifier"):
        design_file.write({"name": "../evil", "schema": design_file.SCHEMA}, tmp_path)
    with pytest.raises(designs.ArtefactNameError, match="modelIdentifier"):
        packaging.build_fmu(packaging.PLANTS["CarPlant"], "Car Plant", packaging.plant_data("sedan"), tmp_path)
    with pytest.raises(designs.ArtefactNameError):
        designs.artefact_name("LateralIntervalObserver", "../x")
    assert list(tmp_path.iterdir()) == []
    assert designs.artefact_name("LateralIntervalObserver", "250lm_v2") == "LateralIntervalObserver_250lm_v2"


# ---------------------------------------------------------------------------------------------
# item 8: one unit, one writer, no stale temporaries
# ---------------------------------------------------------------------------------------------
def _assert_pairs_match(out: Path):
    """Every observer FMU in ``out`` has its design file beside it, the design inside it."""
    fmus = sorted(p for p in out.glob("*.fmu") if not p.name.startswith("."))
    for fmu in fmus:
        if identity.read_fmu(fmu).parts["kind"] == "design":
            inner = _inner(fmu, f"resources/{fmu.stem}.design.json")
            assert design_file.reproducible(json.loads(fmu.with_suffix(".design.json").read_text())) == inner, fmu
    build_summary(fmus)                                   # raises on a mismatched pair


#: a `latobs build` whose packaging stops half-way (the FMU's temporary partly written, the design
#: file's written): says "sealing" and waits to be killed
HANG_IN_SEAL = """
import signal, sys, time
signal.signal(signal.SIGINT, signal.default_int_handler)   # a background job may start with SIGINT ignored
import latobs.packaging as pk
def hang(files, model_identifier, model_description, guard_variables, path, *a, **k):
    open(path, "wb").write(b"PK half an FMU")
    print("sealing", flush=True)
    time.sleep(300)
pk.seal_fmu = hang
from latobs.cli import main
sys.exit(main(sys.argv[1:]))
"""


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGINT], ids=["SIGKILL", "Ctrl-C"])
def test_a_build_killed_mid_way_leaves_the_old_pair_and_the_next_build_cleans_up(sig, tmp_path):
    """A real `latobs build` process stopped while packaging (its design already solved): the
    design file and FMU on disk stay the old, matching pair (before, the new design file was
    already written beside the old FMU), and the next build removes what the killed one left."""
    out = tmp_path / "fmus"
    toml = _vehicle_file(tmp_path, "mycar")
    fmu, = build(["LateralIntervalObserver"], str(toml), out, backend="python")
    old = fmu.read_bytes()
    # the next build has work to do: a vehicle of its own, so that no FMU of the cache is it
    lr = {signal.SIGKILL: 1.742, signal.SIGINT: 1.743}[sig]
    _vehicle_file(tmp_path, "mycar", lr=lr)
    proc = subprocess.Popen([sys.executable, "-P", "-c", HANG_IN_SEAL, "build", "LateralIntervalObserver",
                             "--vehicle", str(toml), "--backend", "python", "--out", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        _wait_line(proc, "sealing")
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=30)
    finally:
        proc.kill()
    # the pair on disk is the old one, whole; a SIGKILLed build leaves its temporaries, Ctrl-C none
    assert fmu.read_bytes() == old
    _assert_pairs_match(out)
    left = stale_temporaries(out)
    if sig == signal.SIGKILL:
        assert any(".fmu." in p.name for p in left) and any(".design.json." in p.name for p in left), left
    else:
        assert proc.returncode == 130 and err.strip() == "latobs build: interrupted" and left == [], (err, left)
    # the next build removes them and writes the new pair
    rc = main(["build", "LateralIntervalObserver", "--vehicle", str(toml), "--backend", "python", "--out", str(out)])
    assert rc == 0 and stale_temporaries(out) == []
    assert _inner(fmu, "resources/LateralIntervalObserver_mycar.design.json")["vehicle"]["parameters"]["lr"]["value"] \
        == lr
    _assert_pairs_match(out)


def _wait_line(proc, text: str) -> bool:
    for line in proc.stdout:
        if line.strip() == text:
            return True
    raise AssertionError(f"the build ended without {text!r}: {proc.stderr.read()}")


def test_a_failed_packaging_writes_neither_file(tmp_path, monkeypatch):
    out = tmp_path / "fmus"
    monkeypatch.setattr(pipeline, "_from_cache", lambda p, design: False)    # packaged here, not from the cache
    monkeypatch.setattr(packaging, "seal_fmu", lambda *a, **k: ["an invented problem"])
    with pytest.raises(packaging.PackagingError, match="an invented problem"):
        build(["LateralIntervalObserver"], None, out, backend="python")
    assert sorted(p.name for p in out.iterdir()) == [".latobs.lock"]


@pytest.mark.slow
@needs_cc
def test_two_builds_into_one_folder_at_once_never_mix_backends(tmp_path):
    """`latobs build --backend c` and `--backend python` into one folder at once: one builds, the
    other waits for the lock, then refuses to replace the other backend's FMUs (exit 2, saying
    why); the folder holds one backend's FMUs and matching design files."""
    out = tmp_path / "fmus"
    names = ["LateralIntervalObserver", "CarPlant"]
    procs = {b: _latobs("build", *names, "--backend", b, "--out", out) for b in ("c", "python")}
    results = {b: (p.communicate(timeout=600), p.returncode) for b, p in procs.items()}
    codes = sorted(rc for _, rc in results.values())
    assert codes == [0, 2], results
    winner = next(b for b, (_, rc) in results.items() if rc == 0)
    (_, err), _ = results[next(b for b in results if b != winner)]
    assert "refusing to replace" in err and len(err.strip().splitlines()) <= 2, err   # (+ "waiting for" line)
    assert {identity.read_fmu(out / f"{n}.fmu").parts["backend"] for n in names} == {winner}
    _assert_pairs_match(out)
    assert stale_temporaries(out) == []


def test_a_build_waits_for_the_folder_lock_then_gives_up_saying_why(tmp_path):
    out = tmp_path / "fmus"
    with locked_folder(out, "test holder"):
        proc = _latobs("build", "CarPlant", "--backend", "python", "--out", out,
                       env={**os.environ, LOCK_TIMEOUT_ENV: "0.5"})
        stdout, stderr = proc.communicate(timeout=300)
    assert proc.returncode == 2, stderr
    assert "waiting for another latobs (pid" in stderr and "test holder" in stderr
    assert f"latobs build: error: {out} is being written by another latobs" in stderr
    assert not (out / "CarPlant.fmu").exists()


@pytest.mark.slow
def test_a_build_waiting_for_the_lock_builds_once_it_is_released(tmp_path):
    out = tmp_path / "fmus"
    with locked_folder(out, "test holder"):
        proc = _latobs("build", "CarPlant", "--backend", "python", "--out", out)
        line = proc.stderr.readline()
        assert "waiting for another latobs" in line, line
        time.sleep(0.5)
        assert proc.poll() is None and not (out / "CarPlant.fmu").exists()
    stdout, stderr = proc.communicate(timeout=300)
    assert proc.returncode == 0, stderr
    # built, or (the run's cache holding it) installed from latobs.cache
    assert ("built" in stdout or "from the cache" in stdout) and (out / "CarPlant.fmu").is_file(), stdout


# ---------------------------------------------------------------------------------------------
# item 22: two backends, one folder
# ---------------------------------------------------------------------------------------------
@pytest.mark.slow
@needs_cc
def test_an_explicit_backend_never_replaces_the_other_backends_fmu(tmp_path, capsys):
    out = tmp_path / "fmus"
    assert main(["build", "CarPlant", "--backend", "python", "--out", str(out)]) == 0
    raw = (out / "CarPlant.fmu").read_bytes()
    capsys.readouterr()
    assert main(["build", "CarPlant", "--backend", "c", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "CarPlant.fmu is a pythonfmu FMU" in err and "another --out" in err
    assert (out / "CarPlant.fmu").read_bytes() == raw
    # "auto" (the default, and every command that builds a missing FMU) keeps the folder's backend
    assert main(["build", "CarPlant", "--out", str(out)]) == 0
    assert "reusing CarPlant.fmu" in capsys.readouterr().out


@pytest.mark.slow
def test_fmus_made_in_parallel_processes_are_those_of_one_process(built_fmus, tmp_path, monkeypatch, capsys):
    """`latobs build` of several FMUs makes them in parallel processes (LATOBS_JOBS=2, the cache
    off so that the workers make everything): each FMU byte-identical to the one-process build of
    the session, its design file beside it, and what each worker's build said printed with this
    folder's paths."""
    monkeypatch.setenv("LATOBS_JOBS", "2")
    monkeypatch.setenv(cache.ENV_OFF, "1")
    names = ["SideslipBankObserverPaper", "CarPlant"]
    paths = build(names, None, tmp_path / "out", backend="python")
    printed = capsys.readouterr().out
    assert "making 2 FMUs in 2 processes" in printed
    for name, path in zip(names, paths):
        assert path.read_bytes() == built_fmus.path(name).read_bytes(), name
        assert f"built {path} (pythonfmu)" in printed, printed
    _assert_pairs_match(tmp_path / "out")
    assert "latobs-part-" not in printed
