"""The independent exact linear plant (tests/linear_plant_000.py) against paper 000's design model.

(a) Its first-principles derivation (sympy) agrees with ``latobs.synthesis.bicycle_roll_model``
    entry by entry to 1e-12 relative at three speeds for the sedan, compact and suv sets.
(b) Its steady turn has the requested lateral acceleration and is a fixed point of the ODE.
"""
from __future__ import annotations

import ast
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.linalg import expm

import linear_plant_000 as lp
from latobs.synthesis import bicycle_roll_model as brm
from latobs.synthesis.params import G as PROJECT_G
from latobs.synthesis.params import load_vehicle

G = lp.G  # m/s^2 (equal to the project's G: test_helper_is_independent_of_the_project)
VEHICLES = ("sedan", "compact", "suv")
SPEEDS = (10.0, 17.5, 25.0)  # m/s: paper 000's speed modes are 10, 17.5 and 25 m/s
REL = 1e-12


def _params(name: str) -> dict[str, float]:
    v = load_vehicle(name)
    return {k: v.value(k) for k in lp.PARAMETERS}


def _differences(mine: np.ndarray, theirs: np.ndarray, label: str) -> list[str]:
    """Entries (1-based, as in the paper) that differ by more than REL relative."""
    out = []
    for idx in np.ndindex(mine.shape):
        a, b = float(mine[idx]), float(theirs[idx])
        scale = max(abs(a), abs(b))
        if (scale == 0.0 and a != b) or (scale > 0 and abs(a - b) > REL * scale):
            out.append(f"{label}({idx[0] + 1},{idx[1] + 1}): derived {a:.17g}, design model {b:.17g}")
    return out


def test_helper_is_independent_of_the_project():
    """The helper imports nothing from latobs (its agreement would otherwise prove nothing)."""
    tree = ast.parse(Path(lp.__file__).read_text())
    mods = [a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names]
    mods += [n.module or "" for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)]
    assert not [m for m in mods if m.startswith("latobs") or "synthesis" in m or "fmu_src" in m], mods
    assert lp.G == PROJECT_G


def test_derivation_is_linear_and_both_roll_balances_agree():
    """(N), (Y), (R) solve uniquely; the roll balance about the roll axis follows from them."""
    d = lp.derivation()
    assert d["A"].shape == (4, 4) and d["B"].shape == (4, 1) and d["F"].shape == (4, 1)
    assert lp.roll_axis_form_residual() == 0


@pytest.mark.parametrize("vehicle", VEHICLES)
def test_derivation_equals_design_model(vehicle):
    """(a) A, B, F of the derivation equal brm.model(vehicle, vx) to 1e-12 relative, entry by entry
    (zeros exactly), at 10, 17.5 and 25 m/s."""
    p = _params(vehicle)
    v = load_vehicle(vehicle)
    diffs = []
    for vx in SPEEDS:
        A, B, F = lp.model(p, vx)
        M = brm.model(v, vx)
        for mine, theirs, label in ((A, M.A, "A"), (B, M.B, "B"), (F, M.F, "F")):
            assert mine.shape == np.asarray(theirs).shape
            diffs += [f"vx={vx}: " + s for s in _differences(mine, np.asarray(theirs), label)]
        assert np.array_equal(M.C, np.eye(4)[1:]), "measurements y = [r, phi, phi']"
    assert not diffs, f"{vehicle}: the design model differs from the derivation:\n" + "\n".join(diffs)


@pytest.mark.parametrize("vehicle", VEHICLES)
def test_relaxed_derivation_equals_the_relaxed_design_model(vehicle):
    """The derivation with the axle forces as relaxed states (``lp.relaxed_model``: the same balances,
    sigma / vx F' + F = C alpha) equals ``brm.relaxed_lpv_coefficients`` at the same speeds, entry by
    entry to 1e-11 relative of each matrix's largest entry (the relaxation rows are ~1e4 x the others)."""
    v = load_vehicle(vehicle)
    p = {**_params(vehicle), "sigma": 0.5}
    veh = v.with_values(sigma=0.5)
    for vx in SPEEDS:
        A, B, F = lp.relaxed_model(p, vx)
        M = brm.evaluate(brm.relaxed_lpv_coefficients(veh), vx)
        for mine, theirs in ((A, M.A), (B, M.B), (F, M.F)):
            assert mine.shape == theirs.shape
            assert np.max(np.abs(mine - theirs)) <= 1e-11 * np.max(np.abs(mine)), (vx, mine, theirs)
            assert np.array_equal(mine == 0, theirs == 0)       # the zeros exactly where the derivation's
        assert np.array_equal(M.C, np.eye(6)[1:4]), "measurements y = [r, phi, phi']"


def test_hand_entries_of_the_derivation():
    """A few entries written out by hand from (N), (Y), (R) (the three ERRATA corrections among them)."""
    p = _params("sedan")
    m, Iz, Ix, lf, lr, hr, Kr, br, Cf, Cr = (p[k] for k in lp.PARAMETERS)
    vx = 17.5
    A, B, F = lp.model(p, vx)
    Ieq = Ix + m * hr**2
    assert A[0, 0] == pytest.approx(-Ieq * (Cf + Cr) / (Ix * m * vx), rel=1e-14)
    assert A[0, 1] == pytest.approx(-1 - Ieq * (lf * Cf - lr * Cr) / (Ix * m * vx**2), rel=1e-14)
    assert A[0, 2] == pytest.approx(hr * (m * G * hr - Kr) / (Ix * vx), rel=1e-14)
    assert A[0, 3] == pytest.approx(-hr * br / (Ix * vx), rel=1e-14)        # printed: -hr Lr/(Ix Vx)
    assert A[1, 1] == pytest.approx(-(lf**2 * Cf + lr**2 * Cr) / (Iz * vx), rel=1e-14)   # printed: Ix
    assert A[3, 0] == pytest.approx(-hr * (Cf + Cr) / Ix, rel=1e-14)
    assert B[3, 0] == pytest.approx(hr * Cf / Ix, rel=1e-14)                 # printed: Cf/Ix
    assert B[0, 0] == pytest.approx(Ieq * Cf / (Ix * m * vx), rel=1e-14)
    assert F[:, 0] == pytest.approx([-G / vx, 0.0, 0.0, 0.0], rel=1e-14)


