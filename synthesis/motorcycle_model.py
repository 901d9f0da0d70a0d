"""Sharp's (1971) linear lateral motorcycle model, derived symbolically with sympy at design time
(Kane's method, small-angle linearisation; paper 003's printed eq. (1) has garbled signs): the
full 8-state model, paper 003's reduced model and coefficients, and the plant's structure in
plain numbers. Axes, bodies, coefficients and tyres are on the documentation's paper-003 page."""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from .params import G, Vehicle, load_vehicle

#: the full model's state order (8 states)
STATE_FULL = ("roll_angle", "steer_angle", "vy", "yaw_rate", "roll_rate", "steer_rate", "Ff", "Fr")
#: the reduced model's state order (sigma -> 0, roll angle an input; paper 003 section II.D)
STATE_REDUCED = ("vy", "yaw_rate", "roll_rate", "steer_angle", "steer_rate")
#: measured outputs of paper 003: y = [steer_angle, yaw_rate, roll_rate]
OUTPUTS = ("steer_angle", "yaw_rate", "roll_rate")
#: generalised speeds of the mechanical equations (E1), in this order
SPEEDS = ("vy", "yaw_rate", "roll_rate", "steer_rate")

#: vehicle parameters the model uses (names of synthesis/vehicles/sharp_motorcycle.toml)
PARAMETERS = ("mr", "mf", "b", "h", "a", "an", "e", "f", "epsilon", "Irx", "Irz", "Crxz", "Ifx", "Ifz",
              "ify", "iry", "rf", "rr", "Zf", "C_delta", "Cf1", "Cf2", "Cr1", "Cr2", "sigma")
#: the parameters that enter the mechanical equations (E1), the arguments of the lambdified matrices
_MECH = ("mr", "mf", "b", "h", "a", "an", "e", "f", "epsilon", "Irx", "Irz", "Crxz", "Ifx", "Ifz",
         "ify", "iry", "rf", "rr", "Zf", "C_delta")

#: closed forms of paper 003's coefficients in the parameter names (g the gravity); the tests check
#: that the derivation gives exactly these (paper_coefficients() evaluates the derived ones)
_PAPER_FORMULAS = {
    "M": "mf + mr",
    "mf_k": "mf*((a + e)*cos(epsilon) + f*sin(epsilon))",
    "mf_j_mr_h": "mf*((a + e)*sin(epsilon) - f*cos(epsilon)) + mr*h",
    "mf_e": "mf*e",
    "a1": "mf*e*k + Ifz*cos(epsilon)",
    "a2": "mf*j*k + Crxz + (Ifz - Ifx)*sin(epsilon)*cos(epsilon)",
    "a3": "mf*k**2 + Irz + Ifx*sin(epsilon)**2 + Ifz*cos(epsilon)**2",
    "a4": "ify/rf + iry/rr",
    "b1": "mf*e*j + Ifz*sin(epsilon)",
    "b2": "mr*h**2 + mf*j**2 + Irx + Ifx*cos(epsilon)**2 + Ifz*sin(epsilon)**2",
    "b3": "Zf*an - mf*e*g",
    "b4": "(mf*j + mr*h)*g",
    "b5": "mf*j + mr*h + ify/rf + iry/rr",
    "c1": "mf*e**2 + Ifz",
    "c2": "(Zf*an - mf*e*g)*sin(epsilon)",
    "c3": "mf*e + ify/rf*sin(epsilon)",
    "K": "C_delta",
    "lf": "(a - an)/cos(epsilon)",
    "lr": "b",
}


# ---------------------------------------------------------------------------------------------
# the symbolic derivation (sympy, once per process)
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Derivation:
    """The derived linear equations (E1) and tyre geometry, symbolic (sympy objects).

    M, C0, C1 (4x4 over SPEEDS), K (4x2 over [phi, delta]), B_F (4x2 over [Ff, Fr]), B_tau (4x1);
    ``slip``: {"front"/"rear": (coefficients of [vy, r, roll_rate, steer_rate] in the contact
    point's lateral velocity, coefficient of delta in the wheel heading)}; ``camber``:
    {"front"/"rear": coefficients of [phi, delta]}; ``symbols``: name -> sympy Symbol (the
    PARAMETERS plus "g", "vx", "Iry", "Ify"); ``eqs``: the nonlinear Kane equations (a
    sympy Matrix, generalised accelerations/speeds/coordinates as plain symbols named in
    ``state_symbols``).
    """

    M: object
    C0: object
    C1: object
    K: object
    B_F: object
    B_tau: object
    slip: dict
    camber: dict
    symbols: dict
    eqs: object
    state_symbols: dict


