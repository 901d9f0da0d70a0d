"""Running an SSP package in fmpy, and comparing a run with the harness's.

:func:`simulate_fmpy` runs a package with fmpy's SSP support, :func:`fmpy_equivalent` is the
scenario the harness runs the same way (fmpy starts every connection at 0.0), and
:func:`harness_trace` / :func:`compare` put a harness result beside a package's run.
"""
from __future__ import annotations

import tempfile
import zipfile
from pathlib import Path
from typing import Mapping

import numpy as np

from .check import experiment_of
from .interface import PLANT_LABEL, SOURCE_LABEL, FmuInterface, SspError, _typed


def simulate_fmpy(ssp: Path) -> dict[str, np.ndarray]:
    """Run the package with fmpy's SSP support (``fmpy.ssp.simulation.simulate_ssp``); returns
    {"time": t_1..t_n, "<component>.<output connector>": values at those times}.

    What ``simulate_ssp`` (fmpy 0.3) does and does not, and what is done about it here:

    * it takes stop time and step from its arguments, not from the SSD: they are read from
      ``ssd:DefaultExperiment`` and the ``osp:FixedStepAlgorithm`` annotation (:func:`experiment_of`).
      It advances time by repeated addition while ``time < stop``, so it is given
      ``stop - step/2`` to take exactly n steps;
    * it reads the SSD's ``ssd:ParameterBinding``s but does not apply them; it applies only its
      ``parameter_set`` argument, matching ``<component>.<name>`` to a component by a bare
      prefix (component ``A`` would take ``AB.x`` as a variable ``B.x`` of its own and fail). The
      bound values that differ from the FMUs' start values are passed in it (setting a start value
      again changes nothing); a prefix clash among those is refused with SspError;
    * it does not initialise inputs from connections: at initialisation every input keeps its
      start value, and in the first step every input is 0.0 (the harness and libcosim give the
      first step u(t_0) and the plant outputs at t_0); :func:`fmpy_equivalent` is the scenario
      that the harness runs the same way. The results therefore differ from the harness's from t_1 on by what one step
      with zero inputs does (see the README, "SSP export");
    * each row holds the connector values after the step from its time: the output at t_(k+1).
    """
    from fmpy.ssp.simulation import simulate_ssp
    from fmpy.ssp.ssd import Parameter, ParameterSet, read_ssd

    ssp = Path(ssp)
    start, stop, dt = experiment_of(ssp)
    desc = read_ssd(str(ssp))                        # validates against fmpy's SSP 1.0 schema
    pset = ParameterSet(name="bindings")
    with tempfile.TemporaryDirectory(prefix="latobs_ssp_fmpy_") as tmp, zipfile.ZipFile(ssp) as z:
        comps = [e for e in desc.system.elements if getattr(e, "source", None)]
        for i, comp in enumerate(comps):
            fmu = Path(tmp) / f"{i}.fmu"
            fmu.write_bytes(z.read(comp.source))
            f = FmuInterface.read(fmu, comp.name)
            start_values = f.start_values()
            for binding in comp.parameterBindings:
                for ps in binding.parameterValues:
                    for p in ps.parameters:
                        var = f.var(p.name)
                        if var is None:
                            continue
                        if _typed(var.type, p.value) != start_values.get(p.name):
                            pset.parameters.append(Parameter(name=f"{comp.name}.{p.name}", type=p.type,
                                                             value=p.value, unit=getattr(p, "unit", None)))
    names = [c.name for c in comps]
    for p in pset.parameters:
        owner = p.name.split(".", 1)[0]
        clash = [n for n in names if n != owner and owner.startswith(n)]
        if clash:
            raise SspError(f"fmpy's simulate_ssp would apply parameter {p.name} to component {clash[0]} (bare "
                           "prefix match): rename the components")
    n = int(round((stop - start) / dt))
    res = simulate_ssp(str(ssp), start_time=start, stop_time=start + (n - 0.5) * dt, step_size=dt,
                       parameter_set=pset)
    if len(res) != n:
        raise SspError(f"fmpy's simulate_ssp took {len(res)} steps, expected {n}")
    outputs = {f"{c.name}.{k.name}" for c in comps for k in c.connectors if k.kind == "output"}
    out = {"time": start + dt * np.arange(1, n + 1)}
    for name in res.dtype.names:
        if name in outputs:
            out[name] = np.asarray(res[name])
    return out


def fmpy_equivalent(scenario):
    """The scenario as fmpy's ``simulate_ssp`` runs its package: every signal 0.0 at the start
    time t_0, the scenario's values from t_1 on. The harness on this scenario takes the steps
    ``simulate_ssp`` takes: the plant and the observers initialised with their inputs at their
    start values (``initialise_at_start_values``; the plant's initial state does not depend on
    them) and stepped from t_0 with 0.0, and every later step as in the harness."""
    from ..validation.scenarios import Scenario, get_scenario

    base = get_scenario(scenario)

    def zero_first(sig: Mapping[str, np.ndarray], t) -> dict[str, np.ndarray]:
        t = np.asarray(t, dtype=float)
        out = {}
        for k, v in sig.items():
            v = np.array(v, dtype=float, copy=True)
            v[t == 0.0] = 0.0                 # the scenarios' time grids start at 0
            out[k] = v
        return out

    class ZeroAtStart(Scenario):
        def signals(self, t, vehicle="sedan"):
            return zero_first(base.signals(t, vehicle), t)

        def parameter_signals(self, t, vehicle="sedan"):
            return zero_first(base.parameter_signals(t, vehicle), t)

        def info(self, vehicle="sedan"):
            return {**base.info(vehicle), "fmpy_equivalent": "every signal 0.0 at t_0"}

    sc = ZeroAtStart(name=base.name, description=base.description, duration=base.duration, plant=base.plant,
                     settle_time=base.settle_time, signal_names=base.signal_names)
    object.__setattr__(sc, "optional_plant_inputs", tuple(getattr(base, "optional_plant_inputs", ())))
    object.__setattr__(sc, "initialise_at_start_values", True)
    return sc


def harness_trace(result, start: int = 1) -> dict[str, np.ndarray]:
    """A :class:`~latobs.validation.harness.SimResult` as {"time", "<component>.<name>"} from
    sample ``start`` on (1: t_1..t_n, what libcosim and fmpy record): the plant outputs under
    ``plant.``, the other bus signals (the scenario's) under ``signals.``, each observer's outputs
    under its label."""
    plant = FmuInterface.read(Path(result.info["plant_fmu"]), PLANT_LABEL)
    plant_out = {v.name for v in plant.outputs}
    out = {"time": np.asarray(result.time[start:])}
    for k, v in result.bus.items():
        out[f"{PLANT_LABEL if k in plant_out else SOURCE_LABEL}.{k}"] = np.asarray(v[start:])
    for label, outs in result.observers.items():
        for k, v in outs.items():
            out[f"{label}.{k}"] = np.asarray(v[start:])
    return out


def compare(run: Mapping[str, np.ndarray], reference: Mapping[str, np.ndarray]) -> dict[str, float]:
    """Max |run - reference| per signal present in both (same length and times required)."""
    rt, ft = np.asarray(run["time"]), np.asarray(reference["time"])
    if rt.shape != ft.shape or np.max(np.abs(rt - ft), initial=0.0) > 1e-9:
        raise SspError(f"the two runs are not on one time grid ({len(rt)} and {len(ft)} samples)")
    return {k: float(np.max(np.abs(np.asarray(run[k], dtype=float) - np.asarray(reference[k], dtype=float)),
                            initial=0.0))
            for k in reference if k != "time" and k in run}
