"""Monte Carlo campaigns (latobs.validation.campaign*, latobs.campaign_runner): definitions, draws,
journal, summary; a campaign on a local Dask cluster that resumes and re-runs a run alone; and a
campaign on a running dask-scheduler that loses a worker mid-way."""
from __future__ import annotations

import json
import math
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from latobs.validation import campaign as cp
from latobs.validation import campaign_run as cr
from latobs.validation import campaign_stats as cs
from latobs.validation.campaign import CampaignError
from latobs.validation.scenarios import get_scenario

from conftest import HOST_ONLY

SHIPPED = sorted(p.stem for p in Path(cp.__file__).parents[1].joinpath("campaigns").glob("*.toml"))


def _write(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "c.toml"
    p.write_text(text, encoding="utf-8")
    return p


BASE = 'name = "t"\nkind = "cosim"\nscenario = "bank-braking"\nobservers = ["SideslipBankObserver"]\nruns = 4\nseed = 1\n'


# --------------------------------------------------------------------------------------------
# definitions
# --------------------------------------------------------------------------------------------
def test_the_shipped_campaigns_load_and_cover_every_paper_and_the_real_data():
    assert {"robustness-000", "robustness-000-flat", "robustness-001", "robustness-002", "robustness-003",
            "mbds-bootstrap"} <= set(SHIPPED)
    from latobs.campaign_runner import resolve, shipped

    for name, path in shipped().items():
        c = cp.load(path)
        assert c.name == name and c.runs >= 100 and c.observers
        r = resolve(name)                       # observers are known designs, plant vehicle resolved
        assert r.kind == "replay" or r.plant_vehicle
    assert cp.load(shipped()["mbds-bootstrap"]).kind == "replay"


@pytest.mark.parametrize("extra, culprit", [
    ("colour = 1\n", "colour"),
    ("[plant]\nmu = { uniform = [1.0, 0.5] }\n", "[plant] mu"),
    ("[plant]\nmu = { gamma = [1.0, 0.5] }\n", "[plant] mu"),
    ("[plant]\nmu = 'wet'\n", "[plant] mu"),
    ("[signals]\nyaw_scale = 1.1\n", "yaw_scale"),
    ("[scenario_fields]\nspeeed = 3.0\n", "speeed"),
    ("[noise.yaw_rate]\nstd = { normal = [0.0, 0.01] }\n", "[noise.yaw_rate] std"),
    ("[noise.yaw_rate]\nsdt = 0.1\n", "[noise.yaw_rate]"),
    ("[replay]\ncsv = 'mbds'\n", "[replay]"),
])
def test_a_bad_definition_is_refused_naming_the_culprit(tmp_path, extra, culprit):
    with pytest.raises(CampaignError) as e:
        cp.load(_write(tmp_path, BASE + extra))
    assert culprit in str(e.value) and "c.toml" in str(e.value)


def test_bad_top_level_values_are_refused(tmp_path):
    for bad, culprit in (("runs = 0", "runs"), ('kind = "batch"', "kind"), ('scenario = "nope"', "nope"),
                         ('name = "a/b"', "name"), ("dt = -1.0", "dt")):
        text = "\n".join(line for line in BASE.splitlines() if not line.startswith(bad.split(" ")[0] + " ")) + "\n"
        with pytest.raises(CampaignError, match=culprit):
            cp.load(_write(tmp_path, text + bad + "\n"))
    with pytest.raises(CampaignError, match="not valid TOML"):
        cp.load(_write(tmp_path, "name = \n"))


def test_a_scenario_alone_takes_the_robustness_distributions_of_its_observers_paper():
    from latobs.campaign_runner import resolve

    c = resolve("double-lane-change", runs=7)
    t = resolve("robustness-000")
    assert c.scenario == "double-lane-change" and c.runs == 7 and c.plant == t.plant and c.noise == t.noise
    assert c.observers == ("SideslipBankObserver", "SideslipBankObserverTire", "SideslipBankObserverPaper",
                           "SideslipBankObserverTirePaper")          # those of `latobs validate`
    assert c.scenario_fields == {}                                  # the scenario's own duration
    with pytest.raises(CampaignError, match="MotorcyclePlant"):
        resolve("motorcycle-lane-change", observers=["SideslipBankObserver"])
    with pytest.raises(CampaignError, match="unknown campaign or scenario"):
        resolve("no-such-thing")


@pytest.mark.parametrize("extra, culprit", [
    ("[scenario_fields]\nduration = -1.0\n", r"\[scenario_fields\] duration = -1: .*outside \(0, 3600\]"),
    ("[scenario_fields]\nduration = 1e12\n", r"\[scenario_fields\] duration = 1e\+12: .*outside"),
    ("[scenario_fields]\nduration = { uniform = [5.0, 5000.0] }\n", r"duration = 5000 \(an end of U\[5, 5000\]\)"),
    ("[scenario_fields]\nduration = { normal = [10.0, 1.0] }\n", r"\[scenario_fields\] duration .*any real number"),
    ("[scenario_fields]\nduration = 0.001\n", r"duration = 0.001: .*shorter than one step"),
    ("[scenario_fields]\ndecel = { choice = [2.0, -1.0] }\n", r"decel = -1 .*refuses it.*decel > 0"),
])
def test_a_drawn_scenario_field_outside_what_the_scenario_accepts_is_refused_on_load(tmp_path, extra, culprit):
    """Every end of every drawn field's support is tried before anything runs: a negative or huge
    duration (every run would fail) is refused naming the file, the table and the key."""
    with pytest.raises(CampaignError, match=culprit) as e:
        cp.load(_write(tmp_path, BASE + extra))
    assert "c.toml" in str(e.value)


def _model_description_fmu(path: Path, variables: str) -> cp.FmuRef:
    """An FMU archive holding only a modelDescription.xml with ``variables`` (ScalarVariable
    elements): all a range check reads."""
    import zipfile

    xml = ('<?xml version="1.0" encoding="UTF-8"?>\n<fmiModelDescription fmiVersion="2.0" modelName="P" '
           'guid="{0}"><CoSimulation modelIdentifier="P"/><ModelVariables>' + variables
           + '</ModelVariables><ModelStructure/></fmiModelDescription>')
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("modelDescription.xml", xml)
    return cp.FmuRef("plant", path.name, "0" * 64, path=str(path))


_PLANT_VARS = (
    '<ScalarVariable name="mu" valueReference="0" causality="parameter" variability="fixed" initial="exact">'
    '<Real min="0.01" max="2" start="1"/></ScalarVariable>'
    '<ScalarVariable name="scale_f" valueReference="1" causality="parameter" variability="fixed" '
    'initial="exact"><Real min="0.1" max="10" start="1"/></ScalarVariable>'
    '<ScalarVariable name="delta" valueReference="2" causality="input" variability="continuous">'
    '<Real start="0"/></ScalarVariable>'
    '<ScalarVariable name="vx" valueReference="3" causality="input" variability="continuous">'
    '<Real min="0" max="30" start="20"/></ScalarVariable>'
    '<ScalarVariable name="bank_angle" valueReference="4" causality="input" variability="continuous">'
    '<Real min="-0.5" max="0.5" start="0"/></ScalarVariable>')


@pytest.mark.parametrize("extra, culprit", [
    ("[plant]\nmu = { uniform = [0.5, 3.0] }\n", r"\[plant\] mu = U\[0.5, 3\] reaches 3, above the maximum 2"),
    ("[plant]\nmu = -0.2\n", r"\[plant\] mu = -0.2 reaches -0.2, below the minimum 0.01"),
    ("[plant]\nmu = { normal = [1.0, 0.1] }\n", r"\[plant\] mu = N\(1, 0.1\) reaches -inf"),
    ("[plant]\nmu = { choice = [0.5, 2.5] }\n", r"reaches 2.5, above the maximum 2"),
    ("[plant]\nfriction = 0.5\n", r"\[plant\] friction: p.fmu has no such parameter; its parameters: mu, scale_f"),
    # bank-braking starts at 25 m/s: speed_scale 1.3 drives vx to 32.5 > 30
    ("[signals]\nspeed_scale = { uniform = [0.9, 1.3] }\n", r"input vx .*speed_scale = 1.3 reaches 32.5, above"),
    ("[scenario_fields]\nv_start = { uniform = [20.0, 31.0] }\n", r"input vx .*v_start = 31 .*reaches 31, above"),
    ("[signals]\nbank_offset = { uniform = [-0.6, 0.0] }\n", r"input bank_angle .*bank_offset = -0.6 reaches"),
])
def test_a_draw_outside_the_plant_fmus_declared_ranges_is_refused_before_any_run(tmp_path, extra, culprit):
    """The plant FMU's declared min/max bound every [plant] parameter's support and every plant input
    the scenario drives once [signals] transformed it (read from its modelDescription, any FMU)."""
    ref = _model_description_fmu(tmp_path / "p.fmu", _PLANT_VARS)
    c = cp.load(_write(tmp_path, BASE + extra))
    with pytest.raises(CampaignError, match=culprit) as e:
        cr.check_supports(c, [ref])
    assert "c.toml" in str(e.value)


def test_draws_inside_the_declared_ranges_pass_the_check(tmp_path):
    ref = _model_description_fmu(tmp_path / "p.fmu", _PLANT_VARS)
    c = cp.load(_write(tmp_path, BASE + "[plant]\nmu = { uniform = [0.01, 2.0] }\nscale_f = { normal = [1.0, 0.1], "
                                        "clip = [0.5, 1.5] }\n[signals]\nspeed_scale = { uniform = [0.9, 1.2] }\n"))
    cr.check_supports(c, [ref])                        # 25 m/s * 1.2 = 30 m/s: the declared maximum


# --------------------------------------------------------------------------------------------
# draws
# --------------------------------------------------------------------------------------------
def test_run_seeds_are_distinct_and_independent_of_the_number_of_runs():
    seeds = [cp.run_seed(2026, k) for k in range(5000)]
    assert len(set(seeds)) == len(seeds)
    assert cp.run_seed(2026, 17) == seeds[17] and cp.run_seed(2027, 17) != seeds[17]


def test_draws_are_reproducible_and_follow_the_declared_distributions(tmp_path):
    c = cp.load(_write(tmp_path, BASE + """
[plant]
mu = { uniform = [0.6, 1.0] }
scale_f = { loguniform = [0.5, 2.0] }
scale_r = { choice = [0.8, 1.2] }
[signals]
bank_offset = { normal = [0.0, 0.02], clip = [-0.01, 0.01] }
steer_scale = 1.5
[noise.yaw_rate]
std = { uniform = [0.001, 0.002] }
bias = { normal = [0.003, 0.001] }
"""))
    draws = [cp.draw(c, cp.run_seed(c.seed, k)) for k in range(4000)]
    assert draws[5] == cp.draw(c, cp.run_seed(c.seed, 5))
    col = {k: np.array([d[k] for d in draws]) for k in draws[0]}
    assert 0.6 <= col["plant.mu"].min() and col["plant.mu"].max() <= 1.0
    assert abs(col["plant.mu"].mean() - 0.8) < 0.01
    assert abs(np.log(col["plant.scale_f"]).mean()) < 0.03          # log-uniform on [1/2, 2]: mean log 0
    assert set(col["plant.scale_r"]) == {0.8, 1.2}
    assert col["signals.bank_offset"].min() == -0.01 and col["signals.bank_offset"].max() == 0.01
    assert np.all(col["signals.steer_scale"] == 1.5)
    assert abs(col["noise.yaw_rate.bias"].mean() - 0.003) < 1e-4 and abs(col["noise.yaw_rate.bias"].std() - 0.001) < 1e-4
    assert c.drawn_names() == ["plant.mu", "plant.scale_f", "plant.scale_r", "signals.bank_offset",
                               "noise.yaw_rate.std", "noise.yaw_rate.bias"]


def test_random_manoeuvre_runs_get_the_run_seed_as_the_scenario_seed():
    from latobs.campaign_runner import resolve

    c = resolve("robustness-001")
    p = cp.draw(c, 12345)
    assert p["scenario.seed"] == 12345 and cp.scenario_of(c, p).base.seed == 12345


def test_replay_segments_lie_wholly_in_one_part_of_the_record():
    """On the record's own time axis (the MBDS record runs from t = 150 s to 700 s, split 425 s)."""
    from latobs.campaign_runner import resolve

    c = resolve("mbds-bootstrap")
    counts = {"train": 0, "test": 0}
    for k in range(2000):
        p = cp.draw(c, cp.run_seed(1, k), record_span=(150.0, 700.0), split=425.0)
        t0, part = p["segment.t_start_s"], p["segment.part"]
        counts[part] += 1
        assert (150.0 <= t0 and t0 + 30.0 <= 425.0) if part == "train" else (425.0 <= t0 and t0 + 30.0 <= 700.0)
    # each part in proportion to its room for a segment: 245 s and 245 s
    assert abs(counts["train"] / 2000 - 0.5) < 0.05
    record = {"t": np.arange(15000, 70000) / 100.0, "yaw_rate": np.zeros(55000)}
    seg = cr.replay_segment(c, {"segment.t_start_s": 430.0}, record, 1)
    assert seg["t"][0] == 430.0 and seg["t"].size == 3000


def test_a_perturbed_scenario_scales_and_offsets_the_plant_inputs_and_nothing_else():
    base = get_scenario("bank-braking", duration=10.0)
    t = base.time_grid(0.01)
    ref = base.sampled(t)
    p = cp.PerturbedScenario.of(base, speed_scale=1.1, steer_scale=0.5, bank_scale=2.0, bank_offset=0.01)
    got = p.sampled(t)
    np.testing.assert_array_equal(got["vx"], ref["vx"] * 1.1)
    np.testing.assert_array_equal(got["delta"], ref["delta"] * 0.5)
    np.testing.assert_array_equal(got["bank_angle"], ref["bank_angle"] * 2.0 + 0.01)
    assert (p.name, p.duration, p.settle_time, p.plant) == (base.name, 10.0, base.settle_time, "CarPlant")
    moto = cp.PerturbedScenario.of(get_scenario("motorcycle-lane-change"), steer_scale=2.0)
    t = moto.time_grid(0.01)
    np.testing.assert_array_equal(moto.sampled(t)["rider_torque"], 2.0 * moto.base.sampled(t)["rider_torque"])


# --------------------------------------------------------------------------------------------
# journal and summary
# --------------------------------------------------------------------------------------------
def _row(k, value, status="ok"):
    return {"run": k, "seed": cp.run_seed(0, k), "status": status, "error": None if status == "ok" else "E: x",
            "params": {"plant.mu": 0.5 + k / 100}, "metrics": {"O.beta.rms": value, "O.vy.violations": float(k % 3 == 0)},
            "headline": ["O.beta.rms", "O.vy.violations"], "seconds": 0.1, "worker": "w"}


def test_the_journal_keeps_whole_rows_once_and_drops_a_torn_last_line(tmp_path):
    j = cs.Journal(tmp_path / "runs.jsonl")
    for k in range(3):
        j.append(_row(k, float(k)))
    j.append(_row(1, 99.0))                                  # a run delivered twice
    j.close()
    with open(j.path, "a") as f:
        f.write('{"run": 3, "seed": 1, "sta')               # killed mid-write
    rows = cs.Journal(j.path).read()
    assert sorted(rows) == [0, 1, 2] and rows[1]["metrics"]["O.beta.rms"] == 1.0
    j2 = cs.Journal(j.path)
    j2.append(_row(3, 3.0))                                  # the torn line is ended, the row whole
    j2.close()
    assert sorted(cs.Journal(j.path).read()) == [0, 1, 2, 3]
    lines = j.path.read_text().splitlines()
    j.path.write_text("\n".join(["garbage", *lines]) + "\n")
    with pytest.raises(CampaignError, match="line 1"):
        cs.Journal(j.path).read()


def test_the_summary_gives_numpy_percentiles_enclosure_and_the_worst_runs(tmp_path):
    c = cp.load(_write(tmp_path, BASE))
    rng = np.random.default_rng(3)
    values = rng.lognormal(size=200)
    rows = [_row(k, float(v)) for k, v in enumerate(values)] + [_row(200, 0.0, status="failed")]
    s = cs.summarize(c, rows)
    st = s["metrics"]["O.beta.rms"]
    for p in cs.PERCENTILES:
        assert st[f"p{p}"] == pytest.approx(np.percentile(values, p), rel=1e-12)
    assert st["max"] == values.max() and st["n"] == 200 and st["mean_ci95"][0] < values.mean() < st["mean_ci95"][1]
    assert (s["ok"], s["failed"], s["failures"][0]["run"]) == (200, 1, 200)
    assert s["enclosure"]["O.vy"]["runs_with_violations"] == len([k for k in range(200) if k % 3 == 0])
    worst = s["worst"]["O.beta.rms"]
    assert [w["run"] for w in worst] == list(np.argsort(-values)[: cs.WORST_RUNS])
    assert worst[0]["seed"] == cp.run_seed(0, worst[0]["run"])
    t = cs.rows_table(rows)
    assert t.num_rows == 201 and t.column("O.beta.rms").to_pylist()[:3] == list(values[:3])


def test_the_bootstrap_interval_is_the_plain_resampling_of_each_columns_finite_values():
    """stats_table's shared resampling counts give, per column, the interval of resampling its own
    finite values with the same draws (held against the plain gather); columns with other missing
    runs are resampled apart."""
    rng = np.random.default_rng(5)
    a, b = rng.lognormal(size=300), rng.normal(size=300)
    c = b.copy()
    c[::7] = np.nan
    got = cs.stats_table({"a": a, "b": b, "c": c, "none": np.full(300, np.nan)}, np.random.default_rng(9))
    ref = np.random.default_rng(9)
    idx = ref.integers(0, 300, size=(cs.BOOTSTRAP_RESAMPLES, 300))      # a and b: one group, drawn first
    for name, x in (("a", a), ("b", b)):
        assert got[name]["mean_ci95"] == pytest.approx(np.percentile(x[idx].mean(axis=1), (2.5, 97.5)), rel=1e-12)
    cf = c[np.isfinite(c)]
    idx = ref.integers(0, cf.size, size=(cs.BOOTSTRAP_RESAMPLES, cf.size))
    assert got["c"]["n"] == cf.size and got["c"]["mean_ci95"] == pytest.approx(
        np.percentile(cf[idx].mean(axis=1), (2.5, 97.5)), rel=1e-12)
    assert got["none"] == {"n": 0} and list(got) == ["a", "b", "c", "none"]
    assert got["a"]["p95"] == pytest.approx(np.percentile(a, 95), rel=1e-15)


def test_an_interval_that_never_misses_is_plotted_and_ranked_by_its_width_in_degrees(tmp_path):
    """robustness-001 holds its enclosure: a histogram of zero violation counts says nothing, so the
    report plots each interval's mean width and lists the widest runs (angles in degrees)."""
    import math

    from latobs.validation import campaign_report

    metrics = {"O.beta.violations": 0.0, "O.beta.mean_width": 0.0, "O.vy.violations": 0.0, "O.vy.mean_width": 0.0}
    heads = cs.headline_columns(metrics, {"O": ["yaw_rate"]})
    assert heads == list(metrics)                          # widths are headline metrics beside the counts
    c = cp.load(_write(tmp_path, BASE))
    rows = [{"run": k, "seed": cp.run_seed(0, k), "status": "ok", "error": None, "params": {"plant.mu": 0.5 + k / 100},
             "metrics": {**metrics, "O.beta.mean_width": 0.01 + k / 1000, "O.vy.mean_width": 0.2 + k / 100},
             "headline": heads, "seconds": 0.1, "worker": "w"} for k in range(30)]
    s = cs.summarize(c, rows)
    assert [w["run"] for w in s["worst"]["O.beta.mean_width"]] == [29, 28, 27, 26, 25]    # the widest runs
    assert s["worst"]["O.beta.violations"] == []
    figs = campaign_report.figures(tmp_path, rows)
    assert {p.name for p in figs} == {"hist_O.png", "scatter_O.beta.mean_width.png", "scatter_O.vy.mean_width.png"}
    md = campaign_report.markdown(c, s, figs)
    assert "**`O.beta.mean_width`** (widest runs)" in md and "| value [deg] |" in md
    assert f"| {campaign_report._g(math.degrees(0.039))} |" in md           # run 29: 0.039 rad
    assert "No run violated `O.beta.violations`, `O.vy.violations`" in md


SEDAN_LIKE = {"name": "t", "kind": "car", "parameters": {"m": 1500.0, "Iz": 2500.0, "lf": 1.2, "lr": 1.5,
                                                          "Cf": 8.0e4, "Cr": 9.0e4}}


def test_a_run_scores_the_observer_beside_the_baselines_on_the_same_samples():
    """baseline_metrics: each baseline's RMS, the ratio to the best one and the win, on the samples
    after settling and on the valid ones, held against numpy on the same arrays (the bicycle from
    baselines.bicycle, tested against solve_ivp in test_validation_baselines); an input quantity
    is not scored; an interval is scored by its midpoint."""
    from latobs.validation import baselines as bl

    rng = np.random.default_rng(7)
    n = 2001
    t = np.arange(n) * 0.005
    delta = 0.02 * np.sin(1.3 * t)
    vx = np.full(n, 20.0)
    bike = bl.bicycle(t, delta, vx, SEDAN_LIKE["parameters"])
    beta = bike["beta"] + 0.002 * np.sin(5 * t)               # the truth: near the bicycle
    vy = bike["vy"] + 0.03 * np.cos(3 * t)
    beta_hat = beta + rng.normal(0, 1e-3, n)
    vy_mid = vy + rng.normal(0, 0.01, n)
    valid = (np.sin(0.7 * t) > -0.5).astype(np.int32)
    outputs = {"beta_hat": beta_hat, "yaw_rate_hat": bike["yaw_rate"] + 1.0, "valid": valid,
               "vy_lower": vy_mid - 0.2, "vy_upper": vy_mid + 0.2}
    truth = {"beta": beta, "vy": vy, "yaw_rate": bike["yaw_rate"], "delta": delta, "vx": vx}
    after = t >= 1.0
    row = cr.baseline_metrics("O", outputs, truth, truth, t, after, "SideslipBankObserver", {"vehicle": SEDAN_LIKE},
                              inputs=["yaw_rate", "delta", "vx"])

    def rms(e):
        return float(np.sqrt(np.mean(e * e)))

    for q, est in (("beta", beta_hat), ("vy", vy_mid)):
        x = truth[q]
        for pre, sel in (("", after), ("valid_", after & (valid != 0))):
            obs, zero, bic = rms((est - x)[sel]), rms(x[sel]), rms((bike[q] - x)[sel])
            assert row[f"O.{q}.{pre}ratio"] == pytest.approx(obs / min(zero, bic), rel=1e-12)
            assert row[f"O.{q}.{pre}wins"] == float(obs < min(zero, bic))
        assert row[f"O.{q}.rms_zero"] == pytest.approx(rms(x[after]), rel=1e-12)
        assert row[f"O.{q}.rms_bicycle"] == pytest.approx(rms((bike[q] - x)[after]), rel=1e-12)
    assert row["O.beta.wins"] == 1.0 and row["O.vy.ratio"] > 0
    assert row["O.vy.midpoint_rms"] == pytest.approx(rms((vy_mid - vy)[after]), rel=1e-12)
    assert row["O.valid_fraction"] == pytest.approx(np.mean(valid[after] != 0))
    assert not any(k.startswith("O.yaw_rate.") for k in row)      # the observer reads the yaw rate
    # a baseline better than the observer: no win, ratio > 1
    worse = cr.baseline_metrics("O", {"beta_hat": beta + 0.5}, truth, truth, t, after, "SideslipBankObserver",
                                {"vehicle": SEDAN_LIKE})
    assert worse["O.beta.wins"] == 0.0 and worse["O.beta.ratio"] > 1 and "O.valid_fraction" not in worse
    # no vehicle parameters: the bicycle cannot be computed, so no verdict (the zero baseline alone)
    none = cr.baseline_metrics("O", {"beta_hat": beta_hat}, truth, truth, t, after, "SideslipBankObserver",
                               {"vehicle": {"name": "x", "parameters": {}}})
    assert math.isnan(none["O.beta.wins"]) and "O.beta.rms_bicycle" not in none


def test_a_filtered_estimate_is_scored_one_step_behind_in_a_campaign_run():
    """X_filtered (a filter's x(k|k), published one step behind): row k + 1 against the truth at row k,
    the baselines on the same samples (rows 0 .. n - 2), under its own name beside X_hat; a
    filtered estimate of a quantity the observer reads is not scored against baselines."""
    from latobs.validation import baselines as bl

    n = 1201
    t = np.arange(n) * 0.005
    delta = 0.02 * np.sin(1.3 * t)
    vx = np.full(n, 20.0)
    bike = bl.bicycle(t, delta, vx, SEDAN_LIKE["parameters"])
    beta = bike["beta"] + 0.002 * np.sin(5 * t)
    truth = {"beta": beta, "yaw_rate": bike["yaw_rate"], "delta": delta, "vx": vx}
    after = t >= 1.0
    delayed = np.concatenate([[0.0], beta[:-1]])           # the truth one row late: a perfect x(k|k)
    outputs = {"beta_hat": beta + 0.01, "beta_filtered": delayed, "yaw_rate_filtered": truth["yaw_rate"] + 1.0}
    row = cr.observer_metrics("O", outputs, truth, after, "SideslipKalmanFilter")
    assert row["O.beta_filtered.rms"] == 0.0 and row["O.beta_filtered.max_abs"] == 0.0
    assert row["O.beta.rms"] == pytest.approx(0.01)
    same = cr.observer_metrics("O", {"beta_filtered": beta}, truth, after, "SideslipKalmanFilter")
    assert same["O.beta_filtered.rms"] > 0                 # not delayed: scored against the wrong time
    b = cr.baseline_metrics("O", outputs, truth, truth, t, after, "SideslipKalmanFilter", {"vehicle": SEDAN_LIKE},
                            inputs=["yaw_rate", "delta", "vx"])
    sel = after[:-1]
    assert b["O.beta_filtered.rms_zero"] == pytest.approx(float(np.sqrt(np.mean(beta[:-1][sel] ** 2))), rel=1e-12)
    assert b["O.beta_filtered.rms_bicycle"] == pytest.approx(
        float(np.sqrt(np.mean((bike["beta"][:-1] - beta[:-1])[sel] ** 2))), rel=1e-12)
    assert b["O.beta_filtered.ratio"] == 0.0 and b["O.beta_filtered.wins"] == 1.0
    assert b["O.beta.rms_zero"] == pytest.approx(float(np.sqrt(np.mean(beta[after] ** 2))), rel=1e-12)
    assert not any(k.startswith("O.yaw_rate") for k in b)
    assert cs.headline_columns(row, {"O": ["yaw_rate", "delta", "vx"]}) == ["O.beta.rms", "O.beta_filtered.rms"]


def test_the_summary_gives_each_observers_ratio_distribution_win_fraction_and_worst_runs(tmp_path):
    from latobs.validation import campaign_report

    c = cp.load(_write(tmp_path, BASE))
    rng = np.random.default_rng(11)
    ratio = rng.lognormal(-0.5, 0.6, 120)
    vratio = ratio * 0.9
    rows = []
    for k, r in enumerate(ratio):
        bic = 1.0 + (k % 4)
        m = {"O.beta.rms": r * bic, "O.beta.rms_zero": 4.5, "O.beta.rms_bicycle": bic, "O.beta.ratio": r,
             "O.beta.wins": float(r < 1), "O.valid_fraction": 0.8, "O.beta.valid_rms": vratio[k] * bic,
             "O.beta.valid_ratio": vratio[k], "O.beta.valid_wins": float(vratio[k] < 1)}
        rows.append({"run": k, "seed": cp.run_seed(0, k), "status": "ok", "error": None,
                     "params": {"plant.mu": 0.5 + k / 1000}, "metrics": m, "headline": ["O.beta.rms"],
                     "seconds": 0.1, "worker": "w"})
    s = cs.summarize(c, rows)
    v = s["versus_baselines"]["O.beta"]
    assert v["win_fraction"] == pytest.approx(np.mean(ratio < 1)) and v["wins"] == int(np.sum(ratio < 1))
    assert v["ratio"]["p50"] == pytest.approx(np.median(ratio), rel=1e-12)
    assert v["baselines"] == ["bicycle", "zero"]
    assert v["best_baseline_runs"] == {"bicycle": 120 - sum(1 for k in range(120) if 1.0 + (k % 4) > 4.5)}
    assert [w["run"] for w in v["worst"]] == list(np.argsort(-ratio)[: cs.WORST_RUNS])
    assert v["valid"]["win_fraction"] == pytest.approx(np.mean(vratio < 1))
    assert v["valid"]["mean_valid_fraction"] == pytest.approx(0.8)
    figs = campaign_report.figures(tmp_path, rows)
    assert "versus_baselines.png" in {p.name for p in figs}
    md = campaign_report.markdown(c, s, figs)
    assert "## Against the baselines" in md
    assert f"| `O` | beta | 120 | {100 * np.mean(ratio < 1):.1f} % |" in md


# --------------------------------------------------------------------------------------------
# campaigns on Dask
# --------------------------------------------------------------------------------------------
def _fmu_folder(built_fmus, tmp_path, names) -> Path:
    d = tmp_path / "fmus"
    d.mkdir(exist_ok=True)
    for n in names:
        shutil.copy2(built_fmus.c_path(n), d / f"{n}.fmu")
    return d


@pytest.mark.slow
def test_a_local_campaign_holds_paper_001s_enclosure_resumes_and_reruns_a_run_alone(built_fmus, tmp_path, capsys):
    """robustness-001 (paper 001 inside its guarantee) on a local cluster of 2 workers: every bound
    contains the truth in every run; an extended campaign runs only the new runs; a journal cut by
    a kill is completed with the same rows; a run re-run alone from its seed gives the same metrics."""
    from latobs import packaging
    from latobs.campaign_runner import run_campaign, rerun

    fmus = _fmu_folder(built_fmus, tmp_path, ["LateralIntervalObserver"])
    packaging.package_plant("CarPlant", "sedan_no_roll", fmus, backend="c", platforms=HOST_ONLY)
    out = tmp_path / "out"
    kw = dict(out=out, fmu_dir=fmus, workers=2, progress=False, plots=False)
    s = run_campaign("robustness-001", runs=10, **kw)
    folder = Path(s["folder"])
    journal = cs.Journal(folder / "runs.jsonl")
    rows = journal.read()
    assert sorted(rows) == list(range(10)) and all(r["status"] == "ok" for r in rows.values())
    for base, e in s["enclosure"].items():                   # the design's guarantee
        assert e["runs_with_violations"] == 0 and e["runs"] == 10, base
    widths = [r["metrics"]["LateralIntervalObserver.Fyf.mean_width"] for r in rows.values()]
    assert all(w > 0 for w in widths)
    assert len({r["worker"] for r in rows.values()}) >= 2    # spread over the cluster

    s = run_campaign("robustness-001", runs=12, **kw)        # extended: two new runs only
    assert s["timing"]["runs_this_invocation"] == 2
    after = cs.Journal(folder / "runs.jsonl").read()
    assert all(after[k]["metrics"] == rows[k]["metrics"] for k in range(10))

    lines = (folder / "runs.jsonl").read_text().splitlines()   # killed: 3 rows lost, 1 torn
    (folder / "runs.jsonl").write_text("\n".join(lines[:-3]) + "\n" + lines[-3][:25])
    s = run_campaign("robustness-001", runs=12, **kw)
    assert s["timing"]["runs_this_invocation"] == 3 and s["runs"] == 12
    again = cs.Journal(folder / "runs.jsonl").read()
    assert {k: r["metrics"] for k, r in again.items()} == {k: r["metrics"] for k, r in after.items()}
    assert (folder / "report.md").is_file() and (folder / "runs.parquet").is_file()

    seed = again[7]["seed"]
    row = rerun("robustness-001", seed, out=out, fmu_dir=fmus, plots=False)
    assert row["identical_to_journal"] and row["journal_run"] == 7
    assert (folder / f"rerun_{seed}" / "metrics.json").is_file()
    # the campaign's verdict against the baselines is validate's on the same run
    full = json.loads((folder / f"rerun_{seed}" / "metrics.json").read_text())
    verdicts = full["observers"]["LateralIntervalObserver"]["baselines"]["summary"]
    for q in ("vy", "beta", "Fyf", "Fyr"):
        assert again[7]["metrics"][f"LateralIntervalObserver.{q}.ratio"] == pytest.approx(verdicts[q]["ratio"],
                                                                                          rel=1e-12), q
        assert again[7]["metrics"][f"LateralIntervalObserver.{q}.wins"] == float(verdicts[q]["observer_best"]), q
    assert "LateralIntervalObserver.beta" in s["versus_baselines"]

    with pytest.raises(CampaignError, match="another campaign"):   # same folder, other definition
        run_campaign("robustness-001", runs=12, seed=5, **kw)


def _start(cmd, log: Path) -> subprocess.Popen:
    """A process of its own session, in the log's folder: not the project's, whose ``latobs/``
    folder would shadow the installed package (python -m puts the working directory first)."""
    return subprocess.Popen(cmd, stdout=open(log, "w"), stderr=subprocess.STDOUT, start_new_session=True,
                            cwd=log.parent)


def _kill(p: subprocess.Popen) -> None:
    try:
        os.killpg(p.pid, signal.SIGKILL)
    except ProcessLookupError:
        pass
    p.wait(timeout=30)


@pytest.mark.slow
def test_a_campaign_on_a_dask_scheduler_completes_when_a_worker_is_killed(built_fmus, tmp_path):
    """`latobs campaign --scheduler` against a dask-scheduler and two dask-workers started here;
    one worker is killed (SIGKILL, nanny and all) mid-campaign. The campaign completes: every run
    in the journal exactly once, all ok, and the rows equal the same runs computed in this process."""
    fmus = _fmu_folder(built_fmus, tmp_path, ["CarPlant", "SideslipBankObserver", "SideslipBankObserverTire"])
    sched_file = tmp_path / "scheduler.json"
    procs = [_start([sys.executable, "-m", "dask", "scheduler", "--host", "127.0.0.1", "--port", "0",
                     "--no-dashboard", "--scheduler-file", str(sched_file)], tmp_path / "scheduler.log")]
    try:
        deadline = time.monotonic() + 60
        while not sched_file.is_file() and time.monotonic() < deadline:
            time.sleep(0.2)
        address = json.loads(sched_file.read_text())["address"]
        assert address.startswith("tcp://127.0.0.1:")
        workers = [_start([sys.executable, "-m", "dask", "worker", "--scheduler-file", str(sched_file),
                           "--nthreads", "1", "--nworkers", "1", "--no-dashboard", "--name", f"w{i}"],
                          tmp_path / f"worker{i}.log") for i in range(2)]
        procs += workers
        from dask.distributed import Client

        with Client(address, timeout="60s") as client:
            client.wait_for_workers(2, timeout=60)
        runs = 300                     # (~10 ms a run: enough to kill a worker mid-campaign)
        out = tmp_path / "out"
        campaign = _start([sys.executable, "-m", "latobs", "campaign", "robustness-000", "--runs", str(runs),
                           "--scheduler", address, "--fmu-dir", str(fmus), "--out", str(out), "--no-plots",
                           "--no-progress"], tmp_path / "campaign.log")
        procs.append(campaign)
        journal = out / "campaign_robustness-000" / "runs.jsonl"
        deadline = time.monotonic() + 120

        def both_at_work() -> bool:
            """12 rows in the journal, and rows from both workers (a loaded machine may start one
            of them late: the kill must come while both are at work)."""
            if not journal.is_file():
                return False
            text = journal.read_text()
            rows = [json.loads(x) for x in text.splitlines()[:text.count("\n")]]   # whole lines only
            return len(rows) >= 12 and len({r["worker"] for r in rows if r["run"] != 0}) == 2

        while not both_at_work() and time.monotonic() < deadline:
            assert campaign.poll() is None, (tmp_path / "campaign.log").read_text()[-3000:]
            time.sleep(0.05)
        done_at_kill = journal.read_text().count("\n")
        _kill(workers[0])
        assert done_at_kill < runs // 2, "the campaign was no longer in its middle when the worker was killed"
        assert campaign.wait(timeout=300) == 0, (tmp_path / "campaign.log").read_text()[-3000:]
    finally:
        for p in procs:
            _kill(p)
    lines = [json.loads(x) for x in journal.read_text().splitlines()]
    assert sorted(r["run"] for r in lines) == list(range(runs))          # nothing lost, nothing twice
    assert all(r["status"] == "ok" for r in lines)
    summary = json.loads((journal.parent / "summary.json").read_text())
    assert (summary["runs"], summary["ok"], summary["timing"]["scheduler"]) == (runs, runs, address)
    by_run = {r["run"]: r for r in lines}
    # run 0 runs first in the campaign's own process (a wiring check); the rest on the workers
    assert len({r["worker"] for r in lines[:done_at_kill] if r["run"] != 0}) == 2
    # the survivor finished it: the results the killed worker had sent before the kill still land
    # after done_at_kill (how many depends on the machine's load: 5 was once too few), but from
    # midway between the kill and the end (at least 75 runs later) every row is the survivor's
    assert len({r["worker"] for r in lines[(done_at_kill + runs) // 2:]}) == 1

    from latobs.campaign_runner import fmu_refs, resolve

    c = resolve("robustness-000", runs=runs)
    refs = fmu_refs(c, fmus)
    for k in (0, lines[done_at_kill - 1]["run"], lines[-1]["run"]):
        assert cr.run_case(c, k, cp.run_seed(c.seed, k), refs)["metrics"] == by_run[k]["metrics"], k


def test_the_local_cluster_serves_no_dashboard_and_never_warns_about_port_8787(recwarn):
    """`latobs campaign` on a local cluster: no Dask dashboard unless asked, and no "Port 8787 is
    already in use" warning while another process holds Dask's default port."""
    import socket

    from latobs.campaign_runner import local_cluster

    holder = socket.socket()
    try:
        holder.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        holder.bind(("0.0.0.0", 8787))
        holder.listen()
    except OSError:
        pass                                   # someone else holds it: the case the test is about
    try:
        cluster = local_cluster(0)
        try:
            http = cluster.scheduler.http_server      # health and metrics routes only, on a free local port
            assert http.port != 8787 and http.address == "127.0.0.1"
        finally:
            cluster.close()
    finally:
        holder.close()
    assert not [w for w in recwarn if "8787" in str(w.message)]


@pytest.mark.slow
def test_a_campaign_whose_runs_all_fail_exits_2_after_writing_its_report(built_fmus, tmp_path, monkeypatch, capsys):
    """Every run fails (each co-simulation raises the error a failing FMU raises): the command writes
    the folder with the failures, then exits 2 naming the first one, never "0 runs ok" and 0."""
    from latobs import cli
    from latobs.validation import harness

    def failing(*a, **k):
        raise harness.CoSimulationError("plant FMU CarPlant: fmi2Error at t = 0.5 s")

    monkeypatch.setattr(harness, "run", failing)
    fmus = _fmu_folder(built_fmus, tmp_path, ["CarPlant", "SideslipBankObserver"])
    c = _write(tmp_path, BASE + "[scenario_fields]\nduration = 1.0\n")
    rc = cli.main(["campaign", str(c), "--runs", "1", "--fmu-dir", str(fmus), "--out", str(tmp_path / "out"),
                   "--no-plots", "--no-progress"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1
    assert "all 1 runs failed" in err[0] and "fmi2Error at t = 0.5 s" in err[0]
    report = (tmp_path / "out" / "campaign_t" / "report.md").read_text()
    assert "fmi2Error at t = 0.5 s" in report


@pytest.mark.slow
def test_latobs_campaign_refuses_a_draw_outside_the_plants_range_before_anything_is_written(built_fmus, tmp_path,
                                                                                          capsys):
    from latobs import cli

    fmus = _fmu_folder(built_fmus, tmp_path, ["CarPlant", "SideslipBankObserver"])
    c = _write(tmp_path, BASE + "[plant]\nmu = { uniform = [0.5, 3.0] }\n")
    rc = cli.main(["campaign", str(c), "--fmu-dir", str(fmus), "--out", str(tmp_path / "out"), "--no-progress"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "[plant] mu" in err[0] and "c.toml" in err[0]
    assert not (tmp_path / "out").exists()                 # nothing ran, nothing was written


def test_a_worker_keeps_its_own_copy_of_an_fmu_whose_folder_is_deleted(tmp_path, built_fmus):
    """A long-lived process runs a campaign, its FMU folder is deleted, and another campaign on an
    FMU of the same bytes (a cached build) runs in it: the worker's copy is used, not the deleted
    file; an FMU whose bytes changed after its sha256 was taken is refused."""
    import hashlib
    import shutil

    from latobs.validation import campaign_run as cr
    from latobs.validation.campaign import CampaignError

    src = built_fmus.c_path("CarPlant")
    first, second = tmp_path / "a", tmp_path / "b"
    first.mkdir(), second.mkdir()
    shutil.copy2(src, first / "CarPlant.fmu"), shutil.copy2(src, second / "CarPlant.fmu")
    sha = hashlib.sha256(src.read_bytes()).hexdigest()
    path, folder = cr._local(cr.FmuRef("plant", "CarPlant.fmu", sha, path=str(first / "CarPlant.fmu")))
    shutil.rmtree(first)
    again, folder2 = cr._local(cr.FmuRef("plant", "CarPlant.fmu", sha, path=str(second / "CarPlant.fmu")))
    assert (again, folder2) == (path, folder) and Path(again).is_file() and Path(folder).is_dir()
    (tmp_path / "c").mkdir()
    changed = tmp_path / "c" / "CarPlant.fmu"
    changed.write_bytes(b"not the FMU it was")
    with pytest.raises(CampaignError, match="changed since the campaign started"):
        cr._local(cr.FmuRef("plant", "CarPlant.fmu", "0" * 64, path=str(changed)))


def test_an_fmus_design_and_description_are_read_once_per_file_version(fmu_dir, tmp_path):
    """A campaign reads the same FMU's design file and model description thousands of times: each
    is parsed once per file version, and an FMU replaced at the same path (renamed over it, or
    rewritten in place) is read again, never served from the earlier file."""
    from latobs.validation import instance

    path = tmp_path / "observer.fmu"
    shutil.copy2(fmu_dir / "SideslipBankObserver.fmu", path)
    first = instance.observer_design(path)
    assert first["name"] == "SideslipBankObserver"
    first["name"] = "changed by the caller"                       # a copy: the next call is not affected
    assert instance.observer_design(path)["name"] == "SideslipBankObserver"
    md = instance._model_description(str(path))
    assert instance._model_description(str(path)) is md           # parsed once
    other = tmp_path / "other.fmu"
    shutil.copy2(fmu_dir / "SideslipBankObserverTire.fmu", other)
    os.replace(other, path)                                       # renamed over it: another inode
    assert instance.observer_design(path)["name"] == "SideslipBankObserverTire"
    assert instance._model_description(str(path)).modelName == "SideslipBankObserverTire"
    raw = (fmu_dir / "SideslipBankObserverPaper.fmu").read_bytes()
    with open(path, "r+b") as fh:                                 # rewritten in place: same inode
        fh.write(raw)
        fh.truncate()
    os.utime(path, ns=(time.time_ns(), time.time_ns() + 1_000_000))
    assert instance.observer_design(path)["name"] == "SideslipBankObserverPaper"
    assert instance._model_description(str(path)).modelName == "SideslipBankObserverPaper"
