"""Identify a car's cornering stiffnesses (and yaw inertia) from a recorded drive (``latobs identify``).

The model is paper 001's design model, the single-track (bicycle) model with first-order tire
relaxation (``synthesis.relaxation_model``, eq. 9: states vy, r at the CG, ay = sum Fy / m and the
yaw acceleration; input the road-wheel angle delta; the relaxation length sigma from the base
vehicle), or, for a base vehicle without sigma, the bicycle model of paper 002's Kalman peer
(``synthesis.sideslip_kalman_filter.model``). It is discretised exactly per sample at the recorded
speed (zero-order hold). The front and rear axle stiffnesses Cf, Cr are the output-error
least-squares fit (``scipy.optimize.least_squares``) of the simulated yaw rate and lateral
acceleration, and of the sideslip when the record has a reference ``beta``, to the record's tuning
part (t < tune_until); each signal's residual is divided by the signal's spread, and the unknowns
are the scale factors of the base vehicle's values (numbers near 1). The yaw inertia Iz is a third
unknown, kept when the record's transients reveal it (:data:`IZ_MAX_SPREAD`), else the base
vehicle's with the reason recorded.

Uncertainty: a moving-block bootstrap over segments of the tuning part, linearised at the fit
(one Gauss-Newton step per resample from the segments' Jacobians and residuals: the spread that
re-fitting each resample would show, without simulating again). The 2.5 and 97.5 percentiles are
the interval written to the vehicle file's ``[ranges]``: the stiffness box of papers 001 and 002.

The sensors' measurement-error bounds (:func:`measurement_error_bounds`: paper 001's interval
observer needs them) come from each sensor's residual about its zero-phase low-pass.

What the record cannot reveal is taken from the base vehicle and marked so: mass, geometry,
relaxation length, roll (latobs's records carry no roll signals); the steering ratio needs a
steering-wheel angle, which latobs's records do not carry (``delta`` is the road-wheel angle).
"""
from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, field
from typing import Callable, Mapping

import numpy as np

from ..data.checks import unit_findings, uniform_step
from .lateral_interval_observer import ERROR_BOUND_PARAMETERS
from .params import G, Vehicle
from .relaxation_model import coefficients
from .sideslip_kalman_filter import model as bicycle
from .sideslip_kalman_filter import vehicle_dict

#: the record's columns the fit needs (SI: s, rad, m/s, rad/s, m/s^2); ``beta`` (rad) is used when present
REQUIRED = ("t", "delta", "vx", "yaw_rate", "ay")
MIN_TUNING_SECONDS = 10.0     # s, the shortest tuning part accepted
MIN_SPEED = 5.0               # m/s, samples below are not fitted (the model is singular at vx = 0)
MIN_MOVING_FRACTION = 0.5     # of the tuning part above MIN_SPEED
MIN_STEER_RMS = math.radians(0.1)   # rad, the least steering excitation (RMS of delta about its mean)
SEGMENT_SECONDS = 10.0        # s, the bootstrap's blocks
BOOTSTRAP = 400               # resamples
SCALE_BOUNDS = (0.2, 5.0)     # the stiffness scales searched, x the base vehicle's
#: the yaw inertia is identified with Cf, Cr when the record's transients reveal it: its 95 %
#: interval within +-IZ_MAX_SPREAD of the fit (relative), else it stays the base vehicle's, and why
IZ_MAX_SPREAD = 0.15
#: the fit simulates at most this many fitted samples (the first of the tuning part; 10 min at
#: 100 Hz, twice the MBDS record's tuning part): time and memory stay bounded on a long record
#: (a fit costs about 0.2 ms per fitted sample; the bootstrap's blocks hold the rest of the spread)
MAX_FIT_SAMPLES = 60_000
SIM_CHUNK = 8192              # samples discretised at once (memory: a few MB)


class IdentificationError(ValueError):
    """A record that cannot identify what was asked: the message names the culprit and why."""


@dataclass
class Identified:
    """The result of :func:`identify` (SI units)."""
    Cf: float
    Cr: float
    Cf_interval: tuple[float, float]       # 95 % (bootstrap), N/rad
    Cr_interval: tuple[float, float]
    base: str                              # the base vehicle's name
    record_sha256: str
    tune_until: float                      # s: the tuning part is t < tune_until
    samples: int                           # fitted samples (moving, tuning part)
    rms: dict[str, float]                  # {signal: RMS of its residual at the fit, SI}
    rms_base: dict[str, float]             # the same with the base vehicle's Cf, Cr
    signals: list[str]                     # the fitted signals
    nfev: int = 0
    tire_ratios: tuple[float, float] = (1.0, 1.0)   # effective / zero-slip stiffness (:func:`_tire_curve_ratios`)
    # {signal: (bound, RMS)} of the measurement error, SI (:func:`measurement_error_bounds`)
    error_bounds: dict = field(default_factory=dict)
    Iz: float | None = None                # kg m^2, when identified (else the base vehicle's stays)
    Iz_interval: tuple[float, float] | None = None
    not_identified: dict = field(default_factory=dict)     # {parameter: why the record does not reveal it}
    glitches: dict = field(default_factory=dict)           # {signal: [t of each glitch repaired]} (find_glitches)
    rejected: dict = field(default_factory=dict)           # {signal: samples the error bound rejected}
    capped_at: float | None = None                         # s: the fit stopped there (MAX_FIT_SAMPLES)


