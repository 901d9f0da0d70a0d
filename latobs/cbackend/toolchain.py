"""C compilers for the native FMUs: the FMI 2.0.4 platforms an FMU ships for and how each is built.

Every target is compiled by ``zig cc`` from the ``ziglang`` package (a dependency: ``pip install``
brings a C compiler and its cross targets; zig builds each target's C runtime once, minutes, and
keeps it in the user cache folder; ``python -m latobs.cbackend.toolchain --prepare`` builds them
all at once). On x86-64 Linux, linux64 is compiled with the system C compiler when there is one
(``$CC``, ``cc``, ``gcc``: no first-build cost; once zig's runtime is built, zig is as fast); the
outputs are the same bit for bit (``tests/cbackend/test_cross_build.py``). The targets of one build are
compiled in parallel, a thread per target running its compiler.

Platform folders as FMI 2.0.4 names them: ``linux64`` (x86-64, glibc 2.17 and newer), ``win64``
(x86-64 Windows, the system's universal C runtime only), ``darwin64`` (one universal Mach-O holding
x86-64 and arm64 macOS) and ``aarch64-linux`` (glibc 2.17 and newer).
"""
from __future__ import annotations

import hashlib
import os
import platform as _platform
import shlex
import shutil
import struct
import subprocess
import sys
import tempfile
from functools import lru_cache
from pathlib import Path

#: FMI 2.0.4 platform folder -> the zig targets it holds (darwin64: one universal binary of both)
PLATFORMS: dict[str, tuple[str, ...]] = {
    "linux64": ("x86_64-linux-gnu.2.17",),
    "win64": ("x86_64-windows-gnu",),
    "darwin64": ("x86_64-macos.10.13", "aarch64-macos.11.0"),
    "aarch64-linux": ("aarch64-linux-gnu.2.17",),
}
#: shared-library suffix per platform folder
SUFFIX = {"linux64": ".so", "aarch64-linux": ".so", "win64": ".dll", "darwin64": ".dylib"}

# Flags every target gets: C99, optimised, symbols hidden but the FMI functions' (FMI2_Export),
# no FMA contraction (the sources say it too: fp_contract.h), no debug information.
GLIBC_COMPAT = "glibc_compat.h"
COMMON_FLAGS = ("-std=c99", "-O2", "-fvisibility=hidden", "-ffp-contract=off", "-Wall", "-Wextra", "-g0")


class ToolchainError(RuntimeError):
    pass


#: FMI 3.0 platform folders -> the platform of :data:`PLATFORMS` that builds them (``--platforms``
#: takes either spelling; a darwin one builds the universal library both darwin folders are cut from)
FMI3_ALIASES = {"x86_64-linux": "linux64", "x86_64-windows": "win64", "x86_64-darwin": "darwin64",
                "aarch64-darwin": "darwin64"}


def parse_platforms(text: str) -> list[str]:
    """``"all"``, ``"host"`` or a comma-separated list of platform folders (FMI 2.0 names, or FMI
    3.0 names: :data:`FMI3_ALIASES`) -> the folders, in the order of :data:`PLATFORMS`. ValueError
    naming an unknown platform."""
    names = [t.strip() for t in text.split(",") if t.strip()]
    if not names:
        raise ValueError("no platform given (all, host, or some of: " + ", ".join(PLATFORMS) + ")")
    out: set[str] = set()
    for n in names:
        if n == "all":
            out.update(PLATFORMS)
        elif n == "host":
            host = host_platform()
            if host is None:
                raise ValueError(f"this machine ({sys.platform} {_platform.machine()}) is none of the FMU "
                                 "platforms " + ", ".join(PLATFORMS))
            out.add(host)
        elif n in PLATFORMS or n in FMI3_ALIASES:
            out.add(FMI3_ALIASES.get(n, n))
        else:
            raise ValueError(f"unknown platform {n!r} (all, host, or some of: " + ", ".join(PLATFORMS) + ")")
    return [p for p in PLATFORMS if p in out]


