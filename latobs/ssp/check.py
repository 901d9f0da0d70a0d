"""Checks of an SSP package, run before one is written (nothing invalid is ever written).

:func:`check_package`: the SSD and every SSV against the SSP 1.0 XML schemas (fmpy's copy, through
lxml, always; pyssp-standard's validator too when it is installed), and the structure against the
FMUs' model descriptions (every connector a variable of its FMU with the same causality and type,
every connection output -> input of one type, every input connector connected exactly once, every
bound parameter a parameter of its FMU). Also the readers of a package (connections, experiment).
"""
from __future__ import annotations

import math
import tempfile
import zipfile
from pathlib import Path
from typing import Any

from .interface import NS, SSD_NAME, Connection, FmuInterface, SspError


def _schema_problems(xml: bytes, schema: str, what: str) -> list[str]:
    """Validate against the SSP 1.0 XSD ``schema`` (file name): fmpy's copy through lxml, and
    pyssp-standard's (xmlschema, XSD 1.0; for the SSD also its XSD 1.1 variant with assertions)
    when pyssp-standard is installed."""
    from lxml import etree

    import fmpy

    problems = []
    xsd = etree.XMLSchema(etree.parse(str(Path(fmpy.__file__).parent / "ssp" / "schema" / schema)))
    try:
        doc = etree.fromstring(xml)
    except etree.XMLSyntaxError as exc:
        return [f"{what}: not well-formed XML: {exc}"]
    if not xsd.validate(doc):
        problems += [f"{what}: line {e.line}: {e.message}" for e in xsd.error_log]
    for key in _pyssp_schemas(schema):
        s = _xmlschema(key)
        problems += [f"{what} (pyssp-standard {key}): {e.reason or e.message}" for e in s.iter_errors(xml.decode())]
    return problems


def _pyssp_schemas(schema: str) -> tuple[str, ...]:
    """The pyssp-standard schema keys for ``schema``; none when pyssp-standard is not installed
    (it is a test extra; fmpy's copy of the same XSDs is always used)."""
    from importlib.util import find_spec

    if find_spec("pyssp_standard") is None:
        return ()
    return {"SystemStructureDescription.xsd": ("ssd", "ssd11"),
            "SystemStructureParameterValues.xsd": ("ssv",)}.get(schema, ())


_SCHEMAS: dict[str, Any] = {}


def _xmlschema(key: str):
    if key not in _SCHEMAS:
        import xmlschema
        from pyssp_standard.standard import ModelicaStandard

        path = str(ModelicaStandard.schemas[key])
        _SCHEMAS[key] = (xmlschema.XMLSchema11 if "11" in key else xmlschema.XMLSchema10)(path)
    return _SCHEMAS[key]


def pyssp_compliance(ssd_path: Path) -> None:
    """pyssp-standard's own compliance check of an SSD file (raises on a violation)."""
    from pyssp_standard.ssd import SSD

    SSD(ssd_path, "r").__check_compliance__()


def read_ssd_tree(ssp: Path):
    from lxml import etree

    with zipfile.ZipFile(ssp) as z:
        return etree.fromstring(z.read(SSD_NAME))


def connections_of(ssp: Path) -> list[Connection]:
    root = read_ssd_tree(ssp)
    return [Connection(c.get("startElement"), c.get("startConnector"), c.get("endElement"), c.get("endConnector"))
            for c in root.iterfind("ssd:System/ssd:Connections/ssd:Connection", NS)]


def experiment_of(ssp: Path) -> tuple[float, float, float]:
    """(start, stop, step) in s: ssd:DefaultExperiment and its osp:FixedStepAlgorithm baseStepSize."""
    root = read_ssd_tree(ssp)
    de = root.find("ssd:DefaultExperiment", NS)
    alg = root.find("ssd:DefaultExperiment/ssd:Annotations/ssc:Annotation/osp:Algorithm/osp:FixedStepAlgorithm", NS)
    if de is None or alg is None or de.get("stopTime") is None:
        raise SspError(f"{ssp}: no ssd:DefaultExperiment with a stopTime and an osp:FixedStepAlgorithm")
    return float(de.get("startTime", 0.0)), float(de.get("stopTime")), float(alg.get("baseStepSize"))


