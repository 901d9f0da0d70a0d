"""Run an FMU's binary of any platform in a plain C host (``latobs/native/fmu_runner.c``): natively
for this machine's platform, under Wine for ``win64`` and under qemu for ``aarch64-linux``.

It proves an FMU's other binaries run, not only link: the same host, compiled for each platform
by :func:`latobs.cbackend.toolchain.compile_for`, loads the FMU's own binary of that platform
(``dlopen`` / ``LoadLibraryW``), co-simulates it on recorded inputs and writes every output with
17 significant digits, so outputs of two platforms compare to the bit.

* :func:`available` ``(platform)``: why a platform cannot run here, or None;
* :func:`run` ``(fmu, platform, time, inputs, ...)``: a :class:`RunResult` (the outputs at every
  communication point reached, and the fmi2Status of each);
* :func:`bench`: the time per step, no Python in the loop (``latobs bench``).

Emulators: Wine (Debian ``wine64``; its loader ``/usr/lib/wine/wine64`` is not on PATH; else
``wine64`` or ``wine`` on PATH), with its own prefix in the user cache folder (created by the
first run, 10-30 s); ``qemu-aarch64`` (Debian ``qemu-user``) with the aarch64 glibc of
``libc6-arm64-cross`` (``/usr/aarch64-linux-gnu``). macOS binaries cannot run on another system.
The compiled hosts are kept in the user cache folder, keyed by their source and compiler.

This module reads model descriptions with fmpy: it is a validation tool, downstream of packaging.
"""
from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import sys
import sysconfig
import tempfile
import time as _time
import zipfile
from contextlib import contextmanager, nullcontext
from dataclasses import dataclass, field
from pathlib import Path, PureWindowsPath
from typing import Mapping, Sequence

import numpy as np

from . import toolchain

SOURCE = Path(__file__).resolve().parent.parent / "native" / "fmu_runner.c"
#: Debian's wine64 loader (the package puts no ``wine64`` on PATH)
WINE_LOADERS = ("/usr/lib/wine/wine64", "wine64", "wine")
QEMU_AARCH64 = ("qemu-aarch64", "qemu-aarch64-static")
AARCH64_SYSROOT = Path("/usr/aarch64-linux-gnu")
#: the one letter a variable type has in the host's CSV columns (r12: Real, value reference 12)
TYPE_LETTER = {"Real": "r", "Integer": "i", "Enumeration": "i", "Boolean": "b",
               "Float64": "r", "Int32": "i"}     # (FMI 3.0: scalar Float64, Int32, Boolean)
#: fmi2Status values
STATUS = ("OK", "Warning", "Discard", "Error", "Fatal", "Pending")


class RunnerError(RuntimeError):
    """An FMU cannot be run on a platform here (no binary, no emulator, the host failed)."""


@dataclass
class RunResult:
    """One run of an FMU in the host.

    platform  the binary's platform folder
    time      the communication points reached, s (all of them unless a call failed)
    outputs   {output name: array} one value per point of ``time`` (Integer and Boolean outputs
              as float64, exactly); after a failed call the last row holds nan (the outputs
              after fmi2Discard, which the FMU still gives)
    status    the worst fmi2Status of the calls that led to each point (0 OK, 1 Warning,
              2 Discard, 3 Error, 4 Fatal): a step that failed is the last point
    seconds   wall time of the host process (the emulator's start included)
    log       what the FMU logged and the host said (stderr)
    """

    platform: str
    time: np.ndarray
    outputs: dict[str, np.ndarray]
    status: np.ndarray
    seconds: float
    log: str = ""
    points: int = field(default=0, repr=False)   # the communication points asked for

    @property
    def ok(self) -> bool:
        """Every communication point reached, no call above fmi2Warning."""
        return len(self.time) == self.points and bool(np.all(self.status <= 1))

    def failure(self) -> str | None:
        """What went wrong (None if :attr:`ok`)."""
        if self.ok:
            return None
        s = int(self.status[-1])
        return (f"a call returned fmi2{STATUS[s] if 0 <= s < len(STATUS) else s} at t = {float(self.time[-1])!r} s "
                f"({len(self.time)} of {self.points} communication points); log: {self.log.strip()[-2000:]}")

    def __getitem__(self, name: str) -> np.ndarray:
        return self.outputs[name]


