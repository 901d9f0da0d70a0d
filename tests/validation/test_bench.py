"""`latobs bench` (issue 12): the LMI solver choice, the pairings, the tables. No timing assertion:
a benchmark is not a test; these check what it measures and that it reports every row."""
from __future__ import annotations

import json
from types import SimpleNamespace

import pytest

from latobs import bench
from latobs.synthesis import designs, lmi


def _tiny_problem():
    import cvxpy as cp

    x = cp.Variable((2, 2), symmetric=True)
    return cp.Problem(cp.Minimize(cp.trace(x)), [x >> 0, x[0, 0] >= 1, x[1, 1] >= 2])


def test_using_scs_solves_with_scs_and_restores_clarabel():
    prob = _tiny_problem()
    with lmi.using("scs") as usage:
        assert lmi.current() == "SCS" and usage.name == "SCS"
        assert usage.settings["eps_abs"] == usage.settings["eps_rel"] == 1e-9
        status, seconds = lmi.solve(prob)
    assert prob.solver_stats.solver_name == "SCS"
    assert lmi.solved(status) and prob.value == pytest.approx(3.0, abs=1e-6)
    assert len(usage.calls) == 1 and usage.calls[0][0] == status and usage.seconds == pytest.approx(seconds)
    assert lmi.current() == "CLARABEL"              # the block's choice does not leak
    info = {}
    lmi.solve(prob, info)
    assert prob.solver_stats.solver_name == "CLARABEL" and info["solver"] == "CLARABEL"


def test_using_passes_settings_through_to_the_solver():
    prob = _tiny_problem()
    with lmi.using("SCS", max_iters=3):             # far too few iterations: SCS stops at the cap
        lmi.solve(prob)
    assert prob.solver_stats.solver_name == "SCS" and prob.solver_stats.num_iters <= 3


def test_an_unknown_solver_is_a_value_error_naming_it():
    with pytest.raises(ValueError, match="'MOSEK'.*CLARABEL, SCS"):
        with lmi.using("MOSEK"):
            pass
    assert lmi.current() == "CLARABEL"


def test_a_design_records_the_solver_it_was_solved_with():
    """The cheapest LMI design (paper 001, one small LMI problem) with each solver: the design dict
    names the solver actually used, not a hard-coded one."""
    from latobs.synthesis.params import load_vehicle

    entry = designs.get("LateralIntervalObserver")
    veh = load_vehicle(entry.default_vehicle)
    for solver in ("SCS", "CLARABEL"):
        with lmi.using(solver) as usage:
            data = entry.solve(veh, entry.options(entry.name))
        assert data["solver"]["name"] == solver and usage.calls


def test_lmi_row_certifies_as_the_pipeline_does():
    """A design the pipeline certifies is a certified row (its tables attached, as designs.run)."""
    row = bench.lmi_row("SideslipBankObserverPaper", "CLARABEL")
    assert row["result"] == "certified" and row["checks_passed"] == row["checks_total"] > 0, row


def test_lmi_row_reports_a_certificate_failure_and_a_solver_failure(monkeypatch):
    """A design that fails is a row with its reason, never a crash."""
    from latobs.synthesis import certificate, tables

    class DesignError(RuntimeError):
        pass

    def solve_ok(vehicle, opts):
        lmi.solve(_tiny_problem())
        return {"name": "Fake", "gamma": 0.5, "solver": {"name": lmi.current(), "status": "optimal", "seconds": 0.0}}

    def solve_fails(vehicle, opts):
        raise DesignError("LMI (20) infeasible")

    base = designs.get("LateralIntervalObserver")
    check = SimpleNamespace(name="LMI (20) on the stored P", value=0.02, limit=0.0, passed=False)
    monkeypatch.setattr(certificate, "certify", lambda data: (False, [check]))
    monkeypatch.setattr(tables, "attach", lambda data: data)          # a fake design has no runtime
    monkeypatch.setitem(designs.DESIGNS, "Fake", base.__class__("Fake", "001", "sedan", "", base.options, solve_ok))
    row = bench.lmi_row("Fake", "SCS")
    assert row["result"] == "certificate failed" and "LMI (20) on the stored P: 0.02 > 0" in row["reason"]
    assert row["recorded_solver"] == "SCS" and row["lmi_solves"] == 1 and row["gamma"] == 0.5
    monkeypatch.setitem(designs.DESIGNS, "Fake", base.__class__("Fake", "001", "sedan", "", base.options, solve_fails))
    row = bench.lmi_row("Fake", "CLARABEL")
    assert row["result"] == "no solution" and "LMI (20) infeasible" in row["reason"] and row["gamma"] is None


