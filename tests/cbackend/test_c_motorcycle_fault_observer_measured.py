"""The measured-speed paper-003 observer (latobs's default MotorcycleFaultObserver: the roll angle a
state, a PMI torque, M(v) = M + v M_vx + M_ivx / v at the measured speed) in the native C model
against its Python twin: co-simulation on the motorcycle scenarios, changing step sizes through the
speed clamp, the hold and a reverse excursion (the same bits, the same warnings: both runtimes
compute each step map with products summed from the left), the absurd
step refused with the state kept, and the ModelExchange derivatives against numpy's A(v) - L(v) C
rebuilt from the design file."""
from __future__ import annotations

from ctypes import c_double

import numpy as np
import pytest
from fmpy import extract, instantiate_fmu, read_model_description

from latobs.native_guard import find_compiler
from latobs.pipeline import PLANT_NOISE
from latobs.validation import harness
from latobs.validation.harness import NoiseSpec
from latobs.validation.scenarios import SCENARIOS

from c_models import assert_equivalent, run_cs

pytestmark = [pytest.mark.slow,
              pytest.mark.skipif(find_compiler() is None, reason="no C compiler (set CC, or install cc/gcc)")]

OBS, PLANT, VEHICLE = "MotorcycleFaultObserver", "MotorcyclePlant", "sharp_motorcycle"
SCENARIOS_003 = [name for name, sc in SCENARIOS.items() if sc.plant == PLANT]


def _outputs_equal(ref: list, got: list):
    """The same bits: the step maps of both runtimes sum their products from the left alike."""
    assert len(ref) == len(got)
    for a, b in zip(ref, got):
        assert a == b


@pytest.mark.parametrize("scenario", SCENARIOS_003)
@pytest.mark.parametrize("dt, noise", [(0.005, True), (0.002, False)])
def test_measured_observer_equals_python_runtime(built_fmus, scenario, dt, noise):
    res = harness.run(scenario, built_fmus.path(PLANT), {"py": built_fmus.path(OBS), "c": built_fmus.c_path(OBS)},
                      dt=dt, vehicle=VEHICLE, noise=NoiseSpec(signals=PLANT_NOISE[PLANT]) if noise else None)
    assert_equivalent(res.observers["py"], res.observers["c"], f"{scenario} dt={dt} noise={noise}", rel=0.0)
    assert res.logs["c"] == res.logs["py"]


def test_speed_clamp_steps_of_changing_size_and_warnings_equal_python(built_fmus):
    """Speeds inside, below and above the band (the model speed clamped to it), the hold, a reverse
    excursion; steps of 5, 3, 12.5 ms and 1 s: the same outputs to the bit and the same warnings."""
    rng = np.random.default_rng(11)
    speeds = [14.0, 14.0, 19.0, 0.5, -0.5, -4.0, 3.0, 9.0, 40.0, 31.0, 12.4, 26.0, 26.0, 8.0]
    steps = []
    for k, vx in enumerate(speeds * 3):
        y = 0.05 * rng.standard_normal(3)
        steps.append(((0.005, 0.003, 0.005, 0.0125, 1.0)[k % 5],
                      {"vx": vx, "steer_angle": y[0], "yaw_rate": y[1], "roll_rate": y[2]}))
    u0 = {"vx": 14.0, "steer_angle": 0.01, "yaw_rate": 0.1, "roll_rate": -0.05}
    py, py_log = run_cs(built_fmus.path(OBS), "py", u0, steps)
    c, c_log = run_cs(built_fmus.c_path(OBS), "c", u0, steps)
    _outputs_equal(py, c)
    assert c_log == py_log
    assert sum("frozen" in m for m in c_log) == 3 and sum("outside the design grid" in m for m in c_log) == 6


def test_absurd_step_is_refused_with_the_state_kept(built_fmus):
    u = {"vx": 15.0, "steer_angle": 0.01, "yaw_rate": 0.1, "roll_rate": 0.0}
    ref, _ = run_cs(built_fmus.c_path(OBS), "ref", u, [(0.005, u)] * 3)
    got, log = run_cs(built_fmus.c_path(OBS), "c", u, [(0.005, u), (1e300, u), (0.005, u), (0.005, u)])
    assert got[2] is None and any(m.startswith("[ERROR]") and "refused" in m for m in log), log
    assert [got[0], got[1], got[3], got[4]] == ref


def test_me_derivatives_are_the_model_at_the_clamped_measured_speed(built_fmus, tmp_path):
    """s' = (A(v) - L(v) C) s + L(v) y with v = vx clamped to the band, A, L, C from the design file
    (numpy, not the tables the C model reads)."""
    fmu = built_fmus.c_path(OBS)
    md = read_model_description(str(fmu))
    m = instantiate_fmu(extract(str(fmu), unzipdir=str(tmp_path / "me")), md, fmi_type="ModelExchange")
    vr = {v.name: v.valueReference for v in md.modelVariables}
    m.setupExperiment(startTime=0.0)
    m.enterInitializationMode()
    m.setReal([vr["vx"]], [16.0])
    m.exitInitializationMode()
    m.newDiscreteStates()
    m.enterContinuousTimeMode()
    d = built_fmus.design(OBS)
    A = [np.asarray(x, float) for x in d["model"]["A"]]
    L = [np.asarray(x, float) for x in d["modes"][0]["gains"]["L"]]
    C = np.asarray(d["model"]["C"][0], float)
    lo, hi = d["modes"][0]["band"]
    n = len(md.derivatives)
    rng = np.random.default_rng(2)
    for vx in (16.0, 8.0, 31.0, 5.0, 45.0):
        s, y = rng.standard_normal(n), 0.1 * rng.standard_normal(3)
        m.setReal([vr[k] for k in ("vx", "steer_angle", "yaw_rate", "roll_rate")], [vx, *y])
        m.setContinuousStates((c_double * n)(*s), n)
        dx = (c_double * n)()
        m.getDerivatives(dx, n)
        v = min(max(vx, lo), hi)
        b = (1.0, v, 1.0 / v)
        Av, Lv = sum(bk * a for bk, a in zip(b, A)), sum(bk * l for bk, l in zip(b, L))
        np.testing.assert_allclose(np.array(dx[:]), (Av - Lv @ C) @ s + Lv @ y, rtol=1e-10, atol=1e-9 * np.abs(Lv).max())
    m.terminate()
    m.freeInstance()
