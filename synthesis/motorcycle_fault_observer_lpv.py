"""Paper 003's observer at the measured speed (latobs's default MotorcycleFaultObserver): the roll
angle as a state, a proportional multiple-integral (PMI) estimate of the rider torque, the model
and the gains evaluated at the measured speed inside each speed band, one Lyapunov matrix for every
band (switching at any time, no dwell time). The paper-faithful design (one frozen model per grid
speed, f = [roll angle, torque] as constant unknown inputs) stays in ``motorcycle_fault_observer``.

Departures from paper 003, each where it happens below and on the documentation's paper-003 page:

* the roll angle phi is a state (phi' = roll rate, Sharp's kinematics) instead of an unknown input
  of eq. (12): the observer no longer assumes phi constant, which is what made it lag the rider's
  torque pulses; (A, C) with y = [steer angle, yaw rate, roll rate] stays detectable (checked);
* the rider torque has ``torque_integrators`` integrators (PMI: tau' = tau_1, tau_1' = 0, the
  last derivative a disturbance) instead of the PI's one (eq. 13);
* the reduced model is exactly A(vx) = A_0 + vx A_1 + A_2 / vx (Sharp 1971: damping ~ vx, tyre
  slip ~ 1/vx), B_tau and E_Gamma constant, H_x = H_0 + H_2 / vx: the observer evaluates it at the
  measured speed, and its gain L(vx) = L_0 + vx L_1 + L_2 / vx = -P^-1 U(vx) with P common and U
  affine in (vx, 1/vx). Every LMI is affine in (vx, 1/vx), so holding at the four corners of the
  box [lo, hi] x [1/hi, 1/lo] (which contains the curve w = 1/vx) it holds at every speed of the band;
* the H-infinity objective is the gain from the disturbances (tyre non-linearity Gamma, model error
  xi on the mechanical states, the torque's last derivative) to the estimation errors of phi and
  tau (the paper's (20) bounds the residual instead); after the minimum, a second solve keeps
  gamma within ``gamma_slack`` of it and takes the smallest gains (round-off never picks a design).

Units: SI (m/s, rad, N m, N, s); the LMIs are posed in the normalised units of ``x_scale`` etc.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import lmi
from .params import Vehicle

STATES = ("vy", "yaw_rate", "roll_rate", "steer_angle", "steer_rate", "roll_angle")
STATE_UNITS = ("m/s", "rad/s", "rad/s", "rad", "rad/s", "rad")
MEASUREMENTS = ("steer_angle", "yaw_rate", "roll_rate")
DISTURBANCES = ("Gamma_f", "Gamma_r")
BASIS = ("1", "vx", "1/vx")
MECHANICAL = 5           # xi (model error) enters the first 5 states; phi' = roll rate is exact
ROLL, ROLL_RATE = 5, 2


class DesignError(RuntimeError):
    """The LMIs are infeasible or the model fails a condition; the message names the design, band and LMI."""


@dataclass(frozen=True)
class DesignOptions:
    """Options of the measured-speed paper-003 design (SI units).

    bands
        Speed bands (m/s) [lo, hi), one gain L(vx) each; contiguous and increasing. Default one
        band over paper 003's grid 10..30 m/s widened by half a grid step (7.5..32.5 m/s).
    torque_integrators
        Integrators on the rider torque: 1 is the paper's PI, 2 (default) a PMI (tau ramps).
    x_scale, f_scale
        Typical magnitudes of STATES and of [tau, tau', ...] (N m, N m/s, ...): normalised units.
    d_scale
        N, the tyre non-linearity Gamma the H-infinity bound is posed for (the paper's 1000 N
        assumes saturation everywhere and leaves phi unobservable at low frequency against it).
    xi_weight, w_weight, z_tau
        Weights of the model error xi (per x_scale), of the torque's last derivative (per its
        f_scale / s) and of the torque error in the objective (the roll-angle error has weight 1).
    alpha, radius
        Pole region of the closed loop at every speed of every band: Re < -alpha (1/s, also the
        certified decay rate of x'Px / 2), |lambda| < radius (rad/s).
    gamma_slack
        The second solve keeps gamma^2 <= (1 + gamma_slack) * its minimum and minimises the gains.
    hysteresis, vx_hold
        Runtime (m/s): band switching hysteresis; below |vx| < vx_hold the estimates are held.
    """

    name: str
    bands: tuple[tuple[float, float], ...] = ((7.5, 32.5),)
    torque_integrators: int = 2
    x_scale: tuple[float, ...] = (1.0, 0.5, 0.5, 0.05, 0.5, 0.2)
    f_scale: tuple[float, ...] = (20.0, 100.0)
    d_scale: float = 100.0
    xi_weight: float = 1.0
    w_weight: float = 1.0
    z_tau: float = 0.1
    alpha: float = 5.0
    radius: float = 150.0
    gamma_slack: float = 0.1
    hysteresis: float = 0.5
    vx_hold: float = 1.0
    margin: float = 1e-7             # strictness of the LMIs, normalised units
    region_margin: float = 0.02      # the solve asks alpha (1 + m), radius (1 - m): the certificate's
                                     # alpha and radius then hold with room for the solver's round-off
    gain_limit: float = 1e6          # certificate: largest admissible entry of L (SI)
    cond_limit: float = 1e8          # certificate: largest admissible cond(P) (normalised)

    def validate(self) -> None:
        where = f"design {self.name}"
        b = [tuple(map(float, x)) for x in self.bands]
        if not b or any(len(x) != 2 or not (0 < x[0] < x[1] < math.inf) for x in b) \
                or any(b[i][1] != b[i + 1][0] for i in range(len(b) - 1)):
            raise ValueError(f"{where}: bands must be contiguous increasing [lo, hi) pairs with 0 < lo < hi, got {self.bands}")
        if not (isinstance(self.torque_integrators, int) and 1 <= self.torque_integrators <= 3):
            raise ValueError(f"{where}: torque_integrators must be 1, 2 or 3, got {self.torque_integrators!r}")
        for what, sc, k in (("x_scale", self.x_scale, len(STATES)), ("f_scale", self.f_scale, self.torque_integrators)):
            if len(sc) != k or any(not (s > 0 and math.isfinite(s)) for s in sc):
                raise ValueError(f"{where}: {what} needs {k} positive magnitudes, got {sc}")
        for what in ("d_scale", "xi_weight", "w_weight", "z_tau", "alpha", "gamma_slack"):
            v = getattr(self, what)
            if not (math.isfinite(v) and v >= 0) or (what == "d_scale" and v == 0):
                raise ValueError(f"{where}: {what} must be finite and >= 0 (d_scale > 0), got {v}")
        if not (self.radius > self.alpha):
            raise ValueError(f"{where}: radius must exceed alpha, got {self.radius}")
        if not (self.hysteresis >= 0 and self.vx_hold >= 0):
            raise ValueError(f"{where}: hysteresis and vx_hold must be >= 0")


# -- the model in the basis (1, vx, 1/vx) ---------------------------------------------------------
def _default_model():
    from .motorcycle_model import reduced_model     # Sharp 1971, reduced (sigma = 0): section II.D
    return reduced_model


def augmented_at(r, nt: int):
    """The design model of a ReducedModel ``r`` (eq. 9): x = [x_paper; phi] (phi' = roll rate),
    s = [x; tau; tau'; ...] (nt torque states). Returns A (na x na), Ed (Gamma), C (ny x na),
    H (2 x 6: forces [Ff, Fr] = H x, phi's column H_phi)."""
    n = len(STATES)
    na = n + nt
    A = np.zeros((na, na))
    A[:5, :5] = r.A
    A[:5, ROLL] = np.ravel(r.E_phi)          # departure: phi a state (eq. 12 has it in f)
    A[ROLL, ROLL_RATE] = 1.0
    A[:5, n] = np.ravel(r.B_tau)
    for j in range(nt - 1):                  # departure: PMI chain tau' = tau_1, ...
        A[n + j, n + j + 1] = 1.0
    Ed = np.zeros((na, 2))
    Ed[:5] = r.E_gamma
    C = np.zeros((3, na))
    C[:, :5] = r.C
    H = np.hstack([np.asarray(r.H_x, float), np.asarray(r.H_phi, float).reshape(2, 1)])
    return A, Ed, C, H


def basis(vx: float) -> tuple[float, float, float]:
    return (1.0, vx, 1.0 / vx)


def model_coefficients(vehicle: Vehicle, opts: DesignOptions, model=None) -> dict:
    """The coefficients of A, E_d, C, H in BASIS, solved from the model at three speeds and checked
    at three others (relative error <= 1e-10, else DesignError: the model is not of that form)."""
    model = model or _default_model()
    nt = opts.torque_integrators
    lo, hi = opts.bands[0][0], opts.bands[-1][1]
    fit = (lo, math.sqrt(lo * hi), hi)
    X = np.array([basis(v) for v in fit])
    mats = [augmented_at(model(vehicle, v), nt) for v in fit]
    Xi = np.linalg.inv(X)
    coef = [[sum(Xi[k, j] * mats[j][m] for j in range(3)) for k in range(3)] for m in range(4)]
    for v in (0.5 * (lo + fit[1]), 0.5 * (fit[1] + hi), 1.05 * hi):
        got = augmented_at(model(vehicle, v), nt)
        for m, name in enumerate(("A", "E_d", "C", "H")):
            b = basis(v)
            pred = sum(bk * ck for bk, ck in zip(b, coef[m]))
            err = np.max(np.abs(pred - got[m])) / max(np.max(np.abs(got[m])), 1e-300)
            if not err <= 1e-10:
                raise DesignError(f"design {opts.name}: model matrix {name} is not A_0 + vx A_1 + A_2/vx "
                                  f"(relative error {err:.2g} at vx = {v:g} m/s); this design needs that form")
    A, Ed, C, H = coef
    # exact structure imposed: the kinematic row phi' = roll rate and the PMI chain are not fitted
    # (the fit returns them to within an ulp), and coefficients below the fit's round-off are 0
    exact = augmented_at(model(vehicle, fit[1]), nt)[0]
    for k in range(3):
        A[k][MECHANICAL:] = exact[MECHANICAL:] if k == 0 else 0.0
        scale = np.max(np.abs(A[0][:MECHANICAL]), axis=1, keepdims=True) / max(abs(b) for b in basis(hi) + basis(lo))
        A[k][:MECHANICAL][np.abs(A[k][:MECHANICAL]) <= 1e-13 * scale] = 0.0
    for name, c, allowed in (("E_d", Ed, (0,)), ("C", C, (0,)), ("H", H, (0, 2))):
        for k in range(3):      # exact structure imposed: coefficients the model does not have are 0
            if k not in allowed:
                if np.max(np.abs(c[k])) > 1e-9 * max(np.max(np.abs(c[0])), 1.0):
                    raise DesignError(f"design {opts.name}: model matrix {name} depends on the speed through "
                                      f"basis function {BASIS[k]!r}; this design assumes it does not")
                c[k] = np.zeros_like(c[k])
    C[0] = np.round(C[0])       # a 0/1 selection (y are states)
    return {"A": A, "E_d": Ed, "C": C, "H": H, "nt": nt}


def at(coef: list, vx: float) -> np.ndarray:
    """sum_k basis_k(vx) coef_k."""
    b = basis(vx)
    return b[0] * coef[0] + b[1] * coef[1] + b[2] * coef[2]


def corners(band) -> list[tuple[float, float]]:
    """(vx, w) corners of [lo, hi] x [1/hi, 1/lo]: the box holds the curve w = 1/vx over the band."""
    lo, hi = float(band[0]), float(band[1])
    return [(lo, 1 / lo), (lo, 1 / hi), (hi, 1 / lo), (hi, 1 / hi)]


def scaling(opts: DesignOptions) -> dict:
    """D = diag(x_scale, f_scale) (s = D s_n) and Y = diag(x_scale of the measured states) (y = Y y_n)."""
    xs, fs = np.asarray(opts.x_scale, float), np.asarray(opts.f_scale, float)
    return {"D": np.diag(np.concatenate([xs, fs])), "Y": np.diag([xs[STATES.index(m)] for m in MEASUREMENTS])}


def performance(opts: DesignOptions, na: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Normalised disturbance columns (B_xi: na x 5, B_w: na x 1) and performance rows C_z (2 x na):
    w = [Gamma / d_scale, xi / x_scale (mechanical states), tau^(nt) / (f_scale[-1] / s)],
    z = [e_phi / x_scale_phi, z_tau e_tau / f_scale_tau]."""
    Bxi = np.zeros((na, MECHANICAL))
    Bxi[:MECHANICAL, :MECHANICAL] = opts.xi_weight * np.eye(MECHANICAL)
    Bw = np.zeros((na, 1))
    Bw[-1, 0] = opts.w_weight
    Cz = np.zeros((2, na))
    Cz[0, ROLL] = 1.0
    Cz[1, len(STATES)] = opts.z_tau
    return Bxi, Bw, Cz


def normalised(A, Ed, C, opts: DesignOptions) -> tuple:
    """An, Bn (all disturbances), Cn (measurements), Cz: the system in normalised units."""
    sc = scaling(opts)
    D, Y = sc["D"], sc["Y"]
    Di = np.linalg.inv(D)
    Bxi, Bw, Cz = performance(opts, A.shape[0])
    Bn = np.hstack([Di @ Ed * float(opts.d_scale), Bxi, Bw])
    return Di @ A @ D, Bn, np.linalg.solve(Y, C @ D), Cz


# -- the LMIs ---------------------------------------------------------------------------------------
def _lmis(P, U, g, An, Bn, Cn, Cz, opts, eps, cp):
    """The LMI families at one (vx, 1/vx) corner: {name: constraint}. PA = P (A - L C), L = -P^-1 U."""
    na = An.shape[0]
    PA = P @ An + U @ Cn
    core = PA + PA.T
    nd = Bn.shape[1]
    # departure from (20): the bound is on the estimation errors z of phi and tau, not the residual
    hinf = cp.bmat([[core + Cz.T @ Cz, P @ Bn], [(P @ Bn).T, -g * np.eye(nd)]])
    alpha, radius = opts.alpha * (1 + opts.region_margin), opts.radius * (1 - opts.region_margin)
    disk = cp.bmat([[-radius * P, PA], [PA.T, -radius * P]])
    # (a cvxpy semidefinite constraint is on the symmetric part (M + M') / 2 of its matrix)
    return {"H-infinity w -> z": hinf << -eps * np.eye(na + nd),
            f"decay Re < -{opts.alpha:g}": core + 2 * alpha * P << -eps * np.eye(na),
            f"disk |lambda| < {opts.radius:g}": disk << -eps * np.eye(2 * na)}


def design(vehicle: Vehicle, opts: DesignOptions, model=None) -> dict:
    """Solve the LMIs (one P, per band U(vx) = U_0 + vx U_1 + U_2/vx, at the band's corners) and
    return the design dict (no certificate yet). Raises DesignError naming the band and LMI."""
    import cvxpy as cp   # design time only

    opts.validate()
    mc = model_coefficients(vehicle, opts, model)
    A, Ed, C = mc["A"], mc["E_d"], mc["C"]
    na, ny = A[0].shape[0], C[0].shape[0]
    _check_detectable(mc, opts)
    sc = scaling(opts)
    P = cp.Variable((na, na), symmetric=True)
    g = cp.Variable(nonneg=True)
    eps = opts.margin
    Us, fam = [], {"P >= I": [P >> (1 + eps) * np.eye(na)]}
    for i, band in enumerate(opts.bands):
        U = [cp.Variable((na, ny)) for _ in BASIS]
        Us.append(U)
        for v, w in corners(band):
            An, Bn, Cn, Cz = normalised(A[0] + v * A[1] + w * A[2], Ed[0], C[0], opts)
            for name, con in _lmis(P, U[0] + v * U[1] + w * U[2], g, An, Bn, Cn, Cz, opts, eps, cp).items():
                fam.setdefault(f"{name}, band {i + 1} [{band[0]:g}, {band[1]:g}) m/s", []).append(con)
    cons = [c for cs in fam.values() for c in cs]
    status, seconds = lmi.solve(cp.Problem(cp.Minimize(g), cons))
    if not lmi.solved(status) or g.value is None:
        raise DesignError(f"design {opts.name}: no solution of the LMIs ({lmi.label()}: {status}); " + _diagnose(fam))
    g_min = float(g.value)
    # second solve: gamma within the slack, the smallest gains (normalised U)
    status2, seconds2 = lmi.solve(cp.Problem(cp.Minimize(sum(cp.norm(u, "fro") for U in Us for u in U)),
                                             cons + [g <= (1 + opts.gamma_slack) * g_min]))
    if not lmi.solved(status2) or P.value is None:
        raise DesignError(f"design {opts.name}: the gain-minimising solve failed ({lmi.label()}: {status2})")
    Pn = (P.value + P.value.T) / 2
    D, Yi = sc["D"], np.linalg.inv(sc["Y"])
    bands = []
    for i, (band, U) in enumerate(zip(opts.bands, Us)):
        Un = [u.value for u in U]
        Ln = [-np.linalg.solve(Pn, u) for u in Un]          # L = -P^-1 U (per basis function), normalised
        L = [D @ l @ Yi for l in Ln]                         # SI: L = D L_n Y^-1
        bands.append({"index": i + 1, "label": f"{band[0]:g}-{band[1]:g} m/s", "band": [float(band[0]), float(band[1])],
                      "vx": float(math.sqrt(band[0] * band[1])), "gains": {"L": L}, "U": Un})
    solver = {"name": lmi.current(), "status": f"{status},{status2}" if status != status2 else str(status),
              "seconds": round(seconds + seconds2, 4), "gamma_min": math.sqrt(g_min)}
    # gamma_bar stored 1e-6 above the solver's: the bounded-real LMI then holds with room for its round-off
    return to_design_dict(vehicle, opts, mc, Pn, float(g.value) * (1 + 1e-6), bands, solver,
                          "latobs.synthesis.motorcycle_model.reduced_model" if model is None else
                          f"{getattr(model, '__module__', '?')}.{getattr(model, '__qualname__', repr(model))}")


def _check_detectable(mc: dict, opts: DesignOptions) -> None:
    """PBH: (A(vx), C) detectable at the corners' speeds; else DesignError naming the speed."""
    for band in opts.bands:
        for v in (band[0], math.sqrt(band[0] * band[1]), band[1]):
            Av, Cv = at(mc["A"], v), mc["C"][0]
            na = Av.shape[0]
            for lam in np.linalg.eigvals(Av):
                if lam.real >= -1e-9 * max(1.0, abs(lam)):
                    s = np.linalg.svd(np.vstack([lam * np.eye(na) - Av, Cv]), compute_uv=False)
                    if not s[-1] > 1e-9 * s[0]:
                        raise DesignError(f"design {opts.name}: at vx = {v:g} m/s the mode {lam:.4g} is not "
                                          "observable from y = [steer angle, yaw rate, roll rate]")


def _diagnose(fam: dict) -> str:
    alone = [k for k, c in fam.items() if not lmi.feasible(c)]
    if alone:
        return "infeasible on its own: " + ", ".join(alone)
    return "each LMI family is feasible alone; together they are not"


def closed_loop(mc: dict, L: list, v: float):
    """A(vx) - L(vx) C in SI at the speed v (m/s)."""
    return at(mc["A"], v) - at(L, v) @ mc["C"][0]


def to_design_dict(vehicle, opts, mc, P, gamma_bar, bands, solver, source) -> dict:
    n, nt = len(STATES), opts.torque_integrators
    na = n + nt
    faults = ["rider_torque"] + [f"rider_torque_d{j}" for j in range(1, nt)]
    edges = [b["band"][0] for b in bands] + [bands[-1]["band"][1]]
    modes = []
    for b in bands:
        ev = np.concatenate([np.linalg.eigvals(closed_loop(mc, b["gains"]["L"], v))
                             for v in np.linspace(b["band"][0], b["band"][1], 9)])
        modes.append({**{k: b[k] for k in ("index", "label", "band", "vx")},
                      "scheduling": {"variable": "vx", "unit": "m/s", "range": b["band"],
                                     "model_speed": "measured, clamped to the band"},
                      "gains": {"L": [np.asarray(x) for x in b["gains"]["L"]]}, "U": b["U"],
                      "slowest_pole_re": float(np.max(ev.real)), "fastest_pole_abs": float(np.max(np.abs(ev)))})
    return {
        "schema": "latobs.design/1",
        "name": opts.name,
        "paper": "003",
        "method": "measured_speed",
        "title": "Motorcycle roll angle and rider torque observer at the measured speed (paper 003 extended: "
                 "roll angle as a state, PMI torque, one Lyapunov matrix)",
        "vehicle": vehicle.as_dict(),
        "options": {k: getattr(opts, k) for k in opts.__dataclass_fields__},
        "structure": {"states": list(STATES), "state_units": list(STATE_UNITS), "faults": faults,
                      "measurements": list(MEASUREMENTS), "forces": ["Ff", "Fr"], "basis": list(BASIS),
                      "model_source": source,
                      "model_form": "s = [x; tau; tau' ...], s' = A(vx) s + E_d Gamma + xi, y = C s, forces [Ff, Fr] = "
                                    "H(vx) x; A(vx) = A_0 + vx A_1 + A_2/vx (BASIS), phi' = roll rate"},
        "model": {"A": mc["A"], "E_d": mc["E_d"], "C": mc["C"], "H": mc["H"]},
        "scaling": {"x_scale": list(opts.x_scale), "f_scale": list(opts.f_scale), "d_scale": opts.d_scale,
                    "rule": "normalised s = D s_n, D = diag(x_scale, f_scale); y = Y y_n, Y = diag(x_scale of y); "
                            "L (SI) = D L_n Y^-1; w and z as in the synthesis module's performance()"},
        "lyapunov": {"P": P, "gamma_bar": gamma_bar, "alpha": opts.alpha, "radius": opts.radius,
                     "rule": "one P for every band and speed: A_cl(vx, w)'P + P A_cl(vx, w) <= -2 alpha P and the "
                             "bounded-real LMI at the corners of every band's (vx, 1/vx) box"},
        "switching": {"kind": "speed_bands", "variable": "vx", "unit": "m/s", "edges": edges,
                      "hysteresis": opts.hysteresis,
                      "rule": "band i on [edges[i], edges[i+1]), the nearest outside; the active band kept within "
                              "the hysteresis; any switching signal is stable (one Lyapunov matrix)"},
        "modes": modes,
        "gamma": math.sqrt(gamma_bar),
        "region": {"alpha": opts.alpha, "radius": opts.radius},
        "runtime": {"vx_hold": opts.vx_hold,
                    "equations": "s' = (A(v) - L(v) C) s + L(v) y, v the measured speed clamped to the active band; "
                                 "[Ff^, Fr^] = H(v) x^"},
        "solver": solver,
        "notes": ["One Lyapunov matrix P for every band and speed: d(x'Px)/dt = x'(A_cl(vx)'P + P A_cl(vx))x <= "
                  "-2 alpha x'Px holds for any speed history inside the bands and any band switching (no dwell time).",
                  "gamma bounds the L2 gain from the normalised w to z of the linear reduced model for any such speed "
                  "history; nothing is claimed for the nonlinear motorcycle."],
    }
