"""latobs's validation drives FMI 3.0 FMUs as it drives FMI 2.0 ones (``latobs build --fmi 3``):
the co-simulation master (an FMI 3.0 observer beside an FMI 2.0 plant in one process, or all FMI
3.0), the replay of a recorded drive, a folder of FMI 3.0 FMUs kept in FMI 3.0, and a campaign;
each gives the FMI 2.0 twins' numbers bit for bit."""
from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from conftest import bits
from latobs import pipeline
from latobs.validation import get_scenario
from latobs.validation.harness import run


pytestmark = pytest.mark.usefixtures("fmi3_host")


@pytest.mark.parametrize("fast", [True, False], ids=["direct", "fmpy-checked"])
def test_the_master_runs_fmi3_fmus_beside_fmi2_ones_bit_for_bit(built_fmus, fast):
    sc = get_scenario("double-lane-change-15", duration=3.0)
    plant2, plant3 = built_fmus.c_path("CarPlant"), built_fmus.c3_path("CarPlant")
    obs2 = {n: built_fmus.c_path(n) for n in ("LateralIntervalObserver", "SideslipBankObserver")}
    obs3 = {n: built_fmus.c3_path(n) for n in obs2}
    want = run(sc, plant2, obs2, dt=0.005, fast=fast)
    for plant, observers in ((plant2, obs3), (plant3, obs3), (plant3, obs2)):
        got = run(sc, plant, observers, dt=0.005, fast=fast)
        assert [k for k in want.bus if bits(got.bus[k]) != bits(want.bus[k])] == []
        for lab in obs2:
            assert want.observers[lab].keys() == got.observers[lab].keys()
            assert [k for k in want.observers[lab] if bits(got.observers[lab][k]) != bits(want.observers[lab][k])] \
                == [], lab


def test_replay_of_the_recorded_drive_and_a_folder_kept_in_fmi3(built_fmus, tmp_path):
    """The MBDS record's first minute through the Kalman filter's FMI 3.0 FMU gives its FMI 2.0
    twin's outputs bit for bit; a command that ensures the FMU in a folder of FMI 3.0 FMUs reuses
    it (no FMI 2.0 FMU written over it)."""
    from latobs.validation.replay import MBDS_CSV, drive, load_csv

    name = "SideslipKalmanFilter"
    data = load_csv(MBDS_CSV)
    keep = data["t"] < data["t"][0] + 60.0
    data = {k: v[keep] for k, v in data.items()}
    r2, r3 = drive(built_fmus.c_path(name), data), drive(built_fmus.c3_path(name), data)
    assert r2.outputs.keys() == r3.outputs.keys() and len(r3.time) > 1000
    assert [k for k in r2.outputs if bits(r2.outputs[k]) != bits(r3.outputs[k])] == []
    folder = tmp_path / "fmi3"
    folder.mkdir()
    shutil.copy2(built_fmus.c3_path(name), folder / f"{name}.fmu")
    raw = (folder / f"{name}.fmu").read_bytes()
    assert pipeline.folder_fmi(folder) == 3 and pipeline.folder_fmi(tmp_path) == 2
    assert pipeline.ensure_fmus([name], folder) == {name: folder / f"{name}.fmu"}
    assert (folder / f"{name}.fmu").read_bytes() == raw


@pytest.mark.slow
def test_a_campaign_of_fmi3_fmus_gives_the_fmi2_campaigns_metrics(built_fmus, tmp_path):
    from latobs import packaging
    from latobs.campaign_runner import run_campaign
    from latobs.validation import campaign_stats as cs

    rows = {}
    for fmi in (2, 3):
        fmus = tmp_path / f"fmus{fmi}"
        fmus.mkdir()
        src = built_fmus.c_path if fmi == 2 else built_fmus.c3_path
        shutil.copy2(src("LateralIntervalObserver"), fmus / "LateralIntervalObserver.fmu")
        packaging.package_plant("CarPlant", "sedan_no_roll", fmus, backend="c", platforms=["linux64"], fmi=fmi)
        s = run_campaign("robustness-001", runs=2, out=tmp_path / f"out{fmi}", fmu_dir=fmus, workers=1,
                         progress=False, plots=False)
        rows[fmi] = cs.Journal(Path(s["folder"]) / "runs.jsonl").read()
    assert sorted(rows[3]) == [0, 1] and all(r["status"] == "ok" for r in rows[3].values())
    assert {k: r["metrics"] for k, r in rows[3].items()} == {k: r["metrics"] for k, r in rows[2].items()}
