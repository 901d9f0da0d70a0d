"""``latobs replay`` checks the record before anything is built or run: its time axis (uniform,
judged relative to the first sample, so Unix timestamps are fine), the columns the observer
needs (an observer that cannot run on the record is refused, naming the signals), the units
of its angles and the inputs' declared ranges."""
from __future__ import annotations

import json
import shutil
import time

import numpy as np
import pytest

from latobs import pipeline
from latobs.cli import main
from latobs.validation import replay as rp
from latobs.validation.replay import ReplayError, uniform_step

UNIX_T0 = 1.7e9          # s, November 2023 in Unix time: one ulp of t is 2.4e-7 s


def _write_csv(path, cols: dict[str, np.ndarray]):
    names = list(cols)
    rows = [",".join(repr(float(x)) for x in row) for row in zip(*(cols[n] for n in names))]
    path.write_text("\n".join([",".join(names), *rows]) + "\n")
    return path


def _car_record(t: np.ndarray) -> dict[str, np.ndarray]:
    """The inputs of SideslipBankObserver and a sideslip column, SI units, on the time axis t."""
    s = t - t[0]
    n = t.size
    return {"t": t, "delta": 0.02 * np.sin(0.5 * s), "vx": np.full(n, 20.0), "yaw_rate": 0.1 * np.sin(0.5 * s),
            "roll_angle": np.zeros(n), "roll_rate": np.zeros(n), "beta": 0.01 * np.sin(0.5 * s)}


# ------------------------------------------------------------------------------------------------
# the time axis
# ------------------------------------------------------------------------------------------------
def test_a_uniform_50_hz_record_in_unix_time_is_uniform():
    t = UNIX_T0 + 0.02 * np.arange(3000)
    steps = np.diff(t)
    assert steps.max() - steps.min() > 2e-7            # the doubles' rounding: 1 ulp either way
    assert uniform_step(t) == pytest.approx(0.02, rel=1e-9)
    # the same times as text with millisecond resolution (as loggers write them)
    assert uniform_step(np.array([float(f"{x:.3f}") for x in t])) == pytest.approx(0.02, rel=1e-9)


def test_a_gap_is_named_with_its_size_and_place():
    t = UNIX_T0 + 0.02 * np.arange(3000)
    t[1000:] += 0.02                                   # one sample dropped
    with pytest.raises(ReplayError) as e:
        uniform_step(t, "u.csv")
    msg = str(e.value)
    assert "u.csv: the time step is not uniform: a gap of 0.04 s between data rows 1000 and 1001" in msg
    assert "t = 1700000019.98 s and 1700000020.02 s" in msg and "19.98 s after the first sample" in msg
    assert "usual step is 0.02 s" in msg and "resample" in msg
    # a logger's jitter within 5 % of the step passes (one rule with identify: latobs.data.checks);
    # a step 30 % long is refused
    t = 0.01 * np.arange(200)
    t[50:] += 2e-7
    assert uniform_step(t) == pytest.approx(0.01, rel=1e-6)
    t[100:] += 0.003
    with pytest.raises(ReplayError, match="a gap of 0.013 s between data rows 100 and 101"):
        uniform_step(t)


def test_replay_of_a_unix_time_record_runs(built_fmus, tmp_path, capsys):
    fmu_dir = tmp_path / "fmus"
    fmu_dir.mkdir()
    shutil.copy2(built_fmus.path("SideslipBankObserver"), fmu_dir)
    csv = _write_csv(tmp_path / "unix_50hz.csv", _car_record(UNIX_T0 + 0.02 * np.arange(1500)))
    assert main(["replay", str(csv), "--observer", "SideslipBankObserver", "--fmu-dir", str(fmu_dir),
                 "--out", str(tmp_path / "out"), "--no-plots"]) == 0
    assert "t = 1700000000 … 1700000029.98 s" in capsys.readouterr().out      # the record's own times
    m = json.loads((tmp_path / "out" / "replay_unix_50hz_SideslipBankObserver" / "metrics.json").read_text())
    assert m["dt_s"] == pytest.approx(0.02, rel=1e-9) and m["n_samples"] == 1500
    beta = m["observers"]["SideslipBankObserver"]["estimates"]["beta_hat"]["all"]
    assert beta["nonfinite_samples"] == 0 and beta["rms"] is not None


