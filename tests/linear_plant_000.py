"""An independent exact linear plant for paper 000's tests: single-track vehicle with roll.

Derived here from first principles with sympy; imports nothing from ``latobs.synthesis`` or
``latobs.fmu_src`` (the tests compare it with the project's design model, so it must not share
a line of code or a constant with it; G below must equal the project's G, which the tests check).

Conventions (SI units, angles in rad)
-------------------------------------
* Road-plane body axes x forward, y left, z up; the frame yaws with the car at r (rad/s) and
  moves forward at vx (m/s, prescribed, > 0).
* P: the point of the roll axis below the CG (the roll axis is parallel to x). v (m/s): lateral
  velocity of P; beta = v / vx (rad): the sideslip angle AT P (not at the CG).
* phi (rad): roll angle, a rotation of the body about +x, so phi > 0 moves the CG to -y (the body
  leans to the RIGHT, outwards in a left turn). The CG sits at (0, -hr sin phi, hr cos phi) from
  P; hr (m) is the CG height above the roll axis.
* delta (rad): road-wheel angle, > 0 steers left. Slip angles of the axles from the planar motion
  of the frame at the axles (small angles): alpha_f = delta - (v + lf r)/vx, alpha_r = -(v - lr r)/vx;
  linear tires Fyf = Cf alpha_f, Fyr = Cr alpha_r (N, per axle, along body y).
* phi_r (rad): road bank angle; > 0 tilts gravity so that it has the component -g sin(phi_r) along
  body +y (the sign of paper 000's F = [-g/Vx, 0, 0, 0]^T, ERRATA.md). Linearised: -g phi_r.
* The whole mass m rolls (no unsprung masses); Ix (kg m^2) is the roll inertia about the CG;
  the suspension puts the roll moment -Kr phi - br phi' on the body; the tires' lateral forces
  reach the body through the roll axis (at P); the vertical reaction at P is m g (small angles).

Newton-Euler (linear in the states and inputs)
----------------------------------------------
Lateral velocity of the CG: v - hr phi' (small angles), so its lateral acceleration in the
yawing frame is v' + vx r - hr phi''.

  (N)  lateral force balance of the body (at the CG):
           m (v' + vx r - hr phi'') = Fyf + Fyr - m g phi_r
  (Y)  yaw about the CG:
           Iz r' = lf Fyf - lr Fyr
  (R)  roll about the CG: the lateral force Fyf + Fyr at P (hr below the CG) has the moment
       +hr (Fyf + Fyr) about +x; the vertical reaction m g at P, which lies hr phi to the LEFT of
       the CG (+y), has the moment +m g hr phi; gravity acts at the CG (no moment about it):
           Ix phi'' = hr (Fyf + Fyr) + m g hr phi - Kr phi - br phi'

Eliminating Fyf + Fyr with (N) gives the same roll balance about the roll axis P,
       (Ix + m hr^2) phi'' - m hr (v' + vx r) = m g hr (phi + phi_r) - Kr phi - br phi',
in which the sprung mass's lateral acceleration appears with the lever hr and the bank tilts
gravity's moment as well (``roll_axis_form_residual`` checks this equivalence symbolically).
(N), (Y), (R) are solved for v', r', phi''. With beta = v/vx at CONSTANT vx, beta' = v'/vx, and
x = [beta, r, phi, phi'] obeys x' = A x + B delta + F phi_r (``model``). At a time-varying speed
``simulate`` integrates v itself (exact: beta' = v'/vx - beta vx'/vx) and reports beta = v/vx.

Measurements: y = [r, phi, phi'] (paper 000) and the lateral acceleration
ay = (Fyf + Fyr) / m = (v' + vx r - hr phi'') + g phi_r, the specific force an accelerometer at
the CG measures in road-plane axes (CarPlant's ``ay`` output: sum of the tire forces / m).
"""
from __future__ import annotations

import functools
from typing import Callable, Mapping

import numpy as np
import sympy as sp
from scipy.integrate import solve_ivp

G = 9.81  # m/s^2; must equal the project's G (the tests check it)

PARAMETERS = ("m", "Iz", "Ix", "lf", "lr", "hr", "Kr", "br", "Cf", "Cr")
STATES = ("beta", "yaw_rate", "roll_angle", "roll_rate")
MEASUREMENTS = ("yaw_rate", "roll_angle", "roll_rate")


