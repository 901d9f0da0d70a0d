"""Validation manoeuvres: the registry of the scenarios that drive a plant FMU.

A :class:`Scenario` gives the plant's input signals on any time grid (SI units, keyed by FMU
variable name); :data:`SCENARIOS` holds the registered ones, :func:`get_scenario` fetches one with
validated overrides. The manoeuvres themselves live in :mod:`.car_manoeuvres`, :mod:`.w1_steer`
and :mod:`.motorcycle_manoeuvres`, the base class in :mod:`.scenario_base`; docs/validation.md
lists them.
"""
from __future__ import annotations

import dataclasses

from .car_manoeuvres import (BankBraking, DoubleLaneChange, Fishhook, FishhookVaryingStiffness, RandomManoeuvre,
                             SineWithDwell, SineWithDwellVaryingStiffness, SteadyTurn, StiffnessSweep,
                             carplant_steady_turn)
from .motorcycle_manoeuvres import MotorcycleLaneChange
from .scenario_base import (DEG, KMH, MPH, SPEED_BANDS_KMH, SPEED_MODES_KMH, Scenario, steady_state_ay_gain,
                            steer_for_ay, understeer_gradient)
from .w1_steer import W1_DEN, W1_NUM, W1Steer, w1_gain_squared

__all__ = ["BankBraking", "DEG", "DoubleLaneChange", "Fishhook", "FishhookVaryingStiffness", "KMH", "MPH",
           "MotorcycleLaneChange", "RandomManoeuvre", "SCENARIOS", "SPEED_BANDS_KMH", "SPEED_MODES_KMH", "Scenario",
           "SineWithDwell", "SineWithDwellVaryingStiffness", "SteadyTurn", "StiffnessSweep", "UnknownScenarioError",
           "W1Steer", "W1_DEN", "W1_NUM", "carplant_steady_turn", "get_scenario", "register", "scenario_names",
           "steady_state_ay_gain", "steer_for_ay", "understeer_gradient", "w1_gain_squared"]


# --------------------------------------------------------------------------------------------
# registry
# --------------------------------------------------------------------------------------------
class UnknownScenarioError(KeyError):
    """Asked for a scenario that is not registered (the message lists the known ones)."""

    def __str__(self) -> str:  # KeyError would print the message in quotes
        return str(self.args[0]) if self.args else ""


SCENARIOS: dict[str, Scenario] = {
    s.name: s for s in (
        BankBraking(), SteadyTurn(), DoubleLaneChange(), SineWithDwell(), Fishhook(),
        # paper 001's operating range (speed modes 11.5/14.5/18 m/s): the same lane change at 15 m/s
        DoubleLaneChange(name="double-lane-change-15",
                         description="The double lane change at 15 m/s (paper 001's speed range): open-loop "
                                     "road-wheel steering for a 4 m/s^2 steady-state lateral acceleration.",
                         speed=15.0),
        RandomManoeuvre(),
        # paper 002 (Delibasi 2014), vehicle delibasi: W1-filtered steering, swept stiffness box
        W1Steer(), SineWithDwellVaryingStiffness(), FishhookVaryingStiffness(),
        # paper 003 (Ichalal 2017): the motorcycle double lane change, plant MotorcyclePlant
        MotorcycleLaneChange(),
    )
}


def scenario_names() -> list[str]:
    return sorted(SCENARIOS)


def get_scenario(name: str | Scenario, **overrides) -> Scenario:
    """The registered scenario ``name``; keyword overrides replace fields (validated).

    Raises UnknownScenarioError (a KeyError) naming the known scenarios when ``name`` is unknown, and TypeError naming the
    scenario's fields when an override is not one of them.
    """
    if isinstance(name, Scenario):
        base = name
    else:
        if name not in SCENARIOS:
            raise UnknownScenarioError(f"unknown scenario {name!r}; known scenarios: {', '.join(scenario_names())}")
        base = SCENARIOS[name]
    if not overrides:
        return base
    fields = {f.name for f in dataclasses.fields(base)}
    bad = sorted(set(overrides) - fields)
    if bad:
        raise TypeError(f"scenario {base.name!r} has no field(s) {', '.join(bad)}; fields: {', '.join(sorted(fields))}")
    return dataclasses.replace(base, **overrides)


def register(scenario: Scenario) -> Scenario:
    """Add (or replace) a scenario in the registry; returns it."""
    if not scenario.name:
        raise ValueError("a registered scenario needs a name")
    SCENARIOS[scenario.name] = scenario
    return scenario
