"""Baseline: the linear bicycle-model Kalman filter of the MBDS dataset's authors (design time).

The sideslip estimator of Leanza, Reina, Blanco-Claraco (Sensors 2021), repository
MBDS/sideslip-angle-vehicle-estimation, ``estimators/matlab_kf`` (a Kalman filter of the linear
single-track model measuring ay and the yaw rate), re-derived here with states [vy, r] at the CG
(the authors use [beta, r]; at a given speed vy = vx beta, the same model):

    vy' = -(Cf + Cr)/(m vx) vy - ((lf Cf - lr Cr)/(m vx) + vx) r + Cf/m delta
    r'  = -(lf Cf - lr Cr)/(Iz vx) vy - (lf^2 Cf + lr^2 Cr)/(Iz vx) r + lf Cf/Iz delta
    ay  = (Fyf + Fyr)/m = -(Cf + Cr)/(m vx) vy - (lf Cf - lr Cr)/(m vx) r + Cf/m delta

(linear tires Fyf = Cf (delta - (vy + lf r)/vx), Fyr = Cr (-(vy - lr r)/vx); ay = vy' + vx r),
measurements y = [ay, r] = C(vx) x + D delta.

Discrete filter, at each sample k with the measured speed vx_k (speed-varying model):
    * model at v_k = max(vx_k, vx_min) (``vx_min`` = 1 m/s: a documented clamp, the model has 1/vx);
    * update with y_k: S = C P C' + R, K = P C' S^-1, x += K (y_k - C x - D delta_k),
      P = (I - K C) P, symmetrised (P + P')/2;
    * predict to k+1, delta_k held over h_k = t_{k+1} - t_k (exact zero-order hold, Van Loan:
      [[Phi, Gam], [0, 1]] = expm(h [[A, B], [0, 0]]); the authors use forward Euler):
      x = Phi x + Gam delta_k, P = Phi P Phi' + Q h_k (Q the continuous-time process-noise
      intensity on [vy', r'], discretised to first order).
  ``estimate="filtered"`` returns x_{k|k} (uses y_k: the authors' convention, the figures below);
  ``estimate="predicted"`` returns x_{k|k-1} (uses data up to k-1: what the FMU runtime
  ``fmu_src/kalman_observer.py`` outputs at t_k, stepping from t_{k-1} with row k-1's inputs).
  beta^ = atan(vy^ / v_k) (filtered) or atan(vy^ / v_{k-1}) (predicted). Start: x_{0|-1} = [0, r_0], P = P0.

Tuning (``tune``): Q = diag(q_vy, q_r), R = diag(r_ay, r_r); the estimate depends only on the
ratios Q/R, so r_r is fixed and (q_vy, q_r, r_ay) are searched on a log grid, on t < 425 s of
the MBDS record only (its held-out part t >= 425 s is only evaluated). See ``TUNED`` and
``report`` for the figures.
"""
from __future__ import annotations

import itertools
from typing import Mapping

import numpy as np
import scipy.linalg

VEHICLE_KEYS = ("m", "lf", "lr", "Iz", "Cf", "Cr")
VX_MIN = 1.0                    # m/s, the model's speed is clamped to >= VX_MIN
P0 = (1.0, 0.01)                # initial covariance diag: vy (m/s)^2, r (rad/s)^2
SPLIT = 425.0                   # s, the MBDS record's held-out split

#: Covariances tuned by ``tune()`` on t < 425 s of the MBDS record (filtered estimate);
#: q: continuous process-noise intensities on vy' ((m/s^2)^2 s) and r' ((rad/s^2)^2 s),
#: r_meas: measurement variances of ay ((m/s^2)^2) and r ((rad/s)^2).
#: Tuned for the "predicted" estimate (the runtime's output) on the default grid of ``tune``.
TUNED = {"q": (0.1, 1e-4), "r_meas": (10.0, 1e-4)}


def vehicle_dict(vehicle) -> dict[str, float]:
    """{m, lf, lr, Iz, Cf, Cr} from a mapping or a ``synthesis.params.Vehicle``."""
    if isinstance(vehicle, Mapping):
        return {k: float(vehicle[k]) for k in VEHICLE_KEYS}
    return {k: float(vehicle.value(k)) for k in VEHICLE_KEYS}


