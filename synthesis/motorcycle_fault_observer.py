"""Paper 003's design: the switched H-infinity PI observer of the motorcycle's roll angle and rider
torque, per mode LMIs (20)-(23) (with the printed misprints corrected), normalised units, an
optional pole region, the existence conditions and the average dwell time. The LMIs and the
measured design choices are on the documentation's paper-003 page."""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, Iterable, Sequence

import numpy as np
import scipy.linalg

from . import lmi
from .params import Vehicle

STATES = ("vy", "yaw_rate", "roll_rate", "steer_angle", "steer_rate")
STATE_UNITS = ("m/s", "rad/s", "rad/s", "rad", "rad/s")
FAULTS = ("roll_angle", "rider_torque")              # f: the unknown inputs estimated (eq. 12)
FAULT_UNITS = ("rad", "N*m")
DISTURBANCES = ("Gamma_f", "Gamma_r")                # d: non-linear parts of the tyre forces (5)-(6)
DISTURBANCE_UNITS = ("N", "N")
MEASUREMENTS = ("steer_angle", "yaw_rate", "roll_rate")   # y (section IV)
FORCES = ("Ff", "Fr")


class DesignError(RuntimeError):
    """The LMIs are infeasible or the solver failed; the message names the design, mode and LMI."""


class ConditionError(DesignError):
    """An existence condition of the observer fails (rank condition (24) or detectability)."""


@dataclass(frozen=True)
class DesignOptions:
    """Options of a paper-003 design (SI units: m/s, rad, N m, N, s).

    beta
        The paper's trade-off in min beta alpha_bar + (1 - beta) gamma_bar, beta in [0, 1].
        Larger beta: smaller alpha_bar (P closer to I: better conditioned Lyapunov function,
        tighter ISS constant and larger guaranteed decay 1/(2 lambda_max(P))) at the price of a
        larger gamma (weaker disturbance attenuation). The default 0.5 weighs both equally.
    speeds
        The grid speeds (m/s) of the modes (section IV: 10..30 in steps of 5).
    x_scale, f_scale, d_scale
        Typical magnitudes of the states (STATES), the faults (phi rad, tau N m) and the tyre-force
        non-linearities (N): the LMIs are posed in these normalised units (module docstring).
    alpha, radius
        Optional pole region of every closed loop A* = A~ - L C~ (1/s, rad/s): Re < -alpha,
        |lambda| < radius. None: not imposed. Default alpha = 5 /s, radius = 150 rad/s (not in the
        paper, which mentions pole location constraints without using them: the pure (20)-(23)
        design leaves the roll-angle estimate with a ~1.5 s time constant; module docstring).
    hysteresis
        m/s, the runtime keeps a mode until the speed leaves its band by this much (not in the paper).
    lmi22
        "corrected" (a misprint corrected: docs/papers/003.md, departures) or "printed" (the paper's (22), infeasible: for the tests).
    """

    name: str
    beta: float = 0.5
    speeds: tuple[float, ...] = (10.0, 15.0, 20.0, 25.0, 30.0)
    x_scale: tuple[float, ...] = (1.0, 0.5, 0.5, 0.05, 0.5)
    f_scale: tuple[float, ...] = (0.2, 20.0)
    d_scale: tuple[float, ...] = (1000.0, 1000.0)
    alpha: float | None = 5.0
    radius: float | None = 150.0
    hysteresis: float = 0.5
    lmi22: str = "corrected"
    margin: float = 1e-7             # strictness of (20), (21) in normalised units
    rank_tol: float = 1e-9           # relative singular-value tolerance of the rank tests
    vx_hold: float = 1.0             # runtime: below this |vx| (m/s) the estimates are held
    gain_limit: float = 1e6          # certificate: largest admissible entry of L_P, L_I (SI)
    cond_limit: float = 1e8          # certificate: largest admissible cond(P) (normalised)

    def validate(self) -> None:
        if not (0.0 <= self.beta <= 1.0):
            raise ValueError(f"design {self.name}: beta must be in [0, 1], got {self.beta}")
        sp = list(self.speeds)
        if len(sp) < 1 or any(not (v > 0 and math.isfinite(v)) for v in sp) or sp != sorted(set(sp)):
            raise ValueError(f"design {self.name}: speeds must be positive and strictly increasing, got {self.speeds}")
        for what, sc, k in (("x_scale", self.x_scale, len(STATES)), ("f_scale", self.f_scale, len(FAULTS)),
                            ("d_scale", self.d_scale, len(DISTURBANCES))):
            if len(sc) != k or any(not (s > 0 and math.isfinite(s)) for s in sc):
                raise ValueError(f"design {self.name}: {what} needs {k} positive magnitudes, got {sc}")
        if self.alpha is not None and not (self.alpha >= 0 and math.isfinite(self.alpha)):
            raise ValueError(f"design {self.name}: alpha must be >= 0 or None, got {self.alpha}")
        if self.radius is not None and not (self.radius > (self.alpha or 0.0)):
            raise ValueError(f"design {self.name}: radius must exceed alpha, got {self.radius}")
        if self.lmi22 not in ("corrected", "printed"):
            raise ValueError(f"design {self.name}: lmi22 must be 'corrected' or 'printed', got {self.lmi22!r}")
        if not (self.hysteresis >= 0):
            raise ValueError(f"design {self.name}: hysteresis must be >= 0, got {self.hysteresis}")