@functools.lru_cache(maxsize=1)
def derivation() -> Derivation:
    """Kane's equations of Sharp's two-frame motorcycle, linearised about straight running.

    Cached: ~1 s the first time in a process (``xreplace``, a structural substitution: ``subs`` took ~11 s). See the module docstring for the model.
    """
    import sympy as sp
    from sympy.physics.vector import Point, ReferenceFrame, dot, dynamicsymbols, outer

    t = sp.Symbol("t")
    psi, phi, delta = dynamicsymbols("psi phi delta")
    vy, r, p, d = dynamicsymbols("v_y r p d")   # generalised speeds: vy, yaw rate, roll rate, steer rate
    S = {n: sp.Symbol(n, real=True) for n in PARAMETERS + ("g", "vx", "Iry", "Ify")}
    mr, mf, b, h, a, an, e, f, eps = (S[n] for n in ("mr", "mf", "b", "h", "a", "an", "e", "f", "epsilon"))
    Irx, Irz, Crxz, Ifx, Ifz, Iry, Ify = (S[n] for n in ("Irx", "Irz", "Crxz", "Ifx", "Ifz", "Iry", "Ify"))
    ify, iry, rf, rr, Zf, Cd, g, U = (S[n] for n in ("ify", "iry", "rf", "rr", "Zf", "C_delta", "g", "vx"))
    Ff, Fr, tau = sp.symbols("F_f F_r tau", real=True)

    # frames: inertial N (z down), yaw A, rear frame B (roll about A.x), steering-head H (fixed in
    # B, H.z along the steering axis s), front frame C (steer about H.z)
    N = ReferenceFrame("N")
    A = N.orientnew("A", "Axis", [psi, N.z])
    B = A.orientnew("B", "Axis", [phi, A.x])
    H = B.orientnew("H", "Axis", [eps, B.y])     # H.z = sin(eps) B.x + cos(eps) B.z
    C = H.orientnew("C", "Axis", [delta, H.z])
    qd = {psi.diff(t): r, phi.diff(t): p, delta.diff(t): d}
    for fr in (A, B, H, C):
        fr.set_ang_vel(N, fr.ang_vel_in(N).xreplace(qd))

    # points: P (ground, below the rear mass centre, on the roll axis), rear mass centre Gr,
    # rear contact Rc, steering-axis ground point Sg, front mass centre Gf, front contact Fc
    # (the front-frame point at the contact). In H's axes (x perpendicular to the axis, z along
    # it), Gf is e ahead of the axis and Fc an behind it; their positions along the axis follow
    # from k, j (Gf) and from the contact being on the ground (Fc).
    P = Point("P")
    P.set_vel(N, U * A.x + vy * A.y)
    Gr = P.locatenew("Gr", -h * B.z)
    Rc = P.locatenew("Rc", -b * B.x)
    Sg = P.locatenew("Sg", a / sp.cos(eps) * B.x)
    Gf = Sg.locatenew("Gf", e * C.x + (f - a * sp.tan(eps)) * C.z)
    Fc = Sg.locatenew("Fc", -an * C.x - an * sp.tan(eps) * C.z)
    for pt in (Gr, Rc, Sg):
        pt.v2pt_theory(P, N, B)
    for pt in (Gf, Fc):
        pt.v2pt_theory(Sg, N, C)

    wB, wC = B.ang_vel_in(N), C.ang_vel_in(N)
    IB = Irx * outer(B.x, B.x) + Iry * outer(B.y, B.y) + Irz * outer(B.z, B.z) \
        + Crxz * (outer(B.x, B.z) + outer(B.z, B.x))
    IC = Ifx * outer(C.x, C.x) + Ify * outer(C.y, C.y) + Ifz * outer(C.z, C.z)
    # angular momenta: frames, and the wheels' spin (spin -vx/R about the axle, polar inertia only)
    HB = IB.dot(wB)
    HC = IC.dot(wC)
    Hrw = iry * (dot(wB, B.y) - U / rr) * B.y
    Hfw = ify * (dot(wC, C.y) - U / rf) * C.y

    def ddt(vec):
        return vec.dt(N).xreplace(qd)

    aGr, aGf = ddt(Gr.vel(N)), ddt(Gf.vel(N))
    dHB, dHC, dHrw, dHfw = ddt(HB), ddt(HC), ddt(Hrw), ddt(Hfw)
    eqs = []
    for u in (vy, r, p, d):
        vGr, vGf = Gr.vel(N).diff(u, N), Gf.vel(N).diff(u, N)
        vFc, vRc = Fc.vel(N).diff(u, N), Rc.vel(N).diff(u, N)
        wBu, wCu = wB.diff(u, N), wC.diff(u, N)
        active = (dot(mr * g * N.z, vGr) + dot(mf * g * N.z, vGf) + dot(Zf * N.z, vFc)
                  + dot(Ff * A.y, vFc) + dot(Fr * A.y, vRc) + dot((tau - Cd * d) * H.z, wCu - wBu))
        inertia = -(dot(mr * aGr, vGr) + dot(mf * aGf, vGf) + dot(dHB, wBu) + dot(dHC + dHfw, wCu)
                    + dot(dHrw, wBu))
        eqs.append(active + inertia)

    # plain symbols for the accelerations, speeds and coordinates, then the Jacobians at zero
    ud = sp.symbols("vy_dot r_dot p_dot d_dot", real=True)
    us = sp.symbols("vy_ r_ p_ d_", real=True)
    qs = sp.symbols("psi_ phi_ delta_", real=True)
    rep = {**dict(zip([x.diff(t) for x in (vy, r, p, d)], ud)), **dict(zip((vy, r, p, d), us)),
           **dict(zip((psi, phi, delta), qs))}
    E = sp.Matrix([x.xreplace(rep) for x in eqs])
    zero = {**{x: 0 for x in ud + us + qs}, Ff: 0, Fr: 0, tau: 0}

    def jacobian_at_zero(xs):
        """E's Jacobian in xs at the straight-running point (every variable of ``zero`` at 0):
        each column the derivative of E along its own variable's axis (the others put to 0
        first: the same expressions as E.jacobian(xs).xreplace(zero), in a sixth of the time)."""
        return sp.Matrix.hstack(*[E.xreplace({z: 0 for z in zero if z != x}).diff(x).xreplace({x: 0}) for x in xs])

    Mm = -jacobian_at_zero(ud)
    Cm = -jacobian_at_zero(us)
    Kq = -jacobian_at_zero(qs)
    if any(sp.simplify(x) != 0 for x in Kq[:, 0]):
        raise AssertionError("motorcycle derivation: the yaw angle must not enter the equations")
    Bf = jacobian_at_zero([Ff, Fr, tau])
    Cm = sp.expand(Cm)
    C1 = Cm.diff(U)
    C0 = Cm.xreplace({U: 0})

    # tyre kinematics: lateral velocity of the contact points, wheel heading and camber
    def lin(expr, xs):
        expr = expr.xreplace(rep)
        return [sp.simplify(sp.diff(expr, x).xreplace(zero)) for x in xs]

    speeds = list(us)
    slip = {"front": (lin(dot(Fc.vel(N), A.y), speeds),
                      # heading of the front wheel's ground line C.y x N.z relative to A.x
                      lin(dot(C.y.cross(N.z), A.y) / dot(C.y.cross(N.z), A.x), [qs[2]])[0]),
            "rear": (lin(dot(Rc.vel(N), A.y), speeds),
                     lin(dot(B.y.cross(N.z), A.y) / dot(B.y.cross(N.z), A.x), [qs[2]])[0])}
    # camber: sin(gamma) = (wheel axle) . (down), > 0 leaning right
    camber = {"front": lin(dot(C.y, N.z), [qs[1], qs[2]]), "rear": lin(dot(B.y, N.z), [qs[1], qs[2]])}
    state_symbols = {"accelerations": ud, "speeds": us, "coordinates": qs, "forces": (Ff, Fr), "tau": tau}
    return Derivation(M=Mm, C0=C0, C1=C1, K=Kq[:, 1:], B_F=Bf[:, :2], B_tau=Bf[:, 2], slip=slip,
                      camber=camber, symbols=S, eqs=E, state_symbols=state_symbols)


