"""Issue 47, list 6: a vehicle name too long for an FMU refused when its file is loaded (it failed
after the solve), a user's vehicle file named as a shipped vehicle but different refused (it built
the shipped FMU's name), and ``export-ssp --out`` under missing folders writing nothing outside
--out and leaving nothing on failure (a probe file was written in the nearest existing ancestor:
``/`` for ``--out /missing/x.ssp``)."""
from __future__ import annotations

import os
import tempfile
from pathlib import Path

import pytest

from latobs.cli import main
from latobs.ssp import SspError, export
from latobs.synthesis import designs
from latobs.synthesis.params import VEHICLE_NAME_MAX, VehicleParameterError, load_vehicle

SEDAN_TOML = Path(__file__).resolve().parents[2] / "synthesis" / "vehicles" / "sedan.toml"


def _main(argv) -> int:
    """``main(argv)``'s exit code (argparse's errors exit by SystemExit)."""
    try:
        return main([str(a) for a in argv])
    except SystemExit as exc:
        return int(exc.code)


def _sedan_file(folder: Path, name: str, file: str, lr: str | None = None) -> Path:
    text = SEDAN_TOML.read_text().replace('name = "sedan"', f'name = "{name}"')
    if lr is not None:
        text = text.replace("lr    = { value = 1.6,", f"lr    = {{ value = {lr},")
        assert f"value = {lr}," in text
    path = folder / file
    path.write_text(text)
    return path


def test_a_300_character_vehicle_name_is_refused_when_its_file_is_loaded(tmp_path, capsys):
    """It failed only after the solve (the FMU's file name too long); refused by load_vehicle now,
    and `latobs design` exits 2 with one line before anything is solved or written."""
    long = "a" * 300
    car = _sedan_file(tmp_path, long, "long.toml")
    with pytest.raises(VehicleParameterError, match=f"has 300 characters, at most {VEHICLE_NAME_MAX}"):
        load_vehicle(str(car))
    out = tmp_path / "out"
    assert _main(["design", "LateralIntervalObserver", "--vehicle", str(car), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "300 characters" in err and not out.exists()
    ok = _sedan_file(tmp_path, "b" * VEHICLE_NAME_MAX, "ok.toml")
    assert load_vehicle(str(ok)).name == "b" * VEHICLE_NAME_MAX
    with pytest.raises(designs.ArtefactNameError, match="characters"):
        designs.artefact_name("LateralIntervalObserver", long)


def test_a_user_file_named_as_a_shipped_vehicle_must_be_that_vehicle(tmp_path, capsys):
    """./sedan.toml with other parameters built SideslipBankObserver.fmu, the shipped car's FMU
    name: refused now, telling to rename; a byte-identical copy is the shipped sedan and loads."""
    mine = tmp_path / "mine"
    mine.mkdir()
    other = _sedan_file(mine, "sedan", "sedan.toml", lr="1.7")
    with pytest.raises(VehicleParameterError, match=r"named 'sedan' like the shipped vehicle, but its content differs.*"
                                                    r'name = \\?"my_sedan\\?"'):
        load_vehicle(str(other))
    out = tmp_path / "out"
    assert _main(["design", "SideslipBankObserver", "--vehicle", str(other), "--out", str(out)]) == 2
    assert "like the shipped vehicle" in capsys.readouterr().err and not out.exists()
    same = _sedan_file(tmp_path, "sedan", "copy.toml")
    assert load_vehicle(str(same)) == load_vehicle("sedan")
    renamed = _sedan_file(mine, "my_sedan", "sedan2.toml", lr="1.7")
    assert designs.artefact_name("SideslipBankObserver", load_vehicle(str(renamed)).name) == \
        "SideslipBankObserver_my_sedan"


def test_export_ssp_out_under_missing_folders_writes_only_there_and_leaves_nothing_on_failure(tmp_path, monkeypatch):
    """The check of --out writes nothing (it wrote a probe file in the nearest existing folder);
    the missing folders are made as asked, and removed again when the package is not written."""
    out = tmp_path / "missing" / "deeper" / "x.ssp"

    def no_probe(*a, **k):
        raise AssertionError("a file written outside --out")

    monkeypatch.setattr(tempfile, "mkstemp", no_probe)
    export._check_out(out)
    assert list(tmp_path.iterdir()) == []
    monkeypatch.undo()
    with pytest.raises(SspError, match="would not be valid SSP 1.0, nothing written"):
        export._write_package(out, {"SystemStructure.ssd": b"<not-an-ssd/>"})
    assert list(tmp_path.iterdir()) == []                       # the folders made for it: gone
    monkeypatch.setattr(export, "check_package", lambda path: [])
    export._write_package(out, {"SystemStructure.ssd": b"<ssd/>"})
    assert out.is_file() and sorted(p.name for p in tmp_path.rglob("*")) == ["deeper", "missing", "x.ssp"]
    (tmp_path / "keep").mkdir()
    (tmp_path / "keep" / "f").write_text("x")
    monkeypatch.setattr(export, "check_package", lambda path: ["boom"])
    with pytest.raises(SspError, match="boom"):
        export._write_package(tmp_path / "keep" / "new" / "y.ssp", {"a": b""})
    assert sorted(p.name for p in (tmp_path / "keep").iterdir()) == ["f"]      # what was there stays
    assert os.listdir(tmp_path / "missing" / "deeper") == ["x.ssp"]
