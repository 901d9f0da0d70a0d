"""The datasheet inside every FMU (``latobs.datasheet``): ``documentation/index.html`` and ``model.png``.

On four FMUs of the session build, one observer and one plant per backend, the page is checked
against the FMU's own ``modelDescription.xml`` and design file: every model-description variable
is listed with its unit, range and start, and its model-description text is the page's
description, sign convention and sensor; the largest step is the declared one; the certificate's
summary (count, pass status of every check, gamma) is the design file's; the platforms are the
FMU's binaries folders; every link resolves. Then headless Chromium renders the page (a
screenshot that is a PNG of more than one colour). ``.ci/run`` installs Chromium where it is
missing; the rendering is skipped only when Chromium is absent and apt-get too.
"""
from __future__ import annotations

import json
import math
import os
import shutil
import struct
import subprocess
import xml.etree.ElementTree as ET
import zipfile
from html.parser import HTMLParser
from importlib import import_module
from pathlib import Path

import numpy as np
import pytest

from latobs import datasheet, packaging
from latobs.fmu_src.spec import max_step

pytestmark = pytest.mark.slow
#: (name, backend): an observer and a plant per backend
CASES = [("SideslipBankObserver", "c"), ("MotorcyclePlant", "c"), ("SideslipKalmanFilter", "python"),
         ("CarPlant", "python")]


class Page(HTMLParser):
    """What the tests read of a page: ids, links, and every table's rows as cells
    {"class", "text", "attrs" (of the cell and the elements inside it)}."""

    def __init__(self, text: str):
        super().__init__()
        self.ids: dict[str, dict] = {}
        self.links: list[str] = []
        self.tables: list[dict] = []
        self._cell = None
        self._open_ids: list[str] = []
        self.feed(text)

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        for key in ("href", "src"):
            if key in a:
                self.links.append(a[key])
        if "id" in a:
            self.ids[a["id"]] = {"attrs": a, "text": "", "tag": tag}
            self._open_ids.append(a["id"])
        if tag == "table":
            self.tables.append({"class": a.get("class", "").split(), "rows": []})
        elif tag == "tr" and self.tables:
            self.tables[-1]["rows"].append([])
        elif tag in ("td", "th") and self.tables and self.tables[-1]["rows"]:
            self._cell = {"class": a.get("class", "").split(), "text": "", "attrs": [a], "tag": tag}
            self.tables[-1]["rows"][-1].append(self._cell)
        elif self._cell is not None:
            self._cell["attrs"].append(a)

    def handle_endtag(self, tag):
        if tag in ("td", "th"):
            self._cell = None
        if self._open_ids and self.ids[self._open_ids[-1]]["tag"] == tag:
            self._open_ids.pop()

    def handle_data(self, data):
        if self._cell is not None:
            self._cell["text"] += data
        for i in self._open_ids:
            self.ids[i]["text"] += data

    def table(self, cls: str) -> list[dict]:
        return [t for t in self.tables if cls in t["class"]]


def _num(text: str):
    t = text.strip().replace("−", "-")
    if t == "—":
        return None
    if t.endswith("∞"):
        return -math.inf if t.startswith("-") else math.inf
    return float(t)


def broken_links(folder: Path, page: Page) -> list[str]:
    """The links of the page ``folder/documentation/index.html`` that resolve neither to an id of
    the page, nor to a file inside ``folder``, nor are https:// links."""
    doc, bad = folder / datasheet.PAGE, []
    for link in page.links:
        if link.startswith("#"):
            ok = link[1:] in page.ids
        elif link.startswith("https://"):
            ok = True
        else:
            target = (doc.parent / link).resolve()
            ok = ("://" not in link and not link.startswith("/") and target.is_file()
                  and folder.resolve() in target.parents)
        if not ok:
            bad.append(link)
    return bad


