"""The observer designs (derived from ``latobs.catalogue``): name -> paper, default vehicle, design options.

``run(name, vehicle)`` is the design-time pipeline of one observer: parameters -> design model
-> LMI design -> independent certificate -> design dict (written by ``design_file.write``).
"""
from __future__ import annotations

import re
from dataclasses import dataclass, replace
from typing import Callable

from .. import catalogue
from .params import Vehicle, load_vehicle

# The design and certificate modules (cvxpy, scipy) are imported where they are used, so that
# reading the catalogue (``latobs list``, ``latobs validate``) does not load the solver stack.


class CertificateError(RuntimeError):
    """A design solved but failed its independent certificate; it must not be packaged."""


class ArtefactNameError(ValueError):
    """A name that cannot name an FMU (and its files): not an FMI modelIdentifier."""


#: an FMI modelIdentifier (and so an FMU's file name): ASCII letters, digits and underscores, not
#: starting with a digit. A vehicle's name is appended to a model's after "_" (``NAME_V``).
MODEL_IDENTIFIER = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")


def check_vehicle_name(vehicle: str, origin: str = "") -> str:
    """``vehicle`` (a parameter set's ``name``) if it can name an FMU (the rule vehicle files are
    loaded by: ``params.vehicle_name_problem``), else ArtefactNameError."""
    from .params import vehicle_name_problem

    problem = vehicle_name_problem(vehicle)
    if problem:
        raise ArtefactNameError(f"{origin + ': ' if origin else ''}{problem}")
    return vehicle


def fmu_name(model: str, vehicle: str | None, default_vehicle: str) -> str:
    """The FMU (artefact) name of ``model`` for the vehicle named ``vehicle``: ``model`` for its
    default vehicle (or None), else ``model_vehicle``; ArtefactNameError if that is not an FMI
    modelIdentifier (so no name ever reaches a file name outside its folder)."""
    if not MODEL_IDENTIFIER.match(model):
        raise ArtefactNameError(f"model name {model!r} is not an FMI modelIdentifier (ASCII letters, digits and "
                                "underscores, not starting with a digit)")
    if vehicle in (None, default_vehicle):
        return model
    return f"{model}_{check_vehicle_name(vehicle)}"


@dataclass(frozen=True)
class DesignEntry:
    name: str
    paper: str
    default_vehicle: str
    description: str
    options: Callable[[str], object]       # artefact name -> options of the paper's design
    solve: Callable[[Vehicle, object], dict]
    plant: str = "CarPlant"                # the plant FMU it is validated beside


def _entry(e) -> DesignEntry:
    """The design registry's entry of a catalogue entry (its modules imported when used)."""
    def options(name: str):
        return catalogue.resolve(e.options)(name=name, **dict(e.option_args))

    def solve(vehicle: Vehicle, opts) -> dict:
        result = catalogue.resolve(e.design)(vehicle, opts)
        return catalogue.resolve(e.to_dict)(result) if e.to_dict else result

    return DesignEntry(e.name, e.paper, e.default_vehicle, e.description, options, solve, e.plant)


#: the observers of the catalogue (``latobs.catalogue``)
DESIGNS: dict[str, DesignEntry] = {name: _entry(catalogue.get(name)) for name in catalogue.OBSERVERS}


def get(name: str) -> DesignEntry:
    if name not in DESIGNS:
        raise KeyError(f"unknown design {name!r}; known: {', '.join(DESIGNS)}")
    return DESIGNS[name]


def artefact_name(name: str, vehicle: str | None) -> str:
    """A build for a vehicle other than the design's default is named NAME_V."""
    return fmu_name(name, vehicle, get(name).default_vehicle)


def parse_artefact(artefact: str) -> tuple[str, str | None]:
    """(design, vehicle) of an artefact name ``NAME`` or ``NAME_V`` (V a known vehicle set);
    the longest design name that fits wins. Unknown -> KeyError naming the known designs."""
    from .params import vehicle_names

    if artefact in DESIGNS:
        return artefact, None
    for name in sorted(DESIGNS, key=len, reverse=True):
        if artefact.startswith(name + "_") and artefact[len(name) + 1:] in vehicle_names():
            return name, artefact[len(name) + 1:]
    raise KeyError(f"unknown design {artefact!r}; known: {', '.join(DESIGNS)} (optionally _VEHICLE)")


def run(name: str, vehicle: str | None = None, **overrides) -> dict:
    """Design and certify; returns the design dict with ``certified`` and ``checks``.

    Raises ``sideslip_bank_observer.DesignError`` when the LMIs are infeasible and ``CertificateError``
    (carrying the failed checks) when the certificate fails.
    """
    from .identity import of_design
    from . import certificate, tables

    entry = get(name)
    veh = load_vehicle(vehicle or entry.default_vehicle)
    ident = of_design(name, veh, overrides)   # what it is made from; checks the artefact name first
    opts = replace(entry.options(artefact_name(name, veh.name)), **overrides)
    data = entry.solve(veh, opts)
    data["design"] = name          # the catalogue entry (the FMU model), whatever the artefact name
    data["identity"] = ident.as_dict()
    tables.attach(data)            # what the runtimes evaluate, computed once here (certified below)
    ok, checks = certificate.certify(data)
    data["certified"] = ok
    data["checks"] = certificate.as_dicts(checks)
    if not ok:
        failed = [c for c in checks if not c.passed]
        raise CertificateError(
            f"design {data['name']} failed its certificate ({len(failed)} of {len(checks)} checks): "
            + "; ".join(f"{c.name}: {c.value:.6g} > {c.limit:.6g}" for c in failed[:5]))
    return data


@dataclass(frozen=True)
class Outcome:
    """What ``attempt`` found for one design and vehicle: ``status`` "certified"; "n/a" (the
    vehicle lacks a parameter or range the design needs, ``detail`` names it); "infeasible" (the
    design's LMIs have no solution, ``detail`` names the LMI); or "refused" (solved, but the
    certificate fails, ``detail`` names the failing checks). ``seconds``: design + certificate."""

    design: str
    vehicle: str
    status: str
    detail: str
    seconds: float
    data: dict | None = None


def design_errors() -> tuple[type, ...]:
    """The DesignError class of every paper's design module (LMIs infeasible, solver failure)."""
    modules = dict.fromkeys(catalogue.get(n).design.partition(":")[0] for n in catalogue.OBSERVERS)
    return tuple(catalogue.resolve(m).DesignError for m in modules)


def attempt(name: str, vehicle: str, *, runner=run, **overrides) -> Outcome:
    """``run`` with its user-facing failures as an :class:`Outcome` (a bug still raises).
    ``runner``: what designs (``run``'s signature): e.g. ``run`` through a cache."""
    import time

    from .params import VehicleParameterError

    t0 = time.perf_counter()
    try:
        data = runner(name, vehicle, **overrides)
        status, detail = "certified", ""
    except VehicleParameterError as exc:
        data, status, detail = None, "n/a", str(exc)
    except CertificateError as exc:
        data, status, detail = None, "refused", str(exc)
    except design_errors() as exc:
        data, status, detail = None, "infeasible", str(exc)
    return Outcome(name, vehicle, status, detail, time.perf_counter() - t0, data)
