"""The steady-turn calibration of the validation scenarios is the car plant's own rest point
(solved on ``CarPlantModel.derivatives``, no copy of the plant's physics), and the scenarios reach
vehicle data only through ``synthesis.params``."""
from __future__ import annotations

import subprocess
import sys

import pytest

from latobs.fmu_src.car_plant import CarPlantModel
from latobs.synthesis.params import G, load_vehicle
from latobs.validation.scenarios import carplant_steady_turn

KMH = 1 / 3.6


@pytest.mark.parametrize("name", ("sedan", "compact", "suv", "delibasi"))
@pytest.mark.parametrize("ay_g", (0.19, -0.5))
def test_steady_turn_is_the_plants_rest_point_to_round_off(name, ay_g):
    v = load_vehicle(name)
    vx, ay = 50 * KMH, ay_g * G
    ss = carplant_steady_turn(v, vx, ay)
    plant = CarPlantModel({"vehicle": v.as_dict()})
    x = [ss["vy"], ss["yaw_rate"], ss["roll_angle"], 0.0, *ss["F"]]
    d = plant.derivatives(x, {"delta": ss["delta"], "vx": vx, "bank_angle": 0.0})
    k = vx / v.sigma
    assert max(abs(a) for a in d[:4]) < 1e-13 * G
    assert max(abs(a) for a in d[4:]) < 1e-13 * k * v.m * G
    assert ss["ay"] == pytest.approx(ay, rel=1e-15, abs=0)           # the plant's S/m, not a copy's
    assert ss["yaw_rate"] == ay / vx


def test_scenarios_reach_vehicles_only_through_params():
    """The stiffness sweep of paper 002 (delibasi's box) without importing a design module."""
    code = ("import sys; from latobs.validation.scenarios import get_scenario; "
            "s = get_scenario('sine-with-dwell-varying-stiffness'); s.stiffness_ranges('delibasi'); "
            "print(sorted(m for m in sys.modules if m.startswith('latobs.synthesis.') "
            "and m not in ('latobs.synthesis.params',)))")
    # -P: the installed latobs, not the source folder of the working directory
    out = subprocess.run([sys.executable, "-P", "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]", out
