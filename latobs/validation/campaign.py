"""Monte Carlo campaigns: one manoeuvre, or segments of a recorded drive, run many times over
declared distributions; every run reproducible from its seed alone.

This module is the campaign's mathematics and bookkeeping, with no parallel engine in it (the
Dask side is :mod:`latobs.campaign`): the definition file, the draws, one run on built FMUs, the
append-only journal of finished runs, and the summary statistics.

Campaign definition (TOML; shipped ones in ``latobs/campaigns/``; :func:`load`)::

    name = "robustness-000"              # the output folder is OUT/campaign_<name>
    description = "..."
    kind = "cosim"                       # "cosim": plant + observer FMUs on a scenario;
                                         # "replay": observer FMUs on segments of a recorded drive
    scenario = "bank-braking"            # cosim: a registered scenario (latobs list)
    observers = ["SideslipBankObserver"] # observer FMU names (NAME or NAME_VEHICLE)
    plant_vehicle = "sedan"              # cosim, optional: the plant FMU's vehicle
    runs = 1000
    seed = 2026                          # the campaign seed (run k's seed derives from it and k)
    dt = 0.005                           # cosim, optional: communication step, s
    settle_time = 3.0                    # optional: metrics from this time (s) of each run on

    [scenario]                           # scenario fields: a number or a distribution
    duration = 10.0
    [plant]                              # plant FMU parameters: a number or a distribution
    mu = { uniform = [0.6, 1.0] }
    [signals]                            # transforms of the scenario's plant inputs
    speed_scale = { uniform = [0.9, 1.1] }   # vx *= speed_scale
    steer_scale = { uniform = [0.5, 1.5] }   # the steering input (delta / rider_torque) *= it
    bank_offset = { normal = [0.0, 0.02] }   # rad, added to bank_angle
    bank_scale = 1.0                         # bank_angle *= it (before the offset)
    [noise.yaw_rate]                     # a sensor's additive white noise std and constant bias,
    std = { uniform = [0.001, 0.004] }   # in the signal's SI unit, drawn per run
    bias = { normal = [0.0, 0.001] }
    [replay]                             # replay: the record and its segments
    csv = "mbds"                         # a .csv/.csv.gz path or "mbds" (latobs replay's files)
    segment_s = 30.0                     # segment length, s (each run: one segment)
    part = "both"                        # "train" (t < split), "test" (t >= split) or "both"

A distribution is ``{ uniform = [low, high] }``, ``{ normal = [mean, std] }`` (optionally with
``clip = [low, high]``), ``{ loguniform = [low, high] }`` or ``{ choice = [v1, v2, ...] }``; a plain
number is a fixed value.

Reproducibility: run k of a campaign with seed S has the seed ``run_seed(S, k)`` (numpy's
SeedSequence of [S, k]); every draw of the run comes from ``numpy.random.default_rng(seed)`` in a
fixed order (scenario fields, plant parameters, signal transforms, sensors, segment: each sorted
by name), and the sensor noise of the run from the same seed (the harness's NoiseSpec). So a run
is re-run alone from its seed and the definition (``latobs campaign NAME --rerun SEED``), whatever
the number of runs, workers or machines. A scenario with a ``seed`` field (``random-manoeuvre``)
that the definition does not fix gets the run's seed.
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import os
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from .. import catalogue
from .scenarios import Scenario, get_scenario

KINDS = ("cosim", "replay")
#: transforms of :class:`PerturbedScenario` (``[signals]``) and their neutral values
SIGNAL_TRANSFORMS = {"speed_scale": 1.0, "steer_scale": 1.0, "bank_scale": 1.0, "bank_offset": 0.0}
#: the steering input of each plant, the one ``steer_scale`` multiplies
STEER_SIGNAL = {e.name: e.steer for e in catalogue.ENTRIES if e.steer}
PARTS = ("both", "train", "test")
#: percentiles of every metric in the summary
PERCENTILES = (5, 50, 95, 99)
#: resamples of the bootstrap confidence interval of each metric's mean
BOOTSTRAP_RESAMPLES = 2000
WORST_RUNS = 5


class CampaignError(ValueError):
    """A bad campaign definition or output folder; the message names the file, table and key."""


# --------------------------------------------------------------------------------------------
# distributions
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Dist:
    """One declared distribution: kind in fixed/uniform/normal/loguniform/choice, its arguments,
    an optional clip interval (normal)."""

    kind: str
    args: tuple[float, ...]
    clip: tuple[float, float] | None = None

    def draw(self, rng: np.random.Generator) -> float:
        a = self.args
        if self.kind == "fixed":
            return a[0]
        if self.kind == "uniform":
            x = rng.uniform(a[0], a[1])
        elif self.kind == "normal":
            x = rng.normal(a[0], a[1])
        elif self.kind == "loguniform":
            x = math.exp(rng.uniform(math.log(a[0]), math.log(a[1])))
        else:  # choice
            x = a[int(rng.integers(len(a)))]
        if self.clip is not None:
            x = min(max(x, self.clip[0]), self.clip[1])
        return float(x)

    @property
    def drawn(self) -> bool:
        return self.kind != "fixed"

    def support(self) -> tuple[float, float]:
        """(lowest, highest) value a draw can take: a normal without clip reaches every real number."""
        a = self.args
        if self.kind == "fixed":
            return a[0], a[0]
        if self.kind == "normal":
            if self.clip is not None:
                return self.clip
            return (a[0], a[0]) if a[1] == 0 else (-math.inf, math.inf)
        return min(a), max(a)

    def extremes(self) -> tuple[float, ...]:
        """The values a check must try: every choice, else the two ends of the support."""
        if self.kind == "choice":
            return tuple(sorted(set(self.args)))
        lo, hi = self.support()
        return (lo,) if lo == hi else (lo, hi)

    def nominal(self) -> float:
        """A representative value inside the support (the scenario the input-range check starts from)."""
        a = self.args
        if self.kind == "uniform":
            return 0.5 * (a[0] + a[1])
        if self.kind == "loguniform":
            return math.sqrt(a[0] * a[1])
        if self.kind == "normal":
            return a[0] if self.clip is None else min(max(a[0], self.clip[0]), self.clip[1])
        return a[0]

    def describe(self) -> str:
        a = ", ".join(f"{x:g}" for x in self.args)
        text = {"fixed": f"{a}", "uniform": f"U[{a}]", "normal": f"N({a})", "loguniform": f"logU[{a}]",
                "choice": f"one of {{{a}}}"}[self.kind]
        return text + (f" clipped to [{self.clip[0]:g}, {self.clip[1]:g}]" if self.clip else "")

    def as_json(self) -> Any:
        if self.kind == "fixed":
            return self.args[0]
        d: dict[str, Any] = {self.kind: list(self.args)}
        if self.clip:
            d["clip"] = list(self.clip)
        return d


def parse_dist(value: Any, where: str) -> Dist:
    """A :class:`Dist` from its TOML value; CampaignError naming ``where`` when malformed."""
    def number(x) -> float:
        if isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x):
            raise CampaignError(f"{where}: {x!r} is not a finite number")
        return float(x)

    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return Dist("fixed", (number(value),))
    if not isinstance(value, Mapping):
        raise CampaignError(f"{where}: expected a number or a distribution such as {{ uniform = [0.8, 1.2] }}, "
                            f"got {value!r}")
    kinds = [k for k in value if k != "clip"]
    if len(kinds) != 1 or kinds[0] not in ("uniform", "normal", "loguniform", "choice"):
        raise CampaignError(f"{where}: a distribution has exactly one of uniform, normal, loguniform, choice "
                            f"(and clip for normal); got keys {sorted(value)}")
    kind = kinds[0]
    raw = value[kind]
    if not isinstance(raw, (list, tuple)):
        raise CampaignError(f"{where}: {kind} takes a list, got {raw!r}")
    args = tuple(number(x) for x in raw)
    if kind == "choice":
        if not args:
            raise CampaignError(f"{where}: choice needs at least one value")
    elif len(args) != 2:
        raise CampaignError(f"{where}: {kind} takes two numbers, got {list(raw)}")
    elif kind in ("uniform", "loguniform") and not args[0] < args[1]:
        raise CampaignError(f"{where}: {kind} needs low < high, got {list(raw)}")
    elif kind == "loguniform" and args[0] <= 0:
        raise CampaignError(f"{where}: loguniform needs 0 < low, got {list(raw)}")
    elif kind == "normal" and args[1] < 0:
        raise CampaignError(f"{where}: normal needs std >= 0, got {list(raw)}")
    clip = None
    if "clip" in value:
        if kind != "normal":
            raise CampaignError(f"{where}: clip applies to normal only")
        c = value["clip"]
        if not (isinstance(c, (list, tuple)) and len(c) == 2) or not number(c[0]) < number(c[1]):
            raise CampaignError(f"{where}: clip takes [low, high] with low < high, got {c!r}")
        clip = (float(c[0]), float(c[1]))
    return Dist(kind, args, clip)


# --------------------------------------------------------------------------------------------
# the definition
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Campaign:
    """A campaign definition (module docstring); build it with :func:`load` or :func:`from_dict`."""

    name: str
    kind: str
    observers: tuple[str, ...]
    runs: int
    seed: int
    description: str = ""
    scenario: str = ""
    plant_vehicle: str | None = None
    dt: float | None = None
    settle_time: float | None = None
    scenario_fields: Mapping[str, Dist] = field(default_factory=dict)
    plant: Mapping[str, Dist] = field(default_factory=dict)
    signals: Mapping[str, Dist] = field(default_factory=dict)
    noise: Mapping[str, tuple[Dist, Dist]] = field(default_factory=dict)
    replay: Mapping[str, Any] = field(default_factory=dict)
    source: str = ""

    # ---- the scenario (cosim)
    def base_scenario(self) -> Scenario:
        return get_scenario(self.scenario)

    def drawn_names(self) -> list[str]:
        """Names of the quantities drawn per run (the parameters a run row records)."""
        names = [f"scenario.{k}" for k, d in sorted(self.scenario_fields.items()) if d.drawn]
        if self.kind == "cosim" and self._scenario_takes_seed():
            names.append("scenario.seed")
        names += [f"plant.{k}" for k, d in sorted(self.plant.items()) if d.drawn]
        names += [f"signals.{k}" for k, d in sorted(self.signals.items()) if d.drawn]
        for s, (std, bias) in sorted(self.noise.items()):
            names += [f"noise.{s}.{w}" for w, d in (("std", std), ("bias", bias)) if d.drawn]
        if self.kind == "replay":
            names += ["segment.t_start_s", "segment.part"]
        return names

    def _scenario_takes_seed(self) -> bool:
        fields = {f.name for f in dataclasses.fields(self.base_scenario())}
        return "seed" in fields and "seed" not in self.scenario_fields

    def as_dict(self) -> dict[str, Any]:
        """The definition as plain JSON data (what :func:`from_dict` reads back)."""
        d: dict[str, Any] = {"name": self.name, "description": self.description, "kind": self.kind,
                             "observers": list(self.observers), "runs": self.runs, "seed": self.seed}
        for k in ("scenario", "plant_vehicle", "dt", "settle_time"):
            if getattr(self, k) not in (None, ""):
                d[k] = getattr(self, k)
        for table, attr in (("scenario_fields", self.scenario_fields), ("plant", self.plant),
                            ("signals", self.signals)):
            if attr:
                d[table] = {
                    k: v.as_json() for k, v in sorted(attr.items())}
        if self.noise:
            d["noise"] = {s: {"std": a.as_json(), "bias": b.as_json()} for s, (a, b) in sorted(self.noise.items())}
        if self.replay:
            d["replay"] = dict(self.replay)
        return d

    def fingerprint(self, fmu_hashes: Mapping[str, str]) -> str:
        """sha256 of everything a run's result depends on: the definition except its run count and
        description, and the FMUs' sha256 ({role: hash}). Resuming needs the same fingerprint."""
        d = self.as_dict()
        for k in ("runs", "description"):
            d.pop(k, None)
        blob = json.dumps({"definition": d, "fmus": dict(sorted(fmu_hashes.items()))}, sort_keys=True)
        return hashlib.sha256(blob.encode()).hexdigest()

    def with_overrides(self, observers: list[str] | None = None, runs: int | None = None,
                       seed: int | None = None) -> "Campaign":
        return dataclasses.replace(self, observers=tuple(observers) if observers else self.observers,
                                   runs=self.runs if runs is None else int(runs),
                                   seed=self.seed if seed is None else int(seed))