def cache_dir() -> Path:
    """latobs's folder in the user cache folder (``latobs.cache.folder``: ``$LATOBS_CACHE_DIR``,
    else the platform's user cache folder)."""
    from .. import cache

    return cache.folder()


def _wine() -> str | None:
    for w in WINE_LOADERS:
        found = w if os.path.isabs(w) and os.access(w, os.X_OK) else (None if os.path.isabs(w) else shutil.which(w))
        if found:
            return found
    return None


def _emulator(platform: str) -> tuple[list[str] | None, str | None]:
    """(the command prefix that runs a program of ``platform`` here, why not)."""
    if platform not in toolchain.PLATFORMS:
        return None, f"unknown platform {platform!r} (one of: {', '.join(toolchain.PLATFORMS)})"
    host = toolchain.host_platform()
    if platform == host:
        return [], None
    if platform == "win64" and host in ("linux64", "darwin64"):
        wine = _wine()
        return ([wine], None) if wine else (None, "win64 runs under Wine here, and Wine is not installed "
                                                  "(Debian: apt-get install wine64)")
    if platform == "aarch64-linux" and host == "linux64":
        qemu = next((q for q in map(shutil.which, QEMU_AARCH64) if q), None)
        if qemu is None:
            return None, "aarch64-linux runs under qemu here, and qemu-aarch64 is not installed (Debian: qemu-user)"
        if not (AARCH64_SYSROOT / "lib" / "ld-linux-aarch64.so.1").is_file():
            return None, (f"aarch64-linux runs under qemu here, and the aarch64 C library is not installed "
                          f"(Debian: libc6-arm64-cross, in {AARCH64_SYSROOT})")
        return [qemu, "-L", str(AARCH64_SYSROOT)], None
    return None, (f"{platform} binaries cannot run on this machine ({host or sys.platform}): no emulator for them")


def available(platform: str) -> str | None:
    """Why FMU binaries of ``platform`` (a folder of :data:`toolchain.PLATFORMS`) cannot be run
    here, or None when :func:`run` can run them (the host compiles and an emulator is found)."""
    cmd, why = _emulator(platform)
    return why if cmd is None else toolchain.missing([platform])


def _sources() -> dict[str, bytes]:
    from ..native_guard import fmi2_headers

    headers = fmi2_headers()
    out = {"fmu_runner.c": SOURCE.read_bytes()}
    for h in ("fmi2Functions.h", "fmi2FunctionTypes.h", "fmi2TypesPlatform.h", "fmi3Functions.h",
              "fmi3FunctionTypes.h", "fmi3PlatformTypes.h"):
        out[h] = (headers / h).read_bytes()
    return out


def compile_runner(platform: str) -> Path:
    """The host program for ``platform``, compiled on first use into the user cache folder (its
    name holds the sha256 of the sources, the compilers and the platform; written atomically)."""
    sources = _sources()
    digest = hashlib.sha256(platform.encode() + b"\0" + toolchain.describe())
    for name in sorted(sources):
        digest.update(name.encode() + b"\0" + sources[name])
    exe = cache_dir() / "runner" / f"fmu_runner-{platform}-{digest.hexdigest()[:20]}"
    exe = exe.with_suffix(".exe") if platform == "win64" else exe
    if exe.is_file():
        return exe
    try:
        # (cached=False: the program is itself kept in the cache folder, named by its inputs)
        raw = toolchain.compile_for(platform, sources, ["fmu_runner.c"], exe.name, shared=False, libs=("-lm", "-ldl"),
                                    cached=False)
    except toolchain.ToolchainError as exc:
        raise RunnerError(f"cannot compile the FMU host for {platform}: {exc}") from exc
    from ..atomic import atomic_write_bytes

    return atomic_write_bytes(exe, raw, mode=0o755)