@pytest.fixture(scope="module")
def sheets(built_fmus, tmp_path_factory):
    """{(name, backend): (unzipped folder, Page, model description root, design/plant data, spec)}."""
    out = {}
    for name, backend in CASES:
        fmu = built_fmus.get(name, backend)
        folder = tmp_path_factory.mktemp(f"sheet_{name}_{backend}")
        with zipfile.ZipFile(fmu) as z:
            z.extractall(folder)
        kind = packaging.OBSERVERS.get(name) or packaging.PLANTS[name]
        data = json.loads((folder / "resources" / f"{name}.{kind.data_kind}.json").read_text())
        spec = import_module(f"latobs.fmu_src.models.{kind.model_module}").SPEC
        page = Page((folder / datasheet.PAGE).read_text(encoding="utf-8"))
        out[(name, backend)] = (folder, page, ET.parse(folder / "modelDescription.xml").getroot(), data, spec)
    return out


IDS = [f"{n}[{b}]" for n, b in CASES]


def _page_variables(page: Page) -> dict[str, dict]:
    rows = {}
    for table in page.table("variables"):
        for row in table["rows"][1:]:
            cells = {c["class"][0] if c["class"] else f"col{k}": c for k, c in enumerate(row)}
            name = cells["col0"]["text"].strip()
            assert name not in rows, f"{name} listed twice"
            rows[name] = {"unit": cells["unit"]["text"].strip(), "causality": cells["causality"]["text"].strip(),
                          "min": _num(row[4]["text"]), "max": _num(row[5]["text"]), "start": row[6]["text"].strip(),
                          "description": cells["description"]["text"], "sign": cells["sign"]["text"],
                          "sensor": cells["sensor"]["text"]}
    return rows


@pytest.mark.parametrize("case", CASES, ids=IDS)
def test_every_variable_listed_with_its_unit_range_and_text(sheets, case):
    folder, page, md, data, spec = sheets[case]
    listed = _page_variables(page)
    declared = md.findall("./ModelVariables/ScalarVariable")
    assert sorted(sv.get("name") for sv in declared) == sorted(listed), "the page lists the model description's " \
                                                                       "variables, each once"
    for sv in declared:
        name, typed = sv.get("name"), sv[0]
        row = listed[name]
        assert row["unit"] == typed.get("unit", "1"), f"{name}: unit {row['unit']!r} on the page, " \
                                                      f"{typed.get('unit')!r} in modelDescription.xml"
        for key in ("min", "max"):
            x = typed.get(key)
            if x is None:
                assert row[key] is None, f"{name}: {key} {row[key]} on the page, none declared"
            else:
                assert row[key] == pytest.approx(float(x), rel=1e-5, abs=1e-12), f"{name}: {key}"
        if typed.get("start") is not None:
            assert float(row["start"]) == pytest.approx(float(typed.get("start")), rel=1e-5, abs=1e-12), name
        # the model description's text is the page's description, sign convention and sensor, joined
        text = "; ".join([row["description"]] + [row[k] if k == "sign" else f"from: {row[k]}"
                                                 for k in ("sign", "sensor") if row[k] != "—"])
        if row["unit"] != "1" and not name.startswith("der("):
            text += f" [{row['unit']}]"
        assert sv.get("description") == text, name
    # every physical input states its sign convention, every observer input its sensor
    for v in spec.inputs:
        assert listed[v.name]["sign"] != "—" or v.unit == "1", f"{v.name}: no sign convention"
        if data.get("checks") is not None:
            assert listed[v.name]["sensor"] != "—", f"{v.name}: no sensor"


