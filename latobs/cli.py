"""latobs: vehicle lateral-dynamics observers from published LMI designs, designed, certified,
packaged as FMI 2.0 FMUs and validated. Commands: list, design, build, validate, replay, campaign,
bench, demo, export-ssp, check (``latobs COMMAND --help``). Over ~600 lines: one argparse parser
with its help per command (the documentation's CLI reference is generated from them); the work
is in the pipeline, validation and bench."""
from __future__ import annotations

import argparse
import math
import os
import sys
from pathlib import Path

DEFAULT_OUT = Path("build")

# Exit codes (the documentation's command-line reference): 0 done; 2 a user's mistake (bad argument, file,
# vehicle, parameter, design that does not certify, FMU that fails in the co-simulation): one
# line ``latobs CMD: error: ...`` naming the culprit on stderr, no traceback; 1 an internal error
# (a bug): one line ``latobs CMD: internal error: ...``, the traceback with LATOBS_DEBUG=1;
# 130 interrupted (Ctrl-C): one line ``latobs CMD: interrupted``.
EXIT_OK, EXIT_INTERNAL, EXIT_USER, EXIT_INTERRUPTED = 0, 1, 2, 130
DEBUG_ENV = "LATOBS_DEBUG"


class CliError(RuntimeError):
    """A user-facing failure: printed without a traceback, exit code 2."""


class _Parser(argparse.ArgumentParser):
    """argparse with its errors on one line, like every other user error (exit 2)."""

    def error(self, message):
        self.exit(EXIT_USER, f"{self.prog}: error: {_one_line(message)} (see `{self.prog} --help`)\n")


#: `latobs list` fits this many columns
LIST_WIDTH = 100


def _list_entry(name: str, text: str, width: int = LIST_WIDTH) -> str:
    """``name`` and ``text`` wrapped to ``width`` columns: the text beside the name when the name
    is short, else on the next lines, indented."""
    import textwrap

    indent = " " * 26
    first = f"  {name:<23} " if len(name) <= 23 else f"  {name}\n{indent}"
    lines = textwrap.wrap(" ".join(text.split()), width=width - len(indent)) or [""]
    return first + ("\n" + indent).join(lines)


def _cmd_list(args) -> int:
    import tomllib

    from .campaign_runner import shipped
    from .packaging import PLANTS
    from .synthesis import designs
    from .synthesis.params import load_vehicle, vehicle_names
    from .validation.scenarios import SCENARIOS

    print("designs (observer FMUs; `latobs build NAME`):")
    for name, e in designs.DESIGNS.items():
        print(_list_entry(name, f"paper {e.paper}, default vehicle {e.default_vehicle}: {e.description}"))
    print("plants (`latobs build NAME`):")
    for name, k in PLANTS.items():
        print(_list_entry(name, f"default vehicle {k.default_vehicle}"))
    print("vehicles (--vehicle NAME, or a TOML file):")
    for name in vehicle_names():
        v = load_vehicle(name)
        print(_list_entry(name, f"{v.kind}: {v.description}"))
    print("scenarios (`latobs validate SCENARIO`):")
    for name, sc in SCENARIOS.items():
        print(_list_entry(name, f"{sc.duration:g} s: {sc.description}"))
    print("campaigns (`latobs campaign NAME`):")
    for name, path in shipped().items():
        raw = tomllib.loads(path.read_text(encoding="utf-8"))
        print(_list_entry(name, f"{raw.get('runs', '?')} runs: {raw.get('description', '')}"))
    return 0


def _cmd_design(args) -> int:
    from .pipeline import design_one

    design_one(args.name, args.vehicle, Path(args.out))
    return 0


def _cmd_build(args) -> int:
    import contextlib

    from . import cache

    with cache.turned_off() if args.no_cache else contextlib.nullcontext():
        return _build(args)


def _build(args) -> int:
    import contextlib
    import json

    from .pipeline import build, build_summary

    to_stdout = args.json == "-"
    if args.json is not None and not to_stdout and not args.json.endswith(".json"):
        # `--json NAME` would otherwise take an FMU name for the file (argparse's optional value)
        raise CliError(f"--json takes a FILE ending in .json (or '-' for stdout), got {args.json!r}; "
                       "put the FMU names before --json")
    if args.platforms is not None and args.backend == "python":
        raise CliError("--platforms chooses the native FMUs' platforms; the pythonfmu backend (--backend python) "
                       "ships pythonfmu's binaries")
    if 3 in args.fmi and args.backend == "python":
        raise CliError("--fmi 3 makes native FMUs; the pythonfmu backend (--backend python) makes FMI 2.0 FMUs only")
    # with the summary on stdout, the progress lines go to stderr so that stdout is the JSON alone
    with contextlib.redirect_stdout(sys.stderr) if to_stdout else contextlib.nullcontext():
        built = build(args.names, args.vehicle, Path(args.out), args.backend, platforms=args.platforms, fmi=args.fmi)
    if args.json is not None:
        from .atomic import locked_folder

        with locked_folder(args.out, "build"):   # the FMUs and design files as no other build leaves them
            text = json.dumps(build_summary(built), indent=1) + "\n"
        if to_stdout:
            sys.stdout.write(text)
        else:
            from .atomic import atomic_write_text

            try:
                atomic_write_text(args.json, text)
            except OSError as exc:
                raise CliError(f"--json: cannot write {args.json}: {exc}") from exc
            print(f"wrote {args.json}")
    return 0


def _cmd_check(args) -> int:
    from .check import check, seal

    results, skipped = check(args.fmu, args.platform)      # (user errors first: not a file, not an FMU)
    results = [seal(args.fmu), *results]
    for r in results:
        print(r.line())
    for platform, why in skipped:
        print(f"SKIP  {Path(args.fmu).stem}  {platform}: {why}")
    return 0 if all(r.passed for r in results) else 1


