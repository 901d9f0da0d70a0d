"""The examples (examples/*.py) run and do what their docstrings say; the CI workflow is valid YAML
and runs commands that exist (issue 10, items 3 and 4)."""
from __future__ import annotations

import ast
import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.schedule_first      # (few long tests: tests/conftest.py)

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = ROOT / "examples"
WORKFLOW = ROOT / ".github" / "workflows" / "build-fmus.yml"
OURS = ("simulate_with_fmpy.py", "model_exchange_with_fmpy.py", "replay_csv.py", "custom_vehicle.py")


def run_example(name: str, *args: str, cwd: Path, python_flags: tuple[str, ...] = ()) -> subprocess.CompletedProcess:
    proc = subprocess.run([sys.executable, *python_flags, str(EXAMPLES / name), *args], cwd=cwd,
                          capture_output=True, text=True, timeout=180)
    assert proc.returncode == 0, f"{name} exited {proc.returncode}\n{proc.stdout}\n{proc.stderr}"
    return proc


@pytest.fixture(scope="module")
def observer_and_plant(tmp_path_factory, design_speed):
    """SideslipBankObserver.fmu (the session's design) and CarPlant.fmu, built by latobs.packaging."""
    from latobs import packaging
    from latobs.synthesis import design_file

    out = tmp_path_factory.mktemp("example_fmus")
    packaging.package_design(design_file.write(design_speed, out), out)
    packaging.package_plant("CarPlant", None, out)
    return out


def test_examples_are_documented_and_listed():
    readme = (EXAMPLES / "README.md").read_text()
    for name in OURS:
        tree = ast.parse((EXAMPLES / name).read_text())
        doc = ast.get_docstring(tree)
        assert doc and "Run it" in doc and f"examples/{name}" in doc, name
        assert any(isinstance(n, ast.If) and "__main__" in ast.unparse(n.test) for n in tree.body), name
    for name in (*OURS, "open_ssp_in_libcosim.py"):
        assert f"`{name}`" in readme


@pytest.mark.slow
def test_simulate_with_fmpy_imports_no_latobs(observer_and_plant, tmp_path):
    proc = run_example("simulate_with_fmpy.py", "--fmu-dir", str(observer_and_plant), "--duration", "10",
                       "--check-no-latobs", cwd=tmp_path, python_flags=("-X", "importtime"))
    # -X importtime lists every module imported in the process, the FMUs' own included: their
    # runtime is latobs_rt_<hash>, never the latobs package
    imported = [line.rsplit("|", 1)[-1].strip() for line in proc.stderr.splitlines() if line.startswith("import time:")]
    assert any(m.startswith("latobs_rt_") for m in imported) and "fmpy" in imported
    assert not [m for m in imported if m == "latobs" or m.startswith("latobs.")]
    out = proc.stdout
    assert "latobs modules loaded: none" in out
    assert "yaw_rate <- plant" in out and "delta <- driver" in out
    (b_hat, b), = re.findall(r"beta: estimate ([-+.\d]+) deg, truth ([-+.\d]+) deg", out)
    (bank_hat, bank), = re.findall(r"bank: estimate ([-+.\d]+) deg, truth ([-+.\d]+) deg", out)
    assert float(bank) == 3.0 and abs(float(bank_hat) - 3.0) < 0.3      # converged to the road's bank
    assert abs(float(b_hat) - float(b)) < 0.1


@pytest.mark.slow
def test_model_exchange_with_fmpy_agrees_with_co_simulation(built_fmus, tmp_path):
    """The native FMUs of the session; ModelExchange within 5e-3 of each estimate's peak of the
    co-simulation over 3 s at 1 ms (measured: 1.4e-3 on beta, 3e-4 on bank, 7e-4 on the yaw rate).
    The difference is O(h): the co-simulation's first-order hold integrates the samples as ramps,
    the ModelExchange run as the held steps it is given."""
    import os

    for name in ("SideslipBankObserver", "CarPlant"):
        os.link(built_fmus.c_path(name), tmp_path / f"{name}.fmu")
    out = run_example("model_exchange_with_fmpy.py", "--fmu-dir", str(tmp_path), "--duration", "3",
                      cwd=tmp_path).stdout
    diffs = re.findall(r"(\w+): max \|ME - CS\| = ([-+.\de]+) \(peak ([-+.\de]+)\)", out)
    assert [d[0] for d in diffs] == ["beta_hat", "bank_angle_hat", "yaw_rate_hat"]
    for name, diff, peak in diffs:
        assert float(diff) <= 5e-3 * float(peak), (name, diff, peak)
    assert "final bank: ModelExchange" in out


