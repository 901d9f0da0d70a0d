"""Paper 002's validation scenarios: W1-filtered random steering and the swept stiffness box.

Everything is recomputed here from first principles (W1's coefficients, the bicycle model's
steady-state gain, the per-tyre stiffness box of vehicles.md), not from the module's helpers.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.signal import welch

from latobs.synthesis.params import G, load_vehicle
from latobs.validation.scenarios import SCENARIOS, get_scenario

KMH = 1 / 3.6
VEH = load_vehicle("delibasi")


def w1_sq(f):
    """|W1(j 2 pi f)|^2, W1 = 39.4784 / (s^2 + 8.8858 s + 39.4784) (vehicles.md, delibasi)."""
    s = 2j * np.pi * np.asarray(f, float)
    return np.abs(39.4784 / (s ** 2 + 8.8858 * s + 39.4784)) ** 2


def ss_gain(v):
    """(m/s^2)/rad, linear bicycle, steady state."""
    L = VEH.lf + VEH.lr
    K = VEH.m / L * (VEH.lr / VEH.Cf - VEH.lf / VEH.Cr)
    return v ** 2 / (L + K * v ** 2)


# ------------------------------------------------------------------------------------------
# w1-steer
# ------------------------------------------------------------------------------------------
def test_w1_steer_spectrum_follows_w1():
    """The PSD of delta is |W1|^2 up to a constant: per band (0.1 ... 5 Hz, where |W1|^2 falls
    from 1 to 1/626) the Welch PSD divided by |W1|^2 stays within 20 % of its median (estimate
    scatter ~5 % with ~117 averaged segments of a 600 s run); a white or first-order spectrum
    would be off by 10x - 600x at 3-5 Hz. Also the power below 1 Hz over the power above 3 Hz
    matches the integral of |W1|^2 within 15 %."""
    s = get_scenario("w1-steer", duration=600.0)
    dt = 0.005
    d = s.signals(s.time_grid(dt), VEH)["delta"]
    f, p = welch(d, fs=1 / dt, nperseg=2048)
    ratio = p / w1_sq(f)
    edges = [0.1, 0.3, 0.6, 1.0, 1.5, 2.0, 3.0, 4.0, 5.0]
    bands = [np.mean(ratio[(f >= lo) & (f < hi)]) for lo, hi in zip(edges[:-1], edges[1:])]
    med = np.median(bands)
    assert all(abs(b / med - 1) < 0.2 for b in bands), [round(b / med, 3) for b in bands]
    lo, hi = (f > 0) & (f <= 1.0), (f >= 3.0) & (f <= 50.0)
    measured = np.sum(p[lo]) / np.sum(p[hi])
    fine = np.linspace(1e-4, 50.0, 500001)
    g = w1_sq(fine)
    expected = np.sum(g[fine <= 1.0]) / np.sum(g[fine >= 3.0])
    assert measured == pytest.approx(expected, rel=0.15), (measured, expected)
    assert expected > 50                                      # the band limit is what is tested


def test_w1_steer_amplitude_speed_and_start():
    s = get_scenario("w1-steer")
    assert s.duration == pytest.approx(30.0) and s.speed == pytest.approx(30 * KMH)
    assert 20 * KMH < s.speed < 40 * KMH                           # inside paper 002's speed box
    t = s.time_grid(0.005)
    sig = s.signals(t, VEH)
    d = sig["delta"]
    assert np.all(sig["vx"] == s.speed) and np.all(sig["bank_angle"] == 0.0)
    rms = math.sqrt(np.mean(d ** 2))
    assert rms == pytest.approx(1.0 / ss_gain(s.speed), rel=1e-9)  # ay_rms = 1 m/s^2
    assert math.degrees(rms) == pytest.approx(2.68, abs=0.01)
    assert d[0] == 0.0 and abs(d[1]) < 1e-4                         # starts from straight driving
    peak_ay = np.max(np.abs(d)) * ss_gain(s.speed)
    assert 2.0 < peak_ay < 4.0                                      # linear range, ~3 m/s^2
    assert s.info(VEH)["ay_ss_peak_mps2"] == pytest.approx(peak_ay, rel=1e-12)


def test_w1_steer_is_reproducible_from_its_seed():
    s = get_scenario("w1-steer")
    t5, t10 = s.time_grid(0.005), s.time_grid(0.01)
    a = s.signals(t5, VEH)["delta"]
    assert np.array_equal(a, s.signals(t5, VEH)["delta"])          # same seed, same signal
    # the same manoeuvre on a coarser communication grid (samples of the same internal signal)
    np.testing.assert_allclose(s.signals(t10, VEH)["delta"], a[::2], rtol=0, atol=1e-12)
    b = get_scenario("w1-steer", seed=1).signals(t5, VEH)["delta"]
    assert abs(np.corrcoef(a, b)[0, 1]) < 0.5                       # another seed, another signal


# ------------------------------------------------------------------------------------------
# swept stiffness scenarios
# ------------------------------------------------------------------------------------------
# per-axle box over the centre 2 x 600 N/deg: the per-tyre ranges divided by 600 N/deg
F_BOX = (590 / 600, 610 / 600)
R_BOX = (550 / 600, 650 / 600)


@pytest.mark.parametrize("name", ["sine-with-dwell-varying-stiffness", "fishhook-varying-stiffness"])
def test_stiffness_sweep_stays_in_the_box_and_reaches_both_ends(name):
    s = get_scenario(name)
    t = s.time_grid(0.005)
    p = s.parameter_signals(t, VEH)
    assert set(p) == {"stiffness_scale_f", "stiffness_scale_r"}
    for key, (lo, hi) in (("stiffness_scale_f", F_BOX), ("stiffness_scale_r", R_BOX)):
        x = p[key]
        assert np.all(x >= lo - 1e-12) and np.all(x <= hi + 1e-12), key
        assert x.min() == pytest.approx(lo, abs=1e-12) and x.max() == pytest.approx(hi, abs=1e-12), key
        assert np.max(np.abs(np.diff(x))) < (hi - lo) * 0.01        # smooth, no jump
    # in physical units: the delibasi box 67.6..69.9 kN/rad front, 63.0..74.5 kN/rad rear
    cf, cr = p["stiffness_scale_f"] * VEH.Cf, p["stiffness_scale_r"] * VEH.Cr
    assert (cf.min(), cf.max()) == pytest.approx((67609.0, 69900.9), abs=0.1)
    assert (cr.min(), cr.max()) == pytest.approx((63025.4, 74484.5), abs=0.1)
    # rear from its minimum up and back, front in antiphase
    assert p["stiffness_scale_r"][0] == pytest.approx(R_BOX[0]) and p["stiffness_scale_f"][0] == pytest.approx(F_BOX[1])
    assert np.corrcoef(p["stiffness_scale_f"], p["stiffness_scale_r"])[0, 1] == pytest.approx(-1.0, abs=1e-9)
    info = s.info(VEH)
    assert info["stiffness_scale_r_range"] == pytest.approx(list(R_BOX), rel=1e-12)
    assert info["stiffness_scale_f_range"] == pytest.approx(list(F_BOX), rel=1e-12)


@pytest.mark.parametrize("name, base", [("sine-with-dwell-varying-stiffness", "sine-with-dwell"),
                                        ("fishhook-varying-stiffness", "fishhook")])
def test_varying_stiffness_manoeuvres_at_35_kmh(name, base):
    """The standard shapes at 35 km/h, 2.5 x the steering angle of a 0.3 g steady state at 35 km/h."""
    s = get_scenario(name)
    v = 35 * KMH
    t = s.time_grid(0.001)
    sig = s.signals(t, VEH)
    assert np.all(sig["vx"] == pytest.approx(v)) and np.all(sig["bank_angle"] == 0.0)
    amp = 2.5 * 0.3 * G / ss_gain(v)
    assert np.max(np.abs(sig["delta"])) == pytest.approx(amp, rel=1e-4)
    assert math.degrees(amp) == pytest.approx(14.7, abs=0.05)
    over = {"speed": v, "amplitude_factor": 2.5} | ({"reference_speed": v} if base == "fishhook" else {})
    ref = get_scenario(base, **over).signals(t, VEH)
    assert np.array_equal(sig["delta"], ref["delta"])              # the same manoeuvre shape
    assert s.duration == SCENARIOS[base].duration


def test_sweep_needs_a_stiffness_box():
    s = get_scenario("sine-with-dwell-varying-stiffness")
    with pytest.raises(ValueError, match="no cornering stiffness box"):
        s.parameter_signals(np.arange(3.0), "sedan")
    p = get_scenario(s.name, scale_f_range=(0.9, 1.1), scale_r_range=(0.8, 1.2)).parameter_signals(
        np.linspace(0, s.duration, 601), "sedan")
    assert (p["stiffness_scale_f"].min(), p["stiffness_scale_f"].max()) == pytest.approx((0.9, 1.1))
    assert (p["stiffness_scale_r"].min(), p["stiffness_scale_r"].max()) == pytest.approx((0.8, 1.2))


# ------------------------------------------------------------------------------------------
# existing scenarios unchanged
# ------------------------------------------------------------------------------------------
# integral of |signal| dt on the 10 ms grid for the sedan, from the scenarios before paper 002
FINGERPRINTS = {
    "bank-braking": {"delta": 0.3333289468309436, "vx": 517.675, "bank_angle": 1.1867366248935443},
    "double-lane-change": {"delta": 0.11047172107087602, "vx": 200.22222222222226, "bank_angle": 0.0},
    "sine-with-dwell": {"delta": 0.19186585396870331, "vx": 133.5555555555556, "bank_angle": 0.0},
    "fishhook": {"delta": 0.654863452447716, "vx": 161.13556800000003, "bank_angle": 0.0},
    "double-lane-change-15": {"delta": 0.18558952655257613, "vx": 135.15, "bank_angle": 0.0},
    "random-manoeuvre": {"delta": 0.11140622539232997, "vx": 87.45131117633096, "bank_angle": 0.0},
}


@pytest.mark.parametrize("name", sorted(FINGERPRINTS))
def test_existing_scenarios_unchanged(name):
    s = get_scenario(name)
    t = s.time_grid(0.01)
    sig = s.signals(t, "sedan")
    assert set(sig) == set(FINGERPRINTS[name])
    for k, ref in FINGERPRINTS[name].items():
        assert float(np.sum(np.abs(sig[k])) * 0.01) == pytest.approx(ref, rel=1e-12, abs=1e-15), k
    assert s.parameter_signals(t, "sedan") == {}                   # they drive no stiffness input


def test_new_scenarios_registered():
    assert {"w1-steer", "sine-with-dwell-varying-stiffness", "fishhook-varying-stiffness"} <= set(SCENARIOS)
    for name in ("w1-steer", "sine-with-dwell-varying-stiffness", "fishhook-varying-stiffness"):
        assert SCENARIOS[name].plant == "CarPlant" and "Paper 002" in SCENARIOS[name].description
