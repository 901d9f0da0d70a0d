"""Bounded resources (issue 47): inputs that would exhaust the machine are refused before they
run, records are regular files within a size limit, campaign names are safe folder names, and the
parallel build's workers and temporary folders do not outlive it."""
from __future__ import annotations

import gzip
import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from latobs.data import budget, records

#: runs a command in a child process and prints {"rc", "seconds", "maxrss_mb", "stderr"}: the peak
#: resident memory of that child alone (this launcher has no other child). The child's address
#: space is capped at 4 GB so that a version that would exhaust memory fails fast instead of
#: being killed with the machine.
_LAUNCHER = textwrap.dedent("""
    import json, resource, subprocess, sys, time
    def cap():
        resource.setrlimit(resource.RLIMIT_AS, (4 << 30, 4 << 30))
    t0 = time.perf_counter()
    try:
        p = subprocess.run(sys.argv[1:], capture_output=True, text=True, timeout=60, preexec_fn=cap)
        rc, err = p.returncode, p.stderr
    except subprocess.TimeoutExpired as exc:
        rc, err = "timeout", str(exc.stderr)
    seconds = time.perf_counter() - t0
    print(json.dumps({"rc": rc, "seconds": seconds, "stderr": err,
                      "maxrss_mb": resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024}))
""")


def _measured(args: list[str], cwd: Path, env: dict | None = None) -> dict:
    out = subprocess.run([sys.executable, "-c", _LAUNCHER, sys.executable, "-m", "latobs", *args], cwd=cwd,
                         capture_output=True, text=True, timeout=120, env={**os.environ, **(env or {})})
    return json.loads(out.stdout)


def _campaign_file(tmp_path: Path, name: str, extra: str) -> Path:
    path = tmp_path / f"{name}.toml"
    path.write_text(f'name = "{name}"\nscenario = "double-lane-change"\nobservers = ["SideslipBankObserver"]\n'
                    f"seed = 1\n{extra}\n", encoding="utf-8")
    return path


@pytest.mark.parametrize("case", ["campaign dt = 1e-9", "campaign runs = 1e10", "replay /dev/zero"])
def test_inputs_that_would_exhaust_memory_exit_2_within_5_s_using_less_than_500_mb(tmp_path, case):
    if case == "campaign dt = 1e-9":
        args = ["campaign", str(_campaign_file(tmp_path, "tiny_step", "runs = 10\ndt = 1e-9"))]
        expect = ["1e-09", "would need about", "more than the limit"]
    elif case == "campaign runs = 1e10":
        args = ["campaign", str(_campaign_file(tmp_path, "many_runs", "runs = 10000000000"))]
        expect = ["10000000000 runs", "would need about", "more than the limit"]
    else:
        if not Path("/dev/zero").exists():
            pytest.skip("no /dev/zero")
        args = ["replay", "/dev/zero", "--observer", "SideslipBankObserver"]
        expect = ["/dev/zero", "character device"]
    r = _measured([*args, "--out", str(tmp_path / "out"), "--fmu-dir", str(tmp_path / "fmus")], tmp_path)
    assert r["rc"] == 2, r
    assert all(e in r["stderr"] for e in expect), r["stderr"]
    assert r["seconds"] < 5.0, r
    assert r["maxrss_mb"] < 500, r
    assert not (tmp_path / "fmus").exists()            # refused before anything was built


def test_the_memory_limit_is_the_options_and_says_how_to_raise_it(tmp_path):
    # a plain campaign fits the machine; with a 1 MB limit its 10 runs' rows and run do not
    path = _campaign_file(tmp_path, "small", "runs = 10")
    r = _measured(["campaign", str(path), "--max-memory", "1", "--out", str(tmp_path / "out"),
                   "--fmu-dir", str(tmp_path / "fmus")], tmp_path)
    assert r["rc"] == 2 and "limit of 1 MB (--max-memory / $LATOBS_MAX_MEMORY_MB = 1 MB)" in r["stderr"], r
    r = _measured(["campaign", str(path), "--max-hours", "1e-9", "--out", str(tmp_path / "out"),
                   "--fmu-dir", str(tmp_path / "fmus")], tmp_path)
    assert r["rc"] == 2 and "would take about" in r["stderr"] and "--max-hours" in r["stderr"], r


