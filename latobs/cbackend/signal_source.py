"""Emitter of the native ScenarioSignals (``fmu_src/c/signal_source.c``): the signal table as data.

The data file (``fmu_src/models/signal_source.py``) becomes ``model_data.h``: the grid's start
time and step and every sample as exact double literals, so that the FMU plays back the values
the scenario computed, bit for bit.
"""
from __future__ import annotations

from .emit import CModel, c_array, c_define

SOURCE = "signal_source.c"


def emit(data: dict) -> CModel:
    """``model_data.h`` of the signal source for the data file ``data`` (checked beforehand by
    the model file's ``SignalTable``)."""
    rows = [[float(x) for x in row] for row in data["rows"]]
    label = repr(str(data.get("scenario", "?"))).replace("*/", "* /")   # inside a C comment
    header = (f"/* ScenarioSignals of scenario {label}: {len(rows)} samples of "
              f"{', '.join(s['name'] for s in data['signals'])} */\n"
              + c_define("SS_T0", float(data["t0"])) + c_define("SS_DT", float(data["dt"]))
              + c_define("SS_N_ROWS", len(rows)) + c_array("SS_TABLE", rows))
    return CModel(header=header)
