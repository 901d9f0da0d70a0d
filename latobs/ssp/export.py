"""``latobs export-ssp``: a validation scenario as an SSP 1.0 package, written after it is checked.

The package is the co-simulation that ``latobs validate SCENARIO`` runs (:mod:`latobs.ssp.ssd`
lists its files), wired as the harness wires it (:func:`latobs.ssp.interface.wiring`).

Timing. The harness steps every FMU from t_k with the plant's inputs u(t_k) and the observers'
inputs the plant outputs at t_k (a Jacobi scheme: the observer output at t_(k+1) depends on the
bus at t_k). libcosim's fixed-step algorithm is also Jacobi (every FMU steps, then outputs are
copied to inputs), and the signal source outputs after the step from t_k the sample of t_(k+1), so
the plant steps from t_k with u(t_k) and each observer with the plant outputs at t_k: the same
ordering, step for step. Two differences remain. libcosim steps by the difference of two double
time points (round-off). It also initialises the observers with the plant outputs of
initialisation mode, the FMUs' start values (latobs FMUs compute their outputs at
exitInitializationMode), where the harness uses the plant outputs after initialisation: the same
when the plant starts at rest, as in every shipped scenario. fmpy's ``simulate_ssp`` is Jacobi as
well but starts every connection at 0.0 (see :func:`latobs.ssp.run.simulate_fmpy`).

This package is on the validation side: it reads the built FMUs (fmpy), never their Python.
"""
from __future__ import annotations

import os
import tempfile
from pathlib import Path
from typing import Any, Mapping

from ..atomic import atomic_path
from .check import check_package
from .interface import (DEFAULT_DT, PLANT_LABEL, SOURCE_LABEL, SOURCE_MODEL, SSD_NAME, TIMING, FmuInterface, SspError,
                        _typed, scenario_signals, wiring)
from .source import build_source_fmu, native_platforms
from .ssd import Component, ssd_bytes, ssv_bytes


def default_observers(scenario) -> list[str]:
    """The observers ``latobs validate`` runs by default (as :func:`latobs.pipeline.run_validation`)."""
    from .. import catalogue

    return catalogue.default_observers(scenario.plant)


def _check_out(out: Path) -> None:
    """Fail before any work if ``out`` cannot be written: it is a folder, or its nearest existing
    ancestor is not a writable folder. Nothing is written here (a probe file in the nearest existing
    ancestor was written outside --out: in / for ``--out /missing/x.ssp``)."""
    if out.is_dir():
        raise SspError(f"--out {out}: is a folder; give the .ssp file to write")
    anc = out.absolute().parent
    while not anc.exists() and anc != anc.parent:
        anc = anc.parent
    if not anc.is_dir():
        raise SspError(f"--out {out}: {anc} is a file, not a folder")
    if not os.access(anc, os.W_OK | os.X_OK):
        raise SspError(f"--out {out}: cannot write in {anc}")


def _write_package(out: Path, files: Mapping[str, bytes]) -> None:
    """The package of ``files`` written to ``out`` atomically after :func:`check_package` passed.
    The missing folders of ``out``'s parent are made (as asked) and removed again when the
    package is not written: a failed export leaves nothing, a missing --out folder never makes
    one elsewhere."""
    from .. import packaging

    made = [p for p in (out.absolute().parent, *out.absolute().parent.parents) if not p.exists()]
    try:
        with atomic_path(out, suffix=".ssp") as tmp_ssp:
            packaging.write_zip(tmp_ssp, files, stored=(".fmu",))
            problems = check_package(tmp_ssp)
            if problems:
                raise SspError(f"the package would not be valid SSP 1.0, nothing written: {'; '.join(problems)}")
    except OSError as exc:
        _remove_empty(made)
        raise SspError(f"--out {out}: cannot write ({exc.strerror or exc})") from None
    except BaseException:
        _remove_empty(made)
        raise


def _remove_empty(folders: list[Path]) -> None:
    for p in folders:                   # deepest first
        try:
            p.rmdir()
        except OSError:
            break


