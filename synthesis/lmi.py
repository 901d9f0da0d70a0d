"""cvxpy + an SDP solver, the way every design module solves its LMIs (design time only): Clarabel
(with a fallback of settings on a numerical failure) unless a caller chooses SCS for a block of
code (``with lmi.using("SCS"):``, as ``latobs bench`` does); the solver used is recorded in the
design dict."""
from __future__ import annotations

import contextlib
import contextvars
import time
from dataclasses import dataclass, field
from typing import Iterator


#: Clarabel settings of the fallback solve (paper 002's solves: "If Clarabel stops on a numerical error,
#: chordal decomposition and equilibration off is a working fallback").
FALLBACK_SETTINGS = {"equilibrate_enable": False, "chordal_decomposition_enable": False}
#: Statuses after which the fallback is tried (a numerical failure, not a clean verdict).
_RETRY = ("solver_error", "infeasible_inaccurate", "unbounded_inaccurate", "user_limit")
#: SCS's settings (see the module docstring): tight tolerances (SCS's defaults are 1e-4), and
#: SCS's default iteration cap, which bounds a solve's time.
SCS_SETTINGS = {"eps_abs": 1e-9, "eps_rel": 1e-9, "max_iters": 100_000}
#: Known solvers: cvxpy name -> settings of the first attempt.
SOLVERS = {"CLARABEL": {}, "SCS": SCS_SETTINGS}
#: Names for messages.
LABELS = {"CLARABEL": "Clarabel", "SCS": "SCS"}
DEFAULT = "CLARABEL"


@dataclass
class Usage:
    """What :func:`using` yields: the solver chosen, its settings, and every :func:`solve` call
    made in the block (``calls``: [(status, seconds)], seconds of wall time, fallback included)."""

    name: str
    settings: dict
    calls: list = field(default_factory=list)

    @property
    def seconds(self) -> float:
        """s, wall time of every solve in the block."""
        return float(sum(s for _, s in self.calls))


# (solver name, settings of its first attempt, the Usage of the innermost `using` block or None);
# a ContextVar, so threads and tasks each see theirs
_CHOICE: contextvars.ContextVar[tuple[str, dict, Usage | None]] = contextvars.ContextVar(
    "latobs_lmi_solver", default=(DEFAULT, {}, None))


def _check(name: str) -> str:
    key = str(name).upper()
    if key not in SOLVERS:
        raise ValueError(f"unknown LMI solver {name!r}; known: {', '.join(SOLVERS)}")
    return key


@contextlib.contextmanager
def using(name: str, **settings) -> Iterator[Usage]:
    """Solve every LMI in the ``with`` block with solver ``name`` (``"CLARABEL"`` or ``"SCS"``,
    case-insensitive); ``settings`` override that solver's :data:`SOLVERS` settings (e.g.
    ``max_iters=20_000`` to cap SCS). Unknown name: ValueError naming it. Yields a
    :class:`Usage` that records the block's solves."""
    key = _check(name)
    usage = Usage(key, {**SOLVERS[key], **settings})
    token = _CHOICE.set((key, dict(usage.settings), usage))
    try:
        yield usage
    finally:
        _CHOICE.reset(token)


def current() -> str:
    """The cvxpy name of the solver :func:`solve` uses here ("CLARABEL" by default)."""
    return _CHOICE.get()[0]


def settings() -> dict:
    """The settings of the current solver's first attempt (a copy)."""
    return dict(_CHOICE.get()[1])


def label() -> str:
    """The current solver's name for messages ("Clarabel", "SCS")."""
    return LABELS[current()]


def _attempt(prob, settings: dict) -> str:
    """One solve with the current solver, its settings overridden by ``settings``; the status."""
    import warnings

    import cvxpy as cp

    name, base, _ = _CHOICE.get()
    try:
        with warnings.catch_warnings():
            # "Solution may be inaccurate": the status says so (optimal_inaccurate), and every
            # design is certified independently of the solver's claim anyway
            warnings.filterwarnings("ignore", message="Solution may be inaccurate")
            prob.solve(solver=name, **{**base, **settings})
        return str(prob.status)
    except cp.error.SolverError:
        return "solver_error"


