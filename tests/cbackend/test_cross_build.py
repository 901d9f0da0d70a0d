"""Native FMUs for every FMI platform from one Linux machine (``latobs.cbackend.toolchain``).

Every native FMU of the session build (``latobs build``'s default: all platforms) holds
``binaries/linux64``, ``win64``, ``darwin64`` and ``aarch64-linux``; each binary is read here
with the pure-Python readers of ``binfmt.py`` (no objdump, readelf or otool needed):

* win64: a PE32+ x86-64 DLL exporting every function ``fmi2Functions.h`` declares, importing
  only KERNEL32 and the universal C runtime (``api-ms-win-crt-*``, ``ucrtbase``): no vcruntime,
  no msvcr*, no MinGW runtime (libgcc, libwinpthread);
* darwin64: one universal Mach-O of exactly an x86-64 and an arm64 dylib, each exporting every
  fmi2 function, named ``@rpath/<id>.dylib`` (no scratch-folder path), needing only libSystem,
  for macOS 10.13 and 11.0 and later, the arm64 one ad-hoc signed (its page hashes checked);
* linux64 and aarch64-linux: ELF shared objects needing libc and libm only, no symbol version
  newer than GLIBC_2.17, exporting the fmi2 functions only;
* two builds give byte-identical FMUs, every platform;
* with no system C compiler (PATH without gcc/cc, CC unset) ``latobs build`` makes the same
  five-platform native FMUs through zig alone, and their linux64 binaries give the gcc-built
  ones' outputs bit for bit in a closed-loop co-simulation.
"""
from __future__ import annotations

import os
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

from latobs import cbackend, packaging, pipeline
from latobs.cbackend import toolchain
from latobs.cli import main

import binfmt

FMU_NAMES = [*packaging.OBSERVERS, *packaging.PLANTS]
C_NAMES = [n for n in FMU_NAMES if cbackend.emitter((packaging.OBSERVERS.get(n) or packaging.PLANTS[n]).model_module)]
#: what a Windows DLL may import: the system's own DLLs only (the universal C runtime ships with
#: Windows 10 and later, and as an update for 7 and 8)
WINDOWS_SYSTEM = ("kernel32.dll", "ucrtbase.dll")
MACHO_LINKER_SYMBOLS = {"_mh_dylib_header", "__dso_handle"}   # the linker's own, in every dylib
SCRATCH = (b"latobs-c-", b"/tmp/", b"pytest-of-")


@pytest.fixture(scope="module")
def fmi2() -> set[str]:
    from latobs.native_guard import fmi2_headers

    return set(binfmt.fmi2_functions(fmi2_headers() / "fmi2Functions.h"))


def _binaries(fmu: Path) -> dict[str, bytes]:
    with zipfile.ZipFile(fmu) as z:
        return {n: z.read(n) for n in z.namelist() if n.startswith("binaries/") and not n.endswith("/")}


def _binary(built_fmus, name: str, platform: str) -> bytes:
    with zipfile.ZipFile(built_fmus.c_path(name)) as z:
        return z.read(f"binaries/{platform}/{name}{toolchain.SUFFIX[platform]}")


# ---------------------------------------------------------------------------------------------
# the platform list and the command line (no build)
# ---------------------------------------------------------------------------------------------
def test_platform_names_parse_in_fmi_order_and_an_unknown_one_is_named():
    assert toolchain.parse_platforms("all") == ["linux64", "win64", "darwin64", "aarch64-linux"]
    assert toolchain.parse_platforms(" aarch64-linux,win64 ,win64") == ["win64", "aarch64-linux"]
    if toolchain.host_platform():
        assert toolchain.parse_platforms("host") == [toolchain.host_platform()]
    for bad in ("win32", "linux64,macos", ""):
        with pytest.raises(ValueError, match=repr(bad.split(",")[-1]) if bad else "no platform"):
            toolchain.parse_platforms(bad)