def export_ssp(scenario, observers: list[str] | None = None, out: Path | None = None,
               fmu_dir: Path = Path("build"), plant_parameters: Mapping[str, Any] | None = None,
               plant_vehicle: str | None = None, dt: float = DEFAULT_DT, quiet: bool = False) -> Path:
    """Write the SSP 1.0 package of ``latobs validate SCENARIO`` (same defaults: the default
    observers, FMUs built into ``fmu_dir`` if missing, the plant's default vehicle) to ``out``
    (default ``build/SCENARIO.ssp``), atomically, after :func:`check_package` passed.
    ``scenario`` is a registered name or a :class:`~latobs.validation.scenarios.Scenario` (e.g.
    ``get_scenario("bank-braking", duration=3.0)``). Returns the path written."""
    from .. import packaging
    from ..pipeline import ensure_fmus, ensure_plant
    from ..synthesis import designs
    from ..validation import get_scenario

    sc = get_scenario(scenario)                       # unknown: UnknownScenarioError (a KeyError)
    fmu_dir = Path(fmu_dir)
    observers = list(observers or default_observers(sc))
    for n in observers:
        if n in (PLANT_LABEL, SOURCE_LABEL):
            raise SspError(f"observer name {n!r} is reserved for a component of the system")
        if not (fmu_dir / f"{n}.fmu").is_file():
            try:
                designs.parse_artefact(n)
            except KeyError as exc:
                raise SspError(f"--observer {n}: {exc.args[0] if exc.args else exc}") from None
    if len(set(observers)) != len(observers):
        raise SspError(f"--observer: each observer once, got {', '.join(observers)}")
    kind = packaging.PLANTS.get(sc.plant)
    if kind is None:
        raise SspError(f"scenario {sc.name!r} drives plant {sc.plant!r}, which latobs does not build")
    plant_vehicle = plant_vehicle or kind.default_vehicle
    vehicle_name = plant_vehicle
    if str(plant_vehicle).endswith(".toml"):     # a TOML file: its FMU is named after the set's `name`
        from ..synthesis.params import load_vehicle

        vehicle_name = load_vehicle(plant_vehicle).name
    out = Path(out) if out is not None else Path("build") / f"{sc.name}.ssp"
    if out.suffix.lower() != ".ssp":
        raise SspError(f"--out {out}: an SSP package is a .ssp file")
    _check_out(out)
    if not dt > 0:
        raise SspError(f"step {dt} s must be > 0")

    fmus = ensure_fmus(observers, fmu_dir)
    plant_path = ensure_plant(sc.plant, plant_vehicle, fmu_dir)     # reused if current, else built
    plant = FmuInterface.read(plant_path, PLANT_LABEL)
    obs = {n: FmuInterface.read(fmus[n], n) for n in observers}

    params = dict(plant_parameters or {})
    known = {p.name: p for p in plant.parameters}
    for k, value in params.items():
        if k not in known:
            raise SspError(f"--plant-param {k}: {plant.model_name} has no parameter {k!r}; its parameters: "
                           f"{', '.join(known) or '(none)'}")
        lo, hi = known[k].min, known[k].max
        if (lo is not None and value < lo) or (hi is not None and value > hi):
            raise SspError(f"--plant-param {k}={value:g}: outside {plant.model_name}'s declared range "
                           f"[{'-inf' if lo is None else f'{lo:g}'}, {'inf' if hi is None else f'{hi:g}'}]")
    t = sc.time_grid(dt)
    try:
        signals = scenario_signals(sc, t, plant_vehicle)
    except (ValueError, KeyError) as exc:
        raise SspError(f"scenario {sc.name!r} for vehicle {plant_vehicle!r}: {exc}") from exc
    conns = wiring(sc, signals, plant, obs)

    units = {v.name: v.unit for v in plant.inputs}
    with tempfile.TemporaryDirectory(prefix="latobs_ssp_") as tmp:
        # the signal source runs where the plant runs
        source = build_source_fmu(sc.name, t, signals, units, Path(tmp), native_platforms(plant_path) or None)
        src_fmu = FmuInterface.read(source, SOURCE_LABEL)
        files: dict[str, bytes] = {f"resources/{SOURCE_MODEL}.fmu": source.read_bytes()}
        components = [Component(SOURCE_LABEL, f"resources/{SOURCE_MODEL}.fmu", src_fmu, [])]
        driven = [c.end_connector for c in conns if c.end_element == PLANT_LABEL]
        start = plant.start_values()
        start.update({k: _typed(known[k].type, v) for k, v in params.items()})
        entries = [(PLANT_LABEL, plant_path, plant, driven, start)]
        entries += [(n, fmus[n], obs[n], [v.name for v in obs[n].inputs], obs[n].start_values()) for n in observers]
        for label, path, f, inputs, values in entries:
            src = f"resources/{path.name}"
            if src in files:
                raise SspError(f"two components would share {src}")
            files[src] = path.read_bytes()
            ssv = None
            if f.parameters:
                ssv = f"resources/{label}.ssv"
                files[ssv] = ssv_bytes(label, [(p, values[p.name]) for p in f.parameters], f.units)
            components.append(Component(label, src, f, inputs, ssv))
        info = {"scenario": sc.name, "vehicle": str(vehicle_name), "step": repr(float(dt)),
                "plantParameters": ", ".join(f"{k}={v!r}" for k, v in params.items()) or "nominal",
                "timing": TIMING}
        desc = (f"latobs validate {sc.name}: {plant.model_name} ({vehicle_name}) beside "
                f"{', '.join(observers) or 'no observer'}; {sc.description}")
        files[SSD_NAME] = ssd_bytes(sc.name, desc, components, conns, float(t[0]), float(t[-1]), dt, info)
        _write_package(out, files)
    if not quiet:
        print(f"wrote {out}: {len(components)} components ({SOURCE_LABEL}, {PLANT_LABEL}: {plant_path.name}, "
              f"{', '.join(observers)}), {len(conns)} connections, step {dt:g} s, stop {float(t[-1]):g} s; "
              "SSP 1.0 schema-valid")
    return out