@dataclass
class ModeModel:
    """One switched mode: the reduced model at the grid speed vx (eq. 12), SI units."""

    index: int                      # 1-based
    vx: float
    band: tuple[float, float]
    A: np.ndarray                   # 5x5
    E_f: np.ndarray                 # 5x2: [E_phi, B_tau]
    E_d: np.ndarray                 # 5x2: E_Gamma
    C: np.ndarray                   # 3x5
    F_d: np.ndarray                 # 3x2 (zero: y are states)
    F_f: np.ndarray                 # 3x2 (zero)
    H_x: np.ndarray                 # 2x5: tyre forces [Ff, Fr] = H_x x + H_phi phi + Gamma
    H_phi: np.ndarray               # 2

    @property
    def where(self) -> str:
        return f"mode {self.index} (vx = {self.vx:g} m/s)"


@dataclass
class ModeDesign:
    """The LMI solution of one mode. P, U in normalised units; L_P, L_I in SI."""

    P: np.ndarray
    U: np.ndarray
    gamma_bar: float
    alpha_bar: float
    L_P: np.ndarray
    L_I: np.ndarray
    status: str
    seconds: float
    conditions: dict

    @property
    def gamma(self) -> float:
        return math.sqrt(max(self.gamma_bar, 0.0))    # corrected misprint (docs/papers/003.md): gamma = sqrt(gamma_bar)


@dataclass
class Design:
    options: DesignOptions
    vehicle: Vehicle
    modes: list[ModeModel]
    solutions: list[ModeDesign]
    model_source: str
    solver: dict = field(default_factory=dict)

    @property
    def gamma(self) -> float:
        return max(s.gamma for s in self.solutions)


# -- model ---------------------------------------------------------------------------------------
def _default_model() -> Callable:
    from .motorcycle_model import reduced_model     # Sharp 1971, reduced (sigma = 0): section II.D
    return reduced_model


def bands(speeds: Sequence[float]) -> list[tuple[float, float]]:
    """Scheduling bands: mode i on [v_i - D, v_i + D') with D, D' half the distances to the
    neighbouring grid speeds (nearest grid speed); departure from eq. (12)'s [v_s, v_s+1]."""
    sp = [float(v) for v in speeds]
    if len(sp) == 1:
        return [(0.5 * sp[0], 1.5 * sp[0])]
    edges = [sp[0] - (sp[1] - sp[0]) / 2] + [(a + b) / 2 for a, b in zip(sp, sp[1:])] + [sp[-1] + (sp[-1] - sp[-2]) / 2]
    return list(zip(edges[:-1], edges[1:]))