def model(vals: Mapping, vx):
    """(A, B, C, D) of the bicycle model at speed(s) vx (array: stacked along the first axis)."""
    m, lf, lr, Iz, Cf, Cr = (float(vals[k]) for k in VEHICLE_KEYS)
    v = np.atleast_1d(np.asarray(vx, dtype=float))
    n = v.size
    A = np.empty((n, 2, 2))
    A[:, 0, 0] = -(Cf + Cr) / (m * v)
    A[:, 0, 1] = -(lf * Cf - lr * Cr) / (m * v) - v
    A[:, 1, 0] = -(lf * Cf - lr * Cr) / (Iz * v)
    A[:, 1, 1] = -(lf**2 * Cf + lr**2 * Cr) / (Iz * v)
    B = np.broadcast_to(np.array([Cf / m, lf * Cf / Iz]), (n, 2)).copy()
    C = np.empty((n, 2, 2))
    C[:, 0, :] = A[:, 0, :]
    C[:, 0, 1] += v                     # ay = vy' + vx r
    C[:, 1, :] = (0.0, 1.0)
    D = np.broadcast_to(np.array([Cf / m, 0.0]), (n, 2)).copy()
    return A, B, C, D


def discretise(vals: Mapping, vx, h):
    """(Phi, Gam, C, D) stacked per sample: exact ZOH of the model at vx over h (Van Loan)."""
    A, B, C, D = model(vals, vx)
    h = np.broadcast_to(np.asarray(h, dtype=float), (A.shape[0],))
    M = np.zeros((A.shape[0], 3, 3))
    M[:, :2, :2] = A * h[:, None, None]
    M[:, :2, 2] = B * h[:, None]
    E = scipy.linalg.expm(M)                  # stacked (n, 3, 3): Van Loan's block exponential
    return E[:, :2, :2], E[:, :2, 2], C, D


def _mat2(x, name):
    a = np.asarray(x, dtype=float)
    if a.shape == (2,):
        a = np.diag(a)
    if a.shape != (2, 2) or not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be 2 variances or a finite 2x2 matrix, got {x!r}")
    return a


def run_kalman(data_columns: Mapping, vehicle_values: Mapping, q, r_meas, *, p0=P0, vx_min=VX_MIN,
               estimate: str = "filtered", return_states: bool = False, _disc=None):
    """beta^ (rad, one per row) of the Kalman filter (module docstring) on recorded columns.

    data_columns: {t, delta, vx, yaw_rate, ay} arrays (SI, rad); vehicle_values: {m, lf, lr, Iz,
    Cf, Cr}; q: continuous process-noise intensity on [vy', r'] (2 values or 2x2); r_meas:
    measurement covariance on [ay, r] (2 values or 2x2); p0: initial covariance (2 or 2x2).
    ``estimate``: "filtered" (x_{k|k}) or "predicted" (x_{k|k-1}). With ``return_states``, also
    the (N, 2) array of [vy^, r^]."""
    if estimate not in ("filtered", "predicted"):
        raise ValueError(f"estimate must be 'filtered' or 'predicted', got {estimate!r}")
    t = np.asarray(data_columns["t"], dtype=float)
    delta = np.asarray(data_columns["delta"], dtype=float)
    vx = np.asarray(data_columns["vx"], dtype=float)
    ay = np.asarray(data_columns["ay"], dtype=float)
    r = np.asarray(data_columns["yaw_rate"], dtype=float)
    N = t.size
    Q, R, P = _mat2(q, "q"), _mat2(r_meas, "r_meas"), _mat2(p0, "p0")
    v = np.maximum(vx, vx_min)
    h = np.diff(t, append=t[-1] + (t[-1] - t[-2] if N > 1 else 0.01))
    Phi, Gam, C, D = _disc if _disc is not None else discretise(vehicle_values, v, h)
    # Plain numpy matrices, deliberately NOT the hand-expanded 2x2 algebra of the FMU runtime
    # (fmu_src/kalman_observer.py): tests/test_baselines_002.py holds the two formulations equal.
    x = np.array([0.0, float(r[0])])
    I2 = np.eye(2)
    filtered = estimate == "filtered"
    rows = np.empty((N, 2))
    for k in range(N):
        if not filtered:
            rows[k] = x
        Ck = C[k]                                    # update with y_k = [ay_k, r_k]
        S = Ck @ P @ Ck.T + R
        K = np.linalg.solve(S.T, Ck @ P.T).T         # P C' S^-1
        x = x + K @ (np.array([ay[k], r[k]]) - Ck @ x - D[k] * delta[k])
        P = (I2 - K @ Ck) @ P
        P = 0.5 * (P + P.T)
        if filtered:
            rows[k] = x
        x = Phi[k] @ x + Gam[k] * delta[k]           # predict to k+1 with delta_k held
        P = Phi[k] @ P @ Phi[k].T + Q * h[k]
        P = 0.5 * (P + P.T)
    out = rows
    # the predicted x_{k|k-1} is converted with the speed of the step it was predicted over
    # (v_{k-1}, v_0 at k = 0): all the runtime knows at the end of that step
    vconv = v if filtered else np.concatenate([v[:1], v[:-1]])
    beta = np.arctan(out[:, 0] / vconv)
    return (beta, out) if return_states else beta