def _limits(args) -> None:
    """--max-memory, --max-hours, --max-record-mb: the limits of :mod:`latobs.data.budget`, given
    to it (and to the processes this one starts) as its environment variables."""
    from .data import budget

    for attr, env in (("max_memory", budget.MEMORY_ENV), ("max_hours", budget.HOURS_ENV),
                      ("max_record_mb", budget.RECORD_ENV)):
        value = getattr(args, attr, None)
        if value is not None:
            os.environ[env] = repr(value)


def _cmd_validate(args) -> int:
    from .pipeline import run_validation

    _limits(args)
    plant_parameters = _plant_params(args.plant_param)
    _check_observers(args.observer or [], Path(args.fmu_dir))
    run_validation(args.scenario, observers=args.observer, out=Path(args.out), fmu_dir=Path(args.fmu_dir),
                   plant_parameters=plant_parameters, noise=args.noise, seed=args.seed,
                   tag=args.tag, plots=not args.no_plots, plant_vehicle=args.plant_vehicle)
    return 0


def _cmd_replay(args) -> int:
    from .pipeline import replay

    _limits(args)
    replay(args.csv, args.observer, vehicle=args.vehicle, out=Path(args.out), fmu_dir=Path(args.fmu_dir),
           split=_split(args.split), plots=not args.no_plots)
    return 0


def _cmd_identify(args) -> int:
    """``latobs identify``: Cf, Cr of the car of a record, written as a vehicle file."""
    import tomli_w

    from . import __version__
    from .atomic import atomic_write_text
    from .data.records import load_csv
    from .synthesis import identification
    from .synthesis.params import load_vehicle
    from .validation.replay import MBDS_ALIAS, default_split, resolve_csv

    _limits(args)
    path = resolve_csv(args.record)
    if not path.exists():
        raise CliError(f"{args.record}: no such file (a .csv or .csv.gz with a header row, or 'mbds')")
    base_name = args.vehicle or ("mbds_250lm" if args.record == MBDS_ALIAS else None)
    if base_name is None:
        raise CliError("--vehicle BASE is needed: the mass, geometry and yaw inertia the record cannot reveal "
                       "(a shipped set's name or a vehicle .toml file)")
    base = load_vehicle(base_name)
    out = Path(args.out)
    if out.suffix != ".toml":
        raise CliError(f"--out takes a vehicle file ending in .toml, got {args.out!r}")
    name = args.name or out.stem
    from .synthesis.designs import ArtefactNameError, check_vehicle_name

    try:
        check_vehicle_name(name)
    except ArtefactNameError as exc:
        raise CliError(f"--name / the file name: {exc}") from None
    try:
        cols = load_csv(path)
    except (OSError, ValueError) as exc:
        raise CliError(str(exc) if str(exc).startswith(f"{path}:") else f"{args.record}: {exc}") from None
    t = cols.get("t")
    if args.tune_until is not None:
        tune_until, what = args.tune_until, f"t < {args.tune_until:g} s"
    elif args.tune_fraction is not None or default_split(path) is None:
        f = args.tune_fraction if args.tune_fraction is not None else 0.6
        if not 0.0 < f <= 1.0:
            raise CliError(f"--tune-fraction must be in (0, 1], got {f:g}")
        if t is None or len(t) < 2:
            raise CliError(f"{args.record}: no time column 't'")
        tune_until = float(t[0] + f * (t[-1] - t[0]))
        what = f"the first {100 * f:g} % (t < {tune_until:.6g} s)"
    else:
        tune_until = default_split(path)
        what = f"t < {tune_until:g} s (the record's tuning part; t >= {tune_until:g} s is held out)"
    from tqdm import tqdm

    # one tick per simulation of the record (the fit's evaluations, the bootstrap's Jacobian, the
    # residuals): its count is not known before the fit converges, so the bar counts and times them
    bar = tqdm(desc="identify: simulations of the record", unit="sim", mininterval=0.5, leave=False,
               disable=None)        # (None: off when stderr is not a terminal)
    try:
        result = identification.identify(cols, base, tune_until, use_beta=not args.without_beta,
                                         source=str(args.record), progress=lambda stage: bar.update())
    except identification.IdentificationError as exc:
        raise CliError(str(exc)) from None
    finally:
        bar.close()
    doc = identification.vehicle_document(result, base, name, path.name if args.record != MBDS_ALIAS else "mbds",
                                          what, __version__)
    atomic_write_text(out, "# Written by latobs identify; see [identification] for how.\n" + tomli_w.dumps(doc))
    print(f"identified on {what}, {result.samples} samples, fitting {', '.join(result.signals)}:")
    if result.capped_at is not None:
        print(f"  the fit stopped at t = {result.capped_at:.6g} s: at most {identification.MAX_FIT_SAMPLES} fitted "
              "samples (time and memory; the error bounds use the whole tuning part)")
    for k, ts in result.glitches.items():
        shown = ", ".join(f"{x:.6g}" for x in ts[:5]) + (", ..." if len(ts) > 5 else "")
        print(f"  {len(ts)} glitch(es) in {k} repaired and left out (t = {shown} s): see [identification] glitches")
    for k, v, (lo, hi), kappa in (("Cf", result.Cf, result.Cf_interval, result.tire_ratios[0]),
                                  ("Cr", result.Cr, result.Cr_interval, result.tire_ratios[1])):
        slope = f"; the slope at zero slip: fitted / {kappa:.4f} on {base.name}'s tire curve" if kappa != 1.0 else ""
        print(f"  {k} = {v:.0f} N/rad (95 % interval {lo:.0f} ... {hi:.0f}; {base.name}: {base.value(k):.0f}{slope})")
    if result.Iz is not None:
        print(f"  Iz = {result.Iz:.0f} kg*m^2 (95 % interval {result.Iz_interval[0]:.0f} ... {result.Iz_interval[1]:.0f}; "
              f"{base.name}: {base.value('Iz'):.0f})")
    for k, why in result.not_identified.items():
        print(f"  {k} not identified ({base.name}'s {base.value(k):g} kept): {why}")
    for k in result.signals:
        print(f"  residual RMS {k}: {result.rms[k]:.4g} (with {base.name}'s values: {result.rms_base[k]:.4g})")
    for k, (bound, rms) in result.error_bounds.items():
        print(f"  {identification.NOISE_SIGNALS[k]} = {bound:.4g} {'rad/s' if k == 'yaw_rate' else 'm/s^2'} "
              f"(measurement noise RMS {rms:.4g}; the interval observer's bound; "
              f"{identification.robust_basis(result, k)})")
    print(f"wrote {out}; next: latobs build NAME --vehicle {out}, latobs replay {args.record} --vehicle {out} "
          "--observer NAME")
    return 0