def test_a_design_over_the_time_cap_is_a_stopped_row():
    row = bench.lmi_row_isolated("LateralIntervalObserver", "SCS", timeout=0.01)
    assert row["result"] == "stopped" and row["timed_out"] and "0.01 s cap" in row["reason"]
    assert "stopped" in bench._lmi_cell(row)[0]


def test_pairings_are_the_demo_runs_and_their_bus_carries_every_input():
    """Pairings 000..003 are runs of latobs.demo.RUNS (nominal plant); every observer's inputs are
    on its pairing's bus (scenario signals and plant outputs); every FMU `latobs build` builds is
    benchmarked."""
    from importlib import import_module

    import numpy as np

    from latobs import demo, packaging
    from latobs.validation.scenarios import get_scenario

    from latobs import catalogue

    runs = {(scen, tuple(catalogue.default_observers(get_scenario(scen).plant) if obs is None else obs),
             veh or packaging.PLANTS[get_scenario(scen).plant].default_vehicle)
            for scen, _tag, params, _noise, obs, veh in demo.RUNS if not params}
    keys = set()
    for p in bench.pairings():
        keys.add(p.key)
        sc = get_scenario(p.scenario)
        assert sc.plant == p.plant
        if p.key != "mbds":
            assert (p.scenario, p.observers, p.vehicle) in runs, p
        spec = lambda name: import_module(f"latobs.fmu_src.models.{bench._kind(name).model_module}").SPEC
        signals = set(sc.sampled(np.linspace(0.0, 1.0, 3), p.vehicle)) | {v.name for v in spec(p.plant_fmu).outputs}
        for o in p.observers:
            missing = {v.name for v in spec(o).inputs} - signals
            assert not missing, (p.key, o, missing)
    assert {"000", "001", "002", "003"} <= keys
    names = bench.fmu_names()
    assert set(designs.DESIGNS) | set(packaging.PLANTS) <= set(names)
    assert all(bench._fmu_pairing(n) for n in names)


