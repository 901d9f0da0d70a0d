"""Helpers shared by the native C backend's model tests (``test_c_*.py``).

* :data:`REL` and :func:`assert_equivalent`: the backend's equivalence bound, C against Python;
* :func:`run_cs`: one FMU alone through fmpy, steps of given sizes and inputs (its log its own);
* :func:`held_inputs`: signals as an fmpy input held from sample to sample, for ModelExchange runs.
  fmpy's CVode driver applies an FMU's inputs only in its event function, not before computing
  derivatives, and takes long internal steps between input events: with interpolated inputs its
  ModelExchange result lags them (25 % on paper 000's bank estimate). Every sample time after the
  first appears twice (the value before, then after): fmpy makes it an input event, sets the new
  value in event mode and restarts CVode, so the ModelExchange FMU integrates the very ODE the
  co-simulation stepped.
"""
from __future__ import annotations

import numpy as np
from fmpy.fmi1 import FMICallException

from latobs.validation.harness import FmuInstance

REL = 1e-9          # the C backend's equivalence bound (relative to the output's peak)


def assert_equivalent(ref: dict, got: dict, what: str, rel: float = REL):
    """max |got - ref| <= rel max |ref| (+ 1e-300) per signal, integer signals equal."""
    for name, a in ref.items():
        a, b = np.asarray(a), np.asarray(got[name])
        if a.dtype.kind in "iu":
            assert np.array_equal(a, b), f"{what}: {name} differs at {np.flatnonzero(a != b)[:5]}"
            continue
        scale, err = float(np.max(np.abs(a))), float(np.max(np.abs(b - a)))
        assert err <= rel * scale + 1e-300, f"{what}: {name} max |diff| {err:.3g} vs peak {scale:.3g}"


def run_cs(fmu, label: str, u0: dict, steps: list, params: dict | None = None) -> tuple[list, list]:
    """One FMU alone: start with inputs ``u0`` (and ``params``), then doStep(h) with inputs u per
    (h, u) of ``steps``; the outputs after each step (a refused step: None) and the log."""
    f = FmuInstance(label, fmu)
    try:
        out = [f.start(u0, params or {})]
        t = 0.0
        for h, u in steps:
            f.set_inputs(u)
            try:
                f.slave.doStep(t, h)
                t += h
                out.append(f.get_outputs())
            except FMICallException:
                out.append(None)
        return out, list(f.logs)
    finally:
        f.close()


def held_inputs(t: np.ndarray, signals: dict) -> np.ndarray:
    """``signals`` sampled on ``t`` as an fmpy input held from each sample to the next (see the
    module docstring)."""
    rows = np.zeros(2 * len(t) - 1, dtype=[("time", float)] + [(k, float) for k in signals])
    rows["time"] = np.repeat(t, 2)[1:]
    for k, v in signals.items():
        rows[k] = np.repeat(np.asarray(v, float), 2)[:-1]
    return rows