def _split(text: str):
    """--split: a time in s, 'none', or 'auto' (the file's default: 425 s for the MBDS record)."""
    if text.lower() in ("auto", "none"):
        return text.lower() if text.lower() == "auto" else None
    try:
        value = float(text)
    except ValueError:
        raise CliError(f"--split wants a time in s, 'none' or 'auto', got {text!r}") from None
    if value != value or value in (float("inf"), float("-inf")):
        raise CliError(f"--split must be a finite time in s, got {text!r}")
    return value


def _cmd_bench(args) -> int:
    from .bench import main as bench_main

    return bench_main(args.bench_args)


def _cmd_campaign(args) -> int:
    from .campaign_runner import rerun, run_campaign

    _limits(args)
    if args.rerun is not None:
        rerun(args.campaign, args.rerun, observers=args.observer, out=Path(args.out), fmu_dir=Path(args.fmu_dir),
              tag=args.tag, plots=not args.no_plots)
        return 0
    if args.scheduler is not None and args.workers is not None:
        raise CliError("--workers sizes the local cluster; with --scheduler the scheduler's workers run the campaign")
    run_campaign(args.campaign, observers=args.observer, runs=args.runs, out=Path(args.out),
                 fmu_dir=Path(args.fmu_dir), scheduler=args.scheduler, workers=args.workers, seed=args.seed,
                 tag=args.tag, fresh=args.fresh, plots=not args.no_plots, progress=not args.no_progress,
                 dashboard=args.dashboard)
    return 0


def _cmd_demo(args) -> int:
    from .demo import demo

    demo(Path(args.out), verbose=args.verbose, platforms=args.platforms)
    return 0


def _cmd_export_ssp(args) -> int:
    from .ssp import SspError, export_ssp

    plant_parameters = _plant_params(args.plant_param)
    _check_observers(args.observer or [], Path(args.fmu_dir))
    try:
        export_ssp(args.scenario, observers=args.observer, out=Path(args.out) if args.out else None,
                   fmu_dir=Path(args.fmu_dir), plant_parameters=plant_parameters, plant_vehicle=args.plant_vehicle)
    except SspError as exc:
        raise CliError(str(exc)) from None
    return 0


# --- argument values -------------------------------------------------------------------------
# Checked before any work. The ``type=`` checks below raise argparse.ArgumentTypeError, which
# argparse reports as "latobs CMD: error: argument --X: ..." (exit 2). What only the FMU knows
# (a parameter's name and its declared [min, max]) is checked by the harness against the FMU.

def _kv(text: str) -> tuple[str, float]:
    if "=" not in text:
        raise CliError(f"--plant-param wants NAME=VALUE, got {text!r}")
    k, v = (s.strip() for s in text.split("=", 1))
    if not k:
        raise CliError(f"--plant-param wants NAME=VALUE, got {text!r} (no NAME)")
    try:
        value = float(v)
    except ValueError:
        raise CliError(f"--plant-param {k}: {v!r} is not a number") from None
    if not math.isfinite(value):
        raise CliError(f"--plant-param {k}: {v!r} is not a finite number")
    return k, value


def _plant_params(items: list[str]) -> dict[str, float]:
    """--plant-param NAME=VALUE ... as a dict; a NAME given twice is refused."""
    out: dict[str, float] = {}
    for text in items:
        k, value = _kv(text)
        if k in out:
            raise CliError(f"--plant-param {k} given twice ({out[k]:g} and {value:g})")
        out[k] = value
    return out


def _check_observers(names: list[str], fmu_dir: Path) -> None:
    """--observer NAME: an FMU in --fmu-dir, or a design (NAME or NAME_V) that can be built there."""
    from .synthesis import designs

    for name in names:
        if not (fmu_dir / f"{name}.fmu").is_file():
            try:
                designs.parse_artefact(name)
            except KeyError as exc:
                raise CliError(f"--observer {name}: no {fmu_dir / (name + '.fmu')} and {exc.args[0]}") from None


def _int_at_least(minimum: int, text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"invalid int value: {text!r}") from None
    if value < minimum:
        raise argparse.ArgumentTypeError(f"must be an integer >= {minimum}, got {text!r}")
    return value


def _seed(text: str) -> int:
    """--seed: an integer >= 0 (numpy's default_rng refuses negative seeds)."""
    return _int_at_least(0, text)


