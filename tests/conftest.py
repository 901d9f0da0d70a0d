"""Shared fixtures: designs are solved once per test run, FMUs built once per test run (shared by the workers).

``built_fmus`` is THE session build: every FMU that ``latobs build`` makes (the observers of
``latobs.packaging.OBSERVERS``, designed by ``designs.run`` as ``latobs.pipeline.build`` does, and
the plants of ``latobs.packaging.PLANTS``), each designed and packaged at most once per session,
on first use, into one temporary folder. Tests that need one of these FMUs or its design dict
take them from there instead of designing again (the scheduled paper-002 estimator alone takes
~40 s to design); ``fmu_dir`` holds paper 000's four observers and CarPlant from it.
"""
from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

# numpy's and scipy's BLAS (OpenBLAS) in one thread per process, set before either loads it (the
# workers and the subprocesses they start): a run already has a worker per core, and OpenBLAS's own
# threads beside the other worker's only cost CPU (`latobs identify` alone: 6.5 s of CPU with them,
# 4.9 s without). A value set outside the run is kept.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import pytest  # noqa: E402

from latobs import packaging, pipeline  # noqa: E402
from latobs.synthesis import designs

#: every FMU ``latobs build`` makes (observers, then plants): tests parametrised over it check a
#: new FMU automatically
FMU_NAMES = [*packaging.OBSERVERS, *packaging.PLANTS]


def _has_c_model(name: str) -> bool:
    from latobs import cbackend

    kind = packaging.OBSERVERS.get(name) or packaging.PLANTS[name]
    return cbackend.emitter(kind.model_module) is not None


#: the FMUs of the native C backend (those whose runtime has a C model)
C_NAMES = [n for n in FMU_NAMES if _has_c_model(n)]


def _host_only() -> list[str] | None:
    from latobs.cbackend import toolchain

    host = toolchain.host_platform()
    return [host] if host else None


#: ``platforms`` of a test's own native build that only runs on this machine (a design variant, a
#: plant for another vehicle): this machine's binary alone, a fifth of the compilations. The
#: binaries of every platform are those of the session build (``built_fmus``), which
#: test_cross_run, test_fmi3 and test_check run under Wine and qemu. None where this machine is
#: not a platform of ``toolchain.PLATFORMS``: all of them.
HOST_ONLY = _host_only()


#: whether the workers build their shares of every FMU at the start (a whole run: set at collection)
_BUILD_SHARES = {"on": False}


def pytest_collection_modifyitems(config, items):
    """A run where many tests use the session build (the whole suite, not a few tests) on several
    workers: each worker starts by building its share of the FMUs (``SessionBuild.build_share``).

    The order in which the workers take the test files (``--dist loadfile``, ``--no-loadscope-reorder``
    in pyproject.toml): first the files marked ``schedule_first`` (a few tests of seconds to a minute
    each: taken last, one of them kept a worker busy ~12 s after the other had finished), then the
    others by their number of tests, most first (pytest-xdist's own reordering); each file's tests
    in their order."""
    users = sum("built_fmus" in getattr(item, "fixturenames", ()) for item in items)
    _BUILD_SHARES["on"] = users >= 200 and int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1")) > 1
    count, first = {}, set()
    for item in items:
        f = item.nodeid.split("::")[0]
        count[f] = count.get(f, 0) + 1
        if item.get_closest_marker("schedule_first") is not None:
            first.add(f)
    rank = {f: (f not in first, -n) for f, n in count.items()}
    items.sort(key=lambda item: rank[item.nodeid.split("::")[0]])       # (stable: a file's order kept)


#: (name, backend) of every FMU in both backends, ids "NAME" (pythonfmu) and "NAME[c]" (native C):
#: the interop checks and the fuzz run on each; ``built_fmus.get(name, backend)`` gives the FMU
FMU_VARIANTS = ([pytest.param((n, "python"), id=n) for n in FMU_NAMES]
                + [pytest.param((n, "c"), id=f"{n}[c]") for n in C_NAMES])


