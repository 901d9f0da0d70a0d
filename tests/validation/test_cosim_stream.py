"""A long co-simulation streamed in blocks (issue 47, item 4): the same rows and metrics as the
whole-array run, in a memory that does not grow with its length."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from latobs.validation import campaign_run as cr
from latobs.validation import get_scenario, harness, master, metrics, stream, validate
from test_resources import _close, _without     # the comparison of the streamed replay's test

NOISE = {"yaw_rate": (0.002, 0.001), "ay": (0.05, 0.0), "delta": (0.0005, 0.0)}


@pytest.fixture(scope="module")
def fmus(fmu_dir, built_fmus):
    return fmu_dir / "CarPlant.fmu", {"SideslipBankObserver": fmu_dir / "SideslipBankObserver.fmu",
                                      "LateralIntervalObserver": built_fmus.path("LateralIntervalObserver")}


def _kwargs():
    return {"dt": 0.005, "noise": harness.NoiseSpec(NOISE), "seed": 7}


def test_noise_drawn_in_blocks_is_the_whole_runs_draw_bit_for_bit():
    spec = harness.NoiseSpec(NOISE, seed=3)
    whole = spec.draw(10_001, 0)
    blocks = spec.blocks(10_001, 0)
    parts = [blocks.take(m) for m in (1, 2999, 5000, 2001)]
    for x, v in whole.items():
        assert np.concatenate([p[x] for p in parts]).tobytes() == v.tobytes(), x


def test_a_streamed_cosimulation_gives_the_whole_runs_rows_and_metrics(fmus, tmp_path, monkeypatch):
    import pyarrow.parquet as pq

    plant, observers = fmus
    sc = get_scenario("bank-braking")                          # 30 s at 5 ms: 6000 steps
    whole = harness.run(sc, plant, observers, **_kwargs())
    m_whole = metrics.compute(whole)
    flat_whole = cr.result_metrics(whole, 4.0)
    # a short run keeps the whole-array path: no outputs.parquet, no "streamed"
    _, m_short, paths = validate(sc, plant, observers, tmp_path / "short", plots=False, **_kwargs())
    assert "streamed" not in m_short and not (tmp_path / "short" / "outputs.parquet").exists()
    assert len(paths) == 1

    monkeypatch.setenv(master.STREAM_ENV, "1000")
    monkeypatch.setattr(master, "BLOCK_STEPS", 1700)            # 4 blocks, the last one short
    sink = stream.CosimSink(tmp_path / "s", keep=True, flat_settle=4.0)
    res, m, paths = validate(sc, plant, observers, tmp_path / "s", plots=False, sink=sink, **_kwargs())
    assert m["streamed"]["blocks"] == 4 and m["streamed"]["outputs"] == "outputs.parquet"
    assert paths == [tmp_path / "s" / "metrics.json", tmp_path / "s" / "outputs.parquet"]
    assert json.loads((tmp_path / "s" / "metrics.json").read_text())["n_samples"] == whole.time.size

    # every row, bit for bit the whole run's
    table = pq.read_table(tmp_path / "s" / "outputs.parquet").to_pydict()
    assert np.asarray(table["t"]).tobytes() == whole.time.tobytes()
    for x, v in whole.bus.items():
        assert np.asarray(table[x], dtype=float).tobytes() == v.tobytes(), x
    for x, v in whole.measured.items():
        assert np.asarray(table[f"measured.{x}"], dtype=float).tobytes() == v.tobytes(), x
    for lab, outs in whole.observers.items():
        for x, v in outs.items():
            assert np.array_equal(np.asarray(table[f"{lab}.{x}"]), v), (lab, x)
            assert np.asarray(table[f"{lab}.{x}"]).dtype == v.dtype, (lab, x)

    # the metrics summed over the blocks: the whole run's (to the rounding of the sums)
    keys = ("baselines", "streamed", "info")
    _close(_without(m_whole, keys), _without(m, keys))
    for lab, o in m["observers"].items():
        b, bw = o["baselines"], m_whole["observers"][lab]["baselines"]
        _close(bw["zero"], b["zero"])                            # the zero baseline, summed over the blocks
        assert "not computed for a streamed co-simulation" in b["skipped"]["bicycle"]
        for name, v in b["summary"].items():
            if "bicycle" in bw["summary"][name]["baselines"]:      # no verdict that the observer is best
                assert v["observer_best"] is not True and "bicycle" in v["not_computed"]
                assert v["observer_rms"] == pytest.approx(bw["summary"][name]["observer_rms"], rel=1e-12)
            else:                                                  # the bicycle gives no such estimate
                _close(bw["summary"][name], v)
    # the campaign's flat metrics: the whole run's, but for the model baseline's
    flat = sink.flat(res)
    model = {k for k in flat_whole if k.endswith(("ratio", "wins")) or "bicycle" in k}
    assert set(flat) == set(flat_whole) - {k for k in flat_whole if "bicycle" in k}
    _close({k: v for k, v in flat_whole.items() if k not in model}, {k: v for k, v in flat.items() if k not in model})
    for k, v in flat.items():
        if k.endswith(".ratio"):
            key = k[:-len(".ratio")]
            obs = flat.get(key + ".midpoint_rms", flat.get(key + ".rms"))
            assert v == pytest.approx(obs / flat[key + ".rms_zero"], rel=1e-12), k
    # the figures' samples: every k-th of the whole run
    assert res.time.size == whole.time.size and res.time.tobytes() == whole.time.tobytes()   # k = 1 here


def test_a_streamed_run_keeps_every_kth_sample_for_its_figures(fmus, tmp_path, monkeypatch):
    plant, observers = fmus
    sc = get_scenario("bank-braking", duration=10.0)
    whole = harness.run(sc, plant, {"SideslipBankObserver": observers["SideslipBankObserver"]}, dt=0.005)
    monkeypatch.setenv(master.STREAM_ENV, "100")
    monkeypatch.setattr(master, "BLOCK_STEPS", 300)
    monkeypatch.setattr(stream, "PLOT_SAMPLES", 500)            # 2001 samples: every 5th
    res, m, paths = validate(sc, plant, {"SideslipBankObserver": observers["SideslipBankObserver"]},
                             tmp_path / "f", plots=True, dt=0.005)
    assert m["streamed"]["figures_every_kth_sample"] == 5
    assert res.time.tobytes() == whole.time[::5].tobytes()
    assert res.observers["SideslipBankObserver"]["beta_hat"].tobytes() == \
        whole.observers["SideslipBankObserver"]["beta_hat"][::5].tobytes()
    assert any(p.suffix == ".png" for p in paths)


def test_a_campaign_run_streamed_gives_the_flat_metrics_of_the_whole_run(fmus, monkeypatch):
    """A campaign worker's run (no output folder): the flat metrics summed over the blocks."""
    plant, observers = fmus
    sc = get_scenario("double-lane-change-15")
    obs = {"LateralIntervalObserver": observers["LateralIntervalObserver"]}
    whole = cr.result_metrics(harness.run(sc, plant, obs, dt=0.002), 2.0)
    monkeypatch.setenv(master.STREAM_ENV, "100")
    monkeypatch.setattr(master, "BLOCK_STEPS", 1000)
    with stream.CosimSink(None, keep=False, settle_time=2.0) as sink:
        res = harness.run(sc, plant, obs, dt=0.002, sink=sink)
    assert sink.used and res.time.size == 0 and res.info["streamed"]["blocks"] == 5
    flat = sink.flat(res)
    same = {k for k in flat if not k.endswith(("ratio", "wins"))}
    _close({k: whole[k] for k in same}, {k: flat[k] for k in same})