def _tag(text: str) -> str:
    """--tag: the suffix of a folder name: a plain word (no path separator, newline, NUL, space or
    other control character; :func:`latobs.validation.campaign.check_name`), or empty."""
    if text == "":
        return text
    if "/" in text or "\\" in text or text in (".", ".."):
        raise argparse.ArgumentTypeError(f"must be a plain name (no '/', not '.' or '..'), got {text!r}")
    from .validation.campaign import NAME_MAX, NAME_RE

    if len(text) > NAME_MAX or not NAME_RE.fullmatch(text):
        raise argparse.ArgumentTypeError(f"must be a plain word of letters, digits, '.', '_', '+' or '-' (it names a "
                                         f"folder), got {text!r}")
    return text


def _positive(unit: str):
    """A ``type=`` of a finite number > 0 of ``unit``: --max-memory / --max-record-mb (MB), --max-hours,
    bench's --lmi-timeout (seconds)."""
    def check(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"invalid number of {unit}: {text!r}") from None
        if not (math.isfinite(value) and value > 0):
            raise argparse.ArgumentTypeError(f"must be a positive number of {unit}, got {text!r}")
        return value
    return check


MAX_MEMORY_HELP = ("refuse, before starting, what is estimated to need more memory than this many MB (default: "
                   "80 percent of the memory available; $LATOBS_MAX_MEMORY_MB)")
MAX_RECORD_HELP = ("read records of up to this many MB of CSV text (a .gz's decompressed text; default 1024; "
                   "$LATOBS_MAX_RECORD_MB); device files and FIFOs are never read")


def _dir(text: str, writable: bool) -> str:
    """A directory argument: an existing directory, or a path whose nearest existing ancestor is
    a directory (it is created when written to); with ``writable``, that one must be writable."""
    try:
        path = Path(text)
        if path.exists() and not path.is_dir():
            raise argparse.ArgumentTypeError(f"{text!r} is a file, not a directory")
        anc = path.absolute()
        while not anc.exists():
            anc = anc.parent
        if not anc.is_dir():
            raise argparse.ArgumentTypeError(f"{text!r}: {anc} is a file, not a directory")
        if writable and not os.access(anc, os.W_OK | os.X_OK):
            raise argparse.ArgumentTypeError(f"{text!r}: directory {anc} is not writable")
    except OSError as exc:
        raise argparse.ArgumentTypeError(f"{text!r}: {exc.strerror or exc}") from None
    return text


def _out_dir(text: str) -> str:
    """--out: where the command writes."""
    return _dir(text, writable=True)


def _fmu_dir(text: str) -> str:
    """--fmu-dir: where the FMUs are (written only when one is missing and gets built)."""
    return _dir(text, writable=False)


def _vehicle(text: str) -> str:
    """--vehicle / --plant-vehicle: a shipped set's name or a vehicle TOML file, loaded and
    validated now (the value is passed on unchanged)."""
    from .synthesis.params import VehicleParameterError, load_vehicle

    is_file = text.endswith(".toml")
    if is_file and not Path(text).is_file():
        raise argparse.ArgumentTypeError(f"{text!r}: no such file" if not Path(text).exists()
                                         else f"{text!r} is not a file")
    from .synthesis.designs import ArtefactNameError, check_vehicle_name

    try:
        check_vehicle_name(load_vehicle(text).name)    # it names FMUs and files: checked before any is written
    except Exception as exc:            # a file's content is the user's, whatever it breaks
        if not (is_file or isinstance(exc, (VehicleParameterError, ArtefactNameError))):
            raise
        msg = str(exc) if isinstance(exc, (VehicleParameterError, ArtefactNameError, OSError, UnicodeError)) else \
            f"malformed vehicle file ({type(exc).__name__}: {exc})"
        raise argparse.ArgumentTypeError(msg if not is_file or msg.startswith(text) else f"{text}: {msg}") \
            from None
    return text


PLATFORMS_HELP = ("comma-separated FMI platform folders, `host`, or `all`{default}: linux64, win64, darwin64 "
                  "(x86-64 + arm64), aarch64-linux (FMI 3.0 spellings too: x86_64-linux, x86_64-windows, "
                  "x86_64-darwin, aarch64-darwin)")


def _fmi_versions(text: str) -> list[int]:
    """``--fmi``: "2", "3" or "2,3"."""
    try:
        out = sorted({int(t) for t in text.split(",") if t.strip()})
    except ValueError:
        out = []
    if not out or any(v not in (2, 3) for v in out):
        raise argparse.ArgumentTypeError(f"--fmi takes 2, 3 or 2,3 (got {text!r})")
    return out


