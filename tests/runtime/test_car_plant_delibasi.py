"""CarPlant for paper 002 (Delibasi 2014): the ``delibasi`` plant and time-varying cornering stiffness.

* ``delibasi.toml`` carries every parameter CarPlant needs: Cf = Cr = the centre of paper 002's
  physical per-axle box (2 tyres x 600 N/deg x 180/pi), the rest assumed (typical sedan);
* the inputs ``stiffness_scale_f``/``_r`` (start 1.0) multiply the axle cornering stiffnesses on
  top of the parameters ``scale_f``/``_r``, held per communication step; 1.0 is bit-identical to
  not driving them; non-positive values are clamped to 0.1, a non-finite one refuses the step.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest
from fmpy import read_model_description

from latobs import packaging
from latobs.fmu_src.car_plant import CarPlantModel
from latobs.packaging import plant_data
from latobs.synthesis import sideslip_fixed_order_estimator
from latobs.synthesis.params import load_vehicle
from latobs.validation.harness import FmuInstance, WiringError, run
from latobs.validation.scenarios import Scenario, get_scenario

H = 0.005  # s, communication step
DATA = plant_data("delibasi")
VP = {k: v["value"] for k, v in DATA["vehicle"]["parameters"].items()}
C_CENTRE = 2 * 600.0 * 180.0 / math.pi  # N/rad per axle: 2 tyres x 600 N/deg


@pytest.fixture(scope="module")
def plant_fmu(tmp_path_factory):
    """CarPlant built for delibasi by the packaging step (as `latobs build CarPlant --vehicle delibasi`)."""
    out = tmp_path_factory.mktemp("fmus_002")
    path = packaging.package_plant("CarPlant", "delibasi", out)
    assert path.name == "CarPlant_delibasi.fmu"
    return path


def bicycle_steady_state(v: float, delta: float, Cf: float, Cr: float) -> tuple[float, float]:
    """(beta rad, r rad/s) of the linear bicycle model at rest in a steady turn, solved here from
    m v (beta' + r) = Fyf + Fyr, Iz r' = lf Fyf - lr Fyr, Fyf = Cf (delta - beta - lf r / v),
    Fyr = Cr (-beta + lr r / v) with beta' = r' = 0 (Iz drops out)."""
    m, lf, lr = VP["m"], VP["lf"], VP["lr"]
    A = np.array([[Cf + Cr, m * v + (lf * Cf - lr * Cr) / v],
                  [lf * Cf - lr * Cr, (lf ** 2 * Cf + lr ** 2 * Cr) / v]])
    b = np.array([Cf * delta, lf * Cf * delta])
    beta, r = np.linalg.solve(A, b)
    return float(beta), float(r)


def drive(fmu: FmuInstance, inputs: list[dict]) -> dict[str, np.ndarray]:
    out = []
    for k, u in enumerate(inputs):
        fmu.set_inputs(u)
        fmu.slave.doStep(k * H, H)
        out.append(fmu.get_outputs())
    return {n: np.array([o[n] for o in out]) for n in out[0]}


def manoeuvre(n: int) -> list[dict]:
    return [{"delta": 0.08 * math.sin(2.5 * k * H), "vx": 9.0 + 0.2 * math.sin(0.5 * k * H), "bank_angle": 0.0}
            for k in range(n)]


# ------------------------------------------------------------------------------------------
# the delibasi vehicle feeds the plant
# ------------------------------------------------------------------------------------------
def test_delibasi_parameters_for_the_plant():
    veh = load_vehicle("delibasi")
    # the paper's values are unchanged
    assert (veh.m, veh.lf, veh.lr, veh.kG, veh.Iz) == (1500.0, 1.4, 1.7, 1.3, 2535.0)
    # Cf = Cr = the centre of the physical box of ERRATA 002 (per axle, N/rad)
    box = sideslip_fixed_order_estimator.boxes(veh)["physical"]
    assert veh.Cf == pytest.approx(C_CENTRE, rel=1e-15) and veh.Cr == pytest.approx(C_CENTRE, rel=1e-15)
    assert veh.Cf == pytest.approx(0.5 * sum(box.cf), rel=1e-12)
    assert veh.Cr == pytest.approx(0.5 * sum(box.cr), rel=1e-12)
    # every parameter the plant needs, each added one with its source
    CarPlantModel(DATA)
    for k in ("Cf", "Cr", "Ix", "hr", "Kr", "br", "track", "sigma", "h_rc", "roll_share_f", "mf_C", "mf_E", "mu"):
        src = veh.parameters[k].source
        assert src.startswith("derived") or src.startswith("assumed (typical sedan"), (k, src)


def test_stiffness_inputs_extend_the_interface(plant_fmu):
    md = read_model_description(str(plant_fmu))
    ins = [v for v in md.modelVariables if v.causality == "input"]
    outs = [v.name for v in md.modelVariables if v.causality == "output"]
    assert [v.name for v in ins] == ["delta", "vx", "bank_angle", "stiffness_scale_f", "stiffness_scale_r"]
    assert outs == ["beta", "vy", "yaw_rate", "ay", "roll_angle", "roll_rate", "Fyf", "Fyr", "alpha_f",
                    "alpha_r", "vy_cg", "beta_cg"]
    for v in ins[3:]:
        assert (v.unit, float(v.start), float(v.min), float(v.max)) == ("1", 1.0, 0.0, 100.0)   # refused outside


# ------------------------------------------------------------------------------------------
# scale 1 changes nothing; the input acts like the parameter
# ------------------------------------------------------------------------------------------
def test_unit_stiffness_inputs_equal_the_run_without_them(plant_fmu):
    u = manoeuvre(600)
    a, b = FmuInstance("a", plant_fmu), FmuInstance("b", plant_fmu)
    try:
        a.start(u[0])                                           # stiffness inputs never set
        b.start({**u[0], "stiffness_scale_f": 1.0, "stiffness_scale_r": 1.0})
        ya = drive(a, u)
        yb = drive(b, [{**x, "stiffness_scale_f": 1.0, "stiffness_scale_r": 1.0} for x in u])
    finally:
        a.close()
        b.close()
    assert np.max(np.abs(ya["beta"])) > 0.01                  # a real manoeuvre
    for name in ya:
        assert np.array_equal(ya[name], yb[name]), name        # bit-identical
    rt = CarPlantModel(DATA)                                    # and equal to the runtime without them
    for k, x in enumerate(u):
        rt.step(H, x)
        assert all(rt.y[n] == ya[n][k] for n in rt.y), k


@pytest.mark.parametrize("sigma, linear", [(0.0, 1.0), (0.0, 0.0), (0.5, 0.0)])
def test_stiffness_input_acts_like_the_scale_parameter(sigma, linear):
    """Input 4.0 on both axles == parameters scale_f = scale_r = 4.0: same B, same substeps (the
    substep rule scales its stiffness estimate with the inputs; without it, at 2 m/s with
    algebraic tires, the outputs differ by O(1))."""
    base = {"sigma": sigma, "linear_tires": linear}
    a = CarPlantModel(DATA, {**base, "scale_f": 4.0, "scale_r": 4.0})
    b = CarPlantModel(DATA, base)
    worst = 0.0
    for k in range(600):
        u = {"delta": 0.1 * math.sin(4.0 * k * H), "vx": 2.0 + 6.0 * k / 600, "bank_angle": 0.0}
        a.step(H, u)
        b.step(H, {**u, "stiffness_scale_f": 4.0, "stiffness_scale_r": 4.0})
        worst = max(worst, max(abs(a.y[n] - b.y[n]) / max(1.0, abs(a.y[n])) for n in a.y))
    assert worst <= 1e-9
    assert not a.events and not b.events


# ------------------------------------------------------------------------------------------
# physics: the linear bicycle model's steady state with the scaled stiffness
# ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("kf, kr", [(1.0, 550 / 600), (610 / 600, 650 / 600), (1.3, 0.8)])
def test_steady_state_matches_the_bicycle_model_with_scaled_stiffness(plant_fmu, kf, kr):
    """Linear tires, delta = 0.01 rad at 30 km/h (ay ~ 0.2 m/s^2): the steady sideslip and yaw
    rate are the linear bicycle model's with Cf*kf, Cr*kr within 0.1 %. The plant departs from
    the bicycle model only at second order here: slip angle atan(.) vs its argument and cos(delta)
    (~delta^2 ~ 1e-4), left/right slip difference r t/(2 vx) ~ 2e-3 times the small load transfer
    (~1e-2); roll is steady (phidot = 0, so beta = beta_cg); measured ~3e-5. The tolerance is
    30x tighter than the effect of the scale itself (the k = 1 prediction misses by > 1 %)."""
    v, delta = 30.0 / 3.6, 0.01
    fmu = FmuInstance("ss", plant_fmu)
    try:
        u = {"delta": delta, "vx": v, "bank_angle": 0.0, "stiffness_scale_f": kf, "stiffness_scale_r": kr}
        fmu.start(u, {"linear_tires": 1.0})
        y = drive(fmu, [u] * 1600)                            # 8 s: the slowest mode decays in < 0.5 s
    finally:
        fmu.close()
    beta_ref, r_ref = bicycle_steady_state(v, delta, VP["Cf"] * kf, VP["Cr"] * kr)
    beta_nom, r_nom = bicycle_steady_state(v, delta, VP["Cf"], VP["Cr"])
    beta, r = y["beta"][-1], y["yaw_rate"][-1]
    assert abs(y["beta"][-1] - y["beta"][-200]) < 1e-9         # settled
    assert beta == pytest.approx(beta_ref, rel=1e-3) and r == pytest.approx(r_ref, rel=1e-3)
    assert y["beta_cg"][-1] == pytest.approx(beta, rel=1e-9)
    assert max(abs(beta_nom / beta_ref - 1), abs(r_nom / r_ref - 1)) > 1e-2   # the scale matters


def test_a_stiffness_step_mid_run_moves_the_steady_state(plant_fmu):
    """The input is read every step: rear scale 1 for 6 s, then 650/600 (the box's rear maximum)."""
    v, delta, k = 30.0 / 3.6, 0.01, 650 / 600
    u0 = {"delta": delta, "vx": v, "bank_angle": 0.0}
    fmu = FmuInstance("step", plant_fmu)
    try:
        fmu.start(u0, {"linear_tires": 1.0})
        y = drive(fmu, [u0] * 1200 + [{**u0, "stiffness_scale_r": k}] * 1200)
    finally:
        fmu.close()
    for i, kr in ((1199, 1.0), (2399, k)):
        beta_ref, r_ref = bicycle_steady_state(v, delta, VP["Cf"], VP["Cr"] * kr)
        assert y["beta"][i] == pytest.approx(beta_ref, rel=1e-3), kr
        assert y["yaw_rate"][i] == pytest.approx(r_ref, rel=1e-3), kr


def test_swept_stiffness_scenario_drives_the_plant(plant_fmu):
    """sine-with-dwell-varying-stiffness through the harness: the scenario's stiffness signals reach
    the plant by name (the run equals the runtime fed the same held inputs) and change the
    response against the same manoeuvre at the box centre."""
    sc = get_scenario("sine-with-dwell-varying-stiffness")
    res = run(sc, plant_fmu, {}, vehicle="delibasi")
    assert res.inputs["plant"] == ["delta", "vx", "bank_angle", "stiffness_scale_f", "stiffness_scale_r"]
    assert res.info["plant_inputs_at_start"] == {}
    rt = CarPlantModel(DATA)
    names = res.inputs["plant"]
    for k in range(len(res.time) - 1):
        rt.step(res.dt, {n: float(res.bus[n][k]) for n in names})
        assert all(rt.y[n] == res.bus[n][k + 1] for n in rt.y), k
    centre = run(get_scenario(sc.name, scale_f_range=(1.0, 1.0), scale_r_range=(1.0, 1.0)), plant_fmu, {},
                 vehicle="delibasi")
    nominal = run("sine-with-dwell", plant_fmu, {}, vehicle="delibasi")  # other manoeuvre, same plant
    assert nominal.info["plant_inputs_at_start"] == {"stiffness_scale_f": 1.0, "stiffness_scale_r": 1.0}
    dbeta = np.max(np.abs(res.bus["beta"] - centre.bus["beta"]))
    assert dbeta > math.radians(0.05), math.degrees(dbeta)
    assert not [m for m in res.logs["plant"] if m.startswith(("[WARNING]", "[ERROR]"))], res.logs["plant"]


@dataclass(frozen=True)
class NoBank(Scenario):
    """Provides delta and vx only: bank_angle is a REQUIRED CarPlant input."""

    name: str = "test-no-bank"
    duration: float = 0.1

    def signals(self, t, vehicle="sedan"):
        t = np.asarray(t, float)
        return {"delta": np.zeros_like(t), "vx": np.full_like(t, 9.0)}


@dataclass(frozen=True)
class Strict(NoBank):
    """Provides every required input but declares no optional plant input."""

    name: str = "test-strict"
    optional_plant_inputs = ()

    def signals(self, t, vehicle="sedan"):
        return {**super().signals(t, vehicle), "bank_angle": np.zeros_like(np.asarray(t, float))}


def test_only_the_optional_inputs_may_be_left_out(plant_fmu):
    with pytest.raises(WiringError, match="'bank_angle'") as exc:
        run(NoBank(), plant_fmu, {}, vehicle="delibasi")
    assert "stiffness_scale" not in str(exc.value)
    with pytest.raises(WiringError, match="'stiffness_scale_f', 'stiffness_scale_r'"):
        run(Strict(), plant_fmu, {}, vehicle="delibasi")


# ------------------------------------------------------------------------------------------
# bad inputs never crash
# ------------------------------------------------------------------------------------------
def test_nan_and_nonpositive_stiffness_inputs(plant_fmu):
    u = {"delta": 0.05, "vx": 9.0, "bank_angle": 0.0}
    fmu = FmuInstance("bad", plant_fmu)
    try:
        fmu.start(u)
        drive(fmu, [u] * 20)
        before = fmu.get_outputs()
        fmu.set_inputs({**u, "stiffness_scale_r": math.nan})
        with pytest.raises(Exception, match="discard"):
            fmu.slave.doStep(20 * H, H)
        assert fmu.get_outputs() == before                       # refused step: state held
        fmu.set_inputs({**u, "stiffness_scale_r": 0.0})          # clamped to 0.1
        fmu.slave.doStep(20 * H, H)
        clamped = fmu.get_outputs()
    finally:
        fmu.close()
    assert any("non-finite input(s) stiffness_scale_r" in m and m.startswith("[ERROR]") for m in fmu.logs)
    assert any("stiffness_scale_r = 0.0 clamped to 0.1" in m and m.startswith("[WARNING]") for m in fmu.logs)
    rt = CarPlantModel(DATA)
    for _ in range(20):
        rt.step(H, u)
    rt.step(H, {**u, "stiffness_scale_r": 0.1})
    assert all(rt.y[n] == clamped[n] for n in rt.y)
    assert all(math.isfinite(x) for x in clamped.values())


def test_runtime_holds_the_last_valid_scale_on_nan():
    """Driven directly (no FMU glue), a non-finite scale holds the last valid value, with a warning."""
    a, b = CarPlantModel(DATA), CarPlantModel(DATA)
    u = {"delta": 0.05, "vx": 9.0, "bank_angle": 0.0}
    for x in (1.05, math.nan, math.inf):
        a.step(H, {**u, "stiffness_scale_f": x})
        b.step(H, {**u, "stiffness_scale_f": 1.05})
    assert a.y == b.y
    assert [lvl for lvl, msg in a.events if "stiffness_scale_f" in msg] == ["warning"]   # once per episode
    c = CarPlantModel(DATA)
    c.step(H, {**u, "stiffness_scale_r": 1e6})
    assert any("clamped to 10.0" in msg for _, msg in c.events)