@functools.lru_cache(maxsize=1)
def _numeric():
    """The derivation as numpy functions of the _MECH parameters and g (lambdified once)."""
    import sympy as sp

    D = derivation()
    args = [D.symbols[n] for n in _MECH] + [D.symbols["g"]]
    for name, mat in (("M", D.M), ("K", D.K), ("B_F", D.B_F), ("B_tau", D.B_tau), ("C1", D.C1)):
        if D.symbols["vx"] in mat.free_symbols:
            raise AssertionError(f"motorcycle derivation: {name} must not depend on vx")
    geo = sp.Matrix([*D.slip["front"][0], D.slip["front"][1], *D.slip["rear"][0], D.slip["rear"][1],
                     *D.camber["front"], *D.camber["rear"]])
    return {name: sp.lambdify(args, mat, "numpy") for name, mat in
            (("M", D.M), ("C0", D.C0), ("C1", D.C1), ("K", D.K), ("B_F", D.B_F), ("B_tau", D.B_tau),
             ("geometry", geo))}


def _values(vehicle) -> tuple[Vehicle, dict]:
    v = load_vehicle(vehicle) if isinstance(vehicle, str) else vehicle
    return v, v.require(PARAMETERS, "the Sharp motorcycle model (synthesis/motorcycle_model.py)")