def _platforms(text: str) -> list[str]:
    from .cbackend.toolchain import parse_platforms

    try:
        return parse_platforms(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _positive_int(text: str) -> int:
    return _int_at_least(1, text)


def _out_file(text: str) -> str:
    """A file the command writes (its folder is created if missing)."""
    if Path(text).is_dir():
        raise argparse.ArgumentTypeError(f"{text!r} is a directory, not a file")
    _dir(str(Path(text).parent), writable=True)
    return text


def _check_bench_args(argv: list[str]) -> None:
    """The values of `latobs bench`'s options (bench parses them itself: latobs.bench.main),
    checked here so that a bad one is one line, not a traceback."""
    from .bench import BACKENDS
    from .synthesis import designs

    def names(known, what: str):
        def check(text: str) -> str:
            given = [x.strip() for x in text.split(",") if x.strip()]
            bad = [x for x in given if x not in known]
            if bad or not given:
                raise argparse.ArgumentTypeError(f"unknown {what} {', '.join(map(repr, bad)) or '(none given)'}; "
                                                 f"known: {', '.join(known)}")
            return text
        return check

    def existing_file(text: str) -> str:
        if not Path(text).is_file():
            raise argparse.ArgumentTypeError(f"{text!r}: no such file")
        return text

    p = _Parser(prog="latobs bench", add_help=False)
    p.add_argument("--fmu-dir", type=_fmu_dir)
    p.add_argument("--steps", type=_positive_int)
    p.add_argument("--repeats", type=_positive_int)
    p.add_argument("--json", type=_out_file)
    p.add_argument("--from-json", type=existing_file)
    p.add_argument("--backends", type=names(BACKENDS, "backend(s)"))
    p.add_argument("--designs", type=names(list(designs.DESIGNS), "design(s)"))
    p.add_argument("--scs-max-iters", type=_positive_int)
    p.add_argument("--lmi-timeout", type=_positive("seconds"))
    for flag in ("--skip-build", "--skip-lmi", "--skip-fmus", "--skip-coupled", "--skip-scaling"):
        p.add_argument(flag, action="store_true")
    p.parse_known_args(argv)


def parser() -> argparse.ArgumentParser:
    from . import __version__

    p = _Parser(prog="latobs", description=__doc__)
    p.add_argument("--version", action="version", version=f"latobs {__version__}")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")
    sub.add_parser("list", help="designs, plants, vehicles, scenarios and campaigns").set_defaults(func=_cmd_list)
    d = sub.add_parser("design", help="solve the LMIs, certify, write NAME.design.json")
    d.add_argument("name", help="an observer design (see `latobs list`)")
    d.add_argument("--vehicle", type=_vehicle, metavar="V",
                   help="a shipped vehicle set or a vehicle .toml file (default: the design's); a vehicle other "
                        "than the default names the file NAME_V.design.json, V the set's `name`")
    d.add_argument("--out", default=str(DEFAULT_OUT), type=_out_dir, metavar="DIR",
                   help="folder written (default: build); nothing is written outside it")
    d.set_defaults(func=_cmd_design)
    b = sub.add_parser("build", help="design and package FMUs (default: every observer and plant)")
    b.add_argument("names", nargs="*", metavar="NAME",
                   help="observer designs and plants to build (see `latobs list`; default: all of them)")
    b.add_argument("--vehicle", type=_vehicle, metavar="V",
                   help="a shipped vehicle set or a vehicle .toml file (default: each FMU's own); a vehicle "
                        "other than an FMU's default names it NAME_V.fmu, V the set's `name`")
    b.add_argument("--backend", choices=("auto", "c", "python"), default="auto",
                   help="c: native FMUs (compiled by zig cc, installed with latobs, and the system C compiler for this "
                        "machine's platform when there is one), python: pythonfmu FMUs, auto (default): the "
                        "backend of the FMU already in --out, else c where possible, else python with a message. "
                        "An FMU of the other backend already in --out is not replaced (exit 2): one folder per "
                        "backend")
    b.add_argument("--out", default=str(DEFAULT_OUT), type=_out_dir, metavar="DIR",
                   help="folder written (default: build): NAME.fmu and, for observers, NAME.design.json. An FMU "
                        "already there is reused only if built from identical inputs, else rebuilt; the folder "
                        "is locked while a build writes it (another build waits)")
    b.add_argument("--json", nargs="?", const="-", default=None, metavar="FILE",
                   help="a machine-readable summary of the FMUs built (name, kind, paper, vehicle, path, "
                        "sha256, size, backend, platforms; gamma and certificate of observers): written atomically "
                        "to FILE (*.json), or to stdout without FILE (or with '-'; progress goes to stderr then)")
    b.add_argument("--platforms", type=_platforms, default=None, metavar="LIST",
                   help="the native FMUs' binaries: " + PLATFORMS_HELP.format(default=" (default)")
                        + ". Not with --backend python (pythonfmu ships its own binaries)")
    b.add_argument("--fmi", type=_fmi_versions, default=[2], metavar="2|3|2,3",
                   help="the FMI version(s) of the FMUs (default 2): FMI 3.0 FMUs (native C, co-simulation and "
                        "model exchange) go to DIR/fmi3 under the same names, with their design files. Not 3 with "
                        "--backend python (pythonfmu makes FMI 2.0 FMUs only)")
    b.add_argument("--no-cache", action="store_true",
                   help="solve, compile and decide everything again instead of reusing the cache's designs, "
                        "FMUs and build-time facts of identical inputs (the cache folder: $LATOBS_CACHE_DIR, "
                        "else ~/.cache/latobs; LATOBS_NO_CACHE=1 turns it off for every command)")
    b.set_defaults(func=_cmd_build)
    v = sub.add_parser("validate", help="co-simulate the plant FMU with observer FMU(s) on a scenario")
    v.add_argument("scenario", metavar="SCENARIO", help="a registered scenario (see `latobs list`)")
    v.add_argument("--observer", action="append", default=None,
                   help="observer FMU name (repeatable; default: paper 000's observers beside CarPlant, every "
                        "observer of the scenario's plant otherwise)")
    v.add_argument("--out", default=str(DEFAULT_OUT), type=_out_dir, metavar="DIR",
                   help="writes DIR/SCENARIO[_TAG]/ (metrics.json and figures; default: build)")
    v.add_argument("--fmu-dir", default=str(DEFAULT_OUT), type=_fmu_dir, help="where the FMUs are (built if missing)")
    v.add_argument("--plant-param", action="append", default=[], metavar="NAME=VALUE",
                   help="CarPlant parameter, e.g. scale_f=0.8 or mu=0.3 (repeatable)")
    v.add_argument("--noise", action="store_true", help="add the default sensor noise and bias")
    v.add_argument("--seed", type=_seed, default=0, help="seed of the --noise draws (an integer >= 0)")
    v.add_argument("--tag", default="", type=_tag, help="suffix of the output folder (SCENARIO_TAG)")
    v.add_argument("--no-plots", action="store_true", help="write metrics.json only, no PNG figures")
    v.add_argument("--plant-vehicle", default=None, metavar="V", type=_vehicle,
                   help="vehicle of the plant FMU (default: the plant's default vehicle), e.g. sedan_no_roll")
    v.add_argument("--max-memory", type=_positive("MB"), default=None, metavar="MB", help=MAX_MEMORY_HELP)
    v.set_defaults(func=_cmd_validate)
    r = sub.add_parser("replay", help="drive an observer FMU with recorded signals and score it against the "
                                      "reference columns present")
    r.add_argument("csv", metavar="CSV", help="a .csv or .csv.gz file with a header row and a time column t, "
                                            "or 'mbds' for the bundled MBDS real-vehicle record")
    r.add_argument("--observer", required=True, help="observer FMU name (see `latobs list`)")
    r.add_argument("--vehicle", type=_vehicle,
                   help="vehicle of the FMU: NAME_V.fmu for a non-default vehicle (built if missing)")
    r.add_argument("--out", default=str(DEFAULT_OUT), type=_out_dir, metavar="DIR",
                   help="writes DIR/replay_<csv stem>_<FMU name>/ (default: build)")
    r.add_argument("--fmu-dir", default=str(DEFAULT_OUT), type=_fmu_dir, help="where the FMUs are (built if missing)")
    r.add_argument("--split", default="auto", metavar="T",
                   help="also score t < T and t >= T separately (s); 'none', or 'auto' (default: 425 s for the "
                        "MBDS record, whose t >= 425 s is a held-out test, none for other files)")
    r.add_argument("--no-plots", action="store_true", help="write metrics.json only, no PNG figures")
    r.add_argument("--max-memory", type=_positive("MB"), default=None, metavar="MB", help=MAX_MEMORY_HELP)
    r.add_argument("--max-record-mb", type=_positive("MB"), default=None, metavar="MB", help=MAX_RECORD_HELP)
    r.set_defaults(func=_cmd_replay)
    idf = sub.add_parser("identify", help="identify a car's cornering stiffnesses from a recorded drive into a "
                                          "vehicle file (then build and replay with --vehicle FILE)")
    idf.add_argument("record", metavar="RECORD", help="a .csv or .csv.gz file as `latobs replay` reads it (t, delta "
                                                    "(road-wheel angle), vx, yaw_rate, ay; beta when present), or "
                                                    "'mbds' for the bundled MBDS record")
    idf.add_argument("--vehicle", type=_vehicle, default=None, metavar="BASE",
                     help="the base vehicle: mass, geometry, yaw inertia, everything the record does not identify "
                          "(a shipped set or a .toml; default for 'mbds': mbds_250lm; needed otherwise)")
    tune = idf.add_mutually_exclusive_group()
    tune.add_argument("--tune-until", type=float, default=None, metavar="T",
                      help="fit on t < T s only (default: 425 s for the MBDS record, else --tune-fraction 0.6)")
    tune.add_argument("--tune-fraction", type=float, default=None, metavar="F",
                      help="fit on the first fraction F of the record (0 < F <= 1)")
    idf.add_argument("--without-beta", action="store_true",
                     help="do not fit the record's reference sideslip 'beta' (only yaw rate and ay)")
    idf.add_argument("--name", default=None, help="the identified vehicle's name (default: the file name's stem)")
    idf.add_argument("--out", required=True, metavar="FILE.toml", help="the vehicle file written")
    idf.add_argument("--max-record-mb", type=_positive("MB"), default=None, metavar="MB", help=MAX_RECORD_HELP)
    idf.set_defaults(func=_cmd_identify)
    bn = sub.add_parser("bench", help="µs per step of the built FMUs and the coupled run, beside references",
                        add_help=False)
    bn.add_argument("bench_args", nargs=argparse.REMAINDER, help="see `latobs bench --help`")
    bn.set_defaults(func=_cmd_bench)
    c = sub.add_parser("campaign", help="Monte Carlo campaign of a scenario or a campaign file on Dask "
                                        "(runs.parquet, summary, report.md)")
    c.add_argument("campaign", metavar="SCENARIO",
                   help="a registered scenario (with the distributions of its observers' robustness campaign), "
                        "a shipped campaign (robustness-000..003, robustness-000-flat, mbds-bootstrap) or a campaign .toml file")
    c.add_argument("--observer", action="append", default=None, help="observer FMU name (repeatable; default: "
                                                                      "the campaign's)")
    c.add_argument("--runs", type=_positive_int, default=None, metavar="N",
                   help="number of runs (default: the campaign's); more than before extends a campaign")
    c.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="a running dask-scheduler, e.g. tcp://127.0.0.1:8786 (default: a local cluster)")
    c.add_argument("--workers", type=_positive_int, default=None, metavar="N",
                   help="processes of the local cluster (default: the number of cores)")
    c.add_argument("--seed", type=_seed, default=None, help="campaign seed (default: the campaign's)")
    c.add_argument("--out", default=str(DEFAULT_OUT), type=_out_dir, metavar="DIR",
                   help="writes DIR/campaign_NAME[_TAG]/ (default: build)")
    c.add_argument("--fmu-dir", default=str(DEFAULT_OUT), type=_fmu_dir, help="where the FMUs are (built if missing)")
    c.add_argument("--tag", default="", type=_tag, help="suffix of the output folder")
    c.add_argument("--rerun", type=_seed, default=None, metavar="SEED",
                   help="run the one run of this seed alone, with the full validation output and plots")
    c.add_argument("--fresh", action="store_true", help="discard the runs already in the output folder")
    c.add_argument("--no-plots", action="store_true", help="no PNG figures")
    c.add_argument("--no-progress", action="store_true", help="no progress bar")
    c.add_argument("--dashboard", nargs="?", const=":8787", default=None, metavar="ADDRESS",
                   help="serve the local cluster's Dask dashboard (default address :8787); none without it")
    c.add_argument("--max-memory", type=_positive("MB"), default=None, metavar="MB", help=MAX_MEMORY_HELP)
    c.add_argument("--max-hours", type=_positive("hours"), default=None, metavar="H",
                   help="refuse, before starting, a campaign estimated to take longer than H hours (default 24; "
                        "$LATOBS_MAX_HOURS)")
    c.set_defaults(func=_cmd_campaign)
    m = sub.add_parser("demo", help="build everything, run the default scenarios, write build/report/index.md")
    m.add_argument("--out", default=str(DEFAULT_OUT), type=_out_dir, metavar="DIR",
                   help="folder written: the FMUs, DIR/report/index.md and its figures (default: build)")
    m.add_argument("--verbose", action="store_true", help="print every run's tables (default: a summary, one line "
                                                          "per observer and scenario; the rest is in the report)")
    m.add_argument("--platforms", type=_platforms, default=None, metavar="LIST",
                   help="the native FMUs' binaries: " + PLATFORMS_HELP.format(default="")
                        + " (default: this machine's, a quick first run; an FMU already in DIR that holds it is "
                          "reused)")
    m.set_defaults(func=_cmd_demo)
    x = sub.add_parser("export-ssp", help="write a scenario's co-simulation as an SSP 1.0 package (.ssp)")
    x.add_argument("scenario", metavar="SCENARIO", help="a registered scenario (see `latobs list`)")
    x.add_argument("--observer", action="append", default=None, help="observer FMU name (repeatable; default: "
                                                                      "those of `latobs validate SCENARIO`)")
    x.add_argument("--out", default=None, type=_out_file, metavar="FILE",
                   help="the .ssp file to write (default: build/SCENARIO.ssp)")
    x.add_argument("--fmu-dir", default=str(DEFAULT_OUT), type=_fmu_dir, help="where the FMUs are (built if missing)")
    x.add_argument("--plant-param", action="append", default=[], metavar="NAME=VALUE",
                   help="plant parameter written into its parameter set, e.g. mu=0.3 (repeatable)")
    x.add_argument("--plant-vehicle", default=None, metavar="V", type=_vehicle,
                   help="vehicle of the plant FMU (default: the plant's default vehicle)")
    x.set_defaults(func=_cmd_export_ssp)
    k = sub.add_parser("check", help="run an FMU's own reference experiments (inside it) and print pass/fail",
                       description="Runs the reference experiments an FMU carries (FMI-LS-REF, "
                                   "extra/org.fmi-standard.fmi-ls-ref) and compares its outputs with the reference "
                                   "outputs: bit for bit on the platform that certified them, within the tolerances "
                                   "they state elsewhere. One line per experiment and platform. Exit 0: all pass, 1: "
                                   "any fails, 2: no such FMU, no reference results, or a platform that cannot run "
                                   "here.")
    k.add_argument("fmu", metavar="FMU", help="the .fmu file")
    k.add_argument("--platform", default="host", metavar="P",
                   help="host (default: this machine's platform folder), all (every platform folder of the FMU that "
                        "can run here: win64 under Wine, aarch64-linux under qemu), or one platform folder (linux64, "
                        "win64, darwin64, aarch64-linux)")
    k.set_defaults(func=_cmd_check)
    return p


