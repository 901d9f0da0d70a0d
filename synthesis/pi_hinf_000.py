"""Paper 000, Theorem 2: switched H-infinity PI observer with a common Lyapunov matrix.

Menhour, Koenig, d'Andrea-Novel, "Continuous-time switched H-infinity proportional-integral
observer: sideslip and road bank angles estimation", ECC 2014.

Per mode i, with [T N] = pinv([I; C]) (Theorem 1, eq. 6; here T = diag(1, 1/2, 1/2, 1/2),
N = [0; I3/2]), the estimation error e_a = [z~; w^] obeys eq. (19):
    e_a' = (A_a - K_a C_a) e_a + F_a w,   beta~ = L_a e_a
    A_a = [[T A, T F], [0, 0]],  C_a = [C, 0],  F_a = [-T F; 0],  L_a = [-L, 0],  L = [1 0 0 0].
LMI (20), variables P = P^T > 0 (common to all modes), Gamma_i = -P K_a,i, g = gamma^2:
    [[A_a^T P + P A_a + C_a^T Gamma^T + Gamma C_a, P F_a, L_a^T],
     [F_a^T P, -g I, 0], [L_a, 0, -I]]  < 0          minimise g.
With Gamma = -P K_a the (1,1) block equals (A_a - K_a C_a)^T P + P (A_a - K_a C_a) (ERRATA 000).

Departures from the printed paper (ERRATA.md, section 000):
  * LMI (20) alone is degenerate (gamma -> 0 with unbounded gains and a bank pole near 0).
    This design adds regional pole placement on the same common P (Chilali & Gahinet 1996):
      alpha-stability  A_cl^T P + P A_cl + 2 a P < 0                    (Re lambda < -a)
      disk             [[-R P, P A_cl], [A_cl^T P, -R P]] < 0            (|lambda| < R)
    with P A_cl = P A_a + Gamma C_a: linear in (P, Gamma).
  * Tire modes: C2 is fitted to the vehicle's tire curve by default (see ``mode_models``).
  * Tire-mode design (paper section IV-B, eq. 27): the paper designs M = 2 observers at one
    unstated speed. Here each tire mode has one gain pair, constrained by all LMIs at every speed
    of the grid (36/63/90 km/h) with the same common P, and the runtime evaluates the mode's
    model at the measured speed (clamped to the grid). The speed-mode design follows eq. (25):
    mode i uses the model at its grid speed.
Scaling: the LMIs are posed for S^-1 A S / tau with S from a diagonal balancing of the average
augmented matrix and tau = sqrt(a R) (s^-1), so Clarabel sees entries near 1; gamma is invariant
under both, the gains and P are mapped back (K = tau S K_bar, P = S^-T P_bar S^-1 / tau).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg

from . import bicycle_roll_model as brm
from . import lmi
from . import tire
from .params import Vehicle

KMH = 1.0 / 3.6  # m/s per km/h
L_BETA = np.array([[1.0, 0.0, 0.0, 0.0]])  # xi = beta: the estimated output of eq. (3)


class DesignError(RuntimeError):
    """The LMIs are infeasible or the solver failed; the message names the design and the LMI."""


@dataclass(frozen=True)
class DesignOptions:
    """Options of a paper-000 design. Angles in degrees, rates in 1/s, speeds in km/h."""

    name: str
    switching: str                      # "speed" (eq. 25) or "tire" (eq. 27)
    speeds_kmh: tuple[float, ...] = (36.0, 63.0, 90.0)
    alpha: float = 0.5                  # 1/s: all closed-loop poles with Re < -alpha
    radius: float = 100.0               # rad/s: all closed-loop poles with |lambda| < radius
    alpha_star_deg: float = 0.5         # tire modes: switching slip angle alpha*
    hysteresis_deg: float = 0.05        # tire modes: half-width of the hysteresis band (not in the paper)
    c2_scale: float | None = None       # tire modes: C2 = c2_scale * C1; None: fitted to the tire curve
    c2_fit_deg: float = 4.0             # tire modes: C2 is the tire curve's secant slope on [alpha*, this]
    margin: float = 1e-6                # strictness of every LMI in scaled units
    gain_limit: float = 1e4             # certificate: largest admissible gain entry
    cond_limit: float = 1e7             # certificate: largest admissible cond(P)

    def validate(self) -> None:
        if self.switching not in ("speed", "tire"):
            raise ValueError(f"design {self.name}: switching must be 'speed' or 'tire', got {self.switching!r}")
        if len(self.speeds_kmh) < 1 or any(not (v > 0 and math.isfinite(v)) for v in self.speeds_kmh):
            raise ValueError(f"design {self.name}: speeds_kmh must be positive, got {self.speeds_kmh}")
        if list(self.speeds_kmh) != sorted(set(self.speeds_kmh)):
            raise ValueError(f"design {self.name}: speeds_kmh must be strictly increasing, got {self.speeds_kmh}")
        if not (self.alpha >= 0 and self.radius > self.alpha):
            raise ValueError(f"design {self.name}: need 0 <= alpha < radius, got alpha={self.alpha}, radius={self.radius}")
        if self.c2_scale is not None and not (0 < self.c2_scale <= 1):
            raise ValueError(f"design {self.name}: c2_scale must be in (0, 1], got {self.c2_scale}")
        if not (self.alpha_star_deg < self.c2_fit_deg < 90):
            raise ValueError(f"design {self.name}: need alpha_star_deg < c2_fit_deg < 90")
        if not (0 < self.hysteresis_deg < self.alpha_star_deg):
            raise ValueError(f"design {self.name}: need 0 < hysteresis_deg < alpha_star_deg")


@dataclass
class ModeModel:
    """One switched mode: its model's 1/Vx coefficients and the speeds where the LMIs hold."""

    label: str
    coeffs: dict
    speeds: tuple[float, ...]           # m/s
    scheduling: dict
    Cf: float
    Cr: float
    stiffness_scale: tuple[float, float] = (1.0, 1.0)   # (Cf, Cr) = scale * the vehicle's


