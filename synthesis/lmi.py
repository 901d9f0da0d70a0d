"""cvxpy + Clarabel, the way every design module solves its LMIs (design time only)."""
from __future__ import annotations

import time


def solve(prob) -> tuple[str, float]:
    """Solve a cvxpy problem with Clarabel: (status, seconds); a solver failure is a status."""
    import cvxpy as cp

    t0 = time.perf_counter()
    try:
        prob.solve(solver=cp.CLARABEL)
        status = prob.status
    except cp.error.SolverError:
        status = "solver_error"
    return str(status), time.perf_counter() - t0


def solved(status: str) -> bool:
    import cvxpy as cp

    return status in (cp.OPTIMAL, cp.OPTIMAL_INACCURATE)


def feasible(constraints: list) -> bool:
    """Whether the constraints alone are feasible (used to name the LMI family at fault)."""
    import cvxpy as cp

    return solved(solve(cp.Problem(cp.Minimize(0), constraints))[0])
