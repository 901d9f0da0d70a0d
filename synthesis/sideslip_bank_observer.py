"""Paper 000's design: Theorem 2's switched H-infinity PI observer with a common Lyapunov matrix
(LMI 20), with regional pole placement, the model at the measured speed (LPV vertices), a second
H-infinity channel from model error and the validity freeze (or the paper as printed:
``DesignOptions(faithful=True)``). The LMIs and every departure are on the documentation's
paper-000 page."""
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
    # -- departures from the paper (docs/papers/000.md; faithful=True turns every one of them off) -----------
    faithful: bool = False              # True: the paper as printed (LMI 20 + region; speed modes at their
                                        # grid speed, eq. 25 literally; tire modes on the 3 grid speeds)
    lpv_range_kmh: tuple[float, float] | None = None   # LPV modes' speed range; None: the speed bands' outer
                                        # edges (V_1 - D_1, V_M + D_M)
    lpv_pieces: int = 2                 # LPV modes: polytopes per mode range (``lpv_vertices``)
    robust_weight: float = 1.0          # rho of the objective gamma1^2 / gamma_ref^2 + rho gamma2^2
    gamma_ref: float = 0.05             # scale of gamma1 (bank -> beta error, rad/rad) in the objective
    robust_bound: float | None = None   # optional hard bound on gamma2
    model_error_weights: tuple[float, float, float] = (1.0, 1.0, 1.0)   # Wd on d (bicycle_roll_model.MODEL_ERRORS)
    robust_output_weights: tuple[float, float] = (0.05, 1.0)            # Wz on [bank (rad), beta (rad)] errors:
                                        # with a common P, weight b on the bank row forces gamma1 >= ~b
                                        # (the bank estimate tracks the bank in channel 1), see design()
    valid_alpha_deg: float | None = None   # runtime `valid`: estimated slip angles within +-this (deg); None:
                                        # where the first axle's tire-curve force falls valid_force_drop below
                                        # linear (``linear_domain_slip``; 3.0 deg on the sedan, rear axle) ...
    valid_force_drop: float = 0.2       # ... (fraction), when the vehicle has a tire curve; else 3 deg ...
    valid_ay_g: float = 0.4             # ... and |vx r| within this (g): the design's linear domain
    valid_release: float = 0.8          # valid again below this fraction of both limits (hysteresis)
    freeze_integral: bool = True        # hold the bank estimate (integral action) while not valid

    @property
    def robust(self) -> bool:
        return not self.faithful and self.robust_weight > 0

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
        if not (math.isfinite(self.robust_weight) and self.robust_weight >= 0):
            raise ValueError(f"design {self.name}: robust_weight must be finite and >= 0 (0: no model-error channel), "
                             f"got {self.robust_weight}")
        for key in ("gamma_ref", "valid_alpha_deg", "valid_ay_g", "valid_force_drop"):
            val = getattr(self, key)
            if val is None and key == "valid_alpha_deg":
                continue
            if not (math.isfinite(val) and val > 0):
                raise ValueError(f"design {self.name}: {key} must be finite and > 0, got {val}")
        if not 0 < self.valid_force_drop < 1:
            raise ValueError(f"design {self.name}: valid_force_drop must be in (0, 1), got {self.valid_force_drop}")
        if not 0 < self.valid_release < 1:
            raise ValueError(f"design {self.name}: valid_release must be in (0, 1), got {self.valid_release}")
        for key, n in (("model_error_weights", 3), ("robust_output_weights", 2)):
            w = getattr(self, key)
            if len(w) != n or any(not (math.isfinite(x) and x >= 0) for x in w) or not any(w):
                raise ValueError(f"design {self.name}: {key} needs {n} finite weights >= 0, not all 0, got {w}")
        if self.robust_bound is not None and not self.robust_bound > 0:
            raise ValueError(f"design {self.name}: robust_bound must be > 0, got {self.robust_bound}")
        if self.lpv_range_kmh is not None:
            lo, hi = self.lpv_range_kmh
            if not 0 < lo < hi:
                raise ValueError(f"design {self.name}: lpv_range_kmh must be (lo, hi) with 0 < lo < hi, got {self.lpv_range_kmh}")


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
    model_range: tuple[float, float] | None = None     # m/s: LPV, the model at the measured speed
                                                        # clamped to this range; None: at speeds[0]


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
    gamma_robust: float | None = None   # model-error channel bound (None: faithful design)
    E: list = field(default_factory=list)
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
    La = np.hstack([-L_BETA, np.zeros((1, n - L_BETA.shape[1] + nw))])     # (beta: the first state)
    return Aa, Ca, Fa, La