def rms_deg(err) -> float:
    return float(np.degrees(np.sqrt(np.mean(np.square(err)))))


def split_rms(cols: Mapping, beta_hat, split: float = SPLIT) -> dict[str, float]:
    """beta RMS error (deg) on t < split, t >= split and the whole record."""
    t, beta = np.asarray(cols["t"]), np.asarray(cols["beta"])
    e = np.asarray(beta_hat) - beta
    return {"before_split": rms_deg(e[t < split]), "after_split": rms_deg(e[t >= split]), "all": rms_deg(e)}


def tune(cols: Mapping, vehicle_values: Mapping, split: float = SPLIT, r_r: float = 1e-4,
         q_vy=None, q_r=None, r_ay=None, estimate: str = "filtered"):
    """Grid search of (q_vy, q_r, r_ay) minimising the beta RMS on t < split ONLY (the rows
    t >= split are not even passed to the filter). Returns (best q, best r_meas, rms deg, table)."""
    t = np.asarray(cols["t"])
    train = {k: np.asarray(v)[t < split] for k, v in cols.items()}
    q_vy = np.logspace(-3, 2, 6) if q_vy is None else q_vy
    q_r = np.logspace(-5, 0, 6) if q_r is None else q_r
    r_ay = np.logspace(-2, 2, 5) if r_ay is None else r_ay
    table = []
    v = np.maximum(train["vx"], VX_MIN)
    disc = discretise(vehicle_values, v, np.diff(train["t"], append=2 * train["t"][-1] - train["t"][-2]))
    for a, b, c in itertools.product(q_vy, q_r, r_ay):
        bh = run_kalman(train, vehicle_values, (a, b), (c, r_r), estimate=estimate, _disc=disc)
        table.append(((float(a), float(b)), (float(c), r_r), rms_deg(bh - train["beta"])))
    best = min(table, key=lambda row: row[2])
    return best[0], best[1], best[2], table


def to_data_dict(vehicle_values: Mapping, q, r_meas, p0=P0, vx_min: float = VX_MIN) -> dict:
    """The data file of the runtime ``fmu_src/kalman_observer.py``."""
    return {"kind": "kalman_baseline",
            "vehicle": vehicle_dict(vehicle_values),
            "noise": {"q": _mat2(q, "q").tolist(), "r": _mat2(r_meas, "r_meas").tolist()},
            "initial": {"P0": _mat2(p0, "p0").tolist()},
            "runtime": {"vx_min": float(vx_min)}}


def report(estimate: str = "filtered") -> dict:
    """Tune on the MBDS record's t < 425 s and score on both parts (prints and returns figures)."""
    from latobs.validation.replay import MBDS_CSV, load_csv
    from .params import load_vehicle

    cols = load_csv(MBDS_CSV)
    vals = vehicle_dict(load_vehicle("mbds_250lm"))
    q, rm, best, _ = tune(cols, vals, estimate=estimate)
    out = {"q": q, "r_meas": rm, "tuning_rms_deg": best}
    for est in ("filtered", "predicted"):
        out[est] = split_rms(cols, run_kalman(cols, vals, q, rm, estimate=est))
    return out


if __name__ == "__main__":     # python -m latobs.synthesis.kalman_baseline
    print(report())
