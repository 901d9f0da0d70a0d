"""``latobs replay``: the bundled MBDS record, the CSV loader, replay through a built observer FMU
(checked against the co-simulation harness on the same signals), the split scores, errors, and
the truth-signal mapping (metrics.REFERENCE_SIGNALS) of the co-simulation metrics and plots."""
from __future__ import annotations

import gzip
import json
import math

import numpy as np
import pytest

from latobs.cli import main
from latobs.validation import metrics, plots, report
from latobs.validation.harness import SimResult
from latobs.validation.replay import (
    MBDS_CSV,
    ReplayError,
    ReplayRun,
    default_split,
    drive,
    load_csv,
    resolve_csv,
    score,
    uniform_step,
)

MBDS_COLUMNS = ["t", "delta", "vx", "vy", "yaw_rate", "ay", "ax", "beta"]


def _write_csv(path, cols: dict[str, np.ndarray]):
    names = list(cols)
    lines = [",".join(names)] + [",".join(repr(float(x)) for x in row) for row in zip(*(cols[n] for n in names))]
    text = "\n".join(lines) + "\n"
    if str(path).endswith(".gz"):
        with gzip.open(path, "wt") as fh:
            fh.write(text)
    else:
        path.write_text(text)
    return path


# ------------------------------------------------------------------------------------------------
# the bundled record and the loader
# ------------------------------------------------------------------------------------------------
def test_bundled_mbds_record_loads_as_documented():
    assert MBDS_CSV.is_file() and MBDS_CSV.name.endswith(".csv.gz")
    assert (MBDS_CSV.parent / "LICENSE").is_file() and (MBDS_CSV.parent / "README.md").is_file()
    assert "held-out" in (MBDS_CSV.parent / "README.md").read_text()
    assert resolve_csv("mbds") == MBDS_CSV
    d = load_csv(MBDS_CSV)
    assert list(d) == MBDS_COLUMNS
    assert all(v.shape == (55_001,) for v in d.values())
    assert d["t"][0] == pytest.approx(149.99) and d["t"][-1] == pytest.approx(699.99)
    assert uniform_step(d["t"]) == pytest.approx(0.01, rel=1e-9)
    assert default_split(MBDS_CSV) == 425.0
    assert np.sum(d["t"] < 425.0) == 27_501                  # the tuning part; the rest is held out
    assert 16 < d["vx"].min() and d["vx"].max() < 62          # m/s, as the README says
    assert np.max(np.abs(d["beta"])) < math.radians(6)        # rad


def test_loader_names_the_culprit(tmp_path):
    good = {"t": np.arange(5) * 0.01, "a": np.ones(5)}
    assert set(load_csv(_write_csv(tmp_path / "ok.csv.gz", good))) == {"t", "a"}

    p = tmp_path / "text.csv"
    p.write_text("t,a\n0,1\n0.01,x\n0.02,3\n")
    with pytest.raises(ReplayError, match=r"text.csv: column 'a', line 3: 'x' is not a number"):
        load_csv(p)
    p.write_text("t,a\n0,1\n0.01,nan\n0.02,3\n")
    with pytest.raises(ReplayError, match=r"column 'a', line 3: value 'nan' is not finite"):
        load_csv(p)
    p.write_text("t,a\n0,1\n0.02,2\n0.01,3\n")
    with pytest.raises(ReplayError, match=r"column 't' is not strictly increasing at line 4"):
        load_csv(p)
    p.write_text("time,a\n0,1\n1,2\n")
    with pytest.raises(ReplayError, match=r"no time column 't'"):
        load_csv(p)
    p.write_text("t,a\n0,1\n1,2,3\n")
    with pytest.raises(ReplayError, match=r"line 3 has 3 field\(s\), the header 2"):
        load_csv(p)
    bad = tmp_path / "bad.csv.gz"
    bad.write_bytes(b"not gzip at all")
    with pytest.raises(ReplayError, match=r"bad.csv.gz: cannot read it"):
        load_csv(bad)
    with pytest.raises(ReplayError, match=r"no such file"):
        load_csv(tmp_path / "missing.csv")
    with pytest.raises(ReplayError, match=r"time step is not uniform"):
        uniform_step(np.array([0.0, 0.01, 0.02, 0.0351]), "f.csv")
    uniform_step(np.arange(100) * 0.01 + 1e-10)              # float noise is fine


