"""The signal source of an SSP package: the scenario's input signals as a native FMU.

``ScenarioSignals`` is an ordinary native C model (model file ``fmu_src/models/signal_source.py``,
maths ``fmu_src/c/signal_source.c``, emitter ``latobs/cbackend/signal_source.py``) built by the
native C backend like every latobs FMU: one Real output per signal, the sample at or before the
current time (zero-order hold on the harness's uniform grid), so that after the step from t_k it
outputs the sample of t_(k+1). It is built for the platforms the package's plant FMU runs on.
"""
from __future__ import annotations

import zipfile
from pathlib import Path
from typing import Mapping

import numpy as np

from .interface import DEFAULT_DT, SOURCE_MODEL, SspError


def signal_data(scenario_name: str, t: np.ndarray, signals: Mapping[str, np.ndarray],
                units: Mapping[str, str | None]) -> dict:
    """The signal source's data file: the signals sampled on the uniform grid ``t`` (one row per
    time point), their units (``units``: signal name -> unit, e.g. the plant inputs')."""
    names = list(signals)
    return {"scenario": scenario_name, "t0": float(t[0]),
            "dt": float(t[1] - t[0]) if len(t) > 1 else DEFAULT_DT, "stop_time": float(t[-1]),
            "signals": [{"name": n, "unit": units.get(n)} for n in names],
            "rows": [[float(signals[n][k]) for n in names] for k in range(len(t))]}


def native_platforms(fmu: Path) -> list[str]:
    """The native platform folders (``latobs.cbackend.toolchain.PLATFORMS``) an FMU has binaries for."""
    from ..cbackend.toolchain import PLATFORMS

    with zipfile.ZipFile(fmu) as z:
        held = {n.split("/")[1] for n in z.namelist() if n.startswith("binaries/") and n.count("/") >= 2}
    return [p for p in PLATFORMS if p in held]


def build_source_fmu(scenario_name: str, t: np.ndarray, signals: Mapping[str, np.ndarray],
                     units: Mapping[str, str | None], out_dir: Path, platforms: list[str] | None = None) -> Path:
    """Build ``out_dir/ScenarioSignals.fmu`` (native C backend, for ``platforms``; None: all) playing
    back ``signals`` sampled on the uniform grid ``t``; returns its path. SspError when it cannot
    be built (no compiler for a platform, fmpy validate's problems)."""
    from ..cbackend import NativeBuildError, build_c_fmu
    from ..packaging import FmuKind, PackagingError

    kind = FmuKind(SOURCE_MODEL, "signal_source", "signals", "")
    try:
        return build_c_fmu(kind, SOURCE_MODEL, signal_data(scenario_name, t, signals, units), Path(out_dir),
                           platforms=platforms)
    except (NativeBuildError, PackagingError, ValueError) as exc:
        raise SspError(f"the signal-source FMU: {exc}") from exc
