"""The documentation: the MkDocs site builds with ``--strict``, its generated pages say what the
code declares, and nothing user-facing points outside the repository.

- ``mkdocs build --strict`` of ``mkdocs.yml`` (every page in the navigation, every link and anchor
  resolved, the API pages collected by mkdocstrings) into a temporary folder;
- the FMU pages come from ``latobs.datasheet.markdown``, the generator of each FMU's own datasheet:
  every variable of the model description is on the page, with the cells of the HTML datasheet;
- the command-line reference comes from ``latobs.cli.parser``: every command and option;
- README: under 10 KB, the two commands ``.ci/run`` and the CI workflow rely on, links that resolve,
  and its worked example runs on the FMUs ``latobs build`` makes;
- no user-facing text (README, CHANGELOG, the docs and their generated pages, every command's
  help, the vehicle and campaign files, the examples, the datasheet generator and the papers'
  citations) mentions files outside the repository or the project's issue numbers.
"""
from __future__ import annotations

import os
import re
import subprocess
import sys
from importlib import import_module
from pathlib import Path

import pytest

from latobs import datasheet, packaging
from latobs.cli import parser, reference_markdown
from latobs.fmu_src import framework

ROOT = Path(__file__).resolve().parents[2]
DOCS = ROOT / "docs"
#: what user-facing text must never say: a path outside the repository, the project's internal
#: reference files, an issue number
FORBIDDEN = re.compile(r"\.\./shared|shared/(?:reference|data|seeds)|CONTRACT\.md|ERRATA|vehicles\.md"
                       r"|\bissues?\s*#?\d+|#\d{1,4}\b(?!\s*(?:m/s|km|s\b))", re.I)


