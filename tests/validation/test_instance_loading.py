"""The harness's FMU instances load their FMI functions as fmpy does: fmpy inspects the Python
signatures of every method of every new slave; ``instance._fast_loading`` reads them once per
process and gives every later instance the same table for its own library."""
from __future__ import annotations

import pytest
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave

from latobs.validation import instance


def _table(slave) -> dict:
    return {name: (f.__name__, getattr(f, "argnames", None), tuple(f.argtypes or ()), f.restype)
            for name, f in slave._functions.items()}


def _slaves(cls_fmpy, cls_fast, path, tmp_path):
    d = extract(str(path), unzipdir=str(tmp_path / "x"))
    md = read_model_description(d)
    kw = dict(guid=md.guid, unzipDirectory=d, modelIdentifier=md.coSimulation.modelIdentifier, instanceName="i")
    return [cls(**kw) for cls in (cls_fmpy, cls_fast, cls_fast)]


@pytest.mark.parametrize("fmi", [2, 3])
def test_every_instance_gets_fmpys_own_function_table(built_fmus, fmi, tmp_path, monkeypatch):
    """fmpy's table of the first slave, the first fast one (fmpy's loader) and a second fast one
    (the remembered table, its library's own function pointers): the same names, C symbols,
    argument names and types and result types, and the fast class keeps fmpy's class name."""
    if fmi == 2:
        base, fast, path = FMU2Slave, instance._Slave2, built_fmus.c_path("SideslipBankObserver")
    else:
        from fmpy.fmi3 import FMU3Slave

        base, fast, path = FMU3Slave, instance._slave3(), built_fmus.c3_path("SideslipBankObserver")
    monkeypatch.setattr(instance, "_FUNCTIONS", {})
    plain, first, second = _slaves(base, fast, path, tmp_path)
    try:
        assert fast.__name__ == base.__name__ and issubclass(fast, base)
        assert len(plain._functions) > 20
        assert _table(first) == _table(plain) == _table(second)
        assert all(second._functions[n] is not first._functions[n] for n in first._functions)
        # a call through the remembered table works: fmi2GetVersion / fmi3GetVersion
        assert second._functions[f"fmi{fmi}GetVersion"]().decode().startswith(str(fmi))
    finally:
        for s in (plain, first, second):
            s.freeLibrary()


@pytest.mark.parametrize("fmi", [2, 3])
def test_the_harness_extracts_what_this_platform_runs(built_fmus, fmi, tmp_path):
    """``instance.extract`` of a native FMU (four platforms' binaries and its C sources inside):
    all but its sources, documentation, extra folder and other platforms' binaries; the FMU runs
    from there."""
    import fmpy
    import zipfile

    path = built_fmus.c_path("CarPlant") if fmi == 2 else built_fmus.c3_path("CarPlant")
    names = zipfile.ZipFile(path).namelist()
    mine = f"binaries/{fmpy.platform if fmi == 2 else fmpy.platform_tuple}/"
    assert any(n.startswith("sources/") for n in names) and any(
        n.startswith("binaries/") and not n.startswith(mine) for n in names)
    folder = tmp_path / "x"
    assert instance.extract(str(path), str(folder)) == str(folder)
    got = sorted(p.relative_to(folder).as_posix() for p in folder.rglob("*") if p.is_file())
    skipped = ("sources/", "documentation/", "extra/", "binaries/")
    assert got == sorted(n for n in names if not n.endswith("/") and (not n.startswith(skipped) or n.startswith(mine)))
    assert "modelDescription.xml" in got and any(n.startswith(mine) for n in got)
    f = instance.FmuInstance("plant", path, str(folder))
    try:
        out = f.start()
        f.do_step(0.0, 0.01)
        assert out and all(v == v for v in out.values())
    finally:
        f.close()
