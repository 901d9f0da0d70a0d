"""latobs's content-addressed cache (``latobs.cache``): paper 001's build-time fact (the longest
communication step, decided by probing the runtime), a design and an FMU each made once per
inputs and reused in any folder; a changed input never served a stale value, an unreadable or
damaged entry made again, the folder kept to its size bound, and ``latobs build --no-cache`` /
LATOBS_NO_CACHE deciding everything again."""
from __future__ import annotations

import copy
import os

import pytest

from latobs import cache, packaging
from latobs.fmu_src.lateral_interval_observer import IntervalObserver


def _bare(design):
    d = copy.deepcopy({k: v for k, v in design.items() if k != "tables"})
    del d["runtime"]["max_communication_step"]
    return d


def test_a_build_time_fact_is_decided_once_per_design_content(built_fmus, tmp_path, monkeypatch):
    """The runtime's own decision (its probes) once, then from the cache: the same value; another
    design content decides again; so does an unreadable entry, and a turned-off cache. The probes
    themselves (5 s each) are counted through a stand-in after the first real one."""
    design = built_fmus.design("LateralIntervalObserver")
    monkeypatch.setenv(cache.ENV_DIR, str(tmp_path / "cache"))      # an empty cache
    calls = []
    real = IntervalObserver.build_time_facts.__func__

    def counted(cls, data):
        calls.append(1)
        return real(cls, data) if len(calls) == 1 else {"max_communication_step": 0.25}

    monkeypatch.setattr(IntervalObserver, "build_time_facts", classmethod(counted))
    first = packaging.complete_runtime_data(_bare(design))["runtime"]["max_communication_step"]
    assert first == design["runtime"]["max_communication_step"] and len(calls) == 1
    again = packaging.complete_runtime_data(_bare(design))
    assert again["runtime"]["max_communication_step"] == first and len(calls) == 1     # from the cache
    assert again["tables"]["max_communication_step"] == first
    entries = list((tmp_path / "cache" / "build-time-facts").glob("*.json"))
    assert len(entries) == 1
    # another design (its initial box changed): another key, decided again
    other = _bare(design)
    other["runtime"]["x0_halfwidth"] = [2.0, 0.0, 0.0, 30.0]
    packaging.complete_runtime_data(other)
    assert len(calls) == 2 and len(list((tmp_path / "cache" / "build-time-facts").glob("*.json"))) == 2
    # an unreadable entry: decided again, rewritten
    entries[0].write_text("{ not json")
    assert packaging.complete_runtime_data(_bare(design))["runtime"]["max_communication_step"] == 0.25
    assert len(calls) == 3
    # turned off: decided every time, nothing read
    with cache.turned_off():
        assert os.environ[cache.ENV_OFF] == "1"
        packaging.complete_runtime_data(_bare(design))
    assert len(calls) == 4 and cache.ENV_OFF not in os.environ


def test_an_unwritable_cache_folder_still_computes(tmp_path, monkeypatch):
    (tmp_path / "file").write_text("a file where the cache folder would be")
    monkeypatch.setenv(cache.ENV_DIR, str(tmp_path / "file"))
    assert cache.remember("k", {"a": 1}, lambda: {"x": 1.5}) == {"x": 1.5}