@dataclass
class Design:
    options: DesignOptions
    vehicle: Vehicle
    T: np.ndarray
    N: np.ndarray
    C: np.ndarray
    modes: list[ModeModel]
    P: np.ndarray
    K_P: list[np.ndarray]               # 4x3 per mode (proportional gain, paper's K_i)
    K_I: list[np.ndarray]               # 1x3 per mode (integral gain, paper's K_Ii)
    gamma: float
    solver: dict = field(default_factory=dict)


def t_n_matrices(C: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """[T N] = pinv([I; C]) (Theorem 1, Algorithm 1); T + N C = I."""
    n = C.shape[1]
    TN = np.linalg.pinv(np.vstack([np.eye(n), C]))
    return TN[:, :n], TN[:, n:]


def augmented(A: np.ndarray, F: np.ndarray, C: np.ndarray, T: np.ndarray):
    """Eq. (19): A_a, C_a, F_a, L_a of the error system e_a = [z~; w^]."""
    n, nw = A.shape[0], F.shape[1]
    Aa = np.block([[T @ A, T @ F], [np.zeros((nw, n)), np.zeros((nw, nw))]])
    Ca = np.hstack([C, np.zeros((C.shape[0], nw))])
    Fa = np.vstack([-T @ F, np.zeros((nw, nw))])
    La = np.hstack([-L_BETA, np.zeros((1, nw))])
    return Aa, Ca, Fa, La


def mode_models(vehicle: Vehicle, opts: DesignOptions) -> list[ModeModel]:
    """The switched modes of eq. (25) (speed) or eq. (27) (tire)."""
    speeds = tuple(v * KMH for v in opts.speeds_kmh)
    Cf, Cr = vehicle.require(("Cf", "Cr"), f"design {opts.name}").values()
    if opts.switching == "speed":
        # eq. (25): band [V_i - D, V_i + D[ with D half the distance to the neighbouring grid speed
        edges = [speeds[0] - (speeds[1] - speeds[0]) / 2 if len(speeds) > 1 else 0.5 * speeds[0]]
        edges += [(a + b) / 2 for a, b in zip(speeds, speeds[1:])]
        edges += [speeds[-1] + (speeds[-1] - speeds[-2]) / 2 if len(speeds) > 1 else 1.5 * speeds[0]]
        coeffs = brm.lpv_coefficients(vehicle)
        return [ModeModel(f"Vx = {opts.speeds_kmh[i]:g} km/h", coeffs, (v,),
                          {"variable": "vx", "unit": "m/s", "value": v, "range": [edges[i], edges[i + 1]]},
                          Cf, Cr, (1.0, 1.0))
                for i, v in enumerate(speeds)]
    # Eq. (27): mode 1 below alpha*, mode 2 above. The paper reads C1, C2 off its measured tire
    # curve (Fig. 1); vehicles.md suggests e.g. C2 = 0.5 C1. Departure: by default C2 is fitted to
    # the vehicle's own tire curve (tire.mode_stiffness); 0.5 C1 on a tire that is still linear at
    # a few degrees makes mode 2's model 50 % wrong exactly where the observer uses it.
    if opts.c2_scale is None:
        sf, sr = tire.mode_stiffness(vehicle, math.radians(opts.alpha_star_deg), math.radians(opts.c2_fit_deg))
        how = f"secant of the tire curve on [{opts.alpha_star_deg:g}, {opts.c2_fit_deg:g}] deg"
    else:
        sf = sr = opts.c2_scale
        how = "c2_scale option"
    out = []
    for label, (kf, kr) in (("C1 (linear tires)", (1.0, 1.0)),
                            (f"C2 = ({sf:.3f} Cf, {sr:.3f} Cr), {how}", (sf, sr))):
        out.append(ModeModel(label, brm.lpv_coefficients(vehicle, kf * Cf, kr * Cr), speeds,
                             {"variable": "max(|alpha_f|, |alpha_r|)", "unit": "rad",
                              "range": [0.0, math.radians(opts.alpha_star_deg)] if kf == 1.0 and kr == 1.0
                              else [math.radians(opts.alpha_star_deg), None]},
                             kf * Cf, kr * Cr, (kf, kr)))
    return out


def _balancing(mats: list[np.ndarray], n: int) -> np.ndarray:
    """Diagonal state scaling S (powers of 2) for the augmented matrices.

    The n physical states are balanced by scipy on the mean |T A| block; the integrator states
    (zero rows of A_a) would be scaled to ~0 by balancing, so each gets the scale that makes its
    coupling column T F of the scaled matrix of norm ~1.
    """
    avg = np.mean([np.abs(M) for M in mats], axis=0)
    _, (sx, _perm) = scipy.linalg.matrix_balance(avg[:n, :n] + 1e-12 * np.eye(n), permute=False, separate=True)
    sw = []
    for j in range(n, avg.shape[0]):
        coupling = np.max(avg[:n, j] / sx)
        sw.append(2.0 ** round(math.log2(1.0 / coupling)) if coupling > 0 else 1.0)
    return np.diag(np.concatenate([sx, sw]))


def design(vehicle: Vehicle, opts: DesignOptions) -> Design:
    """Solve Theorem 2 + pole region on a common P with cvxpy/Clarabel. Raises DesignError."""
    import cvxpy as cp  # design time only

    opts.validate()
    C = brm.C
    T, N = t_n_matrices(C)
    modes = mode_models(vehicle, opts)
    vertices = []                       # (mode index, speed, Aa, Ca, Fa, La)
    for i, mm in enumerate(modes):
        for v in mm.speeds:
            lm = brm.evaluate(mm.coeffs, v)
            vertices.append((i, v, *augmented(lm.A, lm.F, lm.C, T)))
    na = vertices[0][2].shape[0]
    ny = C.shape[0]
    S = _balancing([vx[2] for vx in vertices], C.shape[1])
    Si = np.linalg.inv(S)
    tau = math.sqrt(max(opts.alpha, 1e-3) * opts.radius)      # 1/s, time scaling
    a_s, R_s = opts.alpha / tau, opts.radius / tau

    P = cp.Variable((na, na), symmetric=True)
    Gam = [cp.Variable((na, ny)) for _ in modes]
    g = cp.Variable(nonneg=True)
    eps = opts.margin
    families: dict[str, list] = {"H-infinity LMI (20)": [], f"alpha-stability (Re < -{opts.alpha:g})": [],
                                 f"disk (|lambda| < {opts.radius:g})": []}
    hinf_key, alpha_key, disk_key = families
    for i, v, Aa, Ca, Fa, La in vertices:
        As, Cs, Fs, Ls = Si @ Aa @ S / tau, Ca @ S, Si @ Fa / tau, La @ S
        PA = P @ As + Gam[i] @ Cs                     # P A_cl in scaled coordinates
        lyap = PA + PA.T
        nw = Fs.shape[1]
        M = cp.bmat([[lyap, P @ Fs, Ls.T],
                     [(P @ Fs).T, -g * np.eye(nw), np.zeros((nw, 1))],
                     [Ls, np.zeros((1, nw)), -np.eye(1)]])
        families[hinf_key].append((M + M.T) / 2 << -eps * np.eye(na + nw + 1))
        families[alpha_key].append(lyap + 2 * a_s * P << -eps * np.eye(na))
        D = cp.bmat([[-R_s * P, PA], [PA.T, -R_s * P]])
        families[disk_key].append((D + D.T) / 2 << -eps * np.eye(2 * na))
    base = [P >> eps * np.eye(na)]
    prob = cp.Problem(cp.Minimize(g), base + [c for cs in families.values() for c in cs])
    status, seconds = lmi.solve(prob)
    if not lmi.solved(status) or P.value is None:
        raise DesignError(f"design {opts.name}: no solution (Clarabel: {status}) of Theorem 2 + pole region "
                          f"on a common P over {len(vertices)} mode/speed vertices; "
                          + _diagnose(base, families, opts))
    Pb = P.value
    P_orig = Si.T @ Pb @ Si / tau
    P_orig = (P_orig + P_orig.T) / 2
    Ka = [tau * S @ (-np.linalg.solve(Pb, G.value)) for G in Gam]   # K_a = -P^-1 Gamma, unscaled
    n = C.shape[1]
    return Design(options=opts, vehicle=vehicle, T=T, N=N, C=C, modes=modes, P=P_orig,
                  K_P=[K[:n, :] for K in Ka], K_I=[K[n:, :] for K in Ka],
                  gamma=float(math.sqrt(max(g.value, 0.0))),
                  solver={"name": "CLARABEL", "status": str(status), "seconds": round(seconds, 4),
                          "lmis": 1 + sum(len(c) for c in families.values()), "time_scale_per_s": tau,
                          "state_scaling": np.diag(S).tolist()})


def _diagnose(base: list, families: dict, opts: DesignOptions) -> str:
    """Name the LMI family that is infeasible on its own (feasibility problems, Clarabel)."""
    def feasible(cons) -> bool:
        return lmi.feasible(base + cons)

    region = [name for name in families if not name.startswith("H-infinity")]
    relax = f"Relax the pole region (alpha = {opts.alpha:g} 1/s, radius = {opts.radius:g} rad/s)."
    alone = [name for name in region if not feasible(families[name])]
    if alone:
        return "infeasible on its own: " + " and ".join(alone) + ". " + relax
    if not feasible([c for name in region for c in families[name]]):
        return "the pole-region LMIs are infeasible together: " + " + ".join(region) + ". " + relax
    return "the pole region is feasible; adding the H-infinity LMI (20) is not. " + relax


def closed_loop(coeffs: dict, K_P, K_I, T, C, vx: float):
    """A_a - K_a C_a, F_a, L_a for one mode at speed vx (m/s): eq. (19)."""
    lm = brm.evaluate({k: [np.asarray(M) for M in v] for k, v in coeffs.items()}, vx)
    Aa, Ca, Fa, La = augmented(lm.A, lm.F, np.asarray(C), np.asarray(T))
    Ka = np.vstack([np.asarray(K_P), np.asarray(K_I)])
    return Aa - Ka @ Ca, Fa, La


def runtime_max_step(design: Design) -> float:
    """Internal RK4 step of the runtime (s): <= 1 ms and h*|lambda|max <= 0.1 on every vertex."""
    lam = 0.0
    for i, mm in enumerate(design.modes):
        for v in mm.speeds:
            Acl, _, _ = closed_loop(mm.coeffs, design.K_P[i], design.K_I[i], design.T, design.C, v)
            lam = max(lam, float(np.max(np.abs(np.linalg.eigvals(Acl)))))
    return min(1e-3, 0.1 / lam) if lam > 0 else 1e-3


def to_design_dict(design: Design) -> dict:
    """Everything the certificate and the FMU runtime need, as plain data (no certificate yet)."""
    o, veh = design.options, design.vehicle
    speeds = [v * KMH for v in o.speeds_kmh]
    if o.switching == "speed":
        switching = {"kind": "speed_bands", "variable": "vx", "unit": "m/s",
                     "edges": [m.scheduling["range"][0] for m in design.modes] + [design.modes[-1].scheduling["range"][1]],
                     "rule": "eq. (25): mode i on [V_i - D, V_i + D[; outside the grid the nearest mode (clamp)"}
    else:
        lf, lr = veh.require(("lf", "lr"), f"design {o.name} (slip premise)").values()
        switching = {"kind": "tire_slip", "variable": "max(|alpha_f|, |alpha_r|)", "unit": "rad",
                     "alpha_star": math.radians(o.alpha_star_deg), "hysteresis": math.radians(o.hysteresis_deg),
                     "lf": lf, "lr": lr,
                     "rule": "eq. (27) with the estimated slip angles of eq. (2); a hysteresis band "
                             "(not in the paper) prevents chattering at alpha*"}
    modes = []
    for i, mm in enumerate(design.modes):
        model_speed = ({"kind": "fixed", "value": mm.speeds[0]} if o.switching == "speed"
                       else {"kind": "measured", "range": [min(speeds), max(speeds)]})
        modes.append({"index": i + 1, "label": mm.label, "scheduling": mm.scheduling,
                      "model_speed": model_speed, "design_speeds": list(mm.speeds),
                      "stiffness_scale": mm.stiffness_scale, "Cf": mm.Cf, "Cr": mm.Cr, "model": mm.coeffs,
                      "gains": {"K_P": design.K_P[i], "K_I": design.K_I[i]}})
    return {
        "schema": "latobs.design/1",
        "name": o.name,
        "paper": "000",
        "title": "Continuous-time switched H-infinity PI observer: sideslip and road bank angle "
                 "(Menhour, Koenig, d'Andrea-Novel, ECC 2014)",
        "vehicle": veh.as_dict(),
        "options": {k: getattr(o, k) for k in o.__dataclass_fields__},
        "structure": {"states": list(brm.STATES), "state_units": list(brm.STATE_UNITS),
                      "input": "delta", "unknown_input": "bank_angle", "measurements": list(brm.OUTPUTS),
                      "T": design.T, "N": design.N, "C": design.C, "L": L_BETA,
                      "model_form": "M(Vx) = sum_k M[k] * Vx**-k"},
        "switching": switching,
        "modes": modes,
        "gamma": design.gamma,
        "region": {"alpha": o.alpha, "radius": o.radius},
        "P": design.P,
        "runtime": {"max_step": runtime_max_step(design), "vx_hold": 1.0,
                    "equations": "x^ = z + N y; z' = T A x^ + T B u + T F w^ + K_P (y - C x^); "
                                 "w^' = K_I (y - C x^)"},
        "solver": design.solver,
        "notes": [
            "The common P proves stability under arbitrary switching among the grid models only, "
            "not for speeds between grid points nor for the nonlinear vehicle.",
            "gamma bounds ||beta - beta^||_2 / ||phi_r||_2 per grid model; it says nothing about how "
            "fast the bank estimate converges: see the check slowest_bank_pole.",
        ],
    }