def mode_models(vehicle: Vehicle, opts: DesignOptions, model: Callable | None = None) -> list[ModeModel]:
    """The switched models of eq. (12) at the grid speeds: f = [phi, tau], d = [Gamma_f, Gamma_r]."""
    model = model or _default_model()
    out = []
    for i, (v, band) in enumerate(zip(opts.speeds, bands(opts.speeds))):
        m = model(vehicle, float(v))
        A = np.asarray(m.A, float)
        E_f = np.column_stack([np.asarray(m.E_phi, float).ravel(), np.asarray(m.B_tau, float).ravel()])
        E_d = np.asarray(m.E_gamma, float).reshape(len(STATES), len(DISTURBANCES))
        C = np.asarray(m.C, float)
        H_x, H_phi = np.asarray(m.H_x, float), np.asarray(m.H_phi, float).ravel()
        where = f"design {opts.name}, mode {i + 1} (vx = {v:g} m/s)"
        shapes = {"A": (A.shape, (5, 5)), "E_f": (E_f.shape, (5, 2)), "C": (C.shape, (3, 5)),
                  "H_x": (H_x.shape, (2, 5)), "H_phi": (H_phi.shape, (2,))}
        for k, (got, want) in shapes.items():
            if got != want:
                raise DesignError(f"{where}: model matrix {k} has shape {got}, expected {want}")
        for k, M in (("A", A), ("E_f", E_f), ("E_d", E_d), ("C", C), ("H_x", H_x), ("H_phi", H_phi)):
            if not np.all(np.isfinite(M)):
                raise DesignError(f"{where}: model matrix {k} has non-finite entries")
        # y = [delta, r, phidot] are states: C must select them, hence F_d = F_f = 0 (eq. 12)
        if not (np.all((C == 0) | (C == 1)) and np.all(C.sum(axis=1) == 1) and len(set(np.argmax(C, 1))) == 3):
            raise DesignError(f"{where}: C is not a selection of three states; this design assumes y = "
                              f"states (F_d = F_f = 0), got C = {C.tolist()}")
        out.append(ModeModel(i + 1, float(v), band, A, E_f, E_d, C, np.zeros((3, 2)), np.zeros((3, 2)), H_x, H_phi))
    return out


def augmented(mm: ModeModel):
    """Eq. (15): A~, C~, E~_d, I~ (and F_d) of the augmented error system."""
    n, nf = mm.A.shape[0], mm.E_f.shape[1]
    At = np.block([[mm.A, mm.E_f], [np.zeros((nf, n)), np.zeros((nf, nf))]])
    Ct = np.hstack([mm.C, np.zeros((mm.C.shape[0], nf))])
    Edt = np.vstack([mm.E_d, np.zeros((nf, mm.E_d.shape[1]))])
    It = np.vstack([np.eye(n), np.zeros((nf, n))])
    return At, Ct, Edt, It, mm.F_d


def scaling(opts_or_dict) -> dict:
    """Normalisation matrices: x~ = D x~_n, d = Dd d_n, xi = Dx xi_n, r = Y r_n (Y from C)."""
    get = (lambda k: opts_or_dict[k]) if isinstance(opts_or_dict, dict) else (lambda k: getattr(opts_or_dict, k))
    xs, fs, ds = (np.asarray(get(k), float) for k in ("x_scale", "f_scale", "d_scale"))
    return {"D": np.diag(np.concatenate([xs, fs])), "Dx": np.diag(xs), "Dd": np.diag(ds)}


def normalised(At, Ct, Edt, It, Fd, sc: dict):
    """The augmented system in normalised units (module docstring). I~ is unchanged (xi in state
    magnitudes per second); C~_n is the same 0/1 selection as C~ when Y = C Dx C'."""
    D, Dx, Dd = sc["D"], sc["Dx"], sc["Dd"]
    C = Ct[:, : Dx.shape[0]]
    Y = C @ Dx @ C.T
    Di, Yi = np.linalg.inv(D), np.linalg.inv(Y)
    return Di @ At @ D, Yi @ Ct @ D, Di @ Edt @ Dd, Di @ It @ Dx, Yi @ Fd @ Dd, Y


# -- existence conditions --------------------------------------------------------------------------
def _rank(M: np.ndarray, tol: float) -> tuple[int, float]:
    s = np.linalg.svd(M, compute_uv=False)
    if s.size == 0 or s[0] == 0:
        return 0, 0.0
    return int(np.sum(s > tol * s[0])), float(s[-1] / s[0]) if M.shape[0] >= M.shape[1] else 0.0


def rank_condition_24(A, E_f, C, tol: float = 1e-9) -> dict:
    """Eq. (24): rank [[sI - A, -E_f], [0, sI], [C, 0]] = n + rank(E_f) for Re s >= 0.

    Only s = 0 and the eigenvalues of A with Re >= 0 can fail it: elsewhere sI - A and sI are
    invertible and the block-triangular matrix has full column rank. Returns {"ok", "points":
    [{s, rank, required, margin}]} with margin = sigma_min / sigma_max of the pencil.
    """
    A, E_f, C = (np.asarray(M, float) for M in (A, E_f, C))
    n, nf, ny = A.shape[0], E_f.shape[1], C.shape[0]
    need = n + np.linalg.matrix_rank(E_f)
    pts = [0.0 + 0.0j] + [complex(l) for l in np.linalg.eigvals(A) if l.real >= -tol * max(1.0, abs(l))]
    out = []
    for s in pts:
        M = np.block([[s * np.eye(n) - A, -E_f], [np.zeros((nf, n)), s * np.eye(nf)], [C, np.zeros((ny, nf))]])
        r, margin = _rank(M, tol)
        out.append({"s": s, "rank": r, "required": int(need), "margin": margin})
    return {"ok": all(p["rank"] >= p["required"] for p in out), "points": out}