def speed_band_edges(speeds: tuple[float, ...]) -> list[float]:
    """Eq. (25): band [V_i - D, V_i + D[ with D half the distance to the neighbouring grid speed (m/s)."""
    edges = [speeds[0] - (speeds[1] - speeds[0]) / 2 if len(speeds) > 1 else 0.5 * speeds[0]]
    edges += [(a + b) / 2 for a, b in zip(speeds, speeds[1:])]
    edges += [speeds[-1] + (speeds[-1] - speeds[-2]) / 2 if len(speeds) > 1 else 1.5 * speeds[0]]
    return edges


def mode_models(vehicle: Vehicle, opts: DesignOptions) -> list[ModeModel]:
    """The switched modes of eq. (25) (speed) or eq. (27) (tire).

    Departure from the paper (docs/papers/000.md) unless ``opts.faithful``: every mode's model is evaluated at the
    measured speed (LPV, the model's 1/Vx polynomial), clamped to the mode's range: its own
    speed band for speed modes, ``lpv_range_kmh`` (default: the bands' outer edges) for the tire
    modes. Eq. (25) taken literally (faithful) uses the grid speed's model over the whole band,
    which biases the bank estimate by up to 0.6 rad in a 0.3 g turn at a band's edge.
    """
    speeds = tuple(v * KMH for v in opts.speeds_kmh)
    Cf, Cr = vehicle.require(("Cf", "Cr"), f"design {opts.name}").values()
    edges = speed_band_edges(speeds)
    lpv = None if opts.faithful else (tuple(v * KMH for v in opts.lpv_range_kmh) if opts.lpv_range_kmh
                                      else (edges[0], edges[-1]))
    if opts.switching == "speed":
        coeffs = brm.lpv_coefficients(vehicle)
        return [ModeModel(f"Vx = {opts.speeds_kmh[i]:g} km/h", coeffs, (v,),
                          {"variable": "vx", "unit": "m/s", "value": v, "range": [edges[i], edges[i + 1]]},
                          Cf, Cr, (1.0, 1.0),
                          None if lpv is None else (max(edges[i], lpv[0]), min(edges[i + 1], lpv[1])))
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
                             kf * Cf, kr * Cr, (kf, kr), lpv))
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


def lpv_vertices(lo: float, hi: float, pieces: int) -> list[tuple[str, float, float]]:
    """Points (label, v, w) whose convex hull contains the curve (v, w) = (1/Vx, 1/Vx^2) for Vx in
    [lo, hi] (m/s): [1/hi, 1/lo] cut into ``pieces`` equal intervals in v; on each, the triangle
    of its two end points on the curve and the intersection ((v1 + v2)/2, v1 v2) of the tangents
    there (w = v^2 is convex: the arc lies between its chord and its tangents). The end points
    are shared between neighbouring pieces."""
    v_lo, v_hi = 1.0 / hi, 1.0 / lo
    knots = [v_lo + (v_hi - v_lo) * k / pieces for k in range(pieces + 1)]
    pts = [(f"{1.0 / v * 3.6:.4g} km/h", v, v * v) for v in knots]
    for v1, v2 in zip(knots, knots[1:]):
        pts.append((f"tangent corner between {1.0 / v2 * 3.6:.4g} and {1.0 / v1 * 3.6:.4g} km/h", (v1 + v2) / 2, v1 * v2))
    return pts


