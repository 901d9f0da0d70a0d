"""The command line: exit codes and messages (CONTRACT.md)."""
from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from latobs.cli import main


def test_list_names_everything(capsys):
    assert main(["list"]) == 0
    out = capsys.readouterr().out
    for name in ("SideslipBankObserver", "SideslipBankObserverTire", "CarPlant", "sedan", "mbds_250lm",
                 "bank-braking", "double-lane-change", "sine-with-dwell", "fishhook"):
        assert name in out


def test_every_design_has_an_fmu_model():
    from latobs.packaging import OBSERVERS
    from latobs.synthesis.designs import DESIGNS

    assert set(OBSERVERS) == set(DESIGNS)


def test_design_writes_a_certified_file(tmp_path, capsys):
    assert main(["design", "SideslipBankObserver", "--out", str(tmp_path)]) == 0
    data = json.loads((tmp_path / "SideslipBankObserver.design.json").read_text())
    for key in ("name", "paper", "vehicle", "modes", "gamma", "certified", "checks", "solver"):
        assert key in data
    assert data["certified"] and all(c["passed"] for c in data["checks"])
    assert set(data["checks"][0]) >= {"name", "value", "limit", "passed"}
    assert {"name", "status", "seconds"} <= set(data["solver"])
    assert "gamma" in capsys.readouterr().out


def test_errors_exit_nonzero_with_the_culprit(tmp_path, capsys, monkeypatch):
    assert main(["design", "SideslipBankObserver", "--vehicle", "mbds_250lm", "--out", str(tmp_path)]) == 2
    assert "lacks parameter(s) Ix, hr, Kr, br" in capsys.readouterr().err
    assert not list(tmp_path.iterdir())                 # nothing half-written
    assert main(["build", "CarPlant", "--vehicle", "mbds_250lm", "--out", str(tmp_path)]) == 2
    assert "CarPlant_mbds_250lm: the CarPlant runtime rejects its data" in capsys.readouterr().err
    assert not list(tmp_path.glob("*.fmu"))
    assert main(["design", "NoSuchObserver"]) == 2
    assert "unknown design" in capsys.readouterr().err
    from latobs.cbackend import toolchain
    monkeypatch.setattr(toolchain, "system_compiler", lambda: None)     # a machine without a C compiler
    monkeypatch.setattr(toolchain, "zig_cc", lambda: None)              # (nor zig)
    assert main(["build", "CarPlant", "--backend", "c", "--out", str(tmp_path)]) == 2
    assert "CarPlant: no C compiler found" in capsys.readouterr().err
    assert not list(tmp_path.glob("*.fmu"))
    assert main(["build", "CarPlant", "--out", str(tmp_path)]) == 0      # auto: falls back, saying why
    assert "CarPlant: pythonfmu backend (no C compiler found" in capsys.readouterr().out
    monkeypatch.undo()
    assert main(["validate", "no-such-scenario", "--out", str(tmp_path)]) == 2
    assert "no-such-scenario" in capsys.readouterr().err


def test_demo_certificate_section_renders(tmp_path, design_speed):
    from latobs.demo import _design_section
    from latobs.synthesis import design_file

    text = _design_section(design_file.write(design_speed, tmp_path))
    n = len(design_speed["checks"])
    assert f"certified, {n}/{n} checks passed" in text
    assert text.count("| Vx = ") == 3            # one row per speed mode


