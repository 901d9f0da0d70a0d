"""Co-simulation of a plant FMU and observer FMUs with fmpy, wired by variable name: the public
entry points of the validation harness.

Only the built FMUs are used, through fmpy's FMI 2.0 co-simulation API; the FMUs' Python internals
are never imported. :mod:`.instance` loads and drives one FMU, :mod:`.master` steps them together;
docs/validation.md describes the signal bus, the wiring, the measurement model and the timing.
"""
from __future__ import annotations

from .instance import (
    MAX_LOG_MESSAGES,
    CoSimulationError,
    FmuInstance,
    WiringError,
    _unit_of,
    design_summary,
    observer_design,
    read_fmu_design,
)
from .master import PLANT_LABEL, CoSimulation, NoiseSpec, SimResult, run

__all__ = ["MAX_LOG_MESSAGES", "PLANT_LABEL", "CoSimulation", "CoSimulationError", "FmuInstance", "NoiseSpec",
           "SimResult", "WiringError", "_unit_of", "design_summary", "observer_design", "read_fmu_design", "run"]