def test_budget_limits_come_from_the_environment_else_the_available_memory(monkeypatch):
    monkeypatch.delenv(budget.MEMORY_ENV, raising=False)
    limit, why = budget.memory_limit()
    assert 0 < limit <= budget.available_memory() and "available" in why
    monkeypatch.setenv(budget.MEMORY_ENV, "300")
    assert budget.memory_limit()[0] == 300 * budget.MB
    budget.check("x", memory=299 * budget.MB)
    with pytest.raises(budget.ResourceLimitError, match="x would need about 301 MB of memory, more than the limit "
                                                        "of 300 MB"):
        budget.check("x", memory=301 * budget.MB)
    monkeypatch.setenv(budget.MEMORY_ENV, "-1")
    with pytest.raises(budget.ResourceLimitError, match="LATOBS_MAX_MEMORY_MB must be a positive number"):
        budget.memory_limit()


# --- records -----------------------------------------------------------------------------------
def test_a_fifo_is_refused_by_replay_and_identify_without_waiting_for_a_writer(tmp_path):
    fifo = tmp_path / "drive.csv"
    os.mkfifo(fifo)
    for args in (["replay", str(fifo), "--observer", "SideslipBankObserver"],
                 ["identify", str(fifo), "--vehicle", "sedan", "--out", str(tmp_path / "car.toml")]):
        r = _measured(args, tmp_path)
        assert r["rc"] == 2 and "is a FIFO (named pipe), not a record file" in r["stderr"], r
        assert r["stderr"].count(str(fifo)) == 1, r["stderr"]


def _record(path: Path, rows: int) -> Path:
    t = np.arange(rows) * 0.01
    text = "t,delta,vx\n" + "".join(f"{x:.2f},0.01,20\n" for x in t)
    if path.suffix == ".gz":
        path.write_bytes(gzip.compress(text.encode()))
    else:
        path.write_text(text)
    return path


def test_a_record_over_the_size_limit_is_refused_unless_asked(tmp_path, monkeypatch):
    big = _record(tmp_path / "big.csv", 20000)            # ~ 300 kB
    monkeypatch.setenv(budget.RECORD_ENV, "0.1")
    with pytest.raises(records.RecordError, match=r"big.csv: 0.\d+ MB, larger than the record limit of 0.1 MB "
                                                  r"\(--max-record-mb"):
        records.load_csv(big)
    # a .gz is counted by its text as it is read: a small file of much text is refused too
    gz = _record(tmp_path / "big.csv.gz", 20000)
    assert gz.stat().st_size < 0.1 * budget.MB
    with pytest.raises(records.RecordError, match="more than 0.1 MB of text, the record limit"):
        records.load_csv(gz)
    monkeypatch.setenv(budget.RECORD_ENV, "1")
    assert records.load_csv(gz)["t"].size == records.load_csv(big)["t"].size == 20000
    # and on the command line
    monkeypatch.delenv(budget.RECORD_ENV)
    for limit, ok in (("0.1", False), ("1", True)):
        r = _measured(["identify", str(big), "--vehicle", "sedan", "--out", str(tmp_path / "car.toml"),
                       "--max-record-mb", limit], tmp_path)
        assert ("larger than the record limit" in r["stderr"]) != ok, r


def test_a_record_read_in_blocks_is_the_record_read_at_once(tmp_path, monkeypatch):
    path = _record(tmp_path / "r.csv", 1000)
    whole = records.load_csv(path)
    monkeypatch.setattr(records, "BLOCK_ROWS", 7)
    records._parsed.cache_clear()
    blocks = records.load_csv(path)
    assert list(blocks) == list(whole) and all(np.array_equal(blocks[k], whole[k]) for k in whole)
    # t checked across a block boundary (rows 7 and 8: lines 8 and 9), with the file's own text
    lines = path.read_text().splitlines()
    lines[8] = "0.055,0.01,20"
    path.write_text("\n".join(lines) + "\n")
    records._parsed.cache_clear()
    with pytest.raises(records.RecordError, match=r"not strictly increasing at line 9 \(t = 0.055 after 0.06\)"):
        records.load_csv(path)


