"""The master's stepping loop compiled (``latobs/native/master_loop.c``): the calls the Python loop
of :mod:`latobs.validation.master` makes, in the same order on the same matrices, without a
Python statement per FMU per step. Compiled on first use for this machine (the system C
compiler, else zig: ``latobs.cbackend.toolchain``) into latobs's cache folder, named by the
content it is made from; when it cannot be compiled or loaded here the Python loop runs instead
(:func:`unavailable_reason` says why).

It drives FMI 2.0 FMUs through their libraries' own functions with Real routes; the master keeps
the Python loop for FMI 3.0 FMUs, Integer or Boolean routes and fmpy's checked calls."""
from __future__ import annotations

import ctypes
import hashlib
import os
from functools import lru_cache
from pathlib import Path

SOURCE = Path(__file__).resolve().parent.parent / "native" / "master_loop.c"
#: LATOBS_MASTER_LOOP=python: always the Python loop (the reference the compiled one is tested against)
ENV = "LATOBS_MASTER_LOOP"
WHAT = ("setting inputs", "doStep", "getting outputs")


class Row(ctypes.Structure):
    _fields_ = [("fn", ctypes.c_void_p), ("component", ctypes.c_void_p), ("vr", ctypes.c_void_p),
                ("n", ctypes.c_size_t), ("row0", ctypes.c_void_p), ("stride", ctypes.c_ssize_t)]


class Step(ctypes.Structure):
    _fields_ = [("fn", ctypes.c_void_p), ("component", ctypes.c_void_p)]


class Route(ctypes.Structure):
    _fields_ = [("dst", ctypes.c_void_p), ("dst_stride", ctypes.c_ssize_t), ("dst_cols", ctypes.c_void_p),
                ("src", ctypes.c_void_p), ("src_stride", ctypes.c_ssize_t), ("src_cols", ctypes.c_void_p),
                ("noise", ctypes.c_void_p), ("noise_stride", ctypes.c_ssize_t), ("n", ctypes.c_size_t)]


_state: dict[str, str] = {}


@lru_cache(maxsize=1)
def library() -> ctypes.CDLL | None:
    """The compiled loop, loaded (once per process); None when it cannot be made here."""
    if os.environ.get(ENV, "").strip().lower() == "python":
        _state["why"] = f"{ENV}=python"
        return None
    from ..atomic import atomic_write_bytes
    from ..cbackend import toolchain
    from ..cbackend.runner import cache_dir

    platform = toolchain.host_platform()
    if platform is None:
        _state["why"] = "this machine is none of the native platforms"
        return None
    source = SOURCE.read_bytes()
    digest = hashlib.sha256(platform.encode() + b"\0" + toolchain.describe() + b"\0" + source).hexdigest()[:20]
    path = cache_dir() / "master-loop" / f"master_loop-{platform}-{digest}{toolchain.SUFFIX[platform]}"
    try:
        if not path.is_file():
            # (cached=False: the library is itself kept in the cache folder, named by its inputs)
            raw = toolchain.compile_for(platform, {"master_loop.c": source}, ["master_loop.c"], path.name,
                                        shared=True, libs=(), cached=False)
            atomic_write_bytes(path, raw, mode=0o755)
        lib = ctypes.CDLL(str(path))
    except (OSError, toolchain.ToolchainError) as exc:
        _state["why"] = f"the compiled loop cannot be made here: {exc}"
        return None
    fn = lib.latobs_master_loop
    fn.restype = ctypes.c_long
    fn.argtypes = [ctypes.c_long, ctypes.c_long, ctypes.c_void_p, ctypes.c_double,
                   ctypes.c_void_p, ctypes.c_long, ctypes.c_void_p, ctypes.c_long, ctypes.c_void_p, ctypes.c_long,
                   ctypes.c_void_p, ctypes.c_long, ctypes.POINTER(ctypes.c_int), ctypes.POINTER(ctypes.c_long),
                   ctypes.POINTER(ctypes.c_int)]
    return lib


def unavailable_reason() -> str | None:
    """Why the Python loop runs instead (None: the compiled loop is available)."""
    return None if library() is not None else _state.get("why", "unknown")


def _address(fn) -> int:
    return ctypes.cast(fn, ctypes.c_void_p).value


class Loop:
    """The compiled loop over the master's calls: ``sets``/``gets`` ((fn, component, vr address,
    count, row 0 address, row stride, port) as the master builds them), ``steps`` ((fn, component,
    port)), ``routes`` ((destination matrix, its columns, source matrix, its columns, noise matrix or
    None)); ``run(k0, k1)`` makes steps k0 .. k1-1 and returns None, or (k, what, port, status) of
    the first failed call. The matrices must outlive it."""

    def __init__(self, lib: ctypes.CDLL, t, dt: float, sets, steps, gets, routes):
        import numpy as np

        self.lib, self.dt = lib, float(dt)
        self.t = np.ascontiguousarray(t, dtype=np.float64)
        self.ports = ([s[-1] for s in sets], [s[-1] for s in steps], [g[-1] for g in gets])
        self.sets = (Row * max(1, len(sets)))(*[Row(_address(fn), c, vr, n, a, stride)
                                                for fn, c, vr, n, a, stride, _ in sets])
        self.steps = (Step * max(1, len(steps)))(*[Step(_address(fn), c) for fn, c, _ in steps])
        self.gets = (Row * max(1, len(gets)))(*[Row(_address(fn), c, vr, n, a, stride)
                                                for fn, c, vr, n, a, stride, _ in gets])
        self.keep = []
        built = []
        for dst, cols, src, src_cols, nz in routes:
            for m in (dst, src) + ((nz,) if nz is not None else ()):
                if m.dtype != np.float64 or not m.flags.c_contiguous or m.ndim != 2:
                    raise ValueError("compiled loop: a route's matrices must be C-contiguous float64 rows")
            dc, sc = np.ascontiguousarray(cols, dtype=np.intp), np.ascontiguousarray(src_cols, dtype=np.intp)
            self.keep += [dc, sc]
            built.append(Route(dst.ctypes.data, dst.strides[0], dc.ctypes.data, src.ctypes.data, src.strides[0],
                               sc.ctypes.data, nz.ctypes.data if nz is not None else None,
                               nz.strides[0] if nz is not None else 0, len(dc)))
        self.routes = (Route * max(1, len(built)))(*built)
        self.counts = (len(sets), len(steps), len(gets), len(built))
        self.what, self.which, self.status = ctypes.c_int(), ctypes.c_long(), ctypes.c_int()

    def run(self, k0: int, k1: int):
        ns, nst, ng, nr = self.counts
        k = self.lib.latobs_master_loop(k0, k1, self.t.ctypes.data, self.dt, self.sets, ns, self.steps, nst,
                                        self.gets, ng, self.routes, nr, ctypes.byref(self.what),
                                        ctypes.byref(self.which), ctypes.byref(self.status))
        if k < 0:
            return None
        what = self.what.value
        return k, WHAT[what], self.ports[what][self.which.value], self.status.value