@dataclass(frozen=True)
class Mechanics:
    """The linear mechanical equations (E1) in numbers: M du/dt + (C0 + vx C1) u + K [phi, delta]
    = B_F [Ff, Fr] + B_tau tau, u = [vy, yaw_rate, roll_rate, steer_rate]; and the tyre geometry
    (slip/camber coefficients, derived)."""

    M: np.ndarray
    C0: np.ndarray
    C1: np.ndarray
    K: np.ndarray
    B_F: np.ndarray
    B_tau: np.ndarray
    slip_front: np.ndarray   # coefficients of [vy, r, roll_rate, steer_rate] in the contact lateral velocity
    heading_front: float     # coefficient of delta in the front wheel heading (cos eps)
    slip_rear: np.ndarray
    heading_rear: float
    camber_front: np.ndarray  # coefficients of [phi, delta]
    camber_rear: np.ndarray


def mechanics(vehicle: Vehicle | str = "sharp_motorcycle") -> Mechanics:
    """Numeric matrices of (E1) and the derived tyre geometry for a vehicle."""
    _, p = _values(vehicle)
    f = _numeric()
    args = [p[n] for n in _MECH] + [G]
    arr = lambda name, shape: np.asarray(f[name](*args), dtype=float).reshape(shape)  # noqa: E731
    geo = arr("geometry", (14,))
    return Mechanics(M=arr("M", (4, 4)), C0=arr("C0", (4, 4)), C1=arr("C1", (4, 4)), K=arr("K", (4, 2)),
                     B_F=arr("B_F", (4, 2)), B_tau=arr("B_tau", (4,)), slip_front=geo[0:4], heading_front=geo[4],
                     slip_rear=geo[5:9], heading_rear=geo[9], camber_front=geo[10:12], camber_rear=geo[12:14])


def paper_coefficients(vehicle: Vehicle | str = "sharp_motorcycle") -> dict[str, float]:
    """Paper 003's coefficients (eq. (1)-(2)) read off the DERIVED matrices (SI units):
    M, mf_k, mf_j_mr_h, mf_e, a1..a4, b1..b5, c1..c3, K, lf, lr (see the module docstring)."""
    m = mechanics(vehicle)
    M, C1, C0, K, BF = m.M, m.C1, m.C0, m.K, m.B_F
    return {
        "M": M[0, 0], "mf_k": M[0, 1], "mf_j_mr_h": M[0, 2], "mf_e": M[0, 3],
        "a1": M[1, 3], "a2": M[1, 2], "a3": M[1, 1], "a4": -C1[1, 2],
        "b1": M[2, 3], "b2": M[2, 2], "b3": K[2, 1], "b4": -K[2, 0], "b5": C1[2, 1],
        "c1": M[3, 3], "c2": K[3, 1], "c3": C1[3, 1], "K": C0[3, 3],
        "lf": BF[1, 0], "lr": -BF[1, 1],
    }