#: the measurement-error bounds: the residual of each sensor about its zero-phase low-pass
#: (2nd-order Butterworth, forward and backward) at NOISE_CUTOFF_HZ, above a car's lateral dynamics
#: (about 1-2 Hz) and below the vibration, at the NOISE_QUANTILE of its magnitude over the tuning
#: part, glitches repaired and left out (:func:`find_glitches`), and the samples farther than
#: NOISE_REJECT_K robust standard deviations (1.4826 x the median absolute deviation) rejected: a
#: few bad samples cannot set the bound (a clean record's residual stays within the limit: on the
#: MBDS record at most 8.6 of them, none rejected)
NOISE_SIGNALS = dict(zip(("yaw_rate", "ay"), ERROR_BOUND_PARAMETERS))     # {signal: vehicle parameter}
NOISE_CUTOFF_HZ = 5.0
NOISE_QUANTILE = 0.9999
NOISE_REJECT_K = 12.0


def robust_sigma(x: np.ndarray) -> float:
    """1.4826 x the median absolute deviation of ``x`` from its median: the standard deviation of a
    normal sample, unmoved by a few outliers of any size."""
    x = np.asarray(x, dtype=float)
    return float(1.4826 * np.median(np.abs(x - np.median(x)))) if x.size else 0.0


def measurement_error_bounds(cols: Mapping[str, np.ndarray], fit: np.ndarray, rejected: dict | None = None
                             ) -> dict[str, tuple[float, float]]:
    """{signal: (bound, RMS)} of the yaw rate's (rad/s) and ay's (m/s^2) measurement error on the
    samples ``fit``: the NOISE_QUANTILE of |y - lowpass(y)| (see NOISE_CUTOFF_HZ; at most 0.4 x the
    Nyquist frequency of a slower record) over the samples within NOISE_REJECT_K robust standard
    deviations (``rejected``, when given, gets {signal: the number of samples rejected}). A bound,
    not a model: the sensor's noise, vibration and quantisation as the record shows them; a bias
    common to the whole drive is not visible here. ``cols``: glitches already repaired."""
    from scipy.signal import butter, filtfilt

    t = np.asarray(cols["t"], dtype=float)
    dt = float(np.median(np.diff(t)))
    wn = min(NOISE_CUTOFF_HZ * 2.0 * dt, 0.4)           # of the Nyquist frequency
    b, a = butter(2, wn)
    out = {}
    for k in NOISE_SIGNALS:
        y = np.asarray(cols[k], dtype=float)
        r = (y - filtfilt(b, a, y))[fit]
        keep = np.abs(r - np.median(r)) <= NOISE_REJECT_K * robust_sigma(r) if r.size else np.ones(0, bool)
        if rejected is not None:
            rejected[k] = int(r.size - keep.sum())
        e = np.abs(r[keep]) if keep.any() else np.abs(r)
        out[k] = (float(np.quantile(e, NOISE_QUANTILE)), float(np.sqrt(np.mean(e ** 2))))
    return out


#: glitches: samples of the record's signals that are not measurements. A sample is one when no
#: car reaches it (|value| beyond GLITCH_IMPOSSIBLE, SI) or when it stands alone: farther from the
#: running median of GLITCH_WINDOW samples than GLITCH_K robust standard deviations of that
#: difference and GLITCH_FLOOR of the signal's range (its 0.5 ... 99.5 percentiles; a signal that
#: is mostly flat has no deviation to speak of). The running median follows steps and ramps, so
#: only a spike of at most (GLITCH_WINDOW - 1) / 2 samples stands out. Each glitch is replaced by
#: the line between its neighbours and left out of the fit and of the error bounds; the times are
#: reported. More than GLITCH_MAX_FRACTION of a column: refused (the record is damaged, not glitchy).
#: (The MBDS record: four one-sample steering spikes of 0.13 to 0.5 rad, one at t = 207.27 s in the
#: tuning part.) Non-finite values are refused, not repaired (check_record names the row).
GLITCH_SIGNALS = ("delta", "vx", "yaw_rate", "ay", "beta")
GLITCH_IMPOSSIBLE = {"delta": 1.2, "vx": 120.0, "yaw_rate": 5.0, "ay": 60.0, "beta": 1.2}
GLITCH_WINDOW = 5
GLITCH_K = 15.0
GLITCH_FLOOR = 0.1
GLITCH_MAX_FRACTION = 0.01


