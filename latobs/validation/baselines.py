"""Simple baseline estimates from the same signals as an observer (the estimate 0, a car's
open-loop linear bicycle, a motorcycle's steady turn, and on a record with a tuning part a ridge
regression on causally filtered signals), so that a report shows what an observer adds. Pure
numpy/scipy; defined on the documentation's "Results files" page."""
from __future__ import annotations

import hashlib
import math
import threading
from typing import Any, Mapping

import numpy as np

G = 9.81            # m/s^2, as latobs.synthesis.params.G
VX_MIN = 1.0        # m/s: below it the bicycle baseline holds its state

#: The baselines in the order reports show them.
BASELINES = ("zero", "bicycle", "steady_turn", "regression")
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
# the exact zero-order hold of many small systems
# --------------------------------------------------------------------------------------------
def _taylor_terms(theta: float) -> int:
    """The fewest Taylor terms K (at most 18) of exp(X), ||X||_1 <= theta <= 1/2, whose remainder
    bound 2 theta^(K+1) / (K+1)! is below 1e-22 (relative error below 1e-22 / exp(-1/2): machine
    precision)."""
    bound = theta                     # theta^k / k!: the remainder bound after K = k - 1 terms, halved
    for k in range(1, 19):
        if 2.0 * bound <= 1e-22:
            return k - 1
        bound *= theta / (k + 1)
    return 18


