"""Vehicle parameter sets: the first stage of the pipeline. Each set is a TOML file (SI units, a unit
and a description per value, its source); loading validates every value (finite, of the declared
sign, ranges with min <= max), and errors name the vehicle and the parameter."""
from __future__ import annotations

import functools
import math
import re
import tomllib
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Iterable, Mapping

G = 9.81  # m/s^2, gravitational acceleration used by every model of this package


class VehicleParameterError(ValueError):
    """A vehicle parameter set is missing a value or holds an invalid one."""


#: a vehicle's name: it names FMUs (``NAME_VEHICLE``: an FMI modelIdentifier, a C symbol prefix)
#: and their files, so ASCII letters, digits and underscores, at most VEHICLE_NAME_MAX characters
#: (the longest FMU name, SideslipFixedOrderEstimatorScheduled_V.design.json and its temporaries,
#: then stays far below a file system's 255 bytes and Windows's 260-character paths)
VEHICLE_NAME = re.compile(r"[A-Za-z0-9_]+\Z")
VEHICLE_NAME_MAX = 64


def vehicle_name_problem(name: str) -> str | None:
    """Why ``name`` cannot be a vehicle's name (see :data:`VEHICLE_NAME`), or None."""
    if not VEHICLE_NAME.match(name):
        return (f"vehicle name {name!r} cannot name an FMU (FMU names NAME_VEHICLE are FMI modelIdentifiers: "
                "ASCII letters, digits and underscores only)")
    if len(name) > VEHICLE_NAME_MAX:
        return (f"vehicle name {name[:20]!r}... has {len(name)} characters, at most {VEHICLE_NAME_MAX} (it names "
                "FMUs and their files)")
    return None


@dataclass(frozen=True)
class Parameter:
    name: str
    value: float
    unit: str
    description: str = ""
    source: str = ""
    sign: str = "positive"


@dataclass(frozen=True)
class Range:
    name: str
    min: float
    max: float
    unit: str
    description: str = ""


@dataclass(frozen=True)
class Vehicle:
    """A validated vehicle parameter set. Attribute access returns the value in SI units."""

    name: str
    kind: str
    description: str
    source: str
    parameters: Mapping[str, Parameter]
    ranges: Mapping[str, Range] = field(default_factory=dict)

    def __getattr__(self, item: str) -> float:
        params = object.__getattribute__(self, "parameters")
        if item in params:
            return params[item].value
        raise AttributeError(f"vehicle {self.name!r} has no parameter {item!r}")

    def value(self, name: str) -> float:
        return self.require([name], f"parameter {name}")[name]

    def require(self, names: Iterable[str], needed_by: str) -> dict[str, float]:
        """Return the named values, or raise naming every missing one and who needs them."""
        names = list(names)
        missing = [n for n in names if n not in self.parameters]
        if missing:
            raise VehicleParameterError(
                f"vehicle {self.name!r} lacks parameter(s) {', '.join(missing)} needed by "
                f"{needed_by}; it defines {', '.join(sorted(self.parameters))}"
            )
        return {n: self.parameters[n].value for n in names}

    def speed_range(self) -> tuple[float, float] | None:
        """The ``speed`` range in m/s (converted from km/h), or None if the set has none; another
        unit raises naming it."""
        rng = self.ranges.get("speed")
        if rng is None:
            return None
        per = {"m/s": 1.0, "km/h": 1.0 / 3.6}
        if rng.unit not in per:
            raise VehicleParameterError(f"vehicle {self.name!r}: range 'speed' must be in m/s or km/h, got {rng.unit!r}")
        return rng.min * per[rng.unit], rng.max * per[rng.unit]

    def with_values(self, **values: float) -> "Vehicle":
        """A copy with some values replaced (validated like a loaded file)."""
        params = dict(self.parameters)
        for k, v in values.items():
            if k not in params:
                raise VehicleParameterError(f"vehicle {self.name!r} has no parameter {k!r} to replace")
            old = params[k]
            _check_value(self.name, k, v, old.sign)
            params[k] = Parameter(k, float(v), old.unit, old.description, "overridden", old.sign)
        return Vehicle(self.name, self.kind, self.description, self.source, params, self.ranges)

    def as_dict(self) -> dict:
        """Every parameter with its unit, for design files and reports."""
        out = {
            "name": self.name,
            "kind": self.kind,
            "description": self.description,
            "source": self.source,
            "parameters": {k: {"value": p.value, "unit": p.unit, "description": p.description,
                               **({"source": p.source} if p.source else {}),
                               **({"sign": p.sign} if p.sign != "positive" else {})}
                           for k, p in self.parameters.items()},
        }
        if self.ranges:
            out["ranges"] = {k: {"min": r.min, "max": r.max, "unit": r.unit, "description": r.description}
                             for k, r in self.ranges.items()}
        return out