# ------------------------------------------------------------------------------------------------
# replay through the real SideslipBankObserver FMU
# ------------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def cosim_csv(fmu_dir, tmp_path_factory):
    """bank-braking at 100 Hz co-simulated with CarPlant and the observer: (CSV path, SimResult)."""
    from latobs.validation.harness import run

    sim = run("bank-braking", fmu_dir / "CarPlant.fmu", {"obs": fmu_dir / "SideslipBankObserver.fmu"}, dt=0.01)
    path = _write_csv(tmp_path_factory.mktemp("replay") / "bank_braking_100hz.csv", {"t": sim.time, **sim.bus})
    return path, sim


@pytest.mark.slow
def test_replay_matches_the_cosimulation_and_scores_both_sides_of_the_split(cosim_csv, fmu_dir, tmp_path, capsys):
    path, sim = cosim_csv
    # the replay drives the FMU exactly as the harness does: same outputs at the same instants
    rr = drive(fmu_dir / "SideslipBankObserver.fmu", load_csv(path))
    for name, y in sim.observers["obs"].items():
        np.testing.assert_allclose(rr.outputs[name], y, rtol=0, atol=1e-12, err_msg=name)

    assert main(["replay", str(path), "--observer", "SideslipBankObserver", "--fmu-dir", str(fmu_dir),
                 "--out", str(tmp_path), "--split", "12.5"]) == 0
    out = capsys.readouterr().out
    assert "beta_hat" in out and "t < 12.5 s" in out
    d = tmp_path / "replay_bank_braking_100hz_SideslipBankObserver"
    m = json.loads((d / "metrics.json").read_text())
    assert (d / "replay.png").is_file() and (d / "replay_zoom.png").is_file()   # 30 s record > 20 s zoom
    assert m["kind"] == "replay" and m["observer"] == "SideslipBankObserver" and m["split_s"] == 12.5
    assert m["dt_s"] == pytest.approx(0.01) and m["n_samples"] == 3001 and not m["nothing_scored"]
    seg = m["segments"]
    assert seg["before_split"]["n_samples"] + seg["after_split"]["n_samples"] == seg["all"]["n_samples"] == 3001
    assert seg["after_split"]["t_from_s"] == pytest.approx(12.5)
    o = m["observers"]["SideslipBankObserver"]
    assert set(o["estimates"]) == {"beta_hat", "yaw_rate_hat", "roll_angle_hat", "roll_rate_hat", "bank_angle_hat"}
    for name, e in o["estimates"].items():
        a, b, c = e["all"], e["before_split"], e["after_split"]
        assert b["n_samples"] + c["n_samples"] == a["n_samples"] == 3001
        # the whole record's mean square is the sample-weighted mean of the two parts'
        assert a["rms"] ** 2 * 3001 == pytest.approx(b["rms"] ** 2 * b["n_samples"] + c["rms"] ** 2 * c["n_samples"])
        assert a["max_abs"] == pytest.approx(max(b["max_abs"], c["max_abs"]))
    beta = o["estimates"]["beta_hat"]
    assert beta["truth"] == "beta" and beta["unit"] == "rad"
    # the same error as the co-simulation metrics on the same run
    ref = metrics.compute(sim)["observers"]["obs"]["estimates"]["beta_hat"]
    assert beta["all"]["rms"] == pytest.approx(ref["rms"], rel=1e-9)
    assert beta["all"]["rms"] < 5e-3                                          # rad
    occ = o["modes"]["all"]["occupancy"]
    assert sum(occ.values()) == pytest.approx(1.0) and len(occ) == 3         # 90 -> 36 km/h: all speed modes
    assert "may_in_force_sum" not in o                                        # no force bounds
    assert "beta_hat" in report.metrics_markdown(m)

    # no split for an unknown file by default; --no-plots writes the metrics only
    assert main(["replay", str(path), "--observer", "SideslipBankObserver", "--fmu-dir", str(fmu_dir),
                 "--out", str(tmp_path / "b"), "--no-plots"]) == 0
    d2 = tmp_path / "b" / "replay_bank_braking_100hz_SideslipBankObserver"
    m2 = json.loads((d2 / "metrics.json").read_text())
    assert m2["split_s"] is None and set(m2["segments"]) == {"all"} and not list(d2.glob("*.png"))
    assert m2["observers"]["SideslipBankObserver"]["estimates"]["beta_hat"]["all"] == beta["all"]


