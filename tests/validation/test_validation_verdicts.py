"""The observer beside its baselines: every baseline as good as or better than the observer is
flagged (printed table, metrics.json, report), on the same samples; the baselines' parameters
come from the design file only (never from a shipped vehicle set of the same name); a baseline
that cannot be computed is said so beside the observer's figures, and no verdict in the
observer's favour is given then."""
from __future__ import annotations

import json

import numpy as np
import pytest

from latobs.synthesis.params import VehicleParameterError, load_vehicle
from latobs.validation import baselines as bl
from latobs.validation import harness, metrics, report
from latobs.validation.harness import SimResult, design_summary
from latobs.validation.replay import ReplayRun, score

SEDAN = {k: load_vehicle("sedan").value(k) for k in bl.BICYCLE_PARAMETERS}


def _sim(design, observer_offset: float, nan_after: float | None = None) -> SimResult:
    """A flat-road run: the truth is the sedan's bicycle + 0.001 rad (the bicycle baseline's error),
    the observer's beta_hat is the truth + ``observer_offset`` (NaN from ``nan_after`` s)."""
    t = np.arange(0.0, 4.0 + 1e-9, 0.01)
    delta, vx = 0.02 * np.sin(2.0 * t), np.full_like(t, 20.0)
    truth = bl.bicycle(t, delta, vx, SEDAN)["beta"] + 0.001
    beta_hat = truth + observer_offset
    if nan_after is not None:
        beta_hat[t >= nan_after] = np.nan
    info = {"observer_models": {"o": "SideslipBankObserver"}, "observer_designs": {"o": design}}
    return SimResult(time=t, bus={"delta": delta, "vx": vx, "beta": truth}, observers={"o": {"beta_hat": beta_hat}},
                     logs={}, scenario="x", dt=0.01, settle_time=1.0, info=info)


def _design(params: dict, name: str = "sedan") -> dict:
    return design_summary({"design": "SideslipBankObserver", "paper": "000",
                           "vehicle": {"name": name, "kind": "car",
                                       "parameters": {k: {"value": v} for k, v in params.items()}}},
                          "o.fmu:resources/o.design.json")


# ------------------------------------------------------------------------------------------------
# every baseline as good or better is flagged
# ------------------------------------------------------------------------------------------------
def test_every_baseline_as_good_as_the_observer_is_flagged(tmp_path):
    r = _sim(_design(SEDAN), observer_offset=0.05)          # worse than both baselines
    m = metrics.compute(r)
    # the printed table: both baseline rows flagged
    tt = report.text_table(m)
    assert "  zero baseline !" in tt and "  linear bicycle baseline !" in tt
    b = m["observers"]["o"]["baselines"]
    s = b["summary"]["beta_hat"]
    zero, bicycle = (b[k]["beta_hat"]["rms_after_settle"] for k in ("zero", "bicycle"))
    assert bicycle < zero < s["observer_rms"]               # both baselines beat the observer
    assert s["statistic"] == "rms_after_settle" and s["best_baseline"] == "bicycle"
    assert s["baselines_as_good"] == ["zero", "bicycle"] and s["observer_best"] is False
    # metrics.json
    saved = json.loads(metrics.write(m, tmp_path).read_text())
    assert saved["observers"]["o"]["baselines"]["summary"]["beta_hat"]["baselines_as_good"] == ["zero", "bicycle"]
    # the report: both cells flagged, the verdict names both
    md = report.metrics_markdown(m)
    row = next(line for line in md.splitlines() if line.startswith("| o | beta_hat |"))
    cells = [c.strip() for c in row.strip("|").split("|")]
    assert cells[-4].endswith("⚠") and cells[-3].endswith("⚠")       # zero, bicycle columns
    assert cells[-1] == "⚠ zero and linear bicycle baselines"
    # an observer between the two: only the bicycle is flagged
    s = metrics.compute(_sim(_design(SEDAN), observer_offset=0.002))["observers"]["o"]["baselines"]["summary"]
    assert s["beta_hat"]["baselines_as_good"] == ["bicycle"]
    assert "  zero baseline !" not in report.text_table(metrics.compute(_sim(_design(SEDAN), 0.002)))


def test_an_observer_better_than_every_baseline_is_said_so():
    m = metrics.compute(_sim(_design(SEDAN), observer_offset=0.0))      # exact: error 0
    s = m["observers"]["o"]["baselines"]["summary"]["beta_hat"]
    assert s["baselines_as_good"] == [] and s["observer_best"] is True and s["not_computed"] == {}
    assert "!" not in report.text_table(m).split("\n* lowest")[0]
    row = next(line for line in report.metrics_markdown(m).splitlines() if line.startswith("| o | beta_hat |"))
    assert row.rstrip(" |").endswith("| observer")