@pytest.mark.slow
def test_replay_csv_first_seconds(tmp_path):
    proc = run_example("replay_csv.py", "--seconds", "10", "--fmu-dir", str(tmp_path / "fmus"),
                       "--out", str(tmp_path / "out"), cwd=tmp_path)
    assert "beta_hat vs beta: RMS error" in proc.stdout
    assert "best baseline" in proc.stdout
    csv = tmp_path / "out" / "mbds_250lm_100hz_first10s.csv"
    assert len(csv.read_text().splitlines()) == 1 + 1001            # header + 10 s at 100 Hz
    m = json.loads((tmp_path / "out" / "replay_mbds_250lm_100hz_first10s_SideslipKalmanFilter" / "metrics.json")
                   .read_text())
    assert m["n_samples"] == 1001 and m["split_s"] is None
    rms = m["observers"]["SideslipKalmanFilter"]["estimates"]["beta_hat"]["all"]["rms"]
    assert 0 < rms < 0.02                                              # rad, about 0.4 deg
    assert f"{rms:.4g}" in proc.stdout


@pytest.mark.slow
def test_custom_vehicle_designs_and_builds(tmp_path):
    proc = run_example("custom_vehicle.py", "--out", str(tmp_path / "custom"), cwd=tmp_path)
    out = proc.stdout
    fmu = tmp_path / "custom" / "SideslipBankObserver_sedan_heavy.fmu"
    assert fmu.is_file()
    design = json.loads(fmu.with_name("SideslipBankObserver_sedan_heavy.design.json").read_text())
    assert design["vehicle"]["name"] == "sedan_heavy"
    assert design["vehicle"]["parameters"]["m"]["value"] == pytest.approx(1.3 * 1500.0)
    n = len(design["checks"])
    assert f"certificate: certified, {n}/{n} checks passed" in out
    assert f"gamma = {design['gamma']:.4g}" in out
    assert f"FMU: {fmu.relative_to(tmp_path)}" in out or f"FMU: {fmu}" in out


def test_workflow_runs_real_commands():
    """What the workflow runs exists: the README's install and test commands, and latobs
    arguments that the CLI's parser accepts."""
    from latobs.cli import parser

    text = WORKFLOW.read_text()
    readme = (ROOT / "README.md").read_text()
    assert "\t" not in text
    for cmd in ('pip install ".[test]" && pytest', "pip install ."):
        assert cmd in readme and cmd in text
    for cmd in re.findall(r"^\s+(?:run: )?(latobs [^\n#]+)$", text, flags=re.M):
        args = parser().parse_args(cmd.split()[1:])
        assert args.command in ("build", "demo")
    assert "latobs build --json build/summary.json" in text and "latobs demo" in text


def test_workflow_is_valid_yaml():
    yaml = pytest.importorskip("yaml", reason="PyYAML is not installed (not among the test extras)")
    doc = yaml.safe_load(WORKFLOW.read_text())
    on = doc.get("on", doc.get(True))                 # YAML 1.1 reads the key `on` as True
    assert set(on["push"]) == {"branches", "tags"}
    build, test = doc["jobs"]["build"], doc["jobs"]["test"]
    assert build["strategy"]["matrix"]["python-version"] == ["3.11", "3.12"]
    runs = "\n".join(s.get("run", "") for s in build["steps"])
    assert "pip install ." in runs and "latobs demo" in runs and "latobs build --json build/summary.json" in runs
    assert runs.index("latobs demo") < runs.index("latobs build --json")   # the summary describes the uploads
    (upload,) = [s for s in build["steps"] if s.get("uses", "").startswith("actions/upload-artifact@")]
    assert set(upload["with"]["path"].split()) == {"build/*.fmu", "build/*.design.json", "build/summary.json",
                                                   "build/report/"}
    assert "${{ matrix.python-version }}" in upload["with"]["name"]      # one artifact per Python
    assert any('pip install ".[test]" && pytest' in s.get("run", "") for s in test["steps"])