@pytest.mark.parametrize("vehicle", VEHICLES)
@pytest.mark.parametrize("vx", SPEEDS)
def test_steady_state_turn(vehicle, vx):
    """(b) steady_state: ay = vx (beta' + r) = vx r is the requested one, the tire forces / m give
    the same ay, x_ss is a fixed point of x' = A x + B delta (flat road), the roll angle is the
    roll gradient's m hr ay / (Kr - m g hr) and a left turn leans the body right (phi > 0)."""
    p = _params(vehicle)
    ay = 0.19 * G
    delta, x = lp.steady_state(p, vx, ay)
    A, B, F = lp.model(p, vx)
    xdot = A @ x + B[:, 0] * delta
    scale = np.abs(A) @ np.abs(x) + np.abs(B[:, 0]) * abs(delta)
    assert np.all(np.abs(xdot) <= 1e-12 * scale + 1e-300), xdot
    assert x[3] == 0.0 and vx * (xdot[0] + x[1]) == pytest.approx(ay, rel=1e-12)
    ay_forces = lp.lateral_acceleration_row(p, vx) @ np.r_[vx * x[0], x[1], x[2], x[3], delta, 0.0]
    assert ay_forces == pytest.approx(ay, rel=1e-12)
    assert x[2] == pytest.approx(p["m"] * p["hr"] * ay / (p["Kr"] - p["m"] * G * p["hr"]), rel=1e-12)
    assert delta > 0 and x[1] > 0 and x[2] > 0
    # the linear bicycle's steady-state steer (roll does not change it: no roll steer)
    L = p["lf"] + p["lr"]
    k_us = p["m"] / L * (p["lr"] / p["Cf"] - p["lf"] / p["Cr"])
    assert delta == pytest.approx(ay * (L + k_us * vx**2) / vx**2, rel=1e-12)


@pytest.mark.parametrize("vehicle", ("compact", "suv"))
def test_steady_state_is_a_fixed_point_of_the_integration(vehicle):
    """(b) integrated from x_ss with delta_ss held, the ODE stays at x_ss (DOP853, tight tolerances)."""
    p = _params(vehicle)
    vx = 50 / 3.6
    delta, x = lp.steady_state(p, vx, 0.19 * G)
    t = np.linspace(0.0, 5.0, 51)
    sim = lp.simulate(p, lambda s: vx, lambda s: delta, lambda s: 0.0, t, x0=x)
    assert np.max(np.abs(sim["x"] - x)) < 1e-8      # rad, rad/s: the integration's own error (~1e-10)
    assert sim["ay"] == pytest.approx(np.full_like(t, 0.19 * G), abs=1e-6)   # m/s^2
    assert sim["y"].shape == (len(t), 3) and np.array_equal(sim["y"], sim["x"][:, 1:])


def test_simulate_matches_the_matrix_exponential():
    """At constant speed and held inputs simulate() equals x(t) = e^{At} x0 + A^-1 (e^{At} - I) (B u + F w)."""
    p = _params("suv")
    vx, delta, bank = 20.0, 0.01, 0.05
    A, B, F = lp.model(p, vx)
    x0 = np.array([0.002, -0.01, 0.003, 0.0])
    t = np.linspace(0.0, 3.0, 31)
    sim = lp.simulate(p, lambda s: vx, lambda s: delta, lambda s: bank, t, x0=x0)
    w = B[:, 0] * delta + F[:, 0] * bank
    for i, ti in enumerate(t):
        E = expm(A * ti)
        ref = E @ x0 + np.linalg.solve(A, (E - np.eye(4)) @ w)
        assert np.allclose(sim["x"][i], ref, rtol=1e-8, atol=1e-11), (ti, sim["x"][i], ref)


def test_bank_with_the_wheels_straight():
    """delta = 0 on a bank phi_r: in the steady state the tires carry the downhill gravity component
    and the centripetal force of the turn that the bank induces (r = 0 only for a neutral-steer
    car, lf Cf = lr Cr): ay = (Fyf + Fyr)/m = g phi_r + vx r, and the body rolls by
    m hr ay / (Kr - m g hr) as in a flat turn of that ay."""
    p = _params("compact")
    vx, bank = 15.0, 0.05
    A, B, F = lp.model(p, vx)
    x = np.linalg.solve(A, -F[:, 0] * bank)
    ay = lp.lateral_acceleration_row(p, vx) @ np.r_[vx * x[0], x[1], x[2], x[3], 0.0, bank]
    assert ay == pytest.approx(G * bank + vx * x[1], rel=1e-10)
    m, hr, Kr = p["m"], p["hr"], p["Kr"]
    assert x[2] == pytest.approx(m * hr * ay / (Kr - m * G * hr), rel=1e-10)
    assert x[3] == 0.0 and math.isfinite(x[0])
    neutral = dict(p, Cr=p["Cf"] * p["lf"] / p["lr"])      # lf Cf = lr Cr: no induced turn
    A, B, F = lp.model(neutral, vx)
    x = np.linalg.solve(A, -F[:, 0] * bank)
    assert abs(x[1]) < 1e-15
    assert x[2] == pytest.approx(m * G * hr * bank / (Kr - m * G * hr), rel=1e-10)
