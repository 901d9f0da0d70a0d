"""The tables of paper 002's estimators, the Kalman peer, paper 003's observer and the motorcycle
plant (``synthesis.tables``) pass their independent checks (``synthesis.table_checks``), and a
perturbed table fails them (a corrupted design or plant file is never packaged)."""
from __future__ import annotations

import copy

import pytest

from latobs import packaging
from latobs.synthesis import table_checks, tables
from latobs.synthesis.params import load_vehicle

# small designs written here (no LMI solve): the tables and their checks read only these keys
TF = {"paper": "002", "kind": "fixed_order", "estimator": {"num": [0.5, 0.02], "den": [4.0, 1.3, 0.05]}}
TF_SCHEDULED = {"paper": "002", "kind": "fixed_order",
                "estimators": [{"num": [0.5, 0.02], "den": [4.0, 1.3, 0.05], "vx_band": [10.0, 20.0]},
                               {"num": [0.4, 0.01], "den": [6.0, 1.9, 0.05], "vx_band": [20.0, 30.0]}]}


def _kalman():
    return {"paper": "002", "kind": "kalman_baseline", "name": "K", "vehicle": load_vehicle("mbds_250lm").as_dict(),
            "noise": {"q": [[0.1, 0.0], [0.0, 1e-4]], "r": [[10.0, 0.0], [0.0, 1e-4]]}}


def _motorcycle_observer(built_fmus):
    d = copy.deepcopy(built_fmus.design("MotorcycleFaultObserverPaper"))
    d.pop("tables", None)
    return d


def _failed(data: dict) -> list[str]:
    return [c.name for c in table_checks.checks(data) if not c.passed]


def _perturb(data: dict, path: tuple, rel: float = 1e-6) -> dict:
    bad = copy.deepcopy(data)
    node = bad["tables"]
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = node[path[-1]] * (1.0 + rel) + rel
    return bad


CASES = [  # (data factory, table entry perturbed)
    (lambda _: dict(TF), ("bands", 0, "Phi_h0", 1, 0)),
    (lambda _: dict(TF), ("bands", 0, "C", 1)),
    (lambda _: dict(TF), ("bands", 0, "a0")),
    (lambda _: dict(TF_SCHEDULED), ("bands", 1, "Gam_h0", 1)),
    (lambda _: dict(TF_SCHEDULED), ("edges", 1)),
    (lambda _: _kalman(), ("a", 3)),
    (lambda _: _kalman(), ("b", 0)),
    (lambda _: _kalman(), ("vx_max",)),
    (_motorcycle_observer, ("modes", 0, "map_h0", 2, 3)),
    (_motorcycle_observer, ("modes", 1, "M", 0, 0)),
    (_motorcycle_observer, ("modes", 2, "F", 1, 5)),
    (_motorcycle_observer, ("hysteresis",)),
    (lambda _: packaging.plant_data("sharp_motorcycle"), ("Minv", 1, 2)),
    (lambda _: packaging.plant_data("sharp_motorcycle"), ("kt",)),
]


@pytest.mark.parametrize("make, path", CASES, ids=["/".join(map(str, p)) for _, p in CASES])
def test_stored_tables_pass_and_a_perturbed_entry_fails(make, path, request):
    data = make(request.getfixturevalue("built_fmus") if make is _motorcycle_observer else None)
    data.pop("tables", None)
    tables.attach(data)
    assert table_checks.checks(data) and not _failed(data)
    assert _failed(_perturb(data, path))


def test_malformed_tables_fail_without_crashing():
    data = tables.attach(dict(TF))
    bad = copy.deepcopy(data)
    bad["tables"]["bands"][0]["Phi_h0"] = [[1.0]]          # wrong shape
    assert any("step maps" in n for n in _failed(bad))


def test_plant_data_with_failing_tables_is_refused(monkeypatch):
    from latobs.synthesis.tables import motorcycle_plant

    real = motorcycle_plant.compute
    monkeypatch.setattr(motorcycle_plant, "compute", lambda data: {**real(data), "kt": real(data)["kt"] * 1.01})
    with pytest.raises(packaging.PackagingError, match="kt"):
        packaging.plant_data("sharp_motorcycle")
