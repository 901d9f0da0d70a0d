"""Reference results inside every FMU (FMI-LS-REF) and ``latobs check``.

Every FMU of ``latobs build`` (both backends) carries its reference experiment: a well-formed
manifest, an experiments file, input and reference CSVs whose columns are the FMU's inputs and
outputs; ``latobs check`` reproduces it bit for bit on the host, and fails, naming the variable,
when a reference value is one ulp off or when the FMU computes with another gain."""
from __future__ import annotations

import copy
import io
import zipfile
from contextlib import redirect_stderr, redirect_stdout
from pathlib import Path
from xml.etree import ElementTree as ET

import numpy as np
import pytest
from fmpy import read_model_description

from latobs import packaging, pipeline, reference
from latobs.cbackend.toolchain import host_platform
from latobs.cli import main

from conftest import FMU_VARIANTS


def _cli(*argv) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with redirect_stdout(out), redirect_stderr(err):
        code = main(["check", *map(str, argv)])
    return code, out.getvalue(), err.getvalue()


def _members(fmu: Path) -> dict[str, bytes]:
    with zipfile.ZipFile(fmu) as z:
        return {n: z.read(n) for n in z.namelist()}


def _rewrite(fmu: Path, dest: Path, change) -> Path:
    """A copy of ``fmu`` at ``dest`` with its members {name: bytes} passed through ``change``."""
    packaging.write_zip(dest, change(_members(fmu)))
    return dest


@pytest.mark.parametrize("variant", FMU_VARIANTS)
def test_every_fmu_holds_a_well_formed_reference_experiment(variant, built_fmus):
    name, backend = variant
    fmu = built_fmus.get(name, backend)
    members = _members(fmu)
    man = ET.fromstring(members[reference.MANIFEST])
    ns = "{http://fmi-standard.org/fmi-ls-manifest}"
    assert man.tag == "fmiReferences" and man.get(f"{ns}fmi-ls-name") == "org.fmi-standard.fmi-ls-ref"
    assert man.get(f"{ns}fmi-ls-version") and man.get(f"{ns}fmi-ls-description")
    roles = {r.get("source"): r.get("role") for r in man.findall("Related")}
    for source in roles:                   # every related file is in the archive
        assert f"{reference.LS_DIR}/{source}" in members, source
    assert "experiment/validation" in roles.values() and "result" in roles.values()

    md = read_model_description(str(fmu))
    causality = {v.name: v.causality for v in md.modelVariables}
    typ = {v.name: v.type for v in md.modelVariables}
    experiments = reference.read(fmu)
    assert [e.name for e in experiments] == [pipeline.REFERENCE_EXPERIMENTS[name].scenario]
    for e in experiments:
        assert e.inputs and e.outputs
        assert all(causality.get(n) == "input" for n in e.inputs), e.inputs.keys()
        assert sorted(e.inputs) == sorted(n for n, c in causality.items() if c == "input" and n in e.inputs)
        assert sorted(e.outputs) == sorted(n for n, c in causality.items() if c == "output"), e.outputs.keys()
        assert e.step == float(md.defaultExperiment.stepSize)
        k = np.arange(len(e.time))
        assert np.all(np.diff(e.time) > 0) and np.array_equal(e.time, e.start + k * e.step)
        assert 100 <= len(e.time) <= 1001                  # a few hundred rows
        assert e.platform == host_platform()
        for n, v in e.outputs.items():
            assert np.all(np.isfinite(v)), n
            if typ[n] == "Integer":
                assert np.array_equal(v, np.round(v)), n
            assert e.absolute[n] == pytest.approx(e.relative * np.max(np.abs(v)), rel=1e-15, abs=0)
        assert e.relative == 1e-12


@pytest.mark.parametrize("variant", FMU_VARIANTS)
def test_latobs_check_passes_on_the_host(variant, built_fmus):
    name, backend = variant
    code, out, err = _cli(built_fmus.get(name, backend))
    assert code == 0, out + err
    assert out.startswith(f"PASS  {name}  ") and "bit for bit" in out, out


def test_the_reference_is_the_observers_own_validation_run(built_fmus):
    """The reference outputs of an observer are its outputs in the co-simulation of its own
    scenario beside its plant (the standalone run on the recorded inputs gives the same bits)."""
    from latobs.validation import get_scenario
    from latobs.validation.harness import run

    fmu = built_fmus.c_path("SideslipBankObserver")
    e, = reference.read(fmu)
    spec = pipeline.REFERENCE_EXPERIMENTS["SideslipBankObserver"]
    sc = get_scenario(spec.scenario, duration=spec.seconds, **dict(spec.overrides))
    res = run(sc, built_fmus.c_path("CarPlant"), {"obs": fmu}, dt=e.step, vehicle="sedan")
    assert np.array_equal(res.time, e.time)
    for n, v in e.inputs.items():
        assert np.array_equal(res.measured[n], v), n
    for n, v in e.outputs.items():
        assert np.array_equal(res.observers["obs"][n], v), n


