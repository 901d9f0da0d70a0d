"""A native FMU rebuilt from its own sources/ by an importer gives the original numbers, bit for bit.

Importers that recompile a source FMU (fmpy's ``build_platform_binary``, FMI Kit for Simulink,
dSPACE, a user's MSVC project) use their own compiler flags and drop the build description's
``compilerOptions``: latobs's ``-ffp-contract=off`` is lost, and where the CPU has fused
multiply-add the compiler's default contracts a*b + c into one FMA (GCC in its GNU modes, the
default, even across statements), which changes the last bit and, through the observers'
feedback, the outputs. ``fmu_src/c/fp_contract.h`` states the contract in the sources.

The test rebuilds the FMU with fmpy's ``build_platform_binary`` (CMake, Release: -O3) with FMA
enabled where the host has it (the flags a user with ``-march=native`` has; aarch64 always has
FMA), runs the original and the rebuilt binary on a validation scenario's inputs in the C host,
and compares every output bit for bit. The control: the same rebuild with the contract header
emptied gives different numbers (on a host with FMA), so the comparison can fail.
"""
from __future__ import annotations

import platform
import re
import shutil
import subprocess
import zipfile
from pathlib import Path

import numpy as np
import pytest
from fmpy import extract

from latobs.cbackend import host
from latobs.native_guard import find_compiler
from latobs.validation import harness

pytestmark = [pytest.mark.slow,
              pytest.mark.skipif(find_compiler() is None, reason="no C compiler (set CC, or install cc/gcc)"),
              pytest.mark.skipif(shutil.which("cmake") is None, reason="no cmake (fmpy's build needs it)")]
DT = 0.005


def _host_fma() -> bool:
    """True when the compiler may emit FMA here: aarch64 always, x86-64 when the CPU has it."""
    if platform.machine() in ("aarch64", "arm64"):
        return True
    try:
        return platform.machine() == "x86_64" and " fma " in Path("/proc/cpuinfo").read_text() + " "
    except OSError:
        return False


FMA = _host_fma()
#: what a user building for their own CPU passes (-march=native); on aarch64 FMA is the baseline
C_FLAGS = "-mfma" if FMA and platform.machine() == "x86_64" else ""


#: the fused multiply-add instructions of x86-64 (FMA3: vfmadd..., vfmsub..., vfnmadd..., vfnmsub...,
#: vfmaddsub..., vfmsubadd...) and aarch64 (fmadd, fmsub, fnmadd, fnmsub, fmla, fmls)
FMA_INSN = re.compile(r"\s(vfn?m(add|sub)\w*|f(n?m(add|sub)|ml[as])\b)")


def _fma_instructions(library: Path) -> int:
    """How many FMA instructions ``objdump -d`` finds in ``library`` (-1: no objdump)."""
    objdump = shutil.which("objdump")
    if objdump is None:
        return -1
    text = subprocess.run([objdump, "-d", str(library)], capture_output=True, text=True, check=True).stdout
    return len(FMA_INSN.findall(text))


def _rebuild(fmu: Path, tmp: Path, *, contract: bool = True) -> tuple[Path, int]:
    """fmpy's build_platform_binary on the FMU's own sources/, its binaries removed first; with
    ``contract=False`` fp_contract.h is emptied (the sources as they were without it). Returns the
    rebuilt FMU and the number of FMA instructions in its library."""
    from fmpy.build import build_platform_binary

    folder = Path(extract(str(fmu), unzipdir=str(tmp / "x")))
    shutil.rmtree(folder / "binaries")
    if not contract:
        (folder / "sources" / "fp_contract.h").write_text("/* emptied by the test */\n")
    (tmp / "build").mkdir()
    # fmpy's CMake project links no library (an FMI 2.0 model description cannot name one; the
    # build description's <Library name="m"/> does): a Python process has libm loaded anyway, the
    # C host needs it linked
    build_platform_binary(folder, build_dir=tmp / "build", cmake_options={
        "CMAKE_C_FLAGS:STRING": C_FLAGS, "CMAKE_C_STANDARD_LIBRARIES:STRING": "-lm"})
    library = folder / "binaries" / "linux64" / f"{fmu.stem}.so"
    assert library.is_file()
    fma = _fma_instructions(library)
    out = tmp / fmu.name
    with zipfile.ZipFile(out, "w") as z:
        for p in sorted(folder.rglob("*")):
            if p.is_file():
                z.write(p, p.relative_to(folder).as_posix())
    return out, fma


@pytest.fixture(scope="module")
def scenario(built_fmus):
    """bank-braking (4 s) with the C CarPlant and the C SideslipBankObserver: each FMU's inputs."""
    from latobs.validation.scenarios import get_scenario

    res = harness.run(get_scenario("bank-braking", duration=4.0), built_fmus.c_path("CarPlant"),
                      {"obs": built_fmus.c_path("SideslipBankObserver")}, dt=DT)
    n = len(res.time) - 1
    return {"SideslipBankObserver": {k: res.measured[k][:n] for k in res.inputs["obs"]},
            "CarPlant": {k: res.bus[k][:n] for k in res.inputs[harness.PLANT_LABEL]}}


def _differences(a: dict, b: dict) -> dict[str, float]:
    assert set(a) == set(b)
    return {k: float(np.max(np.abs(np.asarray(a[k], float) - np.asarray(b[k], float))))
            for k in a if not np.array_equal(a[k], b[k])}


@pytest.mark.parametrize("name", ["SideslipBankObserver", "CarPlant"])
def test_fmpy_rebuild_from_the_sources_gives_the_original_outputs_bit_for_bit(built_fmus, scenario, name, tmp_path):
    fmu = built_fmus.c_path(name)
    inputs = scenario[name]
    original = host.run(fmu, inputs, DT)
    rebuilt, fma = _rebuild(fmu, tmp_path / "with")
    # every code path (ModelExchange too, which the co-simulation run does not reach): no FMA
    assert fma <= 0, f"the rebuild (CFLAGS {C_FLAGS!r}) holds {fma} fused multiply-add instruction(s)"
    assert _differences(host.run(rebuilt, inputs, DT), original) == {}, \
        f"the rebuild (CFLAGS {C_FLAGS!r}) differs from the original"
    if not FMA:
        return          # no FMA here: without the contract the rebuild could not differ either
    (tmp_path / "without").mkdir()
    uncontracted, fma = _rebuild(fmu, tmp_path / "without", contract=False)
    diff = _differences(host.run(uncontracted, inputs, DT), original)
    print(f"{name}: without the contract (CFLAGS {C_FLAGS!r}): {fma} FMA instructions, max |diff| per output: {diff}")
    assert fma != 0 and diff, "the control rebuild without the contract should contract to FMA and differ"