def detectability(At, Ct, tol: float = 1e-9) -> dict:
    """PBH test of (A~, C~): rank [lambda I - A~; C~] = n_a at every eigenvalue lambda of A~ with
    Re lambda >= 0 (the unstable or marginal modes must be observable)."""
    At, Ct = np.asarray(At, float), np.asarray(Ct, float)
    na = At.shape[0]
    out = []
    for lam in np.linalg.eigvals(At):
        if lam.real < -tol * max(1.0, abs(lam)):
            continue
        r, margin = _rank(np.vstack([lam * np.eye(na) - At, Ct]), tol)
        out.append({"s": complex(lam), "rank": r, "required": na, "margin": margin})
    return {"ok": all(p["rank"] >= p["required"] for p in out), "points": out}


def check_conditions(mm: ModeModel, tol: float = 1e-9, name: str = "") -> dict:
    """Both existence conditions for one mode; raises ConditionError naming the mode and condition."""
    At, Ct, *_ = augmented(mm)
    r24 = rank_condition_24(mm.A, mm.E_f, mm.C, tol)
    det = detectability(At, Ct, tol)
    for label, res in (("rank condition (24)", r24), ("detectability of (A~, C~) (PBH test)", det)):
        if not res["ok"]:
            bad = [p for p in res["points"] if p["rank"] < p["required"]]
            raise ConditionError(
                f"design {name}: {mm.where}: {label} fails at s = "
                + ", ".join(f"{p['s']:.4g} (rank {p['rank']} < {p['required']})" for p in bad)
                + ": f = [roll angle, rider torque] cannot be estimated from y = [steer angle, yaw rate, "
                  "roll rate] with this model")
    return {"rank_24": r24, "detectability": det}


# -- LMIs (20)-(23) ------------------------------------------------------------------------------------
def _sym(M):
    return (M + M.T) / 2


def _cp_bmat(blocks):
    import cvxpy as cp
    return cp.bmat(blocks)


def lmi_blocks(At, Ct, Edt, It, Fd, P, U, gamma_bar):
    """The matrices of (20) and (21) (numpy or cvxpy expressions), with the misprint corrected (docs/papers/003.md): C~'U' not C~'U."""
    bm = np.block if isinstance(P, np.ndarray) else _cp_bmat
    na, nd, nxi = At.shape[0], Edt.shape[1], It.shape[1]
    PA = P @ At + U @ Ct                                   # = P (A~ - L C~) with L = -P^-1 U
    core = PA + PA.T                                       # A~'P + C~'U' + P A~ + U C~
    Omega = core + Ct.T @ Ct
    Lam = P @ Edt + U @ Fd + Ct.T @ Fd
    Pi = core + np.eye(na)
    Phi = P @ Edt + U @ Fd
    PI = P @ It
    Z = np.zeros((nd, nxi))
    g = gamma_bar
    m20 = bm([[Omega, Lam, PI], [Lam.T, Fd.T @ Fd - g * np.eye(nd), Z], [PI.T, Z.T, -g * np.eye(nxi)]])
    m21 = bm([[Pi, Phi, PI], [Phi.T, -g * np.eye(nd), Z], [PI.T, Z.T, -g * np.eye(nxi)]])
    return m20, m21


def lmi_22(P, alpha_bar, printed: bool = False):
    """(22), corrected (docs/papers/003.md): [[alpha_bar I, P], [P, I]] (>= 0); printed: [[-alpha_bar I, P], [P, -I]]."""
    na = P.shape[0]
    bm = np.block if isinstance(P, np.ndarray) else _cp_bmat
    s = -1.0 if printed else 1.0
    return bm([[s * alpha_bar * np.eye(na), P], [P, s * np.eye(na)]])


