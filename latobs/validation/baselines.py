"""Simple baseline estimates from the same signals as an observer (the estimate 0, a car's
open-loop linear bicycle, a motorcycle's steady turn), so that a report shows what an observer
adds. Pure numpy/scipy; defined on the documentation's "Results files" page."""
from __future__ import annotations

import math
from typing import Any, Mapping

import numpy as np

G = 9.81            # m/s^2, as latobs.synthesis.params.G
VX_MIN = 1.0        # m/s: below it the bicycle baseline holds its state

#: The baselines in the order reports show them.
BASELINES = ("zero", "bicycle", "steady_turn")
#: Parameters the bicycle baseline needs (SI: kg, kg m^2, m, m, N/rad, N/rad).
BICYCLE_PARAMETERS = ("m", "Iz", "lf", "lr", "Cf", "Cr")
#: The quantities the bicycle baseline outputs (at the centre of gravity).
BICYCLE_OUTPUTS = ("beta", "vy", "yaw_rate", "ay", "Fyf", "Fyr", "alpha_f", "alpha_r")
#: Parameters of Sharp's motorcycle (latobs.synthesis.motorcycle_model) the steady-turn forces need.
STEADY_TURN_PARAMETERS = ("mf", "mr", "a", "an", "b", "e", "f", "epsilon", "Cr1", "Cr2")
#: Quantities of the steady-turn baseline: always / only with STEADY_TURN_PARAMETERS.
STEADY_TURN_OUTPUTS = ("roll_angle", "rider_torque", "steer_rate")
STEADY_TURN_MODEL_OUTPUTS = ("Ff", "Fr", "vy")


class BaselineUnavailable(ValueError):
    """A baseline cannot be computed (a parameter or signal is missing); the message says which."""


# --------------------------------------------------------------------------------------------
# parameters
# --------------------------------------------------------------------------------------------
def parameter_values(vehicle: Mapping[str, Any] | None, names, needed_by: str = "the baseline",
                     source: str | None = None) -> dict[str, float]:
    """{name: value} of ``names`` from a vehicle dict: a design file's ``vehicle`` entry
    (``{"name", "parameters": {name: {"value": v, ...} or v}}``) or a flat {name: value}; only
    from it (never from another parameter set of the same name). ``source``: where the dict
    comes from (a design file), named in the error. Raises :class:`BaselineUnavailable` naming
    every missing or non-finite parameter."""
    if vehicle is None:
        raise BaselineUnavailable(f"{needed_by} needs the vehicle parameters {', '.join(names)}; none were given")
    params = vehicle.get("parameters", vehicle) if isinstance(vehicle, Mapping) else {}
    out, missing = {}, []
    for n in names:
        v = params.get(n)
        if isinstance(v, Mapping):
            v = v.get("value")
        try:
            v = float(v)
        except (TypeError, ValueError):
            v = float("nan")
        if math.isfinite(v):
            out[n] = v
        else:
            missing.append(n)
    if missing:
        who = vehicle.get("name") if isinstance(vehicle, Mapping) else None
        where = (f"the design file {source} does not carry for vehicle {who or '(unnamed)'!s}" if source else
                 f"the vehicle {who or '(unnamed)'!s} parameter set lacks")
        raise BaselineUnavailable(
            f"{needed_by} needs {', '.join(missing)}, which {where} (it has {', '.join(sorted(params)) or 'none'})")
    return out


# --------------------------------------------------------------------------------------------
# zero
# --------------------------------------------------------------------------------------------
def zero(n: int, quantities) -> dict[str, np.ndarray]:
    """The trivial estimate: {quantity: zeros(n)} for every quantity (any unit)."""
    return {q: np.zeros(int(n)) for q in quantities}


# --------------------------------------------------------------------------------------------
# matrix exponential of many small matrices
# --------------------------------------------------------------------------------------------
def expm_batch(M: np.ndarray) -> np.ndarray:
    """expm of each matrix of a stack ``M`` (shape (..., n, n)): scaling and squaring with an
    18-term Taylor series on matrices scaled to 1-norm <= 1/2 (truncation error below 1e-22
    relative, i.e. machine precision). Agrees with scipy.linalg.expm to rounding; about 100 times
    faster than it on a stack of 3x3 matrices."""
    M = np.asarray(M, dtype=float)
    norm = np.abs(M).sum(axis=-2).max(axis=-1)                 # 1-norm per matrix
    with np.errstate(divide="ignore"):
        s = np.where(norm > 0.5, np.ceil(np.log2(np.maximum(norm, 1e-300) / 0.5)), 0.0).astype(int)
    X = M / (2.0 ** s)[..., None, None]
    eye = np.broadcast_to(np.eye(M.shape[-1]), M.shape)
    E = eye.copy()
    term = eye.copy()
    for k in range(1, 19):
        term = term @ X / k
        E = E + term
    for j in range(int(s.max()) if s.size else 0):
        sq = s > j
        E[sq] = E[sq] @ E[sq]
    return E