def _synthetic_result() -> dict:
    lmi_rows = []
    for name in ("SideslipBankObserver", "SideslipKalmanFilter", "MotorcycleFaultObserver"):
        for solver in bench.SOLVERS:
            lmi_rows.append({"design": name, "paper": "000", "vehicle": "sedan", "solver": solver,
                             "result": "certified", "reason": None, "gamma": 0.05, "design_seconds": 1.0,
                             "lmi_seconds": 0.5, "lmi_solves": 1, "lmi_statuses": ["optimal"],
                             "certificate_seconds": 0.2, "recorded_solver": solver, "checks_passed": 10,
                             "checks_total": 10, "uses_lmi": name != "SideslipKalmanFilter"})
    lmi_rows[-1].update(result="certificate failed", reason="LMI (20): 0.01 > 0", checks_passed=9)
    lmi_rows += [dict(lmi_rows[0], design="SideslipFixedOrderEstimator"),
                 dict(lmi_rows[1], design="SideslipFixedOrderEstimator", result="stopped", timed_out=True,
                      design_seconds=180.0, reason="not finished within the 180 s cap (process stopped)")]
    fmu = {"fmpy_us_per_step": 10.0, "fmpy_us_per_step_first": 12.0, "c_host_us_per_doStep": 0.1,
           "c_host_us_per_step": 0.2, "c_host_median_us_per_doStep": 0.1, "c_host_median_us_per_step": 0.2,
           "reference_us_per_step": 0.1, "reference": "C host fmi2DoStep", "fmpy_over_reference": 100.0}
    fmus = {"CarPlant": {"pairing": "000", "scenario": "bank-braking", "kind": "plant", "n_steps": 100,
                         "python_runtime_us_per_step": 30.0, "python_runtime_us_per_step_first": 31.0,
                         "backends": {"python": dict(fmu, fmpy_over_reference=0.3), "c": fmu}},
            "MotorcyclePlant": {"pairing": "003", "scenario": "motorcycle-lane-change", "kind": "plant",
                                "n_steps": 100, "backends": {"python": {"error": "fmpy: boom"}, "c": fmu}}}
    run = {"seconds": 0.5, "first_seconds": 0.6, "scenario_seconds": 30.0, "steps": 6000,
           "real_time_factor": 60.0, "first_real_time_factor": 50.0, "us_per_step": 83.0}
    fmus["A"] = fmus["B"] = fmus["CarPlant"]          # (each 0.1 µs per doStep in the C host)
    coupled = [{"pairing": "000", "scenario": "bank-braking", "plant": "CarPlant", "observers": ["A", "B"],
                "backend": "c", **run, "fresh_process_real_time_factor": 20.0, "master_loop": "compiled",
                "loop_us_per_step": 0.6},
               {"pairing": "003", "scenario": "motorcycle-lane-change", "plant": "MotorcyclePlant",
                "observers": ["MotorcycleFaultObserver"], "backend": "python", "error": "missing FMU(s) X"}]
    row = lambda T, k: {"duration": T, "steps": int(T / 0.005), "n_observers": k,
                        "seconds_extract_per_run": 0.1 + T / 100, "seconds_extracted_once": 0.05 + T / 100,
                        "us_per_step_extract_per_run": 20.0, "us_per_step_extracted_once": 15.0, "real_time_factor_extracted_once": 100.0}
    lengths = [row(T, 4) for T in bench.LENGTHS]
    nobs = [row(10.0, k) for k in range(5)]
    fit = {c: {"intercept": 0.05, "slope": 0.01} for c in ("seconds_extract_per_run", "seconds_extracted_once")}
    return {"n_steps": 100, "repeats": 1, "dt": 0.005, "backends": ["python", "c"],
            "build": [{"backend": "python", "seconds": 80.0, "warm_new_folder_seconds": 1.25,
                       "warm_same_folder_seconds": 0.5, "returncode": 0, "fmus": 11, "lmi_solver_seconds": 12.0,
                       "error": None},
                      {"backend": "c", "seconds": 90.0, "returncode": 1, "fmus": 0, "lmi_solver_seconds": 0.0,
                       "error": "no C compiler"}],
            "lmi": {"solvers": list(bench.SOLVERS), "settings": {"CLARABEL": {}, "SCS": dict(lmi.SCS_SETTINGS)},
                    "rows": lmi_rows},
            "fmus": fmus, "numpy_reference": {"numpy_affine_map_us": 2.0, "numpy_rk4_substeps_us": 40.0},
            "coupled": coupled,
            "demo": {"seconds": 58.25, "warm_new_folder_seconds": 24.5, "returncode": 0, "error": None},
            "campaign": {"campaign": "robustness-000", "runs": 1000, "workers": 2, "seconds": 12.5, "returncode": 0,
                         "command": "campaign robustness-000 --runs 1000 --workers 2", "error": None, "ok": 1000,
                         "execution_s": 8.0, "cluster_start_s": 0.5, "runs_per_s": 125.0},
            "scaling": {"backend": "c", "scenario": "bank-braking", "observers": ["A"], "lengths": lengths,
                        "n_observers": nobs, "observers_duration": 10.0, "fit_lengths": fit, "fit_n_observers": fit}}


def test_tables_have_every_row_and_the_json_every_figure():
    r = _synthetic_result()
    text = bench.table(r)
    lines = text.splitlines()
    for name in ("SideslipBankObserver", "SideslipKalmanFilter", "MotorcycleFaultObserver",
                 "SideslipFixedOrderEstimator"):
        assert sum(line.startswith(f"| {name} (") for line in lines) == 1        # one row, both solvers
    assert "certificate failed" in text and "LMI (20): 0.01 > 0" in text and "(no LMI)" in text
    assert "> 180 (stopped)" in text and "1 stopped at the cap" in text
    assert sum(line.startswith("| CarPlant |") for line in lines) == 3            # 2 backends + the ratio table
    assert any(line.startswith("| MotorcyclePlant |") and "fmpy: boom" in line for line in lines)
    assert any(line.startswith("| 000 | bank-braking (30)") and "fresh process: 20×" in line
               and "| 0.60 (compiled) | 2.0 |" in line for line in lines)
    assert any(line.startswith("| 003 |") and "missing FMU(s) X" in line for line in lines)
    assert any(line.startswith("| pythonfmu | 80.0 | 1.25 | 0.50 | 11 |") for line in lines)
    assert any(line.startswith("| native C |") and "no C compiler" in line for line in lines)
    for T in bench.LENGTHS:
        assert any(line.startswith(f"| {T:g} | {int(T / 0.005)} | 4 |") for line in lines)
    assert sum(line.startswith(f"| {k} | ") for line in lines for k in range(5)) >= 5
    assert "per observer added" in text
    assert "| 58.2 | 24.5 | ok |" in lines
    assert any(line == "| robustness-000 | 1000 of 1000 | 2 | 12.5 | 0.5 | 8.0 | 125 | 16.0 |" for line in lines)
    assert all(line.count("|") == lines[i - 1].count("|") for i, line in enumerate(lines)
               if line.startswith("|---"))                                         # header and rule agree
    back = json.loads(json.dumps(bench._jsonable(r)))
    assert back["lmi"]["rows"][0]["lmi_seconds"] == 0.5 and back["scaling"]["lengths"][-1]["duration"] == 40.0


