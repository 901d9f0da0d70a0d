"""Paper 001's design: Theorem 1's switched interval observer (LMIs 34-36, a common diagonal Q),
solved in a normalised time scale, its Metzler structure projected and re-checked, and the
observer matrices of eqs. (30), (33). The LMIs and the departures are on the documentation's
paper-001 page."""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from . import lmi
from . import relaxation_model as rm
from .params import Vehicle

PAPER_EDGES = (10.0, 13.0, 16.0, 20.0)      # m/s, eq. (44): V_x^0 .. V_x^3
PAPER_SPEEDS = (11.5, 14.5, 18.0)           # m/s, eq. (44): the modes' model speeds


class DesignError(RuntimeError):
    """The LMIs are infeasible or the solver failed; the message names the design and the LMI."""


@dataclass(frozen=True)
class DesignOptions:
    """Options of a paper-001 design (SI units: m/s, 1/s)."""

    name: str
    edges: tuple[float, ...] | None = None      # band edges (m/s); None: eq. (44), or the vehicle's speed range
    speeds: tuple[float, ...] | None = None     # model speed per band (m/s); None: eq. (44) or band midpoints
    box: tuple[float, float] = (0.2, 0.2)       # relative half-widths of the Cf and Cr box (eq. 10)
    epsilon: float = 0.5                        # 1/s, ISS rate of eq. (35)
    eta: float = 7.0                            # 1/s, Metzler shift of eq. (36)
    margin: float = 1e-7                        # strictness of (35) in scaled units
    # rad/s, m/s^2: |measured - true| of [r, ay] (not in the paper: its y is exact); None: the
    # vehicle's parameters yaw_rate_error_bound, ay_error_bound (`latobs identify` writes them), else 0.
    # The FMU's start values of its parameters of the same names
    y_error_bound: tuple[float, float] | None = None
    x0_halfwidth: tuple[float, float, float, float] = (3.0, 0.0, 0.0, 30.0)  # initial box half-widths
    # bound of an additive model error w of eq. (9), x' = A x + B delta + w (units of x': m/s^2,
    # rad/s^2, m/s^3, rad/s^3). Not in the paper (0: its model class). E.g. a rolling car's
    # kinematic slip hr*phidot/vx puts up to ~30 m/s^3 on x3' and ~12 rad/s^3 on x4' (sedan, CarPlant)
    model_error_bound: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
    gain_limit: float = 1e4                     # certificate: largest admissible |entry| of E, K, J

    def validate(self) -> None:
        where = f"design {self.name}"
        if self.edges is not None:
            e = list(self.edges)
            if len(e) < 2 or any(not (x > 0 and math.isfinite(x)) for x in e) or e != sorted(set(e)):
                raise ValueError(f"{where}: edges must be >= 2 positive increasing speeds (m/s), got {self.edges}")
            if self.speeds is not None and len(self.speeds) != len(e) - 1:
                raise ValueError(f"{where}: {len(e) - 1} bands need {len(e) - 1} speeds, got {self.speeds}")
        if self.speeds is not None and self.edges is None and len(self.speeds) != len(PAPER_SPEEDS):
            raise ValueError(f"{where}: speeds without edges must be one per band of eq. (44)")
        if not all(0 <= b < 1 for b in self.box):
            raise ValueError(f"{where}: box half-widths must be in [0, 1) (relative), got {self.box}")
        if not (self.epsilon > 0 and self.eta > 0):
            raise ValueError(f"{where}: epsilon and eta must be > 0 (1/s), got {self.epsilon}, {self.eta}")
        if len(self.model_error_bound) != 4 or any(not (b >= 0 and math.isfinite(b)) for b in self.model_error_bound):
            raise ValueError(f"{where}: model_error_bound must be four finite values >= 0, got {self.model_error_bound}")
        if self.y_error_bound is not None and (len(self.y_error_bound) != 2 or any(
                not (b >= 0 and math.isfinite(b)) for b in self.y_error_bound)):
            raise ValueError(f"{where}: y_error_bound must be two finite values >= 0 (rad/s, m/s^2), got "
                             f"{self.y_error_bound}")


@dataclass
class Design:
    options: DesignOptions
    vehicle: Vehicle
    values: dict                        # the model's vehicle parameters (SI)
    edges: list[float]
    speeds: list[float]
    cf_box: tuple[float, float]
    cr_box: tuple[float, float]
    q: np.ndarray                       # diagonal of Q
    gamma: float
    modes: list[dict]                   # per mode: A, B, N, E, J, H, P, K
    solver: dict = field(default_factory=dict)
    y_error_bound: tuple[float, float] = (0.0, 0.0)     # rad/s, m/s^2 (:func:`error_bounds`)