# --------------------------------------------------------------------------------------------
# the linear bicycle
# --------------------------------------------------------------------------------------------
def bicycle_matrices(params: Mapping[str, float], vx) -> tuple[np.ndarray, np.ndarray]:
    """(A, B) of the linear single-track model (module docstring) at speed(s) ``vx`` (m/s, > 0):
    A of shape (len(vx), 2, 2) in [1/s, m/s^2 per (m/s) ...], B of shape (2,) = [Cf/m (m/s^2/rad),
    lf Cf/Iz (1/s^2/rad)]."""
    m, Iz, lf, lr, Cf, Cr = (float(params[k]) for k in BICYCLE_PARAMETERS)
    v = np.atleast_1d(np.asarray(vx, dtype=float))
    A = np.empty((v.size, 2, 2))
    A[:, 0, 0] = -(Cf + Cr) / (m * v)
    A[:, 0, 1] = -v - (lf * Cf - lr * Cr) / (m * v)
    A[:, 1, 0] = -(lf * Cf - lr * Cr) / (Iz * v)
    A[:, 1, 1] = -(lf * lf * Cf + lr * lr * Cr) / (Iz * v)
    return A, np.array([Cf / m, lf * Cf / Iz])


def bicycle_steady_state(params: Mapping[str, float], delta: float, vx: float) -> np.ndarray:
    """[vy, r] (m/s, rad/s) of the linear single-track model at constant delta (rad), vx (m/s):
    x = -A^-1 B delta."""
    A, B = bicycle_matrices(params, [vx])
    return -np.linalg.solve(A[0], B * float(delta))


def bicycle(time, delta, vx, params: Mapping[str, float], vx_min: float = VX_MIN,
            initial: str | tuple[float, float] = "rest") -> dict[str, np.ndarray]:
    """Open-loop linear single-track (bicycle) model driven by ``delta`` (rad) and ``vx`` (m/s)
    sampled at ``time`` (s), integrated exactly with the inputs held over each step (module
    docstring; Rajamani eq. 2.31). ``params``: m (kg), Iz (kg m^2), lf, lr (m), Cf, Cr (N/rad per
    axle). ``initial``: "rest" (vy = r = 0), "steady" (the steady state of delta_0, vx_0; rest if
    vx_0 < vx_min) or a pair (vy0 m/s, r0 rad/s). No measurement feeds back.

    Returns arrays of the sample times' values: vy (m/s), beta = vy/vx (rad), yaw_rate (rad/s),
    ay = (Fyf + Fyr)/m (m/s^2), Fyf, Fyr (N), alpha_f, alpha_r (rad); at samples with
    vx < vx_min the state is held and the outputs use vx_min.
    """
    p = {k: float(params[k]) for k in BICYCLE_PARAMETERS}
    t = np.asarray(time, dtype=float)
    d = np.asarray(delta, dtype=float)
    v = np.asarray(vx, dtype=float)
    n = t.size
    if d.shape != t.shape or v.shape != t.shape:
        raise ValueError(f"time, delta and vx must have the same shape, got {t.shape}, {d.shape}, {v.shape}")
    if not (np.all(np.isfinite(d)) and np.all(np.isfinite(v)) and np.all(np.isfinite(t))):
        raise ValueError("time, delta and vx must be finite")
    if vx_min <= 0:
        raise ValueError(f"vx_min must be > 0 m/s, got {vx_min}")
    ve = np.maximum(v, vx_min)                       # the speed the outputs (and held steps) use
    if isinstance(initial, str):
        if initial == "rest":
            x0 = (0.0, 0.0)
        elif initial == "steady":
            x0 = tuple(bicycle_steady_state(p, d[0], v[0])) if n and v[0] >= vx_min else (0.0, 0.0)
        else:
            raise ValueError(f"initial must be 'rest', 'steady' or (vy0, r0), got {initial!r}")
    else:
        x0 = tuple(float(x) for x in initial)
    x = np.empty((n, 2))
    if n:
        x[0] = x0
    if n > 1:
        h = np.diff(t)
        moving = v[:-1] >= vx_min
        A, B = bicycle_matrices(p, ve[:-1])
        M = np.zeros((n - 1, 3, 3))
        M[:, :2, :2] = A * h[:, None, None]
        M[:, :2, 2] = B[None, :] * h[:, None]
        E = expm_batch(M[moving]) if np.any(moving) else np.zeros((0, 3, 3))
        Phi = np.broadcast_to(np.eye(3), (n - 1, 3, 3)).copy()   # held: x_k+1 = x_k
        Phi[moving] = E
        # recursion on Python floats (fast for long records)
        p00, p01, p10, p11 = (Phi[:, i, j].tolist() for i, j in ((0, 0), (0, 1), (1, 0), (1, 1)))
        g0 = (Phi[:, 0, 2] * d[:-1]).tolist()
        g1 = (Phi[:, 1, 2] * d[:-1]).tolist()
        vy, r = x0
        out_vy, out_r = [vy], [r]
        for k in range(n - 1):
            vy, r = p00[k] * vy + p01[k] * r + g0[k], p10[k] * vy + p11[k] * r + g1[k]
            out_vy.append(vy)
            out_r.append(r)
        x[:, 0], x[:, 1] = out_vy, out_r
    vy, r = x[:, 0], x[:, 1]
    af = d - (vy + p["lf"] * r) / ve
    ar = -(vy - p["lr"] * r) / ve
    Fyf, Fyr = p["Cf"] * af, p["Cr"] * ar
    return {"vy": vy, "beta": vy / ve, "yaw_rate": r, "ay": (Fyf + Fyr) / p["m"], "Fyf": Fyf, "Fyr": Fyr,
            "alpha_f": af, "alpha_r": ar}


