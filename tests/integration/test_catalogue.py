"""The catalogue (``latobs.catalogue``) is the one list of FMUs: every registry is derived from it,
every dotted name in it resolves to what the entry says, and each entry's model file declares
what its runtime, emitter, plant and reference experiment use."""
from __future__ import annotations

import ast
import inspect
import re
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from latobs import catalogue

ENTRIES = {e.name: e for e in catalogue.ENTRIES}
DOTTED_FIELDS = ("citation", "options", "design", "to_dict", "certificate", "data", "model", "runtime", "emitter")


def test_names_are_unique_fmi_model_identifiers():
    from latobs.synthesis.designs import MODEL_IDENTIFIER

    assert len(ENTRIES) == len(catalogue.ENTRIES)
    for e in catalogue.ENTRIES:
        assert MODEL_IDENTIFIER.match(e.name) and re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", e.name), e.name
        assert e.kind in ("observer", "plant"), e.name
    assert catalogue.OBSERVERS + catalogue.PLANTS == tuple(ENTRIES)
    with pytest.raises(KeyError, match="NoSuchObserver.*SideslipBankObserver"):
        catalogue.get("NoSuchObserver")


def test_the_catalogue_imports_only_the_standard_library():
    """Every layer reads it: it must not pull in numpy, the solver stack, fmpy or another latobs module."""
    tree = ast.parse(Path(catalogue.__file__).read_text(encoding="utf-8"))
    imported = {a.name.split(".")[0] for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
    imported |= {n.module.split(".")[0] for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.module}
    assert imported <= set(sys.stdlib_module_names) | {"__future__"}, imported
    assert not any(isinstance(n, ast.ImportFrom) and n.level for n in ast.walk(tree))
    code = ("import sys, latobs.catalogue; heavy = [m for m in ('numpy', 'cvxpy', 'fmpy', 'scipy') if m in sys.modules]; "
            "mods = [m for m in sys.modules if m.startswith('latobs.') and m != 'latobs.catalogue']; "
            "print(heavy, mods)")
    out = subprocess.run([sys.executable, "-P", "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[] []", out


def test_every_module_string_is_in_one_place():
    """The dotted names of the entries are built from ``MODULES`` (a rename is a one-line edit there)."""
    prefixes = tuple(catalogue.MODULES.values())
    for e in catalogue.ENTRIES:
        for f in DOTTED_FIELDS:
            value = getattr(e, f)
            if value is not None:
                module = value.partition(":")[0]
                assert module in prefixes or module.rsplit(".", 1)[0] in prefixes, (e.name, f, value)
    for key, module in catalogue.MODULES.items():
        catalogue.resolve(module)                                          # every module imports


@pytest.mark.parametrize("name", list(ENTRIES))
def test_every_dotted_name_resolves(name):
    e = ENTRIES[name]
    for f in DOTTED_FIELDS:
        value = getattr(e, f)
        if value is not None:
            obj = catalogue.resolve(value)
            assert obj is not None, (name, f)
            if ":" in value:
                assert callable(obj) or f == "citation", (name, f, value)
    with pytest.raises((ImportError, AttributeError)):
        catalogue.resolve(e.model + ":NoSuchAttribute")


@pytest.mark.parametrize("name", list(ENTRIES))
def test_each_entry_matches_its_model_file_runtime_and_emitter(name):
    from latobs import cbackend
    from latobs.fmu_src.spec import ModelSpec

    e = ENTRIES[name]
    spec = catalogue.resolve(e.model).SPEC
    assert isinstance(spec, ModelSpec)
    assert spec.runtime is catalogue.resolve(e.runtime), name
    assert spec.paper == (catalogue.resolve(e.citation) if e.citation else None), name
    assert spec.inputs and spec.outputs, name
    outputs = {v.name for v in (*spec.outputs, *spec.integer_outputs)}
    # each quantity scored against another bus signal is estimated (X_hat, or an interval X_lower/X_upper),
    # and that signal is an output of its plant
    for quantity, signal in e.truth:
        assert f"{quantity}_hat" in outputs or {f"{quantity}_lower", f"{quantity}_upper"} <= outputs, (name, quantity)
        plant_spec = catalogue.resolve(catalogue.get(e.plant).model).SPEC
        assert signal in {v.name for v in plant_spec.outputs}, (name, signal)
    # its C model: the emitter writes the data of exactly this C file, which exists
    emitter = catalogue.resolve(e.emitter)
    assert emitter is cbackend.emitter(e.model_module), name
    assert emitter.SOURCE == e.c_model and (cbackend.C_SRC / e.c_model).is_file(), name


@pytest.mark.parametrize("name", list(ENTRIES))
def test_each_entry_names_a_consistent_design_plant_scenario_and_campaign(name):
    from latobs.campaign_runner import shipped
    from latobs.synthesis.params import load_vehicle
    from latobs.validation.scenarios import SCENARIOS

    e = ENTRIES[name]
    load_vehicle(e.default_vehicle)
    sc = SCENARIOS[e.reference.scenario]
    assert 0 < e.reference.seconds <= sc.duration
    for field_name, _ in e.reference.overrides:
        assert hasattr(sc, field_name), (name, field_name)
    spec = catalogue.resolve(e.model).SPEC
    if e.kind == "plant":
        assert e.plant is None and e.design is None and e.certificate is None and e.data, name
        assert sc.plant == name
        # its sensors' noise is on its signals (the bus); its steering input is an input
        assert e.noise and {s for s, _ in e.noise} <= {v.name for v in (*spec.inputs, *spec.outputs)}, name
        assert all(std > 0 and bias >= 0 for _, (std, bias) in e.noise), name
        assert e.steer in {v.name for v in spec.inputs}, name
        return
    assert not e.noise and e.steer is None, name
    plant = ENTRIES[e.plant]
    assert plant.kind == "plant" and sc.plant == e.plant, name
    # the observer reads only signals its plant puts out (or drives) in the reference experiment
    plant_spec = catalogue.resolve(plant.model).SPEC
    bus = {v.name for v in (*plant_spec.inputs, *plant_spec.outputs, *plant_spec.integer_outputs)}
    assert {v.name for v in spec.inputs} <= bus, name
    assert e.design and e.certificate and e.options and e.data is None, name
    options = catalogue.resolve(e.options)
    assert set(dict(e.option_args)) <= {f for f in inspect.signature(options).parameters}, name
    assert e.campaign in shipped() and shipped()[e.campaign].is_file(), name
    raw = tomllib.loads(shipped()[e.campaign].read_text(encoding="utf-8"))
    assert all(o.split("_")[0] in ENTRIES or o in ENTRIES or any(o.startswith(n + "_") for n in ENTRIES)
               for o in raw.get("observers", [])), raw.get("observers")


# -- the registries of the other layers are derived from the catalogue ------------------------------
def test_design_registry_is_the_catalogues_observers():
    from latobs.synthesis import designs

    assert list(designs.DESIGNS) == list(catalogue.OBSERVERS)
    for name, d in designs.DESIGNS.items():
        e = ENTRIES[name]
        assert (d.name, d.paper, d.default_vehicle, d.description, d.plant) == \
            (e.name, e.paper, e.default_vehicle, e.description, e.plant)
        opts = d.options(name)
        assert isinstance(opts, catalogue.resolve(e.options)) and opts.name == name
        for k, v in e.option_args:
            assert getattr(opts, k) == v, (name, k)


def test_packaging_registries_are_the_catalogues():
    from latobs import packaging

    assert list(packaging.OBSERVERS) == list(catalogue.OBSERVERS)
    assert list(packaging.PLANTS) == list(catalogue.PLANTS)
    for name, k in {**packaging.OBSERVERS, **packaging.PLANTS}.items():
        e = ENTRIES[name]
        assert k == packaging.FmuKind(name, e.model_module, "design" if e.kind == "observer" else "plant",
                                      e.default_vehicle)


def test_emitter_registry_is_the_catalogues():
    from latobs import cbackend

    parts = {model: dotted.rsplit(".", 1)[-1] for model, dotted in catalogue.PART_EMITTERS.items()}
    assert cbackend.EMITTERS == {**{e.model_module: e.emitter_module for e in catalogue.ENTRIES}, **parts}
    for dotted in catalogue.PART_EMITTERS.values():
        catalogue.resolve(dotted)                               # a part's emitter exists
    models = {p.stem for p in Path(catalogue.resolve(catalogue.MODULES["models"]).__file__).parent.glob("*.py")}
    assert models - {"__init__"} == set(cbackend.EMITTERS)     # no model file outside the catalogue


def test_reference_experiments_and_validation_defaults_are_the_catalogues():
    from latobs import pipeline
    from latobs.validation import metrics

    assert list(pipeline.REFERENCE_EXPERIMENTS) == list(ENTRIES)
    for name, spec in pipeline.REFERENCE_EXPERIMENTS.items():
        r = ENTRIES[name].reference
        assert (spec.scenario, spec.seconds, spec.overrides, spec.note) == (r.scenario, r.seconds, r.overrides, r.note)
    assert catalogue.default_observers("CarPlant") == ["SideslipBankObserver", "SideslipBankObserverTire",
                                                       "SideslipBankObserverPaper", "SideslipBankObserverTirePaper"]
    assert catalogue.default_observers("MotorcyclePlant") == ["MotorcycleFaultObserver", "MotorcycleFaultObserverPaper"]
    assert metrics.REFERENCE_SIGNALS == {e.name: dict(e.truth) for e in catalogue.ENTRIES if e.truth}
    assert pipeline.PLANT_NOISE == {n: dict(ENTRIES[n].noise) for n in catalogue.PLANTS}
    assert list(pipeline.PLANT_NOISE["CarPlant"]) == ["yaw_rate", "roll_angle", "roll_rate", "delta", "vx"]


def test_campaign_and_bench_registries_are_the_catalogues():
    from latobs import bench
    from latobs.validation import campaign

    assert campaign.STEER_SIGNAL == {"CarPlant": "delta", "MotorcyclePlant": "rider_torque"}
    assert bench.paper_000_observers() == tuple(catalogue.default_observers("CarPlant"))
    mbds, = [p for p in bench.pairings() if p.key == "mbds"]
    assert mbds.observers == ("SideslipFixedOrderEstimatorScheduled", "SideslipKalmanFilter")
    for p in bench.pairings():
        for o in p.observers:                        # every benchmarked FMU is a catalogue observer (or NAME_V)
            assert o in catalogue.OBSERVERS or any(o.startswith(n + "_") for n in catalogue.OBSERVERS), o
        assert p.plant in catalogue.PLANTS


def test_no_fmu_name_list_is_kept_by_hand_outside_the_catalogue():
    """A module that spells out two or more of the catalogue's FMU names in one literal list, tuple,
    set or dict keeps a registry by hand (pairings of artefacts for another vehicle excepted)."""
    root = Path(catalogue.__file__).resolve().parent
    names = set(ENTRIES)
    found = []
    for folder in (root, root.parent / "synthesis", root.parent / "fmu_src"):
        for path in folder.rglob("*.py"):
            if path.name == "catalogue.py":
                continue
            for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
                items = (node.keys if isinstance(node, ast.Dict) else
                         node.elts if isinstance(node, (ast.List, ast.Tuple, ast.Set)) else [])
                literal = [k.value for k in items if isinstance(k, ast.Constant) and k.value in names]
                if len(literal) >= 2:
                    found.append(f"{path.relative_to(root.parent)}:{node.lineno}: {literal}")
    assert not found, "\n".join(found)
