"""Paper 003 at the measured speed (``synthesis.motorcycle_fault_observer_lpv``): the design's model
is the reduced model at any speed, its steady-turn roll angle is the nonlinear motorcycle's (an
equilibrium solved with fsolve on MotorcyclePlant's own equations, not the observer's), and its
certificate rejects what it must."""
from __future__ import annotations

import copy
import math

import numpy as np
import pytest
from scipy.optimize import fsolve

from latobs.fmu_src.motorcycle_plant import MotorcyclePlantModel
from latobs.packaging import plant_data
from latobs.synthesis import certificate
from latobs.synthesis import motorcycle_fault_observer_lpv as lpv
from latobs.synthesis.motorcycle_model import reduced_model
from latobs.synthesis.params import load_vehicle

VEHICLE = load_vehicle("sharp_motorcycle")


@pytest.fixture(scope="module")
def d(built_fmus) -> dict:
    """The catalogue's design, as ``designs.run`` makes it (solved once per test run: the session's)."""
    return built_fmus.design("MotorcycleFaultObserver", runtime_facts=False)


def _coef(d, key):
    return [np.asarray(x, float) for x in d["model"][key]]


def test_the_model_is_the_reduced_model_at_any_speed(d):
    A, C = _coef(d, "A"), _coef(d, "C")[0]
    for v in (7.6, 11.3, 17.0, 23.9, 32.4):
        r = reduced_model(VEHICLE, v)
        Av = A[0] + v * A[1] + A[2] / v
        np.testing.assert_allclose(Av[:5, :5], r.A, rtol=1e-12, atol=1e-12 * np.abs(r.A).max())
        np.testing.assert_allclose(Av[:5, 5], r.E_phi, rtol=1e-12, atol=1e-12 * np.abs(r.E_phi).max())
        np.testing.assert_allclose(Av[:5, 6], r.B_tau, rtol=1e-12, atol=1e-15)
        assert Av[5, 2] == 1.0 and not np.any(np.delete(Av[5], 2))       # phi' = roll rate
        np.testing.assert_array_equal(C[:, :5], r.C)


@pytest.mark.parametrize("lean", [0.05, 0.2])
def test_steady_turn_roll_is_unbiased_at_every_speed(d, lean):
    """The observer's equilibrium, fed the measurements of the nonlinear motorcycle's steady turn
    (MotorcyclePlant's equations, algebraic tyres, Magic Formula), estimates its roll angle within
    0.1 deg at every speed of 10..30 m/s (the paper's design: -5.7 deg at 12.5 m/s)."""
    A, C, L = _coef(d, "A"), _coef(d, "C")[0], [np.asarray(x, float) for x in d["modes"][0]["gains"]["L"]]
    plant = MotorcyclePlantModel(plant_data("sharp_motorcycle"), {"sigma": 0.0})
    for v in np.arange(10.0, 30.01, 2.5):
        def res(z):
            dx = plant.derivatives([lean, z[0], z[1], z[2], 0.0, 0.0, 0.0, 0.0], {"rider_torque": z[3], "vx": v})
            return [dx[2], dx[3], dx[4], dx[5]]
        z, _, ier, msg = fsolve(res, [0.0, 0.0, 9.81 * math.tan(lean) / v, 0.0], full_output=True, xtol=1e-13)
        assert ier == 1, msg
        y = np.array([z[0], z[2], 0.0])
        b = (1.0, v, 1.0 / v)
        Lv = sum(bk * l for bk, l in zip(b, L))
        s = -np.linalg.solve(sum(bk * a for bk, a in zip(b, A)) - Lv @ C, Lv @ y)
        assert abs(math.degrees(s[5] - lean)) <= 0.1, (v, math.degrees(s[5] - lean))
        assert abs(s[6] - z[3]) <= 0.02 * max(abs(z[3]), 1.0)


def test_one_lyapunov_matrix_and_the_pole_region_hold_on_a_fine_speed_grid(d):
    """Independent of the certificate's corner LMIs: at 200 speeds the stored P gives a decay of at
    least 2 alpha and the poles stay in the region."""
    A, C, L = _coef(d, "A"), _coef(d, "C")[0], [np.asarray(x, float) for x in d["modes"][0]["gains"]["L"]]
    D = np.diag(np.concatenate([d["options"]["x_scale"], d["options"]["f_scale"]]))
    P = np.asarray(d["lyapunov"]["P"], float)
    lo, hi = d["modes"][0]["band"]
    for v in np.linspace(lo, hi, 200):
        b = (1.0, v, 1.0 / v)
        Acl = sum(bk * a for bk, a in zip(b, A)) - sum(bk * l for bk, l in zip(b, L)) @ C
        An = np.linalg.solve(D, Acl @ D)
        Q = An.T @ P + P @ An + 2 * d["options"]["alpha"] * P
        assert np.max(np.linalg.eigvalsh((Q + Q.T) / 2)) <= 0
        ev = np.linalg.eigvals(Acl)
        assert ev.real.max() < -d["options"]["alpha"] and np.abs(ev).max() < d["options"]["radius"]


def test_the_certificate_rejects_larger_gains_a_moved_model_and_a_pmi_with_bad_options(d):
    ok, _ = certificate.certify(d)
    assert ok
    big = copy.deepcopy(d)
    for m in big["modes"]:        # gains and U scaled alike: consistent, but the poles leave the region
        m["gains"]["L"] = [3.0 * np.asarray(x) for x in m["gains"]["L"]]
        m["U"] = [3.0 * np.asarray(x) for x in m["U"]]
    ok, checks = certificate.certify(big)
    failed = {c.name.split(":")[0] for c in checks if not c.passed}
    assert not ok and any("disk" in f or "radius" in f for f in failed), failed
    moved = copy.deepcopy(d)
    moved["model"]["A"][2] = 1.01 * np.asarray(moved["model"]["A"][2])
    ok, checks = certificate.certify(moved)
    assert not ok and any("re-derived" in c.name for c in checks if not c.passed)
    with pytest.raises(ValueError, match="torque_integrators"):
        lpv.DesignOptions(name="x", torque_integrators=0).validate()
    with pytest.raises(ValueError, match="bands"):
        lpv.DesignOptions(name="x", bands=((10.0, 20.0), (21.0, 30.0))).validate()
