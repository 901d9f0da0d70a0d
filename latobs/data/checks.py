"""Checks of a record's time axis and units, one rule shared by ``latobs identify`` (design time)
and ``latobs replay`` (validation); numpy only.

Time (:func:`uniform_step`): judged relative to the first sample (tau = t - t_0, so Unix
timestamps are as good as seconds from zero); a record is uniform when every step lies within
:data:`UNIFORM_RTOL` of the mean step, plus :data:`UNIFORM_ULPS` ulps of max|t| (the doubles'
rounding of large times). The relative term admits the printed precision of the times and a
logger's jitter (200 Hz written with 9 significant digits: steps of 0.00499984 s and 0.0050001 s
around 1000 s), and still refuses a real gap (a dropped sample is a step 100 % too long) or a
short step.

Units (:func:`unit_findings`): latobs's records are SI (s, rad, rad/s, m/s, m/s^2). A column in
degrees, km/h, g or a time in milliseconds is a likely mistake that the values alone may not
betray (3 degrees of steering are 3 rad, under pi). The findings use magnitudes no vehicle reaches
in SI (99th percentiles, so that one glitch is not taken for the record) and physics: in steady
cornering a car's lateral acceleration is its speed times its yaw rate (ay = vx r + vy', vy' ~ 0),
so the ratio vx r / ay over the cornering samples is about 1 in SI, 3.6 with vx in km/h, 57 with r
in deg/s, 1/9.81 with ay in g; with the wheelbase L, the kinematic steering angle L r / vx is at
most the road-wheel angle delta (understeer: delta vx / (L r) about 1 to 3; 57 times more with
delta in degrees). Each finding names the column, the evidence and the fix.
"""
from __future__ import annotations

import math
from typing import Any, Mapping

import numpy as np

UNIFORM_RTOL = 0.05   # a step within 5 % of the mean step is uniform (printing precision, jitter)
UNIFORM_ULPS = 8      # plus this many ulps of max|t|: the rounding of the times as doubles


class RecordCheckError(ValueError):
    """A record whose time axis is not a fixed step; the message names where and by how much."""


def uniform_step(t: np.ndarray, source: Any = "the record", error: type[Exception] = RecordCheckError) -> float:
    """The time step of ``t`` (s): the mean step of tau = t - t_0, when every step is within
    ``UNIFORM_RTOL`` of it (plus ``UNIFORM_ULPS`` ulps of max|t|); else ``error`` naming the step
    that departs most from the usual (median) step, where it is (data rows and times) and by how much."""
    t = np.asarray(t, dtype=float)
    if t.ndim != 1 or t.size < 2:
        raise error(f"{source}: fewer than 2 samples, no time step")
    if not np.all(np.isfinite(t)):
        i = int(np.argmax(~np.isfinite(t)))
        raise error(f"{source}: column 't' holds {t[i]} at data row {i + 1}: times must be finite")
    tau = t - t[0]
    dt = float(tau[-1] / (t.size - 1))
    d = np.diff(tau)
    tol = UNIFORM_RTOL * dt + UNIFORM_ULPS * float(np.spacing(np.max(np.abs(t))))
    usual = float(np.median(d))
    if not dt > 0 or np.any(np.abs(d - dt) > tol):
        i = int(np.argmax(np.abs(d - usual)))
        what = "a gap" if d[i] > usual else "a short step"
        raise error(f"{source}: the time step is not uniform: {what} of {d[i]:.6g} s between data rows "
                    f"{i + 1} and {i + 2} (t = {t[i]:.12g} s and {t[i + 1]:.12g} s, {tau[i]:.9g} s after the "
                    f"first sample) where the usual step is {usual:.6g} s (allowed deviation {tol:.3g} s, "
                    f"{100 * UNIFORM_RTOL:g} % of the step); resample the record to a fixed step")
    return dt


#: the 99th percentile of |x| beyond which an SI column cannot be what it names: (limit, unit
#: it is given in, the likely unit, the fix). Road-wheel angles beyond 40 deg, sideslip beyond
#: 40 deg, lean beyond 70 deg, yaw rates beyond 150 deg/s, roll rates beyond 300 deg/s, 300 km/h
ANGLE_LIMITS = {"delta": 0.7, "steer_angle": 1.2, "beta": 0.7, "roll_angle": 1.2, "bank_angle": 0.6,
                "yaw_rate": 2.6, "roll_rate": 5.2, "steer_rate": 20.0}
