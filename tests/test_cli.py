"""The command line: exit codes and messages (CONTRACT.md)."""
from __future__ import annotations

import json

import pytest

from latobs.cli import main


def test_list_names_everything(capsys):
    assert main(["list"]) == 0
    out = capsys.readouterr().out
    for name in ("SideslipBankObserver", "SideslipBankObserverTire", "CarPlant", "sedan", "mbds_250lm",
                 "bank-braking", "double-lane-change", "sine-with-dwell", "fishhook"):
        assert name in out


def test_every_design_has_an_fmu_model():
    from latobs.packaging import OBSERVERS
    from latobs.synthesis.designs import DESIGNS

    assert set(OBSERVERS) == set(DESIGNS)


def test_design_writes_a_certified_file(tmp_path, capsys):
    assert main(["design", "SideslipBankObserver", "--out", str(tmp_path)]) == 0
    data = json.loads((tmp_path / "SideslipBankObserver.design.json").read_text())
    for key in ("name", "paper", "vehicle", "modes", "gamma", "certified", "checks", "solver"):
        assert key in data
    assert data["certified"] and all(c["passed"] for c in data["checks"])
    assert set(data["checks"][0]) >= {"name", "value", "limit", "passed"}
    assert {"name", "status", "seconds"} <= set(data["solver"])
    assert "gamma" in capsys.readouterr().out


def test_errors_exit_nonzero_with_the_culprit(tmp_path, capsys):
    assert main(["design", "SideslipBankObserver", "--vehicle", "mbds_250lm", "--out", str(tmp_path)]) == 2
    assert "lacks parameter(s) Ix, hr, Kr, br" in capsys.readouterr().err
    assert not list(tmp_path.iterdir())                 # nothing half-written
    assert main(["build", "CarPlant", "--vehicle", "mbds_250lm", "--out", str(tmp_path)]) == 2
    assert "CarPlant_mbds_250lm: the CarPlant runtime rejects its data" in capsys.readouterr().err
    assert not list(tmp_path.glob("*.fmu"))
    assert main(["design", "NoSuchObserver"]) == 2
    assert "unknown design" in capsys.readouterr().err
    assert main(["build", "CarPlant", "--backend", "c", "--out", str(tmp_path)]) == 2
    assert "not available yet" in capsys.readouterr().err
    assert main(["validate", "no-such-scenario", "--out", str(tmp_path)]) == 2
    assert "no-such-scenario" in capsys.readouterr().err


def test_demo_certificate_section_renders(tmp_path, design_speed):
    from latobs.demo import _design_section
    from latobs.synthesis import design_file

    text = _design_section(design_file.write(design_speed, tmp_path))
    n = len(design_speed["checks"])
    assert f"certified, {n}/{n} checks passed" in text
    assert text.count("| Vx = ") == 3            # one row per speed mode


def test_validate_loads_no_design_stack_and_can_skip_plots(tmp_path, fmu_dir):
    """`latobs validate` with built FMUs imports neither the solver (cvxpy, Clarabel) nor the
    certificate (scipy) nor, with --no-plots, matplotlib; and writes no PNG then."""
    import subprocess
    import sys

    code = (
        "import sys, json\n"
        "from latobs.cli import main\n"
        f"rc = main(['validate', 'double-lane-change', '--fmu-dir', {str(fmu_dir)!r}, '--out', {str(tmp_path)!r}, "
        "'--no-plots'])\n"
        "print(json.dumps([rc, sorted(m for m in sys.modules if m.split('.')[0] in "
        "('cvxpy', 'clarabel', 'scipy', 'matplotlib', 'pythonfmu') or m.endswith(('.certificate', '.pi_hinf_000', '.hinf')))]))\n")
    proc = subprocess.run([sys.executable, "-P", "-c", code], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    rc, heavy = json.loads(proc.stdout.strip().splitlines()[-1])
    assert rc == 0 and heavy == []
    out = tmp_path / "double-lane-change"
    assert (out / "metrics.json").is_file() and not list(out.glob("*.png"))


def test_bench_takes_its_own_options(capsys):
    """`latobs bench --fmu-dir D` reaches bench's parser (argparse's REMAINDER alone would refuse
    an option as the subcommand's first argument)."""
    from latobs.cli import main

    with pytest.raises(SystemExit) as exc:
        main(["bench", "--help"])
    assert exc.value.code == 0
    assert "--fmu-dir" in capsys.readouterr().out
