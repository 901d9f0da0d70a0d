"""``latobs bench``'s LMI section: every design solved with each solver (Clarabel, SCS), each
result through the independent certificate, each design x solver in a fresh process under a cap."""
from __future__ import annotations

import json
import subprocess
import sys
import time

from ..synthesis import designs  # the catalogue only (no solver stack)
from .measure import SOLVER_LABEL, SOLVERS, _progress, _reason


# ------------------------------------------------------------------------------------------------
# (a) LMI solve time per design and solver, each result certified
# ------------------------------------------------------------------------------------------------
def lmi_row(name: str, solver: str, scs_max_iters: int | None = None) -> dict:
    """Design ``name`` (default vehicle) with ``solver`` and certify it as the pipeline does
    (``designs.run``: ``entry.solve``, then ``tables.attach`` and ``certificate.certify``, timed
    together as the certificate), timing each part. Never raises:
    a failure is ``result`` ("no solution", "certificate failed", "error") with ``reason``."""
    from ..synthesis import certificate, lmi, tables
    from ..synthesis.params import load_vehicle

    entry = designs.get(name)
    row: dict = {"design": name, "paper": entry.paper, "vehicle": entry.default_vehicle, "solver": solver,
                 "result": None, "reason": None, "gamma": None, "design_seconds": None, "lmi_seconds": 0.0,
                 "lmi_solves": 0, "lmi_statuses": [], "certificate_seconds": None, "recorded_solver": None,
                 "checks_passed": None, "checks_total": None}
    settings = {"max_iters": scs_max_iters} if solver == "SCS" and scs_max_iters else {}
    with lmi.using(solver, **settings) as usage:
        row["settings"] = dict(usage.settings)
        t0 = time.perf_counter()
        try:
            veh = load_vehicle(entry.default_vehicle)
            data = entry.solve(veh, entry.options(designs.artefact_name(name, veh.name)))
        except Exception as exc:           # a row, not a crash
            data = None
            row["result"] = "no solution" if type(exc).__name__ in ("DesignError", "ConditionError") else "error"
            row["reason"] = _reason(exc)
        row["design_seconds"] = time.perf_counter() - t0
    row["lmi_seconds"] = usage.seconds
    row["lmi_solves"] = len(usage.calls)
    row["lmi_statuses"] = sorted({s for s, _ in usage.calls})
    row["uses_lmi"] = bool(usage.calls)
    if data is None:
        return row
    rec = data.get("solver") or {}
    row["recorded_solver"] = rec.get("name")
    row["recorded_solver_seconds"] = rec.get("seconds")
    row["recorded_status"] = rec.get("status")
    row["gamma"] = data.get("gamma")
    data["design"] = name
    t1 = time.perf_counter()
    try:
        tables.attach(data)
        ok, checks = certificate.certify(data)
    except Exception as exc:
        row["certificate_seconds"] = time.perf_counter() - t1
        row["result"], row["reason"] = "error", "certificate raised " + _reason(exc)
        return row
    row["certificate_seconds"] = time.perf_counter() - t1
    row["checks_passed"] = sum(bool(c.passed) for c in checks)
    row["checks_total"] = len(checks)
    row["certified"] = bool(ok)
    if ok:
        row["result"] = "certified"
    else:
        failed = [c for c in checks if not c.passed]
        row["result"] = "certificate failed"
        row["reason"] = "; ".join(f"{c.name}: {c.value:.6g} > {c.limit:.6g}" for c in failed[:3]) + (
            f" (+{len(failed) - 3} more)" if len(failed) > 3 else "")
    if row["uses_lmi"] and row["recorded_solver"] != solver:
        row["result"] = "error"
        row["reason"] = f"the design dict records solver {row['recorded_solver']!r}, not {solver!r}"
    return row


#: s, wall-time cap of one design in the LMI section (a fresh process, killed at the cap): SCS at
#: eps 1e-9 takes about 70 s per Lemma 5 solve of paper 002, whose designs make 4 to ~100 solves
LMI_TIMEOUT = 180.0


def lmi_row_isolated(name: str, solver: str, scs_max_iters: int | None = None,
                     timeout: float | None = LMI_TIMEOUT) -> dict:
    """:func:`lmi_row` in a fresh Python process (nothing cached from another design or solver),
    stopped after ``timeout`` s: then a row with result "stopped" and the cap as the reason."""
    entry = designs.get(name)
    # the solver stack and the design modules imported first: the design time is not an import time
    code = ("import json, cvxpy, scipy.linalg; from latobs.bench.lmi import lmi_row; from latobs.bench.measure import _jsonable; "
            "from latobs.synthesis import certificate, sideslip_fixed_order_estimator, lateral_interval_observer, sideslip_kalman_filter, "
            "sideslip_bank_observer, motorcycle_fault_observer; "
            f"print('LMI-ROW ' + json.dumps(_jsonable(lmi_row({name!r}, {solver!r}, {scs_max_iters!r}))))")
    base = {"design": name, "paper": entry.paper, "vehicle": entry.default_vehicle, "solver": solver,
            "gamma": None, "design_seconds": None, "lmi_seconds": 0.0, "lmi_solves": 0, "lmi_statuses": [],
            "certificate_seconds": None, "recorded_solver": None, "checks_passed": None, "checks_total": None}
    # one process (LATOBS_JOBS=1: the solvers compared on the same sequential work), in a session of
    # its own: stopped at the cap with everything it started (a worker left running would load
    # every later measurement of the run)
    import os
    import signal

    env = {**os.environ, "LATOBS_JOBS": "1"}
    t0 = time.perf_counter()
    posix = os.name == "posix"
    with subprocess.Popen([sys.executable, "-P", "-c", code], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                          text=True, env=env, start_new_session=posix) as child:
        try:
            out, err = child.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            if posix:
                os.killpg(child.pid, signal.SIGKILL)
            else:
                child.kill()
            child.communicate()
            return {**base, "result": "stopped", "design_seconds": time.perf_counter() - t0, "timed_out": True,
                    "reason": f"not finished within the {timeout:g} s cap (process stopped)"}
    proc = subprocess.CompletedProcess(child.args, child.returncode, out, err)
    line = next((x for x in reversed(proc.stdout.splitlines()) if x.startswith("LMI-ROW ")), None)
    if proc.returncode != 0 or line is None:
        tail = " | ".join(proc.stderr.strip().splitlines()[-2:])
        return {**base, "result": "error", "reason": f"design process exit {proc.returncode}: {tail[:400]}"}
    row = json.loads(line[len("LMI-ROW "):])
    row["process_seconds"] = time.perf_counter() - t0
    return row


def lmi_section(names: list[str], solvers=SOLVERS, scs_max_iters: int | None = None,
                timeout: float | None = LMI_TIMEOUT) -> list[dict]:
    """Every design x solver (:func:`lmi_row_isolated`)."""
    rows = []
    for name in names:
        for solver in solvers:
            _progress(f"LMI design {name} with {SOLVER_LABEL.get(solver, solver)}")
            rows.append(lmi_row_isolated(name, solver, scs_max_iters, timeout))
    return rows
