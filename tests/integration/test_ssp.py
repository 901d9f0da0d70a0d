"""`latobs export-ssp`: the SSP 1.0 package of a validation scenario.

One package is exported per module, of bank-braking cut to 3 s with the four default observers and
two plant parameters (so that the parameter sets matter), then checked against the SSP 1.0
schemas, against the harness's wiring, and run in libcosim (the example script, in a fresh
process) and in fmpy's SSP support, each compared with the harness on the same scenario.
"""
from __future__ import annotations

import csv
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

from latobs import ssp as S
from latobs.ssp import export
from latobs.validation import get_scenario, harness

pytestmark = pytest.mark.slow
ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "examples" / "open_ssp_in_libcosim.py"
OBSERVERS = ["SideslipBankObserver", "SideslipBankObserverTire", "SideslipBankObserverPaper",
             "SideslipBankObserverTirePaper"]       # latobs validate's default beside CarPlant
PLANT_PARAMETERS = {"scale_f": 0.9, "mu": 0.9}
RTOL = 1e-9     # libcosim vs harness: |a - b| <= RTOL * max(1, |b|) (measured: 1e-12, round-off)


@pytest.fixture(scope="module")
def scenario():
    return get_scenario("bank-braking", duration=3.0)


@pytest.fixture(scope="module")
def package(fmu_dir, scenario, tmp_path_factory):
    assert S.default_observers(scenario) == OBSERVERS
    out = tmp_path_factory.mktemp("ssp") / "bank-braking-3s.ssp"
    return S.export_ssp(scenario, None, out, fmu_dir, plant_parameters=PLANT_PARAMETERS, quiet=True)


@pytest.fixture(scope="module")
def reference(fmu_dir, scenario):
    """What `latobs validate` runs: the harness, same FMUs, scenario, step and plant parameters."""
    return harness.run(scenario, fmu_dir / "CarPlant.fmu", {n: fmu_dir / f"{n}.fmu" for n in OBSERVERS},
                       plant_parameters=PLANT_PARAMETERS, vehicle="sedan")


def test_the_package_is_valid_ssp_1_0(package, tmp_path):
    from lxml import etree
    import xmlschema
    from pyssp_standard.ssd import SSD
    from pyssp_standard.standard import ModelicaStandard

    assert S.check_package(package) == []
    with zipfile.ZipFile(package) as z:
        names = set(z.namelist())
        assert names == {"SystemStructure.ssd", "resources/ScenarioSignals.fmu", "resources/CarPlant.fmu",
                         "resources/plant.ssv", *(f"resources/{n}.fmu" for n in OBSERVERS),
                         *(f"resources/{n}.ssv" for n in OBSERVERS)}
        z.extractall(tmp_path)
    # pyssp-standard's validator and its schemas, independently of latobs.ssp
    SSD(tmp_path / "SystemStructure.ssd", "r").__check_compliance__()
    xmlschema.XMLSchema10(str(ModelicaStandard.schemas["ssd"])).validate(str(tmp_path / "SystemStructure.ssd"))
    ssv = xmlschema.XMLSchema10(str(ModelicaStandard.schemas["ssv"]))
    for f in (tmp_path / "resources").glob("*.ssv"):
        ssv.validate(str(f))
    # the experiment, the step libcosim reads, and the parameter values
    assert S.experiment_of(package) == (0.0, 3.0, 0.005)
    plant = etree.parse(str(tmp_path / "resources" / "plant.ssv"))
    values = {p.get("name"): float(p[0].get("value")) for p in plant.iterfind(".//ssv:Parameter", S.NS)}
    assert values == {"mu": 0.9, "scale_f": 0.9, "scale_r": 1.0, "sigma": 0.5, "linear_tires": 0.0}
    obs = etree.parse(str(tmp_path / "resources" / "SideslipBankObserver.ssv"))
    assert [(p.get("name"), p[0].get("value")) for p in obs.iterfind(".//ssv:Parameter", S.NS)] == [("vx_hold", "1.0")]


def test_an_invalid_package_is_never_written(fmu_dir, scenario, tmp_path, monkeypatch):
    out = tmp_path / "bad.ssp"
    bad = S.Connection("SideslipBankObserver", "mode", S.PLANT_LABEL, "delta")   # Integer -> Real,
    monkeypatch.setattr(export, "wiring", lambda *a: [bad])                      # inputs left unconnected
    with pytest.raises(S.SspError, match=r"not be valid SSP 1.0.*mode -> plant.delta: not an output -> input "
                                         r"connection of one type.*SideslipBankObserver.vx is connected 0 times"):
        S.export_ssp(scenario, ["SideslipBankObserver"], out, fmu_dir, quiet=True)
    monkeypatch.undo()
    real = S.ssd_bytes
    monkeypatch.setattr(export, "ssd_bytes", lambda *a: real(*a).replace(b' version="1.0"', b""))   # schema: required
    with pytest.raises(S.SspError, match="version"):
        S.export_ssp(scenario, ["SideslipBankObserver"], out, fmu_dir, quiet=True)
    assert list(tmp_path.iterdir()) == []