def solve_mode(mm: ModeModel, opts: DesignOptions) -> ModeDesign:
    """Solve (20)-(23) (+ the optional pole region) for one mode with cvxpy (lmi: Clarabel by default)."""
    import cvxpy as cp  # design time only

    conditions = check_conditions(mm, opts.rank_tol, opts.name)
    sc = scaling(opts)
    # departure: the LMIs are posed in normalised units (module docstring), gains mapped back below
    At, Ct, Edt, It, Fd, Y = normalised(*augmented(mm), sc)
    na, ny = At.shape[0], Ct.shape[0]
    P = cp.Variable((na, na), symmetric=True)
    U = cp.Variable((na, ny))
    gb = cp.Variable(nonneg=True)
    ab = cp.Variable(nonneg=True)
    m20, m21 = lmi_blocks(At, Ct, Edt, It, Fd, P, U, gb)
    eps = opts.margin       # small strictness margins so that the certificate's limits are exact zeros
    fam = {
        "(20) H-infinity d~ -> r": [_sym(m20) << -eps * np.eye(m20.shape[0])],
        "(21) ISS": [_sym(m21) << -eps * np.eye(m21.shape[0])],
        # corrected misprint (docs/papers/003.md): the printed (22) has -alpha_bar I and -I on the diagonal (never >= 0)
        f"(22) {opts.lmi22}": [_sym(lmi_22(P, ab, opts.lmi22 == "printed")) >> eps * np.eye(2 * na)],
        "(23) P >= I": [P >> (1 + eps) * np.eye(na)],
    }
    PA = P @ At + U @ Ct
    if opts.alpha is not None:     # optional alpha-stability (not in (20)-(23)): Re lambda(A*) < -alpha
        fam[f"alpha-stability Re < -{opts.alpha:g}"] = [_sym(PA + PA.T + 2 * opts.alpha * P) << -eps * np.eye(na)]
    if opts.radius is not None:    # optional disk |lambda(A*)| < radius
        Dk = cp.bmat([[-opts.radius * P, PA], [PA.T, -opts.radius * P]])
        fam[f"disk |lambda| < {opts.radius:g}"] = [_sym(Dk) << -eps * np.eye(2 * na)]
    cons = [c for cs in fam.values() for c in cs]
    prob = cp.Problem(cp.Minimize(opts.beta * ab + (1 - opts.beta) * gb), cons)
    status, seconds = lmi.solve(prob)
    if not lmi.solved(status) or P.value is None or U.value is None:
        raise DesignError(f"design {opts.name}: {mm.where}: no solution of LMIs (20)-(23) ({lmi.label()}: {status}); "
                          + _diagnose(fam))
    Pn, Un = _sym(P.value), U.value
    Ln = -np.linalg.solve(Pn, Un)                         # L = -P^-1 U (a misprint corrected: docs/papers/003.md, departures), normalised
    L = sc["D"] @ Ln @ np.linalg.inv(Y)                   # back to SI: L = D L_n Y^-1
    n = mm.A.shape[0]
    return ModeDesign(P=Pn, U=Un, gamma_bar=float(gb.value), alpha_bar=float(ab.value), L_P=L[:n], L_I=L[n:],
                      status=str(status), seconds=seconds, conditions=conditions)


def _diagnose(fam: dict) -> str:
    alone = [k for k, c in fam.items() if not lmi.feasible(c)]
    if alone:
        return "infeasible on its own: " + ", ".join(alone)
    return "each LMI family is feasible alone; together they are not (" + " + ".join(fam) + ")"


def design(vehicle: Vehicle, opts: DesignOptions, model: Callable | None = None) -> Design:
    """Per-mode LMI design (20)-(23). ``model(vehicle, vx)`` returns a ReducedModel (default:
    ``motorcycle_model.reduced_model``). Raises ConditionError / DesignError."""
    opts.validate()
    modes = mode_models(vehicle, opts, model)
    sols = [solve_mode(mm, opts) for mm in modes]
    source = "latobs.synthesis.motorcycle_model.reduced_model" if model is None else \
        f"{getattr(model, '__module__', '?')}.{getattr(model, '__qualname__', repr(model))}"
    statuses = sorted({s.status for s in sols})
    solver = {"name": lmi.current(), "status": statuses[0] if len(statuses) == 1 else ",".join(statuses),
              "seconds": round(sum(s.seconds for s in sols), 4),
              "per_mode": [{"mode": mm.index, "status": s.status, "seconds": round(s.seconds, 4)}
                           for mm, s in zip(modes, sols)]}
    return Design(opts, vehicle, modes, sols, source, solver)