def _check_value(vehicle: str, name: str, value, sign: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise VehicleParameterError(f"vehicle {vehicle!r}: parameter {name!r} must be a number, got {value!r}")
    value = float(value)
    if not math.isfinite(value):
        raise VehicleParameterError(f"vehicle {vehicle!r}: parameter {name!r} is not finite ({value})")
    if sign == "positive" and not value > 0:
        raise VehicleParameterError(f"vehicle {vehicle!r}: parameter {name!r} must be > 0, got {value}")
    if sign == "negative" and not value < 0:
        raise VehicleParameterError(f"vehicle {vehicle!r}: parameter {name!r} must be < 0, got {value}")
    if sign not in ("positive", "negative", "any"):
        raise VehicleParameterError(f"vehicle {vehicle!r}: parameter {name!r} has unknown sign rule {sign!r}")
    return value


def parse_vehicle(data: Mapping, origin: str) -> Vehicle:
    """Validate the content of one vehicle TOML file (``origin`` names it in errors)."""
    for key in ("name", "kind", "parameters"):
        if key not in data:
            raise VehicleParameterError(f"{origin}: missing top-level key {key!r}")
    name = str(data["name"])
    problem = vehicle_name_problem(name)
    if problem:
        raise VehicleParameterError(f"{origin}: {problem}")
    params: dict[str, Parameter] = {}
    for pname, entry in data["parameters"].items():
        if not isinstance(entry, Mapping) or "value" not in entry or "unit" not in entry:
            raise VehicleParameterError(f"vehicle {name!r}: parameter {pname!r} needs a value and a unit")
        sign = entry.get("sign", "positive")
        value = _check_value(name, pname, entry["value"], sign)
        params[pname] = Parameter(pname, value, str(entry["unit"]), str(entry.get("description", "")),
                                  str(entry.get("source", "")), sign)
    ranges: dict[str, Range] = {}
    for rname, entry in data.get("ranges", {}).items():
        lo = _check_value(name, f"{rname}.min", entry.get("min"), "positive")
        hi = _check_value(name, f"{rname}.max", entry.get("max"), "positive")
        if lo > hi:
            raise VehicleParameterError(f"vehicle {name!r}: range {rname!r} has min {lo} > max {hi}")
        ranges[rname] = Range(rname, lo, hi, str(entry.get("unit", "")), str(entry.get("description", "")))
    return Vehicle(name, str(data["kind"]), str(data.get("description", "")), str(data.get("source", "")),
                   params, ranges)


def vehicle_names() -> list[str]:
    folder = resources.files(__package__) / "vehicles"
    return sorted(p.name[:-5] for p in folder.iterdir() if p.name.endswith(".toml"))


def load_vehicle(name_or_path: str | Path) -> Vehicle:
    """Load a shipped set by name (``sedan``...) or any TOML file by path (a file named as a shipped
    set, ``name = "sedan"``, must hold that set: otherwise VehicleParameterError, rename it)."""
    path = Path(name_or_path)
    if path.suffix == ".toml" and path.exists():
        vehicle = _parsed(path.read_text(), str(path))
        if vehicle.name in vehicle_names() and vehicle != load_vehicle(vehicle.name):
            # its FMUs would take the shipped car's names (NAME.fmu, NAME_V.fmu) and their cache
            raise VehicleParameterError(
                f"{path}: named {vehicle.name!r} like the shipped vehicle, but its content differs from it: give it "
                f"a name of its own (name = \"my_{vehicle.name}\"), so that its FMUs are not named as the shipped "
                f"car's (a file identical to the shipped {vehicle.name}.toml is that vehicle and keeps its name)")
        return vehicle
    names = vehicle_names()
    if str(name_or_path) not in names:
        raise VehicleParameterError(f"unknown vehicle {str(name_or_path)!r}; known: {', '.join(names)}")
    res = resources.files(__package__) / "vehicles" / f"{name_or_path}.toml"
    return _parsed(res.read_text(), f"vehicles/{name_or_path}.toml")


@functools.lru_cache(maxsize=64)
def _parsed(text: str, origin: str) -> Vehicle:
    """The Vehicle of a TOML text, parsed once per text and origin (a campaign's runs load the same
    set thousands of times); the Vehicle is frozen and nothing changes its parameters."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise VehicleParameterError(f"{origin}: not valid TOML: {exc}") from exc
    return parse_vehicle(data, origin)


def axle_stiffness_ranges(vehicle: Vehicle) -> tuple[tuple[float, float], tuple[float, float]]:
    """((Cf min, max), (Cr min, max)), N/rad per axle, of a vehicle: its per-tyre ranges
    ``cf_tyre``, ``cr_tyre`` (N/deg, two tyres per axle; paper 002's delibasi) or else its
    ``[ranges]`` ``Cf``, ``Cr`` (N/rad). VehicleParameterError when it has neither."""
    if "cf_tyre" in vehicle.ranges and "cr_tyre" in vehicle.ranges:
        rf, rr = vehicle.ranges["cf_tyre"], vehicle.ranges["cr_tyre"]
        if not rf.unit == rr.unit == "N/deg":
            raise VehicleParameterError(f"vehicle {vehicle.name!r}: ranges 'cf_tyre', 'cr_tyre' must be in N/deg, "
                                        f"got {rf.unit!r}, {rr.unit!r}")
        k = 2.0 * 180.0 / math.pi
        return (k * rf.min, k * rf.max), (k * rr.min, k * rr.max)
    out = []
    for key in ("Cf", "Cr"):
        rg = vehicle.ranges.get(key)
        if rg is None or rg.unit != "N/rad":
            raise VehicleParameterError(f"vehicle {vehicle.name!r} has no range {key!r} in N/rad (nor the "
                                        f"per-tyre ranges cf_tyre, cr_tyre in N/deg)")
        out.append((rg.min, rg.max))
    return out[0], out[1]