def _hooks():
    """The site's hooks module (docs/hooks.py: the generated pages)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("latobs_docs_hooks", DOCS / "hooks.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _spec(kind):
    return import_module(f"latobs.fmu_src.models.{kind.model_module}").SPEC


FMUS = {**packaging.OBSERVERS, **packaging.PLANTS}


def test_site_builds_strict(tmp_path):
    pytest.importorskip("mkdocs", reason="MkDocs is not installed (pip install '.[docs]')")
    site = tmp_path / "site"
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1"}
    proc = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "-f", str(ROOT / "mkdocs.yml"),
                           "-d", str(site)], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    for name in FMUS:                                        # one generated page per FMU
        page = (site / "fmus" / name / "index.html").read_text()
        assert name in page
    cli = (site / "cli" / "index.html").read_text()
    assert "latobs build" in cli and "--platforms" in cli
    api = (site / "api" / "index.html").read_text()
    assert "build_summary" in api or "doc-function" in api   # mkdocstrings rendered the API
    for page in site.rglob("*.html"):
        text = page.read_text()
        assert not FORBIDDEN.search(re.sub(r"<[^>]+>", " ", text)), (page, FORBIDDEN.search(text))


@pytest.mark.parametrize("name", list(FMUS))
def test_fmu_page_is_the_datasheet(name):
    """Every model-description variable is on the FMU's page, in the datasheet's cells."""
    kind = FMUS[name]
    spec = _spec(kind)
    page = _hooks().fmu_page(name, kind)
    names = [v.name for _, _, _, v in framework.variable_table(spec)]
    assert names
    cells = datasheet._interface_cells(spec, {}, ())
    for rows in cells.values():
        for row in rows:
            line = "| " + " | ".join([f"`{row[0]}`"] + [datasheet._md(x) for x in row[2:]]) + " |"
            assert line in page, line
    assert sorted(r[0] for rows in cells.values() for r in rows) == sorted(names)
    html_page = datasheet._interface(spec, {}, ())
    for v in names:
        assert f'id="var-{v}"' in html_page
    if spec.paper is not None:
        assert spec.paper.title in page


def test_fmu_page_changes_with_the_spec():
    """The page is generated: a changed declaration changes it."""
    import dataclasses

    kind = FMUS["CarPlant"]
    spec = _spec(kind)
    v = spec.inputs[0]
    changed = dataclasses.replace(spec, inputs=(dataclasses.replace(v, description="a changed text"),
                                               *spec.inputs[1:]))
    assert "a changed text" in datasheet.markdown(changed, "CarPlant", data_kind="plant")
    assert "a changed text" not in datasheet.markdown(spec, "CarPlant", data_kind="plant")


def test_cli_reference_has_every_command_and_option():
    import argparse

    from latobs.bench import parser as bench_parser

    text = reference_markdown()
    sub = next(a for a in parser()._actions if isinstance(a, argparse._SubParsersAction))
    for name, cmd in sub.choices.items():
        assert f"## `latobs {name}`" in text
        cmd = bench_parser() if name == "bench" else cmd
        for a in cmd._actions:
            for opt in a.option_strings:
                if opt not in ("-h", "--help"):
                    assert f"`{opt}" in text or f", {opt}" in text, (name, opt)


def test_readme():
    text = (ROOT / "README.md").read_text()
    assert len(text.encode()) < 10_000
    # the two commands (.ci/run and the CI workflow run them)
    assert "\n```\npip install . && latobs demo\n```\n" in text
    assert '\n```\npip install ".[test]" && pytest\n```\n' in text
    for target in re.findall(r"\]\(([^)#]+)\)", text):
        if "://" not in target:
            assert (ROOT / target).exists(), target


def _user_facing_texts():
    """(where, text) of every user-facing text."""
    import argparse

    from latobs.bench import parser as bench_parser

    yield "README.md", (ROOT / "README.md").read_text()
    yield "CHANGELOG.md", (ROOT / "CHANGELOG.md").read_text()
    for f in sorted(DOCS.rglob("*.md")):
        yield str(f.relative_to(ROOT)), f.read_text()
    hooks = _hooks()
    for name, kind in FMUS.items():
        yield f"FMU page {name}", hooks.fmu_page(name, kind)
    yield "FMU index", hooks.fmu_index()
    yield "CLI reference", reference_markdown()
    p = parser()
    yield "latobs --help", p.format_help()
    sub = next(a for a in p._actions if isinstance(a, argparse._SubParsersAction))
    for name, cmd in sub.choices.items():
        yield f"latobs {name} --help", (bench_parser() if name == "bench" else cmd).format_help()
    for folder, pattern in (("synthesis/vehicles", "*.toml"), ("latobs/campaigns", "*.toml"), ("examples", "*")):
        for f in sorted((ROOT / folder).glob(pattern)):
            if f.is_file():
                yield str(f.relative_to(ROOT)), f.read_text()
    for f in ("latobs/datasheet.py", "fmu_src/papers.py", "latobs/demo.py", "latobs/cli.py"):
        yield f, (ROOT / f).read_text()


def test_nothing_user_facing_points_outside():
    found = [(where, m.group(0)) for where, text in _user_facing_texts() for m in FORBIDDEN.finditer(text)]
    assert not found, found


def test_the_scan_sees_a_pointer():
    assert FORBIDDEN.search("see ../shared/CONTRACT.md") and FORBIDDEN.search("as in issue 9")
    assert FORBIDDEN.search("(ERRATA 001)") and FORBIDDEN.search("fixed in #21")
    assert not FORBIDDEN.search("paper 002's eq. (28), 5 ms, 2 bands, the paper's misprint")


@pytest.mark.slow
def test_readme_example_runs(built_fmus, tmp_path, capsys):
    """The README's worked example (plain fmpy, CarPlant feeding the paper-000 observer) runs on the
    FMUs `latobs build` makes and finds the bank angle."""
    code = re.search(r"```python\n(.*?)```", (ROOT / "README.md").read_text(), re.S).group(1)
    for name in ("CarPlant", "SideslipBankObserver"):
        assert f'"build/{name}.fmu"' in code
        code = code.replace(f'"build/{name}.fmu"', repr(str(built_fmus.get(name, "c"))))
    capsys.readouterr()                                  # the session build's progress lines
    exec(compile(code, "README.md", "exec"), {})
    bank = float(capsys.readouterr().out.splitlines()[-1].split()[0])
    assert abs(bank - 4.0) < 0.2