def _md_cell(text) -> str:
    """One line of Markdown showing ``text`` literally, its `code` spans kept."""
    parts = " ".join(str(text).split()).replace("|", "\\|").replace("<", "&lt;").split("`")
    return "`".join(x if k % 2 else x.replace("*", "\\*").replace("_", "\\_") for k, x in enumerate(parts))


def _parser_markdown(sub: argparse.ArgumentParser, title: str, summary: str) -> list[str]:
    """One command's section of the CLI reference: usage, description, its arguments."""
    out = [f"## `{title}`", ""]
    if summary:
        out += [_md_cell(summary[0].upper() + summary[1:]) + ".", ""]
    out += ["```", sub.format_usage().replace("usage: ", "").strip(), "```", ""]
    if sub.description and sub.description.strip() != summary:
        out += [_md_cell(sub.description), ""]
    rows = []
    for a in sub._actions:
        if isinstance(a, argparse._HelpAction) or a.help == argparse.SUPPRESS:
            continue
        name = ", ".join(a.option_strings) or (a.metavar or a.dest)
        if a.option_strings and a.nargs != 0:
            name += f" {a.metavar or a.dest.upper()}"
        default = "" if a.default in (None, False, [], "", argparse.SUPPRESS) or a.nargs == 0 else f"`{a.default}`"
        choices = f" (one of: {', '.join(map(str, a.choices))})" if a.choices else ""
        rows.append(f"| `{_md_cell(name)}` | {_md_cell((a.help or '') + choices)} | {default} |")
    if rows:
        out += ["| argument | meaning | default |", "|---|---|---|", *rows, ""]
    return out