def test_check_fails_on_a_reference_value_one_ulp_off(built_fmus, tmp_path):
    fmu = built_fmus.c_path("SideslipBankObserver")
    e, = reference.read(fmu)
    member = f"{reference.LS_DIR}/{e.name}_ref.csv"
    k = len(e.time) // 2
    value = e.outputs["beta_hat"][k]

    def change(files):
        lines = files[member].decode().splitlines()
        header = lines[0].split(",")
        row = lines[k + 1].split(",")
        j = header.index("beta_hat")
        assert float(row[j]) == value
        row[j] = repr(float(np.nextafter(value, np.inf)))
        lines[k + 1] = ",".join(row)
        files[member] = ("\n".join(lines) + "\n").encode()
        return files

    altered = _rewrite(fmu, tmp_path / fmu.name, change)
    code, out, err = _cli(altered)
    assert code == 1, out + err
    assert out.startswith("FAIL") and "beta_hat" in out and f"t = {e.time[k]:.6g} s" in out, out
    assert "bit for bit" in out                 # the rule that failed: the certifying platform's
    # within the tolerance of another platform, one ulp passes
    got = dict(e.outputs)
    got["beta_hat"] = got["beta_hat"].copy()
    got["beta_hat"][k] = np.nextafter(value, np.inf)
    assert not reference.compare(e, got, e.platform).passed
    assert reference.compare(e, got, "win64").passed


def test_check_fails_when_the_fmu_computes_with_another_gain(built_fmus, tmp_path):
    """The FMU of a design whose gain differs in the 9th digit, carrying the certified FMU's
    reference results: `latobs check` fails and names the output."""
    name = "SideslipFixedOrderEstimator"
    original = built_fmus.c_path(name)
    data = copy.deepcopy(built_fmus.design(name))
    for est in (data["estimator"], data["modes"][0]["estimator"]):
        est["num"][0] *= 1 + 1e-9
    data.pop("tables")                           # the runtime's tables of the edited design: computed again
    other = pipeline.package_design_data(data, tmp_path / "other", "c")
    assert pipeline.model_identifier(other) == name
    certified = {n: raw for n, raw in _members(original).items() if n.startswith(reference.LS_DIR)}
    swapped = _rewrite(other, tmp_path / f"{name}.fmu", lambda files: {
        **{n: raw for n, raw in files.items() if not n.startswith(reference.LS_DIR)}, **certified})
    assert _cli(other)[0] == 0                   # its own references: pass
    code, out, err = _cli(swapped)
    assert code == 1, out + err
    assert out.startswith(f"FAIL  {name}") and "beta_hat" in out, out


def test_check_user_errors_exit_2(built_fmus, tmp_path):
    fmu = built_fmus.c_path("CarPlant")
    cases = [(tmp_path / "missing.fmu", "no such file")]
    text = tmp_path / "text.fmu"
    text.write_text("not a zip")
    cases.append((text, "not an FMU"))
    nomd = _rewrite(fmu, tmp_path / "nomd.fmu", lambda f: {n: r for n, r in f.items() if n != "modelDescription.xml"})
    cases.append((nomd, "no modelDescription.xml"))
    bare = _rewrite(fmu, tmp_path / "bare.fmu",
                    lambda f: {n: r for n, r in f.items() if not n.startswith(reference.LS_DIR)})
    cases.append((bare, "no reference results"))
    for path, why in cases:
        code, out, err = _cli(path)
        assert code == 2 and why in err and err.count("\n") == 1, (path, out, err)
    code, out, err = _cli(fmu, "--platform", "sparc64")
    assert code == 2 and "unknown platform 'sparc64'" in err
    python_fmu = built_fmus.path("CarPlant")
    held = sorted({n.split("/")[1] for n in _members(python_fmu) if n.startswith("binaries/")} - {host_platform()})
    assert held                                  # pythonfmu ships other platforms' binaries
    code, out, err = _cli(python_fmu, "--platform", held[0])
    assert code == 2 and "cannot run here" in err and "pythonfmu" in err, err
    code, out, err = _cli(python_fmu, "--platform", "all")
    assert code == 0 and out.startswith("PASS") and "SKIP" in out, out


def test_latobs_help_lists_check(capsys):
    with pytest.raises(SystemExit):
        main(["--help"])
    assert "check" in capsys.readouterr().out