SPEED_LIMIT = 85.0            # m/s (306 km/h): vx's 99th percentile beyond it reads as km/h
STEADY_AY = 1.5               # m/s^2: the cornering samples of the ay = vx r test (either side above)
STEADY_SECONDS = 2.0          # s of cornering samples needed for it
MS_STEP = (0.5, 20.0)         # a "step" of 0.5 to 20 s is a 50 Hz ... 2 kHz logger's in milliseconds


def _p99(x: np.ndarray) -> float:
    x = np.abs(np.asarray(x, dtype=float))
    x = x[np.isfinite(x)]
    return float(np.percentile(x, 99)) if x.size else 0.0


def unit_findings(cols: Mapping[str, np.ndarray], wheelbase: float | None = None) -> list[str]:
    """What in ``cols`` ({column: array}, SI expected) looks like another unit (see the module):
    one message per finding, naming the column, the evidence and the fix; [] when nothing does."""
    out: list[str] = []
    t = np.asarray(cols["t"], dtype=float) if "t" in cols else None
    dt = None
    if t is not None and t.size >= 2:
        dt = float(np.median(np.diff(t)))
        if MS_STEP[0] <= dt <= MS_STEP[1]:
            out.append(f"column 't' steps by {dt:.6g} s (a {1.0 / dt:.3g} Hz record): it looks like milliseconds "
                       f"({dt:.6g} ms is {1000.0 / dt:.4g} Hz); give t in s (divide it by 1000)")
    for k, limit in ANGLE_LIMITS.items():
        if k in cols and (p := _p99(cols[k])) > limit:
            out.append(f"column {k!r} reaches {p:.4g} (99th percentile of its magnitude, "
                       f"{math.degrees(p):.0f} deg if rad): it looks like degrees; give it in rad (multiply by pi/180)")
    seen = {m.split("'")[1] for m in out if "'" in m}
    if "vx" in cols and (p := _p99(cols["vx"])) > SPEED_LIMIT:
        out.append(f"column 'vx' reaches {p:.4g} (99th percentile, {3.6 * p:.0f} km/h if m/s): it looks like km/h; "
                   "give it in m/s (divide by 3.6)")
        seen.add("vx")
    if dt is not None and dt > 0 and all(k in cols for k in ("vx", "yaw_rate", "ay")):
        vx, r, ay = (np.asarray(cols[k], dtype=float) for k in ("vx", "yaw_rate", "ay"))
        turn = np.isfinite(vx * r * ay) & (np.maximum(np.abs(ay), np.abs(vx * r)) > STEADY_AY) & (ay != 0)
        if turn.sum() * dt >= STEADY_SECONDS:
            q = float(np.median(np.abs(vx[turn] * r[turn] / ay[turn])))
            if not 1 / 3.0 < q < 2.0:        # SI: about 1 (a body-fixed ay reads less in a roll, more under bias)
                causes = {"vx in km/h (divide by 3.6)": 3.6, "yaw_rate in deg/s (multiply by pi/180)": 180 / math.pi,
                          "vx in km/h and yaw_rate in deg/s": 3.6 * 180 / math.pi, "ay in g (multiply by 9.81)": 9.81,
                          "ay in g and yaw_rate in deg/s": 9.81 * 180 / math.pi}
                likely = min(causes, key=lambda c: abs(math.log(causes[c] / q)))
                out.append(f"columns 'vx', 'yaw_rate', 'ay' disagree: in {turn.sum() * dt:.3g} s of cornering "
                           f"(|ay| or |vx r| > {STEADY_AY:g}) vx * yaw_rate / ay is {q:.3g} (median), about 1 in SI units; "
                           f"most likely {likely}")
                seen.update(("vx", "yaw_rate", "ay"))
        if wheelbase and "delta" in cols and not seen & {"delta", "yaw_rate", "vx"}:
            d = np.asarray(cols["delta"], dtype=float)
            turn &= np.isfinite(d) & (np.abs(r) > 0.02)
            if turn.sum() * dt >= STEADY_SECONDS:
                q = float(np.median(d[turn] * vx[turn] / (wheelbase * r[turn])))
                if q > 15.0:
                    out.append(f"column 'delta' is {q:.3g} times the kinematic steering angle wheelbase * yaw_rate / "
                               f"vx in cornering (median; a car in rad: about 1 to 3): it looks like degrees; give "
                               "the road-wheel angle in rad (multiply by pi/180)")
    return out