@functools.lru_cache(maxsize=1)
def derivation() -> dict:
    """The symbolic derivation: symbols, the solved accelerations and the matrices (cached)."""
    m, Iz, Ix, lf, lr, hr, Kr, br, Cf, Cr, g, vx = sp.symbols(
        "m I_z I_x l_f l_r h_r K_r b_r C_f C_r g v_x", positive=True)
    v, r, phi, phid, delta, phir = sp.symbols("v r phi phidot delta phi_r", real=True)
    vd, rd, phidd = sp.symbols("vdot rdot phiddot", real=True)
    beta = sp.symbols("beta", real=True)

    alpha_f = delta - (v + lf * r) / vx
    alpha_r = -(v - lr * r) / vx
    Fyf = Cf * alpha_f
    Fyr = Cr * alpha_r
    eq_N = sp.Eq(m * (vd + vx * r - hr * phidd), Fyf + Fyr - m * g * phir)
    eq_Y = sp.Eq(Iz * rd, lf * Fyf - lr * Fyr)
    eq_R = sp.Eq(Ix * phidd, hr * (Fyf + Fyr) + m * g * hr * phi - Kr * phi - br * phid)
    sol = sp.solve([eq_N, eq_Y, eq_R], [vd, rd, phidd], dict=True)
    assert len(sol) == 1, sol
    acc = {k: sp.simplify(val) for k, val in sol[0].items()}

    # beta coordinates at constant speed: v = vx beta, beta' = v'/vx
    sub = {v: vx * beta}
    f = sp.Matrix([acc[vd] / vx, acc[rd], phid, acc[phidd]]).subs(sub)
    xs = sp.Matrix([beta, r, phi, phid])
    A = sp.simplify(f.jacobian(xs))
    B = sp.simplify(f.jacobian(sp.Matrix([delta])))
    F = sp.simplify(f.jacobian(sp.Matrix([phir])))
    rest = sp.simplify(f - A * xs - B * delta - F * phir)
    assert rest == sp.zeros(4, 1), rest          # linear, no affine term

    ay = sp.simplify(((Fyf + Fyr) / m).subs(sub))
    syms = dict(m=m, Iz=Iz, Ix=Ix, lf=lf, lr=lr, hr=hr, Kr=Kr, br=br, Cf=Cf, Cr=Cr, g=g, vx=vx,
                v=v, r=r, phi=phi, phid=phid, delta=delta, phir=phir, vd=vd, rd=rd, phidd=phidd, beta=beta)
    return {"symbols": syms, "accelerations": acc, "A": A, "B": B, "F": F, "ay": ay,
            "equations": (eq_N, eq_Y, eq_R)}


def roll_axis_form_residual() -> sp.Expr:
    """(Ix + m hr^2) phi'' - m hr (v' + vx r) - [m g hr (phi + phi_r) - Kr phi - br phi'] on the
    solution of (N), (Y), (R): simplifies to 0 (the two forms of the roll balance agree)."""
    d = derivation()
    s, acc = d["symbols"], d["accelerations"]
    lhs = ((s["Ix"] + s["m"] * s["hr"] ** 2) * acc[s["phidd"]]
           - s["m"] * s["hr"] * (acc[s["vd"]] + s["vx"] * s["r"]))
    rhs = s["m"] * s["g"] * s["hr"] * (s["phi"] + s["phir"]) - s["Kr"] * s["phi"] - s["br"] * s["phid"]
    return sp.simplify(lhs - rhs)


@functools.lru_cache(maxsize=1)
def _numeric():
    """numpy functions of (parameters..., g, vx): A, B, F in beta coordinates and the
    acceleration map [v', r', phi''] = M @ [v, r, phi, phi', delta, phi_r] in v coordinates."""
    d = derivation()
    s = d["symbols"]
    args = [s[k] for k in PARAMETERS] + [s["g"], s["vx"]]
    z = [s["v"], s["r"], s["phi"], s["phid"], s["delta"], s["phir"]]
    acc = sp.Matrix([d["accelerations"][s["vd"]], d["accelerations"][s["rd"]], d["accelerations"][s["phidd"]]])
    M = acc.jacobian(sp.Matrix(z))
    ay_row = sp.Matrix([d["ay"]]).subs({s["beta"]: s["v"] / s["vx"]}).jacobian(sp.Matrix(z))
    return {k: sp.lambdify(args, expr, "numpy")
            for k, expr in (("A", d["A"]), ("B", d["B"]), ("F", d["F"]), ("M", M), ("ay", ay_row))}