def find_glitches(cols: Mapping[str, np.ndarray], source: str = "the record"
                  ) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """(the record with its glitches repaired (new arrays where repaired), {signal: indices of its
    glitches}) of the :data:`GLITCH_SIGNALS` present (finite values: see :data:`GLITCH_SIGNALS`'s
    comment); IdentificationError when a column has more than GLITCH_MAX_FRACTION of them."""
    from scipy.ndimage import median_filter

    out, found = dict(cols), {}
    for k in GLITCH_SIGNALS:
        if k not in cols:
            continue
        y = np.asarray(cols[k], dtype=float)
        if not np.all(np.isfinite(y)):       # refused where it matters (check_record, identify's beta)
            continue
        bad = np.abs(y) > GLITCH_IMPOSSIBLE[k]
        if y.size > GLITCH_WINDOW:
            d = y - median_filter(y, GLITCH_WINDOW, mode="nearest")
            ok = y[~bad]
            span = float(np.percentile(ok, 99.5) - np.percentile(ok, 0.5)) if ok.size else 0.0
            bad |= np.abs(d) > max(GLITCH_K * robust_sigma(d[~bad]), GLITCH_FLOOR * span)
        if not bad.any():
            continue
        idx = np.flatnonzero(bad)
        if idx.size > GLITCH_MAX_FRACTION * y.size:
            t = np.asarray(cols["t"], dtype=float)
            raise IdentificationError(f"{source}: column {k!r} has {idx.size} glitches (samples no car reaches or that "
                                      f"stand alone, the first at data row {idx[0] + 1}, t = {t[idx[0]]:.6g} s): more "
                                      f"than {100 * GLITCH_MAX_FRACTION:g} % of the column; clean the record first")
        good = np.flatnonzero(~bad)
        y = y.copy()
        y[idx] = np.interp(idx, good, y[good])
        out[k], found[k] = y, idx
    return out, found


def check_record(cols: Mapping[str, np.ndarray], tune_until: float, source: str = "the record",
                 wheelbase: float | None = None, excitation: bool = True) -> np.ndarray | None:
    """The mask of the samples to fit (tuning part, moving), after checking the record: the columns
    of :data:`REQUIRED` present and finite there, a uniform time step and SI units (the rules
    ``latobs replay`` applies: :mod:`latobs.data.checks`; ``wheelbase``, m, for the steering angle's
    test), a tuning part of at least
    :data:`MIN_TUNING_SECONDS` mostly above :data:`MIN_SPEED`, steering that excites the yaw
    dynamics. IdentificationError naming the culprit otherwise."""
    missing = [c for c in REQUIRED if c not in cols]
    if missing:
        raise IdentificationError(f"{source}: missing column(s) {', '.join(missing)} (needs {', '.join(REQUIRED)}; "
                                  "delta is the road-wheel angle, rad)")
    t = np.asarray(cols["t"], dtype=float)
    if t.ndim != 1 or len(t) < 3:
        raise IdentificationError(f"{source}: column 't' must hold at least 3 times")
    uniform_step(t, source, IdentificationError)       # the rule latobs replay applies too
    found = unit_findings(cols, wheelbase)
    if found:
        raise IdentificationError(f"{source}: not in SI units (s, rad, rad/s, m/s, m/s^2): {'; '.join(found)}")
    tune = t < tune_until
    if t[tune].size < 2 or t[tune][-1] - t[0] < MIN_TUNING_SECONDS:
        raise IdentificationError(f"{source}: the tuning part (t < {tune_until:g} s) lasts "
                                  f"{(t[tune][-1] - t[0]) if t[tune].size else 0.0:.3g} s; at least "
                                  f"{MIN_TUNING_SECONDS:g} s are needed"
                                  + (f" (T is in the record's time, which starts at t = {t[0]:.12g} s)"
                                     if tune_until <= t[0] else ""))
    for c in REQUIRED[1:]:
        bad = ~np.isfinite(np.asarray(cols[c], dtype=float)[tune])
        if bad.any():
            first = int(np.flatnonzero(tune)[np.argmax(bad)])
            raise IdentificationError(f"{source}: column {c!r} has {int(bad.sum())} non-finite value(s) in the tuning "
                                      f"part, the first at data row {first + 1} (t = {t[first]:.6g} s): a record "
                                      "with non-finite values is refused, not repaired")
    return _check_excitation(cols, tune, source) if excitation else None


def _check_excitation(cols: Mapping[str, np.ndarray], tune: np.ndarray, source: str) -> np.ndarray:
    """The moving samples of the tuning part ``tune``; IdentificationError when too few, or when the
    steering does not excite the yaw dynamics."""
    vx = np.asarray(cols["vx"], dtype=float)
    moving = tune & (vx > MIN_SPEED)
    if moving.sum() < MIN_MOVING_FRACTION * tune.sum():
        raise IdentificationError(f"{source}: only {100 * moving.sum() / tune.sum():.0f} % of the tuning part is above "
                                  f"{MIN_SPEED:g} m/s: too little driving to identify the cornering stiffnesses")
    delta = np.asarray(cols["delta"], dtype=float)[moving]
    steer = float(np.sqrt(np.mean((delta - delta.mean()) ** 2)))
    if steer < MIN_STEER_RMS:
        raise IdentificationError(f"{source}: the steering barely moves in the tuning part (RMS "
                                  f"{math.degrees(steer):.3g} deg about its mean, at least "
                                  f"{math.degrees(MIN_STEER_RMS):.2g} deg needed): Cf and Cr are not excited")
    return moving