def host_platform() -> str | None:
    """The platform folder this machine loads, or None."""
    machine = _platform.machine().lower()
    if sys.platform.startswith("linux"):
        return {"x86_64": "linux64", "amd64": "linux64", "aarch64": "aarch64-linux",
                "arm64": "aarch64-linux"}.get(machine)
    if sys.platform == "win32":
        return "win64" if machine in ("amd64", "x86_64") else None
    if sys.platform == "darwin":
        return "darwin64"
    return None


@lru_cache(maxsize=None)
def zig_cc() -> tuple[str, ...] | None:
    """The ``zig cc`` command of the ``ziglang`` package in this interpreter, or None: its ``zig``
    executable itself where the package holds one (``python -m ziglang`` starts an interpreter
    only to exec it: ~30 ms of CPU per compilation), else ``python -m ziglang cc``."""
    try:
        import ziglang
    except ImportError:
        return None
    exe = Path(ziglang.__file__).with_name("zig.exe" if os.name == "nt" else "zig")
    if exe.is_file() and os.access(exe, os.X_OK):
        return (str(exe), "cc")
    return (sys.executable, "-m", "ziglang", "cc")


def system_compiler() -> str | None:
    """The system C compiler command: ``$CC`` if set and found, else ``cc``, else ``gcc``; None if none."""
    for cc in (os.environ.get("CC", "").strip(), "cc", "gcc"):
        if cc and shutil.which(shlex.split(cc)[0]):
            return cc
    return None


def host_compiler() -> str | None:
    """The C compiler command for this machine: the system one, else zig's; None if neither."""
    cc = system_compiler()
    if cc is not None:
        return cc
    zig = zig_cc()
    return shlex.join(zig) if zig else None


def missing(platforms: list[str], zig: bool = False) -> str | None:
    """Why these platforms cannot be built here (None: they can); ``zig``: every one by zig."""
    need = [p for p in platforms if _uses_zig(p, zig)]
    if not need or zig_cc() is not None:
        return None
    if system_compiler() is None:
        return ("no C compiler found (pip install ziglang; or set CC, or install cc/gcc, for this machine's "
                "platform only)")
    return "building for " + ", ".join(need) + " needs zig (pip install ziglang)"


def _compile_flags(target: str, sources=()) -> list[str]:
    """The flags of a compilation for ``target`` (no linking)."""
    flags = list(COMMON_FLAGS)
    if "linux" in target:
        # glibc_compat.h (the native backend's sources): the old-glibc baseline, included first
        flags += ["-fPIC"] + (["-include", GLIBC_COMPAT] if GLIBC_COMPAT in sources else [])
    return flags


def _target_flags(target: str, out_name: str, shared: bool, sources=()) -> list[str]:
    """The flags of a compilation and link into ``out_name`` for ``target``."""
    flags = _compile_flags(target, sources) + ["-s"]
    if "linux" in target:
        flags += ["-Wl,--build-id=none"]
    elif "macos" in target and shared:
        # the install name is the file's own name, not the scratch folder it was linked in
        flags += ["-Wl,-install_name,@rpath/" + out_name]
    return flags + (["-shared"] if shared else [])


def _run(cmd: list[str], cwd: Path) -> None:
    try:
        proc = subprocess.run(cmd, cwd=cwd, env=dict(os.environ, LC_ALL="C"), capture_output=True, text=True)
    except OSError as exc:
        raise ToolchainError(f"cannot run {cmd[0]}: {exc}") from exc
    if proc.returncode != 0:
        raise ToolchainError(f"C build failed ({shlex.join(cmd)}, exit {proc.returncode}):\n{proc.stderr}")


def _uses_zig(platform: str, zig: bool) -> bool:
    """Whether ``platform`` is compiled by zig: a cross target always; the host platform when
    asked (``zig``), when there is no system compiler, or when it is not linux64 (the system
    compiler is used where glibc_compat.h keeps its symbols at glibc 2.17: x86-64 Linux; on
    aarch64 it would bind the host glibc's newest versions; darwin64 needs both architectures)."""
    return zig or platform != host_platform() or platform != "linux64" or system_compiler() is None