# --- names -------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", ["two\\nlines", "a/b", "nul\\u0000", "tab\\there", ".hidden", "x" * 101, ""])
def test_a_campaign_name_unsafe_as_a_folder_is_refused_before_anything_is_created(tmp_path, name):
    path = tmp_path / "c.toml"
    path.write_text(f'name = "{name}"\nscenario = "double-lane-change"\nobservers = ["SideslipBankObserver"]\n'
                    "runs = 2\nseed = 1\n", encoding="utf-8")
    out = tmp_path / "out"
    r = _measured(["campaign", str(path), "--out", str(out), "--fmu-dir", str(tmp_path / "fmus")], tmp_path)
    assert r["rc"] == 2 and "`name` must be a plain word" in r["stderr"], r
    assert not out.exists() and not (tmp_path / "fmus").exists()


def test_a_tag_with_a_newline_is_refused():
    from latobs.cli import parser

    for args in (["campaign", "double-lane-change", "--tag", "a\nb"],
                 ["validate", "double-lane-change", "--tag", "a\x00b"]):
        with pytest.raises(SystemExit) as exc:
            parser().parse_args(args)
        assert exc.value.code == 2


# --- processes and temporary folders ---------------------------------------------------------------
def _children(pid: int) -> list[int]:
    out = []
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                stat = (d / "stat").read_text()
            except OSError:
                continue
            if int(stat.rsplit(")", 1)[1].split()[1]) == pid:
                out.append(int(d.name))
    return out


def _group(pgid: int) -> list[int]:
    """The live processes of process group ``pgid`` (zombies are dead)."""
    out = []
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                fields = (d / "stat").read_text().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if int(fields[2]) == pgid and fields[0] != "Z":
                out.append(int(d.name))
    return out


def _wait_for(cond, timeout: float) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if cond():
            return True
        time.sleep(0.1)
    return False