_TOP_KEYS = {"name", "description", "kind", "scenario", "observers", "plant_vehicle", "runs", "seed", "dt",
             "settle_time", "plant", "signals", "noise", "replay", "scenario_fields"}


def load(path: str | os.PathLike) -> Campaign:
    """Read and check a campaign TOML file (CampaignError naming the file and key when bad)."""
    import tomllib

    path = Path(path)
    try:
        raw = tomllib.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise CampaignError(f"campaign file {path}: cannot read it: {exc}") from None
    except tomllib.TOMLDecodeError as exc:
        raise CampaignError(f"campaign file {path}: not valid TOML: {exc}") from None
    if "scenario" in raw and isinstance(raw["scenario"], Mapping):
        raise CampaignError(f"campaign file {path}: `scenario` is the scenario's name; put scenario fields in "
                            "a [scenario_fields] table")
    return from_dict(raw, source=str(path))


def from_dict(raw: Mapping[str, Any], source: str = "<dict>") -> Campaign:
    """A checked :class:`Campaign` from plain data (a TOML file's tables)."""
    where = f"campaign {source}"
    unknown = sorted(set(raw) - _TOP_KEYS)
    if unknown:
        raise CampaignError(f"{where}: unknown key(s) {', '.join(unknown)}; known: "
                            f"{', '.join(sorted(_TOP_KEYS))}")

    def req(key, typ, what):
        if key not in raw:
            raise CampaignError(f"{where}: missing `{key}` ({what})")
        v = raw[key]
        if not isinstance(v, typ) or isinstance(v, bool):
            raise CampaignError(f"{where}: `{key}` must be {what}, got {v!r}")
        return v

    name = req("name", str, "a name")
    if not name or any(c in name for c in "/\\ \t") or name.startswith("."):
        raise CampaignError(f"{where}: `name` must be a plain word (it names the output folder), got {name!r}")
    kind = raw.get("kind", "cosim")
    if kind not in KINDS:
        raise CampaignError(f"{where}: `kind` must be one of {', '.join(KINDS)}, got {kind!r}")
    observers = raw.get("observers", [])
    if not (isinstance(observers, list) and all(isinstance(o, str) and o for o in observers)):
        raise CampaignError(f"{where}: `observers` must be a list of observer FMU names, got {observers!r}")
    runs = req("runs", int, "an integer >= 1")
    seed = req("seed", int, "an integer >= 0")
    if runs < 1 or seed < 0:
        raise CampaignError(f"{where}: `runs` must be >= 1 and `seed` >= 0, got runs = {runs}, seed = {seed}")
    opt_float = {}
    for k in ("dt", "settle_time"):
        if k in raw:
            v = raw[k]
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v < 0 \
                    or (k == "dt" and v <= 0):
                raise CampaignError(f"{where}: `{k}` must be a {'positive' if k == 'dt' else 'non-negative'} time "
                                    f"in s, got {v!r}")
            opt_float[k] = float(v)

    def table(key) -> Mapping[str, Any]:
        t = raw.get(key, {})
        if not isinstance(t, Mapping):
            raise CampaignError(f"{where}: [{key}] must be a table")
        return t

    dists = {key: {k: parse_dist(v, f"{where}: [{key}] {k}") for k, v in table(key).items()}
             for key in ("scenario_fields", "plant", "signals")}
    bad = sorted(set(dists["signals"]) - set(SIGNAL_TRANSFORMS))
    if bad:
        raise CampaignError(f"{where}: [signals] {', '.join(bad)}: unknown transform; known: "
                            f"{', '.join(SIGNAL_TRANSFORMS)}")
    noise = {}
    for sig, t in table("noise").items():
        if not isinstance(t, Mapping) or set(t) - {"std", "bias"}:
            raise CampaignError(f"{where}: [noise.{sig}] takes std and bias (numbers or distributions), got {t!r}")
        std = parse_dist(t.get("std", 0.0), f"{where}: [noise.{sig}] std")
        bias = parse_dist(t.get("bias", 0.0), f"{where}: [noise.{sig}] bias")
        lo = min(std.args) if std.kind != "normal" else (std.clip[0] if std.clip else -1.0)
        if lo < 0:
            raise CampaignError(f"{where}: [noise.{sig}] std must stay >= 0 (use uniform, loguniform, choice of "
                                "non-negative values, or normal with clip = [0, ...])")
        noise[sig] = (std, bias)
    scenario = raw.get("scenario", "")
    replay = dict(table("replay"))
    if kind == "cosim":
        if not isinstance(scenario, str) or not scenario:
            raise CampaignError(f"{where}: a cosim campaign names its `scenario` (see `latobs list`)")
        if replay:
            raise CampaignError(f"{where}: [replay] belongs to kind = \"replay\" campaigns")
        try:
            base = get_scenario(scenario)
        except KeyError as exc:
            raise CampaignError(f"{where}: {exc}") from None
        fields = {f.name for f in dataclasses.fields(base)}
        bad = sorted(set(dists["scenario_fields"]) - fields)
        if bad:
            raise CampaignError(f"{where}: [scenario_fields] {', '.join(bad)}: scenario {scenario!r} has no such "
                                f"field; fields: {', '.join(sorted(fields - {'name', 'description'}))}")
        if "bank_angle" not in base.signal_names and any(
                dists["signals"].get(k, Dist("fixed", (SIGNAL_TRANSFORMS[k],))).args != (SIGNAL_TRANSFORMS[k],)
                for k in ("bank_scale", "bank_offset")):
            raise CampaignError(f"{where}: [signals] bank_scale/bank_offset: scenario {scenario!r} has no bank_angle")
        if base.plant not in STEER_SIGNAL and "steer_scale" in dists["signals"]:
            raise CampaignError(f"{where}: [signals] steer_scale: no steering input known for plant {base.plant}")
        scenario_cases(where, scenario, dists["scenario_fields"], opt_float.get("dt", DEFAULT_DT))
    else:
        if scenario or dists["scenario_fields"] or dists["plant"] or dists["signals"]:
            raise CampaignError(f"{where}: a replay campaign has no scenario, [scenario_fields], [plant] or "
                                "[signals]: only [replay] and [noise]")
        unknown = sorted(set(replay) - {"csv", "segment_s", "part"})
        if unknown:
            raise CampaignError(f"{where}: [replay] unknown key(s) {', '.join(unknown)}; known: csv, segment_s, part")
        replay.setdefault("csv", "mbds")
        replay.setdefault("part", "both")
        seg = replay.get("segment_s", 30.0)
        if isinstance(seg, bool) or not isinstance(seg, (int, float)) or not seg > 0:
            raise CampaignError(f"{where}: [replay] segment_s must be a positive time in s, got {seg!r}")
        replay["segment_s"] = float(seg)
        if replay["part"] not in PARTS:
            raise CampaignError(f"{where}: [replay] part must be one of {', '.join(PARTS)}, got {replay['part']!r}")
        if not isinstance(replay["csv"], str):
            raise CampaignError(f"{where}: [replay] csv must be a path or \"mbds\", got {replay['csv']!r}")
    pv = raw.get("plant_vehicle")
    if pv is not None and not (isinstance(pv, str) and pv):
        raise CampaignError(f"{where}: `plant_vehicle` must be a vehicle name, got {pv!r}")
    return Campaign(name=name, kind=kind, observers=tuple(observers), runs=runs, seed=seed,
                    description=str(raw.get("description", "")), scenario=scenario, plant_vehicle=pv,
                    scenario_fields=dists["scenario_fields"], plant=dists["plant"], signals=dists["signals"],
                    noise=noise, replay=replay, source=source, **opt_float)


