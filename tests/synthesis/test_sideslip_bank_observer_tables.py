"""Paper 000's runtime tables (``synthesis.tables.sideslip_bank_observer``) and their independent
checks (``synthesis.table_checks.sideslip_bank_observer``): the stored step maps are the RK4
substeps' composite map (within the stated bound, at both ends and the center of every Taylor
interval), and a corrupted table fails the certificate."""
from __future__ import annotations

import copy
import json

import numpy as np
import pytest

from latobs.fmu_src.framework import DEFAULT_STEP
from latobs.fmu_src.sideslip_bank_observer import SwitchedPIObserver
from latobs.synthesis import certificate
from latobs.synthesis.table_checks import sideslip_bank_observer as checks_000
from latobs.synthesis.tables import sideslip_bank_observer as tables_000


def _failed(data: dict) -> list[str]:
    return [c.name for c in checks_000.checks(data) if not c.passed]


def test_tables_are_plain_data_for_the_default_step(design_speed, design_speed_eq1, design_tire):
    for design in (design_speed, design_speed_eq1, design_tire):
        tab = design["tables"]
        assert json.loads(json.dumps(tab)) == tab                 # JSON round trip, bit for bit
        assert tab["step"] == DEFAULT_STEP                        # the model description's step
        coefs = [iv["coef"] for m in tab["maps"] for iv in m["intervals"]]
        if design is design_speed:    # relaxed axle forces: a term in vx, the RK4 substeps at every step
            assert tab["first_power"] == -1 and coefs == [None] * len(tab["maps"])
        else:
            assert "first_power" not in tab and coefs and all(c is not None for c in coefs)


def test_the_stored_maps_are_the_rk4_substeps(design_speed, design_tire, built_fmus):
    """Every map of the four designs: |polynomial - numpy RK4 substep matrix^n| <= 1e-13 ||map||
    at both ends and the center of every interval (seen <= 1e-15), M(v), G(v) of eq. (5)."""
    for name in ("SideslipBankObserver", "SideslipBankObserverTire", "SideslipBankObserverPaper",
                 "SideslipBankObserverTirePaper"):
        checks = checks_000.checks(built_fmus.design(name))
        maps = [c for c in checks if "step map" in c.name]
        assert all(c.passed for c in checks), [c for c in checks if not c.passed]
        assert maps and max(c.value for c in maps) <= 1e-14
        assert len(maps) == len(built_fmus.design(name)["tables"]["maps"])


def _coef_norm(iv) -> float:
    return max(sum(abs(x) for x in row) for row in iv["coef"][0])


@pytest.mark.parametrize("corrupt", ["taylor coefficient", "fixed map", "model", "interval layout", "missing",
                                     "stale"])
def test_a_corrupted_table_fails_the_certificate(design_speed, design_speed_eq1, built_fmus, corrupt):
    d = copy.deepcopy({"fixed map": built_fmus.design("SideslipBankObserverPaper"), "taylor coefficient": design_speed_eq1,
                       "model": design_speed_eq1}.get(corrupt, design_speed))
    tab = d["tables"]
    assert not _failed(d)
    if corrupt in ("taylor coefficient", "fixed map"):
        iv = tab["maps"][1]["intervals"][-1]
        iv["coef"][0][2][3] += 1e-10 * _coef_norm(iv)             # one entry of [Phi | Gam], 1e-10 relative
        want = "tables: step map mode 2"
    elif corrupt == "model":
        tab["M"][0][0][1][0] *= 1 + 1e-9
        want = "tables: M(v), G(v)"
        assert all("mode 1" in n for n in _failed(d))
    elif corrupt == "interval layout":
        tab["maps"][0]["scale"] *= 1.01
        want = "tables: model speed and Taylor intervals cover the range of mode 1"
    elif corrupt == "stale":                                     # the design changed, its tables not
        d["validity"]["alpha_max"] *= 1.1
        want = "tables: N, switching, grid, validity"
    else:
        d["tables"] = {}
        want = "tables: present"
    assert any(name.startswith(want) for name in _failed(d)), _failed(d)
    ok, _ = certificate.certify(d)
    assert not ok