class SessionBuild:
    """Every FMU of ``latobs build`` (default vehicles), designed and packaged on first use.

    ``design(name)``  the design dict of an observer, as ``latobs design`` writes it (shared
                      by the whole session: copy it before changing it)
    ``path(name)``    the FMU, built into ``out`` as ``latobs build`` builds it (``pipeline.build``:
                      observers from their design file ``out/NAME.design.json``, re-certified by
                      the packaging step; every FMU with its reference experiment inside)
    ``all()``         {name: path} of every FMU in :data:`FMU_NAMES`
    ``c_path(name)``  the same FMU built by the native C backend into ``out/c`` (skips the test
                      when this machine cannot build it: no C compiler, or no C model yet)
    ``c3_path(name)`` its FMI 3.0 twin, ``latobs build --fmi 3`` into ``out/c`` (so ``out/c/fmi3``)
    """

    def __init__(self, out: Path):
        self.out = Path(out)
        self._designs: dict[str, dict] = {}
        self._paths: dict[str, Path] = {}
        self._c_paths: dict[str, Path] = {}
        self._c3_paths: dict[str, Path] = {}

    def design(self, name: str, vehicle: str | None = None, runtime_facts: bool = True) -> dict:
        """(``vehicle``: a shipped set other than the design's default, also solved once per run.
        ``runtime_facts=False``: without what only running its runtime decides, e.g. paper 001's
        longest step, whose search takes ~15 s for a 12-band design: ``pipeline.solve``.)"""
        if name not in packaging.OBSERVERS:
            raise KeyError(f"{name!r} is not an observer of latobs.packaging.OBSERVERS")
        key = (name if vehicle is None else f"{name}_{vehicle}") + ("" if runtime_facts else "~without-facts")
        if key not in self._designs:
            # as `latobs design` writes it (pipeline.solve): what only running the runtime decides
            # included; solved by the first worker that needs it (under a lock of its own: the other
            # workers meanwhile solve other designs), read back from its file by all
            from latobs.atomic import atomic_write_text, locked_folder
            from latobs.synthesis import design_file

            folder = self.out / "designs" / key
            with locked_folder(folder, "design"):
                path = folder / "design.json"
                if not path.is_file():
                    from latobs import pipeline

                    data = pipeline.solve(name, vehicle, quiet=True, runtime_facts=runtime_facts)   # (the run's cache)
                    atomic_write_text(path, design_file.dumps(data))
                self._designs[key] = json.loads(path.read_text(encoding="utf-8"))
        return self._designs[key]

    def path(self, name: str) -> Path:
        if name not in self._paths:
            self._paths[name] = self._build(name, "python", self.out)
        return self._paths[name]

    def _build(self, name: str, backend: str, out: Path, fmi: int = 2) -> Path:
        """``latobs build NAME --backend BACKEND --out OUT [--fmi 3]``, the design solved once per session.

        Each FMU is built in a folder of its own (``parts``; its plant copied in first, so that its
        reference experiment runs beside this session's plant, as in one ``out``), so that the
        workers build different FMUs at once (``latobs build`` locks the folder it writes); the
        FMU and its design file are then installed into OUT, where the tests find them together."""
        import shutil

        from latobs import pipeline
        from latobs.atomic import atomic_path, locked_folder
        from latobs.synthesis import design_file

        part = self.out / "parts" / f"{backend}-fmi{fmi}" / name
        with locked_folder(part, "build"):
            if name in packaging.OBSERVERS:
                beside = pipeline.reference_plant(name, None)
                if beside is not None and beside[1] is None:    # its reference runs beside this session's plant
                    plant = self.c3_path(beside[0]) if fmi == 3 else self.get(beside[0], backend)
                    there = pipeline.fmi_folder(part, fmi) / plant.name
                    if not there.is_file():
                        there.parent.mkdir(parents=True, exist_ok=True)
                        shutil.copyfile(plant, there)
                design_file.write(self.design(name), part)
            elif name not in packaging.PLANTS:
                raise KeyError(f"{name!r} is not an FMU of latobs build ({', '.join(FMU_NAMES)})")
            built, = pipeline.build([name], None, part, backend, fmi=fmi)
            assert built == pipeline.fmi_folder(part, fmi) / f"{name}.fmu", built
            dest = pipeline.fmi_folder(out, fmi)
            with locked_folder(dest, "build"):
                for f in (built.with_name(f"{name}.design.json"), built):     # the FMU last
                    if f.is_file():
                        with atomic_path(dest / f.name) as tmp:
                            shutil.copyfile(f, tmp)
        return dest / f"{name}.fmu"

    def build_share(self, worker: int, workers: int) -> None:
        """Build this worker's share of every FMU (both backends, with its design), the shares
        balanced by ``latobs.pipeline.build_seconds`` (the catalogue's estimates): at the start of
        a whole run the workers build different FMUs at once instead of queueing for the same ones
        (the tests ask for them in one order)."""
        load, share = [0.0] * workers, [[] for _ in range(workers)]
        for name in sorted(FMU_NAMES, key=lambda n: (-pipeline.build_seconds(n), n)):
            w = load.index(min(load))
            load[w] += pipeline.build_seconds(name)
            share[w].append(name)
        from latobs import cbackend

        for name in sorted(share[worker], key=lambda n: n not in packaging.PLANTS):    # plants first
            kind = packaging.OBSERVERS.get(name) or packaging.PLANTS[name]
            try:
                self.path(name)
                if name in C_NAMES and cbackend.unavailable_reason(kind.model_module) is None:
                    self.c_path(name)
            except Exception:      # reported by the tests that need this FMU (they build it again)
                pass

    def all(self) -> dict[str, Path]:
        return {name: self.path(name) for name in FMU_NAMES}

    def get(self, name: str, backend: str = "python") -> Path:
        """The FMU ``name`` of ``backend`` ("python" or "c")."""
        return self.c_path(name) if backend == "c" else self.path(name)

    def c_path(self, name: str) -> Path:
        if name not in self._c_paths:
            from latobs import cbackend

            kind = packaging.OBSERVERS.get(name) or packaging.PLANTS.get(name)
            if kind is None:
                raise KeyError(f"{name!r} is not an FMU of latobs build ({', '.join(FMU_NAMES)})")
            why = cbackend.unavailable_reason(kind.model_module)
            if why:
                pytest.skip(f"{name}: no native C FMU here: {why}")
            self._c_paths[name] = self._build(name, "c", self.out / "c")
        return self._c_paths[name]

    def c3_path(self, name: str) -> Path:
        if name not in self._c3_paths:
            self.c_path(name)          # (skips when there is no native FMU here)
            self._c3_paths[name] = self._build(name, "c", self.out / "c", fmi=3)
        return self._c3_paths[name]