def paper_formulas() -> dict[str, object]:
    """The closed forms of ``paper_coefficients`` as sympy expressions in the parameter symbols of
    ``derivation().symbols`` (k, j substituted)."""
    import sympy as sp

    S = dict(derivation().symbols)
    eps = S["epsilon"]
    k = (S["a"] + S["e"]) * sp.cos(eps) + S["f"] * sp.sin(eps)
    j = (S["a"] + S["e"]) * sp.sin(eps) - S["f"] * sp.cos(eps)
    loc = {**S, "k": k, "j": j, "sin": sp.sin, "cos": sp.cos}
    return {name: sp.sympify(text, locals=loc) for name, text in _PAPER_FORMULAS.items()}


# ---------------------------------------------------------------------------------------------
# the full (8-state) and reduced (5-state) linear models
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class FullModel:
    """Linear model with tyre relaxation at the speed vx (m/s):

        x' = A x + B_tau tau + E_gamma [Gamma_f, Gamma_r],   y = C x

    x in STATE_FULL order; y = [steer_angle, yaw_rate, roll_rate]. Gamma enters the relaxation
    equations: Ff' = (vx/sigma)(Fs_f - Ff) with Fs_f = Cf1 alpha_f + Cf2 gamma_f + Gamma_f."""

    vx: float
    sigma: float
    A: np.ndarray
    B_tau: np.ndarray
    E_gamma: np.ndarray
    C: np.ndarray
    states: tuple[str, ...] = STATE_FULL
    outputs: tuple[str, ...] = OUTPUTS


@dataclass(frozen=True)
class ReducedModel:
    """Paper 003's reduced model (section II.D, sigma -> 0) at the speed vx (m/s), eq. (9):

        x' = A x + E_phi phi + B_tau tau + E_gamma [Gamma_f, Gamma_r],   y = C x

    x in STATE_REDUCED order = [vy, yaw_rate, roll_rate, steer_angle, steer_rate]; the roll angle
    phi is an input (gravity, camber); y = [steer_angle, yaw_rate, roll_rate]. The tyre forces are
    algebraic: [Ff, Fr] = H_x x + H_phi phi + Gamma (``forces``)."""

    vx: float
    A: np.ndarray
    E_phi: np.ndarray
    B_tau: np.ndarray
    E_gamma: np.ndarray
    C: np.ndarray
    H_x: np.ndarray
    H_phi: np.ndarray
    states: tuple[str, ...] = STATE_REDUCED
    outputs: tuple[str, ...] = OUTPUTS

    def forces(self, x, phi) -> tuple[float, float]:
        """Linear part of the tyre forces (Ff, Fr) in N at state x and roll angle phi (rad)."""
        F = self.H_x @ np.asarray(x, dtype=float) + self.H_phi * float(phi)
        return float(F[0]), float(F[1])


def _check_vx(vx: float) -> float:
    vx = float(vx)
    if not (math.isfinite(vx) and vx > 0):
        raise ValueError(f"the motorcycle model needs a forward speed vx > 0 m/s, got {vx}")
    return vx


def _tyre_rows(m: Mechanics, p: dict, vx: float):
    """Linear static tyre forces Fs = Hu u + Hq [phi, delta] over u = SPEEDS (from alpha, gamma)."""
    Hu = np.zeros((2, 4))
    Hq = np.zeros((2, 2))
    for i, (C1, C2, sl, hd, cb) in enumerate(((p["Cf1"], p["Cf2"], m.slip_front, m.heading_front, m.camber_front),
                                              (p["Cr1"], p["Cr2"], m.slip_rear, m.heading_rear, m.camber_rear))):
        Hu[i] = -C1 * sl / vx            # alpha = -(contact lateral velocity)/vx + heading
        Hq[i] = C2 * cb                  # camber
        Hq[i, 1] += C1 * hd
    return Hu, Hq


