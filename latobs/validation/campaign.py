"""Monte Carlo campaigns: the definition (a TOML file), its distributions, the draws of each
run from its seed alone and the perturbed manoeuvre a run drives.

One run on built FMUs is :mod:`.campaign_run`, the journal and the statistics
:mod:`.campaign_stats`, the Dask side and the output folder :mod:`latobs.campaign_runner`;
docs/validation.md describes the definition file and the reproducibility rule.
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from .. import catalogue
from ..atomic import sha256_file  # noqa: F401  (an FMU's identity in a campaign)
from .scenarios import Scenario, get_scenario

KINDS = ("cosim", "replay")
#: transforms of :class:`PerturbedScenario` (``[signals]``) and their neutral values
SIGNAL_TRANSFORMS = {"speed_scale": 1.0, "steer_scale": 1.0, "bank_scale": 1.0, "bank_offset": 0.0}
#: the steering input of each plant, the one ``steer_scale`` multiplies
STEER_SIGNAL = {e.name: e.steer for e in catalogue.ENTRIES if e.steer}
PARTS = ("both", "train", "test")


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
    check_name(name, f"{where}: `name`")
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
# the scenario cases a definition can produce (checked when it is loaded)
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
        check_run_resources(f"{where}: {culprit}", sc.duration, dt)     # before a grid of its steps is made
        try:
            sc.time_grid(dt)
        except ValueError as exc:
            raise CampaignError(f"{where}: {culprit}: {exc}") from None
        out.append((label, sc))
    return out


#: a campaign's name names its folder (campaign_NAME): letters, digits, '.', '_', '+', '-', not
#: starting with '.', at most NAME_MAX characters. Anything else (a '/', a newline, a NUL, a space,
#: a control character) is refused before anything is created.
NAME_RE = re.compile(r"[\w+-][\w.+-]*")
NAME_MAX = 100


def check_name(name: str, what: str = "campaign name") -> str:
    """``name`` if it is safe as (part of) a folder name (:data:`NAME_RE`), else CampaignError."""
    if not (isinstance(name, str) and 0 < len(name) <= NAME_MAX and NAME_RE.fullmatch(name)):
        raise CampaignError(f"{what} must be a plain word of at most {NAME_MAX} letters, digits, '.', '_', '+' or "
                            f"'-', not starting with '.' (it names the output folder), got {name!r}")
    return name


# --------------------------------------------------------------------------------------------
# what a campaign needs (estimated before it runs)
# --------------------------------------------------------------------------------------------
#: memory a run holds per communication step, bytes: its time grid, signals, the plant's and the
#: observers' inputs and outputs and the metrics' copies (a lower estimate: a 1 h random-manoeuvre
#: run at 1 ms, 3.6e6 steps, with its full validation output peaked at 2.87 GB, 800 bytes a step)
RUN_BYTES_PER_STEP = 400
#: time a run takes per communication step, s (a lower estimate: the native FMUs' coupled loop)
RUN_SECONDS_PER_STEP = 1e-6
#: memory a finished run's row takes in the campaign's process (journal, summary), bytes (lower)
ROW_BYTES = 1000
#: time a run takes besides its steps (instantiating the FMUs, the metrics), s (lower)
RUN_SECONDS = 0.01


def check_run_resources(what: str, duration: float, dt: float, workers: int = 1,
                        block_steps: int | None = None) -> None:
    """Refuse (ResourceLimitError) a run of ``duration`` s at step ``dt`` that would not fit
    in memory (``workers`` of them at once) or in time, before it allocates anything.
    ``block_steps``: the run is streamed in blocks of that many steps (its memory that of a block
    and of the figures' samples, :data:`latobs.validation.stream.PLOT_SAMPLES`, whatever its length)."""
    from ..data import budget

    steps = duration / dt if dt > 0 else math.inf
    held = steps
    if block_steps is not None:
        from .stream import PLOT_SAMPLES

        held = min(steps, block_steps + PLOT_SAMPLES)
    budget.check(f"{what}: a run of {duration:g} s at dt = {dt:g} s ({steps:.3g} steps"
                 + (f", {workers} at once" if workers > 1 else "") + (", streamed" if block_steps else "") + ")",
                 memory=workers * held * RUN_BYTES_PER_STEP, seconds=steps * RUN_SECONDS_PER_STEP)


def check_resources(c: "Campaign", workers: int | None = 1, steps: float | None = None) -> None:
    """Refuse (ResourceLimitError, naming the estimate and the limit) a campaign whose runs would
    not fit in memory or time: ``steps`` communication steps a run (default: the scenario's
    duration at the campaign's step; a replay campaign's segment at the bundled record's 100 Hz),
    ``workers`` runs at once (None: unknown, a running scheduler's: one run's memory, time not
    estimated), a row of each run kept. Checked before any FMU is built or any run starts."""
    from ..data import budget

    if steps is None:
        if c.kind == "cosim":
            steps = c.base_scenario().duration / (c.dt or DEFAULT_DT)
        else:
            steps = float(c.replay.get("segment_s", 30.0)) / 0.01
    n = max(1, min(int(workers or 1), c.runs))
    # (a run of more than master.stream_steps() steps is streamed and holds a block, but is still
    # counted at its whole length: the bound on the steps a campaign's run may have, dt = 1e-9 refused)
    budget.check(f"campaign {c.name}: {c.runs} runs of {steps:.3g} steps, {n} at once",
                 memory=n * steps * RUN_BYTES_PER_STEP + c.runs * ROW_BYTES,
                 seconds=c.runs * (steps * RUN_SECONDS_PER_STEP + RUN_SECONDS) / n if workers else None)


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


@dataclass(frozen=True)
class FmuRef:
    """A built FMU a run uses: its role ("plant" or the observer's name), file name, sha256, and
    its local path (None on a Dask worker, which receives the bytes instead: it may not see the file)."""

    role: str
    filename: str
    sha256: str
    path: str | None = None

