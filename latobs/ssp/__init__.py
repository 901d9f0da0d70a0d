"""SSP 1.0 packages of the validation scenarios (``latobs export-ssp``), and running one in fmpy.

An SSP package (a zip, ``.ssp``) is the co-simulation that ``latobs validate SCENARIO`` runs, in the
form other tools (libcosim, fmpy) read. The modules follow the package's seams:

* :mod:`~latobs.ssp.interface`: what the export reads of an FMU, the wiring, names and constants;
* :mod:`~latobs.ssp.source`: the signal-source FMU (the scenario's signals, a native C model);
* :mod:`~latobs.ssp.ssd`: the XML of the system description (SSD) and parameter sets (SSV);
* :mod:`~latobs.ssp.check`: the schema and structure checks, and readers of a package;
* :mod:`~latobs.ssp.export`: :func:`export_ssp`, the command;
* :mod:`~latobs.ssp.run`: a package run in fmpy, and compared with the harness.
"""
from .check import check_package, connections_of, experiment_of, pyssp_compliance, read_ssd_tree
from .export import default_observers, export_ssp
from .interface import (DEFAULT_DT, LATOBS_ANNOTATION, NS, OSP_ANNOTATION, PLANT_LABEL, SOURCE_LABEL, SOURCE_MODEL,
                        SSD_NAME, TIMING, Connection, FmuInterface, FmuVar, SspError, scenario_signals, wiring)
from .run import compare, fmpy_equivalent, harness_trace, simulate_fmpy
from .source import build_source_fmu, signal_data
from .ssd import Component, ssd_bytes, ssv_bytes

__all__ = ["DEFAULT_DT", "LATOBS_ANNOTATION", "NS", "OSP_ANNOTATION", "PLANT_LABEL", "SOURCE_LABEL", "SOURCE_MODEL",
           "SSD_NAME", "TIMING", "Component", "Connection", "FmuInterface", "FmuVar", "SspError", "build_source_fmu",
           "check_package", "compare", "connections_of", "default_observers", "experiment_of", "export_ssp",
           "fmpy_equivalent", "harness_trace", "pyssp_compliance", "read_ssd_tree", "scenario_signals",
           "signal_data", "simulate_fmpy", "ssd_bytes", "ssv_bytes", "wiring"]
