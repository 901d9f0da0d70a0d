"""Catalogue of the observer designs: name -> paper, default vehicle, design options.

``run(name, vehicle)`` is the design-time pipeline of one observer: parameters -> design model
-> LMI design -> independent certificate -> design dict (written by ``design_file.write``).
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Callable

from .params import Vehicle, load_vehicle

# The design and certificate modules (cvxpy, scipy) are imported where they are used, so that
# reading the catalogue (``latobs list``, ``latobs validate``) does not load the solver stack.


class CertificateError(RuntimeError):
    """A design solved but failed its independent certificate; it must not be packaged."""


@dataclass(frozen=True)
class DesignEntry:
    name: str
    paper: str
    default_vehicle: str
    description: str
    options: Callable[[str], object]       # artefact name -> options of the paper's design
    solve: Callable[[Vehicle, object], dict]


def _solve_000(vehicle: Vehicle, opts) -> dict:
    from . import pi_hinf_000

    return pi_hinf_000.to_design_dict(pi_hinf_000.design(vehicle, opts))


def _solve_001(vehicle: Vehicle, opts) -> dict:
    from . import interval_001

    return interval_001.to_design_dict(interval_001.design(vehicle, opts))


def _options_001(name: str):
    from . import interval_001

    return interval_001.DesignOptions(name=name)


def _options_000(switching: str):
    def options(name: str):
        from . import pi_hinf_000

        return pi_hinf_000.DesignOptions(name=name, switching=switching)
    return options


DESIGNS: dict[str, DesignEntry] = {
    "SideslipBankObserver": DesignEntry(
        "SideslipBankObserver", "000", "sedan",
        "switched H-inf PI observer, sideslip + road bank angle, speed modes 36/63/90 km/h (eq. 25)",
        _options_000("speed"), _solve_000),
    "SideslipBankObserverTire": DesignEntry(
        "SideslipBankObserverTire", "000", "sedan",
        "switched H-inf PI observer, sideslip + road bank angle, tire modes C1 / C2 (secant of the tire curve) at alpha* = 0.5 deg (eq. 27)",
        _options_000("tire"), _solve_000),
    "LateralIntervalObserver": DesignEntry(
        "LateralIntervalObserver", "001", "sedan",
        "switched interval observer: guaranteed bounds of lateral velocity, sideslip, yaw rate and axle "
        "forces for cornering stiffnesses in a +-20 % box, speed modes 11.5/14.5/18 m/s (Theorem 1)",
        _options_001, _solve_001),
}


def get(name: str) -> DesignEntry:
    if name not in DESIGNS:
        raise KeyError(f"unknown design {name!r}; known: {', '.join(DESIGNS)}")
    return DESIGNS[name]


def artefact_name(name: str, vehicle: str | None) -> str:
    """CONTRACT: a build for a vehicle other than the design's default is named NAME_V."""
    entry = get(name)
    return name if vehicle in (None, entry.default_vehicle) else f"{name}_{vehicle}"


def run(name: str, vehicle: str | None = None, **overrides) -> dict:
    """Design and certify; returns the design dict with ``certified`` and ``checks``.

    Raises ``pi_hinf_000.DesignError`` when the LMIs are infeasible and ``CertificateError``
    (carrying the failed checks) when the certificate fails.
    """
    from . import certificate

    entry = get(name)
    veh = load_vehicle(vehicle or entry.default_vehicle)
    opts = replace(entry.options(artefact_name(name, veh.name)), **overrides)
    data = entry.solve(veh, opts)
    data["design"] = name          # the catalogue entry (the FMU model), whatever the artefact name
    ok, checks = certificate.certify(data)
    data["certified"] = ok
    data["checks"] = certificate.as_dicts(checks)
    if not ok:
        failed = [c for c in checks if not c.passed]
        raise CertificateError(
            f"design {data['name']} failed its certificate ({len(failed)} of {len(checks)} checks): "
            + "; ".join(f"{c.name}: {c.value:.6g} > {c.limit:.6g}" for c in failed[:5]))
    return data