def reference_markdown() -> str:
    """The CLI reference page of the documentation, generated from :func:`parser` (and ``latobs
    bench``'s own parser): every command with its usage and arguments."""
    from .bench import parser as bench_parser

    columns = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = "100"          # argparse wraps the usage lines to the terminal's width
    try:
        p = parser()
        out = ["# Command-line reference", "",
               "Generated from `latobs`'s own argument parser: what `latobs COMMAND --help` prints, as tables.", "",
               _md_cell(p.description), "",
               "Exit codes: 0 done; 2 a user error (one line `latobs CMD: error: ...` naming the culprit: "
               "argument, value, file, vehicle parameter or FMU; no traceback); 1 an internal error (a bug: one "
               "line `latobs CMD: internal error: ...`, the traceback with `LATOBS_DEBUG=1`); 130 interrupted "
               "(Ctrl-C).", ""]
        sub = next(a for a in p._actions if isinstance(a, argparse._SubParsersAction))
        helps = {c.dest: c.help for c in sub._choices_actions}
        for name, cmd in sub.choices.items():
            if name == "bench":
                cmd = bench_parser()
            out += _parser_markdown(cmd, f"latobs {name}", helps.get(name, ""))
    finally:
        if columns is None:
            os.environ.pop("COLUMNS", None)
        else:
            os.environ["COLUMNS"] = columns
    return "\n".join(out)


