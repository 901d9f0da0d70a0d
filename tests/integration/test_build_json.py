"""`latobs build --json [FILE]`: the machine-readable summary of the FMUs built (issue 10, item 4)."""
from __future__ import annotations

import hashlib
import json
import zipfile
from pathlib import Path

import pytest

from latobs.cli import main
from latobs.native_guard import find_compiler

KEYS = ["name", "kind", "model", "paper", "vehicle", "path", "sha256", "size", "backend", "fmi", "platforms", "design_file",
        "design_sha256", "gamma", "model_error_gamma", "certificate"]


@pytest.mark.slow
def _made(fmu, printed: str) -> bool:
    """Whether the build said it built ``fmu``, or installed it from the cache (latobs.cache)."""
    return f"built {fmu}" in printed or f"installed {fmu} from the cache" in printed


def test_build_json_file(tmp_path, capsys):
    out, summary = tmp_path / "fmus", tmp_path / "ci" / "summary.json"
    assert main(["build", "SideslipBankObserver", "CarPlant", "--out", str(out), "--json", str(summary)]) == 0
    printed = capsys.readouterr().out
    assert _made(out / "CarPlant.fmu", printed) and f"wrote {summary}" in printed
    s = json.loads(summary.read_text())
    assert s["schema"] == "latobs.build-summary/1" and s["latobs_version"]
    obs, plant = s["fmus"]
    for e in (obs, plant):
        assert list(e) == KEYS
        raw = Path(e["path"]).read_bytes()
        assert e["sha256"] == hashlib.sha256(raw).hexdigest() and e["size"] == len(raw)
        with zipfile.ZipFile(e["path"]) as z:            # the default backend where a compiler is: native C
            native = "binaries/linux64/" + e["name"] + ".so" in z.namelist() and "sources/model.h" in z.namelist()
            folders = {n.split("/")[1] for n in z.namelist() if n.startswith("binaries/") and n.count("/") == 2}
        assert e["backend"] == ("c" if native else "python")
        assert sorted(e["platforms"]) == sorted(folders)
        assert e["fmi"] == "2.0"
        if native:                                        # every platform by default
            assert e["platforms"] == ["linux64", "win64", "darwin64", "aarch64-linux"]
        assert e["backend"] == ("c" if find_compiler() else "python")
    assert (obs["name"], obs["kind"], obs["model"], obs["paper"], obs["vehicle"]) == \
        ("SideslipBankObserver", "observer", "SideslipBankObserver", "000", "sedan")
    assert Path(obs["path"]) == out / "SideslipBankObserver.fmu"
    design_path = out / "SideslipBankObserver.design.json"
    assert Path(obs["design_file"]) == design_path
    assert obs["design_sha256"] == hashlib.sha256(design_path.read_bytes()).hexdigest()
    d = json.loads(design_path.read_text())
    assert obs["gamma"] == d["gamma"] and obs["model_error_gamma"] == d["model_error"]["gamma"]
    n = len(d["checks"])
    assert obs["certificate"] == {"certified": True, "passed": n, "total": n} and n > 10
    assert (plant["name"], plant["kind"], plant["model"], plant["paper"], plant["vehicle"]) == \
        ("CarPlant", "plant", "CarPlant", None, "sedan")
    assert all(plant[k] is None for k in ("design_file", "design_sha256", "gamma", "model_error_gamma",
                                           "certificate"))
    assert not list(summary.parent.glob(".*"))                # atomic write: no temporary file left

    # the summary never describes a design the FMU does not carry
    from latobs.pipeline import PipelineError, build_summary

    design_path.write_text(design_path.read_text().replace('"certified": true', '"certified": false'))
    with pytest.raises(PipelineError, match="not the design file inside"):
        build_summary([out / "SideslipBankObserver.fmu"])


@pytest.mark.slow
def test_build_json_stdout_is_the_summary_alone(tmp_path, capsys):
    assert main(["build", "CarPlant", "--out", str(tmp_path), "--json"]) == 0
    cap = capsys.readouterr()
    s = json.loads(cap.out)                                   # nothing but the JSON on stdout
    assert [e["name"] for e in s["fmus"]] == ["CarPlant"]
    assert _made(tmp_path / "CarPlant.fmu", cap.err)    # progress went to stderr
    # a FILE that cannot be written is a user error too (exit 2), after the build
    bad = tmp_path / "CarPlant.fmu" / "summary.json"
    assert main(["build", "CarPlant", "--out", str(tmp_path), "--json", str(bad)]) == 2
    assert f"--json: cannot write {bad}" in capsys.readouterr().err


def test_build_json_user_errors_exit_2_and_write_nothing(tmp_path, capsys):
    summary = tmp_path / "summary.json"
    assert main(["build", "NoSuchFmu", "--out", str(tmp_path), "--json", str(summary)]) == 2
    assert "unknown FMU(s) NoSuchFmu" in capsys.readouterr().err and not summary.exists()
    # an FMU name right after --json would be taken for the file: refused before building
    assert main(["build", "--out", str(tmp_path), "--json", "CarPlant"]) == 2
    assert "put the FMU names before --json" in capsys.readouterr().err
    assert not list(tmp_path.iterdir())


def test_build_fmi3_beside_fmi2_and_refusals(tmp_path, capsys):
    """``--fmi 2,3``: each FMU in both versions, the FMI 3.0 one under the same name in DIR/fmi3, the
    summary naming each version and its FMI 3.0 platform folders; again: both reused; ``--fmi 3``
    with the pythonfmu backend, or an unknown version: exit 2 naming it."""
    from latobs.cbackend import fmi3

    if not find_compiler() or fmi3.host_folder() is None:
        pytest.skip("FMI 3.0 FMUs are native: no C compiler here, or an unknown platform")
    out = tmp_path / "fmus"
    argv = ["build", "CarPlant", "--out", str(out), "--fmi", "2,3", "--platforms", "host", "--json", "-"]
    assert main(argv) == 0
    s = json.loads(capsys.readouterr().out)
    assert [(Path(e["path"]), e["fmi"], e["platforms"]) for e in s["fmus"]] == [
        (out / "CarPlant.fmu", "2.0", ["linux64"]), (out / "fmi3" / "CarPlant.fmu", "3.0", [fmi3.host_folder()])]
    assert main(argv[:-2]) == 0
    assert capsys.readouterr().out.count("reusing CarPlant.fmu (identical inputs)") == 2
    assert main(["build", "CarPlant", "--out", str(out), "--fmi", "3", "--backend", "python"]) == 2
    assert "pythonfmu" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:
        main(["build", "CarPlant", "--out", str(out), "--fmi", "4"])
    assert exc.value.code == 2 and "--fmi takes 2, 3 or 2,3" in capsys.readouterr().err

