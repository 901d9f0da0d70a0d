"""cvxpy + Clarabel, the way every design module solves its LMIs (design time only)."""
from __future__ import annotations

import time


#: Clarabel settings of the fallback solve (ERRATA 002: "If Clarabel stops on a numerical error,
#: chordal decomposition and equilibration off is a working fallback").
FALLBACK_SETTINGS = {"equilibrate_enable": False, "chordal_decomposition_enable": False}
#: Statuses after which the fallback is tried (a numerical failure, not a clean verdict).
_RETRY = ("solver_error", "infeasible_inaccurate", "unbounded_inaccurate", "user_limit")


def _attempt(prob, settings: dict) -> str:
    import warnings

    import cvxpy as cp

    try:
        with warnings.catch_warnings():
            # "Solution may be inaccurate": the status says so (optimal_inaccurate), and every
            # design is certified independently of the solver's claim anyway
            warnings.filterwarnings("ignore", message="Solution may be inaccurate")
            prob.solve(solver=cp.CLARABEL, **settings)
        return str(prob.status)
    except cp.error.SolverError:
        return "solver_error"


def solve(prob, info: dict | None = None) -> tuple[str, float]:
    """Solve a cvxpy problem with Clarabel: (status, seconds); a solver failure is a status.

    If Clarabel's default settings end in a numerical failure (``_RETRY``), the problem is solved
    again with :data:`FALLBACK_SETTINGS`; the returned status is that of the fallback.
    ``info`` (optional dict) receives ``attempts``: [(settings, status), ...].
    """
    t0 = time.perf_counter()
    attempts = [({}, _attempt(prob, {}))]
    if attempts[-1][1] in _RETRY:
        attempts.append((dict(FALLBACK_SETTINGS), _attempt(prob, FALLBACK_SETTINGS)))
    if info is not None:
        info["attempts"] = attempts
    return attempts[-1][1], time.perf_counter() - t0


def solved(status: str) -> bool:
    import cvxpy as cp

    return status in (cp.OPTIMAL, cp.OPTIMAL_INACCURATE)


def feasible(constraints: list) -> bool:
    """Whether the constraints alone are feasible (used to name the LMI family at fault)."""
    import cvxpy as cp

    return solved(solve(cp.Problem(cp.Minimize(0), constraints))[0])