def _kill_and_check_group(p: subprocess.Popen, log) -> None:
    """SIGKILL of ``p`` (started in a session of its own), then: no process of its group is alive
    10 s later (the ones that are get killed, and the test fails naming them)."""
    try:
        os.kill(p.pid, signal.SIGKILL)
        p.wait()
        assert _wait_for(lambda: not _group(p.pid), 10), [Path(f"/proc/{q}/cmdline").read_bytes()
                                                            for q in _group(p.pid)]
    finally:
        for q in _group(p.pid):
            os.kill(q, signal.SIGKILL)
        log.close()


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs /proc (Linux)")
def test_sigkill_of_the_main_build_process_leaves_no_latobs_process_alive_after_10_s(tmp_path):
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    env = {**os.environ, "LATOBS_CACHE_DIR": str(tmp_path / "cache"), "TMPDIR": str(tmp), "LATOBS_JOBS": "2"}
    log = (tmp_path / "build.log").open("w")
    p = subprocess.Popen([sys.executable, "-m", "latobs", "build", "SideslipKalmanFilter", "CarPlant",
                          "--platforms", "host", "--out", str(tmp_path / "out")], env=env, stdout=log,
                         stderr=subprocess.STDOUT, start_new_session=True, cwd=tmp_path)
    try:
        # the two workers are the main process's children that run a multiprocessing spawn
        def workers():
            return [c for c in _children(p.pid)
                    if b"multiprocessing" in Path(f"/proc/{c}/cmdline").read_bytes()
                    and b"resource_tracker" not in Path(f"/proc/{c}/cmdline").read_bytes()]
        assert _wait_for(lambda: len(workers()) >= 2, 120), (tmp_path / "build.log").read_text()
        time.sleep(1.0)                             # the workers at work (importing, designing)
        assert list(tmp.glob(f"latobs-reference-{p.pid}-*"))
    finally:
        _kill_and_check_group(p, log)
    # the killed build's temporary folder is left; the next build's sweep removes it
    from latobs import pipeline

    left = list(tmp.glob("latobs-*"))
    assert left
    assert sorted(pipeline.remove_stale_folders(tmp)) == sorted(left)
    assert not list(tmp.glob("latobs-*"))


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs /proc (Linux)")
def test_sigterm_of_the_main_build_process_ends_its_workers_and_removes_every_temporary_folder(tmp_path):
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    env = {**os.environ, "LATOBS_CACHE_DIR": str(tmp_path / "cache"), "TMPDIR": str(tmp), "LATOBS_JOBS": "2"}
    p = subprocess.Popen([sys.executable, "-m", "latobs", "build", "SideslipKalmanFilter", "CarPlant",
                          "--platforms", "host", "--out", str(tmp_path / "out")], env=env, stdout=subprocess.DEVNULL,
                         stderr=subprocess.DEVNULL, start_new_session=True, cwd=tmp_path)
    try:
        # the workers' scratch folders (latobs-part-PID-*) beside the shared one: the workers at work
        assert _wait_for(lambda: len(list(tmp.glob("latobs-part-*"))) == 2, 120)
        os.kill(p.pid, signal.SIGTERM)
        assert p.wait(timeout=20) == 128 + signal.SIGTERM
        assert _wait_for(lambda: not _group(p.pid), 10)
        assert not list(tmp.iterdir())
    finally:
        for q in _group(p.pid):
            os.kill(q, signal.SIGKILL)


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs /proc (Linux)")
def test_sigkill_of_a_campaign_leaves_no_dask_worker_alive_after_10_s(fmu_dir, tmp_path):
    log_path = tmp_path / "campaign.log"
    log = log_path.open("w")
    p = subprocess.Popen([sys.executable, "-m", "latobs", "campaign", "double-lane-change", "--runs", "400",
                          "--workers", "2", "--fmu-dir", str(fmu_dir), "--out", str(tmp_path / "out"), "--no-plots",
                          "--no-progress"], stdout=log, stderr=subprocess.STDOUT, start_new_session=True,
                         cwd=tmp_path)
    try:
        # the local cluster's two worker processes at work (beside this process and its resource tracker)
        assert _wait_for(lambda: "400 runs (" in log_path.read_text() and len(_group(p.pid)) >= 4, 180), \
            log_path.read_text()
        time.sleep(2.0)
    finally:
        _kill_and_check_group(p, log)


_SLOW_MAP = textwrap.dedent("""
    import os, sys, tempfile, time
    from latobs.synthesis import lmi
    with tempfile.TemporaryDirectory(prefix="latobs-reference-%d-" % os.getpid()):
        print("mapping", flush=True)
        lmi.parallel_map(time.sleep, [60.0, 60.0])
""")


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs /proc (Linux)")
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_sigterm_or_ctrl_c_of_a_parallel_map_ends_its_workers_and_removes_its_folders(tmp_path, sig):
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    p = subprocess.Popen([sys.executable, "-c", _SLOW_MAP], env={**os.environ, "TMPDIR": str(tmp), "LATOBS_JOBS": "2"},
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True, cwd=tmp_path)
    try:
        assert _wait_for(lambda: len([c for c in _children(p.pid) if b"resource_tracker" not in
                                      Path(f"/proc/{c}/cmdline").read_bytes()]) >= 2, 60)
        time.sleep(1.0)
        assert list(tmp.glob("latobs-*"))
        os.kill(p.pid, sig)
        p.wait(timeout=20)
        assert _wait_for(lambda: not _group(p.pid), 10)
        assert not list(tmp.glob("latobs-*"))
        assert p.returncode in ((128 + signal.SIGTERM,) if sig == signal.SIGTERM else (1, -signal.SIGINT)), \
            p.stderr.read()
    finally:
        for q in _group(p.pid):
            os.kill(q, signal.SIGKILL)


