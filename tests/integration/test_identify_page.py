"""The documentation's page "Your car from its log" (``docs/identify.md``) works as written: its
``bash`` blocks run in order in an empty folder (``latobs`` of this installation on PATH): the
stiffnesses identified from the MBDS record's tuning part into ``mycar.toml``, the Kalman peer
built for that car, and its replay scored on the held-out part beside the baselines."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from latobs.synthesis.params import load_vehicle
from test_walkthrough import ROOT, blocks

PAGE = ROOT / "docs" / "identify.md"

pytestmark = [pytest.mark.slow, pytest.mark.schedule_first]


def test_the_page_runs_from_a_log_to_a_scored_fmu(tmp_path):
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}"}
    code = [c for lang, c in blocks(PAGE.read_text()) if lang == "bash"]
    assert len(code) == 3
    for block in code:
        proc = subprocess.run(["bash", "-euo", "pipefail", "-c", block], cwd=tmp_path, env=env, capture_output=True,
                              text=True, timeout=300)
        assert proc.returncode == 0, f"{block}\n{proc.stdout}\n{proc.stderr}"
    car = load_vehicle(str(tmp_path / "mycar.toml"))
    page = PAGE.read_text()
    for k in ("Cf", "Cr"):                  # the page shows what the command gives
        assert f"{k} = {car.value(k):.0f} N/rad" in page, (k, car.value(k))
        assert car.ranges[k].min < car.value(k) < car.ranges[k].max
    metrics = json.loads(next((tmp_path / "results").glob("replay_*_SideslipKalmanFilter_mycar/metrics.json"))
                         .read_text())
    assert metrics["vehicle"] == "mycar" and metrics["split_s"] == 425.0
    beta = metrics["observers"]["SideslipKalmanFilter_mycar"]["estimates"]["beta_hat"]
    held_out = beta["after_split"]
    assert held_out["n_samples"] == 27500 and held_out["nonfinite_samples"] == 0
    assert held_out["rms"] < 0.5 * 0.0335     # well inside the zero baseline's 1.92 deg on the held-out part