def _args(params: Mapping[str, float], vx: float) -> list[float]:
    missing = [k for k in PARAMETERS if k not in params]
    if missing:
        raise KeyError(f"linear plant needs parameter(s) {', '.join(missing)}")
    if not vx > 0:
        raise ValueError(f"linear plant needs vx > 0 m/s, got {vx}")
    return [float(params[k]) for k in PARAMETERS] + [G, float(vx)]


def model(params: Mapping[str, float], vx: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(A 4x4, B 4x1, F 4x1) of x' = A x + B delta + F phi_r, x = [beta, r, phi, phi'], at the
    constant speed vx (m/s). ``params``: m, Iz, Ix, lf, lr, hr, Kr, br, Cf, Cr (SI)."""
    n = _numeric()
    a = _args(params, vx)
    return (np.array(n["A"](*a), dtype=float).reshape(4, 4), np.array(n["B"](*a), dtype=float).reshape(4, 1),
            np.array(n["F"](*a), dtype=float).reshape(4, 1))


def lateral_acceleration_row(params: Mapping[str, float], vx: float) -> np.ndarray:
    """Row c with ay = c @ [v, r, phi, phi', delta, phi_r] (m/s^2; v in m/s, not beta)."""
    return np.array(_numeric()["ay"](*_args(params, vx)), dtype=float).reshape(6)


def steady_state(params: Mapping[str, float], vx: float, ay: float) -> tuple[float, np.ndarray]:
    """Steady turn on a flat road (phi_r = 0) at constant vx (m/s) with the lateral acceleration
    ay (m/s^2): (delta rad, x_ss = [beta, r, phi, 0]).

    In a steady state beta' = r' = phi' = phi'' = 0, so (N) gives ay = vx (beta' + r) = vx r:
    r = ay / vx, and rows beta', r', phi'' of x' = A x + B delta = 0 are three linear equations in
    (beta, phi, delta)."""
    A, B, _ = model(params, vx)
    r = ay / vx
    rows = [0, 1, 3]
    Msys = np.column_stack([A[rows, 0], A[rows, 2], B[rows, 0]])
    beta, phi, delta = np.linalg.solve(Msys, -A[rows, 1] * r)
    return float(delta), np.array([beta, r, phi, 0.0])


def simulate(params: Mapping[str, float], vx_of_t: Callable[[float], float], delta_of_t: Callable[[float], float],
             bank_of_t: Callable[[float], float], t_eval, x0=(0.0, 0.0, 0.0, 0.0), max_step: float = np.inf) -> dict:
    """Integrate the exact linear plant with ``scipy.integrate.solve_ivp`` (DOP853, rtol 1e-10,
    atol 1e-12) over t_eval[0] ... t_eval[-1] (s).

    ``vx_of_t``, ``delta_of_t``, ``bank_of_t``: callables of t (s) giving vx (m/s, > 0), delta (rad)
    and phi_r (rad). ``x0`` = [beta, r, phi, phi'] at t_eval[0]. The state integrated is
    [v, r, phi, phi'] (v = vx beta): exact for a time-varying speed too. Returns a dict of arrays
    on t_eval: t, beta, yaw_rate, roll_angle, roll_rate, x (N x 4, [beta, r, phi, phi']),
    y (N x 3 measurements [r, phi, phi']), ay (m/s^2, sum of the tire forces / m), vx, delta,
    bank_angle."""
    t_eval = np.asarray(t_eval, dtype=float)
    n = _numeric()
    pars = [float(params[k]) for k in PARAMETERS]

    def rhs(t, z):
        vx = float(vx_of_t(t))
        M = np.array(n["M"](*pars, G, vx), dtype=float).reshape(3, 6)
        u = np.array([z[0], z[1], z[2], z[3], float(delta_of_t(t)), float(bank_of_t(t))])
        vd, rd, phidd = M @ u
        return [vd, rd, z[3], phidd]

    vx0 = float(vx_of_t(t_eval[0]))
    z0 = [vx0 * x0[0], x0[1], x0[2], x0[3]]
    sol = solve_ivp(rhs, (t_eval[0], t_eval[-1]), z0, method="DOP853", t_eval=t_eval, rtol=1e-10, atol=1e-12,
                    max_step=max_step)
    if not sol.success:
        raise RuntimeError(f"linear plant integration failed: {sol.message}")
    z = sol.y.T
    vx = np.array([float(vx_of_t(t)) for t in t_eval])
    delta = np.array([float(delta_of_t(t)) for t in t_eval])
    bank = np.array([float(bank_of_t(t)) for t in t_eval])
    ay = np.array([lateral_acceleration_row(params, vx[i]) @ np.r_[z[i], delta[i], bank[i]]
                   for i in range(len(t_eval))])
    x = np.column_stack([z[:, 0] / vx, z[:, 1], z[:, 2], z[:, 3]])
    return {"t": t_eval, "beta": x[:, 0], "yaw_rate": x[:, 1], "roll_angle": x[:, 2], "roll_rate": x[:, 3],
            "x": x, "y": x[:, 1:], "ay": ay, "vx": vx, "delta": delta, "bank_angle": bank}


@functools.lru_cache(maxsize=1)
def _relaxed_numeric():
    """numpy function of (parameters..., sigma, g, vx): (A, B, F) of the car with relaxed axle forces.

    The same balances (N), (Y), (R) with the axle forces Fyf, Fyr as states instead of C alpha, each
    relaxed as a tire is, sigma / vx Fy' + Fy = C alpha (first-order lag over the relaxation length
    sigma, m). States [beta, r, phi, phi', Fyf / (m g), Fyr / (m g)] at constant vx."""
    m, Iz, Ix, lf, lr, hr, Kr, br, Cf, Cr, sigma, g, vx = sp.symbols(
        "m I_z I_x l_f l_r h_r K_r b_r C_f C_r sigma g v_x", positive=True)
    beta, r, phi, phid, ff, fr, delta, phir = sp.symbols("beta r phi phidot f_f f_r delta phi_r", real=True)
    vd, rd, phidd = sp.symbols("vdot rdot phiddot", real=True)
    Fyf, Fyr = m * g * ff, m * g * fr                       # the states are per m g
    eq_N = sp.Eq(m * (vd + vx * r - hr * phidd), Fyf + Fyr - m * g * phir)
    eq_Y = sp.Eq(Iz * rd, lf * Fyf - lr * Fyr)
    eq_R = sp.Eq(Ix * phidd, hr * (Fyf + Fyr) + m * g * hr * phi - Kr * phi - br * phid)
    acc = sp.solve([eq_N, eq_Y, eq_R], [vd, rd, phidd], dict=True)[0]
    v = vx * beta
    alpha_f = delta - (v + lf * r) / vx
    alpha_r = -(v - lr * r) / vx
    f = sp.Matrix([acc[vd] / vx, acc[rd], phid, acc[phidd],
                   vx / sigma * (Cf * alpha_f / (m * g) - ff), vx / sigma * (Cr * alpha_r / (m * g) - fr)])
    xs = sp.Matrix([beta, r, phi, phid, ff, fr])
    args = [m, Iz, Ix, lf, lr, hr, Kr, br, Cf, Cr, sigma, g, vx]
    mats = [sp.simplify(f.jacobian(xs)), sp.simplify(f.jacobian(sp.Matrix([delta]))),
            sp.simplify(f.jacobian(sp.Matrix([phir])))]
    return sp.lambdify(args, mats, "numpy")


def relaxed_model(params: Mapping[str, float], vx: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(A 6x6, B 6x1, F 6x1) of the car with relaxed axle forces (``_relaxed_numeric``), x = [beta, r,
    phi, phi', Fyf / (m g), Fyr / (m g)], at the constant speed vx (m/s). ``params``: those of ``model``
    and sigma (m)."""
    if "sigma" not in params:
        raise KeyError("the relaxed linear plant needs parameter sigma")
    A, B, F = _relaxed_numeric()(*_args(params, vx)[:-2], float(params["sigma"]), G, float(vx))
    return (np.array(A, dtype=float).reshape(6, 6), np.array(B, dtype=float).reshape(6, 1),
            np.array(F, dtype=float).reshape(6, 1))
