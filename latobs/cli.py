"""Command line ``latobs`` (CONTRACT.md): list, design, build, validate, replay, demo."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

DEFAULT_OUT = Path("build")


class CliError(RuntimeError):
    """A user-facing failure: printed without a traceback, exit code 2."""


def _cmd_list(args) -> int:
    from .packaging import PLANTS
    from .synthesis import designs
    from .synthesis.params import load_vehicle, vehicle_names
    from .validation.scenarios import SCENARIOS

    print("designs (observer FMUs):")
    for name, e in designs.DESIGNS.items():
        print(f"  {name:28s} paper {e.paper}, default vehicle {e.default_vehicle}: {e.description}")
    print("plants:")
    for name, k in PLANTS.items():
        print(f"  {name:28s} default vehicle {k.default_vehicle}")
    print("vehicles:")
    for name in vehicle_names():
        v = load_vehicle(name)
        print(f"  {name:28s} {v.kind}: {v.description}")
    print("scenarios:")
    for name, s in SCENARIOS.items():
        print(f"  {name:28s} {s.duration:g} s: {s.description}")
    return 0


def _cmd_design(args) -> int:
    from .pipeline import design_one

    design_one(args.name, args.vehicle, Path(args.out))
    return 0


def _cmd_build(args) -> int:
    from .pipeline import build

    build(args.names, args.vehicle, Path(args.out), args.backend)
    return 0


def _cmd_validate(args) -> int:
    from .pipeline import run_validation

    run_validation(args.scenario, observers=args.observer, out=Path(args.out), fmu_dir=Path(args.fmu_dir),
                   plant_parameters=dict(_kv(p) for p in args.plant_param), noise=args.noise, seed=args.seed,
                   tag=args.tag, plots=not args.no_plots, plant_vehicle=args.plant_vehicle)
    return 0


def _cmd_replay(args) -> int:
    from .pipeline import replay

    replay(args.csv, args.observer, vehicle=args.vehicle, out=Path(args.out), fmu_dir=Path(args.fmu_dir),
           split=_split(args.split), plots=not args.no_plots)
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


def _cmd_demo(args) -> int:
    from .demo import demo

    demo(Path(args.out))
    return 0


def _kv(text: str) -> tuple[str, float]:
    if "=" not in text:
        raise CliError(f"--plant-param wants NAME=VALUE, got {text!r}")
    k, v = text.split("=", 1)
    try:
        return k.strip(), float(v)
    except ValueError as exc:
        raise CliError(f"--plant-param {k}: {v!r} is not a number") from exc


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="latobs", description=__doc__)
    sub = p.add_subparsers(dest="command", required=True)
    sub.add_parser("list", help="designs, plants, vehicles and scenarios").set_defaults(func=_cmd_list)
    d = sub.add_parser("design", help="solve the LMIs, certify, write NAME.design.json")
    d.add_argument("name")
    d.add_argument("--vehicle")
    d.add_argument("--out", default=str(DEFAULT_OUT))
    d.set_defaults(func=_cmd_design)
    b = sub.add_parser("build", help="design and package FMUs (default: every observer and plant)")
    b.add_argument("names", nargs="*")
    b.add_argument("--vehicle")
    b.add_argument("--backend", choices=("python", "c"), default="python")
    b.add_argument("--out", default=str(DEFAULT_OUT))
    b.set_defaults(func=_cmd_build)
    v = sub.add_parser("validate", help="co-simulate the plant FMU with observer FMU(s) on a scenario")
    v.add_argument("scenario")
    v.add_argument("--observer", action="append", default=None, help="observer FMU name (repeatable)")
    v.add_argument("--out", default=str(DEFAULT_OUT))
    v.add_argument("--fmu-dir", default=str(DEFAULT_OUT), help="where the FMUs are (built if missing)")
    v.add_argument("--plant-param", action="append", default=[], metavar="NAME=VALUE",
                   help="CarPlant parameter, e.g. scale_f=0.8 or mu=0.3 (repeatable)")
    v.add_argument("--noise", action="store_true", help="add the default sensor noise and bias")
    v.add_argument("--seed", type=int, default=0)
    v.add_argument("--tag", default="", help="suffix of the output folder (SCENARIO_TAG)")
    v.add_argument("--no-plots", action="store_true", help="write metrics.json only, no PNG figures")
    v.add_argument("--plant-vehicle", default=None, metavar="V",
                   help="vehicle of the plant FMU (default: the plant's default vehicle), e.g. sedan_no_roll")
    v.set_defaults(func=_cmd_validate)
    r = sub.add_parser("replay", help="drive an observer FMU with recorded signals and score it against the "
                                      "reference columns present")
    r.add_argument("csv", metavar="CSV", help="a .csv or .csv.gz file with a header row and a time column t, "
                                            "or 'mbds' for the bundled MBDS real-vehicle record")
    r.add_argument("--observer", required=True, help="observer FMU name (see `latobs list`)")
    r.add_argument("--vehicle", help="vehicle of the FMU: NAME_V.fmu for a non-default vehicle (built if missing)")
    r.add_argument("--out", default=str(DEFAULT_OUT), help="writes OUT/replay_<csv stem>_<FMU name>/")
    r.add_argument("--fmu-dir", default=str(DEFAULT_OUT), help="where the FMUs are (built if missing)")
    r.add_argument("--split", default="auto", metavar="T",
                   help="also score t < T and t >= T separately (s); 'none', or 'auto' (default: 425 s for the "
                        "MBDS record, whose t >= 425 s is a held-out test, none for other files)")
    r.add_argument("--no-plots", action="store_true", help="write metrics.json only, no PNG figures")
    r.set_defaults(func=_cmd_replay)
    bn = sub.add_parser("bench", help="µs per step of the built FMUs and the coupled run, beside references",
                        add_help=False)
    bn.add_argument("bench_args", nargs=argparse.REMAINDER, help="see `latobs bench --help`")
    bn.set_defaults(func=_cmd_bench)
    m = sub.add_parser("demo", help="build everything, run the default scenarios, write build/report/index.md")
    m.add_argument("--out", default=str(DEFAULT_OUT))
    m.set_defaults(func=_cmd_demo)
    return p


# The user-facing errors of each stage, as (module, class). A command imports only what it uses
# (``latobs validate`` never loads the solver stack), so the classes are looked up among the
# modules that are loaded: an exception can only be of a class whose module is.
USER_ERRORS = (("latobs.cli", "CliError"), ("latobs.pipeline", "PipelineError"),
               ("latobs.packaging", "PackagingError"), ("latobs.synthesis.designs", "CertificateError"),
               ("latobs.synthesis.pi_hinf_000", "DesignError"), ("latobs.synthesis.interval_001", "DesignError"),
               ("latobs.synthesis.fixed_order_002", "DesignError"), ("latobs.synthesis.kalman_baseline", "DesignError"),
               ("latobs.synthesis.pi_switched_003", "DesignError"),
               ("latobs.synthesis.params", "VehicleParameterError"),
               ("latobs.validation.replay", "ReplayError"))


def _user_error_types() -> tuple[type, ...]:
    types = [KeyError]
    for module, name in USER_ERRORS:
        m = sys.modules.get(module)
        if m is not None:
            types.append(getattr(m, name))
    return tuple(types)


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] == ["bench"]:
        # argparse's REMAINDER does not pass an option-like first argument (`bench --fmu-dir D`)
        # to the subcommand: bench parses its own arguments
        from .bench import main as bench_main

        return bench_main(argv[1:])
    args = parser().parse_args(argv)
    try:
        return args.func(args)
    except Exception as exc:
        if not isinstance(exc, _user_error_types()):
            raise
        msg = exc.args[0] if isinstance(exc, KeyError) and exc.args else exc
        print(f"latobs {args.command}: error: {msg}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