def test_the_default_folder_is_the_users_cache(monkeypatch, tmp_path):
    monkeypatch.delenv(cache.ENV_DIR, raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    assert cache.folder() == tmp_path / "latobs"


@pytest.mark.parametrize("flag", [["--no-cache"], []])
def test_build_no_cache_flag(flag, tmp_path, monkeypatch):
    from latobs.cli import main

    seen = []
    monkeypatch.setattr("latobs.cli._build", lambda args: seen.append(cache.enabled()) or 0)
    assert main(["build", "CarPlant", "--out", str(tmp_path), *flag]) == 0
    assert seen == [not flag] and cache.enabled()


# ---------------------------------------------------------------------------------------------
# designs and FMUs (issue 24, item 1): shared by every command and output folder
# ---------------------------------------------------------------------------------------------
def test_a_design_is_solved_once_per_inputs_and_solver_versions(tmp_path, monkeypatch):
    """``pipeline.solve`` (every command's design step) solves a design once per identity: the
    second call is the first's design; another vehicle content, another design-time code or
    another solver version is another key, solved again."""
    from latobs import pipeline
    from latobs.synthesis import designs, design_file

    monkeypatch.setenv(cache.ENV_DIR, str(tmp_path / "cache"))
    real, calls = designs.run, []
    monkeypatch.setattr(designs, "run", lambda *a, **k: calls.append(a) or real(*a, **k))
    first = pipeline.solve("SideslipBankObserverPaper", None, quiet=True)
    again = pipeline.solve("SideslipBankObserverPaper", None, quiet=True)
    assert len(calls) == 1 and again == first and first["certified"]
    # in the order designs.run gives (what an FMU packages is written in it: the same bytes)
    fresh = real("SideslipBankObserverPaper")
    assert design_file.dumps(design_file.reproducible(again)) == design_file.dumps(design_file.reproducible(fresh))
    # another vehicle: solved
    pipeline.solve("SideslipBankObserverPaper", "compact", quiet=True)
    assert len(calls) == 2
    # another solver version: another key
    monkeypatch.setattr(cache, "solver_versions", lambda: {"clarabel": "0.0.0-another"})
    pipeline.solve("SideslipBankObserverPaper", None, quiet=True)
    assert len(calls) == 3


def _fmu_entries(root):
    return sorted(p for p in (root / "fmu").iterdir() if not p.name.startswith(".")) if (root / "fmu").is_dir() else []


@pytest.mark.slow
def test_an_fmu_is_built_once_and_installed_into_any_folder(tmp_path, monkeypatch, capsys):
    """A build into a second folder installs the first build's FMU from the cache (the same
    bytes, a current identity, said so); an entry that is not what its key says (a damaged FMU)
    is built again; ``--no-cache`` builds without reading or writing the cache."""
    from latobs import identity
    from latobs.cli import main
    from latobs.pipeline import build

    root = tmp_path / "cache"
    monkeypatch.setenv(cache.ENV_DIR, str(root))
    first, = build(["CarPlant"], None, tmp_path / "a", backend="python")
    assert len(_fmu_entries(root)) == 1
    capsys.readouterr()
    second, = build(["CarPlant"], None, tmp_path / "b", backend="python")
    assert f"installed {tmp_path / 'b' / 'CarPlant.fmu'} from the cache (identical inputs)" in capsys.readouterr().out
    assert second.read_bytes() == first.read_bytes() and identity.read_fmu(second) == identity.read_fmu(first)
    # a damaged entry: not current once installed, so built again (and the folder holds a good FMU)
    entry, = _fmu_entries(root)
    (entry / "CarPlant.fmu").write_bytes(first.read_bytes()[:3000])
    third, = build(["CarPlant"], None, tmp_path / "c", backend="python")
    out = capsys.readouterr().out
    assert "from the cache" not in out and "built" in out and third.read_bytes() == first.read_bytes()
    # --no-cache: built, the cache untouched
    before = {p: p.stat().st_mtime_ns for p in root.rglob("*")}
    assert main(["build", "CarPlant", "--backend", "python", "--out", str(tmp_path / "d"), "--no-cache"]) == 0
    assert "from the cache" not in capsys.readouterr().out
    assert {p: p.stat().st_mtime_ns for p in root.rglob("*")} == before


def test_stored_files_are_whole_and_the_folder_keeps_its_size_bound(tmp_path, monkeypatch):
    """store_files: a reader sees a whole entry or none; the least recently used entries go when
    the folder grows past LATOBS_CACHE_MAX_MB; a name that is not a plain file name is refused."""
    import time

    monkeypatch.setenv(cache.ENV_DIR, str(tmp_path))
    monkeypatch.setenv(cache.ENV_MAX, "0.25")                  # 250 kB
    for k in range(3):
        cache.store_files("fmu", {"k": k}, {"A.fmu": bytes([k]) * 100_000, "A.design.json": b"{}"})
        time.sleep(0.02)
    assert cache.files("fmu", {"k": 0}) is None                 # the oldest went
    assert cache.files("fmu", {"k": 2})["A.fmu"] == bytes([2]) * 100_000
    cache.files("fmu", {"k": 1})                                # used: now the newest
    time.sleep(0.02)
    cache.store_files("fmu", {"k": 3}, {"A.fmu": b"x" * 100_000})
    assert cache.files("fmu", {"k": 2}) is None and cache.files("fmu", {"k": 1}) is not None
    with pytest.raises(ValueError, match="not a plain file name"):
        cache.store_files("fmu", {"k": 4}, {"../escape": b""})
    assert not list(tmp_path.glob("fmu/.*"))                    # no temporaries left


@pytest.mark.parametrize("value", ["lots", "-1", "inf", "nan"])
def test_a_bad_size_bound_is_refused_naming_it(value, tmp_path, monkeypatch):
    monkeypatch.setenv(cache.ENV_DIR, str(tmp_path))
    monkeypatch.setenv(cache.ENV_MAX, value)
    with pytest.raises(cache.CacheSettingError, match="LATOBS_CACHE_MAX_MB"):
        cache.store_files("fmu", {"k": 1}, {"A.fmu": b"x"})
    # a command stops before it makes anything (exit 2, one line naming the setting)
    from latobs.cli import main

    assert main(["build", "CarPlant", "--backend", "python", "--out", str(tmp_path / "out")]) == 2
    assert not (tmp_path / "out" / "CarPlant.fmu").exists()


def _counted_compilations(tmp_path, monkeypatch) -> tuple[str, list]:
    """(this machine's platform, the list every compiler command run from now on is appended to),
    latobs's cache in ``tmp_path``; skips without a C compiler for this machine."""
    from latobs.cbackend import toolchain

    host = toolchain.host_platform()
    if host is None or toolchain.missing([host]):
        pytest.skip("no C compiler for this machine's platform")
    monkeypatch.setenv(cache.ENV_DIR, str(tmp_path / "cache"))
    runs = []
    real = toolchain._run
    monkeypatch.setattr(toolchain, "_run", lambda cmd, cwd: (runs.append(cmd), real(cmd, cwd))[1])
    return host, runs


def test_a_compilation_is_made_once_per_command_compilers_and_source_bytes(tmp_path, monkeypatch):
    """A target's binary is compiled once per (compiler command, compilers, sources' bytes) and
    then taken from the cache, bit for bit; a changed source byte, another output name,
    ``cached=False`` and a turned-off cache compile again. The binary still runs (it is the
    compiler's output, not a stand-in)."""
    import ctypes

    from latobs.cbackend import toolchain

    host, runs = _counted_compilations(tmp_path, monkeypatch)
    src = {"twice.c": b"__attribute__((visibility(\"default\"))) double twice(double x) { return 2.0 * x; }\n"}
    name = "twice" + toolchain.SUFFIX[host]
    first = toolchain.compile_for(host, src, ["twice.c"], name)
    assert len(runs) == 1
    assert toolchain.compile_for(host, src, ["twice.c"], name) == first and len(runs) == 1      # from the cache
    (tmp_path / name).write_bytes(first)
    lib = ctypes.CDLL(str(tmp_path / name))
    lib.twice.restype, lib.twice.argtypes = ctypes.c_double, [ctypes.c_double]
    assert lib.twice(1.25) == 2.5
    changed = {"twice.c": src["twice.c"].replace(b"2.0 * x", b"x + x")}
    toolchain.compile_for(host, changed, ["twice.c"], name)
    assert len(runs) == 2
    toolchain.compile_for(host, src, ["twice.c"], "other" + toolchain.SUFFIX[host])
    assert len(runs) == 3
    toolchain.compile_for(host, src, ["twice.c"], name, cached=False)
    assert len(runs) == 4
    with cache.turned_off():
        toolchain.compile_for(host, src, ["twice.c"], name)
    assert len(runs) == 5
    assert len(list((tmp_path / "cache" / "compile").iterdir())) == 3


def test_a_common_object_is_compiled_once_for_every_library_and_only_from_what_it_reads(tmp_path, monkeypatch):
    """``compile_for(..., common=...)`` (how an FMI layer is compiled: once per target for every
    FMU): the common file is compiled alone into an object, cached by the sources it declares it
    reads, and linked into each library; a library with another model file links the cached
    object (one compiler run, not two); a changed header it reads compiles it again; a header it
    does not declare is not there to be read (the compilation fails naming it), so its cache
    entry names everything it was made from."""
    import ctypes

    from latobs.cbackend import toolchain

    host, runs = _counted_compilations(tmp_path, monkeypatch)
    src = {"api.h": b"double model(double x);\n",
           "layer.c": b'#include "api.h"\n__attribute__((visibility("default"))) double call(double x) '
                      b"{ return model(x) + 1.0; }\n",
           "a.c": b"double model(double x) { return 2.0 * x; }\n",
           "b.c": b"double model(double x) { return 3.0 * x; }\n"}
    common = {"layer.c": ("api.h",)}

    def build(model: str, sources=src) -> float:
        name = f"lib{model}{toolchain.SUFFIX[host]}"
        raw = toolchain.compile_for(host, sources, ["layer.c", f"{model}.c"], name, common=common)
        path = tmp_path / f"{len(runs)}-{name}"          # (a new file each time: a loaded library stays loaded)
        path.write_bytes(raw)
        fn = ctypes.CDLL(str(path)).call
        fn.restype, fn.argtypes = ctypes.c_double, [ctypes.c_double]
        return fn(1.5)

    assert build("a") == 4.0 and len(runs) == 2                 # the object, then the library
    assert any("-c" in cmd and "layer.c" in cmd for cmd in runs)
    assert build("b") == 5.5 and len(runs) == 3                 # the cached object linked with b.c
    assert "layer.o" in runs[-1] and "layer.c" not in runs[-1]
    changed = {**src, "api.h": src["api.h"] + b"/* changed */\n"}
    assert build("a", changed) == 4.0 and len(runs) == 5        # another header: compiled again
    sneaky = {**src, "layer.c": b'#include "other.h"\n' + src["layer.c"], "other.h": b"/* not declared */\n"}
    with pytest.raises(toolchain.ToolchainError, match="other.h"):
        build("a", sneaky)


# ---------------------------------------------------------------------------------------------
# content-addressed means content (issue 47, item 1)
# ---------------------------------------------------------------------------------------------
def _edit_noise(path, value=0.1):
    """Edit the Kalman peer's design file by hand: its first measurement-noise variance (10 -> 0.1)."""
    import json

    data = json.loads(path.read_text())
    data["noise"]["r"][0][0] = value
    path.write_text(json.dumps(data, indent=1) + "\n")


@pytest.mark.slow
def test_a_design_file_edited_beside_its_fmu_is_refused_and_never_cached(tmp_path, monkeypatch, capsys):
    """The issue's reproduction: R[0][0] of SideslipKalmanFilter.design.json edited beside its FMU
    (10 -> 0.1), built again. The build refuses (exit 2, naming the file and what to do) whether or
    not the cache holds the unedited FMU; the user's file is left as they wrote it, the FMU beside it
    untouched; nothing is stored in the cache from it; a build into a fresh folder installs the
    unedited FMU, whose design file is sealed. Packaged on purpose (``packaging.package_design``),
    the edited design is a new design: identified by its content, certified again."""
    from latobs import identity
    from latobs.cli import main
    from latobs.pipeline import PipelineError, build
    from latobs.synthesis import design_file

    root = tmp_path / "cache"
    monkeypatch.setenv(cache.ENV_DIR, str(root))
    name = "SideslipKalmanFilter"
    fmu, = build([name], None, tmp_path / "a", backend="python")
    design = fmu.with_name(f"{name}.design.json")
    assert design_file.seal_state(design_file.read(design)) == "sealed"
    original_fmu, original_design = fmu.read_bytes(), design.read_bytes()
    _edit_noise(design)
    edited = design.read_bytes()
    entries = _fmu_entries(root)
    for cached in (True, False):
        if not cached:
            import shutil

            shutil.rmtree(root)
        with pytest.raises(PipelineError, match="edited by hand"):
            build([name], None, tmp_path / "a", backend="python")
        capsys.readouterr()
        assert main(["build", name, "--backend", "python", "--out", str(tmp_path / "a")]) == 2
        err = capsys.readouterr().err
        assert str(design) in err and "latobs design" in err and err.count("\n") == 1, err
        assert design.read_bytes() == edited and fmu.read_bytes() == original_fmu
        assert _fmu_entries(root) == (entries if cached else [])
    # a fresh folder: the unedited design, solved again (the cache was emptied), sealed
    fresh, = build([name], None, tmp_path / "b", backend="python")
    again = design_file.read(fresh.with_name(design.name))
    assert design_file.seal_state(again) == "sealed" and again["noise"]["r"][0][0] == 10.0
    assert fresh.read_bytes() == original_fmu
    # packaged on purpose: certified again (its runtime tables, still the unedited design's, fail the
    # certificate); without them, another design: its content's identity, not the inputs'
    with pytest.raises(packaging.PackagingError, match="not certified"):
        packaging.package_design(design, tmp_path / "c")
    import json

    data = json.loads(design.read_text())
    del data["tables"]
    design.write_text(json.dumps(data))
    other = packaging.package_design(design, tmp_path / "c")
    parts = identity.read_fmu(other).parts
    assert parts["kind"] == "data" and parts != identity.read_fmu(fmu).parts
    assert original_design != edited


@pytest.mark.slow
def test_a_patched_or_truncated_cache_entry_is_rejected_and_replaced(tmp_path, monkeypatch, capsys):
    """A cached FMU whose bytes were patched (here its binary: what a gain x10 looks like to the
    cache) or cut short is not installed: the entry is checked against the hashes it holds, removed,
    the FMU built again and the entry stored anew, so the build after that installs from the cache."""
    from latobs.pipeline import build

    root = tmp_path / "cache"
    monkeypatch.setenv(cache.ENV_DIR, str(root))
    first, = build(["CarPlant"], None, tmp_path / "a", backend="python")
    good = first.read_bytes()
    for n, damage in enumerate((lambda raw: raw[:len(raw) // 2] + bytes([raw[len(raw) // 2] ^ 1]) + raw[len(raw) // 2 + 1:],
                                lambda raw: raw[:3000])):
        entry, = _fmu_entries(root)
        (entry / "CarPlant.fmu").write_bytes(damage(good))
        capsys.readouterr()
        again, = build(["CarPlant"], None, tmp_path / f"b{n}", backend="python")
        out = capsys.readouterr().out
        assert "from the cache" not in out and again.read_bytes() == good, out
        entry, = _fmu_entries(root)                       # replaced, whole
        assert (entry / "CarPlant.fmu").read_bytes() == good
        third, = build(["CarPlant"], None, tmp_path / f"c{n}", backend="python")
        assert "from the cache" in capsys.readouterr().out and third.read_bytes() == good


def test_a_value_entry_is_checked_against_its_own_hash(tmp_path, monkeypatch):
    """remember/peek: an entry whose value was changed (not its hash) is removed and computed again;
    a whole one is read without computing."""
    import json

    monkeypatch.setenv(cache.ENV_DIR, str(tmp_path))
    calls = []
    assert cache.remember("k", {"a": 1}, lambda: calls.append(1) or {"gain": 2.5}) == {"gain": 2.5}
    assert cache.peek("k", {"a": 1}) == {"gain": 2.5} and cache.peek("k", {"a": 2}) is None
    path, = (tmp_path / "k").glob("*.json")
    doc = json.loads(path.read_text())
    doc["value"]["gain"] = 25.0
    path.write_text(json.dumps(doc))
    assert cache.peek("k", {"a": 1}) is None and not path.exists()
    assert cache.remember("k", {"a": 1}, lambda: calls.append(1) or {"gain": 2.5}) == {"gain": 2.5}
    assert len(calls) == 2
    assert cache.remember("k", {"a": 1}, lambda: calls.append(1) or {"gain": 9.0}) == {"gain": 2.5}
    assert len(calls) == 2


def test_a_files_entry_missing_a_file_or_its_index_is_a_miss(tmp_path, monkeypatch):
    monkeypatch.setenv(cache.ENV_DIR, str(tmp_path))
    content = {"A.fmu": b"x" * 1000, "A.design.json": b"{}"}
    cache.store_files("fmu", {"k": 1}, content)
    assert cache.files("fmu", {"k": 1}) == content
    entry = tmp_path / "fmu" / cache.key("fmu", {"k": 1})
    (entry / "A.design.json").unlink()
    assert cache.files("fmu", {"k": 1}) is None and not entry.exists()
    cache.store_files("fmu", {"k": 1}, content)
    (entry / ".files.json").write_text('["A.fmu", "A.design.json"]')     # the old layout: no hashes
    assert cache.files("fmu", {"k": 1}) is None
    cache.store_files("fmu", {"k": 1}, content)
    assert cache.files("fmu", {"k": 1}) == content