def test_a_diverged_observer_is_beaten_by_every_finite_baseline_on_the_same_samples():
    """NaN estimates after 2 s: the observer's RMS after settle is not finite, every baseline is
    better; the comparison stays on the samples after settling (not the whole run)."""
    m = metrics.compute(_sim(_design(SEDAN), observer_offset=0.0, nan_after=2.0))
    s = m["observers"]["o"]["baselines"]["summary"]["beta_hat"]
    assert s["statistic"] == "rms_after_settle" and s["observer_rms"] is None
    assert s["baselines_as_good"] == ["zero", "bicycle"] and s["observer_best"] is False
    assert "  zero baseline !" in report.text_table(m)


def test_replay_flags_every_baseline_on_the_held_out_part():
    t = 100.0 + 0.01 * np.arange(1001)
    delta, vx = 0.01 * np.sin(1.5 * t), 25.0 + np.sin(0.2 * t)
    ref = bl.bicycle(t, delta, vx, SEDAN, initial="steady")
    outs = {"beta_hat": ref["beta"] + 0.05}                     # worse than zero and the bicycle
    run = ReplayRun(time=t, columns={"delta": delta, "vx": vx, "beta": ref["beta"]}, outputs=outs, inputs=[],
                    dt=0.01, fmu=None, model_name="Obs", label="Obs", design=_design(SEDAN))
    m = score(run, split=105.0, info={"csv": "r.csv"})
    tt = report.text_table(m)
    assert "RMS error, zero baseline [SI] !" in tt and "RMS error, linear bicycle baseline [SI] !" in tt
    s = m["observers"]["Obs"]["baselines"]["summary"]["beta_hat"]
    assert s["segment"] == "after_split" and s["baselines_as_good"] == ["zero", "bicycle"]
    md = report.metrics_markdown(m)
    assert "RMS error, zero baseline [SI] ⚠" in md and "RMS error, linear bicycle baseline [SI] ⚠" in md


@pytest.mark.slow
def test_fishhook_flags_the_zero_estimate(built_fmus, tmp_path):
    """Paper 000's tire-mode observer on the fishhook (no bank): beta's zero estimate is as
    good as the observer after settling, and both baselines that are must be flagged, not only the best."""
    res = harness.run("fishhook", built_fmus.path("CarPlant"), {"o": built_fmus.path("SideslipBankObserverTire")})
    m = metrics.compute(res)
    tt = report.text_table(m)
    beta_rows = tt.split(" beta_hat ")[1].split("yaw_rate_hat")[0]
    assert "zero baseline !" in beta_rows and "linear bicycle baseline !" in beta_rows
    b = m["observers"]["o"]["baselines"]
    for name, s in b["summary"].items():
        obs = s["observer_rms"]
        want = [k for k in ("zero", "bicycle") if name in b.get(k, {})
                and b[k][name]["rms_after_settle"] is not None and b[k][name]["rms_after_settle"] <= obs]
        assert s["baselines_as_good"] == want, name
    # measured: beta RMS after settle 0.0612 rad; zero 0.0576, the bicycle 0.0450
    assert b["summary"]["beta_hat"]["baselines_as_good"] == ["zero", "bicycle"]


# ------------------------------------------------------------------------------------------------
# baselines from the design file only; never silently dropped
# ------------------------------------------------------------------------------------------------
def test_a_design_file_is_never_completed_from_a_shipped_set_of_the_same_name():
    """A new car named like a shipped set ("delibasi"), whose design file carries m, Iz, lf, lr but
    not Cf, Cr: the bicycle baseline is not computed (the shipped delibasi's Cf, Cr are another
    car's), and the report says so beside the observer's figures, with no verdict."""
    own = {"m": 1234.0, "Iz": 2222.0, "lf": 1.1, "lr": 1.5}
    d = design_summary({"design": "SideslipFixedOrderEstimator", "paper": "002",
                        "vehicle": {"name": "delibasi", "parameters": own}}, "E.fmu:resources/E.design.json")
    assert set(d["vehicle"]["parameters"]) == set(own)
    r = _sim(d, observer_offset=0.0)                            # an observer with error 0
    m = metrics.compute(r)
    b = m["observers"]["o"]["baselines"]
    assert "bicycle" not in b and "beta_hat" in b["zero"]
    why = b["skipped"]["bicycle"]
    assert "needs Cf, Cr, which the design file E.fmu:resources/E.design.json does not carry for vehicle delibasi" in why
    s = b["summary"]["beta_hat"]
    assert s["not_computed"] == {"bicycle": why} and s["observer_best"] is None and s["baselines_as_good"] == []
    # beside the observer's figures: the table row, the note, no "observer" verdict
    md = report.metrics_markdown(m)
    row = next(line for line in md.splitlines() if line.startswith("| o | beta_hat |"))
    assert "not computed" in row and row.rstrip(" |").endswith("no verdict: linear bicycle baseline not computed")
    assert f"o: linear bicycle baseline not computed for beta_hat: {why}; no verdict" in md
    tt = report.text_table(m)
    assert "  linear bicycle baseline: not computed (below)" in tt and why in tt
    overview = report.render(".", [report.ReportSection("x", m)])
    assert "no verdict: linear bicycle baseline not computed" in overview