def _mode_vertices(mm: "ModeModel", T: np.ndarray, E: list[np.ndarray], pieces: int):
    """(label, Aa, Ca, Fa, La, Ea) at the points where mode mm's LMIs are imposed.

    Fixed-speed modes (faithful eq. 25) and the faithful tire modes: their design speeds.
    LPV modes (model at the measured speed in [lo, hi]): every entry of A, B, F, E is affine in
    (v, w) = (1/Vx, 1/Vx^2) (``bicycle_roll_model``: A = A0 + v A1 + w A2), so the LMIs, affine
    in the model, hold on the whole range when they hold at the vertices of polytopes that
    contain the curve w = v^2 (``lpv_vertices``; polytopic LPV, Apkarian, Gahinet & Becker 1995):
    a rigorous frozen-speed guarantee and, with the common P, one for any time-varying speed.
    """
    c = mm.coeffs
    if mm.model_range is None:
        pts = [(f"{v * 3.6:.4g} km/h", 1.0 / v, 1.0 / v**2) for v in mm.speeds]
    else:
        pts = lpv_vertices(*mm.model_range, pieces)
    out = []
    for label, v, w in pts:
        A = c["A"][0] + v * c["A"][1] + w * c["A"][2]
        F = c["F"][0] + v * c["F"][1]
        Aa, Ca, Fa, La = augmented(A, F, brm.C, T)
        Ea = np.vstack([-T @ (E[0] + v * E[1]), np.zeros((1, E[0].shape[1]))])
        out.append((label, Aa, Ca, Fa, La, Ea))
    return out


def robust_output_matrix(La: np.ndarray) -> np.ndarray:
    """Outputs of the model-error channel: [bank estimate w^ (= its error when the road is flat);
    beta error] as rows of the augmented error state e_a = [x~; w^] (eq. 19)."""
    n = La.shape[1]
    e_w = np.zeros((1, n))
    e_w[0, -1] = 1.0
    return np.vstack([e_w, La])


def design(vehicle: Vehicle, opts: DesignOptions) -> Design:
    """Solve Theorem 2 + pole region (+ the model-error channel) on a common P with
    cvxpy (lmi: Clarabel by default). Raises DesignError naming the LMI family and the mode/vertex at fault."""
    import cvxpy as cp  # design time only

    opts.validate()
    C = brm.C
    T, N = t_n_matrices(C)
    modes = mode_models(vehicle, opts)
    E = brm.model_error_coefficients(vehicle)
    Wd = np.diag(opts.model_error_weights)
    Wz = np.diag(opts.robust_output_weights)
    vertices = []                       # (mode index, label, Aa, Ca, Fa, La, Ea)
    for i, mm in enumerate(modes):
        for label, *mats in _mode_vertices(mm, T, E, opts.lpv_pieces):
            vertices.append((i, f"mode {i + 1} at {label}", *mats))
    na = vertices[0][2].shape[0]
    ny = C.shape[0]
    S = _balancing([vx[2] for vx in vertices], C.shape[1])
    Si = np.linalg.inv(S)
    tau = math.sqrt(max(opts.alpha, 1e-3) * opts.radius)      # 1/s, time scaling
    a_s, R_s = opts.alpha / tau, opts.radius / tau

    P = cp.Variable((na, na), symmetric=True)
    Gam = [cp.Variable((na, ny)) for _ in modes]
    g = cp.Variable(nonneg=True)
    g2 = cp.Variable(nonneg=True)
    eps = opts.margin
    families: dict[str, list] = {"H-infinity LMI (20)": [], f"alpha-stability (Re < -{opts.alpha:g})": [],
                                 f"disk (|lambda| < {opts.radius:g})": []}
    hinf_key, alpha_key, disk_key = list(families)
    robust_key = "model-error H-infinity LMI (bank and beta errors)"
    if opts.robust:
        families[robust_key] = []
    for i, label, Aa, Ca, Fa, La, Ea in vertices:
        As, Cs, Fs, Ls = Si @ Aa @ S / tau, Ca @ S, Si @ Fa / tau, La @ S
        PA = P @ As + Gam[i] @ Cs                     # P A_cl in scaled coordinates
        lyap = PA + PA.T
        nw = Fs.shape[1]
        M = cp.bmat([[lyap, P @ Fs, Ls.T],
                     [(P @ Fs).T, -g * np.eye(nw), np.zeros((nw, 1))],
                     [Ls, np.zeros((1, nw)), -np.eye(1)]])
        # (a cvxpy semidefinite constraint is on the symmetric part (M + M') / 2 of its matrix)
        families[hinf_key].append(M << -eps * np.eye(na + nw + 1))
        families[alpha_key].append(lyap + 2 * a_s * P << -eps * np.eye(na))
        D = cp.bmat([[-R_s * P, PA], [PA.T, -R_s * P]])
        families[disk_key].append(D << -eps * np.eye(2 * na))
        if opts.robust:
            # departure (not in the paper, docs/papers/000.md): a second H-infinity channel on the same P,
            # from the weighted model error Wd d to the weighted [bank estimate; beta error]
            Es = Si @ Ea @ Wd / tau
            Zs = Wz @ robust_output_matrix(La) @ S
            nd, nz = Es.shape[1], Zs.shape[0]
            M2 = cp.bmat([[lyap, P @ Es, Zs.T],
                          [(P @ Es).T, -g2 * np.eye(nd), np.zeros((nd, nz))],
                          [Zs, np.zeros((nz, nd)), -np.eye(nz)]])
            families[robust_key].append(M2 << -eps * np.eye(na + nd + nz))
    base = [P >> eps * np.eye(na)]
    cons = base + [c for cs in families.values() for c in cs]
    if opts.robust:
        if opts.robust_bound is not None:
            cons.append(g2 <= opts.robust_bound**2)
        # weighted objective: gamma1^2 / gamma_ref^2 + rho gamma2^2 (both channels dimensionless)
        objective = g / opts.gamma_ref**2 + opts.robust_weight * g2
    else:
        objective = g
    prob = cp.Problem(cp.Minimize(objective), cons)
    status, seconds = lmi.solve(prob)
    if not lmi.solved(status) or P.value is None:
        raise DesignError(f"design {opts.name}: no solution ({lmi.label()}: {status}) of Theorem 2 + pole region"
                          f"{' + model-error channel' if opts.robust else ''} on a common P over "
                          f"{len(vertices)} mode/speed vertices; " + _diagnose(base, families, opts))
    Pb = P.value
    P_orig = Si.T @ Pb @ Si / tau
    P_orig = (P_orig + P_orig.T) / 2
    Ka = [tau * S @ (-np.linalg.solve(Pb, G.value)) for G in Gam]   # K_a = -P^-1 Gamma, unscaled
    n = C.shape[1]
    return Design(options=opts, vehicle=vehicle, T=T, N=N, C=C, modes=modes, P=P_orig,
                  K_P=[K[:n, :] for K in Ka], K_I=[K[n:, :] for K in Ka],
                  gamma=float(math.sqrt(max(g.value, 0.0))),
                  gamma_robust=float(math.sqrt(max(g2.value, 0.0))) if opts.robust else None,
                  E=E,
                  solver={"name": lmi.current(), "status": str(status), "seconds": round(seconds, 4),
                          "lmis": 1 + sum(len(c) for c in families.values()), "time_scale_per_s": tau,
                          "state_scaling": np.diag(S).tolist(), "vertices": [v[1] for v in vertices]})