def test_design_errors_name_the_culprit(design_speed):
    d = copy.deepcopy(design_speed)
    d["switching"]["edges"] = d["switching"]["edges"][::-1]
    with pytest.raises(ValueError, match="switching.edges"):
        tables_000.compute(d)
    d = copy.deepcopy(design_speed)
    d["runtime"]["max_step"] = 0.05
    with pytest.raises(ValueError, match="max_step"):
        tables_000.compute(d)


def test_a_term_in_vx_needs_measured_speeds_and_a_known_first_power(design_speed):
    """The model with relaxed axle forces (structure.first_power -1): its tables run the RK4 substeps,
    which needs every mode's model at the measured speed; a first power other than 0 or -1 is named."""
    d = copy.deepcopy(design_speed)
    d["modes"][1]["model_speed"] = {"kind": "fixed", "value": d["modes"][1]["scheduling"]["value"]}
    with pytest.raises(ValueError, match="term in vx needs modes with a measured model speed"):
        tables_000.compute(d)
    for bad in (1, -2, True, "x"):
        d = copy.deepcopy(design_speed)
        d["structure"]["first_power"] = bad
        with pytest.raises(ValueError, match="structure.first_power"):
            tables_000.compute(d)


def test_runtime_refuses_a_design_without_tables(design_speed):
    d = {k: v for k, v in design_speed.items() if k != "tables"}
    with pytest.raises(ValueError, match="tables"):
        SwitchedPIObserver(d, {})


def test_taylor_intervals_cover_the_clamped_range(design_tire):
    """Measured-speed maps: K equal intervals over [1/hi, 1/lo], centers in the middle."""
    tab = design_tire["tables"]
    for m, mode in zip(tab["maps"], tab["modes"] * 2):
        lo, hi = mode["vx_range"]
        K = len(m["intervals"])
        assert m["v_lo"] == 1.0 / hi and m["scale"] == K / (1.0 / lo - 1.0 / hi)
        centers = np.array([iv["center"] for iv in m["intervals"]])
        np.testing.assert_allclose(centers, 1.0 / hi + (np.arange(K) + 0.5) / m["scale"], rtol=1e-14)


def test_the_series_arrays_multiply_as_the_runtimes_left_fold():
    """``series._mm`` (numpy, one column of A at a time) gives, bit for bit, the products added
    from the left from 0.0 of ``series.matmul`` (``fmu_src.linalg.dot``); ``series._norm`` those of
    ``norm_inf``: on random matrices of mixed magnitudes and signs, with zeros of both signs,
    subnormal and huge entries (where a reordered or fused sum would differ)."""
    from latobs.synthesis.tables import series

    rng = np.random.default_rng(7)
    bits = lambda M: np.asarray(M, float).view(np.uint64)            # noqa: E731
    for _ in range(200):
        r, k, c = rng.integers(1, 9, size=3)
        A = rng.standard_normal((r, k)) * 10.0 ** rng.integers(-300, 300, size=(r, k))
        B = rng.standard_normal((k, c)) * 10.0 ** rng.integers(-8, 8, size=(k, c))
        A[rng.random((r, k)) < 0.2] = -0.0
        B[rng.random((k, c)) < 0.2] = 0.0
        want = series.matmul(A.tolist(), B.tolist())
        assert np.array_equal(bits(series._mm(A, B)), bits(want))
        assert series._norm(A) == series.norm_inf(A.tolist())
    # from the left: ((1e16 + 1) - 1e16) + 1 = 1 (a compensated or pairwise sum gives 2)
    assert series._mm(np.array([[1e16, 1.0, -1e16, 1.0]]), np.ones((4, 1)))[0, 0] == 1.0