@pytest.fixture(scope="session", autouse=True)
def _session_cache(tmp_path_factory):
    """latobs's cache (``latobs.cache``) in the run's temporary folder, shared by the workers (and
    the subprocesses they start): a test run starts from an empty cache, as on a fresh machine,
    and never reads or fills the user's. Designs and builds run in one process each
    (``LATOBS_JOBS=1``): the run already has a worker per core."""
    from latobs import cache

    from latobs.synthesis import lmi

    import tempfile

    base = tmp_path_factory.getbasetemp()
    shared = base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base
    saved = {k: os.environ.get(k) for k in (cache.ENV_DIR, cache.ENV_OFF, lmi.JOBS_ENV, "TMPDIR")}
    os.environ[cache.ENV_DIR] = str(shared / "latobs-cache")
    # every temporary file of the run (fmpy's extract(), the subprocesses' too) inside the run's
    # folder, which pytest removes: a run leaves nothing in the machine's temporary folder
    scratch = base / "tmp"
    scratch.mkdir(exist_ok=True)
    saved_tempdir, tempfile.tempdir = tempfile.tempdir, str(scratch)
    os.environ["TMPDIR"] = str(scratch)
    os.environ.pop(cache.ENV_OFF, None)
    # one process per design and build: the run is already one worker per core (the tests of the
    # parallel paths set LATOBS_JOBS themselves)
    os.environ[lmi.JOBS_ENV] = "1"
    yield
    tempfile.tempdir = saved_tempdir
    for k, v in saved.items():
        if v is None:
            os.environ.pop(k, None)
        else:
            os.environ[k] = v


@pytest.fixture(scope="session")
def built_fmus(tmp_path_factory) -> SessionBuild:
    """One build for the whole test run: with pytest-xdist every worker builds into the same folder
    (the run's temporary folder, not a worker's), so that a design is solved and an FMU built once
    per run, not once per worker: ``latobs build`` locks the folder while it writes and reuses an
    FMU another worker built from identical inputs."""
    base = tmp_path_factory.getbasetemp()
    shared = base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base
    out = shared / "session-fmus"
    out.mkdir(exist_ok=True)
    build = SessionBuild(out)
    if _BUILD_SHARES["on"]:
        worker = os.environ.get("PYTEST_XDIST_WORKER", "gw0")
        build.build_share(int(worker.removeprefix("gw")), int(os.environ["PYTEST_XDIST_WORKER_COUNT"]))
    return build


def bits(x) -> bytes:
    """The float64 bytes of an array: two are equal only when the values are, bit for bit."""
    import numpy as np

    return np.ascontiguousarray(np.asarray(x, dtype=float)).tobytes()


@pytest.fixture
def fmi3_host():
    """Skips a test of FMI 3.0 FMUs on a machine that none of their platform folders runs on."""
    from latobs.cbackend import fmi3

    if fmi3.host_folder() is None:
        pytest.skip("this machine is none of the FMI 3.0 platforms")


@pytest.fixture(scope="session")
def design_speed(built_fmus) -> dict:
    return built_fmus.design("SideslipBankObserver")


@pytest.fixture(scope="session")
def design_speed_eq1(built_fmus) -> dict:
    """The speed-mode default on paper 000's own model, eq. (1) (``tire_relaxation=False``: static tire
    forces, polynomials in 1/Vx): the design the runtime's Taylor tables and fixed-speed modes are
    exercised on (the default's model, with a term in Vx, runs the RK4 substeps). Solved through the
    run's cache."""
    from latobs import pipeline

    return pipeline.solve("SideslipBankObserver", None, quiet=True, tire_relaxation=False)