def zoh_2x2(A: np.ndarray, B: np.ndarray, h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(exp(A_k h_k), int_0^h_k exp(A_k s) ds B) of a stack of 2x2 matrices ``A`` (shape (m, 2, 2)),
    an input vector ``B`` (shape (2,) or (m, 2)) and steps ``h`` (shape (m,)): the top blocks of
    exp([[A, B], [0, 0]] h): a Taylor series of :func:`_taylor_terms` terms after one scaling of
    the whole stack to 1-norm <= 1/2, then squaring; written out elementwise (2x2 products on
    arrays: several times faster than a stacked matmul). Agrees with scipy.linalg.expm to rounding."""
    h = np.asarray(h, dtype=float)
    X = np.asarray(A, dtype=float) * h[:, None, None]
    y = np.broadcast_to(np.asarray(B, dtype=float), (h.size, 2)) * h[:, None]
    x00, x01, x10, x11 = X[:, 0, 0], X[:, 0, 1], X[:, 1, 0], X[:, 1, 1]
    y0, y1 = y[:, 0], y[:, 1]
    norm = np.maximum(np.maximum(np.abs(x00) + np.abs(x10), np.abs(x01) + np.abs(x11)), np.abs(y0) + np.abs(y1))
    # one scaling 2^-s for the whole stack (its largest norm): no indexing in the squarings
    top = float(np.max(norm)) if norm.size else 0.0
    s = int(math.ceil(math.log2(top / 0.5))) if top > 0.5 else 0
    sc = 2.0 ** -s
    x00, x01, x10, x11, y0, y1 = (a * sc for a in (x00, x01, x10, x11, y0, y1))
    theta = top * sc
    one, zero = np.ones(h.size), np.zeros(h.size)
    e00, e01, e10, e11, f0, f1 = one.copy(), zero.copy(), zero.copy(), one.copy(), zero.copy(), zero.copy()
    t00, t01, t10, t11 = one, zero, zero, one           # the term X^k / k! (its last column: u)
    for k in range(1, _taylor_terms(theta) + 1):
        u0, u1 = (t00 * y0 + t01 * y1) / k, (t10 * y0 + t11 * y1) / k
        t00, t01, t10, t11 = ((t00 * x00 + t01 * x10) / k, (t00 * x01 + t01 * x11) / k,
                              (t10 * x00 + t11 * x10) / k, (t10 * x01 + t11 * x11) / k)
        e00, e01, e10, e11, f0, f1 = e00 + t00, e01 + t01, e10 + t10, e11 + t11, f0 + u0, f1 + u1
    for _ in range(s):                                  # [[E, f], [0, 1]]^2 = [[E E, E f + f], [0, 1]]
        a, b, c, d = e00, e01, e10, e11
        e00, e01, e10, e11 = a * a + b * c, a * b + b * d, c * a + d * c, c * b + d * d
        f0, f1 = a * f0 + b * f1 + f0, c * f0 + d * f1 + f1
    return np.stack([np.stack([e00, e01], -1), np.stack([e10, e11], -1)], -2), np.stack([f0, f1], -1)


def affine_scan(Phi: np.ndarray, g: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(P_k, q_k) with x_(k+1) = P_k x_0 + q_k for the recursion x_(k+1) = Phi_k x_k + g_k
    (``Phi`` shape (m, 2, 2), ``g`` (m, 2)): an inclusive prefix scan of the affine maps
    (Hillis-Steele: log2(m) rounds of elementwise array operations instead of m Python steps)."""
    p00, p01, p10, p11 = (np.array(Phi[:, i, j], dtype=float) for i, j in ((0, 0), (0, 1), (1, 0), (1, 1)))
    q0, q1 = np.array(g[:, 0], dtype=float), np.array(g[:, 1], dtype=float)
    off, m = 1, p00.size
    while off < m:
        # map k after map k - off: (P_k P_(k-off), P_k q_(k-off) + q_k); the right sides are new arrays
        a, b, c, d = p00[off:], p01[off:], p10[off:], p11[off:]
        e, f, g_, h = p00[:-off], p01[:-off], p10[:-off], p11[:-off]
        r0, r1 = q0[:-off], q1[:-off]
        n0, n1 = a * r0 + b * r1 + q0[off:], c * r0 + d * r1 + q1[off:]
        n00, n01, n10, n11 = a * e + b * g_, a * f + b * h, c * e + d * g_, c * f + d * h
        q0[off:], q1[off:] = n0, n1
        p00[off:], p01[off:], p10[off:], p11[off:] = n00, n01, n10, n11
        off *= 2
    return np.stack([np.stack([p00, p01], -1), np.stack([p10, p11], -1)], -2), np.stack([q0, q1], -1)


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
    if d.shape != t.shape or v.shape != t.shape:
        raise ValueError(f"time, delta and vx must have the same shape, got {t.shape}, {d.shape}, {v.shape}")
    if not (np.all(np.isfinite(d)) and np.all(np.isfinite(v)) and np.all(np.isfinite(t))):
        raise ValueError("time, delta and vx must be finite")
    if vx_min <= 0:
        raise ValueError(f"vx_min must be > 0 m/s, got {vx_min}")
    key = (tuple(p.values()), float(vx_min), initial if isinstance(initial, str) else tuple(map(float, initial)),
           hashlib.blake2b(t.tobytes() + d.tobytes() + v.tobytes(), digest_size=16).digest())
    with _MEMO_LOCK:
        hit = _BICYCLE_MEMO.get(key)
    if hit is None:
        hit = _bicycle(t, d, v, p, vx_min, initial)
        with _MEMO_LOCK:
            if len(_BICYCLE_MEMO) >= 8:
                _BICYCLE_MEMO.pop(next(iter(_BICYCLE_MEMO)))
            _BICYCLE_MEMO[key] = hit
    return {k: a.copy() for k, a in hit.items()}


#: the last few bicycle runs by their inputs' content: the observers of one co-simulation share them
_BICYCLE_MEMO: dict = {}
_MEMO_LOCK = threading.Lock()


def _bicycle(t, d, v, p, vx_min, initial) -> dict[str, np.ndarray]:
    n = t.size
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
        moving = v[:-1] >= vx_min
        A, B = bicycle_matrices(p, ve[:-1])
        Phi, gam = zoh_2x2(A, B, np.diff(t))
        Phi[~moving] = np.eye(2)                     # held: x_k+1 = x_k
        gam[~moving] = 0.0
        P, q = affine_scan(Phi, gam * d[:-1, None])
        x[1:] = P @ np.asarray(x0, dtype=float) + q
        # a held step repeats the sample before it exactly (the scan's products round otherwise)
        src = np.arange(n)
        src[1:][~moving] = 0
        x = x[np.maximum.accumulate(src)]
    vy, r = x[:, 0], x[:, 1]
    af = d - (vy + p["lf"] * r) / ve
    ar = -(vy - p["lr"] * r) / ve
    Fyf, Fyr = p["Cf"] * af, p["Cr"] * ar
    return {"vy": vy, "beta": vy / ve, "yaw_rate": r, "ay": (Fyf + Fyr) / p["m"], "Fyf": Fyf, "Fyr": Fyr,
            "alpha_f": af, "alpha_r": ar}


# --------------------------------------------------------------------------------------------
# a regularised linear regression on causally filtered signals (fitted on a record's tuning part)
# --------------------------------------------------------------------------------------------
#: the sensor columns the regression reads (never a reference column)
REGRESSION_SIGNALS = ("delta", "yaw_rate", "ay", "vx")
#: time constants (s) of the causal first-order low-pass filters applied to every feature (0: raw)
REGRESSION_TAUS_S = (0.0, 0.05, 0.2, 0.5, 2.0)
#: ridge penalties tried (on standardised features), chosen by blocked cross-validation
REGRESSION_ALPHAS = tuple(10.0 ** k for k in np.arange(-4.0, 4.01, 0.5))
REGRESSION_FOLDS = 5
VX_FLOOR = 1.0      # m/s: the speed divisions of the regression's features use max(vx, VX_FLOOR)


def regression_features(signals: Mapping[str, np.ndarray], dt: float) -> tuple[list[str], np.ndarray]:
    """(names, X): the features of :func:`regression` from the sensor columns ``signals`` (delta
    rad, yaw_rate rad/s, ay m/s^2, vx m/s; SI): the signals, the products and quotients of the
    bicycle model's steady and kinematic relations (r vx, r / vx, delta vx, delta / vx, ay / vx,
    ay - r vx, 1 / vx), each also through causal first-order low-pass filters of time constants
    :data:`REGRESSION_TAUS_S` (started at the first sample; past samples only). Shape (n, k)."""
    from scipy.signal import lfilter

    miss = [c for c in REGRESSION_SIGNALS if c not in signals]
    if miss:
        raise BaselineUnavailable(f"no column {', '.join(repr(m) for m in miss)} to drive the regression")
    d, r, ay, vx = (np.asarray(signals[c], dtype=float) for c in REGRESSION_SIGNALS)
    ve = np.maximum(vx, VX_FLOOR)
    base = {"delta": d, "yaw_rate": r, "ay": ay, "vx": vx, "yaw_rate*vx": r * vx, "yaw_rate/vx": r / ve,
            "delta*vx": d * vx, "delta/vx": d / ve, "ay/vx": ay / ve, "ay-yaw_rate*vx": ay - r * vx, "1/vx": 1.0 / ve}
    names, cols = [], []
    for tau in REGRESSION_TAUS_S:
        a = 1.0 if tau == 0.0 else -math.expm1(-dt / tau)
        for n, x in base.items():
            if tau == 0.0:
                y = x
            else:
                y, _ = lfilter([a], [1.0, a - 1.0], x, zi=[(1.0 - a) * x[0]] if x.size else [0.0])
            names.append(n if tau == 0.0 else f"lowpass({n}, {tau:g} s)")
            cols.append(y)
    return names, np.column_stack(cols) if cols else np.zeros((0, 0))


def ridge_fit(X: np.ndarray, y: np.ndarray, alphas=REGRESSION_ALPHAS, folds: int = REGRESSION_FOLDS):
    """Ridge regression y ~ X w + b on standardised columns, the penalty chosen among ``alphas`` by
    the least RMS over ``folds`` contiguous blocks of the samples (each left out in turn: a time
    series is not shuffled). Returns (w, b, alpha, cv_rms) with w for the unstandardised X.

    The normal equations of every training set come from per-block moments (X centred on its
    overall mean first, against cancellation): one pass over the data, then a small solve per
    fold and penalty."""
    X = np.asarray(X, dtype=float)
    y = np.asarray(y, dtype=float)
    n, k = X.shape
    if n < 10 * (k + 1):
        raise BaselineUnavailable(f"the regression needs at least {10 * (k + 1)} tuning samples, got {n}")
    shift, yshift = X.mean(axis=0), float(y.mean())
    Xc, yc = X - shift, y - yshift
    edges = np.linspace(0, n, folds + 1).astype(int)
    blocks = [slice(edges[i], edges[i + 1]) for i in range(folds)]
    moments = [(Xc[b].T @ Xc[b], Xc[b].sum(axis=0), Xc[b].T @ yc[b], float(yc[b].sum()), b.stop - b.start)
               for b in blocks]

    def normal(parts):
        """(Z'Z, Z'(y - ym), mu, sd, ym) of the union of the blocks ``parts`` (Z: standardised)."""
        XtX = sum(m[0] for m in parts)
        sx = sum(m[1] for m in parts)
        Xty = sum(m[2] for m in parts)
        sy = sum(m[3] for m in parts)
        nt = sum(m[4] for m in parts)
        mu, ym = sx / nt, sy / nt
        C = XtX - nt * np.outer(mu, mu)
        sd = np.sqrt(np.maximum(np.diag(C) / nt, 0.0))
        sd = np.where(sd > 0, sd, 1.0)
        return C / np.outer(sd, sd), (Xty - mu * sy) / sd, mu, sd, ym, nt

    def solve(eq, alpha):
        ZtZ, Zty, mu, sd, ym, nt = eq
        w = np.linalg.solve(ZtZ + alpha * nt * np.eye(k), Zty) / sd
        return w, ym - mu @ w                # in the centred coordinates

    trains = [normal([m for j, m in enumerate(moments) if j != i]) for i in range(folds)]
    best = None
    for alpha in alphas:
        se = 0.0
        for i, b in enumerate(blocks):
            w, c = solve(trains[i], alpha)
            se += float(np.sum((Xc[b] @ w + c - yc[b]) ** 2))
        cv = math.sqrt(se / n)
        if best is None or cv < best[1]:
            best = (alpha, cv)
    w, c = solve(normal(moments), best[0])
    return w, float(c + yshift - shift @ w), float(best[0]), best[1]


def regression(time, signals: Mapping[str, np.ndarray], truth, train) -> tuple[np.ndarray, dict[str, Any]]:
    """The estimate of a data scientist's afternoon: a ridge regression of ``truth`` (any unit) on
    :func:`regression_features` of the sensor columns, fitted on the samples ``train`` (a boolean
    mask: the record's tuning part) only, evaluated on every sample (causal: each estimate uses
    past and present samples only). Returns (estimate, about)."""
    t = np.asarray(time, dtype=float)
    if t.size < 2:
        raise BaselineUnavailable("the regression needs at least two samples")
    dt = float(np.median(np.diff(t)))
    names, X = regression_features(signals, dt)
    y = np.asarray(truth, dtype=float)
    train = np.asarray(train, dtype=bool) & np.isfinite(y) & np.all(np.isfinite(X), axis=1)
    w, b, alpha, cv = ridge_fit(X[train], y[train])
    return X @ w + b, {"features": len(names), "filters_s": list(REGRESSION_TAUS_S), "alpha": alpha,
                       "cv_rms": cv, "fitted_on_samples": int(np.sum(train))}


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