# -- closed loop, ISS and dwell time ------------------------------------------------------------------
def closed_loop_normalised(mm: ModeModel, L_P, L_I, sc: dict):
    """A*_n = A~_n - L_n C~_n, E~_d,n, I~_n, C~_n (normalised) from the SI gains."""
    At, Ct, Edt, It, Fd, Y = normalised(*augmented(mm), sc)
    L = np.vstack([np.asarray(L_P, float), np.asarray(L_I, float)])
    Ln = np.linalg.inv(sc["D"]) @ L @ Y
    return At - Ln @ Ct, Edt, It, Ct, Fd


def decay_rate(Acl: np.ndarray, P: np.ndarray) -> float:
    """The largest lambda_0 with A*'P + P A* <= -lambda_0 P: the smallest generalized eigenvalue
    of (-(A*'P + P A*), P) (V = x'Px decays at least as exp(-lambda_0 t))."""
    Q = -_sym(Acl.T @ P + P @ Acl)
    return float(np.min(scipy.linalg.eigh(Q, _sym(P), eigvals_only=True)))


def mu_matrix(Ps: Sequence[np.ndarray]) -> np.ndarray:
    """mu_ij = lambda_max(P_i^-1 P_j), the least mu with x'P_j x <= mu x'P_i x for all x (a switch
    i -> j multiplies V by at most mu_ij)."""
    k = len(Ps)
    mu = np.ones((k, k))
    for i in range(k):
        for j in range(k):
            if i != j:
                mu[i, j] = float(np.max(scipy.linalg.eigh(_sym(Ps[j]), _sym(Ps[i]), eigvals_only=True)))
    return mu


def dwell_time(Ps: Sequence[np.ndarray], Acls: Sequence[np.ndarray]) -> dict:
    """Average dwell time that the multiple Lyapunov functions V_i = x'P_i x guarantee.

    With V_i' <= -lambda_0 V_i in every mode and V_j <= mu V_i at every switch i -> j, a switching
    signal with N_sigma(t0, t) <= N0 + (t - t0)/tau_a and tau_a > ln(mu)/lambda_0 keeps the error
    system GUAS (ISS with the inputs): V(t) <= exp(N0 ln mu) exp(-(lambda_0 - ln(mu)/tau_a)(t - t0))
    V(t0) (Hespanha & Morse 1999; Liberzon 2003, Thm 3.2). mu over all pairs (arbitrary jumps) and
    over neighbouring modes only (the speed is continuous and the bands are contiguous).
    """
    lam = [decay_rate(A, P) for A, P in zip(Acls, Ps)]
    mu = mu_matrix(Ps)
    k = len(Ps)
    mu_all = float(np.max(mu)) if k > 1 else 1.0
    mu_adj = float(max([max(mu[i, i + 1], mu[i + 1, i]) for i in range(k - 1)], default=1.0))
    lam0 = float(min(lam))
    tau = lambda m: (math.log(m) / lam0 if m > 1 else 0.0) if lam0 > 0 else math.inf
    return {"lambda_0_per_mode": lam, "lambda_0": lam0, "mu_matrix": mu, "mu": mu_all, "mu_adjacent": mu_adj,
            "tau_a": tau(mu_all), "tau_a_adjacent": tau(mu_adj),
            "rule": "N_sigma(t0, t) <= N0 + (t - t0)/tau_a with tau_a > ln(mu)/lambda_0 "
                    "(Hespanha & Morse 1999); lambda_0 = min_i max{l : A*_i'P_i + P_i A*_i <= -l P_i}, "
                    "mu = max_{i != j} lambda_max(P_i^-1 P_j)"}


def mode_of_speed(vx: float, edges: Sequence[float], current: int | None, hysteresis: float) -> int:
    """The runtime's scheduling rule (0-based): nearest grid speed, bands [edges[i], edges[i+1]),
    clamped to the first/last mode outside the grid; the current mode is kept while vx stays
    within its band widened by ``hysteresis`` on both sides."""
    k = len(edges) - 1
    if current is not None and 0 <= current < k:
        lo = edges[current] - hysteresis if current > 0 else -math.inf
        hi = edges[current + 1] + hysteresis if current < k - 1 else math.inf
        if lo <= vx < hi:
            return current
    i = int(np.searchsorted(edges, vx, side="right")) - 1
    return min(max(i, 0), k - 1)