def _diagnose(base: list, families: dict, opts: DesignOptions) -> str:
    """Name the LMI family that is infeasible on its own (feasibility problems, the current lmi solver)."""
    def feasible(cons) -> bool:
        return lmi.feasible(base + cons)

    region = [name for name in families if "H-infinity" not in name]
    relax = f"Relax the pole region (alpha = {opts.alpha:g} 1/s, radius = {opts.radius:g} rad/s)."
    alone = [name for name in region if not feasible(families[name])]
    if alone:
        return "infeasible on its own: " + " and ".join(alone) + ". " + relax
    if not feasible([c for name in region for c in families[name]]):
        return "the pole-region LMIs are infeasible together: " + " + ".join(region) + ". " + relax
    return ("the pole region is feasible; adding the H-infinity LMI(s) (" + ", ".join(n for n in families if n not in region)
            + ") is not. " + relax)


def closed_loop(coeffs: dict, K_P, K_I, T, C, vx: float):
    """A_a - K_a C_a, F_a, L_a for one mode at speed vx (m/s): eq. (19)."""
    lm = brm.evaluate({k: v if k == "first_power" else [np.asarray(M) for M in v] for k, v in coeffs.items()}, vx)
    Aa, Ca, Fa, La = augmented(lm.A, lm.F, np.asarray(C), np.asarray(T))
    Ka = np.vstack([np.asarray(K_P), np.asarray(K_I)])
    return Aa - Ka @ Ca, Fa, La