# --------------------------------------------------------------------------------------------
# supports against the declared ranges: checked before any run
# --------------------------------------------------------------------------------------------
#: the longest manoeuvre a campaign runs, s: an hour of driving (720 000 communication steps at the
#: default 5 ms per run); a longer one is a typing mistake far more often than a plan
MAX_DURATION_S = 3600.0
#: the communication step of a cosim run when the definition gives none, s
DEFAULT_DT = 0.005


def scenario_cases(where: str, name: str, fields: Mapping[str, Dist], dt: float) -> list[tuple[str, Scenario]]:
    """The scenario ``name`` built at its fields' nominal values and at each end of each field's
    support (a choice: at each value), the other fields nominal: [(label, scenario)]. Every one
    must be accepted by the scenario, last between 0 and :data:`MAX_DURATION_S` and hold at least
    one step ``dt``; else CampaignError naming ``where``, the field and the value. A field drawn
    from a normal without clip is refused (its support is every real number)."""
    def value(k, x):
        return int(x) if k == "seed" else x

    for k, d in sorted(fields.items()):
        if not all(map(math.isfinite, d.support())):
            raise CampaignError(f"{where}: [scenario_fields] {k} = {d.describe()} can take any real number; "
                                "bound it (clip = [low, high])")
    nominal = {k: value(k, d.nominal()) for k, d in fields.items()}
    cases = [("", nominal)] + [(f"{k} = {x:g} (an end of {d.describe()})", {**nominal, k: value(k, x)})
                               for k, d in sorted(fields.items()) if d.drawn for x in d.extremes()]
    out = []
    for label, vals in cases:
        culprit = f"[scenario_fields] {label}" if label else (
            "[scenario_fields] " + ", ".join(f"{k} = {v:g}" for k, v in sorted(vals.items())) if vals
            else f"scenario {name!r} (its own fields)")
        try:
            sc = get_scenario(name, **vals)
        except (ValueError, TypeError) as exc:
            raise CampaignError(f"{where}: {culprit}: scenario {name!r} refuses it: {exc}") from None
        if not 0 < sc.duration <= MAX_DURATION_S:
            raise CampaignError(f"{where}: {culprit}: the duration {sc.duration:g} s is outside (0, "
                                f"{MAX_DURATION_S:g}] s")
        try:
            sc.time_grid(dt)
        except ValueError as exc:
            raise CampaignError(f"{where}: {culprit}: {exc}") from None
        out.append((label, sc))
    return out


