"""MkDocs hooks of latobs's documentation site (``mkdocs.yml``: ``hooks``).

The pages that are generated, never written by hand, are made here at every build from the code
they describe: one page per FMU (``latobs.datasheet.markdown``, the generator of each FMU's own
datasheet, from the FMU's declarations), the command-line reference (``latobs.cli``'s argument
parser) and the changelog (``CHANGELOG.md``). The navigation's "FMUs" and "Runtimes" sections
list the FMU pages and ``docs/runtime/*.md``.
"""
from __future__ import annotations

from importlib import import_module
from pathlib import Path

#: the documentation page of each paper (FMUs link their paper's page)
PAPER_PAGES = {"000": "000.md", "001": "001.md", "002": "002.md", "003": "003.md"}
KALMAN = "SideslipKalmanFilter"


def _fmus() -> dict:
    """{FMU name: latobs.packaging.FmuKind} of every FMU ``latobs build`` makes."""
    from latobs import packaging

    return {**packaging.OBSERVERS, **packaging.PLANTS}


def fmu_page(name: str, kind) -> str:
    """The Markdown page of one FMU."""
    from latobs import datasheet
    from latobs.synthesis import designs

    spec = import_module(f"latobs.fmu_src.models.{kind.model_module}").SPEC
    summary, paper = "", None
    if kind.data_kind == "design":
        entry = designs.get(name)
        summary = (f"Design `{name}`: {datasheet._md(entry.description)}. Default vehicle `{kind.default_vehicle}`; "
                   f"`latobs build {name} --vehicle V` builds it for another (`{name}_V.fmu`).")
        paper = "kalman.md" if name == KALMAN else PAPER_PAGES.get(entry.paper)
    else:
        summary = (f"Plant (nonlinear truth model for validation), default vehicle `{kind.default_vehicle}`; "
                   f"`latobs build {name} --vehicle V` builds it for another (`{name}_V.fmu`).")
        paper = "003.md" if kind.default_vehicle == "sharp_motorcycle" else None
    return datasheet.markdown(spec, name, data_kind=kind.data_kind, summary=summary,
                              paper_page=f"../papers/{paper}" if paper else "")


def fmu_index() -> str:
    rows = []
    for name, kind in _fmus().items():
        spec = import_module(f"latobs.fmu_src.models.{kind.model_module}").SPEC
        role = "observer" if kind.data_kind == "design" else "plant"
        ins = ", ".join(v.name for v in spec.inputs)
        outs = ", ".join(v.name for v in (*spec.outputs, *spec.integer_outputs))
        rows.append(f"| [{name}]({name}.md) | {role} | {kind.default_vehicle} | {ins} | {outs} |")
    return "\n".join(["# FMUs", "",
                      "Every FMU `latobs build` makes, one page each, generated from the declarations its model "
                      "description and its own datasheet (`documentation/index.html` inside the FMU) are generated "
                      "from. Plant outputs and observer inputs share names: wiring is by name.", "",
                      "| FMU | kind | default vehicle | inputs | outputs |", "|---|---|---|---|---|", *rows, ""])


def _set_section(nav: list, title: str, entries: list) -> None:
    for k, item in enumerate(nav):
        if isinstance(item, dict) and title in item:
            if entries:
                nav[k] = {title: entries}
            else:
                del nav[k]
            return


def on_config(config, **kwargs):
    docs = Path(config["docs_dir"])
    fmus = [{"Overview": "fmus/index.md"}] + [{name: f"fmus/{name}.md"} for name in _fmus()]
    _set_section(config["nav"], "FMUs", fmus)
    runtime = [{p.stem: f"runtime/{p.name}"} for p in sorted((docs / "runtime").glob("*.md"))]
    _set_section(config["nav"], "Runtimes", runtime)
    return config


def on_files(files, config, **kwargs):
    from mkdocs.structure.files import File

    from latobs.cli import reference_markdown

    root = Path(config["config_file_path"]).parent
    pages = {"cli.md": reference_markdown(), "fmus/index.md": fmu_index(),
             "changelog.md": (root / "CHANGELOG.md").read_text(encoding="utf-8")}
    pages.update({f"fmus/{name}.md": fmu_page(name, kind) for name, kind in _fmus().items()})
    for path, text in pages.items():
        files.append(File.generated(config, path, content=text))
    return files