@pytest.mark.slow
def test_replay_steps_in_the_compiled_loop_as_in_the_python_loop(built_fmus, monkeypatch):
    """The replay steps its FMU in the master's stepping loop (compiled where it can be): on the
    MBDS record the native interval observer's outputs and logs are those of the Python loop, bit
    for bit, and the outputs at t_0 are the initialisation's."""
    from latobs.validation import compiled_loop

    if compiled_loop.unavailable_reason() is not None:
        pytest.skip(f"no compiled loop here: {compiled_loop.unavailable_reason()}")
    data = load_csv(resolve_csv("mbds"))
    data = {k: v[:6000] for k, v in data.items()}                    # the first 60 s
    fmu = built_fmus.c_path("LateralIntervalObserver")
    compiled = drive(fmu, data)
    monkeypatch.setattr(compiled_loop, "library", lambda: None)
    python = drive(fmu, data)
    assert compiled.outputs.keys() == python.outputs.keys()
    for k, y in python.outputs.items():
        assert compiled.outputs[k].dtype == y.dtype and np.array_equal(compiled.outputs[k], y), k
    assert compiled.logs == python.logs
    assert compiled.outputs["vy_lower"][0] < compiled.outputs["vy_upper"][0]    # the initial box, not zeros


@pytest.mark.slow
def test_replay_errors_exit_2_naming_the_culprit(cosim_csv, fmu_dir, tmp_path, capsys):
    _, sim = cosim_csv
    base = ["--observer", "SideslipBankObserver", "--fmu-dir", str(fmu_dir), "--out", str(tmp_path / "out")]
    cols = {"t": sim.time, **{k: v for k, v in sim.bus.items() if k != "roll_rate"}}
    no_roll_rate = _write_csv(tmp_path / "no_roll_rate.csv", cols)
    assert main(["replay", str(no_roll_rate), *base]) == 2
    err = capsys.readouterr().err
    assert "lacks 'roll_rate'" in err and "its columns: t, delta" in err
    assert len(err.strip().splitlines()) == 1

    t = sim.time.copy()
    t[100:] += 0.003                                          # one step of 13 ms among 10 ms steps
    jittered = _write_csv(tmp_path / "jitter.csv", {"t": t, **sim.bus})
    assert main(["replay", str(jittered), *base]) == 2
    err = capsys.readouterr().err
    assert "jitter.csv: the time step is not uniform" in err and "t = 0.99 s" in err

    assert main(["replay", str(jittered), "--observer", "NoSuchObserver"]) == 2
    assert "unknown observer 'NoSuchObserver'" in capsys.readouterr().err
    assert main(["replay", str(tmp_path / "nope.csv"), *base]) == 2
    assert "nope.csv: no such file" in capsys.readouterr().err
    assert main(["replay", str(no_roll_rate), *base, "--split", "soon"]) == 2
    assert "--split" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()                   # nothing written on an error


# ------------------------------------------------------------------------------------------------
# scoring without an FMU: nothing to score, the force sum of paper 001, the truth mapping
# ------------------------------------------------------------------------------------------------
def _run(outputs, columns, model="Obs", n=None):
    n = n or len(next(iter(columns.values())))
    t = 10.0 + 0.1 * np.arange(n)
    return ReplayRun(time=t, columns=columns, outputs=outputs, inputs=[], dt=0.1, fmu=None, model_name=model,
                     label=model, units={})