@pytest.fixture(scope="session")
def design_speed_other_gains(built_fmus) -> dict:
    """The speed-mode default with another pole region (alpha = 1 /s, radius 90 rad/s): the same
    model and name, other gains. Solved once per run (the run's cache), with its runtime facts."""
    from latobs import pipeline

    return pipeline.solve("SideslipBankObserver", None, quiet=True, alpha=1.0, radius=90.0)


@pytest.fixture(scope="session")
def design_tire(built_fmus) -> dict:
    return built_fmus.design("SideslipBankObserverTire")


@pytest.fixture(scope="session")
def fmu_dir(built_fmus, tmp_path_factory):
    """A folder holding the paper-000 observer FMUs (the two defaults and the two paper-faithful
    designs, the default observers of `latobs validate`) and the CarPlant FMU of the session build
    (hard links, or copies), and nothing else: what a test builds into it stays out of the build."""
    out = tmp_path_factory.mktemp("fmus_000")
    for name in ("SideslipBankObserver", "SideslipBankObserverTire", "SideslipBankObserverPaper",
                 "SideslipBankObserverTirePaper", "CarPlant"):
        src = built_fmus.path(name)
        try:
            os.link(src, out / src.name)
        except OSError:
            shutil.copy2(src, out / src.name)
    return out


# fmpy's logger proxy -------------------------------------------------------------------------
# fmpy formats an FMU's printf-style messages in a native proxy (``fmpy.logging.addLoggerProxy``)
# that forwards them to ONE process-wide Python logger: the one of the last callbacks registered.
# fmpy's default callbacks (``instantiate()`` without ``callbacks``, ``simulate_fmu`` without
# ``logger``) go through the same proxy. ``simulate_fmu(logger=f)`` registers callbacks that are
# garbage collected when it returns: from then on, the first message of an FMU instantiated with
# the defaults calls freed memory and the process dies (SIGSEGV). Callbacks made here stay alive
# for the process, and every test starts with fmpy's own printing logger registered again.

_LIVE_CALLBACKS: list = []     # every fmpy_callbacks() result, and the default logger: never freed


def fmpy_callbacks(logger=None):
    """fmpy ``fmi2CallbackFunctions`` whose logger, ``logger(env, instance, status, category,
    message)`` (default: fmpy's printing one), is registered with fmpy's proxy and kept alive for
    the process: pass them to ``FMU2Slave``/``FMU2Model.instantiate(callbacks=...)``. The proxy
    sends every fmpy-instantiated FMU's messages to the last logger registered."""
    from ctypes import byref

    from fmpy import calloc, free
    from fmpy.fmi1 import printLogMessage
    from fmpy.fmi2 import (fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE, fmi2CallbackFunctions,
                           fmi2CallbackLoggerTYPE)
    from fmpy.logging import addLoggerProxy

    cb = fmi2CallbackFunctions()
    cb.logger = fmi2CallbackLoggerTYPE(printLogMessage if logger is None else logger)
    cb.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
    cb.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
    addLoggerProxy(byref(cb))
    _LIVE_CALLBACKS.append(cb)
    return cb


_DEFAULT_LOGGER: list = []     # the one process-lived printing logger restore_fmpy_logger registers


def restore_fmpy_logger() -> None:
    """Register fmpy's printing logger again (one object for the process) with fmpy's proxy, so
    that fmpy's default callbacks never reach a logger freed since (see above)."""
    from ctypes import byref

    from fmpy.fmi1 import printLogMessage
    from fmpy.fmi2 import fmi2CallbackFunctions, fmi2CallbackLoggerTYPE
    from fmpy.logging import addLoggerProxy

    if not _DEFAULT_LOGGER:
        _DEFAULT_LOGGER.append(fmi2CallbackLoggerTYPE(printLogMessage))
    cb = fmi2CallbackFunctions()
    cb.logger = _DEFAULT_LOGGER[0]
    addLoggerProxy(byref(cb))     # the proxy keeps the function pointer only; _DEFAULT_LOGGER owns it


@pytest.fixture(autouse=True)
def _live_fmpy_logger():
    """Every test starts with a live logger behind fmpy's proxy (a test before may have freed one)."""
    restore_fmpy_logger()
    yield


def fmutool() -> str:
    """The ``fmutool`` executable of fmu-manipulation-toolbox (a test extra) beside this Python."""
    import shutil
    import sys

    exe = Path(sys.executable).with_name("fmutool")
    found = str(exe) if exe.is_file() else shutil.which("fmutool")
    assert found, "fmutool (fmu-manipulation-toolbox, a test extra) is not installed"
    return found