def _command(platform: str, target: str, zig: bool) -> list[str]:
    """The compiler command of one target."""
    if _uses_zig(platform, zig):
        return [*zig_cc(), "-target", target]
    return shlex.split(system_compiler())


def cached_run(cmd: list[str], args: list[str], sources: dict[str, bytes], out_name: str, cached: bool = True,
                objects: dict[str, bytes] | None = None) -> bytes:
    """``cmd + args`` run in a scratch folder holding ``sources`` (and ``objects``: compiled files
    the command links) under their relative names; the bytes of ``out_name`` it writes. A
    compilation is a pure function of its command, the compilers and the sources' bytes (the
    objects are made from the sources): kept in latobs's cache (``latobs.cache``, kind "compile")
    by their content, like ccache, unless ``cached`` is False."""
    from .. import cache

    sha256_bytes = lambda raw: hashlib.sha256(raw).hexdigest()  # noqa: E731
    # (the interpreter's and zig's own path are not part of it: the compilers' versions are)
    parts = {"command": [Path(cmd[0]).name if cmd[0] in (sys.executable, *(zig_cc() or ())[:1]) else cmd[0], *cmd[1:],
                         *args],
             "compilers": sha256_bytes(describe()),
             "sources": {name: sha256_bytes(raw) for name, raw in sorted(sources.items())}}
    hit = cache.files("compile", parts) if cached else None
    if hit is not None and set(hit) == {"output"}:
        return hit["output"]
    with tempfile.TemporaryDirectory(prefix="latobs-c-") as tmp:
        work = Path(tmp)
        for name, raw in {**sources, **(objects or {})}.items():
            (work / name).write_bytes(raw)
        _run([*cmd, *args], work)
        raw = (work / out_name).read_bytes()
    if cached:
        cache.store_files("compile", parts, {"output": raw})
    return raw


def _compile_target(platform: str, target: str, sources: dict[str, bytes], c_files: list[str], out_name: str,
                    shared: bool, libs: tuple[str, ...], zig: bool, cached: bool = True,
                    common: dict[str, tuple[str, ...]] | None = None) -> bytes:
    """One target's file, compiled in a scratch folder of its own: every source under its relative
    name, the output under its final name (a Windows DLL records its own name). ``common``: the
    files of ``c_files`` that are the same for many outputs (an FMI layer; a model file for both FMI
    versions), each with the names of
    the sources it reads: each is compiled alone into an object, in a folder holding only those
    sources (so that its cache entry names everything it was made from), and linked in. ``cached``:
    taken from latobs's cache when the same compilation was made before (and kept there)."""
    cmd = _command(platform, target, zig)
    objects = {}
    for c_file in (common or {}):
        reads = {name: sources[name] for name in (c_file, *common[c_file])}
        obj = Path(c_file).stem + ".o"
        objects[obj] = cached_run(cmd, [*_compile_flags(target, reads), "-I.", "-c", "-o", obj, c_file], reads,
                                   obj, cached)
    rest = [c for c in c_files if c not in (common or {})]
    args = [*_target_flags(target, out_name, shared, sources), "-I.", "-o", out_name, *rest, *objects,
            *(libs if "windows" not in target else ())]
    return cached_run(cmd, args, sources, out_name, cached, objects)


