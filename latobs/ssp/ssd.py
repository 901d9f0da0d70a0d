"""The XML of an SSP 1.0 package: the system structure description (SSD) and the parameter sets (SSV).

A package (``latobs export-ssp``) holds::

    SystemStructure.ssd             the system: components, connectors, connections, units, the
                                    experiment (start, stop, fixed step)
    resources/ScenarioSignals.fmu   the scenario's input signals (plant inputs), sampled on the
                                    harness's time grid (:mod:`latobs.ssp.source`)
    resources/<plant>.fmu           the plant FMU (CarPlant, MotorcyclePlant, ``_V`` builds)
    resources/<observer>.fmu        each observer FMU, as built
    resources/<component>.ssv       one SSV parameter set per plant and observer: every parameter
                                    of the FMU (the given plant parameters, the others at their
                                    start values), bound with ``ssd:ParameterBinding source=...``

``ssd:DefaultExperiment`` holds start and stop time, and its ``com.opensimulationplatform``
annotation ``osp:FixedStepAlgorithm baseStepSize`` the communication step that libcosim's SSP
loader reads (SSP 1.0 itself has no step size).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping

from .interface import LATOBS_ANNOTATION, NS, OSP_ANNOTATION, Connection, FmuInterface, FmuVar


def _xml_bytes(root) -> bytes:
    from lxml import etree

    return etree.tostring(root, pretty_print=True, xml_declaration=True, encoding="UTF-8")


def _num(x: float) -> str:
    x = float(x)
    return str(int(x)) if x.is_integer() and abs(x) < 1e15 else repr(x)


def _base_unit_attrs(exps: Mapping[str, float]) -> dict[str, str]:
    out = {}
    for k, v in exps.items():
        if k in ("factor", "offset"):
            if float(v) != (1.0 if k == "factor" else 0.0):
                out[k] = repr(float(v))
        elif v:
            out[k] = str(int(v))
    return out



def _q(prefix: str, tag: str) -> str:
    return f"{{{NS[prefix]}}}{tag}"


def _type_element(parent, prefix: str, typ: str, attrs: Mapping[str, str] | None = None):
    from lxml import etree

    return etree.SubElement(parent, _q(prefix, typ), dict(attrs or {}))


def _units_element(parent, prefix: str, units: Mapping[str, dict]):
    from lxml import etree

    if not units:
        return
    el = etree.SubElement(parent, _q(prefix, "Units"))
    for name in sorted(units):
        u = etree.SubElement(el, _q("ssc", "Unit"), name=name)
        etree.SubElement(u, _q("ssc", "BaseUnit"), _base_unit_attrs(units[name]))


def ssv_bytes(name: str, params: list[tuple[FmuVar, Any]], unit_defs: Mapping[str, dict]) -> bytes:
    """An SSV 1.0 parameter set: one ``ssv:Parameter`` per (variable, value), units declared."""
    from lxml import etree

    root = etree.Element(_q("ssv", "ParameterSet"), nsmap={k: NS[k] for k in ("ssv", "ssc")},
                         version="1.0", name=name)
    ps = etree.SubElement(root, _q("ssv", "Parameters"))
    used = {}
    for var, value in params:
        p = etree.SubElement(ps, _q("ssv", "Parameter"), name=var.name)
        if var.type == "Real":
            attrs = {"value": repr(float(value))}
            if var.unit and var.unit in unit_defs:
                attrs["unit"] = var.unit
                used[var.unit] = unit_defs[var.unit]
        elif var.type == "Integer":
            attrs = {"value": str(int(value))}
        elif var.type == "Boolean":
            attrs = {"value": "true" if value else "false"}
        else:
            attrs = {"value": str(value)}
        _type_element(p, "ssv", var.type, attrs)
    _units_element(root, "ssv", used)
    return _xml_bytes(root)


@dataclass
class Component:
    label: str
    source: str                        # archive path of the FMU
    fmu: FmuInterface
    inputs: list[str]                  # connected input connectors
    ssv: str | None = None             # archive path of its parameter set


def ssd_bytes(system_name: str, description: str, components: list[Component], connections: list[Connection],
              start: float, stop: float, dt: float, info: Mapping[str, str]) -> bytes:
    from lxml import etree

    from .. import __version__

    root = etree.Element(_q("ssd", "SystemStructureDescription"),
                         nsmap={k: NS[k] for k in ("ssd", "ssc", "osp", "latobs")},
                         version="1.0", name=system_name, description=description,
                         generationTool=f"latobs {__version__} export-ssp", author="latobs", license="MIT")
    system = etree.SubElement(root, _q("ssd", "System"), name=system_name)
    elements = etree.SubElement(system, _q("ssd", "Elements"))
    units: dict[str, dict] = {}
    for c in components:
        comp = etree.SubElement(elements, _q("ssd", "Component"), name=c.label, source=c.source,
                                type="application/x-fmu-sharedlibrary", implementation="CoSimulation")
        conns = etree.SubElement(comp, _q("ssd", "Connectors"))
        for var in [*(c.fmu.var(n) for n in c.inputs), *c.fmu.outputs]:
            el = etree.SubElement(conns, _q("ssd", "Connector"), name=var.name, kind=var.causality)
            attrs = {}
            if var.type == "Real" and var.unit and var.unit in c.fmu.units:
                attrs["unit"] = var.unit
                units[var.unit] = c.fmu.units[var.unit]
            _type_element(el, "ssc", var.type, attrs)
        if c.ssv:
            pb = etree.SubElement(comp, _q("ssd", "ParameterBindings"))
            etree.SubElement(pb, _q("ssd", "ParameterBinding"), source=c.ssv)
    cs = etree.SubElement(system, _q("ssd", "Connections"))
    for c in connections:
        etree.SubElement(cs, _q("ssd", "Connection"), startElement=c.start_element,
                         startConnector=c.start_connector, endElement=c.end_element, endConnector=c.end_connector)
    _units_element(root, "ssd", units)
    de = etree.SubElement(root, _q("ssd", "DefaultExperiment"), startTime=_num(start), stopTime=_num(stop))
    an = etree.SubElement(etree.SubElement(de, _q("ssd", "Annotations")), _q("ssc", "Annotation"),
                          type=OSP_ANNOTATION)
    alg = etree.SubElement(an, _q("osp", "Algorithm"))
    etree.SubElement(alg, _q("osp", "FixedStepAlgorithm"), baseStepSize=repr(float(dt)))
    an = etree.SubElement(etree.SubElement(root, _q("ssd", "Annotations")), _q("ssc", "Annotation"),
                          type=LATOBS_ANNOTATION)
    etree.SubElement(an, _q("latobs", "Export"), dict(info))
    return _xml_bytes(root)