ROLL = ("Ix", "hr", "Kr", "br")    # a base vehicle with these: paper 000's roll model


def model_kind(vals: Mapping[str, float]) -> str:
    """The identification model of a base vehicle's values: "roll+relaxation" (paper 000's bicycle
    model with roll, eq. 1, its axle forces relaxed as in paper 001's eq. 9), "relaxation" (paper
    001's model), "roll" (paper 000's model) or "bicycle"."""
    roll = all(k in vals for k in ROLL)
    relax = float(vals.get("sigma", 0.0) or 0.0) > 0
    return {(True, True): "roll+relaxation", (False, True): "relaxation", (True, False): "roll",
            (False, False): "bicycle"}[(roll, relax)]


def _roll_model(vals: Mapping[str, float], vx: np.ndarray, relax: bool) -> tuple[np.ndarray, np.ndarray]:
    """(A, B) per sample of paper 000's model (states beta, r, phi, phi'; ``synthesis.bicycle_roll_model``),
    with its axle forces Ff, Fr (per m g) relaxed as states when ``relax`` (sigma/vx F' + F = C alpha:
    ``bicycle_roll_model.relaxed_lpv_coefficients``)."""
    from .bicycle_roll_model import lpv_coefficients, relaxed_lpv_coefficients
    from .params import Parameter

    names = ("m", "Iz", "Ix", "lf", "lr", "hr", "Kr", "br", "Cf", "Cr") + (("sigma",) if relax else ())
    veh = Vehicle("identification", "car", "", "",
                  {k: Parameter(k, float(vals[k]), "", "", "", "positive") for k in names}, {})
    co = relaxed_lpv_coefficients(veh) if relax else lpv_coefficients(veh)
    inv, p = 1.0 / vx, int(co.get("first_power", 0))
    at = lambda key: sum(M[None] * inv[:, None, None] ** (k + p) for k, M in enumerate(co[key]))  # noqa: E731
    return at("A"), at("B")[:, :, 0]


def expm_stack(M: np.ndarray) -> np.ndarray:
    """exp(M[i]) of every matrix of a stack (n, k, k), as ``scipy.linalg.expm`` of the stack but in
    whole-stack numpy operations (scipy's treats a stack one matrix at a time in Python: 5 to 10 us
    a matrix, 15 s of an identification). Scaling and squaring, per matrix: M / 2^s with its 1-norm
    <= 1/2, then Taylor's series to degree 18 (its remainder < 0.5^19 / 19! ~ 2e-23 relative),
    squared s times: as accurate as scipy's or more (``test_identification``: against exact
    exponentials)."""
    M = np.asarray(M, dtype=float)
    if M.ndim != 3 or M.shape[1] != M.shape[2]:
        raise ValueError(f"expm_stack: a stack of square matrices (n, k, k), got shape {M.shape}")
    if not np.all(np.isfinite(M)):
        raise ValueError("expm_stack: the matrices must be finite")
    norm = np.abs(M).sum(axis=1).max(axis=1) if M.shape[0] else np.zeros(0)
    s = np.maximum(0, np.ceil(np.log2(np.maximum(norm, 1e-300) / 0.5))).astype(int)
    X = M / np.ldexp(1.0, s)[:, None, None]
    eye = np.eye(M.shape[1])
    E = eye + X / 18.0
    for j in range(17, 0, -1):          # Horner: I + X/j (I + X/(j+1) (...))
        E = eye + (X @ E) / j
    for j in range(int(s.max(initial=0))):
        sq = s > j
        E[sq] = E[sq] @ E[sq]
    return E