def test_the_design_files_own_stiffnesses_are_used():
    """A design file for a new car named "sedan" with its own Cf, Cr: the bicycle runs on them."""
    own = dict(SEDAN, Cf=61000.0, Cr=83000.0, lr=1.742)
    m = metrics.compute(_sim(_design(own), observer_offset=0.0))
    about = m["observers"]["o"]["baselines"]["about"]["bicycle"]
    assert about["parameters"] == own and about["vehicle"] == "sedan"


def test_replay_says_when_the_bicycle_is_not_computed():
    own = {"m": 1234.0, "Iz": 2222.0, "lf": 1.1, "lr": 1.5}
    d = design_summary({"vehicle": {"name": "mbds_250lm", "parameters": own}}, "S.fmu:resources/S.design.json")
    t = 100.0 + 0.01 * np.arange(501)
    delta, vx = 0.01 * np.sin(1.5 * t), np.full_like(t, 25.0)
    ref = bl.bicycle(t, delta, vx, SEDAN, initial="steady")
    run = ReplayRun(time=t, columns={"delta": delta, "vx": vx, "beta": ref["beta"]},
                    outputs={"beta_hat": ref["beta"] + 1e-4}, inputs=[], dt=0.01, fmu=None, model_name="Obs",
                    label="Obs", design=d)
    m = score(run, split=None, info={"csv": "r.csv"})
    s = m["observers"]["Obs"]["baselines"]["summary"]["beta_hat"]
    assert set(s["not_computed"]) == {"bicycle"} and s["observer_best"] is None
    tt = report.text_table(m)
    assert "RMS error, linear bicycle baseline: not computed" in tt and "S.fmu:resources/S.design.json" in tt
    assert "RMS error, linear bicycle baseline: not computed" in report.metrics_markdown(m)


@pytest.mark.slow
def test_replay_for_a_new_car_named_like_a_shipped_set_never_takes_that_sets_parameters(tmp_path):
    """A vehicle file named "mbds_250lm" (a shipped set's name) with its own stiffnesses and lr is
    refused (its FMUs would take the shipped set's names). Renamed, the replay's bicycle baseline
    runs on the file's parameters, carried by the design file, or is reported as not computed with
    no verdict; never on the shipped set's Cf, Cr."""
    import re
    from importlib import resources

    from latobs import pipeline

    text = (resources.files("latobs.synthesis") / "vehicles" / "mbds_250lm.toml").read_text()
    own = {"lr": 1.2, "Cf": 90000.0, "Cr": 150000.0}
    for k, v in own.items():      # the [parameters] entry (the first line "k = { value = ...")
        text = re.sub(rf"^{k}\s*=\s*{{\s*value\s*=\s*[0-9.]+", f"{k} = {{ value = {v}", text, count=1, flags=re.M)
    toml = tmp_path / "newcar.toml"
    toml.write_text(text)
    with pytest.raises(VehicleParameterError, match="give it a name of its own"):
        load_vehicle(str(toml))
    toml.write_text(text.replace('name = "mbds_250lm"', 'name = "newcar"', 1))
    veh = load_vehicle(str(toml))
    assert veh.name == "newcar" and {k: veh.value(k) for k in own} == own
    t = 10.0 + 0.01 * np.arange(2001)
    delta, vx = 0.01 * np.sin(0.8 * (t - 10)), np.full_like(t, 25.0)
    ref = bl.bicycle(t, delta, vx, {k: veh.value(k) for k in bl.BICYCLE_PARAMETERS}, initial="steady")
    rows = ["t,delta,vx,yaw_rate,beta"] + [",".join(repr(float(x)) for x in r)
                                           for r in zip(t, delta, vx, ref["yaw_rate"], ref["beta"])]
    csv = tmp_path / "newcar.csv"
    csv.write_text("\n".join(rows) + "\n")
    m = pipeline.replay(csv, "SideslipFixedOrderEstimator", vehicle=str(toml), out=tmp_path / "out",
                        fmu_dir=tmp_path / "fmus", plots=False, quiet=True)
    b = next(iter(m["observers"].values()))["baselines"]
    s = b["summary"]["beta_hat"]
    if "bicycle" in b:           # the design file carries the file's Cf, Cr: the record is that model
        assert {k: b["about"]["bicycle"]["parameters"][k] for k in own} == own
        assert b["bicycle"]["beta_hat"]["all"]["rms"] < 1e-9
    else:
        assert "does not carry" in s["not_computed"]["bicycle"] and s["observer_best"] is not True
