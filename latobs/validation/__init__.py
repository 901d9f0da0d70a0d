"""Validation stage: co-simulate the built plant and observer FMUs with fmpy and score them.

    scenarios  manoeuvres (plant input signals) and their registry
    harness    fixed-step co-simulation wired by variable name (fmpy FMU2Slave)
    metrics    errors, interval enclosure, paper 000's ||beta err||/||bank|| ratio, mode occupancy,
               and the same errors for the baselines beside each observer
    baselines  simple estimates on the same signals: zero, the open-loop linear bicycle (cars),
               the steady turn (motorcycles); pure numpy/scipy
    plots      PNG figures (Agg canvas)
    report     index.md with the tables and figures (observer beside its baselines)
    replay     recorded signals through an observer FMU, scored like the co-simulations

Only the built FMUs are driven; the FMUs' Python sources (latobs.fmu_src) are never imported.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Callable, Mapping

from .scenarios import SCENARIOS, Scenario, get_scenario, scenario_names

__all__ = ["SCENARIOS", "Scenario", "get_scenario", "scenario_names", "validate"]


def validate(scenario: Scenario | str, plant_fmu: str | os.PathLike,
             observer_fmus: Mapping[str, str | os.PathLike], out_dir: str | os.PathLike,
             plots: bool | Callable[[Any, Path], Any] = True, sink: Any = None,
             **run_kwargs: Any) -> tuple[Any, dict, list[Path]]:
    """Run the co-simulation, write ``out_dir/metrics.json`` and the PNG plots (unless ``plots``
    is false: matplotlib is then not even imported). A run of more than
    :func:`latobs.validation.master.stream_steps` steps is streamed (:class:`latobs.validation.stream.CosimSink`):
    its rows in ``out_dir/outputs.parquet``, its metrics summed over the blocks, the figures of every
    k-th sample, the returned SimResult holding those samples only (``sink``: that CosimSink, writing
    into ``out_dir``, when the caller wants more of it, e.g. the campaign's flat metrics). ``plots``
    may instead be a callable ``plots(result, out_dir)`` that draws them elsewhere (the demo's worker processes): the PNGs
    are then not among the paths returned.

    ``run_kwargs`` go to :func:`latobs.validation.harness.run` (dt, noise, seed,
    plant_parameters, vehicle, progress, observer_parameters). Returns (SimResult, metrics dict,
    [paths written: metrics.json first, then the PNGs]).
    """
    from . import harness, metrics, stream

    out = Path(out_dir)
    # a long run (more than master.stream_steps() steps) is stepped in blocks, its rows written to
    # out/outputs.parquet and its metrics summed over the blocks (stream.CosimSink)
    sink = sink if sink is not None else stream.CosimSink(out, keep=bool(plots))
    with sink:
        result = harness.run(scenario, plant_fmu, observer_fmus, sink=sink, **run_kwargs)
        m = sink.metrics(result) if sink.used else metrics.compute(result)
        paths = [metrics.write(m, out)]
    if sink.used:
        paths.append(sink.outputs_path)
    if callable(plots):
        plots(result, out)
    elif plots:
        from . import plots as plotting

        paths += plotting.plot_all(result, out)
    return result, m, paths