def test_validate_loads_no_design_stack_and_can_skip_plots(tmp_path, fmu_dir):
    """`latobs validate` with built FMUs imports neither the solver (cvxpy, Clarabel) nor the
    certificate (scipy) nor, with --no-plots, matplotlib; and writes no PNG then."""
    import subprocess
    import sys

    code = (
        "import sys, json\n"
        "from latobs.cli import main\n"
        f"rc = main(['validate', 'double-lane-change', '--fmu-dir', {str(fmu_dir)!r}, '--out', {str(tmp_path)!r}, "
        "'--no-plots'])\n"
        "print(json.dumps([rc, sorted(m for m in sys.modules if m.split('.')[0] in "
        "('cvxpy', 'clarabel', 'scipy', 'matplotlib', 'pythonfmu') or m.startswith(('latobs.synthesis.certificate', "
        "'latobs.synthesis.tables', 'latobs.synthesis.sideslip_bank_observer', 'latobs.synthesis.hinf')))]))\n")
    proc = subprocess.run([sys.executable, "-P", "-c", code], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    rc, heavy = json.loads(proc.stdout.strip().splitlines()[-1])
    assert rc == 0 and heavy == [], proc.stdout[:3000]
    out = tmp_path / "double-lane-change"
    assert (out / "metrics.json").is_file() and not list(out.glob("*.png"))


def test_bench_takes_its_own_options(capsys):
    """`latobs bench --fmu-dir D` reaches bench's parser (argparse's REMAINDER alone would refuse
    an option as the subcommand's first argument)."""
    from latobs.cli import main

    with pytest.raises(SystemExit) as exc:
        main(["bench", "--help"])
    assert exc.value.code == 0
    assert "--fmu-dir" in capsys.readouterr().out


# --------------------------------------------------------------------------------------------
# issue 10, item 5: a user's mistake is exit 2 and ONE line `latobs CMD: error: ...` naming the
# culprit, never a traceback; a bug is exit 1 (one line, the traceback with LATOBS_DEBUG=1);
# Ctrl-C is exit 130 (one line)
# --------------------------------------------------------------------------------------------
SEDAN_TOML = Path(__file__).resolve().parents[2] / "synthesis" / "vehicles" / "sedan.toml"


def _cli(argv, capsys):
    """(exit code, stdout, stderr) of ``main(argv)``; argparse's errors exit by SystemExit."""
    try:
        rc = main([str(a) for a in argv])
    except SystemExit as exc:
        rc = exc.code
    out, err = capsys.readouterr()
    return rc, out, err


def _assert_one_line(rc, err, command, culprits, code=2, kind="error"):
    assert rc == code, err
    assert "Traceback" not in err, err
    lines = err.splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith(f"latobs {command}: {kind}" if command else f"latobs: {kind}"), lines[0]
    for c in culprits:
        assert c in lines[0], (c, lines[0])


def _vehicle_file(tmp_path: Path, name: str, **values) -> Path:
    """The sedan's TOML file renamed ``name`` with some values replaced."""
    import re

    text = SEDAN_TOML.read_text().replace('name = "sedan"', f'name = "{name}"')
    for k, v in values.items():
        text, n = re.subn(rf"^{k}(\s*)= \{{ value = [^,]+,", rf"{k}\1= {{ value = {v},", text, flags=re.M)
        assert n == 1, k
    path = tmp_path / f"{name}.toml"
    path.write_text(text)
    return path


def _setup_files(tmp_path: Path) -> dict[str, Path]:
    files = {"file": tmp_path / "a_file", "unparsable": tmp_path / "unparsable.toml",
             "malformed": tmp_path / "malformed.toml", "nocsv": tmp_path / "missing.csv",
             "no_t": tmp_path / "no_t.csv", "nonnum": tmp_path / "nonnum.csv", "empty": tmp_path / "empty_dir",
             "ro": tmp_path / "read_only"}
    files["file"].write_text("x")
    files["unparsable"].write_text('name = "u"\nkind = "car"\nparameters = [\n')
    files["malformed"].write_text('name = "m"\nkind = "car"\nparameters = 5\n')
    files["no_t"].write_text("x,y\n1,2\n3,4\n")
    files["nonnum"].write_text("t,delta\n0,0.1\n0.01,abc\n")
    files["empty"].mkdir()
    files["ro"].mkdir()
    files["badval"] = _vehicle_file(tmp_path, "badval", Kr=-1)
    return files


# (id, argv with {placeholders} of _setup_files, command, culprits named in the line)
CHEAP_ERRORS = [
    ("no-command", [], "", ["required: COMMAND"]),
    ("unknown-command", ["frobnicate"], "", ["'frobnicate'"]),
    ("design-no-name", ["design"], "design", ["name"]),
    ("unknown-design", ["design", "NoSuchObserver"], "design", ["unknown design 'NoSuchObserver'"]),
    ("unknown-vehicle", ["design", "SideslipBankObserver", "--vehicle", "nosuch"], "design",
     ["--vehicle", "unknown vehicle 'nosuch'"]),
    ("vehicle-toml-missing", ["design", "SideslipBankObserver", "--vehicle", "{nocsv}.toml"], "design",
     ["--vehicle", "missing.csv.toml", "no such file"]),
    ("vehicle-toml-unparsable", ["design", "SideslipBankObserver", "--vehicle", "{unparsable}"], "design",
     ["--vehicle", "unparsable.toml", "not valid TOML"]),
    ("vehicle-toml-malformed", ["design", "SideslipBankObserver", "--vehicle", "{malformed}"], "design",
     ["--vehicle", "malformed.toml", "malformed vehicle file"]),
    ("vehicle-toml-bad-value", ["build", "CarPlant", "--vehicle", "{badval}", "--out", "{empty}"], "build",
     ["--vehicle", "badval.toml", "'Kr' must be > 0"]),
    ("vehicle-lacks-parameter", ["design", "SideslipBankObserver", "--vehicle", "mbds_250lm", "--out", "{empty}"],
     "design", ["mbds_250lm", "lacks parameter(s) Ix, hr, Kr, br"]),
    ("unknown-fmu", ["build", "NoSuchPlant", "--out", "{empty}"], "build", ["unknown FMU(s) NoSuchPlant"]),
    ("backend-bad", ["build", "--backend", "rust"], "build", ["--backend", "'rust'"]),
    ("out-is-a-file", ["design", "SideslipBankObserver", "--out", "{file}"], "design",
     ["--out", "a_file", "not a directory"]),
    ("out-under-a-file", ["validate", "bank-braking", "--out", "{file}/sub", "--fmu-dir", "{empty}"], "validate",
     ["--out", "a_file", "not a directory"]),
    ("out-read-only", ["demo", "--out", "{ro}/report"], "demo", ["--out", "read_only", "not writable"]),
    ("out-name-too-long", ["design", "SideslipBankObserver", "--out", "{empty}/" + "x" * 300], "design",
     ["--out", "xxxx", "too long"]),
    ("fmu-dir-is-a-file", ["validate", "bank-braking", "--fmu-dir", "{file}", "--out", "{empty}"], "validate",
     ["--fmu-dir", "a_file", "not a directory"]),
    ("replay-fmu-dir-is-a-file", ["replay", "mbds", "--observer", "SideslipKalmanFilter", "--fmu-dir", "{file}"],
     "replay", ["--fmu-dir", "a_file", "not a directory"]),
    ("unknown-scenario", ["validate", "no-such-scenario", "--out", "{empty}", "--fmu-dir", "{empty}"], "validate",
     ["unknown scenario 'no-such-scenario'"]),
    ("unknown-observer", ["validate", "bank-braking", "--observer", "NoSuchObserver", "--fmu-dir", "{empty}",
                          "--out", "{empty}"], "validate", ["--observer NoSuchObserver", "unknown design"]),
    ("unknown-plant-vehicle", ["validate", "bank-braking", "--plant-vehicle", "nosuch", "--fmu-dir", "{empty}"],
     "validate", ["--plant-vehicle", "unknown vehicle 'nosuch'"]),
    ("plant-param-no-equals", ["validate", "bank-braking", "--plant-param", "mu"], "validate",
     ["--plant-param", "NAME=VALUE", "'mu'"]),
    ("plant-param-no-value", ["validate", "bank-braking", "--plant-param", "mu="], "validate",
     ["--plant-param mu", "'' is not a number"]),
    ("plant-param-no-name", ["validate", "bank-braking", "--plant-param", "=1"], "validate",
     ["--plant-param", "'=1'", "no NAME"]),
    ("plant-param-not-a-number", ["validate", "bank-braking", "--plant-param", "mu=abc"], "validate",
     ["--plant-param mu", "'abc' is not a number"]),
    ("plant-param-nan", ["validate", "bank-braking", "--plant-param", "mu=nan"], "validate",
     ["--plant-param mu", "'nan' is not a finite number"]),
    ("plant-param-inf", ["validate", "bank-braking", "--plant-param", "mu=-inf"], "validate",
     ["--plant-param mu", "'-inf' is not a finite number"]),
    ("plant-param-twice", ["validate", "bank-braking", "--plant-param", "mu=0.5", "--plant-param", "mu=0.3"],
     "validate", ["--plant-param mu given twice"]),
    ("seed-negative", ["validate", "bank-braking", "--noise", "--seed", "-1"], "validate", ["--seed", "'-1'"]),
    ("seed-not-a-number", ["validate", "bank-braking", "--seed", "abc"], "validate", ["--seed", "'abc'"]),
    ("tag-with-a-slash", ["validate", "bank-braking", "--tag", "../x"], "validate", ["--tag", "'../x'"]),
    ("split-not-a-number", ["replay", "{no_t}", "--observer", "SideslipBankObserver", "--split", "abc"], "replay",
     ["--split", "'abc'"]),
    ("split-nan", ["replay", "{no_t}", "--observer", "SideslipBankObserver", "--split", "nan"], "replay",
     ["--split", "finite", "'nan'"]),
    ("replay-csv-missing", ["replay", "{nocsv}", "--observer", "SideslipBankObserver", "--fmu-dir", "{empty}",
                            "--out", "{empty}"], "replay", ["missing.csv", "no such file"]),
    ("replay-csv-no-t", ["replay", "{no_t}", "--observer", "SideslipBankObserver", "--fmu-dir", "{empty}",
                         "--out", "{empty}"], "replay", ["no_t.csv", "no time column 't'"]),
    ("replay-csv-not-numeric", ["replay", "{nonnum}", "--observer", "SideslipBankObserver", "--fmu-dir", "{empty}",
                                "--out", "{empty}"], "replay", ["nonnum.csv", "column 'delta', line 3", "'abc'"]),
    ("replay-unknown-observer", ["replay", "mbds", "--observer", "NoSuchObserver", "--fmu-dir", "{empty}"],
     "replay", ["unknown observer 'NoSuchObserver'"]),
    ("replay-unknown-vehicle", ["replay", "mbds", "--observer", "SideslipKalmanFilter", "--vehicle", "nosuch"],
     "replay", ["--vehicle", "unknown vehicle 'nosuch'"]),
    ("replay-no-observer", ["replay", "mbds"], "replay", ["--observer"]),
    ("bench-fmu-dir-is-a-file", ["bench", "--fmu-dir", "{file}"], "bench", ["--fmu-dir", "a_file"]),
    ("bench-steps-zero", ["bench", "--steps", "0"], "bench", ["--steps", "'0'"]),
    ("bench-json-is-a-dir", ["bench", "--json", "{empty}"], "bench", ["--json", "empty_dir", "a directory"]),
]


@pytest.mark.parametrize("argv, command, culprits", [c[1:] for c in CHEAP_ERRORS], ids=[c[0] for c in CHEAP_ERRORS])
def test_a_user_error_is_one_line_and_exit_2(argv, command, culprits, tmp_path, capsys, monkeypatch):
    files = _setup_files(tmp_path)
    os.chmod(files["ro"], 0o500)
    if os.geteuid() == 0:            # root writes anywhere: stand in for the permission check
        real = os.access
        monkeypatch.setattr(os, "access", lambda p, m, *a, **k: False if Path(p) == files["ro"] else real(p, m))
    monkeypatch.chdir(tmp_path)      # the default --out/--fmu-dir build/ is created nowhere else
    rc, out, err = _cli([a.format(**files) for a in argv], capsys)
    _assert_one_line(rc, err, command, culprits)
    assert out == ""
    assert not (tmp_path / "build").exists() and not list(files["empty"].iterdir())   # nothing written


# not-certified: the tire-mode design (Theorem 2) refuses Iz = 1e9 in 1.5 s (gains and cond(P) over their
# limits); the speed-mode default's robust-H2 LMIs take Clarabel 9 s on that car before their certificate fails
@pytest.mark.parametrize("name, values, culprit", [("SideslipBankObserver", {"hr": 100}, "no solution"),
                                                   ("SideslipBankObserverTire", {"Iz": 1e9}, "failed its certificate")],
                         ids=["infeasible", "not-certified"])
def test_a_design_that_fails_is_one_line_and_exit_2(name, values, culprit, tmp_path, capsys):
    veh = _vehicle_file(tmp_path, "extreme", **values)
    rc, out, err = _cli(["design", name, "--vehicle", veh, "--out", tmp_path / "out"], capsys)
    _assert_one_line(rc, err, "design", [f"{name}_extreme", culprit])
    assert not (tmp_path / "out").exists()


def _broken_fmu_dir(fmu_dir: Path, tmp_path: Path) -> Path:
    """CarPlant, a truncated SideslipBankObserver as MyTruncated, a zip that is no FMU as MyZip, and
    a text file as MyText: FMUs found under names that are not a catalogue design's are used as
    they are (a catalogue design's would be rebuilt: it carries no identity)."""
    import zipfile

    bad = tmp_path / "broken_fmus"
    bad.mkdir()
    shutil.copy(fmu_dir / "CarPlant.fmu", bad)
    (bad / "MyTruncated.fmu").write_bytes((fmu_dir / "SideslipBankObserver.fmu").read_bytes()[:5000])
    with zipfile.ZipFile(bad / "MyZip.fmu", "w") as z:
        z.writestr("hello.txt", "not an FMU")
    (bad / "MyText.fmu").write_text("garbage")
    return bad


FMU_ERRORS = [
    ("param-below-min", ["validate", "bank-braking", "--plant-param", "mu=-1"], "validate",
     ["CarPlant", "'mu' = -1.0", "outside its declared range [0.01, 2.0]"]),
    ("param-above-max", ["validate", "bank-braking", "--observer", "SideslipBankObserver", "--plant-param",
                         "scale_f=100"], "validate", ["CarPlant", "'scale_f' = 100.0", "declared range"]),
    ("param-unknown", ["validate", "bank-braking", "--plant-param", "foo=1"], "validate",
     ["CarPlant", "no parameter 'foo'", "mu"]),
    ("fmu-truncated", ["validate", "bank-braking", "--observer", "MyTruncated", "--fmu-dir", "{bad}"],
     "validate", ["MyTruncated.fmu", "not a readable FMU"]),
    ("fmu-not-a-zip", ["validate", "bank-braking", "--observer", "MyText", "--fmu-dir", "{bad}"],
     "validate", ["MyText.fmu", "not a readable FMU"]),
    ("zip-not-an-fmu", ["validate", "bank-braking", "--observer", "MyZip", "--fmu-dir", "{bad}"],
     "validate", ["MyZip.fmu", "modelDescription.xml"]),
    ("replay-csv-lacks-inputs", ["replay", "{csv}", "--observer", "SideslipBankObserver"], "replay",
     ["SideslipBankObserver", "'vx', 'yaw_rate', 'roll_angle', 'roll_rate'", "cannot run on", "t_delta.csv"]),
    ("out-subfolder-is-a-file", ["validate", "double-lane-change", "--observer", "SideslipBankObserver",
                                 "--out", "{out}"], "validate", ["double-lane-change", "File exists"]),
]


@pytest.mark.parametrize("argv, command, culprits", [c[1:] for c in FMU_ERRORS], ids=[c[0] for c in FMU_ERRORS])
def test_an_fmu_level_user_error_is_one_line_and_exit_2(argv, command, culprits, fmu_dir, tmp_path, capsys):
    """Errors only the FMUs reveal (a parameter's name and declared range, a broken FMU file, a
    record without the FMU's inputs, an output folder taken by a file), with the session's FMUs."""
    csv = tmp_path / "t_delta.csv"
    csv.write_text("t,delta\n0,0\n0.01,0.001\n0.02,0.002\n")
    out = tmp_path / "out"
    out.mkdir()
    (out / "double-lane-change").write_text("a file where validate writes its folder")
    places = {"bad": _broken_fmu_dir(fmu_dir, tmp_path), "csv": csv, "out": out}
    argv = [a.format(**places) for a in argv]
    if "--fmu-dir" not in argv:
        argv += ["--fmu-dir", str(fmu_dir)]
    if "--out" not in argv:
        argv += ["--out", str(out)]
    before = sorted(p.name for p in fmu_dir.iterdir())
    rc, stdout, err = _cli(argv + ["--no-plots"], capsys)
    _assert_one_line(rc, err, command, culprits)
    assert sorted(p.name for p in fmu_dir.iterdir()) == before         # nothing built
    assert "building" not in stdout


def test_the_issue_command_in_a_real_process(fmu_dir, tmp_path):
    """`latobs validate bank-braking --plant-param mu=-1` (the issue's report): exit 2, one line
    on stderr naming the FMU, the parameter and its range, nothing on stdout, no traceback."""
    # -P: the installed latobs, not the source folder of the working directory (a non-editable
    # install maps synthesis/ to latobs.synthesis; the source tree's latobs/ has no such package)
    proc = subprocess.run([sys.executable, "-P", "-m", "latobs", "validate", "bank-braking", "--plant-param", "mu=-1",
                           "--fmu-dir", str(fmu_dir), "--out", str(tmp_path), "--no-plots"],
                          capture_output=True, text=True, timeout=120, cwd=tmp_path)
    _assert_one_line(proc.returncode, proc.stderr, "validate", ["CarPlant", "'mu'", "[0.01, 2.0]"])
    # nothing on stdout but the FMUs found current (nothing built)
    assert all(line.startswith("reusing ") and line.endswith(".fmu (identical inputs)")
               for line in proc.stdout.splitlines()), proc.stdout


def test_a_bug_is_exit_1_with_one_line_and_the_traceback_on_request(capsys, monkeypatch):
    import latobs.cli as cli

    def bug(args):
        return {}["no such key"]          # a KeyError of the code, not a user's unknown name

    monkeypatch.setattr(cli, "_cmd_list", bug)
    rc, out, err = _cli(["list"], capsys)
    _assert_one_line(rc, err, "list", ["KeyError", "no such key", "LATOBS_DEBUG=1"], code=1, kind="internal error")
    monkeypatch.setenv("LATOBS_DEBUG", "1")
    with pytest.raises(KeyError):
        main(["list"])
    # a user error stays exit 2 under LATOBS_DEBUG, with its traceback before the line
    rc, out, err = _cli(["design", "NoSuchObserver"], capsys)
    assert rc == 2 and "Traceback" in err and err.splitlines()[-1].startswith("latobs design: error: unknown design")


def test_ctrl_c_is_exit_130_with_one_line(capsys, monkeypatch):
    import latobs.cli as cli

    def interrupted(args):
        raise KeyboardInterrupt

    monkeypatch.setattr(cli, "_cmd_list", interrupted)
    rc, out, err = _cli(["list"], capsys)
    _assert_one_line(rc, err, "list", [], code=130, kind="interrupted")
    # and a real SIGINT to a running command
    # SIGINT's default handler first: a shell that starts a job in the background (CI runners may)
    # leaves SIGINT ignored, and Python then never raises KeyboardInterrupt
    code = ("import signal, sys, time\nsignal.signal(signal.SIGINT, signal.default_int_handler)\n"
            "import latobs.cli as cli\n"
            "def slow(args):\n    print('running', flush=True)\n    time.sleep(60)\n"
            "cli._cmd_list = slow\nsys.exit(cli.main(['list']))\n")
    proc = subprocess.Popen([sys.executable, "-P", "-c", code], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    assert proc.stdout.readline() == "running\n"
    time.sleep(0.1)
    proc.send_signal(signal.SIGINT)
    stdout, stderr = proc.communicate(timeout=30)
    _assert_one_line(proc.returncode, stderr, "list", [], code=130, kind="interrupted")


def test_list_describes_tire_mode_2_as_the_secant_not_half_c1(capsys):
    """Issue 10: `latobs list` described tire mode 2 as '0.5 C1'; C2 is the secant of the
    vehicle's tire curve (paper 000's departure, synthesis/sideslip_bank_observer.py)."""
    assert main(["list"]) == 0
    out = capsys.readouterr().out
    assert "0.5 C1" not in out and "0.5*C1" not in out and "0.5·C1" not in out
    assert "C1 / C2 (secant of the tire curve)" in _list_entries(out)["SideslipBankObserverTire"]


def _list_entries(out: str) -> dict[str, str]:
    """`latobs list`'s entries {name: text}: a name at column 3, its text beside it or below it,
    wrapped on lines indented deeper."""
    entries, name = {}, None
    for line in out.splitlines():
        if line.startswith("  ") and not line.startswith("   "):
            name, _, text = line.strip().partition(" ")
            entries[name] = text.strip()
        elif line.startswith("   ") and name is not None:
            entries[name] = (entries[name] + " " + line.strip()).strip()
        else:
            name = None
    return entries


def test_list_fits_100_columns_and_names_every_shipped_campaign(capsys):
    from latobs.campaign_runner import shipped
    from latobs.synthesis import designs
    from latobs.validation.scenarios import SCENARIOS

    assert main(["list"]) == 0
    out = capsys.readouterr().out
    assert max(map(len, out.splitlines())) <= 100
    entries = _list_entries(out)
    for name in [*designs.DESIGNS, *SCENARIOS, *shipped()]:
        assert name in entries and entries[name], name
    assert set(shipped()) >= {"robustness-001", "mbds-bootstrap"}
    assert "1000 runs" in entries["robustness-001"]


def test_version_and_a_help_text_for_every_argument(capsys):
    """`latobs --version`; every argument of every command has a help text; no help text names
    the project's internal documents or issue numbers."""
    import argparse
    import re

    from latobs import __version__
    from latobs.cli import parser

    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0 and capsys.readouterr().out.strip() == f"latobs {__version__}"
    p = parser()
    sub = next(a for a in p._actions if isinstance(a, argparse._SubParsersAction))
    missing, texts = [], [p.description or ""]
    for command, sp in sub.choices.items():
        texts.append(sp.format_help())
        for action in sp._actions:
            if isinstance(action, argparse._HelpAction):
                continue
            if not action.help:
                missing.append(f"{command} {action.option_strings or action.dest}")
    assert missing == []
    for text in texts:
        assert not re.search(r"CONTRACT|ERRATA|\.\./shared|issue ?#?\d", text), text


def test_demo_prints_a_summary_unless_verbose():
    from latobs import cli

    assert cli.parser().parse_args(["demo"]).verbose is False
    assert cli.parser().parse_args(["demo", "--verbose"]).verbose is True
    assert cli.parser().parse_args(["campaign", "robustness-000"]).dashboard is None
    assert cli.parser().parse_args(["campaign", "robustness-000", "--dashboard"]).dashboard == ":8787"


@pytest.mark.slow
def test_the_demos_figures_drawn_in_worker_processes_are_those_drawn_here(fmu_dir, tmp_path, monkeypatch):
    """The demo draws each run's figures in spawned worker processes while its runs go on: the
    same files, byte for byte, as `plot_all` in this process, all written when the block ends."""
    from latobs import demo
    from latobs.validation import harness
    from latobs.validation.plots import plot_all

    result = harness.run("bank-braking", fmu_dir / "CarPlant.fmu",
                         {"SideslipBankObserver": fmu_dir / "SideslipBankObserver.fmu"})
    here = plot_all(result, tmp_path / "here")
    monkeypatch.setenv("LATOBS_JOBS", "2")
    with demo._figures() as submit:
        submit(plot_all, result, tmp_path / "workers")        # (two jobs: the worker processes draw)
    made = sorted((tmp_path / "workers").iterdir())
    assert [p.name for p in made] == sorted(p.name for p in here)
    assert all(p.read_bytes() == (tmp_path / "here" / p.name).read_bytes() for p in made)