def compile_platforms(out_names: dict[str, str], sources: dict[str, bytes], c_files: list[str], *,
                      shared: bool = True, libs: tuple[str, ...] = ("-lm",), zig: bool = False,
                      jobs: int | None = None, cached: bool = True,
                      common: dict[str, tuple[str, ...]] | None = None) -> dict[str, bytes]:
    """:func:`compile_for` of several platforms at once: ``out_names`` {platform: output file
    name} -> {platform: file bytes}. Every target is compiled in a thread of its own running the
    compiler (``jobs`` at a time, default one per core); ToolchainError naming the first failure.
    A compilation made before with the same command, compilers and sources is taken from latobs's
    cache (``latobs.cache``, kind "compile"), unless ``cached`` is False or the cache is off.
    ``common`` {file of ``c_files``: the names of the sources it reads}: files compiled into
    objects of their own, cached by those sources alone (``_compile_target``): an FMI layer,
    compiled once per target for every FMU; a model file, once for both FMI versions."""
    from concurrent.futures import ThreadPoolExecutor

    unknown = [p for p in out_names if p not in PLATFORMS]
    if unknown:
        raise ToolchainError(f"unknown platform {unknown[0]!r} (one of: {', '.join(PLATFORMS)})")
    why = missing(list(out_names), zig)
    if why:
        raise ToolchainError(why)
    tasks = [(p, t) for p in out_names for t in PLATFORMS[p]]
    with ThreadPoolExecutor(max_workers=max(1, min(len(tasks), jobs or os.cpu_count() or 1))) as pool:
        futures = {(p, t): pool.submit(_compile_target, p, t, sources, c_files, out_names[p], shared, libs, zig,
                                          cached, common)
                   for p, t in tasks}
        thin = {task: f.result() for task, f in futures.items()}
    out = {}
    for p in out_names:
        files = [thin[(p, t)] for t in PLATFORMS[p]]
        out[p] = files[0] if len(files) == 1 else fat_macho(files)
    return out


def compile_for(platform: str, sources: dict[str, bytes], c_files: list[str], out_name: str, *,
                shared: bool = True, libs: tuple[str, ...] = ("-lm",), zig: bool = False,
                cached: bool = True, common: dict[str, tuple[str, ...]] | None = None) -> bytes:
    """Compile ``c_files`` (names in ``sources``, written to a scratch folder under their relative
    names) for ``platform`` (a folder of :data:`PLATFORMS`) into a shared library (``shared``) or a
    program named ``out_name``; returns its bytes (darwin64: one universal file of both
    architectures). On x86-64 Linux, linux64 uses the system compiler when there is one, unless ``zig``.
    ToolchainError with the compiler's output. ``common``: as in :func:`compile_platforms`."""
    return compile_platforms({platform: out_name}, sources, c_files, shared=shared, libs=libs, zig=zig,
                             cached=cached, common=common)[platform]


# Mach-O universal ("fat") file: a big-endian header, one record per architecture, then each
# architecture's file at an offset aligned to its page size (2^14, as Apple's lipo writes them).
_FAT_MAGIC = 0xCAFEBABE
_MH_MAGIC_64 = 0xFEEDFACF
_ALIGN = 14


def fat_macho(thin: list[bytes]) -> bytes:
    """One universal Mach-O from thin 64-bit Mach-O files (what ``lipo -create`` writes)."""
    page = 1 << _ALIGN
    up = lambda n: (n + page - 1) // page * page  # noqa: E731
    offsets, pos = [], up(8 + 20 * len(thin))
    for raw in thin:
        offsets.append(pos)
        pos = up(pos + len(raw))
    out = bytearray(struct.pack(">II", _FAT_MAGIC, len(thin)))
    for raw, offset in zip(thin, offsets):
        magic, cputype, cpusubtype = struct.unpack("<IiI", raw[:12])
        if magic != _MH_MAGIC_64:
            raise ToolchainError("fat_macho: not a 64-bit little-endian Mach-O file")
        out += struct.pack(">iIIII", cputype, cpusubtype, offset, len(raw), _ALIGN)
    for raw, offset in zip(thin, offsets):
        out += b"\0" * (offset - len(out)) + raw
    return bytes(out)


def macho_slices(raw: bytes) -> list[tuple[int, int, bytes]]:
    """The (cputype, cpusubtype, thin file) of a universal Mach-O (for tests and checks)."""
    magic, n = struct.unpack(">II", raw[:8])
    if magic != _FAT_MAGIC:
        raise ValueError("not a universal Mach-O file")
    out = []
    for k in range(n):
        cputype, cpusubtype, offset, size, _ = struct.unpack(">iIIII", raw[8 + 20 * k: 28 + 20 * k])
        out.append((cputype, cpusubtype, raw[offset: offset + size]))
    return out