def test_the_stale_folder_sweep_keeps_the_folders_of_live_processes(tmp_path):
    from latobs import pipeline

    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    live = tmp_path / f"latobs-part-{os.getppid()}-abc"
    gone = tmp_path / f"latobs-reference-{dead.pid}-xyz"
    old = tmp_path / "latobs-reference-q1w2e3"           # an older latobs: no PID, by age
    new = tmp_path / "latobs-reference-r4t5y6"
    compiled = tmp_path / "latobs-c-a1b2c3"              # a compilation's scratch folder: by age
    other = tmp_path / f"something-{dead.pid}-else"
    for d in (live, gone, old, new, compiled, other):
        d.mkdir()
        (d / "f").write_text("x")
    for d in (old, compiled):
        os.utime(d, (time.time() - 2 * pipeline.STALE_S,) * 2)
    assert sorted(pipeline.remove_stale_folders(tmp_path)) == sorted([gone, old, compiled])
    assert live.is_dir() and new.is_dir() and other.is_dir()


# --- long records, streamed ------------------------------------------------------------------------
def _drive(path: Path, rows: int, dt: float = 0.001) -> Path:
    """A record SideslipBankObserver can replay (its inputs and the truths beta, yaw_rate), ``rows`` long."""
    t = np.arange(rows) * dt
    d = 0.02 * np.sin(0.5 * t)
    vx = 20 + 2 * np.sin(0.01 * t)
    r = vx * d / 2.7
    cols = np.column_stack([t, d, vx, r, 0.01 * np.sin(0.5 * t), 0.005 * np.cos(0.5 * t), vx * r,
                            0.01 * np.sin(0.5 * t + 0.3)])
    with path.open("w") as fh:
        fh.write("t,delta,vx,yaw_rate,roll_angle,roll_rate,ay,beta\n")
        np.savetxt(fh, cols, fmt=["%.4f"] + ["%.9g"] * 7, delimiter=",")
    return path


def _without(d, keys=("baselines", "streamed", "csv")):
    if isinstance(d, dict):
        return {k: _without(v, keys) for k, v in d.items() if k not in keys}
    return d


def _close(a, b, path=""):
    if isinstance(a, dict):
        assert set(a) == set(b), path
        for k in a:
            _close(a[k], b[k], f"{path}/{k}")
    elif isinstance(a, float) and isinstance(b, float):
        assert b == pytest.approx(a, rel=1e-12, abs=1e-300), path
    else:
        assert a == b, path


def test_a_streamed_replay_scores_as_the_whole_record_and_writes_every_output(fmu_dir, tmp_path, monkeypatch):
    import pyarrow.parquet as pq

    from latobs import pipeline
    from latobs.validation import replay as rp
    from latobs.validation import stream

    rec = _drive(tmp_path / "drive.csv", 3001)
    monkeypatch.setenv(stream.STREAM_ENV, "1000")
    assert not stream.streamed(rec)
    whole = pipeline.replay(str(rec), "SideslipBankObserver", out=tmp_path / "whole", fmu_dir=fmu_dir, split=1.234,
                            plots=False, quiet=True)
    monkeypatch.setenv(stream.STREAM_ENV, "0")
    monkeypatch.setattr(records, "BLOCK_ROWS", 256)       # 12 blocks
    assert stream.streamed(rec)
    streamed = pipeline.replay(str(rec), "SideslipBankObserver", out=tmp_path / "stream", fmu_dir=fmu_dir,
                               split=1.234, plots=True, quiet=True)
    assert streamed["streamed"]["outputs"] == "outputs.parquet" and "streamed" not in whole
    b_whole = whole["observers"]["SideslipBankObserver"]["baselines"]
    b_stream = streamed["observers"]["SideslipBankObserver"]["baselines"]
    assert "not computed for a streamed record" in b_stream["skipped"]["bicycle"]
    _close(b_whole["zero"], b_stream["zero"])                       # the zero baseline, summed over the blocks
    for name, v in b_stream["summary"].items():                    # no verdict without the model baselines
        assert v["baselines"]["zero"] == pytest.approx(b_whole["summary"][name]["baselines"]["zero"], rel=1e-12)
        assert v["observer_best"] is not True
    _close(_without(whole), _without(streamed))
    # every output of every row, bit for bit those of the whole record driven at once
    folder = tmp_path / "stream" / "replay_drive_SideslipBankObserver"
    table = pq.read_table(folder / "outputs.parquet").to_pydict()
    run = rp.drive(fmu_dir / "SideslipBankObserver.fmu", records.load_csv(rec))
    assert np.array_equal(table["t"], run.time)
    for k, v in run.outputs.items():
        assert np.array_equal(np.asarray(table[k]), v), k
    assert (folder / "replay.png").is_file()