@dataclass(frozen=True)
class Declared:
    """A variable of an FMU's modelDescription: causality and declared range (None: unbounded)."""

    causality: str
    min: float | None
    max: float | None


def declared_variables(path: str | os.PathLike) -> dict[str, Declared]:
    """{name: Declared} of every Real/Integer variable of the FMU at ``path``; its min/max from the
    variable or, when it has none, from its declared type."""
    from fmpy import read_model_description

    def num(x):
        return None if x in (None, "") else float(x)

    out = {}
    for v in read_model_description(str(path)).modelVariables:
        if v.type not in ("Real", "Integer"):
            continue
        t = v.declaredType
        lo = v.min if v.min not in (None, "") else getattr(t, "min", None)
        hi = v.max if v.max not in (None, "") else getattr(t, "max", None)
        out[v.name] = Declared(v.causality, num(lo), num(hi))
    return out


def _inside(where: str, what: str, lo: float, hi: float, var: str, decl: Declared, fmu: str) -> None:
    """CampaignError unless [lo, hi] lies within the range ``fmu`` declares for ``var``."""
    rng = f"{'-inf' if decl.min is None else f'{decl.min:g}'} .. {'inf' if decl.max is None else f'{decl.max:g}'}"
    if decl.min is not None and not lo >= decl.min:
        raise CampaignError(f"{where}: {what} reaches {lo:g}, below the minimum {decl.min:g} that {fmu} declares "
                            f"for {var} (range {rng})")
    if decl.max is not None and not hi <= decl.max:
        raise CampaignError(f"{where}: {what} reaches {hi:g}, above the maximum {decl.max:g} that {fmu} declares "
                            f"for {var} (range {rng})")


def check_supports(c: Campaign, fmus: list[FmuRef]) -> None:
    """Before any run of a cosim campaign: every [plant] parameter is one the plant FMU (``fmus[0]``,
    with a local path) has, and its support lies within the range the FMU declares for it; every
    plant input the scenario drives, transformed by [signals], stays within its declared range,
    over the ends of every drawn scenario field and transform (:func:`scenario_cases`; the
    transforms are affine per sample, so the ends bound every draw; a scenario with a seed field
    is checked at its nominal seed). CampaignError naming the file, table and key otherwise."""
    if c.kind != "cosim" or not fmus or fmus[0].path is None:
        return
    import itertools

    where, plant = f"campaign {c.source or c.name}", fmus[0]
    decl = declared_variables(plant.path)
    params = sorted(n for n, d in decl.items() if d.causality == "parameter")
    for k, d in sorted(c.plant.items()):
        if k not in params:
            raise CampaignError(f"{where}: [plant] {k}: {plant.filename} has no such parameter; its parameters: "
                                f"{', '.join(params) or '(none)'}")
        _inside(where, f"[plant] {k} = {d.describe()}", *d.support(), k, decl[k], plant.filename)
    ins = {n: d for n, d in decl.items() if d.causality == "input" and (d.min is not None or d.max is not None)}
    if not ins:
        return
    dt = c.dt or DEFAULT_DT
    drawn = {k: d.extremes() for k, d in sorted(c.signals.items())}
    corners = [dict(zip(drawn, xs)) for xs in itertools.product(*drawn.values())] or [{}]
    for label, base in scenario_cases(where, c.scenario, c.scenario_fields, dt):
        t = base.time_grid(dt)
        for tr in corners:
            sig = PerturbedScenario.of(base, **tr).sampled(t, c.plant_vehicle or "sedan")
            for n in sorted(set(sig) & set(ins)):
                what = (f"input {n} of scenario {c.scenario!r}"
                        + (f" with {label}" if label else "")
                        + (" and [signals] " + ", ".join(f"{k} = {x:g}" for k, x in tr.items()) if tr else ""))
                _inside(where, what, float(np.min(sig[n])), float(np.max(sig[n])), n, ins[n], plant.filename)


