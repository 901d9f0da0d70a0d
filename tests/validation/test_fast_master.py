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
