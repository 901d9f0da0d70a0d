"""The LateralIntervalObserver FMU: equal to its runtime, no direct feedthrough, bad input handled."""
from __future__ import annotations

import math

import pytest
from fmpy import read_model_description

from latobs.fmu_src.lateral_interval_observer import IntervalObserver
from latobs.validation.harness import FmuInstance

pytestmark = pytest.mark.slow
H = 0.005


@pytest.fixture(scope="module")
def built(built_fmus):
    name = "LateralIntervalObserver"               # the session build (conftest.py)
    return built_fmus.path(name), built_fmus.design(name)


def inputs(k: int) -> dict:
    t = k * H
    vx = 19.0 - 8.0 * min(t / 3.0, 1.0)                    # crosses the three speed bands
    return {"delta": 0.02 * math.sin(2.0 * t), "vx": vx, "yaw_rate": 0.05 * math.sin(2.0 * t - 0.3),
            "ay": 1.2 * math.sin(2.0 * t - 0.2)}


def open_fmu(path):
    fmu = FmuInstance("I", path)
    fmu.start(inputs(0))
    return fmu


def test_fmu_equals_its_runtime_and_declares_its_interface(built):
    path, data = built
    fmu = open_fmu(path)
    rt = IntervalObserver(data, {})
    rt.initialize(inputs(0))
    worst, modes = 0.0, set()
    try:
        for k in range(800):
            u = inputs(k)
            fmu.set_inputs(u)
            fmu.slave.doStep(k * H, H)
            rt.step(H, u)
            got = fmu.get_outputs()
            worst = max(worst, max(abs(got[n] - rt.y[n]) for n in got))
            modes.add(int(got["mode"]))
            before = dict(got)
            fmu.set_inputs({n: 3.0 * x + 1.0 for n, x in u.items()})   # no direct feedthrough
            assert fmu.get_outputs() == before
    finally:
        fmu.close()
    assert worst <= 1e-12 and modes == {1, 2, 3}
    md = read_model_description(str(path))
    v = {x.name: x for x in md.modelVariables}
    assert (int(v["mode"].min), int(v["mode"].max)) == (1, 3)
    assert (int(v["consistent"].min), int(v["consistent"].max)) == (0, 1)
    assert v["Fyf_upper"].unit == "N" and v["vy_lower"].displayUnit == "km/h"
    assert all(u.dependencies == [] for u in md.outputs)


def test_bad_input_is_refused_and_the_state_held(built):
    path, _ = built
    fmu = open_fmu(path)
    try:
        for k in range(10):
            fmu.set_inputs(inputs(k))
            fmu.slave.doStep(k * H, H)
        before = fmu.get_outputs()
        fmu.set_inputs(dict(inputs(10), ay=math.nan))
        with pytest.raises(Exception, match="discard"):
            fmu.slave.doStep(10 * H, H)
        assert fmu.get_outputs() == before
        fmu.set_inputs(dict(inputs(10), vx=0.2))          # below vx_hold: frozen, held
        fmu.slave.doStep(10 * H, H)
        assert fmu.get_outputs() == before
    finally:
        fmu.close()
    assert any("non-finite input(s) ay" in m for m in fmu.logs)