def test_connections_are_the_harness_wiring(package, reference, scenario):
    got = {(c.end_element, c.end_connector): (c.start_element, c.start_connector) for c in S.connections_of(package)}
    assert len(got) == len(S.connections_of(package))              # each input connected once
    scenario_names = set(scenario.signals(reference.time[:2]))
    plant_outputs = set(reference.bus) - scenario_names
    expected = {("plant", x): ("signals", x) for x in reference.inputs["plant"]}
    for label in OBSERVERS:
        for x in reference.inputs[label]:
            expected[(label, x)] = ("plant", x) if x in plant_outputs else ("signals", x)
    assert got == expected
    assert expected[("SideslipBankObserver", "yaw_rate")] == ("plant", "yaw_rate")
    assert expected[("SideslipBankObserver", "vx")] == ("signals", "vx")


def _read_csv(path: Path) -> dict[str, np.ndarray]:
    with open(path, newline="") as fh:
        rows = list(csv.reader(fh))
    data = np.array([[float(x) for x in r] for r in rows[1:]])
    return {name: data[:, i] for i, name in enumerate(rows[0])}


def test_libcosim_runs_it_as_the_harness_does(package, reference, fmu_dir, scenario, tmp_path):
    """The example script (libcosimpy only, a fresh process) against the harness: every scenario
    signal, plant output and observer output at t_1..t_n (libcosim records after each step).
    libcosim steps by the difference of two double time points (to_double_duration), not
    exactly 0.005 s: the runs agree to round-off."""
    out = tmp_path / "libcosim.csv"
    proc = subprocess.run([sys.executable, str(EXAMPLE), str(package), "--csv", str(out)], capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "600 steps of libcosim to t = 3 s" in proc.stdout
    run, ref = _read_csv(out), S.harness_trace(reference)
    assert set(run) == set(ref)
    diff = S.compare(run, ref)
    worst = {k: d / max(1.0, float(np.max(np.abs(ref[k])))) for k, d in diff.items()}
    name = max(worst, key=worst.get)
    print(f"libcosim vs harness: worst {name} {diff[name]:.3g} (relative {worst[name]:.3g})")
    assert worst[name] <= RTOL, f"{name} differs by {diff[name]:.3g}"
    # the run is not trivial: the bank estimate moves, and libcosim applied the plant's parameter set
    assert np.ptp(run["SideslipBankObserver.bank_angle_hat"]) > 0.01
    assert set(np.unique(run["SideslipBankObserver.mode"])) == {3.0}
    nominal = harness.run(scenario, fmu_dir / "CarPlant.fmu", {}, vehicle="sedan")
    assert np.max(np.abs(nominal.bus["yaw_rate"][1:] - run["plant.yaw_rate"])) > 1e-3


def test_fmpy_runs_it_with_zero_inputs_in_the_first_step(package, reference, fmu_dir, scenario):
    """fmpy's simulate_ssp starts every connection at 0.0: it equals the harness on the scenario
    with every signal 0 at t_0 exactly, and the harness itself from t_1 on up to what that one
    step changes (bank-braking: CarPlant sees vx jump from 0 to 25 m/s, ax = 5000 m/s^2 for a step)."""
    run = S.simulate_fmpy(package)
    ref = S.harness_trace(reference)
    assert set(run) == set(ref)
    same = harness.run(S.fmpy_equivalent(scenario), fmu_dir / "CarPlant.fmu",
                       {n: fmu_dir / f"{n}.fmu" for n in OBSERVERS}, plant_parameters=PLANT_PARAMETERS)
    assert max(S.compare(run, S.harness_trace(same)).values()) == 0.0
    diff = S.compare(run, ref)
    assert all(diff[k] == 0.0 for k in ref if k.startswith("signals."))   # the signal source is exact
    assert diff["plant.Fyf"] > 0.1                                        # the zero first step shows
    late = S.compare({k: v[-100:] for k, v in run.items()}, {k: v[-100:] for k, v in ref.items()})
    assert max(late[k] / max(1.0, float(np.max(np.abs(ref[k])))) for k in late) < 1e-6   # and fades


def _cli(*args, cwd):
    return subprocess.run([sys.executable, "-m", "latobs", "export-ssp", *args], capture_output=True, text=True,
                          cwd=cwd, timeout=120)


@pytest.mark.parametrize("args, culprit", [
    (["no-such-scenario"], "no-such-scenario"),
    (["bank-braking", "--observer", "NoSuchObserver"], "NoSuchObserver"),
    (["bank-braking", "--out", "afile/x.ssp"], "afile"),
    (["bank-braking", "--out", "x.zip"], "x.zip"),
    (["bank-braking", "--plant-param", "nosuch=1"], "nosuch"),
    (["bank-braking", "--plant-param", "mu=-1"], "mu=-1"),
], ids=["scenario", "observer", "out-under-a-file", "out-not-ssp", "plant-param", "plant-param-range"])
def test_bad_arguments_exit_2_with_one_line(tmp_path, fmu_dir, args, culprit):
    """Refused before anything is built or written (the plant parameter is checked against the
    built CarPlant, so that case gets the built FMUs; the others an empty folder)."""
    (tmp_path / "afile").write_text("not a folder")
    empty = tmp_path / "fmus"
    empty.mkdir()
    fmus = fmu_dir if "--plant-param" in args else empty
    proc = subprocess.run([sys.executable, "-m", "latobs", "export-ssp", *args, "--fmu-dir", str(fmus)],
                          capture_output=True, text=True, cwd=tmp_path, timeout=120)
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("latobs export-ssp: error:") and culprit in lines[0], lines
    assert "Traceback" not in proc.stderr
    assert not list(tmp_path.rglob("*.ssp")) and not list(empty.iterdir()) and not (tmp_path / "build").exists()
