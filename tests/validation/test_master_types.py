"""The co-simulation master's one loop on every FMI 2 type: Integer and Boolean inputs and
outputs (wired plant -> observer and scenario -> FMU) are passed as FMI 2 passes them, with the
one-step delay of Real signals, identically through the direct calls and fmpy's checked wrappers."""
from __future__ import annotations

import textwrap
from dataclasses import dataclass

import numpy as np
import pytest

from latobs.validation.harness import CoSimulationError, run
from latobs.validation.scenarios import Scenario

PLANT_SRC = '''
from pythonfmu import Boolean, Fmi2Causality, Fmi2Slave, Fmi2Variability, Integer, Real


class LatobsTypesPlant(Fmi2Slave):
    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.gear_in, self.flag_in, self.u = 0, False, 0.0
        self.gear, self.flag, self.x = 0, False, 0.0
        self.register_variable(Integer("gear_in", causality=Fmi2Causality.input, variability=Fmi2Variability.discrete))
        self.register_variable(Boolean("flag_in", causality=Fmi2Causality.input, variability=Fmi2Variability.discrete))
        self.register_variable(Real("u", causality=Fmi2Causality.input))
        self.register_variable(Integer("gear", causality=Fmi2Causality.output, variability=Fmi2Variability.discrete))
        self.register_variable(Boolean("flag", causality=Fmi2Causality.output, variability=Fmi2Variability.discrete))
        self.register_variable(Real("x", causality=Fmi2Causality.output))

    def _update(self):
        self.gear, self.flag, self.x = self.gear_in, self.flag_in, 0.5 * self.u + self.gear_in

    def exit_initialization_mode(self):
        self._update()
        return True

    def do_step(self, current_time, step_size):
        self._update()
        return True
'''

OBSERVER_SRC = '''
from pythonfmu import Boolean, Fmi2Causality, Fmi2Slave, Fmi2Variability, Integer, Real


class LatobsTypesObserver(Fmi2Slave):
    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.gear, self.flag, self.x, self.u = 0, False, 0.0, 0.0
        self.gear_hat, self.flag_hat, self.x_hat = 0, False, 0.0
        self.register_variable(Integer("gear", causality=Fmi2Causality.input, variability=Fmi2Variability.discrete))
        self.register_variable(Boolean("flag", causality=Fmi2Causality.input, variability=Fmi2Variability.discrete))
        self.register_variable(Real("x", causality=Fmi2Causality.input))
        self.register_variable(Real("u", causality=Fmi2Causality.input))
        self.register_variable(Integer("gear_hat", causality=Fmi2Causality.output, variability=Fmi2Variability.discrete))
        self.register_variable(Boolean("flag_hat", causality=Fmi2Causality.output, variability=Fmi2Variability.discrete))
        self.register_variable(Real("x_hat", causality=Fmi2Causality.output))

    def _update(self):
        self.gear_hat, self.flag_hat, self.x_hat = self.gear + 1, not self.flag, self.x + self.u

    def exit_initialization_mode(self):
        self._update()
        return True

    def do_step(self, current_time, step_size):
        self._update()
        return True
'''


@dataclass(frozen=True)
class TypedScenario(Scenario):
    name: str = "test-typed"
    description: str = "integer, boolean and real plant inputs"
    duration: float = 1.0
    settle_time: float = 0.0
    gear_offset: float = 0.0

    def signals(self, t, vehicle="sedan"):
        t = np.asarray(t, float)
        return {"gear_in": np.floor(10 * t) % 5 + self.gear_offset, "flag_in": (t >= 0.5).astype(float),
                "u": np.sin(3 * t)}


@pytest.fixture(scope="module")
def typed_fmus(tmp_path_factory):
    pytest.importorskip("pythonfmu")
    from pythonfmu import FmuBuilder

    if not FmuBuilder.has_binary():
        pytest.skip("pythonfmu has no binary for this platform")
    src, out = tmp_path_factory.mktemp("src"), tmp_path_factory.mktemp("fmus")
    paths = {}
    for key, module, code in (("plant", "latobs_types_plant", PLANT_SRC),
                              ("observer", "latobs_types_observer", OBSERVER_SRC)):
        script = src / f"{module}.py"
        script.write_text(textwrap.dedent(code))
        paths[key] = FmuBuilder.build_FMU(script, dest=out)
    return paths


@pytest.mark.slow
@pytest.mark.parametrize("noise", [None, {"x": (0.1, 0.0), "u": (0.0, 0.25)}], ids=["clean", "noise"])
def test_integer_and_boolean_signals_cross_the_one_loop(typed_fmus, noise):
    runs = [run(TypedScenario(), typed_fmus["plant"], {"obs": typed_fmus["observer"]}, dt=0.01, noise=noise, seed=4,
                fast=fast) for fast in (True, False)]
    r = runs[0]
    gear, flag = r.bus["gear"], r.bus["flag"]
    sig = TypedScenario().signals(r.time)
    for out, inp in ((gear, sig["gear_in"]), (flag, sig["flag_in"])):  # plant: at t_k+1 from u(t_k), at t_0 from u(t_0)
        assert out[0] == inp[0]
        np.testing.assert_array_equal(out[1:], inp[:-1])
    obs = r.observers["obs"]
    assert obs["gear_hat"].dtype == np.int64 and obs["flag_hat"].dtype == np.int64
    np.testing.assert_array_equal(obs["gear_hat"][1:], gear[:-1] + 1)   # one step of delay
    np.testing.assert_array_equal(obs["flag_hat"][1:], 1 - flag[:-1])
    np.testing.assert_array_equal(obs["x_hat"][1:], r.measured["x"][:-1] + r.measured["u"][:-1])
    for other in runs[1:]:                                              # the checked calls: the same bits
        for k in r.bus:
            np.testing.assert_array_equal(other.bus[k], r.bus[k])
        for k in obs:
            np.testing.assert_array_equal(other.observers["obs"][k], obs[k])
            assert other.observers["obs"][k].dtype == obs[k].dtype


@pytest.mark.slow
def test_a_value_beyond_fmi2_integer_is_an_error_naming_the_input(typed_fmus):
    """1e12 does not fit an fmi2Integer (32 bits): an error naming the FMU, the input and the
    time, never a silently wrapped value."""
    with pytest.raises(CoSimulationError, match=r"'plant'.*Integer input 'gear_in' gets 1000000000000.0 at t = 0 s"):
        run(TypedScenario(gear_offset=1e12), typed_fmus["plant"], {"obs": typed_fmus["observer"]}, dt=0.01)