def libpython() -> Path | None:
    """This interpreter's shared libpython, or None (a static build: pythonfmu FMUs cannot run in
    a C host then; their library needs libpython's symbols in the host's global scope)."""
    name = sysconfig.get_config_var("LDLIBRARY") or ""
    for folder in (sysconfig.get_config_var("LIBDIR"), Path(sys.base_prefix) / "lib"):
        if folder and (name.endswith(".so") or ".so." in name):
            path = Path(folder) / name
            if path.is_file():
                return path
    return None


def _text(x: float) -> str:
    return repr(float(x))     # shortest round-trip digits; nan, inf, -inf as the host reads them


#: s a Wine server stays up after the last program: consecutive runs start in ~0.2 s, not ~1.2 s
WINE_LINGER = 10


@contextmanager
def _wine_prefix(env: dict[str, str], loader: str):
    """Wine's environment: its own prefix in the user cache folder (its first start, which creates
    it, holds a lock so that two processes never create it at once), no debug output, no
    Mono/Gecko install prompts; a server that lingers :data:`WINE_LINGER` s (Debian's stops at once)."""
    prefix = cache_dir() / "wine"
    env.update(WINEPREFIX=str(prefix), WINEDEBUG="-all", WINEDLLOVERRIDES="mscoree,mshtml=")
    server = Path(loader).parent / "wineserver"
    server = str(server) if server.is_file() else shutil.which("wineserver")
    ready = prefix / ".latobs-ready"
    if ready.is_file():
        if server:     # exits at once (status 2) when this prefix's server is already up
            subprocess.run([server, f"-p{WINE_LINGER}"], env=env, stdin=subprocess.DEVNULL,
                           stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=False)
        yield
        return
    import fcntl

    prefix.parent.mkdir(parents=True, exist_ok=True)
    with open(prefix.parent / "wine.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        yield
        ready.parent.mkdir(parents=True, exist_ok=True)
        ready.write_text("")


def _host_paths(platform: str):
    """A function mapping a local path to the path the host program sees, and one to its URI."""
    if platform == "win64" and toolchain.host_platform() != "win64":     # Wine: drive Z: is /
        def win(p: Path) -> PureWindowsPath:
            return PureWindowsPath("Z:" + str(Path(p).resolve()).replace("/", "\\"))

        return (lambda p: str(win(p))), (lambda p: win(p).as_uri())
    return (lambda p: str(Path(p).resolve())), (lambda p: Path(p).resolve().as_uri())


def _invoke(fmu: Path, platform: str, mode: str, time: np.ndarray, inputs: Mapping[str, Sequence[float]],
            outputs: Sequence[str] | None, parameters: Mapping[str, object] | None, step: float | None,
            workdir: Path | None, timeout: float):
    """Run the host: (its output file's text, the output names, its log, seconds)."""
    from fmpy import read_model_description

    fmu = Path(fmu)
    why = available(platform)
    if why is not None:
        raise RunnerError(f"{fmu.name} on {platform}: {why}")
    if not zipfile.is_zipfile(fmu):
        raise RunnerError(f"{fmu}: not an FMU (zip archive)")
    md = read_model_description(str(fmu))
    if md.coSimulation is None:
        raise RunnerError(f"{fmu.name}: no co-simulation interface")
    ident = md.coSimulation.modelIdentifier
    fmi3 = str(md.fmiVersion).startswith("3")
    if fmi3:       # the FMI 3.0 folder of this platform's binaries (darwin64: two thin files, not run here)
        from .fmi3 import FOLDERS

        if len(FOLDERS[platform]) != 1:
            raise RunnerError(f"{fmu.name}: the host does not run FMI 3.0 {platform} binaries")
    folder = FOLDERS[platform][0] if fmi3 else platform
    lib_name = f"binaries/{folder}/{ident}{toolchain.SUFFIX[platform]}"
    with zipfile.ZipFile(fmu) as z:
        names = set(z.namelist())
    if lib_name not in names:
        raise RunnerError(f"{fmu.name} has no {folder} binary ({lib_name}): build it with "
                          f"latobs build --platforms {platform}")
    python_fmu = "resources/slavemodule.txt" in names
    preload = libpython() if python_fmu and platform == toolchain.host_platform() else None
    if python_fmu and preload is None:
        raise RunnerError(f"{fmu.name} is a pythonfmu FMU: it runs only in a host with this Python's shared "
                          f"libpython, on {toolchain.host_platform()}")
    by_name = {v.name: v for v in md.modelVariables}

    def var(name: str, what: str) -> str:
        v = by_name.get(name)
        if v is None:
            raise RunnerError(f"{fmu.name} has no variable {name!r} ({what})")
        if v.type not in TYPE_LETTER or getattr(v, "dimensions", None):
            raise RunnerError(f"{fmu.name}: {what} {name!r} is of type {v.type}, which the host does not set or get")
        return f"{TYPE_LETTER[v.type]}{v.valueReference}"

    time = np.asarray(time, dtype=float)
    if time.ndim != 1 or len(time) < 2 or not np.all(np.isfinite(time)) or not np.all(np.diff(time) > 0):
        raise RunnerError(f"{fmu.name}: time must be at least two finite, increasing communication points")
    for v in md.modelVariables:
        if v.causality == "input" and v.name not in inputs and v.start is None:
            raise RunnerError(f"{fmu.name}: no values for input {v.name!r}, which declares no start value")
    in_names = list(inputs)
    for name in in_names:
        if by_name.get(name) is None or by_name[name].causality != "input":
            raise RunnerError(f"{fmu.name} has no input {name!r} (its inputs: "
                              + ", ".join(v.name for v in md.modelVariables if v.causality == "input") + ")")
    columns = [time] + [np.broadcast_to(np.asarray(inputs[n], dtype=float), time.shape) for n in in_names]
    out_names = list(outputs) if outputs is not None else [
        v.name for v in md.modelVariables if v.causality == "output" and v.type in TYPE_LETTER]
    out_vars = [var(n, "output") for n in out_names]
    sets = [f"{var(n, 'parameter')}={_text(float(x))}" for n, x in (parameters or {}).items()]
    exe = compile_runner(platform)
    with tempfile.TemporaryDirectory(prefix="latobs-run-", dir=workdir) as tmp:
        tmp = Path(tmp)
        unpacked = tmp / "fmu"
        with zipfile.ZipFile(fmu) as z:
            z.extractall(unpacked)
        table = np.column_stack(columns)
        (tmp / "in.csv").write_text("time," + ",".join(var(n, "input") for n in in_names) + "\n"
                                    + "".join(",".join(map(_text, row)) + "\n" for row in table.tolist()))
        path, uri = _host_paths(platform)
        # FMI 3.0 takes the resources folder as a native path ending in a separator, FMI 2.0 as a URI
        resources = path(unpacked / "resources") + ("\\" if platform == "win64" else "/") if fmi3 \
            else uri(unpacked / "resources")
        args = [("fmi3:" if fmi3 else "") + mode, path(unpacked / lib_name), resources, ident, md.guid,
                path(tmp / "in.csv"),
                path(tmp / "out.csv"), ",".join(out_vars) or "-", _text(step) if step else "-",
                str(preload) if preload else "-", *sets]
        code, log, seconds = execute(platform, exe, args, timeout, f"{fmu.name} on {platform}")
        if code != 0:
            raise RunnerError(f"{fmu.name} on {platform}: the FMU host failed (exit {code}): {log.strip()[-3000:]}")
        text = (tmp / "out.csv").read_text()
    return text, out_names, log, seconds


def execute(platform: str, program: Path, args: Sequence[str], timeout: float = 600.0,
            what: str | None = None) -> tuple[int, str, float]:
    """Run a ``program`` compiled for ``platform`` here (natively, Wine, qemu) with ``args`` (paths
    as the program sees them: :func:`host_path`): (exit code, stdout and stderr, seconds).
    RunnerError when it cannot be started or takes longer than ``timeout`` seconds."""
    what = what or f"{Path(program).name} on {platform}"
    prefix, why = _emulator(platform)
    if prefix is None:
        raise RunnerError(f"{what}: {why}")
    env = dict(os.environ)
    wine = platform == "win64" and bool(prefix)          # a prefix for win64: Wine (none on Windows)
    cmd = [*prefix, str(program), *args]
    for attempt in (1, 2):
        with (_wine_prefix(env, prefix[0]) if wine else nullcontext()), tempfile.TemporaryFile() as out:
            t0 = _time.perf_counter()
            try:    # a file, not a pipe: wineserver outlives wine and would hold a pipe open
                code = subprocess.run(cmd, stdin=subprocess.DEVNULL, stdout=out, stderr=out, env=env,
                                      timeout=timeout).returncode
            except subprocess.TimeoutExpired:
                raise RunnerError(f"{what}: took longer than {timeout:g} s") from None
            except OSError as exc:
                raise RunnerError(f"{what}: cannot start {cmd[0]}: {exc}") from exc
            seconds = _time.perf_counter() - t0
            out.seek(0)
            text = out.read().decode("utf-8", "replace")
        # Wine's client exits 1 without a word when the server it reaches is shutting down (its
        # linger time ran out between our check and the start): the program never ran, so run it
        # once more. Every program run here prints its own errors, so an empty exit 1 is Wine's.
        if wine and attempt == 1 and code == 1 and not text.strip():
            continue
        return code, text, seconds


def host_path(platform: str, path: str | os.PathLike) -> str:
    """``path`` as a program of ``platform`` run here sees it (under Wine: ``Z:\\...``)."""
    return _host_paths(platform)[0](Path(path))


def run(fmu: str | os.PathLike, platform: str, time: Sequence[float], inputs: Mapping[str, Sequence[float]],
        outputs: Sequence[str] | None = None, parameters: Mapping[str, object] | None = None,
        step: float | None = None, workdir: str | os.PathLike | None = None, timeout: float = 600.0) -> RunResult:
    """Co-simulate ``fmu``'s binary of ``platform`` in the C host, on this machine, Wine or qemu.

    time        the communication points t_0 < t_1 < ... < t_N, s (t_0: the start time)
    inputs      {input name: values at each point (or one value)}; the values at t_k are set
                before the step from t_k (those at t_0 also in initialisation mode); the last
                point's are not used. An input left out keeps its start value.
    outputs     the variables to record (default: every output of type Real, Integer, Boolean)
    parameters  {name: value} set after fmi2SetupExperiment, before initialisation
    step        the communication step size of every fmi2DoStep (default: t_(k+1) - t_k, as
                fmpy's ``simulate_fmu`` steps; give the step when the points are a fixed grid and
                the FMU must see exactly that step, as a fixed-step co-simulation does)
    Returns a :class:`RunResult` (a step that fails is recorded there, not raised). RunnerError
    (naming the FMU and the platform) when it cannot run: no binary for ``platform``, no
    emulator, bad names, or the host failed.
    """
    text, names, log, seconds = _invoke(Path(fmu), platform, "run", time, inputs, outputs, parameters, step,
                                        workdir, timeout)
    lines = text.splitlines()[1:]
    rows = np.array([[float(x) for x in line.split(",")] for line in lines]).reshape(len(lines), 2 + len(names))
    return RunResult(platform=platform, time=rows[:, 0], outputs={n: rows[:, 2 + j] for j, n in enumerate(names)},
                     status=rows[:, 1].astype(int), seconds=seconds, log=log, points=len(np.asarray(time)))


def bench(fmu: str | os.PathLike, platform: str, time: Sequence[float], inputs: Mapping[str, Sequence[float]],
          step: float, repeats: int = 5, workdir: str | os.PathLike | None = None) -> dict:
    """Time ``fmu`` in the C host, the rows of ``inputs`` run over and over (each timing lasts
    about 20 ms): {"ns_per_step_with_io", "ns_per_doStep", "median_ns_per_step_with_io",
    "median_ns_per_doStep", "steps_per_timing", "repeats"}, best and median of ``repeats``
    fresh instances; with I/O: fmi2Set* + fmi2DoStep + fmi2Get* of every output."""
    import json

    text, _, _, _ = _invoke(Path(fmu), platform, f"bench={int(repeats)}", time, inputs, None, None, step,
                            workdir, 600.0)
    return json.loads(text)
