"""Built FMUs (pythonfmu backend) driven through fmpy, against the runtime they package."""
from __future__ import annotations

import math
import zipfile
from pathlib import Path

import numpy as np
import pytest
from fmpy.validation import validate_fmu

from latobs import packaging
from latobs.fmu_src.car_plant import CarPlantModel
from latobs.fmu_src.sideslip_bank_observer import SwitchedPIObserver
from latobs.synthesis import design_file
from latobs.validation.harness import FmuInstance

pytestmark = pytest.mark.slow
H = 0.005
OBS_INPUTS = ("delta", "vx", "yaw_rate", "roll_angle", "roll_rate")


def open_fmu(path: Path, label: str, params: dict | None = None, u0: dict | None = None) -> FmuInstance:
    """Instantiate and initialise, with parameters and the initial inputs set in initialisation mode."""
    fmu = FmuInstance(label, Path(path))
    fmu.start(u0, params)
    return fmu


def observer_inputs(k: int) -> dict:
    """Inputs crossing all speed bands, with an excursion outside the grid and below vx_hold."""
    t = k * H
    vx = 30.0 - 25.0 * min(t / 4.0, 1.0) if t < 5.0 else 0.5
    return {"delta": 0.03 * math.sin(2.0 * t), "vx": vx, "yaw_rate": 0.1 * math.sin(2.0 * t + 0.3),
            "roll_angle": 0.02 * math.sin(2.0 * t + 0.5), "roll_rate": 0.04 * math.cos(2.0 * t + 0.5)}


def run_observer_fmu(fmu: FmuInstance, n: int) -> list[dict]:
    out = []
    for k in range(n):
        fmu.set_inputs(observer_inputs(k))
        fmu.slave.doStep(k * H, H)
        out.append(fmu.get_outputs())
    return out


def run_observer_runtime(design: dict, n: int) -> list[dict]:
    rt = SwitchedPIObserver(design, {})
    rt.initialize(observer_inputs(0))
    out = []
    for k in range(n):
        rt.step(H, observer_inputs(k))
        out.append(dict(rt.y))
    return out


def max_diff(a: list[dict], b: list[dict]) -> float:
    return max(abs(x[k] - y[k]) for x, y in zip(a, b) for k in x)


@pytest.mark.parametrize("name", ["SideslipBankObserver", "SideslipBankObserverTire"])
def test_observer_fmu_equals_runtime(fmu_dir, name, request):
    design = request.getfixturevalue("design_speed" if name == "SideslipBankObserver" else "design_tire")
    fmu = open_fmu(fmu_dir / f"{name}.fmu", name, u0=observer_inputs(0))
    try:
        got = run_observer_fmu(fmu, 1200)
    finally:
        fmu.close()
    ref = run_observer_runtime(design, 1200)
    assert max_diff(got, ref) <= 1e-9
    assert {o["mode"] for o in got} >= {1, 2}
    assert any("outside the design grid" in m for m in fmu.logs)
    assert any("frozen" in m for m in fmu.logs)          # vx = 0.5 m/s at the end


def test_car_plant_fmu_equals_runtime(fmu_dir):
    from latobs.packaging import plant_data

    params = {"mu": 0.8, "scale_f": 0.9, "scale_r": 1.1, "sigma": 0.4}
    fmu = open_fmu(fmu_dir / "CarPlant.fmu", "plant", params)
    rt = CarPlantModel(plant_data("sedan"), params)
    try:
        worst = 0.0
        for k in range(800):
            t = k * H
            u = {"delta": 0.05 * math.sin(3.0 * t), "vx": 25.0 - t, "bank_angle": 0.03 * (t > 1.0)}
            fmu.set_inputs(u)
            fmu.slave.doStep(t, H)
            rt.step(H, u)
            got = fmu.get_outputs()
            worst = max(worst, max(abs(got[k_] - rt.y[k_]) for k_ in got))
    finally:
        fmu.close()
    assert worst <= 1e-9


def test_two_fmus_with_different_gains_in_one_process(tmp_path, design_speed, design_speed_other_gains):
    """Two FMUs named SideslipBankObserver with different gains, loaded together: each runs its own."""
    other = design_speed_other_gains
    gains_a = np.asarray(design_speed["modes"][0]["gains"]["K_P"])
    gains_b = np.asarray(other["modes"][0]["gains"]["K_P"])
    assert np.max(np.abs(gains_a - gains_b)) > 1.0
    dirs = [tmp_path / "a", tmp_path / "b"]
    paths = [packaging.package_design(design_file.write(d, o), o) for d, o in zip((design_speed, other), dirs)]
    assert paths[0].name == paths[1].name == "SideslipBankObserver.fmu"
    fa, fb = open_fmu(paths[0], "a", u0=observer_inputs(0)), open_fmu(paths[1], "b", u0=observer_inputs(0))
    try:
        ga, gb = run_observer_fmu(fa, 600), run_observer_fmu(fb, 600)
    finally:
        fa.close()
        fb.close()
    assert max_diff(ga, run_observer_runtime(design_speed, 600)) <= 1e-9
    assert max_diff(gb, run_observer_runtime(other, 600)) <= 1e-9
    assert max(abs(x["beta_hat"] - y["beta_hat"]) for x, y in zip(ga, gb)) > 1e-5