#: the vehicle parameters of the measurement-error bounds, in the order of y = [r, ay]
ERROR_BOUND_PARAMETERS = ("yaw_rate_error_bound", "ay_error_bound")


def error_bounds(vehicle: Vehicle, opts: DesignOptions) -> tuple[float, float]:
    """(rad/s, m/s^2) bounds of |measured - true| of [r, ay]: the option's, else the vehicle's
    parameters ERROR_BOUND_PARAMETERS (both or none), else exact measurements as in the paper."""
    if opts.y_error_bound is not None:
        return (float(opts.y_error_bound[0]), float(opts.y_error_bound[1]))
    have = [k for k in ERROR_BOUND_PARAMETERS if k in vehicle.parameters]
    if not have:
        return (0.0, 0.0)
    if len(have) < 2:
        missing = next(k for k in ERROR_BOUND_PARAMETERS if k not in have)
        raise ValueError(f"design {opts.name}: vehicle {vehicle.name!r} has {have[0]} but not {missing}: give both "
                         "measurement-error bounds (or neither)")
    return (vehicle.value(ERROR_BOUND_PARAMETERS[0]), vehicle.value(ERROR_BOUND_PARAMETERS[1]))


def speed_grid(vehicle: Vehicle, opts: DesignOptions) -> tuple[list[float], list[float]]:
    """(edges, speeds) of the switching law eq. (44): the options', else the paper's, else, for a
    vehicle with a ``speed`` range (m/s or km/h) outside the paper's grid, equal bands covering the range,
    at most 4 m/s wide like the paper's widest band (16-20 m/s), the model speed at each band's
    centre. (The runtime bounds the speed mismatch inside a band; its width gain (vx - vx_i)/sigma
    on the yaw-acceleration state must stay below eta: the certificate checks it.)"""
    if opts.edges is not None:
        edges = [float(x) for x in opts.edges]
        speeds = list(opts.speeds) if opts.speeds is not None else [(a + b) / 2 for a, b in zip(edges, edges[1:])]
        return edges, [float(s) for s in speeds]
    rng = vehicle.speed_range()
    if rng is not None and (rng[0] < PAPER_EDGES[0] or rng[1] > PAPER_EDGES[-1]):
        lo, hi = rng
        n = max(1, math.ceil((hi - lo) / 4.0))
        edges = [lo + (hi - lo) * k / n for k in range(n + 1)]
        return edges, [(a + b) / 2 for a, b in zip(edges, edges[1:])]
    return list(PAPER_EDGES), list(opts.speeds or PAPER_SPEEDS)