# The user-facing errors of each stage, as (module, class). A command imports only what it uses
# (``latobs validate`` never loads the solver stack), so the classes are looked up among the
# modules that are loaded: an exception can only be of a class whose module is. A new stage or
# subcommand adds its error class here. Besides these, every OSError (a file or folder that is
# missing, unreadable or unwritable; a full disk) is the user's (exit 2), and a KeyError is when
# one of USER_KEY_ERRORS raised it (the catalogue's lookups of a name, by contract); any other
# exception is an internal error (exit 1).
USER_ERRORS = (("latobs.cli", "CliError"), ("latobs.pipeline", "PipelineError"),
               ("latobs.packaging", "PackagingError"), ("latobs.synthesis.designs", "CertificateError"),
               ("latobs.synthesis.designs", "ArtefactNameError"), ("latobs.atomic", "FolderBusy"),
               ("latobs.synthesis.sideslip_bank_observer", "DesignError"), ("latobs.synthesis.lateral_interval_observer", "DesignError"),
               ("latobs.synthesis.sideslip_fixed_order_estimator", "DesignError"), ("latobs.synthesis.sideslip_kalman_filter", "DesignError"),
               ("latobs.synthesis.motorcycle_fault_observer", "DesignError"),
               ("latobs.synthesis.params", "VehicleParameterError"),
               ("latobs.validation.scenarios", "UnknownScenarioError"),
               ("latobs.validation.harness", "WiringError"), ("latobs.validation.harness", "CoSimulationError"),
               ("latobs.validation.replay", "ReplayError"), ("latobs.validation.campaign", "CampaignError"),
               ("latobs.check", "CheckError"), ("latobs.cache", "CacheSettingError"),
               ("latobs.data.budget", "ResourceLimitError"), ("latobs.data.records", "RecordError"))
#: (module, function) whose KeyError means "unknown name" (the message names it and the known ones).
USER_KEY_ERRORS = (("latobs.synthesis.designs", "get"), ("latobs.synthesis.designs", "parse_artefact"))


def _user_error_types() -> tuple[type, ...]:
    types: list[type] = [OSError]
    for module, name in USER_ERRORS:
        cls = getattr(sys.modules.get(module), name, None)
        if isinstance(cls, type):
            types.append(cls)
    return tuple(types)


def _is_user_error(exc: BaseException) -> bool:
    if isinstance(exc, _user_error_types()):
        return True
    if isinstance(exc, KeyError):          # only where a lookup of a user's name raised it
        tb = exc.__traceback__
        while tb is not None and tb.tb_next is not None:
            tb = tb.tb_next
        code = tb.tb_frame if tb is not None else None
        return code is not None and (code.f_globals.get("__name__"), code.f_code.co_name) in USER_KEY_ERRORS
    return False


def _one_line(text) -> str:
    """The message on one line (a file's or an FMU's text may hold line breaks)."""
    return " ".join(str(text).split())


def _message(exc: BaseException) -> str:
    if isinstance(exc, KeyError) and exc.args:         # str(KeyError) is the repr of its argument
        return _one_line(exc.args[0])
    if isinstance(exc, OSError) and exc.filename is not None:
        where = f"{exc.filename}" + (f" -> {exc.filename2}" if exc.filename2 is not None else "")
        return _one_line(f"{where}: {exc.strerror or exc}")
    return _one_line(exc) or type(exc).__name__


def _debug() -> bool:
    return os.environ.get(DEBUG_ENV, "") not in ("", "0")


def _run(command: str, fn, *args) -> int:
    """Run a command; a failure becomes its exit code and one line on stderr (module comment at
    the top). With LATOBS_DEBUG=1 the traceback is printed too (internal errors: re-raised)."""
    prefix = f"latobs {command}:" if command else "latobs:"
    try:
        return fn(*args)
    except KeyboardInterrupt:
        if _debug():
            raise
        print(f"{prefix} interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except BrokenPipeError:              # `latobs list | head`: the reader left; say nothing more
        try:
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        except (OSError, ValueError, AttributeError):
            pass
        return EXIT_INTERNAL
    except Exception as exc:
        if _is_user_error(exc):
            if _debug():
                import traceback

                traceback.print_exc()
            print(f"{prefix} error: {_message(exc)}", file=sys.stderr)
            return EXIT_USER
        if _debug():
            raise
        print(f"{prefix} internal error: {type(exc).__name__}: {_one_line(exc)} "
              f"(run with {DEBUG_ENV}=1 for the traceback)", file=sys.stderr)
        return EXIT_INTERNAL


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] == ["bench"]:
        # argparse's REMAINDER does not pass an option-like first argument (`bench --fmu-dir D`)
        # to the subcommand: bench parses its own arguments
        def bench(rest):
            from .bench import main as bench_main

            _check_bench_args(rest)
            return bench_main(rest)

        return _run("bench", bench, argv[1:])
    command = argv[0] if argv and not argv[0].startswith("-") else ""
    args = _run(command, parser().parse_args, argv)    # argparse's errors exit 2 (SystemExit)
    if isinstance(args, int):                          # a type= check failed unexpectedly, or Ctrl-C
        return args
    return _run(args.command, args.func, args)


if __name__ == "__main__":
    sys.exit(main())
