"""Paper 001's guarantee, measured: zero enclosure violations over 200 randomised co-simulations.

Each run: CarPlant FMU with LINEAR tires (the paper's tire model, eq. 6) and axle stiffness
scales drawn uniformly inside the design's +-20 % box, the LateralIntervalObserver FMU, a seeded
random manoeuvre whose speed sweeps across all three speed bands (10-13-16-20 m/s) and whose
steering stays in the linear tire range (random-manoeuvre). Every bound (vy and beta at the CG,
yaw rate, front and rear axle forces) must contain the truth at every communication point.

Paper 001's model class (eq. 9) has no roll. The sedan's CarPlant rolls (CG 0.5 m above the roll
axis): its tires see the kinematic slip hr*phidot/vx, a model error of up to ~30 m/s^3 on x3' and
~12 rad/s^3 on x4' that the stiffness box does not contain (measured in these manoeuvres). So:
  * the guarantee campaign uses CarPlant on the sedan with the roll coupling removed (hr -> 0),
    i.e. a plant inside the model class: zero violations required, 200 runs;
  * on the rolling sedan, the design option ``model_error_bound`` that covers that error restores
    zero violations (50 runs), at the price of wider bounds.
"""
from __future__ import annotations

import numpy as np
import pytest

from latobs.packaging import complete_runtime_data
from latobs import packaging
from latobs.synthesis import design_file, designs

from conftest import HOST_ONLY

pytestmark = [pytest.mark.slow, pytest.mark.schedule_first]
RUNS = 200
SIGNALS = ("vy", "beta", "yaw_rate", "Fyf", "Fyr")


ROLL_ERROR_BOUND = (0.0, 0.0, 36.0, 15.0)   # 1.2 x the largest residual measured on the rolling sedan


@pytest.fixture(scope="module")
def fmus(tmp_path_factory, built_fmus):
    """The FMUs of latobs build's default backend (native C where a C compiler is present, whose
    outputs equal the pythonfmu FMUs' bit for bit: tests/cbackend/test_c_lateral_interval_observer.py and
    tests/cbackend/test_c_car_plant.py; five times faster per run): the default observer and plant
    of the session build, the rigid plant and the robust design built here."""
    out = tmp_path_factory.mktemp("fmus_001")
    backend = packaging.resolve_backend("auto", packaging.OBSERVERS["LateralIntervalObserver"])[0]
    plant_backend = packaging.resolve_backend("auto", packaging.PLANTS["CarPlant"])[0]
    data = built_fmus.design("LateralIntervalObserver")
    observer = built_fmus.get("LateralIntervalObserver", backend)
    plant_rigid = packaging.package_plant("CarPlant", "sedan_no_roll", out, plant_backend,  # paper 001's model class
                                          platforms=HOST_ONLY if plant_backend == "c" else None)
    plant = built_fmus.get("CarPlant", plant_backend)
    robust = complete_runtime_data(designs.run("LateralIntervalObserver", model_error_bound=ROLL_ERROR_BOUND))
    robust_dir = out / "robust"
    observer_robust = packaging.package_design(design_file.write(robust, robust_dir), robust_dir, backend,
                                               platforms=HOST_ONLY if backend == "c" else None)
    return {"plant_rigid": plant_rigid, "plant": plant, "observer": observer, "observer_robust": observer_robust,
            "box": tuple(data["options"]["box"])}


def campaign(plant, observer, runs: int, box: tuple[float, float]):
    """``runs`` co-simulations (seed k, stiffness scales drawn in the box), spread over the cores in
    fresh processes (spawn: no FMU state inherited); the same rows, in seed order, as one loop."""
    import multiprocessing
    import os
    from concurrent.futures import ProcessPoolExecutor

    from enclosure_runs import run_cases

    rng = np.random.default_rng(2026)
    cases = [(k, *(1.0 + rng.uniform(-b, b) for b in box)) for k in range(runs)]
    workers = max(1, min(os.cpu_count() or 1, 4))
    chunks = [cases[i::workers] for i in range(workers)]
    with ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn")) as pool:
        parts = list(pool.map(run_cases, [str(plant)] * workers, [str(observer)] * workers, chunks))
    return sorted((r for part in parts for r in part), key=lambda r: r["seed"])


