"""The FMUs of an SSP package as the system description sees them, and how they are wired.

:class:`FmuInterface` reads what the export needs of a built FMU (its inputs, outputs, parameters
and units, from its model description); :func:`wiring` connects them by the rule of
``latobs validate`` (:mod:`latobs.validation.harness`): the plant's inputs from the signal source's
outputs of the same names (an optional plant input the scenario does not drive, such as CarPlant's
``stiffness_scale_f/r``, stays unconnected at its start value), each observer input from the plant
output of the same name, else from the signal source. Also the package's names and constants.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np

SSD_NAME = "SystemStructure.ssd"
SOURCE_MODEL = "ScenarioSignals"      # model identifier of the signal-source FMU
SOURCE_LABEL = "signals"              # its component name in the SSD
PLANT_LABEL = "plant"                 # as the harness labels the plant
DEFAULT_DT = 0.005                    # s, the harness's communication step (latobs validate)
NS = {
    "ssd": "http://ssp-standard.org/SSP1/SystemStructureDescription",
    "ssc": "http://ssp-standard.org/SSP1/SystemStructureCommon",
    "ssv": "http://ssp-standard.org/SSP1/SystemStructureParameterValues",
    "osp": "http://opensimulationplatform.com/SSP/OSPAnnotations",
    "latobs": "urn:latobs:ssp:1",
}
OSP_ANNOTATION = "com.opensimulationplatform"
LATOBS_ANNOTATION = "org.latobs.export"
TIMING = ("Jacobi fixed step: every FMU steps from t_k with its inputs at t_k (plant: the scenario "
          "signals u(t_k); observers: the plant outputs at t_k), then outputs are copied to inputs. "
          "The signal source outputs after its step from t_k the sample of t_(k+1).")


class SspError(RuntimeError):
    """A user-facing failure of the export (the message names the culprit)."""


# ------------------------------------------------------------------------------------------------
# what the export needs of an FMU
# ------------------------------------------------------------------------------------------------
@dataclass
class FmuVar:
    name: str
    type: str              # Real, Integer, Boolean, String
    causality: str
    unit: str | None = None
    start: Any = None
    min: float | None = None
    max: float | None = None


@dataclass
class FmuInterface:
    """The variables of a built FMU that the SSD refers to (from its modelDescription.xml)."""

    path: Path
    model_name: str
    inputs: list[FmuVar] = field(default_factory=list)
    outputs: list[FmuVar] = field(default_factory=list)
    parameters: list[FmuVar] = field(default_factory=list)
    units: dict[str, dict[str, float]] = field(default_factory=dict)   # unit -> base-unit exponents

    @classmethod
    def read(cls, path: Path, label: str) -> "FmuInterface":
        from fmpy import read_model_description

        try:
            md = read_model_description(str(path))
        except Exception as exc:
            raise SspError(f"{label} ({path}): cannot read its modelDescription.xml: {exc}") from exc
        if md.coSimulation is None:
            raise SspError(f"{label} ({path.name}) has no co-simulation interface")
        me = cls(Path(path), md.modelName)
        for v in md.modelVariables:
            typ = v.type
            if v.causality not in ("input", "output", "parameter"):
                continue
            if typ == "Enumeration":
                raise SspError(f"{label} ({path.name}): variable {v.name!r} is an Enumeration, which libcosim's "
                               "SSP loader cannot connect")
            unit = getattr(v, "unit", None) or getattr(getattr(v, "declaredType", None), "unit", None)
            lo, hi = (None if b in (None, "") else float(b) for b in (getattr(v, "min", None), getattr(v, "max", None)))
            var = FmuVar(v.name, typ, v.causality, unit or None, v.start, lo, hi)
            {"input": me.inputs, "output": me.outputs, "parameter": me.parameters}[v.causality].append(var)
        for u in md.unitDefinitions:
            b = u.baseUnit
            me.units[u.name] = ({k: getattr(b, k) for k in ("kg", "m", "s", "A", "K", "mol", "cd", "rad",
                                                           "factor", "offset")} if b is not None else {})
        return me

    def var(self, name: str) -> FmuVar | None:
        return next((v for v in (*self.inputs, *self.outputs, *self.parameters) if v.name == name), None)

    def start_values(self) -> dict[str, Any]:
        return {p.name: _typed(p.type, p.start) for p in self.parameters}


def _typed(typ: str, value):
    if value is None:
        return None
    if typ == "Real":
        return float(value)
    if typ == "Integer":
        return int(value)
    if typ == "Boolean":
        return value if isinstance(value, bool) else str(value).strip().lower() in ("true", "1")
    return str(value)


# ------------------------------------------------------------------------------------------------
# wiring (the harness's rule)
# ------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Connection:
    start_element: str
    start_connector: str
    end_element: str
    end_connector: str


def scenario_signals(scenario, t: np.ndarray, vehicle) -> dict[str, np.ndarray]:
    """The scenario's signals and parameter signals on the grid t, as the harness samples them."""
    try:
        return scenario.sampled(t, vehicle)
    except ValueError as exc:
        raise SspError(str(exc)) from None


def wiring(scenario, signal_names, plant: FmuInterface, observers: Mapping[str, FmuInterface]) -> list[Connection]:
    """The connections of the harness (:mod:`latobs.validation.harness`, "Wiring"): plant inputs
    from the scenario signals (an optional plant input the scenario does not drive stays
    unconnected, at its start value), each observer input from the plant output of that name,
    else from the scenario signal of that name."""
    signal_names = list(signal_names)
    optional = set(getattr(scenario, "optional_plant_inputs", ()))
    conns = []
    missing = [v.name for v in plant.inputs if v.name not in signal_names and v.name not in optional]
    if missing:
        raise SspError(f"plant {plant.model_name}: input(s) {', '.join(repr(m) for m in missing)} not provided by "
                       f"scenario {scenario.name!r} (it provides {', '.join(sorted(signal_names))})")
    for v in plant.inputs:
        if v.name in signal_names:
            conns.append(Connection(SOURCE_LABEL, v.name, PLANT_LABEL, v.name))
    plant_out = {v.name for v in plant.outputs}
    for label, f in observers.items():
        for v in f.inputs:
            if v.name in plant_out:
                conns.append(Connection(PLANT_LABEL, v.name, label, v.name))
            elif v.name in signal_names:
                conns.append(Connection(SOURCE_LABEL, v.name, label, v.name))
            else:
                raise SspError(f"observer {label} ({f.path.name}): input {v.name!r} has no signal: neither a "
                               f"{plant.model_name} output nor a signal of scenario {scenario.name!r}")
    return conns