def design(vehicle: Vehicle, opts: DesignOptions) -> Design:
    """Solve Theorem 1 (LMIs 34-36) with cvxpy (lmi: Clarabel by default). Raises DesignError naming the LMI."""
    import cvxpy as cp  # design time only

    opts.validate()
    v = rm.vehicle_values(vehicle, f"design {opts.name} (paper 001 relaxation model)")
    edges, speeds = speed_grid(vehicle, opts)
    for i, (s, lo, hi) in enumerate(zip(speeds, edges, edges[1:])):
        if not lo <= s <= hi:
            raise ValueError(f"design {opts.name}: mode {i + 1} model speed {s} m/s outside its band [{lo}, {hi}]")
    nu = error_bounds(vehicle, opts)
    cf_box = (v["Cf"] * (1 - opts.box[0]), v["Cf"] * (1 + opts.box[0]))
    cr_box = (v["Cr"] * (1 - opts.box[1]), v["Cr"] * (1 + opts.box[1]))
    A0, A1, B1 = rm.coefficients(v["m"], v["Iz"], v["lf"], v["lr"], v["sigma"], v["Cf"], v["Cr"])
    C = rm.C
    n, ny = 4, C.shape[0]
    tau = opts.eta                                           # 1/s, time scale of the LMIs
    eps_s, eta_s = opts.epsilon / tau, opts.eta / tau

    q = cp.Variable(n)
    X = [cp.Variable((n, ny)) for _ in speeds]
    W = [cp.Variable((n, ny)) for _ in speeds]
    g = cp.Variable(nonneg=True)
    Q = cp.diag(q)
    lmi35, lmi36 = [], []
    for i, vx in enumerate(speeds):
        As = (A0 + vx * A1) / tau
        L = Q @ As - X[i] @ C @ As - W[i] @ C               # = Q N_i / tau
        M = cp.bmat([[L + L.T + eps_s * Q, Q], [Q, -g * np.eye(n)]])
        # (a cvxpy semidefinite constraint is on the symmetric part (M + M') / 2 of its matrix)
        lmi35.append(M << -opts.margin * np.eye(2 * n))
        lmi36.append(L + eta_s * Q >= 0)
    base = [q >= 1.0]                                        # (34) with alpha = 1
    prob = cp.Problem(cp.Minimize(g), base + lmi35 + lmi36)
    status, seconds = lmi.solve(prob)
    if not lmi.solved(status) or q.value is None:
        raise DesignError(f"design {opts.name}: no solution ({lmi.label()}: {status}) of Theorem 1 (LMIs 34-36, "
                          f"eps = {opts.epsilon:g}, eta = {opts.eta:g}) over {len(speeds)} speed modes; "
                          + _diagnose(base, lmi35, lmi36))
    qv = np.asarray(q.value, float)
    modes, shift, worst = [], 0.0, -math.inf
    for i, vx in enumerate(speeds):
        A, B = A0 + vx * A1, vx * B1
        E = np.diag(1.0 / qv) @ X[i].value
        K = tau * np.diag(1.0 / qv) @ W[i].value
        mode, s = _exact_structure(A, B, E, K, opts.eta, f"design {opts.name}, mode {i + 1} ({vx:g} m/s)")
        shift = max(shift, s)
        # LMI (35) re-checked on the projected N (the numbers the runtime uses), in the solver's
        # scaled units (L = Q N / tau, gamma_s = tau gamma), with the stated margin VERIFY_MARGIN
        Qm = np.diag(qv)
        L = Qm @ mode["N"] / tau
        M = np.block([[L + L.T + eps_s * Qm, Qm], [Qm, -float(g.value) * np.eye(n)]])
        worst = max(worst, lmi.max_eig(M))
        modes.append(mode)
    if not worst <= -VERIFY_MARGIN * opts.margin:
        raise DesignError(f"design {opts.name}: LMI (35) fails on the gains projected onto the Metzler "
                          f"structure of (36): largest eigenvalue {worst:.3g} > -{VERIFY_MARGIN * opts.margin:.3g} "
                          f"(scaled units); raise margin")
    return Design(options=opts, vehicle=vehicle, values=v, edges=edges, speeds=speeds, cf_box=cf_box,
                  cr_box=cr_box, q=qv, gamma=float(g.value) / tau, modes=modes, y_error_bound=nu,
                  solver={"name": lmi.current(), "status": str(status), "seconds": round(seconds, 4),
                          "lmis": len(base) + len(lmi35) + len(lmi36), "time_scale_per_s": tau,
                          "structure": {"largest_projection_shift": shift, "lmi35_max_eig_scaled": worst,
                                        "lmi35_required": -VERIFY_MARGIN * opts.margin}})


#: LMI (35) must hold on the projected gains with max eigenvalue <= -VERIFY_MARGIN x margin (scaled
#: units): the solver imposed -margin to its tolerance, the projection moves N by round-off.
VERIFY_MARGIN = 0.5


def _exact_structure(A, B, E, K, eta: float, where: str) -> tuple[dict, float]:
    """The mode's matrices with the structure of (36) imposed exactly (not in the paper: the solver
    meets (36) only to its tolerance, leaving off-diagonal entries of N = P A - K C of -1e-8 where
    the optimum puts them on 0, and the runtime's order-preserving update needs N Metzler in
    floating point). N is projected onto {N + eta I >= 0} (off-diagonal >= 0, diagonal >= -eta),
    then E, K are re-solved so that eq. (33) holds for the projected N: N = A - E C A - K C row by
    row, [E K] S = A - N with S = [C A; C] (invertible for this model: C picks r and ay, C A adds
    the yaw acceleration and a row with -(cf + cr)/(m sigma) on vy), and P, J, H follow (30, 33).
    Returns (matrices, the largest entry the projection moved)."""
    n = A.shape[0]
    C = rm.C
    N0 = (np.eye(n) - E @ C) @ A - K @ C
    try:
        N, shift = lmi.project_lower(N0, -eta * np.eye(n), f"{where}: (36) N + eta I >= 0")
    except lmi.StructureError as exc:
        raise DesignError(str(exc)) from None
    S = np.vstack([C @ A, C])
    if np.linalg.matrix_rank(S) < n:
        raise DesignError(f"{where}: [C A; C] is singular, the gains cannot be re-solved for the projected N (33)")
    EK = np.linalg.solve(S.T, (A - N).T).T
    E, K = EK[:, :C.shape[0]], EK[:, C.shape[0]:]
    P = np.eye(n) - E @ C
    return {"A": A, "B": B, "E": E, "K": K, "P": P, "N": N, "J": K + N @ E, "H": P @ B}, shift