def simulate(cols: Mapping[str, np.ndarray], vals: Mapping[str, float], x0: tuple[float, float] = (0.0, 0.0)
             ) -> dict[str, np.ndarray]:
    """The model of ``vals`` (:func:`model_kind`) driven by the record's delta at its speed (below
    :data:`MIN_SPEED` held at it), from sideslip and yaw rate ``x0`` = (beta rad, r rad/s) and the
    rest at rest: {"beta" (at the CG), "yaw_rate", "ay", "alpha_f", "alpha_r" (the axle slip
    angles, rad)} at every sample (ay = the sum of the tire forces / m, as a road-plane
    accelerometer at the CG reads it)."""
    t = np.asarray(cols["t"], dtype=float)
    h = np.diff(t, append=t[-1] + (t[-1] - t[-2]))
    vx = np.maximum(np.asarray(cols["vx"], dtype=float), MIN_SPEED)
    delta = np.asarray(cols["delta"], dtype=float)
    kind = model_kind(vals)
    if kind.startswith("roll"):
        A, B = _roll_model(vals, vx, relax=kind == "roll+relaxation")
    elif kind == "relaxation":               # paper 001 (states vy, r, ay, r'); B = vx B1
        A0, A1, B1 = coefficients(vals["m"], vals["Iz"], vals["lf"], vals["lr"], vals["sigma"], vals["Cf"], vals["Cr"])
        A, B = A0[None] + vx[:, None, None] * A1[None], vx[:, None] * B1[None]
    else:                                    # paper 002's Kalman peer (states vy, r)
        A, B, _, _ = bicycle(vals, vx)
    n, k = len(t), A.shape[1]
    x = np.empty((n, k))
    xk = np.zeros(k)
    xk[0] = x0[0] if kind.startswith("roll") else x0[0] * vx[0]      # beta, or vy = beta vx
    xk[1] = x0[1]
    for c in range(0, n, SIM_CHUNK):        # (each matrix's exponential is its own: the same doubles)
        sl = slice(c, min(c + SIM_CHUNK, n))
        M = np.zeros((sl.stop - c, k + 1, k + 1))   # Van Loan: exp([[A, B], [0, 0]] h) = [[Phi, Gam], [0, 1]]
        M[:, :k, :k] = A[sl] * h[sl, None, None]
        M[:, :k, k] = B[sl] * h[sl, None]
        E = expm_stack(M)
        Phi, Gam = E[:, :k, :k], E[:, :k, k]
        for i in range(sl.stop - c):        # x_{i+1} = Phi_i x_i + Gam_i delta_i
            x[c + i] = xk
            xk = Phi[i] @ xk + Gam[i] * delta[c + i]
    m, lf, lr, cf, cr = (float(vals[q]) for q in ("m", "lf", "lr", "Cf", "Cr"))
    if kind.startswith("roll"):      # paper 000's beta is the roll axis point's; the CG's: vy_cg = vy - hr phi'
        beta = x[:, 0] - float(vals["hr"]) * x[:, 3] / vx
        ay = ((x[:, 4] + x[:, 5]) * G if kind == "roll+relaxation" else      # (axle forces per m g)
              (cf * (delta - x[:, 0] - lf * x[:, 1] / vx) + cr * (-x[:, 0] + lr * x[:, 1] / vx)) / m)
    elif kind == "relaxation":
        ay, beta = x[:, 2], np.arctan2(x[:, 0], vx)
    else:
        ay = A[:, 0, 0] * x[:, 0] + (A[:, 0, 1] + vx) * x[:, 1] + B[:, 0] * delta    # vy' + vx r
        beta = np.arctan2(x[:, 0], vx)
    b_axle = x[:, 0] if kind.startswith("roll") else x[:, 0] / vx     # the sideslip the slip angles use
    return {"beta": beta, "yaw_rate": x[:, 1], "ay": ay,
            "alpha_f": delta - b_axle - lf * x[:, 1] / vx, "alpha_r": -b_axle + lr * x[:, 1] / vx}


def record_sha256(cols: Mapping[str, np.ndarray]) -> str:
    """A hash of the record's columns (names and float64 bytes), for the provenance."""
    h = hashlib.sha256()
    for k in sorted(cols):
        h.update(k.encode() + b"\0" + np.ascontiguousarray(np.asarray(cols[k], dtype=float)).tobytes())
    return h.hexdigest()