def check_package(ssp: Path) -> list[str]:
    """Every problem of the package ``ssp`` (empty list: valid). See the module docstring."""
    problems: list[str] = []
    try:
        z = zipfile.ZipFile(ssp)
    except (OSError, zipfile.BadZipFile) as exc:
        return [f"{ssp}: not a zip archive: {exc}"]
    with z, tempfile.TemporaryDirectory(prefix="latobs_ssp_check_") as tmp:
        names = set(z.namelist())
        if SSD_NAME not in names:
            return [f"{ssp}: no {SSD_NAME}"]
        ssd = z.read(SSD_NAME)
        problems += _schema_problems(ssd, "SystemStructureDescription.xsd", SSD_NAME)
        if _pyssp_schemas("SystemStructureDescription.xsd"):
            (Path(tmp) / SSD_NAME).write_bytes(ssd)
            try:
                pyssp_compliance(Path(tmp) / SSD_NAME)
            except Exception as exc:
                problems.append(f"{SSD_NAME}: pyssp-standard compliance: {exc}")
        if problems:
            return problems
        from lxml import etree

        root = etree.fromstring(ssd)
        fmus: dict[str, FmuInterface] = {}
        kinds: dict[tuple[str, str], tuple[str, str]] = {}       # (element, connector) -> (kind, type)
        for comp in root.iterfind("ssd:System/ssd:Elements/ssd:Component", NS):
            label, src = comp.get("name"), comp.get("source")
            if src not in names:
                problems.append(f"component {label}: source {src!r} is not in the archive")
                continue
            target = Path(tmp) / f"{len(fmus)}.fmu"
            target.write_bytes(z.read(src))
            try:
                f = fmus[label] = FmuInterface.read(target, label)
            except SspError as exc:
                problems.append(str(exc))
                continue
            for con in comp.iterfind("ssd:Connectors/ssd:Connector", NS):
                var = f.var(con.get("name"))
                typ = next((etree.QName(ch).localname for ch in con
                            if etree.QName(ch).namespace == NS["ssc"]), None)
                if var is None or var.causality != con.get("kind") or var.type != typ:
                    problems.append(f"component {label}: connector {con.get('name')!r} ({con.get('kind')}, {typ}) "
                                    f"is not a variable of {src} with that causality and type")
                    continue
                kinds[(label, var.name)] = (var.causality, var.type)
            for pb in comp.iterfind("ssd:ParameterBindings/ssd:ParameterBinding", NS):
                ssv_src = pb.get("source")
                if ssv_src not in names:
                    problems.append(f"component {label}: parameter set {ssv_src!r} is not in the archive")
                    continue
                ssv = z.read(ssv_src)
                found = _schema_problems(ssv, "SystemStructureParameterValues.xsd", ssv_src)
                problems += found
                if found:
                    continue
                for p in etree.fromstring(ssv).iterfind("ssv:Parameters/ssv:Parameter", NS):
                    var = f.var(p.get("name"))
                    typ = etree.QName(p[0]).localname if len(p) else None
                    if var is None or var.causality != "parameter" or var.type != typ:
                        problems.append(f"{ssv_src}: {p.get('name')!r} ({typ}) is not a {typ} parameter of {src}")
        ends: dict[tuple[str, str], int] = {}
        for c in root.iterfind("ssd:System/ssd:Connections/ssd:Connection", NS):
            a = (c.get("startElement"), c.get("startConnector"))
            b = (c.get("endElement"), c.get("endConnector"))
            ka, kb = kinds.get(a), kinds.get(b)
            if ka is None or kb is None or ka[0] != "output" or kb[0] != "input" or ka[1] != kb[1]:
                problems.append(f"connection {'.'.join(map(str, a))} -> {'.'.join(map(str, b))}: not an output -> "
                                f"input connection of one type between declared connectors")
            ends[b] = ends.get(b, 0) + 1
        for key, (kind, _) in kinds.items():
            if kind == "input" and ends.get(key, 0) != 1:
                problems.append(f"input connector {'.'.join(key)} is connected {ends.get(key, 0)} times (must be 1)")
        try:
            start, stop, dt = experiment_of(ssp)
            if not (math.isfinite(stop) and stop > start and dt > 0):
                problems.append(f"experiment: start {start}, stop {stop}, step {dt} are not a run")
        except (SspError, TypeError, ValueError) as exc:
            problems.append(str(exc))
    return problems