def describe() -> bytes:
    """The identity of the compilers (``--version`` of the system compiler and zig's version):
    part of what a native FMU is made from."""
    parts = []
    cc = system_compiler()
    if cc:
        parts.append(_version((*shlex.split(cc), "--version")))
    if zig_cc():
        parts.append(_version((sys.executable, "-m", "ziglang", "version")))
    return b"\n".join(parts) + b"\n" + " ".join(COMMON_FLAGS).encode()


def _version_line(cc: str) -> str:
    """The first line of ``cc --version``."""
    return (_version((*shlex.split(cc), "--version")).decode(errors="replace").strip().splitlines() or ["?"])[0]


@lru_cache(maxsize=None)
def _version(cmd: tuple[str, ...]) -> bytes:
    try:
        return subprocess.run(list(cmd), capture_output=True, timeout=60).stdout
    except (OSError, subprocess.SubprocessError) as exc:
        return f"{cmd[0]}: {exc}".encode()


def prepare(platforms: list[str] | None = None) -> dict[str, float]:
    """Have zig build and cache the C runtime of every target of ``platforms`` (default: all), for
    shared libraries and programs, all at once: a one-line C file compiled for each. Minutes on a
    fresh machine (once: zig keeps them in its cache folder), about a second per target after.
    Returns the seconds each platform took. ToolchainError without zig."""
    import time
    from concurrent.futures import ThreadPoolExecutor

    platforms = list(platforms or PLATFORMS)
    if zig_cc() is None:
        raise ToolchainError("zig not found (pip install ziglang)")
    # (one exported symbol: zig 0.17's Mach-O linker crashes on a library that exports none)
    src = {"one.c": b"#include <math.h>\nint main(void) { return (int)sqrt(1.0) - 1; }\n"
                    b"__attribute__((visibility(\"default\"))) double one(double x) { return sin(x) + 1.0; }\n"}

    def one(platform: str) -> float:
        t0 = time.perf_counter()
        for shared in (True, False):
            compile_for(platform, src, ["one.c"], "one" + (SUFFIX[platform] if shared else ""), shared=shared,
                        zig=True, cached=False)     # (zig must run: its runtime is what is made)
        return time.perf_counter() - t0

    # one thread per platform: zig itself builds a runtime's many files on every core
    with ThreadPoolExecutor(max_workers=len(platforms)) as pool:
        return dict(zip(platforms, pool.map(one, platforms)))


def main(argv: list[str] | None = None) -> int:
    import argparse
    import time

    p = argparse.ArgumentParser(prog="python -m latobs.cbackend.toolchain",
                                description="The native FMUs' C compilers (zig cc): which, and their runtimes.")
    p.add_argument("--prepare", action="store_true",
                   help="build and cache zig's C runtime of every target now (minutes, once per machine)")
    p.add_argument("--platforms", default="all", help="comma-separated platform folders, host or all (default)")
    args = p.parse_args(argv)
    try:
        platforms = parse_platforms(args.platforms)
    except ValueError as exc:
        p.error(str(exc))
    cc = system_compiler()
    host = host_platform()
    role = "builds linux64" if host and not _uses_zig(host, False) else "zig builds every platform"
    print(f"system C compiler: {_version_line(cc) if cc else 'none'} ({role})")
    print(f"zig: {_version_line(shlex.join(zig_cc())) if zig_cc() else 'none (pip install ziglang)'}")
    if args.prepare:
        t0 = time.perf_counter()
        try:
            times = prepare(platforms)
        except ToolchainError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 1
        for platform, seconds in times.items():
            print(f"{platform}: ready ({seconds:.1f} s)")
        print(f"all ready in {time.perf_counter() - t0:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