# --------------------------------------------------------------------------------------------
# draws
# --------------------------------------------------------------------------------------------
def run_seed(campaign_seed: int, k: int) -> int:
    """The seed of run ``k`` (0-based) of a campaign with seed ``campaign_seed``: a 32-bit integer
    from numpy's SeedSequence([campaign_seed, k]) (independent streams for distinct k)."""
    return int(np.random.SeedSequence([int(campaign_seed), int(k)]).generate_state(1, dtype=np.uint32)[0])


def draw(c: Campaign, seed: int, record_span: tuple[float, float] | None = None,
         split: float | None = None) -> dict[str, Any]:
    """The run's values of every declared quantity ({"scenario.X", "plant.X", "signals.X",
    "noise.S.std", "noise.S.bias", and for replay "segment.t_start_s", "segment.part"}), fixed ones
    included, drawn from default_rng(seed) in the documented order. Replay needs the record's
    first and last time (s, its own time axis) and its split time (s, on that axis, or None)."""
    rng = np.random.default_rng(seed)
    p: dict[str, Any] = {}
    for k, d in sorted(c.scenario_fields.items()):
        p[f"scenario.{k}"] = d.draw(rng)
    if c.kind == "cosim" and c._scenario_takes_seed():
        p["scenario.seed"] = int(seed)
    for k, d in sorted(c.plant.items()):
        p[f"plant.{k}"] = d.draw(rng)
    for k, d in sorted(c.signals.items()):
        p[f"signals.{k}"] = d.draw(rng)
    for s, (std, bias) in sorted(c.noise.items()):
        p[f"noise.{s}.std"] = max(std.draw(rng), 0.0)
        p[f"noise.{s}.bias"] = bias.draw(rng)
    if c.kind == "replay":
        p.update(_draw_segment(rng, c.replay, record_span, split))
    return p


def _draw_segment(rng, replay: Mapping[str, Any], span: tuple[float, float] | None,
                  split: float | None) -> dict[str, Any]:
    """A segment wholly inside one part of the record (train: t < split, test: t >= split, on the
    record's time axis), the part drawn with probability proportional to its room for a segment,
    the start (``segment.t_start_s``, on the record's time axis) uniform in it."""
    seg = float(replay["segment_s"])
    if span is None:
        raise CampaignError("a replay draw needs the record's time span")
    start, end = (float(x) for x in span)
    inside = split is not None and start < split < end
    bounds = {"train": (start, split if inside else end), "test": (split, end) if inside else None}
    wanted = ("train", "test") if replay["part"] == "both" else (replay["part"],)
    room = {}
    for part in wanted:
        b = bounds.get(part)
        if b is not None and b[1] - b[0] >= seg:
            room[part] = (b[0], b[1] - seg)
    if not room:
        raise CampaignError(f"no {seg:g} s segment fits in the {replay['part']} part of the record "
                            f"(t from {start:g} to {end:g} s, split {split})")
    parts = sorted(room)
    widths = np.array([room[q][1] - room[q][0] + 1e-9 for q in parts])
    part = parts[int(rng.choice(len(parts), p=widths / widths.sum()))]
    t0 = float(rng.uniform(*room[part]))
    return {"segment.t_start_s": t0, "segment.part": part}


# --------------------------------------------------------------------------------------------
# the perturbed manoeuvre
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class PerturbedScenario(Scenario):
    """``base`` with its plant inputs transformed ([signals] of the definition): vx times
    ``speed_scale``; the plant's steering input (:data:`STEER_SIGNAL`) times ``steer_scale``;
    bank_angle times ``bank_scale`` plus ``bank_offset`` (rad). The base scenario's amplitudes
    were computed for its nominal speed: scaling the speed also changes the lateral acceleration
    a given steer produces, which is the point of a robustness campaign."""

    base: Scenario | None = None
    speed_scale: float = 1.0
    steer_scale: float = 1.0
    bank_scale: float = 1.0
    bank_offset: float = 0.0  # rad

    @classmethod
    def of(cls, base: Scenario, **transforms: float) -> "PerturbedScenario":
        return cls(name=base.name, description=base.description, duration=base.duration, plant=base.plant,
                   settle_time=base.settle_time, signal_names=base.signal_names, base=base, **transforms)

    @property
    def optional_plant_inputs(self):   # the base's (a class attribute of each scenario class)
        return getattr(self.base, "optional_plant_inputs", ())

    def signals(self, t, vehicle="sedan"):
        sig = dict(self.base.signals(t, vehicle))
        if "vx" in sig:
            sig["vx"] = np.asarray(sig["vx"], dtype=float) * self.speed_scale
        steer = STEER_SIGNAL.get(self.plant)
        if steer in sig:
            sig[steer] = np.asarray(sig[steer], dtype=float) * self.steer_scale
        if "bank_angle" in sig:
            sig["bank_angle"] = np.asarray(sig["bank_angle"], dtype=float) * self.bank_scale + self.bank_offset
        return sig

    def parameter_signals(self, t, vehicle="sedan"):
        return self.base.parameter_signals(t, vehicle)

    def _derived(self, vehicle):
        d = dict(self.base._derived(vehicle))
        d.update(speed_scale=self.speed_scale, steer_scale=self.steer_scale, bank_scale=self.bank_scale,
                 bank_offset_rad=self.bank_offset)
        return d


def scenario_of(c: Campaign, params: Mapping[str, Any]) -> PerturbedScenario:
    """The run's manoeuvre: the campaign's scenario with its drawn fields and signal transforms."""
    fields = {k.split(".", 1)[1]: v for k, v in params.items() if k.startswith("scenario.")}
    if "seed" in fields:
        fields["seed"] = int(fields["seed"])
    base = get_scenario(c.scenario, **fields)
    transforms = {k.split(".", 1)[1]: float(v) for k, v in params.items() if k.startswith("signals.")}
    return PerturbedScenario.of(base, **transforms)