_STREAM_RSS = textwrap.dedent("""
    import json, sys
    from latobs import cli
    from latobs.data import records
    records.BLOCK_ROWS = 2048
    def status(key):
        for line in open("/proc/self/status"):
            if line.startswith(key + ":"):
                return int(line.split()[1]) / 1024
    warm, args = sys.argv[1], sys.argv[2:]
    assert cli.main([*args[:1], warm, *args[2:]]) == 0     # imports, the FMU: what any length needs
    with open("/proc/self/clear_refs", "w") as fh:        # the peak (VmHWM) from here on
        fh.write("5")
    base = status("VmRSS")
    rc = cli.main(args)
    print(json.dumps({"rc": rc, "growth_mb": status("VmHWM") - base}))
""")


@pytest.mark.skipif(not Path("/proc/self/clear_refs").exists(), reason="needs Linux's /proc/self/clear_refs")
def test_a_streamed_replay_holds_the_same_memory_for_a_record_8_times_longer(fmu_dir, tmp_path):
    """The peak memory a streamed replay adds (after a first replay has imported everything) does
    not grow with the record; the whole-record replay's, the control, does: 10 000 and 80 000 rows
    at 1 ms."""
    warm = _drive(tmp_path / "warm.csv", 3000)

    def growth(rows: int, stream_above_mb: str) -> float:
        rec = _drive(tmp_path / f"d{rows}.csv", rows)
        out = subprocess.run([sys.executable, "-c", _STREAM_RSS, str(warm), "replay", str(rec), "--observer",
                              "SideslipBankObserver", "--fmu-dir", str(fmu_dir), "--out", str(tmp_path / "out"),
                              "--no-plots"], capture_output=True, text=True, timeout=300, cwd=tmp_path,
                             env={**os.environ, "LATOBS_STREAM_ABOVE_MB": stream_above_mb})
        r = json.loads(out.stdout.strip().splitlines()[-1])
        assert r["rc"] == 0, out.stderr
        return r["growth_mb"]

    short, long = growth(10_000, "0"), growth(80_000, "0")
    assert long - short < 5, (short, long)
    whole_short, whole_long = growth(10_000, "1000"), growth(80_000, "1000")
    assert whole_long - whole_short > 20, (whole_short, whole_long)      # the control: it does grow


# --- progress ------------------------------------------------------------------------------------
class _Terminal:
    """A stderr that says it is a terminal and keeps what is written."""

    def __init__(self):
        self.text = ""

    def isatty(self):
        return True

    def write(self, s):
        self.text += s

    def flush(self):
        pass


def test_a_long_run_shows_a_stepping_bar_on_a_terminal_only(fmu_dir, tmp_path, monkeypatch):
    from latobs.validation import master
    from latobs.validation import replay as rp

    rec = records.load_csv(_drive(tmp_path / "d.csv", 2000))
    term = _Terminal()
    monkeypatch.setattr(sys, "stderr", term)
    monkeypatch.setattr(master, "PROGRESS_STEPS", 1000)
    rp.drive(fmu_dir / "SideslipBankObserver.fmu", rec)
    assert "stepping:" in term.text and "/1999 [" in term.text
    term.text = ""
    monkeypatch.setattr(master, "_interactive", lambda: False)     # a worker, or not a terminal
    rp.drive(fmu_dir / "SideslipBankObserver.fmu", rec)
    assert term.text == ""