def identify(cols: Mapping[str, np.ndarray], base: Vehicle, tune_until: float, use_beta: bool = True,
             source: str = "the record", seed: int = 0, progress: Callable[[str], None] | None = None
             ) -> Identified:
    """Cf and Cr of the car that drove ``cols`` (:func:`check_record`, glitches repaired and left
    out: :func:`find_glitches`; ``use_beta``: fit the record's ``beta`` too when it has one), the
    rest of the model from ``base``; see the module. ``progress(stage)``: called at every
    simulation of the record (a progress bar's tick; the CLI's)."""
    from scipy.optimize import least_squares

    tick = progress or (lambda stage: None)
    sha = record_sha256(cols)
    wheelbase = base.value("lf") + base.value("lr") if "lf" in base.parameters and "lr" in base.parameters else None
    check_record(cols, tune_until, source, wheelbase, excitation=False)
    cols, glitch_idx = find_glitches(cols, source)
    t = np.asarray(cols["t"], dtype=float)
    glitch = np.zeros(t.size, dtype=bool)
    for idx in glitch_idx.values():
        glitch[idx] = True
    fit = _check_excitation(cols, t < tune_until, source) & ~glitch
    capped_at, fit_all = None, fit.copy()          # (the error bounds: the whole tuning part)
    where = np.flatnonzero(fit)
    if where.size > MAX_FIT_SAMPLES:
        fit[where[MAX_FIT_SAMPLES:]] = False
        capped_at = float(t[where[MAX_FIT_SAMPLES]])
    vals0 = vehicle_dict(base)
    vals0.update({k: base.value(k) for k in ("sigma", *ROLL) if k in base.parameters})
    signals = ["yaw_rate", "ay"] + (["beta"] if use_beta and "beta" in cols else [])
    meas = {s: np.asarray(cols[s], dtype=float) for s in signals}
    if "beta" in signals and not np.all(np.isfinite(meas["beta"][fit])):
        raise IdentificationError(f"{source}: column 'beta' has non-finite values in the tuning part (or identify "
                                  "without it)")
    spread = {s: float(np.std(meas[s][fit])) or 1.0 for s in signals}
    x0 = (float(meas["beta"][0]) if "beta" in signals and np.isfinite(meas["beta"][0]) else 0.0,
          float(cols["yaw_rate"][0]))

    def values(s: np.ndarray) -> dict:
        v = {**vals0, "Cf": vals0["Cf"] * s[0], "Cr": vals0["Cr"] * s[1]}
        if len(s) > 2:                  # the yaw inertia too
            v["Iz"] = vals0["Iz"] * s[2]
        return v

    # the fit simulates the record up to its last fitted sample only: a sample depends on those
    # before it alone (each step's map is its own), so the fitted samples are the same numbers as a
    # simulation of the whole record's; the held-out part (t >= tune_until) is not computed at every
    # evaluation of the search (on the mbds record: 61 % of the samples simulated)
    head = max(int(np.flatnonzero(fit)[-1]) + 1, 2)
    head_cols = {k: np.asarray(v)[:head] for k, v in cols.items()}
    head_fit, head_meas = fit[:head], {k: v[:head] for k, v in meas.items()}

    def residual_parts(s: np.ndarray) -> dict[str, np.ndarray]:
        tick("fit")
        sim = simulate(head_cols, values(s), x0)
        return {k: (sim[k][head_fit] - head_meas[k][head_fit]) / spread[k] for k in signals}

    def residuals(s: np.ndarray) -> np.ndarray:
        r = np.concatenate(list(residual_parts(s).values()))
        return r / math.sqrt(len(r))

    def solve(n: int):
        sol = least_squares(residuals, x0=np.ones(n), bounds=SCALE_BOUNDS, x_scale=np.ones(n), method="trf",
                            diff_step=1e-4)
        edge = np.isclose(sol.x, SCALE_BOUNDS[0], rtol=1e-3) | np.isclose(sol.x, SCALE_BOUNDS[1], rtol=1e-3)
        return sol, edge

    # Cf, Cr and the yaw inertia (a third scale) first; the inertia is kept only when the record
    # reveals it (the fit inside the search, a bootstrap interval within +-IZ_MAX_SPREAD)
    not_identified = {}
    sol, edge = solve(3)
    iz_box = None
    if not edge.any():
        s_hat = sol.x
        try:
            interval = _bootstrap(cols, fit, signals, residual_parts, s_hat, seed)
            iz_spread = max(s_hat[2] - interval[2][0], interval[2][1] - s_hat[2]) / s_hat[2]
        except np.linalg.LinAlgError:            # a resample that does not determine it at all
            iz_spread = math.inf
        if iz_spread <= IZ_MAX_SPREAD:
            iz_box = interval[2]
        else:
            width = f"+-{100 * iz_spread:.0f} %" if iz_spread < 10.0 else "wider than +-1000 %"
            not_identified["Iz"] = (f"the record's yaw transients do not reveal it: its 95 % interval would be "
                                    f"{width} (at most +-{100 * IZ_MAX_SPREAD:g} % is kept)")
    elif not edge[:2].any():
        not_identified["Iz"] = "the record's yaw transients do not reveal it: its fit ran to the edge of the search"
    if iz_box is None:
        sol, edge = solve(2)
        s_hat = sol.x
    if edge.any():
        raise IdentificationError(f"{source}: the fit ran to the edge of the search ({SCALE_BOUNDS[0]:g}..."
                                  f"{SCALE_BOUNDS[1]:g} x the base vehicle's Cf, Cr): the record does not fit the "
                                  "bicycle model with this base vehicle (check the units: delta is the road-wheel "
                                  "angle in rad, ay in m/s^2)")
    if iz_box is None:
        interval = _bootstrap(cols, fit, signals, residual_parts, s_hat, seed)
    kappa = _tire_curve_ratios(base, simulate(head_cols, values(s_hat), x0), head_fit, vals0, s_hat)
    parts = residual_parts(s_hat)
    parts_base = residual_parts(np.ones(len(s_hat)))
    rejected: dict = {}
    bounds = measurement_error_bounds(cols, fit_all, rejected)
    # the slope at zero slip: the fitted (effective) stiffness over the tire curve's ratio; the box
    # reaches from the effective stiffness to the zero-slip slope's interval
    zero = [s_hat[i] / kappa[i] for i in range(2)]
    box = [(min(interval[i][0] / kappa[i], s_hat[i]), max(interval[i][1] / kappa[i], s_hat[i])) for i in range(2)]
    return Identified(
        Cf=float(vals0["Cf"] * zero[0]), Cr=float(vals0["Cr"] * zero[1]),
        Cf_interval=(float(vals0["Cf"] * box[0][0]), float(vals0["Cf"] * box[0][1])),
        Cr_interval=(float(vals0["Cr"] * box[1][0]), float(vals0["Cr"] * box[1][1])),
        base=base.name, record_sha256=sha, tune_until=float(min(tune_until, t[-1] + 1e-9)),
        samples=int(fit.sum()),
        rms={k: float(np.sqrt(np.mean((v * spread[k]) ** 2))) for k, v in parts.items()},
        rms_base={k: float(np.sqrt(np.mean((v * spread[k]) ** 2))) for k, v in parts_base.items()},
        signals=signals, nfev=int(sol.nfev), tire_ratios=(float(kappa[0]), float(kappa[1])),
        error_bounds=bounds, rejected=rejected, capped_at=capped_at,
        glitches={k: [float(x) for x in t[idx]] for k, idx in glitch_idx.items()},
        Iz=None if iz_box is None else float(vals0["Iz"] * s_hat[2]),
        Iz_interval=None if iz_box is None else (float(vals0["Iz"] * iz_box[0]), float(vals0["Iz"] * iz_box[1])),
        not_identified=not_identified)