def solve(prob, info: dict | None = None, clarabel: dict | None = None) -> tuple[str, float]:
    """Solve a cvxpy problem with the current solver (:func:`using`; Clarabel by default):
    (status, seconds); a solver failure is a status.

    ``clarabel``: Clarabel settings of this problem's first attempt (a design module's choice for
    its LMIs, e.g. ``{"iterative_refinement_enable": False}``); ignored with another solver.
    With Clarabel, if the first attempt ends in a numerical failure (``_RETRY``), the problem is
    solved again with :data:`FALLBACK_SETTINGS`; the returned status is that of the fallback.
    ``info`` (optional dict) receives ``solver`` (the name) and ``attempts``:
    [(settings, status), ...] (settings: those overriding the solver's own, {} for the first
    without ``clarabel``).
    """
    t0 = time.perf_counter()
    first = dict(clarabel or {}) if current() == "CLARABEL" else {}
    attempts = [(first, _attempt(prob, first))]
    if current() == "CLARABEL" and attempts[-1][1] in _RETRY:
        attempts.append((dict(FALLBACK_SETTINGS), _attempt(prob, FALLBACK_SETTINGS)))
    seconds = time.perf_counter() - t0
    usage = _CHOICE.get()[2]
    if usage is not None:
        usage.calls.append((attempts[-1][1], seconds))
    if info is not None:
        info["solver"] = current()
        info["attempts"] = attempts
    return attempts[-1][1], seconds


#: the environment variable bounding the processes of :func:`parallel_map` (default: the cores)
JOBS_ENV = "LATOBS_JOBS"


def jobs(n_items: int) -> int:
    """How many processes :func:`parallel_map` uses for ``n_items`` items: ``$LATOBS_JOBS`` (a
    positive integer; 1: in this process) else the cores this process may use, at most ``n_items``."""
    import os

    text = os.environ.get(JOBS_ENV, "").strip()
    try:
        limit = int(text) if text else len(os.sched_getaffinity(0))
    except (ValueError, AttributeError):
        limit = os.cpu_count() or 1
    if limit < 1:
        raise ValueError(f"{JOBS_ENV}={text!r}: a positive number of processes is needed")
    return max(1, min(limit, n_items))


def _in_worker(choice: tuple[str, dict], fn, item):
    """One item of :func:`parallel_map` in a worker process, under the parent's solver choice:
    (result, the solves it made)."""
    with using(choice[0], **choice[1]) as usage:
        return fn(item), usage.calls


@contextlib.contextmanager
def main_not_run_again() -> Iterator[None]:
    """Spawned workers that do not import the caller's main script (multiprocessing runs it again
    in each child, as ``__mp_main__``: a user's script calling ``latobs`` at its top level, without
    ``if __name__ == "__main__"``, would start building again in every worker). The functions sent
    to the workers are importable by their module's name, so the children need nothing of it."""
    from multiprocessing import spawn

    real = spawn.get_preparation_data

    def without_main(name):
        d = real(name)
        d.pop("init_main_from_path", None)
        d.pop("init_main_from_name", None)
        return d

    spawn.get_preparation_data = without_main
    try:
        yield
    finally:
        spawn.get_preparation_data = real


def parallel_map(fn, items: list) -> list:
    """``[fn(x) for x in items]`` in up to :func:`jobs` fresh processes (spawned: no state of this
    one is inherited but the solver choice of :func:`using`, whose block also records the workers'
    solves; the caller's main script is not run in them). ``fn`` must be a module-level function of
    an importable module, and items and results picklable. Each item is
    computed by the same code on the same input as in this process: the results are those of the
    sequential loop (tested). An exception of ``fn`` is raised here, the first in item order.

    The workers die with this process (:func:`_worker_start`): killed (even by SIGKILL), it leaves
    none behind. A SIGTERM of this process (in the main thread) raises SystemExit(143) here, as
    Ctrl-C raises KeyboardInterrupt: either way the workers are terminated and the callers' ``with``
    and ``finally`` blocks (their temporary folders) run."""
    items = list(items)
    n = jobs(len(items))
    if n <= 1:
        return [fn(x) for x in items]
    import multiprocessing
    import os
    import signal
    import threading
    from concurrent.futures import ProcessPoolExecutor
    from concurrent.futures.process import BrokenProcessPool
    from functools import partial

    name, settings_, usage = _CHOICE.get()
    main = threading.current_thread() is threading.main_thread()
    old_term = signal.signal(signal.SIGTERM, _terminated) if main else None
    try:
        with main_not_run_again():           # (the workers start as the items are submitted)
            pool = ProcessPoolExecutor(max_workers=n, mp_context=multiprocessing.get_context("spawn"),
                                       initializer=_worker_start, initargs=(os.getpid(), main))
            try:
                done = list(pool.map(partial(_in_worker, (name, settings_), fn), items))
            except BaseException:             # Ctrl-C, SIGTERM, an error of fn: no worker outlives it
                for p in list((getattr(pool, "_processes", None) or {}).values()):
                    p.terminate()
                pool.shutdown(wait=False, cancel_futures=True)
                raise
            pool.shutdown()
    except BrokenProcessPool:                 # a worker could not start or died: this process does it
        return [fn(x) for x in items]
    finally:
        if main and old_term is not None:     # (None: a handler not set from Python, left as it is)
            signal.signal(signal.SIGTERM, old_term)
    if usage is not None:
        for _, calls in done:
            usage.calls.extend(calls)
    return [result for result, _ in done]


