"""The interval observer's tables (synthesis.tables.lateral_interval_observer) and their independent
checks in the certificate: the stored step maps are eq. (23)'s exact discretisation, nonnegative,
and a corrupted table fails the certificate."""
from __future__ import annotations

import copy

import numpy as np
import pytest
import scipy.linalg

from latobs.synthesis import certificate, designs
from latobs.synthesis.table_checks import checks
from latobs.synthesis.tables import lateral_interval_observer as tables


@pytest.fixture(scope="module")
def design() -> dict:
    return designs.run("LateralIntervalObserver")


def test_tables_are_stored_and_pass_their_checks(design):
    assert design["tables"] == tables.compute(design)
    cs = checks(design)
    assert cs and all(c.passed for c in cs), [c.name for c in cs if not c.passed]
    ok, all_checks = certificate.certify(design)
    assert ok and {c.name for c in cs} <= {c.name for c in all_checks}


def test_step_maps_are_the_exact_discretisation_and_nonnegative(design):
    """Phi = exp(N h), Gam = int exp(N s) ds, Gam1, Gam2 (eq. 23 over a step) at the default step,
    against scipy's expm of the Van Loan block matrix; all entries >= 0 (N Metzler)."""
    h = design["tables"]["h0"]
    for m in design["tables"]["modes"]:
        N = np.array(m["N"])
        M = np.zeros((16, 16))
        M[:4, :4] = N
        M[:4, 4:8] = M[4:8, 8:12] = M[8:12, 12:16] = np.eye(4)
        E = scipy.linalg.expm(M * h)
        for b, got in enumerate(m["maps_h0"]):
            ref = E[:4, 4 * b:4 * b + 4]
            assert np.max(np.abs(np.array(got) - ref)) <= 1e-13 * np.max(np.abs(ref))
            assert np.min(got) >= 0.0
        off = N - np.diag(np.diag(N))
        assert off.min() >= 0.0


@pytest.mark.parametrize("corrupt", [
    lambda t: t["modes"][1]["maps_h0"][0][0].__setitem__(0, t["modes"][1]["maps_h0"][0][0][0] * (1 + 1e-6)),
    lambda t: t["modes"][0]["maps_h0"][2][1].__setitem__(1, t["modes"][0]["maps_h0"][2][1][1] * (1 + 1e-6)),
    lambda t: t["modes"][2]["N"][0].__setitem__(1, -1e-3),
    lambda t: t["modes"][0].__setitem__("rho", 0.5 * t["modes"][0]["rho"]),
    lambda t: t["model"]["A0"][2].__setitem__(0, 1.01 * t["model"]["A0"][2][0]),
    lambda t: t["stiffness"].__setitem__("k3", 1.001 * t["stiffness"]["k3"]),
    lambda t: t.__setitem__("damped", [2]),
], ids=["Phi", "Gam1", "N-not-Metzler", "rho", "A0", "k3", "damped-rows"])
def test_a_corrupted_table_fails_the_certificate(design, corrupt):
    bad = copy.deepcopy(design)
    corrupt(bad["tables"])
    assert not all(c.passed for c in checks(bad))
    assert not certificate.certify(bad)[0]


def test_bad_design_data_raises_naming_it(design):
    bad = copy.deepcopy(design)
    bad["modes"][0]["H"] = [0.0, 0.0, 0.0, 0.0]
    with pytest.raises(ValueError, match="mode 1 field H violates H = P B_j"):
        tables.compute(bad)


def test_runtime_step_maps_continue_the_tables_bit_for_bit(design):
    """The runtimes compute the step maps at other step sizes by the tables' algorithm: at the default
    step the runtime's own ``phi_gamma`` gives the stored doubles exactly (so a step of any size is
    evaluated by the same mathematics)."""
    from latobs.fmu_src.lateral_interval_observer import phi_gamma

    for m in design["tables"]["modes"]:
        assert [list(map(list, b)) for b in phi_gamma(m["N"], design["tables"]["h0"], m["eta"], order=3)] \
            == m["maps_h0"]
