"""C compilers for the native FMUs: the FMI 2.0.4 platforms an FMU ships for and how each is built.

Every target is compiled by ``zig cc`` from the ``ziglang`` package (a dependency: ``pip install``
brings a C compiler and its cross targets; zig builds each target's C runtime once, minutes, and
keeps it in the user cache folder). The host platform is compiled with the system C compiler when
there is one (``$CC``, ``cc``, ``gcc``: no first-build cost) and the results are the same
(``tests/test_cross_build.py``).

Platform folders as FMI 2.0.4 names them: ``linux64`` (x86-64, glibc 2.17 and newer), ``win64``
(x86-64 Windows, the system's universal C runtime only), ``darwin64`` (one universal Mach-O holding
x86-64 and arm64 macOS) and ``aarch64-linux`` (glibc 2.17 and newer).
"""
from __future__ import annotations

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
COMMON_FLAGS = ("-std=c99", "-O2", "-fvisibility=hidden", "-ffp-contract=off", "-Wall", "-Wextra", "-g0")


class ToolchainError(RuntimeError):
    pass


def parse_platforms(text: str) -> list[str]:
    """``"all"``, ``"host"`` or a comma-separated list of platform folders -> the folders, in the
    order of :data:`PLATFORMS`. ValueError naming an unknown platform."""
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
        elif n in PLATFORMS:
            out.add(n)
        else:
            raise ValueError(f"unknown platform {n!r} (all, host, or some of: " + ", ".join(PLATFORMS) + ")")
    return [p for p in PLATFORMS if p in out]


def host_platform() -> str | None:
    """The platform folder this machine loads, or None."""
    machine = _platform.machine().lower()
    if sys.platform.startswith("linux"):
        return {"x86_64": "linux64", "amd64": "linux64", "aarch64": "aarch64-linux", "arm64": "aarch64-linux"}.get(machine)
    if sys.platform == "win32":
        return "win64" if machine in ("amd64", "x86_64") else None
    if sys.platform == "darwin":
        return "darwin64"
    return None


@lru_cache(maxsize=None)
def zig_cc() -> tuple[str, ...] | None:
    """The ``zig cc`` command of the ``ziglang`` package in this interpreter, or None."""
    try:
        import ziglang  # noqa: F401
    except ImportError:
        return None
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


def missing(platforms: list[str]) -> str | None:
    """Why these platforms cannot be built here (None: they can)."""
    host = host_platform()
    cross = [p for p in platforms if not (p == host and system_compiler())]
    if cross and zig_cc() is None:
        return ("building for " + ", ".join(cross) + " needs zig (pip install ziglang)")
    if not cross and system_compiler() is None and zig_cc() is None:
        return "no C compiler found (set CC, install cc/gcc, or pip install ziglang)"
    return None


def _target_flags(target: str, out_name: str, shared: bool) -> list[str]:
    flags = list(COMMON_FLAGS)
    if "linux" in target:
        flags += ["-fPIC", "-s", "-Wl,--build-id=none", "-include", "glibc_compat.h"]
    elif "macos" in target:
        # the install name is the file's own name, not the scratch folder it was linked in
        flags += ["-s"] + (["-Wl,-install_name,@rpath/" + out_name] if shared else [])
    elif "windows" in target:
        flags += ["-s"]
    return flags + (["-shared"] if shared else [])


def _run(cmd: list[str], cwd: Path) -> None:
    try:
        proc = subprocess.run(cmd, cwd=cwd, env=dict(os.environ, LC_ALL="C"), capture_output=True, text=True)
    except OSError as exc:
        raise ToolchainError(f"cannot run {cmd[0]}: {exc}") from exc
    if proc.returncode != 0:
        raise ToolchainError(f"C build failed ({shlex.join(cmd)}, exit {proc.returncode}):\n{proc.stderr}")


def compile_for(platform: str, sources: dict[str, bytes], c_files: list[str], out_name: str, *,
                shared: bool = True, libs: tuple[str, ...] = ("-lm",)) -> bytes:
    """Compile ``c_files`` (names in ``sources``, written to a scratch folder under their relative
    names) for ``platform`` (a folder of :data:`PLATFORMS`) into a shared library (``shared``) or a
    program; returns its bytes. The host platform uses the system compiler when there is one.
    ToolchainError with the compiler's output."""
    if platform not in PLATFORMS:
        raise ToolchainError(f"unknown platform {platform!r} (one of: {', '.join(PLATFORMS)})")
    why = missing([platform])
    if why:
        raise ToolchainError(why)
    slices = []
    with tempfile.TemporaryDirectory(prefix="latobs-c-") as tmp:
        work = Path(tmp)
        for name, raw in sources.items():
            (work / name).write_bytes(raw)
        for k, target in enumerate(PLATFORMS[platform]):
            name = out_name if len(PLATFORMS[platform]) == 1 else f"{k}.{out_name}"
            if platform == host_platform() and system_compiler():
                cmd = [*shlex.split(system_compiler()), *_target_flags(target, out_name, shared)]
            else:
                cmd = [*zig_cc(), "-target", target, *_target_flags(target, out_name, shared)]
            _run([*cmd, "-I.", "-o", name, *c_files, *(libs if "windows" not in target else ())], work)
            slices.append((target, (work / name).read_bytes()))
    return slices[0][1] if len(slices) == 1 else fat_macho([raw for _, raw in slices])


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


@lru_cache(maxsize=None)
def _version(cmd: tuple[str, ...]) -> bytes:
    try:
        return subprocess.run(list(cmd), capture_output=True, timeout=60).stdout
    except (OSError, subprocess.SubprocessError) as exc:
        return f"{cmd[0]}: {exc}".encode()