def noise_of(params: Mapping[str, Any]) -> dict[str, tuple[float, float]]:
    """{signal: (std, bias)} of the run's sensors."""
    sigs = sorted({k.split(".")[1] for k in params if k.startswith("noise.")})
    return {s: (float(params[f"noise.{s}.std"]), float(params[f"noise.{s}.bias"])) for s in sigs}


# --------------------------------------------------------------------------------------------
# metrics of one run
# --------------------------------------------------------------------------------------------
def observer_metrics(label: str, outputs: Mapping[str, np.ndarray], truth: Mapping[str, np.ndarray],
                     after: np.ndarray, model_name: str | None) -> dict[str, float]:
    """Flat metrics of one observer in one run, on the samples ``after`` (t >= settle time):
    ``LABEL.X.rms`` and ``LABEL.X.max_abs`` of every estimate ``X_hat`` that has a truth, and for
    every interval ``X_lower``/``X_upper``: ``LABEL.X.violations`` (samples outside, or a bound
    not finite), ``LABEL.X.max_violation`` and ``LABEL.X.mean_width``; ``LABEL.nonfinite``: samples
    of any scored output that are not finite. SI units of the signals. The truth is chosen as in
    :mod:`latobs.validation.metrics` (its REFERENCE_SIGNALS map)."""
    from . import metrics

    row: dict[str, float] = {}
    nonfinite = 0
    for name, y in outputs.items():
        if name.endswith("_hat"):
            q = name[:-4]
            src = metrics.truth_signal(q, truth, model_name)
            if src is None:
                continue
            e = (np.asarray(y, dtype=float) - np.asarray(truth[src], dtype=float))[after]
            nonfinite += int(np.sum(~np.isfinite(e)))
            row[f"{label}.{q}.rms"] = float(np.sqrt(np.mean(e * e))) if e.size else math.nan
            row[f"{label}.{q}.max_abs"] = float(np.max(np.abs(e))) if e.size else math.nan
        elif name.endswith("_lower") and name[:-6] + "_upper" in outputs:
            q = name[:-6]
            src = metrics.truth_signal(q, truth, model_name)
            if src is None:
                continue
            s = metrics.enclosure_stats(np.asarray(y)[after], np.asarray(outputs[q + "_upper"])[after],
                                        np.asarray(truth[src])[after])
            nonfinite += s["nonfinite_samples"]
            row[f"{label}.{q}.violations"] = float(s["enclosure_violations"])
            row[f"{label}.{q}.max_violation"] = float(s["max_violation"] or 0.0)
            row[f"{label}.{q}.mean_width"] = math.nan if s["mean_width"] is None else float(s["mean_width"])
    row[f"{label}.nonfinite"] = float(nonfinite)
    return row


# --------------------------------------------------------------------------------------------
# one run, on FMU files (a worker's task)
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class FmuRef:
    """A built FMU a run uses: its role ("plant" or the observer's name), file name, sha256, and
    its local path (None on a Dask worker, which receives the bytes instead: it may not see the file)."""

    role: str
    filename: str
    sha256: str
    path: str | None = None


_WORKER_CACHE: dict[str, tuple[str, str]] = {}   # sha256 -> (FMU path, extracted folder)
_CACHE_LOCK = threading.Lock()
_CACHE_DIR: list[str] = []                          # this process's folder, made on first use
_RUN_LOCK = threading.Lock()                        # one run at a time per process (module docstring)


def _local(ref: FmuRef, blob: bytes | None = None) -> tuple[str, str]:
    """(FMU path, extracted folder) of ``ref`` in this process, written and extracted once per
    process (in a temporary folder removed at exit). ``blob``: the FMU's bytes when the caller
    received them separately (a scattered Dask object); checked against the sha256."""
    import atexit
    import shutil
    import tempfile

    from fmpy import extract

    with _CACHE_LOCK:
        hit = _WORKER_CACHE.get(ref.sha256)
        if hit is not None:
            return hit
        if not _CACHE_DIR:
            _CACHE_DIR.append(tempfile.mkdtemp(prefix="latobs_campaign_"))
            atexit.register(shutil.rmtree, _CACHE_DIR[0], True)
        folder = Path(_CACHE_DIR[0]) / ref.sha256[:16]
        folder.mkdir(parents=True, exist_ok=True)
        if blob is not None:
            if hashlib.sha256(blob).hexdigest() != ref.sha256:
                raise CampaignError(f"FMU {ref.filename}: the bytes received do not match its sha256")
            path = folder / ref.filename
            path.write_bytes(blob)
        elif ref.path is not None:
            path = Path(ref.path)
        else:
            raise CampaignError(f"FMU {ref.filename}: neither its bytes nor its path were given")
        hit = (str(path), extract(str(path), unzipdir=str(folder / "unzipped")))
        _WORKER_CACHE[ref.sha256] = hit
        return hit


#: metrics of a replay run start this long (s) after the segment's start unless the definition
#: says otherwise: the observer starts from its initial state in the middle of a drive
REPLAY_SETTLE_S = 5.0


def settle_time(c: Campaign, scenario: Scenario | None = None) -> float:
    if c.settle_time is not None:
        return c.settle_time
    return float(scenario.settle_time) if scenario is not None else REPLAY_SETTLE_S


def cosim_setup(c: Campaign, params: Mapping[str, Any], seed: int) -> tuple[PerturbedScenario, dict[str, Any]]:
    """The run's scenario and the keyword arguments of :func:`latobs.validation.harness.run`
    (dt, noise with the run's seed, plant parameters, vehicle): what a campaign run and its
    ``--rerun`` both use."""
    from .harness import NoiseSpec

    sc = scenario_of(c, params)
    noise = noise_of(params)
    kwargs = {"dt": c.dt or DEFAULT_DT, "seed": int(seed), "vehicle": c.plant_vehicle or "sedan",
              "noise": NoiseSpec(signals=noise, seed=int(seed)) if noise else None,
              "plant_parameters": {k.split(".", 1)[1]: float(v) for k, v in params.items() if k.startswith("plant.")}}
    return sc, kwargs