def full_model(vehicle: Vehicle | str = "sharp_motorcycle", vx: float = 20.0,
               sigma: float | None = None) -> FullModel:
    """The 8-state linear model (E1)+(E2) at speed vx (m/s); ``sigma`` (m) overrides the vehicle's
    relaxation length (both tyres)."""
    vx = _check_vx(vx)
    _, p = _values(vehicle)
    sig = p["sigma"] if sigma is None else float(sigma)
    if not sig > 0:
        raise ValueError(f"full_model needs a relaxation length sigma > 0 m (use reduced_model for sigma -> 0), "
                         f"got {sig}")
    m = mechanics(vehicle)
    Mi = np.linalg.inv(m.M)
    A = np.zeros((8, 8))
    iu = [2, 3, 4, 5]          # u = [vy, r, roll_rate, steer_rate] in STATE_FULL
    iq = [0, 1]                # [phi, delta]
    iF = [6, 7]
    A[0, 4] = 1.0
    A[1, 5] = 1.0
    A[np.ix_(iu, iu)] = -Mi @ (m.C0 + vx * m.C1)
    A[np.ix_(iu, iq)] = -Mi @ m.K
    A[np.ix_(iu, iF)] = Mi @ m.B_F
    Hu, Hq = _tyre_rows(m, p, vx)
    k = vx / sig
    A[np.ix_(iF, iu)] = k * Hu
    A[np.ix_(iF, iq)] = k * Hq
    A[np.ix_(iF, iF)] = -k * np.eye(2)
    B = np.zeros(8)
    B[iu] = Mi @ m.B_tau
    E = np.zeros((8, 2))
    E[iF, [0, 1]] = k
    C = np.zeros((3, 8))
    C[0, 1] = C[1, 3] = C[2, 4] = 1.0
    return FullModel(vx=vx, sigma=sig, A=A, B_tau=B, E_gamma=E, C=C)


def reduced_model(vehicle: Vehicle | str = "sharp_motorcycle", vx: float = 20.0) -> ReducedModel:
    """Paper 003's 5-state model (sigma -> 0, roll angle as input) at speed vx (m/s)."""
    vx = _check_vx(vx)
    _, p = _values(vehicle)
    m = mechanics(vehicle)
    Mi = np.linalg.inv(m.M)
    Hu, Hq = _tyre_rows(m, p, vx)
    # reduced state x = [vy, r, roll_rate, delta, steer_rate]: u = Su x, delta = x[3]
    Su = np.zeros((4, 5))
    Su[0, 0] = Su[1, 1] = Su[2, 2] = Su[3, 4] = 1.0
    H_x = Hu @ Su
    H_x[:, 3] += Hq[:, 1]
    H_phi = Hq[:, 0].copy()
    D = m.C0 + vx * m.C1
    rows = [0, 1, 2, 4]        # the rows of x' given by the mechanics (x[3]' = steer_rate)
    A = np.zeros((5, 5))
    A[3, 4] = 1.0
    Kd = np.zeros((4, 5))
    Kd[:, 3] = m.K[:, 1]
    A[rows] = Mi @ (-D @ Su - Kd + m.B_F @ H_x)
    E_phi = np.zeros(5)
    E_phi[rows] = Mi @ (-m.K[:, 0] + m.B_F @ H_phi)
    B = np.zeros(5)
    B[rows] = Mi @ m.B_tau
    E = np.zeros((5, 2))
    E[rows] = Mi @ m.B_F
    C = np.zeros((3, 5))
    C[0, 3] = C[1, 1] = C[2, 2] = 1.0
    return ReducedModel(vx=vx, A=A, E_phi=E_phi, B_tau=B, E_gamma=E, C=C, H_x=H_x, H_phi=H_phi)