def test_fmu_refuses_a_swapped_design_file(tmp_path, fmu_dir, design_tire):
    """Gains are checked against the hash baked into the FMU: a replaced design file never runs."""
    path = fmu_dir / "SideslipBankObserver.fmu"
    swapped = tmp_path / "Swapped.fmu"
    with zipfile.ZipFile(path) as zin, zipfile.ZipFile(swapped, "w") as zout:
        for item in zin.infolist():
            data = zin.read(item.filename)
            if item.filename.endswith(".design.json"):
                data = design_file.dumps(design_tire).encode()
            zout.writestr(item, data)
    fmu = open_fmu(swapped, "swapped")
    try:
        fmu.set_inputs(observer_inputs(0))
        with pytest.raises(Exception, match="discard"):
            fmu.slave.doStep(0.0, H)
    finally:
        fmu.close()
    assert any("not the one this FMU was built with" in m for m in fmu.logs)


def test_bad_calls_give_a_status_and_a_log_not_a_crash(fmu_dir):
    fmu = FmuInstance("early", fmu_dir / "SideslipBankObserver.fmu")
    fmu.instantiate()
    try:
        with pytest.raises(Exception, match="discard"):
            fmu.slave.doStep(0.0, H)                      # before initialisation
        assert any("exitInitializationMode first" in m for m in fmu.logs)
    finally:
        fmu.close()
    fmu = open_fmu(fmu_dir / "SideslipBankObserver.fmu", "nan")
    try:
        for k in range(10):
            fmu.set_inputs(observer_inputs(k))
            fmu.slave.doStep(k * H, H)
        before = fmu.get_outputs()
        for bad in (math.nan, math.inf, -math.inf):
            u = dict(observer_inputs(10), yaw_rate=bad)
            fmu.set_inputs(u)
            with pytest.raises(Exception, match="discard"):
                fmu.slave.doStep(10 * H, H)
            assert fmu.get_outputs() == before            # state held
        with pytest.raises(Exception, match="discard"):
            fmu.set_inputs(observer_inputs(10))
            fmu.slave.doStep(10 * H, -H)                  # negative step
        fmu.set_inputs(observer_inputs(10))
        fmu.slave.doStep(10 * H, H)                       # recovers with finite inputs
        assert all(math.isfinite(v) for v in fmu.get_outputs().values())
    finally:
        fmu.close()
    assert sum("non-finite input(s) yaw_rate" in m for m in fmu.logs) == 3
    assert all(m.startswith("[ERROR]") for m in fmu.logs if "non-finite" in m)


def test_plant_fmu_handles_standstill_and_nan(fmu_dir):
    fmu = open_fmu(fmu_dir / "CarPlant.fmu", "plant")
    try:
        for k, vx in enumerate([20.0, 5.0, 0.5, 0.0, 0.0, 70.0]):
            fmu.set_inputs({"delta": 0.05, "vx": vx, "bank_angle": 0.02})
            fmu.slave.doStep(k * H, H)
            assert all(math.isfinite(v) for v in fmu.get_outputs().values())
        fmu.set_inputs({"delta": math.nan, "vx": 10.0, "bank_angle": 0.0})
        with pytest.raises(Exception, match="discard"):
            fmu.slave.doStep(1.0, H)
    finally:
        fmu.close()
    assert any("non-finite input(s) delta" in m for m in fmu.logs)


def test_every_built_fmu_passes_fmpy_validate(fmu_dir):
    fmus = sorted(fmu_dir.glob("*.fmu"))
    assert {p.stem for p in fmus} >= {"SideslipBankObserver", "SideslipBankObserverTire", "CarPlant"}
    for p in fmus:
        assert validate_fmu(str(p)) == [], p.name


def test_uncertified_design_is_never_packaged(tmp_path, design_speed):
    import copy

    bad = copy.deepcopy(design_speed)
    bad["modes"][0]["gains"]["K_I"] = (-np.asarray(bad["modes"][0]["gains"]["K_I"])).tolist()
    path = design_file.write(bad, tmp_path)          # the flag still says certified: the check re-runs
    with pytest.raises(packaging.PackagingError, match="not certified"):
        packaging.package_design(path, tmp_path)
    assert not list(tmp_path.glob("*.fmu"))


def test_a_data_file_read_again_is_a_fresh_copy_of_the_same_content(tmp_path):
    """The framework keeps the data files it parsed (by sha256, the last few): a second instance gets
    its own copy of the same content (a change made by one is not seen by the other), a file of other
    content is parsed again, and the kept files stay bounded."""
    import hashlib
    import json

    from latobs.fmu_src import framework

    framework._PARSED.clear()

    def instance(content: dict, pinned: bool = True):
        """An instance's data as the constructor loads it (the data read alone: no model spec)."""
        raw = json.dumps(content).encode()
        (tmp_path / "d.json").write_bytes(raw)
        probe = framework.Fmi2Slave.__new__(framework.Fmi2Slave)
        probe.data_file, probe.resources, probe._fault = "d.json", str(tmp_path), ""
        probe.data_sha256 = hashlib.sha256(raw).hexdigest() if pinned else ""
        probe._data = probe._load_data()
        assert not probe._fault
        return probe

    content = {"a": [1.0, 0.1, -2.5e-300], "b": {"c": [[1, 2], [3.0, float("1e308")]]}, "n": 3}
    first, second = instance(content), instance(content)
    assert first._data == second._data == content and first._data is not second._data
    first._data["b"]["c"][0][0] = 99
    assert second._data == content and instance(content)._data == content
    assert instance({**content, "n": 4}, pinned=False)._data["n"] == 4
    for k in range(framework._PARSED_KEEP + 3):
        instance({"k": k})
    assert len(framework._PARSED) == framework._PARSED_KEEP