def test_bench_help_lists_the_options(capsys):
    from latobs.cli import main

    with pytest.raises(SystemExit) as exc:
        main(["bench", "--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    for option in ("--fmu-dir", "--steps", "--repeats", "--json", "--skip-lmi", "--skip-build", "--skip-fmus",
                   "--skip-coupled", "--skip-scaling", "--skip-campaign", "--skip-demo", "--backends", "--designs", "--scs-max-iters",
                   "--lmi-timeout"):
        assert option in out


@pytest.mark.parametrize("argv, culprit", [(["--backends", "python,fortran"], "'fortran'"),
                                            (["--designs", "NoSuchObserver"], "'NoSuchObserver'"),
                                            (["--scs-max-iters", "0"], "--scs-max-iters"),
                                            (["--lmi-timeout", "-5"], "--lmi-timeout")])
def test_a_bad_bench_option_is_one_line_and_exit_2(argv, culprit, capsys):
    from latobs.cli import main

    try:
        rc = main(["bench", *argv])
    except SystemExit as exc:                      # argparse's errors exit by SystemExit
        rc = exc.code
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and err[0].startswith("latobs bench: error:") and culprit in err[0]


def test_markdown_is_the_speed_page_without_a_date(tmp_path, capsys):
    """`latobs bench --markdown` (here on the figures of an earlier `--json`, measuring nothing):
    its title and how it is made, the machine and its load, then a heading and the table of every
    measured section; no date."""
    from latobs.cli import main

    r = _synthetic_result()
    r["date"] = "2031-07-04"
    r["machine"] = {"cpu": "Test CPU 9000", "logical_cores": 2, "system": "Linux 6", "python": "3.11.7",
                    "numpy": "2.0", "load_average": [1.5, 1.25, 1.0]}
    f = tmp_path / "bench.json"
    f.write_text(json.dumps(bench._jsonable(r)), encoding="utf-8")
    assert main(["bench", "--from-json", str(f), "--markdown"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("# Speed\n\nThis page is the output of `latobs bench --markdown`")
    assert "\n\nMeasured on Test CPU 9000 (2 logical cores)" in out and "1.50 / 1.25 / 1.00" in out
    headings = [line for line in out.splitlines() if line.startswith("## ")]
    assert headings == ["## Whole build", "## The demo", "## LMI designs: Clarabel and SCS", "## One FMU step", "## Coupled runs",
                        "## A 1000-run campaign", "## Scaling with length and observers"]
    for part in bench.table(r).split("\n\n"):                     # the same tables as the plain output
        assert part in out
    assert "2031" not in out and "ERRATA" not in out
    assert main(["bench", "--from-json", str(f)]) == 0             # without --markdown: the tables alone
    assert capsys.readouterr().out.strip() == bench.table(r).strip()


@pytest.mark.slow
def test_the_fmu_section_measures_every_column_of_both_backends(built_fmus, tmp_path):
    """One FMU, a few steps: the fmpy figure, the plain C host's (the bus carries more signals than
    the FMU's inputs) and the Python runtime's reference are all there, in both backends."""
    from latobs.bench import measure

    name = "SideslipBankObserver"
    folders = {"python": built_fmus.path(name).parent, "c": built_fmus.c_path(name).parent}
    plant = "CarPlant"
    built_fmus.get(plant, "python")
    built_fmus.get(plant, "c")
    entry = measure.fmu_section(folders, [name], 20, 1, {})[name]
    assert "python_runtime_error" not in entry and entry["python_runtime_us_per_step"] > 0, entry
    for backend in ("python", "c"):
        e = entry["backends"][backend]
        assert "c_host_error" not in e or "libpython" in e["c_host_error"], (backend, e)
        assert e["fmpy_us_per_step"] > 0 and e.get("reference_us_per_step") is not None, (backend, e)