def modes_of_speed(data: dict, t: Iterable[float], vx: Iterable[float]) -> list[tuple[float, int]]:
    """(t, mode 1-based) along a speed profile with the runtime's rule (design dict's switching)."""
    sw = data["switching"]
    edges, hyst = [float(e) for e in sw["edges"]], float(sw["hysteresis"])
    cur, out = None, []
    for ti, v in zip(t, vx):
        cur = mode_of_speed(float(v), edges, cur, hyst)
        out.append((float(ti), cur + 1))
    return out


def dwell_report(design, mode_sequence_times, N0: float = 1.0, adjacent: bool = False) -> dict:
    """Does a switching signal respect the average dwell time the design needs?

    ``design``: a Design or a design dict; ``mode_sequence_times``: (t, mode) samples in time order
    (e.g. ``modes_of_speed``). Counts the switches and checks N_sigma(t0, t) <= N0 + (t - t0)/tau_a
    on every window (the binding windows open just before one switch and close at a later one).
    N0 = 1 (chatter bound) by default: one switch is always allowed. ``adjacent``: use the
    neighbouring-mode mu (valid when the speed, hence the mode, only steps to a neighbour).
    """
    dw = design["dwell_time"] if isinstance(design, dict) else dwell_time_of(design)
    tau_a = float(dw["tau_a_adjacent" if adjacent else "tau_a"])
    seq = list(mode_sequence_times)
    switches = [t1 for (t0, m0), (t1, m1) in zip(seq, seq[1:]) if m1 != m0]
    worst, worst_win = math.inf, None
    for i in range(len(switches)):
        for j in range(i, len(switches)):
            allowed = N0 + (switches[j] - switches[i]) / tau_a if math.isfinite(tau_a) else N0
            margin = allowed - (j - i + 1)
            if margin < worst:
                worst, worst_win = margin, (switches[i], switches[j])
    gaps = [b - a for a, b in zip(switches, switches[1:])]
    return {"tau_a_required": tau_a, "N0": N0, "switches": len(switches), "switch_times": switches,
            "min_interval": min(gaps) if gaps else None,
            "worst_margin": worst if switches else None, "worst_window": worst_win,
            "satisfied": (worst >= 0) if switches else True,
            "mu": "adjacent modes" if adjacent else "all mode pairs"}


def dwell_time_of(design: Design) -> dict:
    sc = scaling(design.options)
    Acls = [closed_loop_normalised(mm, s.L_P, s.L_I, sc)[0] for mm, s in zip(design.modes, design.solutions)]
    return dwell_time([s.P for s in design.solutions], Acls)


# -- design file ----------------------------------------------------------------------------------------
def iss_constants(P: np.ndarray, Acl: np.ndarray) -> dict:
    """The ISS bound after (23): kappa = sqrt(lambda_max/lambda_min) and the decay rates."""
    ev = np.linalg.eigvalsh(_sym(P))
    return {"kappa": float(math.sqrt(ev[-1] / ev[0])), "lambda_min_P": float(ev[0]), "lambda_max_P": float(ev[-1]),
            "decay_rate_paper": float(1.0 / (2.0 * ev[-1])),      # exp(-t / (2 lambda_max(P))) of the bound
            "decay_rate_lyapunov": float(decay_rate(Acl, P) / 2.0)}