def _tire_curve_ratios(base: Vehicle, sim: dict, fit: np.ndarray, vals0: dict, s_hat: np.ndarray
                       ) -> tuple[float, float]:
    """(kappa_f, kappa_r): the ratio of the stiffness a linear model fits over the drive's slip
    angles to the slope at zero slip, for a base vehicle with a tire curve (the Magic Formula of
    ``synthesis.tire``: mu, mf_C, mf_E); (1, 1) without one. A tire's force is not linear in its
    slip: over slip angles alpha the least-squares slope of the curve F is sum F(alpha) alpha /
    sum alpha^2, below F'(0). The curve's own zero-slip slope is the unknown: fixed-point
    iteration from the fitted stiffness (kappa depends weakly on it)."""
    from .tire import MF_PARAMS, axle_force

    if not all(k in base.parameters for k in MF_PARAMS):
        return 1.0, 1.0
    out = []
    for i, (axle, key) in enumerate((("f", "Cf"), ("r", "Cr"))):
        alpha = sim["alpha_" + axle][fit]
        fitted = vals0[key] * s_hat[i]
        zero = fitted
        for _ in range(20):
            F = axle_force(base.with_values(**{key: zero}), axle, alpha)
            kappa = float(np.sum(F * alpha) / (zero * np.sum(alpha * alpha)))
            new = fitted / kappa
            if abs(new - zero) <= 1e-9 * zero:
                break
            zero = new
        out.append(kappa)
    return out[0], out[1]


def _bootstrap(cols, fit: np.ndarray, signals: list[str], residual_parts, s_hat: np.ndarray, seed: int
               ) -> list[tuple[float, float]]:
    """The 95 % interval of each scale: moving-block bootstrap over :data:`SEGMENT_SECONDS` blocks of
    the fitted samples, each resample's estimate one Gauss-Newton step from the fit. It holds the
    estimation noise, not the model error (a real tire is not linear in its slip)."""
    t = np.asarray(cols["t"], dtype=float)[fit]
    block = np.floor((t - t[0]) / SEGMENT_SECONDS).astype(int)
    nb = int(block.max()) + 1
    base = residual_parts(s_hat)
    step = 1e-4
    n = len(s_hat)
    jac = []
    for j in range(n):
        d = s_hat.copy()
        d[j] += step * s_hat[j]
        moved = residual_parts(d)
        jac.append({k: (moved[k] - base[k]) / (step * s_hat[j]) for k in signals})
    # per block: J^T J (n x n) and J^T e (n), summed over the signals
    JtJ = np.zeros((nb, n, n))
    Jte = np.zeros((nb, n))
    for k in signals:
        J = np.stack([jac[j][k] for j in range(n)], axis=1)
        e = base[k]
        for i in range(n):
            Jte[:, i] += np.bincount(block, J[:, i] * e, minlength=nb)
            for j in range(n):
                JtJ[:, i, j] += np.bincount(block, J[:, i] * J[:, j], minlength=nb)
    rng = np.random.default_rng(seed)
    draws = rng.integers(0, nb, size=(BOOTSTRAP, nb))
    est = np.empty((BOOTSTRAP, n))
    for b in range(BOOTSTRAP):
        A = JtJ[draws[b]].sum(axis=0)
        g = Jte[draws[b]].sum(axis=0)
        est[b] = s_hat - np.linalg.solve(A, g)
    lo, hi = np.percentile(est, [2.5, 97.5], axis=0)
    return [(float(min(lo[i], s_hat[i])), float(max(hi[i], s_hat[i]))) for i in range(n)]


