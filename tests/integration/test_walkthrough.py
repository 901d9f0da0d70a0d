"""The documentation's walk-through (``docs/walkthrough.md``) works as written.

Its ``bash`` and ``python`` blocks are run in order in an empty folder, as a newcomer would type
them (``latobs`` of this installation on PATH): a vehicle file of their own car, the paper-000
observer and CarPlant built for it (this machine's platform only), ``latobs check`` and
``latobs validate`` on them, and the fmpy script, whose bank estimate must meet the truth.
"""
from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PAGE = ROOT / "docs" / "walkthrough.md"

pytestmark = [pytest.mark.slow, pytest.mark.schedule_first]


def blocks(text: str) -> list[tuple[str, str]]:
    """(language, code) of the page's fenced ``bash`` and ``python`` blocks, in order."""
    return [(m.group(1), m.group(2)) for m in re.finditer(r"^```(bash|python)\n(.*?)^```$", text, re.S | re.M)]


def test_blocks_are_found():
    langs = [lang for lang, _ in blocks(PAGE.read_text())]
    assert langs.count("bash") >= 4 and langs.count("python") == 1, langs


def test_walkthrough_runs(tmp_path):
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}"}
    outputs = []
    for k, (lang, code) in enumerate(blocks(PAGE.read_text())):
        if lang == "bash":
            cmd = ["bash", "-euo", "pipefail", "-c", code]
        else:
            script = tmp_path / f"block_{k}.py"
            script.write_text(code)
            cmd = [sys.executable, str(script)]
        proc = subprocess.run(cmd, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
        assert proc.returncode == 0, f"block {k} ({lang}) failed:\n{code}\n{proc.stdout}\n{proc.stderr}"
        outputs.append(proc.stdout)
    fmu = tmp_path / "fmus" / "SideslipBankObserver_mycar.fmu"
    assert fmu.is_file() and (tmp_path / "fmus" / "CarPlant_mycar.fmu").is_file()
    assert "PASS" in "".join(outputs) and "FAIL" not in "".join(outputs)
    assert (tmp_path / "results" / "bank-braking" / "metrics.json").is_file()
    m = re.search(r"true ([-\d.]+) deg, estimated ([-\d.]+) deg", outputs[-1])
    assert m, outputs[-1]
    assert abs(float(m.group(1)) - float(m.group(2))) < 0.2        # the bank angle is found
    rms = float(re.search(r"sideslip RMS error: ([\d.]+) deg", outputs[-1]).group(1))
    assert rms < 0.2