@pytest.mark.parametrize("case", CASES, ids=IDS)
def test_step_certificate_platforms_and_paper_as_declared(sheets, case):
    folder, page, md, data, spec = sheets[case]
    step = float(page.ids["max-step"]["attrs"]["data-value"])
    assert step == max_step(spec, data)
    assert step == float(md.find("./VendorAnnotations/Tool[@name='latobs']/CommunicationStep").get("max"))
    platforms = sorted(p.name for p in (folder / "binaries").iterdir())
    assert sorted(li.strip() for li in page.ids["platform-list"]["text"].split()) == [f"binaries/{p}" for p in platforms]
    assert page.ids["license"]["text"] == md.get("license") == "MIT"
    if spec.paper is not None:
        assert spec.paper.title in "".join(page.ids["paper"]["text"].split("\n"))
        assert str(spec.paper.year) in page.ids["paper"]["text"]
    if case[0] in packaging.PLANTS:
        assert "certified" not in page.ids and not page.table("checks")
        return
    checks = data["checks"]
    assert int(page.ids["checks-count"]["text"]) == len(checks) > 0
    assert int(page.ids["checks-passed"]["text"]) == sum(c["passed"] for c in checks)
    assert page.ids["certified"]["text"] == ("yes" if data["certified"] and all(c["passed"] for c in checks) else "no")
    (table,) = page.table("checks")
    rows = table["rows"][1:]
    assert [r[1]["text"].startswith(c["name"]) for r, c in zip(rows, checks)] == [True] * len(checks)
    assert [r[-1]["text"] == "pass" for r in rows] == [bool(c["passed"]) for c in checks]
    assert float(page.ids["fig-gamma"]["attrs"]["data-value"]) == data["gamma"]


@pytest.mark.parametrize("case", CASES, ids=IDS)
def test_links_resolve_and_icon_is_a_png(sheets, case):
    folder, page, md, data, spec = sheets[case]
    assert "../model.png" in page.links and "#certificate" in page.links
    assert broken_links(folder, page) == []
    text = (folder / datasheet.PAGE).read_text(encoding="utf-8")
    assert not [w for w in ("../shared", "shared/reference", "CONTRACT", "ERRATA.md") if w in text]
    raw = (folder / datasheet.ICON).read_bytes()
    assert raw[:8] == b"\x89PNG\r\n\x1a\n" and raw[12:16] == b"IHDR"
    assert struct.unpack(">II", raw[16:24]) == (datasheet.SIZE, datasheet.SIZE)


def test_broken_links_are_found(tmp_path):
    """The link check is not vacuous: a missing anchor or file, a path leaving the FMU, plain http."""
    (tmp_path / "documentation").mkdir()
    (tmp_path / "model.png").write_bytes(b"")
    (tmp_path.parent / "outside.png").write_bytes(b"")
    page = Page('<h2 id="here">x</h2><a href="#here">ok</a><a href="#nowhere">x</a><img src="../model.png">'
                '<img src="../missing.png"><img src="../../outside.png"><a href="http://example.org/">x</a>'
                '<a href="https://fmi-standard.org/">ok</a>')
    assert broken_links(tmp_path, page) == ["#nowhere", "../missing.png", "../../outside.png", "http://example.org/"]


def _chromium() -> str | None:
    return shutil.which("chromium") or (("/usr/bin/chromium") if os.access("/usr/bin/chromium", os.X_OK) else None)


@pytest.mark.parametrize("case", [CASES[0], CASES[3]], ids=[IDS[0], IDS[3]])
def test_page_renders_in_headless_chromium(sheets, case, tmp_path):
    exe = _chromium()
    if exe is None:
        if shutil.which("apt-get") is None:
            pytest.skip("chromium is not installed and apt-get is unavailable to install it")
        pytest.fail("chromium is not installed: .ci/run installs it (apt-get install chromium, as root)")
    folder = sheets[case][0]
    shot = tmp_path / "shot.png"
    cmd = [exe, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
           "--disable-background-networking", "--disable-component-update", "--disable-sync",
           f"--user-data-dir={tmp_path / 'profile'}", f"--screenshot={shot}", "--window-size=1200,2000",
           (folder / datasheet.PAGE).resolve().as_uri()]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert shot.is_file() and shot.stat().st_size > 0, proc.stderr[-2000:]
    import matplotlib.image

    img = matplotlib.image.imread(str(shot))
    assert img.shape[:2] == (2000, 1200), img.shape
    colours = np.unique((img[..., :3] * 255).round().astype(np.uint8).reshape(-1, 3), axis=0)
    assert len(colours) > 50, f"the screenshot has {len(colours)} colour(s): nothing rendered"