def replay_segment(c: Campaign, params: Mapping[str, Any], record: Mapping[str, np.ndarray],
                   seed: int) -> dict[str, np.ndarray]:
    """The run's slice of the record ([t_start, t_start + segment_s) from the record's start),
    with the run's sensor noise and bias added to the noisy columns (NoiseSpec with the run's seed)."""
    from .harness import NoiseSpec

    t = np.asarray(record["t"], dtype=float)
    t0 = float(params["segment.t_start_s"])
    sel = (t >= t0 - 1e-9) & (t < t0 + float(c.replay["segment_s"]) - 1e-9)
    data = {k: np.asarray(v, dtype=float)[sel] for k, v in record.items()}
    noise = noise_of(params)
    if noise:
        missing = sorted(set(noise) - set(data))
        if missing:
            raise CampaignError(f"[noise] {', '.join(missing)}: no such column in the record")
        for s, e in NoiseSpec(signals=noise, seed=int(seed)).draw(int(sel.sum())).items():
            data[s] = data[s] + e
    return data


def run_case(c: Campaign, k: int, seed: int, fmus: list[FmuRef], blobs: list[bytes | None] | None = None,
             record: Mapping[str, np.ndarray] | None = None, split: float | None = None) -> dict[str, Any]:
    """Run ``k`` (seed ``seed``) of campaign ``c`` on the FMUs ``fmus`` (the plant first for a
    cosim campaign; ``blobs[i]``: the bytes of ``fmus[i]`` when shipped separately) and, for a
    replay campaign, the ``record`` ({column: array}, ``t`` in s) and its ``split`` time. Returns
    the journal row: run, seed, status ("ok", or "failed" with the error: an FMU or model failure
    is a result of the campaign, not a crash of it), seconds, worker, params, metrics. One run at
    a time per process: the FMU instances of a run are not shared with a concurrent one."""
    import socket

    t_start = time.perf_counter()
    row: dict[str, Any] = {"run": int(k), "seed": int(seed), "status": "ok", "error": None,
                           "worker": f"{socket.gethostname()}:{os.getpid()}", "params": {}, "metrics": {},
                           "headline": []}
    with _RUN_LOCK:
        try:
            blobs = blobs or [None] * len(fmus)
            local = {ref.role: _local(ref, b) for ref, b in zip(fmus, blobs)}
            if c.kind == "cosim":
                row["params"] = params = draw(c, seed)
                row["metrics"], inputs = _cosim_metrics(c, params, seed, fmus, local)
            else:
                t = np.asarray(record["t"], dtype=float)
                row["params"] = params = draw(c, seed, record_span=(float(t[0]), float(t[-1])), split=split)
                row["metrics"], inputs = _replay_metrics(c, params, seed, fmus, local, record)
            row["headline"] = headline_columns(row["metrics"], inputs)
        except Exception as exc:    # noqa: BLE001 - recorded in the journal, named in the report
            row["status"] = "failed"
            row["error"] = f"{type(exc).__name__}: {exc}"[:2000]
    row["seconds"] = time.perf_counter() - t_start
    row["metrics"] = {k: (None if isinstance(v, float) and not math.isfinite(v) else v)
                      for k, v in row["metrics"].items()}
    return row


def run_cases(c: Campaign, ks: list[int], seeds: list[int], fmus: list[FmuRef],
              blobs: list[bytes | None] | None = None, record: Mapping[str, np.ndarray] | None = None,
              split: float | None = None) -> list[dict[str, Any]]:
    """:func:`run_case` for each run index of ``ks`` with its seed of ``seeds`` (one Dask task)."""
    return [run_case(c, k, s, fmus, blobs, record, split) for k, s in zip(ks, seeds)]


def _cosim_metrics(c, params, seed, fmus, local) -> tuple[dict[str, float], dict[str, list[str]]]:
    from . import harness

    sc, kwargs = cosim_setup(c, params, seed)
    plant = local[fmus[0].role]
    observers = {ref.role: local[ref.role] for ref in fmus[1:]}
    res = harness.run(sc, plant[0], {lab: p for lab, (p, _) in observers.items()},
                      unzipped={p: d for p, d in [plant, *observers.values()]}, **kwargs)
    return result_metrics(res, settle_time(c, sc)), res.inputs


def result_metrics(res, settle: float) -> dict[str, float]:
    """Flat metrics (:func:`observer_metrics`) of every observer of a co-simulation result."""
    after = np.asarray(res.time) >= settle - 1e-12
    models = res.info.get("observer_models", {})
    out: dict[str, float] = {}
    for label, outs in res.observers.items():
        out.update(observer_metrics(label, outs, res.bus, after, models.get(label)))
    return out


def _replay_metrics(c, params, seed, fmus, local, record) -> tuple[dict[str, float], dict[str, list[str]]]:
    from . import replay as rp

    data = replay_segment(c, params, record, seed)
    out: dict[str, float] = {}
    inputs: dict[str, list[str]] = {}
    for ref in fmus:
        path, unzipped = local[ref.role]
        run = rp.drive(path, data, label=ref.role, unzipdir=unzipped)
        out.update(replay_metrics(run, c))
        inputs[ref.role] = list(run.inputs)
    return out, inputs


def replay_metrics(run, c: Campaign) -> dict[str, float]:
    """Flat metrics of a replay run (:class:`latobs.validation.replay.ReplayRun`) after the settle time."""
    after = run.time >= run.time[0] + settle_time(c) - 1e-9
    return observer_metrics(run.label, run.outputs, run.columns, after, run.model_name)


