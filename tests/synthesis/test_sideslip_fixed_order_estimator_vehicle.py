"""Paper 002 for a vehicle the user gives: its own parameters in the design file, a missing
stiffness range as a user error, speed bands of bounded beta/r variation."""
from __future__ import annotations

import math
from importlib import resources

import pytest

from latobs.cli import main
from latobs.synthesis import designs, sideslip_fixed_order_estimator as f
from latobs.synthesis.params import VehicleParameterError, load_vehicle

FAST = {"polish": False, "grid": (5, 5, 5)}     # Lemma 5 + certificate on a 5^3 grid (DesignOptions)


def _shipped(name: str) -> str:
    return (resources.files("latobs.synthesis") / "vehicles" / f"{name}.toml").read_text()


def test_a_vehicle_without_stiffness_ranges_is_a_user_error_naming_the_key(tmp_path, capsys):
    with pytest.raises(VehicleParameterError, match=r"needs a range 'Cf' \(N/rad\).*\[ranges\].*Cf = \{ min ="):
        designs.run("SideslipFixedOrderEstimator", "sedan")
    rc = main(["design", "SideslipFixedOrderEstimator", "--vehicle", "sedan", "--out", str(tmp_path)])
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1 and "'Cf'" in err and "[ranges]" in err, err
    assert not any(tmp_path.iterdir())


def test_a_file_with_a_shipped_name_keeps_its_own_values(tmp_path):
    """A TOML called mbds_250lm with other numbers is refused when it is loaded (its FMUs would take
    the shipped set's names): the message asks for a name of its own. Renamed, the design file
    carries the TOML's values (every parameter and range), never the shipped set's."""
    text = (_shipped("mbds_250lm")
            .replace("m  = { value = 982.0,", "m  = { value = 1250.0,")
            .replace("Cf = { value = 70000.0,", "Cf = { value = 61000.0,")
            .replace("lr = { value = 1.07,", "lr = { value = 1.19,")
            .replace("speed = { min = 15.0, max = 63.0", "speed = { min = 20.0, max = 30.0"))
    path = tmp_path / "mbds_250lm.toml"
    path.write_text(text)
    with pytest.raises(VehicleParameterError, match="give it a name of its own"):
        load_vehicle(path)
    path.write_text(text.replace('name = "mbds_250lm"', 'name = "my_mbds_250lm"', 1))
    mine, shipped = load_vehicle(path), load_vehicle("mbds_250lm")
    assert mine.name == "my_mbds_250lm" and mine.value("m") != shipped.value("m")
    d = designs.run("SideslipFixedOrderEstimator", str(path), **FAST)
    assert d["certified"]
    got = d["vehicle"]["parameters"]
    assert {k: p["value"] for k, p in got.items()} == {k: p.value for k, p in mine.parameters.items()}
    assert got["Cf"]["value"] == 61000.0 and got["Cr"]["value"] == 120000.0 and got["m"]["value"] == 1250.0
    assert d["vehicle"]["ranges"]["speed"]["min"] == 20.0 and d["vehicle"]["ranges"]["Cf"]["max"] == 56980.0
    assert d["model"] == {"m": 1250.0, "Iz": 1605.5, "lf": 1.33, "lr": 1.19}
    assert d["modes"][0]["box"]["v"] == [20.0, 30.0]


def test_the_certificate_refuses_a_model_that_is_not_the_files_vehicle(tmp_path):
    from latobs.synthesis import certificate
    import copy
    d = designs.run("SideslipFixedOrderEstimator", **FAST)
    bad = copy.deepcopy(d)
    bad["vehicle"]["parameters"]["lr"]["value"] *= 1.1
    ok, checks = certificate.certify(bad)
    assert not ok and any("= the design file's vehicle" in c.name and not c.passed for c in checks)


@pytest.mark.parametrize("v", [(2.5, 10.5), (15.0, 63.0), (5.56, 11.11), (1.0, 100.0), (7.0, 7.0)])
def test_speed_bands_bound_the_speed_ratio_and_the_beta_per_r_spread(v):
    """For any speed range: contiguous bands, each of speed ratio <= BAND_RATIO and with the
    model's steady beta/r = lr/v - m lf v/(Cr L) moving by <= BAND_BETA_STEP inside it (checked
    on a dense speed grid), and no more bands than needed (one fewer would break a limit)."""
    box = f.vehicle_box(load_vehicle("mbds_250lm"))
    model = lambda s: f.steady_beta_per_r(box, s)      # noqa: E731
    bands = f.speed_bands(v, beta_per_r=model)
    assert bands[0][0] == v[0] and bands[-1][1] == v[1]
    assert all(a[1] == b[0] for a, b in zip(bands, bands[1:]))
    m, lf, lr, cr = box.m, box.lf, box.lr, box.centre()[1]
    for lo, hi in bands:
        assert hi / lo <= f.BAND_RATIO * (1 + 1e-12)
        speeds = [lo + (hi - lo) * k / 50 for k in range(51)]
        br = [model(s) for s in speeds]
        assert br[0] == pytest.approx(lr / lo - m * lf * lo / (cr * (lf + lr)), rel=1e-9)
        assert max(br) - min(br) <= f.BAND_BETA_STEP * (1 + 1e-9)
    # not wasteful: every band but the last uses up one limit (greedy), so at most
    # floor(ratio budget) + floor(beta/r budget) + 1 bands, and at least the larger budget
    rb = math.log(v[1] / v[0]) / math.log(f.BAND_RATIO)
    bb = abs(model(v[1]) - model(v[0])) / f.BAND_BETA_STEP
    assert math.ceil(max(rb, bb) - 1e-9) <= len(bands) <= math.floor(rb) + math.floor(bb) + 1


@pytest.mark.slow
def test_the_lowest_band_estimator_matches_beta_per_r_at_low_speed():
    """Before: one estimator for 2.5..6.5 m/s (a 4 m/s band, speed ratio 2.6) had a DC gain
    y(0)/x(0) half the model's steady beta/r at 2.5 m/s. Now the lowest band of 2.5..10.5 m/s
    (ratio <= 1.25, beta/r spread <= 0.05 s) has a certified estimator whose DC gain is within
    10 % of the model's beta/r at every speed of the band. (Catalogue options, certificate grid
    5^3 instead of 9^3 for time.)"""
    base = f.vehicle_box(load_vehicle("mbds_250lm"))
    opts = f.DesignOptions(name="low", scheduled=True, grid=(5, 5, 5))
    errors = {}
    lowest = f.speed_bands((2.5, 10.5), beta_per_r=lambda v: f.steady_beta_per_r(base, v))[0]
    for tag, band in (("ratio", lowest), ("4 m/s", (2.5, 6.5))):
        box = f.Box(f"low {tag}", base.m, base.Iz, base.lf, base.lr, base.cf, base.cr, band)
        mode = f._design_mode(box, opts)
        dc = mode.y[0] / mode.x[0]
        speeds = [band[0] + (band[1] - band[0]) * k / 20 for k in range(21)]
        errors[tag] = [(dc - f.steady_beta_per_r(box, v)) / f.steady_beta_per_r(box, v) for v in speeds]
    assert max(abs(e) for e in errors["ratio"]) < 0.10, errors["ratio"]
    assert errors["4 m/s"][0] < -0.4, errors["4 m/s"]          # the old band: beta halved at 2.5 m/s