def test_replay_without_reference_says_nothing_was_scored():
    rr = _run({"foo_hat": np.zeros(4), "mode": np.ones(4, dtype=np.int64)}, {"bar": np.zeros(4)})
    m = score(rr, split=None, info={"csv": "x.csv"})
    assert m["nothing_scored"] and m["scored"] == [] and m["observers"]["Obs"]["unscored_outputs"] == ["foo_hat"]
    assert "nothing was scored" in report.text_table(m) and "nothing was scored" in report.metrics_markdown(m)


def test_may_in_force_sum_and_cg_truth_in_replay():
    n = 10
    ay = np.linspace(-2, 2, n)
    mass = 1000.0
    f = mass * ay
    outs = {"Fyf_lower": 0.5 * f - 100, "Fyr_lower": 0.5 * f - 100, "Fyf_upper": 0.5 * f + 100,
            "Fyr_upper": 0.5 * f + 100, "vy_lower": -np.ones(n), "vy_upper": np.ones(n)}
    outs["Fyf_upper"][[2, 7]] -= 500                          # two samples where m*ay is above the sum
    cols = {"ay": ay, "vy": np.zeros(n), "vy_cg": np.full(n, 2.0)}
    m = score(_run(outs, cols, model="LateralIntervalObserver_mbds_250lm"), split=10.45, mass=mass,
              vehicle="v", info={"csv": "r.csv"})
    o = m["observers"]["LateralIntervalObserver_mbds_250lm"]
    fs = o["may_in_force_sum"]
    assert fs["mass_kg"] == mass and fs["unit"] == "N"
    assert fs["all"]["enclosure_violations"] == 2 and fs["all"]["enclosure_rate"] == pytest.approx(0.8)
    assert fs["before_split"]["enclosure_violations"] == 1 and fs["after_split"]["enclosure_violations"] == 1
    assert fs["all"]["mean_width"] == pytest.approx(400 - 100)
    vy = o["intervals"]["vy"]                                 # CG truth when the record has it
    assert vy["truth"] == "vy_cg" and vy["all"]["violation_rate"] == 1.0
    del cols["vy_cg"]
    o = score(_run(outs, cols, model="LateralIntervalObserver_mbds_250lm"), mass=mass)["observers"]
    vy = o["LateralIntervalObserver_mbds_250lm"]["intervals"]["vy"]
    assert vy["truth"] == "vy" and vy["all"]["enclosure_violations"] == 0   # MBDS: vy is at the CG
    assert "m*ay" in report.text_table(score(_run(outs, {"ay": ay}), mass=mass, info={"csv": "r.csv"}))


def test_a_filtered_output_is_scored_one_step_behind_in_replay_and_validate():
    """X_filtered (the Kalman filter's x(k|k)) at row k + 1 estimates the truth at row k: an output
    that is the truth delayed by one row scores zero, and the truth itself does not."""
    n = 12
    beta = np.sin(np.arange(n, dtype=float))
    behind = np.concatenate([[0.0], beta[:-1]])               # row k + 1 holds the truth of row k
    outs = {"beta_hat": beta.copy(), "beta_filtered": behind, "vy_filtered": beta.copy()}
    cols = {"beta": beta, "vy": beta}
    o = score(_run(outs, cols), split=10.55)["observers"]["Obs"]
    f = o["estimates"]["beta_filtered"]
    assert f["lag_steps"] == 1 and f["truth"] == "beta"
    assert f["all"]["rms"] == 0.0 and f["all"]["n_samples"] == n - 1
    assert f["before_split"]["n_samples"] == 6 and f["after_split"]["n_samples"] == 5
    assert o["estimates"]["vy_filtered"]["all"]["rms"] > 0.5          # not delayed: wrong by a step
    assert o["estimates"]["beta_hat"]["all"]["rms"] == 0.0 and "lag_steps" not in o["estimates"]["beta_hat"]
    assert "beta_filtered" in o["baselines"]["summary"]                # beside the baselines too,
    zero = o["baselines"]["zero"]                                      # on the times it estimates
    assert zero["beta_filtered"]["all"]["n_samples"] == n - 1 and zero["beta_hat"]["all"]["n_samples"] == n
    assert zero["beta_filtered"]["all"]["rms"] == pytest.approx(np.sqrt(np.mean(beta[:-1] ** 2)))
    m = score(_run(outs, cols), split=10.55, info={"csv": "r.csv"})
    assert "beta_filtered (1 step behind)" in report.text_table(m)     # the tables say so
    assert "beta_filtered (1 step behind)" in report.metrics_markdown(m)
    t = 0.1 * np.arange(n)
    r = SimResult(time=t, bus=cols, observers={"kf": outs}, logs={}, scenario="x", dt=0.1, info={})
    e = metrics.compute(r, settle_time=0.0)["observers"]["kf"]["estimates"]
    assert e["beta_filtered"]["rms"] == 0.0 and e["beta_filtered"]["lag_steps"] == 1
    assert e["vy_filtered"]["rms"] > 0.5
    zero = metrics.compute(r, settle_time=0.0)["observers"]["kf"]["baselines"]["zero"]
    assert zero["beta_filtered"]["rms"] == pytest.approx(np.sqrt(np.mean(beta[:-1] ** 2)))