# --------------------------------------------------------------------------------------------
# the motorcycle's steady turn
# --------------------------------------------------------------------------------------------
def steady_turn(vx, yaw_rate, params: Mapping[str, float] | None = None, g: float = G) -> dict[str, np.ndarray]:
    """Steady-turn estimates of a motorcycle (paper 003; Sharp's SAE axes: y right, z down; roll,
    yaw rate, forces > 0 to the right) from the measured speed ``vx`` (m/s) and yaw rate (rad/s):

    * roll_angle = atan(vx r / g) (rad): the lean that balances the centripetal acceleration
      vx r against gravity g = 9.81 m/s^2 (thin wheels, no gyroscopic terms);
    * rider_torque = 0 (N m), steer_rate = 0 (rad/s): nothing changes in a steady turn;
    * with ``params`` (Sharp's mf, mr (kg), a, an, b, e, f (m), epsilon (rad), Cr1, Cr2 (N/rad);
      latobs.synthesis.motorcycle_model's notation) also the tyre side forces and the lateral
      velocity of the linear model in the steady turn (r' = vy' = 0, the lateral and yaw
      equations of paper 003 eq. (1)):  Ff + Fr = M vx r,  lf Ff - lr Fr = mf k vx r, so
      Ff = (lr M + mf k) vx r / (lf + lr) and Fr = (lf M - mf k) vx r / (lf + lr) (N), with
      M = mf + mr, k = (a + e) cos(eps) + f sin(eps), lf = (a - an)/cos(eps), lr = b; and the rear
      tyre's linear law Fr = Cr1 alpha_r + Cr2 phi with alpha_r = -(vy - lr r)/vx gives
      vy = lr r - vx (Fr - Cr2 phi) / Cr1 (m/s, at the ground point below the rear-frame CG).
    """
    v = np.asarray(vx, dtype=float)
    r = np.asarray(yaw_rate, dtype=float)
    phi = np.arctan(v * r / g)
    out = {"roll_angle": phi, "rider_torque": np.zeros_like(phi), "steer_rate": np.zeros_like(phi)}
    if params is not None:
        p = {k: float(params[k]) for k in STEADY_TURN_PARAMETERS}
        M = p["mf"] + p["mr"]
        eps = p["epsilon"]
        k = (p["a"] + p["e"]) * math.cos(eps) + p["f"] * math.sin(eps)
        lf = (p["a"] - p["an"]) / math.cos(eps)
        lr = p["b"]
        c = v * r / (lf + lr)
        out["Ff"] = (lr * M + p["mf"] * k) * c
        out["Fr"] = (lf * M - p["mf"] * k) * c
        out["vy"] = lr * r - v * (out["Fr"] - p["Cr2"] * phi) / p["Cr1"]
    return out