def _diagnose(base, lmi35, lmi36) -> str:
    if not lmi.feasible(base + lmi36):
        return "the Metzler constraint (36) alone is infeasible: raise eta"
    if not lmi.feasible(base + lmi35):
        return "the ISS LMI (35) alone is infeasible: lower epsilon"
    return "(35) and (36) are feasible apart but not together: raise eta or lower epsilon"


def to_design_dict(d: Design) -> dict:
    """Everything the certificate and the FMU runtime need, as plain data (no certificate yet)."""
    o, v = d.options, d.values
    A0, A1, B1 = rm.coefficients(v["m"], v["Iz"], v["lf"], v["lr"], v["sigma"], v["Cf"], v["Cr"])
    dA_lo, dA_hi, dB_lo, dB_hi = rm.stiffness_bounds(v, d.cf_box, d.cr_box)
    eta_shift = max(o.eta, max(float(-np.min(np.diag(m["N"]))) for m in d.modes))
    alpha = 1.0
    data = {
        "schema": "latobs.design/1",
        "name": o.name,
        "paper": "001",
        "title": "Vehicle lateral velocity and lateral tire-road forces estimation based on switched "
                 "interval observers (Ifqir, Ichalal, Ait-Oufroukh, Mammar, ACC 2020)",
        "vehicle": d.vehicle.as_dict(),
        "options": {k: getattr(o, k) for k in o.__dataclass_fields__},
        "model": {"states": list(rm.STATES), "state_units": list(rm.STATE_UNITS), "input": "delta",
                  "measurements": list(rm.OUTPUTS), "form": "A(vx) = A0 + vx A1 + dA, B(vx) = vx (B1 + dB1)",
                  "A0": A0, "A1": A1, "B1": B1, "C": rm.C, "dA_lower": dA_lo, "dA_upper": dA_hi,
                  "dB1_lower": dB_lo, "dB1_upper": dB_hi, **{k: v[k] for k in rm.PARAMETERS}},
        "stiffness_box": {"Cf": list(d.cf_box), "Cr": list(d.cr_box), "relative": list(o.box),
                          "unit": "N/rad (per axle)"},
        "switching": {"kind": "speed_bands", "variable": "vx", "unit": "m/s", "edges": d.edges,
                      "rule": "eq. (44): mode i on [V_x^(i-1), V_x^i[; outside the grid the nearest mode"},
        "modes": [{"index": i + 1, "vx": s, "band": [d.edges[i], d.edges[i + 1]],
                   **{k: m[k] for k in ("A", "B", "N", "E", "J", "H", "P", "K")}}
                  for i, (s, m) in enumerate(zip(d.speeds, d.modes))],
        "Q": d.q,
        "gamma": d.gamma,
        "epsilon": o.epsilon,
        "eta": o.eta,
        "alpha": alpha,
        "beta": float(np.max(d.q)),
        "iss_gain": math.sqrt(d.gamma / (alpha * o.epsilon)),
        "runtime": {"vx_hold": 1.0, "y_error_bound": list(d.y_error_bound), "x0_halfwidth": list(o.x0_halfwidth),
                    "disturbance_bound": list(o.model_error_bound), "eta": eta_shift},
        "solver": d.solver,
        "notes": [
            "The bounds contain the state of the linear relaxation model (eq. 9) whenever the axle "
            "cornering stiffnesses lie in stiffness_box and the speed in the design bands; the "
            "runtime bounds the speed mismatch inside a band exactly (not in the paper).",
            "The common diagonal Q proves ISS of the width under arbitrary switching (eq. 37); the "
            "certificate adds the small-gain check of the width dynamics that Theorem 1 omits.",
        ],
    }
    # runtime.max_communication_step (the longest step at which the bounds contract) is decided
    # by running the runtime itself, at build time: latobs.packaging.complete_runtime_data
    return data