def linear_domain_slip(vehicle: Vehicle, opts: DesignOptions) -> float:
    """Slip angle (rad) bounding the `valid` flag's linear domain: ``opts.valid_alpha_deg`` if set;
    else the smallest slip at which an axle's tire-curve force (``tire.axle_force``, the vehicle's
    Magic Formula at static load) falls ``valid_force_drop`` below its linear value C alpha; 3 deg
    when the vehicle has no tire curve."""
    if opts.valid_alpha_deg is not None:
        return math.radians(opts.valid_alpha_deg)
    if any(k not in vehicle.parameters for k in tire.MF_PARAMS):
        return math.radians(3.0)
    a = np.radians(np.linspace(0.01, 30.0, 6000))
    out = math.radians(30.0)
    for axle, c in (("f", vehicle.Cf), ("r", vehicle.Cr)):
        below = tire.axle_force(vehicle, axle, a) < (1.0 - opts.valid_force_drop) * c * a
        if np.any(below):
            out = min(out, float(a[np.argmax(below)]))
    return out


def runtime_max_step(design: Design) -> float:
    """Internal RK4 step of the runtime (s): <= 1 ms and h*|lambda|max <= 0.1 on every vertex."""
    lam = 0.0
    for i, mm in enumerate(design.modes):
        speeds = mm.speeds if mm.model_range is None else np.linspace(*mm.model_range, 41)
        for v in speeds:
            Acl, _, _ = closed_loop(mm.coeffs, design.K_P[i], design.K_I[i], design.T, design.C, float(v))
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
        if mm.model_range is not None:
            model_speed = {"kind": "measured", "range": list(mm.model_range)}
        elif o.switching == "speed":
            model_speed = {"kind": "fixed", "value": mm.speeds[0]}
        else:
            model_speed = {"kind": "measured", "range": [min(speeds), max(speeds)]}
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
        "model_error": {
            "E": design.E, "inputs": list(brm.MODEL_ERRORS), "units": list(brm.MODEL_ERROR_UNITS),
            "form": "x' = A x + B u + F phi_r + (E[0] + E[1] / Vx) d",
            "outputs": ["bank_angle_hat", "beta error"],
            "input_weights": list(o.model_error_weights), "output_weights": list(o.robust_output_weights),
            "gamma": design.gamma_robust,
            "claim": None if design.gamma_robust is None else
            "|| diag(output_weights) G_d diag(input_weights) ||_inf <= gamma on every LMI vertex, common P",
        },
        "objective": ("minimise gamma^2 (LMI 20, the paper)" if design.gamma_robust is None else
                      f"minimise gamma^2 / {o.gamma_ref:g}^2 + {o.robust_weight:g} gamma_model_error^2"),
        "lmi_vertices": [{"mode": i + 1, "label": lab, "v": v, "w": w}
                         for i, mm in enumerate(design.modes)
                         for lab, v, w in (lpv_vertices(*mm.model_range, o.lpv_pieces) if mm.model_range
                                           else [(f"{x * 3.6:.4g} km/h", 1 / x, 1 / x**2) for x in mm.speeds])],
        "validity": {"alpha_max": linear_domain_slip(veh, o), "ay_max": o.valid_ay_g * brm.G,
                     "release": o.valid_release, "lf": veh.lf, "lr": veh.lr,
                     "freeze_integral": bool(o.freeze_integral and not o.faithful),
                     "rule": "valid = max(|alpha_f^|, |alpha_r^|) <= alpha_max and |vx r| <= ay_max (the "
                             "design's linear domain); valid again below release x both limits"},
        "region": {"alpha": o.alpha, "radius": o.radius},
        "P": design.P,
        "runtime": {"max_step": runtime_max_step(design), "vx_hold": 1.0, "input_hold": "first_order",
                    "equations": "x^ = z + N y; z' = T A x^ + T B u + T F w^ + K_P (y - C x^); "
                                 "w^' = K_I (y - C x^)"},
        "solver": design.solver,
        "notes": [
            ("The common P proves stability under arbitrary switching among the grid models only, "
             "not for speeds between grid points nor for the nonlinear vehicle.") if o.faithful else
            ("The common P proves stability and both H-infinity bounds for any switching and any "
             "time-varying speed inside the modes' speed ranges (polytopic LPV vertices), for the "
             "linear model; not for the nonlinear vehicle, whose model error is the input d."),
            ("gamma bounds ||beta - beta^||_2 / ||phi_r||_2 per grid model" if o.faithful else
             "gamma bounds ||beta - beta^||_2 / ||phi_r||_2 for every speed of each mode's range and any "
             "switching; the certificate states the sharper worst frozen-speed norm per band")
            + "; it says nothing about how fast the bank estimate converges: see the slowest bank pole.",
        ],
    }