# ---------------------------------------------------------------------------------------------
# modes (weave, wobble, capsize)
# ---------------------------------------------------------------------------------------------
def modes(vehicle: Vehicle | str = "sharp_motorcycle", vx: float = 20.0, sigma: float | None = None) -> dict:
    """Eigenvalues of the full model at vx, named: ``wobble`` the oscillatory pair of largest
    frequency, ``weave`` the oscillatory pair of smallest frequency, ``capsize`` the real
    eigenvalue nearest 0 (upper-half-plane member of each pair; 1/s); ``all`` every eigenvalue."""
    ev = np.linalg.eigvals(full_model(vehicle, vx, sigma).A)
    osc = sorted((z for z in ev if z.imag > 1e-6), key=lambda z: z.imag)
    real = sorted((z.real for z in ev if abs(z.imag) <= 1e-6), key=abs)
    return {"weave": complex(osc[0]) if osc else None, "wobble": complex(osc[-1]) if osc else None,
            "capsize": float(real[0]) if real else None, "all": ev}


def weave_critical_speed(vehicle: Vehicle | str = "sharp_motorcycle", lo: float = 3.0, hi: float = 10.0) -> float:
    """Speed (m/s) below which the weave mode is unstable (bisection on its real part)."""
    f = lambda v: modes(vehicle, v)["weave"].real  # noqa: E731
    if not (f(lo) > 0 > f(hi)):
        raise ValueError(f"weave does not change stability between {lo} and {hi} m/s")
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if f(mid) > 0 else (lo, mid)
    return 0.5 * (lo + hi)


# ---------------------------------------------------------------------------------------------
# what the nonlinear plant runtime needs (numbers only, JSON-able)
# ---------------------------------------------------------------------------------------------
def plant_structure(vehicle: Vehicle | str = "sharp_motorcycle") -> dict:
    """The derived model as plain numbers for the stdlib plant runtime (fmu_src/motorcycle_plant.py).

    Mechanics over the accelerations d/dt [vy, yaw_rate, roll_rate, steer_rate]:

        M du/dt = -(C0 + vx C1) u - K_sin [sin(phi), sin(delta)] + B_F [Ff, Fr] + B_tau tau

    (paper 003's eq. (1)-(2): the derived linear K with sin() of the angles; no 1/vx terms in
    the mechanics). Tyres: the contact points' lateral velocity w = slip_velocity . u, the slip
    alpha = -w/vx + heading * delta, the camber gamma = camber . [phi, delta]; static loads Fz
    (N, > 0: front -Zf, rear (mf + mr) g + Zf); C1, C2 the cornering and camber stiffnesses;
    sigma the relaxation length.
    """
    veh, p = _values(vehicle)
    m = mechanics(veh)
    Fzf = -p["Zf"]
    Fzr = (p["mf"] + p["mr"]) * G + p["Zf"]
    if not (Fzf > 0 and Fzr > 0):
        raise ValueError(f"vehicle {veh.name!r}: static tyre loads must be > 0 (front {Fzf} N, rear {Fzr} N)")
    lst = lambda a: [[float(x) for x in row] for row in a] if np.ndim(a) == 2 else [float(x) for x in a]  # noqa: E731
    return {
        "schema": "latobs.motorcycle_structure/1",
        "axes": "SAE (Sharp 1971): x forward, y right, z down; phi > 0 leans right, delta > 0 steers right",
        "speeds": list(SPEEDS),
        "angles": ["roll_angle", "steer_angle"],
        "g": G,
        "M": lst(m.M), "C0": lst(m.C0), "C1": lst(m.C1), "K_sin": lst(m.K), "B_F": lst(m.B_F),
        "B_tau": lst(m.B_tau),
        "tyres": {
            "front": {"slip_velocity": lst(m.slip_front), "heading": float(m.heading_front),
                      "camber": lst(m.camber_front), "C1": p["Cf1"], "C2": p["Cf2"], "Fz": float(Fzf),
                      "sigma": p["sigma"]},
            "rear": {"slip_velocity": lst(m.slip_rear), "heading": float(m.heading_rear),
                     "camber": lst(m.camber_rear), "C1": p["Cr1"], "C2": p["Cr2"], "Fz": float(Fzr),
                     "sigma": p["sigma"]},
        },
        "paper_coefficients": {k: float(v) for k, v in paper_coefficients(veh).items()},
    }