def test_cli_refuses_an_unknown_platform_and_platforms_with_pythonfmu(tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:           # argparse's error: one line, exit 2
        main(["build", "CarPlant", "--platforms", "linux64,win32", "--out", str(tmp_path)])
    err = capsys.readouterr().err
    assert exc.value.code == 2
    assert "unknown platform 'win32'" in err and len(err.strip().splitlines()) == 1
    assert main(["build", "CarPlant", "--backend", "python", "--platforms", "host", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "--platforms" in err and "pythonfmu" in err and len(err.strip().splitlines()) == 1
    assert not list(tmp_path.iterdir())
    with pytest.raises(pipeline.PipelineError, match="pythonfmu"):
        pipeline.build(["CarPlant"], None, tmp_path, "python", platforms=["linux64"])
    with pytest.raises(SystemExit) as exc:
        main(["demo", "--platforms", "nope", "--out", str(tmp_path)])
    assert exc.value.code == 2 and "unknown platform 'nope'" in capsys.readouterr().err


# ---------------------------------------------------------------------------------------------
# every native FMU: the platforms and their binaries
# ---------------------------------------------------------------------------------------------
@pytest.mark.slow
@pytest.mark.parametrize("name", C_NAMES)
def test_every_native_fmu_holds_every_platform_and_no_scratch_path(built_fmus, name):
    found = _binaries(built_fmus.c_path(name))
    assert sorted(found) == sorted(f"binaries/{p}/{name}{toolchain.SUFFIX[p]}" for p in toolchain.PLATFORMS)
    for member, raw in found.items():
        assert not [s for s in SCRATCH if s in raw], f"{member} holds a build folder's path"


@pytest.mark.slow
@pytest.mark.parametrize("name", C_NAMES)
def test_windows_dll_exports_fmi2_and_needs_only_the_system_c_runtime(built_fmus, name, fmi2):
    pe = binfmt.read_pe(_binary(built_fmus, name, "win64"))
    assert pe.machine == 0x8664 and pe.is_dll and pe.dll_name == f"{name}.dll"
    assert fmi2 <= set(pe.exports), f"missing exports: {sorted(fmi2 - set(pe.exports))}"
    assert set(pe.exports) <= fmi2, f"exports beyond the FMI API: {sorted(set(pe.exports) - fmi2)}"
    dlls = [d.lower() for d in [*pe.imports, *pe.delay_imports]]
    assert "kernel32.dll" in dlls
    foreign = [d for d in dlls if not (d in WINDOWS_SYSTEM or d.startswith("api-ms-win-crt-"))]
    assert not foreign, f"{name}.dll needs {foreign} (vcruntime/msvcr/MinGW runtimes are not on every Windows)"


@pytest.mark.slow
@pytest.mark.parametrize("name", C_NAMES)
def test_darwin_library_is_universal_x86_64_and_arm64_exporting_fmi2(built_fmus, name, fmi2):
    slices = toolchain.macho_slices(_binary(built_fmus, name, "darwin64"))
    assert sorted(ct for ct, _, _ in slices) == [binfmt.CPU_X86_64, binfmt.CPU_ARM64]
    minimum = {binfmt.CPU_X86_64: (10, 13, 0), binfmt.CPU_ARM64: (11, 0, 0)}
    for cputype, _, thin in slices:
        m = binfmt.read_macho(thin)
        assert m.cputype == cputype and m.filetype == binfmt.MH_DYLIB
        assert m.install_name == f"@rpath/{name}.dylib"
        assert m.dylibs == ["/usr/lib/libSystem.B.dylib"]
        assert m.min_os is not None and m.min_os <= minimum[cputype], m.min_os
        assert fmi2 <= set(m.exports), f"{cputype:#x}: missing exports {sorted(fmi2 - set(m.exports))}"
        assert set(m.exports) <= fmi2 | MACHO_LINKER_SYMBOLS, sorted(set(m.exports) - fmi2)
        if m.symtab_exports:             # the symbol table, where kept, says the same
            assert set(m.symtab_exports) == set(m.exports)
        if cputype == binfmt.CPU_ARM64:  # Apple silicon loads signed code only: zig's ad-hoc signature, intact
            pages, bad = binfmt.code_signature_pages(thin)
            assert pages > 0 and bad == [], f"arm64 slice: pages {bad} do not match their signed hashes"


@pytest.mark.slow
@pytest.mark.parametrize("platform,machine", [("linux64", 62), ("aarch64-linux", 183)])
@pytest.mark.parametrize("name", C_NAMES)
def test_linux_libraries_need_libc_and_libm_at_glibc_2_17(built_fmus, name, platform, machine, fmi2):
    elf = binfmt.read_elf(_binary(built_fmus, name, platform))
    assert elf.machine == machine
    assert set(elf.needed) <= {"libc.so.6", "libm.so.6"} and "libc.so.6" in elf.needed, elf.needed
    assert set(elf.versions) <= set(elf.needed)
    versions = [tuple(map(int, v.removeprefix("GLIBC_").split("."))) for vs in elf.versions.values() for v in vs]
    assert versions and all(v <= (2, 17) for v in versions), elf.versions
    assert set(elf.exports) == fmi2, sorted(set(elf.exports) ^ fmi2)


@pytest.mark.slow
def test_fmpy_validate_and_fmutool_check_a_five_platform_fmu(built_fmus):
    """(integration/test_conformance.py runs both on every native FMU; here on one, its platforms checked.)"""
    from fmpy.validation import validate_fmu

    from conftest import fmutool as _fmutool

    fmu = built_fmus.c_path("CarPlant")
    assert {m.split("/")[1] for m in _binaries(fmu)} == set(toolchain.PLATFORMS)
    assert validate_fmu(str(fmu)) == []
    proc = subprocess.run([_fmutool(), "-input", str(fmu), "-check"], capture_output=True, text=True, timeout=120)
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0 and "No semantic error against the FMI-2 standard" in out, out
    assert not [ln for ln in out.splitlines() if ln.split("|")[0].strip() in ("WARNING", "ERROR", "CRITICAL")], out


# ---------------------------------------------------------------------------------------------
# reproducible, and reused only for the same platforms
# ---------------------------------------------------------------------------------------------
@pytest.mark.slow
def test_two_builds_are_byte_identical_on_every_platform(built_fmus, tmp_path):
    first = built_fmus.c_path("CarPlant")
    again = pipeline.package_plant("CarPlant", None, tmp_path, "c")
    a, b = _binaries(first), _binaries(again)
    assert sorted(a) == sorted(b)
    assert [m for m in a if a[m] != b[m]] == []
    assert first.read_bytes() == again.read_bytes()


@pytest.mark.slow
def test_an_fmu_is_reused_only_for_the_platforms_it_holds(tmp_path, capsys):
    host = toolchain.host_platform()
    if host is None:
        pytest.skip("this machine is none of the FMU platforms")
    assert main(["build", "CarPlant", "--platforms", "host", "--out", str(tmp_path)]) == 0
    with zipfile.ZipFile(tmp_path / "CarPlant.fmu") as z:
        assert [n for n in z.namelist() if n.startswith("binaries/")] == [f"binaries/{host}/CarPlant.so"]
    assert pipeline.current("CarPlant", None, tmp_path, platforms=[host])
    assert not pipeline.current("CarPlant", None, tmp_path)                  # default: every platform
    assert pipeline.current("CarPlant", None, tmp_path, host_suffices=True)  # validate, replay, demo
    capsys.readouterr()
    assert main(["build", "CarPlant", "--platforms", "all", "--out", str(tmp_path), "--json", "-"]) == 0
    out = capsys.readouterr()
    assert f"the platforms ({host} -> linux64,win64,darwin64,aarch64-linux) changed" in out.err
    import json

    assert json.loads(out.out)["fmus"][0]["platforms"] == list(toolchain.PLATFORMS)


# ---------------------------------------------------------------------------------------------
# no system compiler: zig alone, the same numbers
# ---------------------------------------------------------------------------------------------
@pytest.mark.slow
def test_without_a_system_compiler_zig_builds_the_same_fmus_and_the_same_numbers(built_fmus, tmp_path):
    from shutil import which

    from latobs.validation import harness
    from latobs.validation.scenarios import get_scenario

    if toolchain.host_platform() != "linux64" or toolchain.system_compiler() is None:
        pytest.skip("compares a zig build with this Linux x86-64 machine's system compiler's")
    if toolchain.zig_cc() is None:
        pytest.fail("zig (the ziglang package, a dependency) is not installed")
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    (bin_dir / "python").symlink_to(sys.executable)
    path = os.pathsep.join([str(bin_dir), str(Path(sys.executable).parent)])
    assert which("cc", path=path) is None and which("gcc", path=path) is None, "no compiler may be on this PATH"
    env = {k: v for k, v in os.environ.items() if k not in ("CC", "PATH")}
    env["PATH"] = path
    out = tmp_path / "fmus"
    names = ["SideslipBankObserver", "CarPlant"]
    proc = subprocess.run(["latobs", "build", *names, "--out", str(out)], env=env, capture_output=True, text=True,
                          timeout=900)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-3000:]
    for name in names:
        assert f"built {out / name}.fmu (native C: linux64, win64, darwin64, aarch64-linux)" in proc.stdout
        zig_bins, gcc_bins = _binaries(out / f"{name}.fmu"), _binaries(built_fmus.c_path(name))
        assert sorted(zig_bins) == sorted(gcc_bins)
        so = f"binaries/linux64/{name}.so"             # another compiler made it (clang, not gcc) ...
        assert b"GCC: (" in gcc_bins[so] and b"GCC: (" not in zig_bins[so]

    # ... and it computes the same doubles, closed loop, plant and observer (fmpy, linux64)
    sc = get_scenario("bank-braking", duration=4.0)
    ref = harness.run(sc, built_fmus.c_path("CarPlant"), {"obs": built_fmus.c_path("SideslipBankObserver")},
                      dt=0.005)
    got = harness.run(sc, out / "CarPlant.fmu", {"obs": out / "SideslipBankObserver.fmu"}, dt=0.005)
    for k, v in ref.bus.items():
        assert np.array_equal(got.bus[k], v, equal_nan=True), f"plant {k}: max |diff| {np.max(np.abs(got.bus[k] - v))}"
    for k, v in ref.observers["obs"].items():
        assert np.array_equal(got.observers["obs"][k], v, equal_nan=True), \
            f"observer {k}: max |diff| {np.max(np.abs(got.observers['obs'][k] - v))}"


def _zig_twin(fmu: Path, out: Path) -> Path:
    """A copy of ``fmu`` whose linux64 library zig compiled from the FMU's own sources (as
    buildDescription.xml lists them) instead of the system compiler: the same guid, the same code."""
    from xml.etree import ElementTree

    with zipfile.ZipFile(fmu) as z:
        members = {n: z.read(n) for n in z.namelist()}
    sources = {n.removeprefix("sources/"): raw for n, raw in members.items() if n.startswith("sources/")}
    c_files = [f.get("name") for f in ElementTree.fromstring(sources["buildDescription.xml"]).iter("SourceFile")]
    so = f"binaries/linux64/{fmu.stem}.so"
    members[so] = toolchain.compile_for("linux64", sources, c_files, f"{fmu.stem}.so", zig=True)
    out.mkdir(parents=True, exist_ok=True)
    packaging.write_zip(out / fmu.name, members)
    return out / fmu.name


#: the scenario each plant's observers are compared on (short: the first seconds)
COMPARED_ON = {"CarPlant": "bank-braking", "MotorcyclePlant": "motorcycle-lane-change"}


@pytest.mark.slow
@pytest.mark.parametrize("name", [n for n in C_NAMES if n in packaging.OBSERVERS])
def test_zig_and_the_system_compiler_give_the_same_doubles(built_fmus, name, tmp_path_factory):
    """Every observer beside its plant, closed loop in fmpy: the linux64 libraries compiled by zig
    (clang, glibc 2.17 stubs) and by the system compiler (gcc) give the same outputs to the bit:
    -ffp-contract=off, no fast-math, and the same libm functions bound (glibc_compat.h)."""
    from latobs.synthesis import designs
    from latobs.validation import harness
    from latobs.validation.scenarios import get_scenario

    if toolchain.host_platform() != "linux64" or toolchain.system_compiler() is None or toolchain.zig_cc() is None:
        pytest.skip("compares zig with this Linux x86-64 machine's system compiler")
    plant = designs.DESIGNS[name].plant
    twins = tmp_path_factory.mktemp("zig_twins")
    sc = get_scenario(COMPARED_ON[plant], duration=3.0)
    ref = harness.run(sc, built_fmus.c_path(plant), {"obs": built_fmus.c_path(name)}, dt=0.005)
    got = harness.run(sc, _zig_twin(built_fmus.c_path(plant), twins),
                      {"obs": _zig_twin(built_fmus.c_path(name), twins)}, dt=0.005)
    for what, a, b in [*((f"plant {k}", v, got.bus[k]) for k, v in ref.bus.items()),
                       *((f"{name} {k}", v, got.observers["obs"][k]) for k, v in ref.observers["obs"].items())]:
        assert np.array_equal(a, b, equal_nan=True), f"{what}: max |diff| {np.max(np.abs(np.subtract(a, b)))}"


@pytest.mark.slow
def test_prepare_readies_every_target(tmp_path):
    # from a folder of its own: in the repository's root `-m latobs...` would find the source
    # folder latobs/ first, which is not the installed package (no latobs.fmu_src there)
    proc = subprocess.run([sys.executable, "-m", "latobs.cbackend.toolchain", "--prepare"], capture_output=True,
                          text=True, timeout=1800, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    for platform in toolchain.PLATFORMS:
        assert f"{platform}: ready" in proc.stdout