def test_the_reference_identity_holds_the_plant(monkeypatch):
    """An observer's references depend on its plant: another plant FMU, another identity (the
    FMU is rebuilt, not reused)."""
    before = pipeline.reference_identity("SideslipBankObserver", None, "c")
    assert before == pipeline.reference_identity("SideslipBankObserver", None, "c")
    real = packaging.plant_artefact

    def other_plant(name, vehicle):
        kind, veh, cls, base = real(name, vehicle)
        return kind, veh, cls, type(base)({**base.parts, "vehicle": "another"})

    monkeypatch.setattr(packaging, "plant_artefact", other_plant)
    assert pipeline.reference_identity("SideslipBankObserver", None, "c") != before
    assert pipeline.reference_identity("CarPlant", None, "c") == pipeline.reference_identity("CarPlant", None, "c")


def test_an_fmu_without_current_references_is_rebuilt(built_fmus, tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    fmu = built_fmus.c_path("CarPlant")
    bare = _rewrite(fmu, out / fmu.name, lambda f: {n: r for n, r in f.items() if not n.startswith(reference.LS_DIR)})
    assert not pipeline.current("CarPlant", None, out, "c")
    path, = pipeline.build(["CarPlant"], None, out, "c")
    assert "its reference results are missing" in capsys.readouterr().out
    assert path.read_bytes() == fmu.read_bytes()              # the same FMU as the session's, references included
    assert bare == path and pipeline.current("CarPlant", None, out, "c")


def _with_platform(fmu: Path, platform: str, dest: Path) -> Path:
    """``fmu`` itself when it holds ``platform``'s binary, else a copy with that binary compiled
    from the FMU's own sources (an FMU built without that platform)."""
    import re

    from latobs.cbackend import toolchain

    members = _members(fmu)
    ident = pipeline.model_identifier(fmu)
    lib = f"binaries/{platform}/{ident}{toolchain.SUFFIX[platform]}"
    if lib in members:
        return fmu
    why = toolchain.missing([platform])
    if why:
        pytest.skip(f"{fmu.name} holds no {platform} binary and none can be compiled here: {why}")
    sources = {n[len("sources/"):]: raw for n, raw in members.items() if n.startswith("sources/")}
    c_files = re.findall(r'SourceFile name="([^"]+)"', sources["buildDescription.xml"].decode())
    members[lib] = toolchain.compile_for(platform, sources, c_files, Path(lib).name)
    packaging.write_zip(dest, members)
    return dest


@pytest.mark.slow
@pytest.mark.parametrize("platform", ["win64", "aarch64-linux"])
@pytest.mark.parametrize("name", [n for n in pipeline.REFERENCE_EXPERIMENTS if n in __import__("conftest").C_NAMES])
def test_latobs_check_passes_on_the_other_platforms(name, platform, built_fmus, tmp_path):
    """Every native FMU reproduces its references on win64 (Wine) and aarch64-linux (qemu):
    bit for bit, or within the stated tolerance where a libm function differs in the last bit."""
    from latobs.cbackend import runner

    why = runner.available(platform)
    if why:
        pytest.skip(f"{platform} cannot run here: {why}")
    fmu = _with_platform(built_fmus.c_path(name), platform, tmp_path / f"{name}.fmu")
    code, out, err = _cli(fmu, "--platform", platform)
    assert code == 0, out + err
    assert out.startswith(f"PASS  {name}  ") and f"  {platform}: " in out, out


def test_check_verifies_the_seal_and_survives_a_crashing_binary(built_fmus, tmp_path):
    """`latobs check` fails (exit 1, one FAIL line each, the command itself alive) an FMU whose model
    description or embedded design was edited after the build (its manifest's hashes), and one whose
    binary is damaged so that loading it crashes the host process: the run happens in a child
    process, and the signal that ended it is named."""
    fmu = built_fmus.c_path("SideslipKalmanFilter")
    code, out, err = _cli(fmu)
    assert code == 0 and out.startswith("PASS  SideslipKalmanFilter  seal  all: every member"), out + err
    so = next(n for n in _members(fmu) if n.startswith(f"binaries/{host_platform()}/"))
    data = next(n for n in _members(fmu) if n.endswith(".design.json"))
    edits = {
        "model description": lambda f: {**f, "modelDescription.xml": f["modelDescription.xml"].replace(
            b'description="', b'description="edited ', 1)},
        "design": lambda f: {**f, data: f[data].replace(b'"certified": true', b'"certified": false', 1)},
        "binary": lambda f: {**f, so: f[so][:len(f[so]) // 2]},
        "a member added": lambda f: {**f, "resources/extra.txt": b"added"},
    }
    for what, change in edits.items():
        altered = _rewrite(fmu, tmp_path / f"{what.replace(' ', '_')}.fmu", change)
        assert _members(altered) != _members(fmu)
        code, out, err = _cli(altered)
        assert code == 1 and not err, (what, out, err)
        seal = out.splitlines()[0]
        assert seal.startswith("FAIL") and " seal " in seal, (what, out)
        if what == "binary":
            assert "crashed the host process (SIG" in out or "the run failed" in out, out
