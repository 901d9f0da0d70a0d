"""Shared fixtures: designs are solved once per session, FMUs built once per session.

``built_fmus`` is THE session build: every FMU that ``latobs build`` makes (the observers of
``latobs.packaging.OBSERVERS``, designed by ``designs.run`` as ``latobs.pipeline.build`` does, and
the plants of ``latobs.packaging.PLANTS``), each designed and packaged at most once per session,
on first use, into one temporary folder. Tests that need one of these FMUs or its design dict
take them from there instead of designing again (the scheduled paper-002 estimator alone takes
~40 s to design); ``fmu_dir`` holds paper 000's four observers and CarPlant from it.
"""
from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest

from latobs import packaging
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
#: (name, backend) of every FMU in both backends, ids "NAME" (pythonfmu) and "NAME[c]" (native C):
#: the interop checks and the fuzz run on each; ``built_fmus.get(name, backend)`` gives the FMU
FMU_VARIANTS = ([pytest.param((n, "python"), id=n) for n in FMU_NAMES]
                + [pytest.param((n, "c"), id=f"{n}[c]") for n in C_NAMES])


class SessionBuild:
    """Every FMU of ``latobs build`` (default vehicles), designed and packaged on first use.

    ``design(name)``  the design dict of an observer, as ``designs.run(name)`` returns it (shared
                      by the whole session: copy it before changing it)
    ``path(name)``    the FMU, built into ``out`` as ``latobs build`` builds it (``pipeline.build``:
                      observers from their design file ``out/NAME.design.json``, re-certified by
                      the packaging step; every FMU with its reference experiment inside)
    ``all()``         {name: path} of every FMU in :data:`FMU_NAMES`
    ``c_path(name)``  the same FMU built by the native C backend into ``out/c`` (skips the test
                      when this machine cannot build it: no C compiler, or no C model yet)
    """

    def __init__(self, out: Path):
        self.out = Path(out)
        self._designs: dict[str, dict] = {}
        self._paths: dict[str, Path] = {}
        self._c_paths: dict[str, Path] = {}

    def design(self, name: str) -> dict:
        if name not in packaging.OBSERVERS:
            raise KeyError(f"{name!r} is not an observer of latobs.packaging.OBSERVERS")
        if name not in self._designs:
            self._designs[name] = designs.run(name)
        return self._designs[name]

    def path(self, name: str) -> Path:
        if name not in self._paths:
            self._paths[name] = self._build(name, "python", self.out)
        return self._paths[name]

    def _build(self, name: str, backend: str, out: Path) -> Path:
        """``latobs build NAME --backend BACKEND --out OUT``, the design solved once per session."""
        from latobs import pipeline
        from latobs.synthesis import design_file

        if name in packaging.OBSERVERS:
            beside = pipeline.reference_plant(name, None)
            if beside is not None and beside[1] is None:    # its reference runs beside this session's plant
                self.get(beside[0], backend)
            design_file.write(self.design(name), out)
        elif name not in packaging.PLANTS:
            raise KeyError(f"{name!r} is not an FMU of latobs build ({', '.join(FMU_NAMES)})")
        path, = pipeline.build([name], None, out, backend)
        assert path == out / f"{name}.fmu", path
        return path

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


@pytest.fixture(scope="session")
def built_fmus(tmp_path_factory) -> SessionBuild:
    return SessionBuild(tmp_path_factory.mktemp("fmus"))


@pytest.fixture(scope="session")
def design_speed(built_fmus) -> dict:
    return built_fmus.design("SideslipBankObserver")


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