def to_design_dict(design: Design) -> dict:
    """Everything the certificate and the FMU runtime need, as plain data (no certificate yet)."""
    o, veh = design.options, design.vehicle
    sc = scaling(o)
    edges = [b[0] for b in (m.band for m in design.modes)] + [design.modes[-1].band[1]]
    modes, Acls = [], []
    for mm, s in zip(design.modes, design.solutions):
        Acl, *_ = closed_loop_normalised(mm, s.L_P, s.L_I, sc)
        Acls.append(Acl)
        At, Ct, *_ = augmented(mm)
        L = np.vstack([s.L_P, s.L_I])
        poles = np.linalg.eigvals(At - L @ Ct)
        poles = sorted(poles, key=lambda z: (z.real, z.imag))
        modes.append({
            "index": mm.index, "label": f"vx = {mm.vx:g} m/s", "vx": mm.vx, "band": list(mm.band),
            "scheduling": {"variable": "vx", "unit": "m/s", "value": mm.vx, "range": list(mm.band)},
            "model": {"A": mm.A, "E_f": mm.E_f, "E_d": mm.E_d, "C": mm.C, "F_d": mm.F_d, "F_f": mm.F_f,
                      "H_x": mm.H_x, "H_phi": mm.H_phi},
            "gains": {"L_P": s.L_P, "L_I": s.L_I},
            "P": s.P, "U": s.U,                       # normalised units (see "scaling")
            "gamma": s.gamma, "gamma_bar": s.gamma_bar, "alpha_bar": s.alpha_bar,
            "poles": {"re": [z.real for z in poles], "im": [z.imag for z in poles]},
            "iss": iss_constants(s.P, Acl),
            "conditions": {
                "rank_24_min_margin": min(p["margin"] for p in s.conditions["rank_24"]["points"]),
                "rank_24_points": [[p["s"].real, p["s"].imag] for p in s.conditions["rank_24"]["points"]],
                "detectability_min_margin": min([p["margin"] for p in s.conditions["detectability"]["points"]],
                                                default=1.0)},
            "solver": {"status": s.status, "seconds": round(s.seconds, 4)},
        })
    dw = dwell_time([s.P for s in design.solutions], Acls)
    data = {
        "schema": "latobs.design/1",
        "name": o.name,
        "paper": "003",
        "title": "Switched H-infinity PI observer for motorcycle rider torque and roll angle estimation "
                 "(paper 003, eqs. (12)-(24))",
        "vehicle": veh.as_dict(),
        "options": {k: getattr(o, k) for k in o.__dataclass_fields__},
        "structure": {"states": list(STATES), "state_units": list(STATE_UNITS), "faults": list(FAULTS),
                      "fault_units": list(FAULT_UNITS), "disturbances": list(DISTURBANCES) + [f"xi_{k}" for k in STATES],
                      "measurements": list(MEASUREMENTS), "forces": list(FORCES), "input_u": "none (u = 0)",
                      "model_source": design.model_source,
                      "model_form": "x' = A x + E_f f + E_d d + xi, y = C x (F_d = F_f = 0), f = [phi, tau], "
                                    "d = [Gamma_f, Gamma_r]; forces [Ff, Fr] = H_x x + H_phi phi + d"},
        "scaling": {"x_scale": list(o.x_scale), "f_scale": list(o.f_scale), "d_scale": list(o.d_scale),
                    "rule": "LMIs posed for x~ = D x~_n, d = Dd d_n, xi = Dx xi_n, r = Y r_n, D = diag(x_scale, "
                            "f_scale), Dd = diag(d_scale), Y = C Dx C'; gamma is dimensionless; P, U normalised; "
                            "L (SI) = D L_n Y^-1"},
        "switching": {"kind": "speed_bands", "variable": "vx", "unit": "m/s", "edges": edges,
                      "hysteresis": o.hysteresis,
                      "rule": "mode i (model at grid speed v_i) on [edges[i], edges[i+1]) (nearest grid speed; "
                              "eq. (12) uses [v_s, v_s+1]); outside the grid the nearest mode; the current mode is "
                              "kept while vx is within its band widened by the hysteresis (not in the paper)"},
        "modes": modes,
        "gamma": design.gamma,
        "beta": o.beta,
        "region": {"alpha": o.alpha, "radius": o.radius},
        "dwell_time": dw,
        "runtime": {"vx_hold": o.vx_hold,
                    "equations": "x^' = A_s x^ + L_P,s (y - C x^) + E_f,s f^; f^' = L_I,s (y - C x^) (eq. 13, u = 0); "
                                 "[Ff^, Fr^] = H_x x^ + H_phi phi^ (Gamma not estimated)",
                    "outputs": ["roll_angle_hat", "rider_torque_hat", "vy_hat", "steer_rate_hat", "Ff_hat", "Fr_hat",
                                "residual_norm", "mode"]},
        "solver": design.solver,
    }
    data["notes"] = [
        "One Lyapunov matrix per mode: stability under switching only for signals with the average dwell "
        f"time tau_a > {dw['tau_a']:.3g} s (all mode pairs) / {dw['tau_a_adjacent']:.3g} s (neighbouring modes); "
        "see dwell_time.",
        "gamma is the per-mode L2 gain from the normalised d~ = [Gamma; xi] to the normalised residual (16), for "
        "the frozen grid-speed model; nothing is claimed between grid speeds nor for the nonlinear motorcycle.",
        "f = [phi, tau] is assumed constant by the PI structure (section III); time-varying inputs are tracked "
        "with the lag set by the observer poles.",
    ]
    return data