_RSS = textwrap.dedent("""
    import json, sys
    from pathlib import Path
    from latobs.validation import get_scenario, master, validate
    master.BLOCK_STEPS = 10000
    plant, obs, out, above = Path(sys.argv[1]), Path(sys.argv[2]), Path(sys.argv[3]), sys.argv[5]
    def status(key):
        for line in open("/proc/self/status"):
            if line.startswith(key + ":"):
                return int(line.split()[1]) / 1024
    def run(seconds, tag):
        validate(get_scenario("bank-braking", duration=seconds), plant, {"SideslipBankObserver": obs}, out / tag,
                 plots=False, dt=0.001, noise={"yaw_rate": (0.002, 0.0)})
    import os
    os.environ["LATOBS_STREAM_ABOVE_STEPS"] = "1000"
    run(5.0, "warm")                                  # imports, the compiled loop: what any length needs
    os.environ["LATOBS_STREAM_ABOVE_STEPS"] = above
    with open("/proc/self/clear_refs", "w") as fh:    # the peak (VmHWM) from here on
        fh.write("5")
    base = status("VmRSS")
    run(float(sys.argv[4]), "long")
    print(json.dumps({"growth_mb": status("VmHWM") - base}))
""")


@pytest.mark.skipif(not Path("/proc/self/clear_refs").exists(), reason="needs Linux's /proc/self/clear_refs")
def test_a_streamed_cosimulation_holds_the_same_memory_for_a_run_8_times_longer(fmus, tmp_path):
    """The peak memory a streamed co-simulation adds (after a first one imported everything)
    does not grow with its length; the whole-array run's, the control, does: 8 s and 64 s at 1 ms."""
    plant, observers = fmus

    def growth(seconds: float, above: str) -> float:
        out = subprocess.run([sys.executable, "-c", _RSS, str(plant), str(observers["SideslipBankObserver"]),
                              str(tmp_path), str(seconds), above], capture_output=True, text=True, timeout=600,
                             env=os.environ.copy(), cwd=tmp_path)   # (the checkout's root would shadow latobs)
        assert out.returncode == 0, out.stderr
        return json.loads(out.stdout.strip().splitlines()[-1])["growth_mb"]

    short, long = growth(8.0, "1000"), growth(64.0, "1000")
    assert long - short < 5, (short, long)
    whole_short, whole_long = growth(8.0, "1e9"), growth(64.0, "1e9")
    assert whole_long - whole_short > 20, (whole_short, whole_long)      # the control: it does grow