def _check(rows, label, box, capsys):
    violations = {s: sum(r[f"{s}_violations"] for r in rows) for s in SIGNALS}
    widths = {s: round(float(np.mean([r[f"{s}_width"] for r in rows])), 4) for s in SIGNALS}
    with capsys.disabled():
        print(f"\n001 enclosure campaign, {label}: {len(rows)} runs, stiffness scales in +-{box[0]:.0%} / "
              f"+-{box[1]:.0%}, violations {violations}, mean widths {widths}")
    assert all(r["modes"] == [1, 2, 3] for r in rows)          # every run crosses the three speed modes
    assert violations == {s: 0 for s in SIGNALS}, [r for r in rows if any(r[f"{s}_violations"] for s in SIGNALS)][:5]


def test_zero_enclosure_violations_over_200_randomised_cosimulations(fmus, capsys):
    rows = campaign(fmus["plant_rigid"], fmus["observer"], RUNS, fmus["box"])
    _check(rows, "CarPlant with linear tires, no roll (the model class)", fmus["box"], capsys)


def test_a_model_error_bound_covers_the_rolling_car(fmus, capsys):
    rows = campaign(fmus["plant"], fmus["observer_robust"], 50, fmus["box"])
    _check(rows, f"CarPlant with linear tires and roll, model_error_bound {ROLL_ERROR_BOUND}", fmus["box"], capsys)


STEPS = (0.005, 0.02, 0.05, 0.1, 0.2)


@pytest.fixture(scope="module")
def step_rows(fmus):
    """5 plants of the campaign (the first seeds, their stiffness scales) x the 5 steps, 20 s."""
    from enclosure_runs import step_table

    table, rows = step_table(str(fmus["plant_rigid"]), str(fmus["observer"]), 5, fmus["box"], list(STEPS), 20.0)
    return table, rows


def test_every_communication_step_encloses_bounded_or_is_refused(fmus, step_rows, capsys, built_fmus):
    """At every step up to max_communication_step() (0.452 s: every step of the table): zero
    violations, the vy width after settling bounded and not growing (the last third of a run
    against the middle third); above it, every run refused at once with the limit named (once
    50 ms made the widths 1e30 m/s, silently; then 50-200 ms were refused)."""
    from latobs.fmu_src.lateral_interval_observer import IntervalObserver

    table, rows = step_rows
    hmax = IntervalObserver(built_fmus.design("LateralIntervalObserver")).max_communication_step()
    with capsys.disabled():
        print(f"\n001 at every step (max_communication_step {hmax:g} s): {table}")
    for h in STEPS:
        s = table[h]
        if h <= hmax:
            assert s["refused"] == 0 and s["violations"] == 0, (h, s)
            assert s["vy_width_max"] < 1.0 and s["growth"] < 1.5, (h, s)
        else:
            assert s["refused"] == s["runs"] == 5, (h, s)
            assert all("exceeds this FMU's longest step" in r["refused"] for r in rows if r["h"] == h)


def test_vy_width_at_20_ms_within_25_percent_of_5_ms(step_rows):
    """The 20 ms bounds are as tight as the 5 ms ones, within 25 % (200 plants x 60 s: 0.040 m/s at
    20 ms against 0.067 at 5 ms, where the continuous correction alone gave 0.160 at 20 ms): from
    10 ms the sampled-measurement correction is intersected with the continuous one."""
    table, _ = step_rows
    assert table[0.02]["vy_width_mean"] <= 1.25 * table[0.005]["vy_width_mean"], table
