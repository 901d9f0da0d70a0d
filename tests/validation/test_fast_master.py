"""The validation master calling the libraries fmpy loaded directly (the default) gives the results of
the same loop calling them through fmpy's checked wrappers (``fast=False``), bit for bit: the same calls in the
same order and the same arithmetic, on pythonfmu and native C FMUs, with and without noise."""
from __future__ import annotations

import numpy as np
import pytest

from latobs.validation import harness
from latobs.validation.scenarios import get_scenario

pytestmark = pytest.mark.slow
OBSERVERS = ("SideslipBankObserver", "SideslipBankObserverTire")
NOISE = {"yaw_rate": (0.01, 0.002), "roll_rate": (0.02, 0.0), "vx": (0.2, 0.1)}


@pytest.mark.parametrize("backend", ["python", "c"])
@pytest.mark.parametrize("noise", [None, NOISE], ids=["clean", "noise"])
def test_fast_master_equals_the_plain_loop(built_fmus, backend, noise):
    sc = get_scenario("bank-braking", duration=6.0)
    plant = built_fmus.get("CarPlant", backend)
    observers = {o: built_fmus.get(o, backend) for o in OBSERVERS}
    runs = [harness.run(sc, plant, observers, noise=noise, seed=7, fast=fast) for fast in (False, True)]
    plain, fast = runs
    assert set(plain.bus) == set(fast.bus) and set(plain.measured) == set(fast.measured)
    for k in plain.bus:
        assert np.array_equal(plain.bus[k], fast.bus[k]), k
    for k in plain.measured:
        assert np.array_equal(plain.measured[k], fast.measured[k]), k
    for lab in OBSERVERS:
        for k, ref in plain.observers[lab].items():
            assert fast.observers[lab][k].dtype == ref.dtype, (lab, k)
            assert np.array_equal(fast.observers[lab][k], ref), (lab, k)
    assert plain.logs == fast.logs


@pytest.mark.parametrize("scenario", sorted(__import__("latobs.validation.scenarios", fromlist=["SCENARIOS"]).SCENARIOS))
def test_the_compiled_loop_equals_the_python_loop_on_every_scenario(built_fmus, scenario, monkeypatch):
    """The master's compiled stepping loop (latobs/native/master_loop.c, the default where it can be
    compiled) against the Python loop it replaces, on every validation scenario with the observers
    `latobs validate` runs there, with sensor noise: the same results, bit for bit."""
    from latobs import catalogue, packaging, pipeline
    from latobs.validation import compiled_loop

    if compiled_loop.unavailable_reason() is not None:
        pytest.skip(f"no compiled loop here: {compiled_loop.unavailable_reason()}")
    sc = get_scenario(scenario)
    sc = get_scenario(scenario, duration=min(sc.duration, max(5.0, sc.settle_time + 1.0)))   # (its first seconds)
    plant = built_fmus.c_path(sc.plant)
    observers = {o: built_fmus.c_path(o) for o in catalogue.default_observers(sc.plant)}
    noise = pipeline.PLANT_NOISE[sc.plant]
    # the varying-stiffness scenarios draw from a vehicle's stiffness box: the paper-002 car's
    vehicle = "delibasi" if scenario.endswith("-varying-stiffness") else packaging.PLANTS[sc.plant].default_vehicle
    compiled = harness.run(sc, plant, observers, noise=noise, seed=11, vehicle=vehicle)
    assert compiled.info["master_loop"] == "compiled"
    monkeypatch.setattr(compiled_loop, "library", lambda: None)
    python = harness.run(sc, plant, observers, noise=noise, seed=11, vehicle=vehicle)
    assert python.info["master_loop"] == "python"
    for k in python.bus:
        assert np.array_equal(python.bus[k], compiled.bus[k]), k
    for k in python.measured:
        assert np.array_equal(python.measured[k], compiled.measured[k]), k
    for lab, outs in python.observers.items():
        for k, ref in outs.items():
            assert compiled.observers[lab][k].dtype == ref.dtype and np.array_equal(compiled.observers[lab][k], ref)
    assert python.logs == compiled.logs