def vehicle_document(result: Identified, base: Vehicle, name: str, record: str, tune_until_text: str,
                     version: str) -> dict:
    """The vehicle file of the identified car (a ``synthesis.params`` vehicle TOML as a dict): the
    base vehicle's parameters, Cf and Cr identified (the others marked as given), the stiffness box
    from the bootstrap interval, and an ``[identification]`` table of provenance."""
    doc = base.as_dict()
    doc["name"] = name
    doc["description"] = f"identified from {record} by latobs identify (base vehicle {base.name})"
    doc["source"] = f"latobs {version} identify: Cf, Cr fitted to {record} ({tune_until_text}); the rest from {base.name}"
    for k, p in doc["parameters"].items():
        p["source"] = f"given: the base vehicle {base.name} ({p.get('source') or base.source})"
    fitted = " and ".join(result.signals)
    for k, value, (lo, hi), kappa in (("Cf", result.Cf, result.Cf_interval, result.tire_ratios[0]),
                                      ("Cr", result.Cr, result.Cr_interval, result.tire_ratios[1])):
        doc["parameters"][k]["value"] = round(value, 1)
        slope = (f", the slope at zero slip of {base.name}'s tire curve (the fitted stiffness / {kappa:.4f})"
                 if kappa != 1.0 else "")
        doc["parameters"][k]["source"] = (f"identified: output-error fit of {fitted} on {tune_until_text}{slope}; "
                                          f"box {lo:.0f} ... {hi:.0f} N/rad")
    if result.Iz is not None:
        lo, hi = result.Iz_interval
        doc["parameters"]["Iz"]["value"] = round(result.Iz, 1)
        doc["parameters"]["Iz"]["source"] = (f"identified: output-error fit of {fitted} on {tune_until_text}, with Cf "
                                             f"and Cr; 95 % interval {lo:.0f} ... {hi:.0f} kg*m^2")
    for k, why in result.not_identified.items():
        doc["parameters"][k]["source"] += f"; not identified: {why}"
    for k, (bound, rms) in result.error_bounds.items():
        unit = "rad/s" if k == "yaw_rate" else "m/s^2"
        doc["parameters"][NOISE_SIGNALS[k]] = {
            "value": float(f"{bound:.4g}"), "unit": unit,
            "description": f"bound of |measured - true| {k} (the interval observer's measurement-error bound)",
            "source": f"identified: the {100 * NOISE_QUANTILE:g} % quantile of |{k} - its zero-phase "
                      f"{NOISE_CUTOFF_HZ:g} Hz low-pass| on {tune_until_text} (RMS {rms:.4g} {unit}), "
                      f"{robust_basis(result, k)}"}
    ranges = doc.setdefault("ranges", {})
    for k, (lo, hi) in (("Cf", result.Cf_interval), ("Cr", result.Cr_interval)):
        ranges[k] = {"min": round(lo, 1), "max": round(hi, 1), "unit": "N/rad",
                     "description": f"{'front' if k == 'Cf' else 'rear'} axle cornering stiffness box: the 95 % "
                                    "interval of the identification (block bootstrap)"}
    identified = ["Cf", "Cr", *(["Iz"] if result.Iz is not None else []),
                  *(NOISE_SIGNALS[k] for k in result.error_bounds)]
    doc["identification"] = {
        "record": record, "record_sha256": result.record_sha256, "tuning": tune_until_text,
        "tune_until": result.tune_until, "samples": result.samples, "signals": result.signals,
        "base_vehicle": base.name, "latobs": version, "method": "output-error least squares (scipy), bicycle model "
        "of synthesis.sideslip_kalman_filter; 95 % intervals by a moving-block bootstrap of 10 s blocks",
        "residual_rms": {k: round(v, 8) for k, v in result.rms.items()},
        "residual_rms_base": {k: round(v, 8) for k, v in result.rms_base.items()},
        "tire_curve_ratio": {"Cf": round(result.tire_ratios[0], 6), "Cr": round(result.tire_ratios[1], 6),
                             "meaning": "the stiffness a linear model fits over the drive's slip angles / the "
                                        "slope at zero slip, on the base vehicle's tire curve (1: none given)"},
        "identified": identified,
        "glitches": {k: {"count": len(ts), "t": [round(x, 6) for x in ts[:GLITCH_LISTED]]}
                     for k, ts in result.glitches.items()},
        "glitch_rule": (f"a sample beyond {', '.join(f'{k} {v:g}' for k, v in GLITCH_IMPOSSIBLE.items())} (SI), or "
                        f"farther from the running median of {GLITCH_WINDOW} samples than {GLITCH_K:g} robust "
                        f"standard deviations (1.4826 MAD) and {100 * GLITCH_FLOOR:g} % of the signal's range: "
                        "replaced by the line between its neighbours, left out of the fit and the error bounds "
                        "(non-finite values are refused)"),
        "error_bound_rejected": dict(result.rejected),
        "given": sorted(k for k in doc["parameters"] if k not in identified),
        "not_identified": dict(result.not_identified),
    }
    if result.capped_at is not None:
        doc["identification"]["fit_capped_at"] = result.capped_at
    return doc


GLITCH_LISTED = 20      # glitch times listed per signal (the count is whole)


def robust_basis(result: Identified, k: str) -> str:
    """How the bound of ``k`` was made robust: glitches left out, far samples rejected."""
    n = len(result.glitches.get(k, ()))
    return (f"{n} glitch(es) left out, {result.rejected.get(k, 0)} sample(s) beyond {NOISE_REJECT_K:g} robust "
            "standard deviations (1.4826 MAD) rejected")