# --------------------------------------------------------------------------------------------
# the journal: one JSON line per finished run, append-only
# --------------------------------------------------------------------------------------------
class Journal:
    """``runs.jsonl``: the rows of finished runs, appended one line per run and flushed at once
    (fsync at most every second, and at close), so an interrupted campaign keeps every run that
    finished. :meth:`read` skips a torn last line (a kill in the middle of a write; the next
    :meth:`append` cuts it off) and keeps the first row of a run index seen twice."""

    FSYNC_EVERY_S = 1.0

    def __init__(self, path: str | os.PathLike):
        self.path = Path(path)
        self._f = None
        self._synced = 0.0
        self.duplicates = 0

    def read(self) -> dict[int, dict[str, Any]]:
        rows: dict[int, dict[str, Any]] = {}
        if not self.path.is_file():
            return rows
        lines = self.path.read_text(encoding="utf-8").split("\n")
        for i, line in enumerate(lines):
            if not line.strip():
                continue
            try:
                row = json.loads(line)
                k = int(row["run"])
            except (ValueError, KeyError, TypeError):
                if i == len(lines) - 1:          # the last line, cut short by a kill: dropped
                    continue
                raise CampaignError(f"{self.path}: line {i + 1} is not a run row; the journal is damaged "
                                    "(remove the folder to start again)") from None
            if k in rows:
                self.duplicates += 1
                continue
            rows[k] = row
        return rows

    def append(self, row: Mapping[str, Any]) -> None:
        if self._f is None:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            if self.path.is_file():              # a torn last line (a kill mid-write) is cut off
                data = self.path.read_bytes()
                if data and not data.endswith(b"\n"):
                    with open(self.path, "r+b") as f:
                        f.truncate(data.rfind(b"\n") + 1)
            self._f = open(self.path, "a", encoding="utf-8")
        self._f.write(json.dumps(row, allow_nan=False, separators=(",", ":")) + "\n")
        self._f.flush()
        now = time.monotonic()
        if now - self._synced >= self.FSYNC_EVERY_S:
            os.fsync(self._f.fileno())
            self._synced = now

    def close(self) -> None:
        if self._f is not None:
            self._f.flush()
            os.fsync(self._f.fileno())
            self._f.close()
            self._f = None


# --------------------------------------------------------------------------------------------
# summary
# --------------------------------------------------------------------------------------------
def metric_columns(rows: list[Mapping[str, Any]]) -> list[str]:
    cols: dict[str, None] = {}
    for r in rows:
        for k in r.get("metrics", {}):
            cols.setdefault(k, None)
    return list(cols)


def headline_columns(metrics: Mapping[str, Any], inputs: Mapping[str, list[str]]) -> list[str]:
    """The metric columns ranked for the worst runs and plotted: the RMS error of each estimate of
    a quantity the observer does not measure (``beta``, ``bank_angle``, ``Fyf``, not the filtered
    ``yaw_rate`` it reads), and each interval's violation count and mean width (the widest runs:
    an interval that never misses the truth is judged by how wide it is). ``inputs``: {label:
    its inputs}."""
    out = []
    for col in metrics:
        label, _, rest = col.partition(".")
        q, _, what = rest.rpartition(".")
        if what in ("violations", "mean_width") or (what == "rms" and q not in inputs.get(label, ())):
            out.append(col)
    return out


def _stats(x: np.ndarray, rng: np.random.Generator) -> dict[str, Any]:
    x = x[np.isfinite(x)]
    if not x.size:
        return {"n": 0}
    d: dict[str, Any] = {"n": int(x.size), "mean": float(np.mean(x)), "max": float(np.max(x)),
                         "min": float(np.min(x))}
    d.update({f"p{p}": float(np.percentile(x, p)) for p in PERCENTILES})
    means = x[rng.integers(0, x.size, size=(BOOTSTRAP_RESAMPLES, x.size))].mean(axis=1)
    d["mean_ci95"] = [float(np.percentile(means, 2.5)), float(np.percentile(means, 97.5))]
    return d


def summarize(c: Campaign, rows: list[Mapping[str, Any]]) -> dict[str, Any]:
    """Percentiles (5, 50, 95, 99), min, max, mean and its 95 % bootstrap interval of every metric
    over the successful runs (and per part of the record for a replay campaign); the failed
    runs with their errors; for every interval, the runs whose bounds missed the truth; and the
    :data:`WORST_RUNS` worst runs of every headline metric with their seeds and parameters."""
    ok = [r for r in rows if r["status"] == "ok"]
    failed = [r for r in rows if r["status"] != "ok"]
    cols = metric_columns(ok)
    rng = np.random.default_rng(0)        # the bootstrap's resampling: fixed, the summary is reproducible

    def table(sel):
        return {col: _stats(np.array([np.nan if r["metrics"].get(col) is None else r["metrics"][col]
                                      for r in sel], dtype=float), rng) for col in cols}

    out: dict[str, Any] = {"campaign": c.name, "runs": len(rows), "ok": len(ok), "failed": len(failed),
                           "failures": [{"run": r["run"], "seed": r["seed"], "error": r["error"]}
                                        for r in sorted(failed, key=lambda r: r["run"])][:50],
                           "metrics": table(ok)}
    if c.kind == "replay":
        out["by_part"] = {p: table([r for r in ok if r["params"].get("segment.part") == p])
                          for p in ("train", "test") if any(r["params"].get("segment.part") == p for r in ok)}
    enclosure = {}
    for col in cols:
        if col.endswith(".violations"):
            v = [(r["metrics"].get(col) or 0.0, r) for r in ok]
            bad = [r for x, r in v if x > 0]
            enclosure[col[: -len(".violations")]] = {
                "runs_with_violations": len(bad), "runs": len(v), "violating_samples": int(sum(x for x, _ in v)),
                "runs_violating": [{"run": r["run"], "seed": r["seed"]} for r in sorted(bad, key=lambda r: r["run"])][:20]}
    out["enclosure"] = enclosure
    heads = headlines(ok)
    worst = {}
    for col in heads:
        vals = [(r["metrics"].get(col), r) for r in ok if r["metrics"].get(col) is not None]
        vals.sort(key=lambda p: (-p[0], p[1]["run"]))
        worst[col] = [{"run": r["run"], "seed": r["seed"], "value": x, "params": r["params"]}
                      for x, r in vals[:WORST_RUNS] if not (col.endswith(".violations") and x == 0)]
    out["worst"] = worst
    out["headline"] = heads
    return out


def headlines(rows: list[Mapping[str, Any]]) -> list[str]:
    """The headline columns of the runs (:func:`headline_columns`, recorded in each row)."""
    return list(dict.fromkeys(c for r in rows for c in r.get("headline", ())))


def rows_table(rows: list[Mapping[str, Any]]):
    """The runs as a pyarrow Table: run, seed, status, error, seconds, worker, one column per
    drawn quantity (``param.NAME``) and per metric."""
    import pyarrow as pa

    rows = sorted(rows, key=lambda r: r["run"])
    params: dict[str, None] = {}
    for r in rows:
        for k in r["params"]:
            params.setdefault(k, None)
    cols: dict[str, list] = {k: [r.get(k) for r in rows] for k in ("run", "seed", "status", "error", "seconds", "worker")}
    for p in params:
        cols[f"param.{p}"] = [r["params"].get(p) for r in rows]
    for m in metric_columns(rows):
        cols[m] = [r["metrics"].get(m) for r in rows]
    return pa.table(cols)
