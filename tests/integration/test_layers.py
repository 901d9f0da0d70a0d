"""The layers of the pipeline: the import-linter contracts of ``pyproject.toml`` ([tool.importlinter]).

Design time (latobs.synthesis) never imports validation, the runtimes, the backends or the FMI
tools; the FMU runtime (latobs.fmu_src) uses the standard library only; a certificate never
imports a design module; validation reads designs only through the design file; the C emitters
never read a runtime's internals. The contracts are checked on the installed ``latobs`` package:
in an editable install its subpackages live in other folders (synthesis/, fmu_src/), which
import-linter cannot follow, so their modules are first copied into one tree the way a normal
install lays them out.
"""
from __future__ import annotations

import importlib
import os
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

import latobs

PYPROJECT = Path(__file__).resolve().parents[2] / "pyproject.toml"

#: contracts broken by work that lands separately, with what breaks them; each is expected to fail
#: (strict: the test fails as soon as the contract holds, so that it is taken off this list)
PENDING: dict[str, str] = {}


def _contracts() -> list[dict]:
    return tomllib.loads(PYPROJECT.read_text())["tool"]["importlinter"]["contracts"]


def _installed_tree(tmp: Path) -> Path:
    """A folder holding ``latobs`` as a normal install lays it out: the installed package itself
    when it is one tree, else a copy of the modules of every package folder that
    [tool.setuptools.package-dir] maps (each found through the import system, so it is the code
    that runs)."""
    root = Path(latobs.__file__).resolve().parent
    mapped = tomllib.loads(PYPROJECT.read_text())["tool"]["setuptools"]["package-dir"]
    dirs = {name: Path(importlib.import_module(name).__file__).resolve().parent for name in mapped}
    if all(d == root.joinpath(*name.split(".")[1:]) for name, d in dirs.items()):
        return root.parent
    for name, src in sorted(dirs.items()):      # "latobs" first, then its subpackages into it
        dst = tmp.joinpath(*name.split("."))
        for f in src.rglob("*.py"):
            (dst / f.relative_to(src)).parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(f, dst / f.relative_to(src))
    return tmp


@pytest.fixture(scope="module")
def results(tmp_path_factory) -> tuple[dict, str]:
    """{contract name: kept} of every contract, and import-linter's account of the broken ones."""
    tmp = tmp_path_factory.mktemp("layers")
    tree = _installed_tree(tmp / "installed")
    env = dict(os.environ, PYTHONPATH=str(tree), COLUMNS="10000")       # one line per contract
    proc = subprocess.run([sys.executable, "-c", "from importlinter.cli import lint_imports_command as c; c()",
                           "--config", str(PYPROJECT), "--no-cache", "--no-logo"], cwd=tmp, env=env,
                          capture_output=True, text=True, timeout=300)
    text = proc.stdout + proc.stderr
    kept = {}
    for c in _contracts():
        verdicts = [w for w in ("KEPT", "BROKEN") if f"{c['name']} {w}" in text]
        assert len(verdicts) == 1, (c["name"], text)
        kept[c["name"]] = verdicts[0] == "KEPT"
    assert proc.returncode == (0 if all(kept.values()) else 1), text
    return kept, text


def test_contracts_have_unique_ids_and_every_pending_one_exists():
    ids = [c["id"] for c in _contracts()]
    assert len(set(ids)) == len(ids) and set(PENDING) <= set(ids)


@pytest.mark.parametrize("contract", [
    pytest.param(c, id=c["id"], marks=[pytest.mark.xfail(strict=True, reason=PENDING[c["id"]])] if c["id"] in PENDING else [])
    for c in _contracts()])
def test_contract_holds(results, contract):
    kept, text = results
    assert kept[contract["name"]], text