def test_reference_signals_map_observer_to_the_truth_at_its_point(tmp_path):
    assert metrics.reference_map("LateralIntervalObserver") == {"vy": "vy_cg", "beta": "beta_cg"}
    assert metrics.reference_map("LateralIntervalObserver_mbds_250lm") == metrics.reference_map("LateralIntervalObserver")
    assert metrics.reference_map("LateralIntervalObserverX") == {}         # a prefix must end at "_"
    assert metrics.reference_map("SideslipBankObserver") == {} and metrics.reference_map(None) == {}

    n = 6
    t = 0.1 * np.arange(n)
    bus = {"vy": np.zeros(n), "vy_cg": np.full(n, 0.5), "beta": np.zeros(n), "beta_cg": np.full(n, 0.02)}
    lio = {"vy_lower": np.full(n, 0.4), "vy_upper": np.full(n, 0.6),        # encloses vy_cg, not vy
           "beta_lower": np.full(n, 0.01), "beta_upper": np.full(n, 0.03)}
    sbo = {"beta_hat": np.full(n, 0.001)}
    info = {"observer_models": {"lio": "LateralIntervalObserver_mbds_250lm", "sbo": "SideslipBankObserver"}}
    r = SimResult(time=t, bus=bus, observers={"lio": lio, "sbo": sbo}, logs={}, scenario="x", dt=0.1, info=info)
    m = metrics.compute(r)["observers"]
    assert m["lio"]["intervals"]["vy"]["truth"] == "vy_cg" and m["lio"]["intervals"]["vy"]["enclosure_violations"] == 0
    assert m["lio"]["intervals"]["beta"]["truth"] == "beta_cg"
    assert m["lio"]["intervals"]["beta"]["enclosure_violations"] == 0
    assert m["sbo"]["estimates"]["beta_hat"]["truth"] == "beta"
    assert m["sbo"]["estimates"]["beta_hat"]["rms"] == pytest.approx(0.001)
    assert plots._truths(r) == {"beta": {"lio": "beta_cg", "sbo": "beta"}, "vy": {"lio": "vy_cg"}}
    assert plots.estimated_signals(r) == ["beta", "vy"]
    assert plots.plot_estimates(r, tmp_path).is_file()

    # the mapped signal only when it is on the bus; else the plain one
    bus2 = {"vy": bus["vy"], "beta": bus["beta"]}
    r2 = SimResult(time=t, bus=bus2, observers={"lio": lio}, logs={}, scenario="x", dt=0.1, info=info)
    m2 = metrics.compute(r2)["observers"]["lio"]["intervals"]
    assert m2["vy"]["truth"] == "vy" and m2["vy"]["enclosure_violations"] == n
    # no model information (older SimResults): plain names
    r3 = SimResult(time=t, bus=bus, observers={"lio": lio}, logs={}, scenario="x", dt=0.1)
    assert metrics.compute(r3)["observers"]["lio"]["intervals"]["vy"]["truth"] == "vy"