# ------------------------------------------------------------------------------------------------
# columns, units and ranges: checked before any build
# ------------------------------------------------------------------------------------------------
@pytest.fixture
def no_build(monkeypatch):
    """Fails the test if anything is designed or built."""
    def refuse(*args, **kwargs):
        raise AssertionError(f"built something: {args}")
    monkeypatch.setattr(pipeline, "build", refuse)
    monkeypatch.setattr(pipeline, "design_one", refuse)


def test_a_missing_input_column_is_refused_before_any_build(tmp_path, capsys, no_build):
    cols = _car_record(0.01 * np.arange(300))
    del cols["roll_rate"]
    csv = _write_csv(tmp_path / "no_roll_rate.csv", cols)
    fmu_dir = tmp_path / "fmus"
    t0 = time.perf_counter()
    assert main(["replay", str(csv), "--observer", "SideslipBankObserver", "--fmu-dir", str(fmu_dir),
                 "--out", str(tmp_path / "out")]) == 2
    assert time.perf_counter() - t0 < 5.0              # no FMU was built (that takes ~10 s)
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1
    assert ("SideslipBankObserver cannot run on" in err and "no_roll_rate.csv" in err
            and "needs the signals delta, vx, yaw_rate, roll_angle, roll_rate" in err
            and "lacks 'roll_rate'" in err and "its columns: t, delta, vx, yaw_rate, roll_angle, beta" in err)
    assert not fmu_dir.exists() and not (tmp_path / "out").exists()


def test_an_angle_in_degrees_is_refused_before_any_build(tmp_path, capsys, no_build):
    cols = _car_record(0.01 * np.arange(300))
    cols["delta"] = np.degrees(cols["delta"]) * 10.0   # up to 11.5: degrees, not rad
    csv = _write_csv(tmp_path / "deg.csv", cols)
    assert main(["replay", str(csv), "--observer", "SideslipBankObserver", "--fmu-dir", str(tmp_path / "f"),
                 "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "column 'delta' is an angle in rad" in err and "looks like degrees" in err
    assert not (tmp_path / "f").exists()


def test_a_value_outside_a_declared_range_is_named():
    data = {"t": np.arange(4.0), "s": np.array([1.0, 2.0, 12.0, 3.0])}
    with pytest.raises(ReplayError, match=r"r.csv: column 's' = 12 at data row 3 is outside the range \[0.1, 10\] "
                                          r"that Obs declares for input 's' \(1 row\(s\) outside\)"):
        rp.check_record(data, [rp.InputSpec("s", "1", "0.1", "10")], "r.csv", "Obs")
    rp.check_record(data, [rp.InputSpec("s", "1", None, 20.0)], "r.csv", "Obs")          # inside: fine


def test_an_observer_that_cannot_run_on_the_record_is_refused(tmp_path, capsys, no_build):
    """The bundled MBDS record is a car's: the motorcycle's observer needs steer_angle and roll_rate."""
    assert main(["replay", "mbds", "--observer", "MotorcycleFaultObserver", "--fmu-dir", str(tmp_path / "f"),
                 "--out", str(tmp_path / "out")]) == 2
    cap = capsys.readouterr()
    assert "MotorcycleFaultObserver cannot run on" in cap.err and "mbds_250lm_100hz.csv.gz" in cap.err
    assert "needs the signals vx, steer_angle, yaw_rate, roll_rate" in cap.err
    assert "lacks 'steer_angle', 'roll_rate'" in cap.err
    assert "--vehicle" not in cap.out + cap.err       # no advice to use the car's parameters
    assert not (tmp_path / "f").exists()