#: how often a worker of :func:`parallel_map` checks that its parent is alive, s; and how long it
#: takes to clean up (its ``finally`` blocks) once the parent is gone, before it exits regardless
PARENT_CHECK_S = 0.5
CLEANUP_S = 2.0
PR_SET_PDEATHSIG = 1          # <linux/prctl.h>


def _terminated(signum, frame):
    """SIGTERM as an exception (SystemExit(128 + SIGTERM)): ``finally`` blocks run."""
    raise SystemExit(128 + signum)


def _worker_start(parent: int, parent_main_thread: bool) -> None:
    """Initializer of :func:`parallel_map`'s workers: a worker ends when its parent does. On Linux
    the kernel sends it SIGTERM when the parent dies (``prctl(PR_SET_PDEATHSIG)``; only when the
    parent's main thread started it: the signal follows the thread); everywhere a watchdog thread
    sees the parent gone (its parent PID changes) within :data:`PARENT_CHECK_S`. SIGTERM raises
    SystemExit in the worker (its ``finally`` blocks remove its scratch folders); after
    :data:`CLEANUP_S` the watchdog ends it regardless."""
    import os
    import signal
    import sys
    import threading

    signal.signal(signal.SIGTERM, _terminated)
    if parent_main_thread and sys.platform.startswith("linux"):
        try:
            import ctypes

            ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, int(signal.SIGTERM), 0, 0, 0)
        except (OSError, AttributeError):
            pass

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(PARENT_CHECK_S)
        try:
            os.kill(os.getpid(), signal.SIGTERM)
        finally:
            time.sleep(CLEANUP_S)
            os._exit(1)

    threading.Thread(target=watch, name="latobs-parent-watch", daemon=True).start()


def solved(status: str) -> bool:
    import cvxpy as cp

    return status in (cp.OPTIMAL, cp.OPTIMAL_INACCURATE)


def feasible(constraints: list) -> bool:
    """Whether the constraints alone are feasible (used to name the LMI family at fault)."""
    import cvxpy as cp

    return solved(solve(cp.Problem(cp.Minimize(0), constraints))[0])


# -- exact structure after the solve ------------------------------------------------------------
# An interior-point solver meets an elementwise constraint X >= 0 only to its tolerance: entries
# the optimum puts on the boundary come back as -1e-9 ... -1e-8, and a runtime or a certificate
# that relies on the sign (a Metzler matrix, a nonnegative gain) then sees the wrong one. The
# design modules therefore impose such structure exactly after the solve (:func:`project_lower`),
# rebuild every dependent number from the projected one, and re-check the definite LMIs on the
# projected numbers with a stated margin (:func:`max_eig`), so that what is certified and
# packaged is exactly what was verified.

#: Largest shift :func:`project_lower` accepts, relative to max(1, max |X|): solver round-off
#: (Clarabel's default tolerances are 1e-8), not a violated constraint.
PROJECTION_TOL = 1e-6


class StructureError(ValueError):
    """The solver's answer is farther from the required structure than round-off (``PROJECTION_TOL``)."""


def project_lower(X, lower, what: str, tol: float = PROJECTION_TOL):
    """The Euclidean projection of ``X`` onto {X >= lower} (elementwise, ``lower`` broadcast; -inf
    leaves an entry free): max(X, lower), entries exactly on the bound. Returns (projected, shift)
    with shift = the largest change. Raises StructureError naming ``what`` if the shift exceeds
    ``tol`` x max(1, max |X|), i.e. if the violation is not round-off."""
    import numpy as np

    X = np.asarray(X, dtype=float)
    out = np.maximum(X, np.broadcast_to(np.asarray(lower, dtype=float), X.shape))
    shift = float(np.max(np.abs(out - X))) if X.size else 0.0
    scale = max(1.0, float(np.max(np.abs(X)))) if X.size else 1.0
    if not shift <= tol * scale:
        raise StructureError(f"{what}: the solver's answer violates the constraint by {shift:.3g} "
                             f"(more than round-off, {tol:g} x {scale:.3g})")
    return out, shift


def max_eig(M) -> float:
    """Largest eigenvalue of the symmetric part of M (inf if M has a non-finite entry): an LMI
    M < 0 re-checked on numbers outside the solver holds with margin m iff max_eig(M) <= -m."""
    import numpy as np

    M = np.asarray(M, dtype=float)
    if not np.all(np.isfinite(M)):
        return float("inf")
    return float(np.max(np.linalg.eigvalsh((M + M.T) / 2)))
