"""Paper 001's interval observer on the real MBDS record, designed for the car ``latobs identify``
finds on its tuning part (t < 425 s): the reference lateral velocity's enclosure, the mean width of
the bounds and the restarts per minute (``consistent`` falling to 0), on the tuning and the held-out
part, as the measurement-error bounds (the FMU parameters yaw_rate_error_bound, ay_error_bound)
vary: the quantile of the tuning part's sensor residuals they are taken at
(``synthesis.identification.measurement_error_bounds``; identify writes the 99.99 % quantile).

    python benchmarks/interval_mbds.py [--box F] [--out DIR] [--more]

A last table gives, per speed mode, the steady-state vy width that each sensor's identified bound
alone keeps through the design's gains (the floor of the width at this design).

``--box F``: the design's relative stiffness half-widths around the identified Cf, Cr (default
0.2, the design's default). Builds the native FMU for this machine in DIR (default a temporary
folder) and drives it with fmpy through ``latobs.validation.replay.drive``. ``--more``: two more
tables, the held-out figures as ay_error_bound alone varies, and with ay low-passed (first order,
causal) before the observer, its error against the zero-phase reference bounded like the sensors'.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import tomli_w

from latobs import __version__, packaging
from latobs.cbackend.toolchain import host_platform
from latobs.synthesis import design_file, designs
from latobs.synthesis import identification as ident
from latobs.validation import replay as rp

from _mbds import SPLIT, setup

QUANTILES = (None, 0.99, 0.995, 0.999, 0.9999, 1.0)    # None: exact measurements (the paper)
SETTLE = 2.0           # s, not scored after the start


def scores(run, t) -> dict[str, tuple[float, float, float]]:
    """{part: (enclosure of the reference vy, mean width m/s, restarts per minute)}."""
    o, vy = run.outputs, run.columns["vy"]
    lo, hi, c = o["vy_lower"], o["vy_upper"], o["consistent"]
    out = {}
    for part, m in (("tuning", (t < SPLIT) & (t >= t[0] + SETTLE)), ("held-out", t >= SPLIT)):
        enc = float(np.mean((vy[m] >= lo[m]) & (vy[m] <= hi[m])))
        falls = int(np.sum(np.diff(c[m].astype(int)) < 0))
        out[part] = (enc, float(np.mean(hi[m] - lo[m])), falls / (m.sum() * run.dt / 60.0))
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--box", type=float, default=0.2)
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument("--more", action="store_true")
    args = ap.parse_args(argv)
    out, cols, base = setup(args.out, "interval-mbds-")
    res = ident.identify(cols, base, SPLIT)
    car = out / "mycar.toml"
    car.write_text(tomli_w.dumps(ident.vehicle_document(res, base, "mycar", "mbds", f"t < {SPLIT:g} s", __version__)))
    data = packaging.complete_runtime_data(designs.run("LateralIntervalObserver", str(car), box=(args.box, args.box)))
    fmu = packaging.package_design(design_file.write(data, out), out, backend="c", platforms=[host_platform()])
    fit = cols["t"] < SPLIT
    print(f"LateralIntervalObserver for the identified car (Cf {res.Cf:.0f}, Cr {res.Cr:.0f} N/rad, box "
          f"+-{100 * args.box:g} %), MBDS record, tuning t < {SPLIT:g} s / held-out t >= {SPLIT:g} s")
    print("| quantile | yaw_rate_error_bound (rad/s) | ay_error_bound (m/s²) | vy enclosed (tuning / held-out) "
          "| mean vy width, m/s (tuning / held-out) | restarts per minute (tuning / held-out) |")
    print("|---|---|---|---|---|---|")
    t = cols["t"]
    q_identify = ident.NOISE_QUANTILE
    for q in QUANTILES:
        if q is None:
            params = {k: 0.0 for k in ident.NOISE_SIGNALS.values()}
        else:
            ident.NOISE_QUANTILE = q
            b = ident.measurement_error_bounds(cols, fit)
            params = {ident.NOISE_SIGNALS[k]: v[0] for k, v in b.items()}
        s = scores(rp.drive(fmu, {k: cols[k] for k in ("t", "delta", "vx", "yaw_rate", "ay", "vy")},
                            parameters=params), t)
        tu, ho = s["tuning"], s["held-out"]
        print(f"| {'0 (exact, the paper)' if q is None else f'{q:g}'} | {params['yaw_rate_error_bound']:.4g} | {params['ay_error_bound']:.3g} | "
              f"{100 * tu[0]:.2f} % / {100 * ho[0]:.2f} % | {tu[1]:.2f} / {ho[1]:.2f} | {tu[2]:.2f} / {ho[2]:.2f} |",
              flush=True)
    ident.NOISE_QUANTILE = q_identify
    bounds = ident.measurement_error_bounds(cols, fit)          # identify's
    _noise_floor(data, bounds)
    if args.more:
        _more(fmu, cols, fit, bounds["yaw_rate"][0])
    return 0


def _noise_floor(data: dict, bounds: dict) -> None:
    """Per mode, the steady-state width of vy (m/s) that each sensor's error bound alone keeps, at
    zero stiffness and speed mismatch: (-N)^-1 2|J| nu + 2|E| nu (the width dynamics of xi = P x
    with N Metzler, then x = xi + E y), row vy, per measured channel; and E's ay entry in the ay
    row, which LMI (36) forces to >= 1 (N[ay, vy] = A[ay, vy] (1 - E[ay, ay]) >= 0, A[ay, vy] < 0)."""
    nu = np.array([bounds["yaw_rate"][0], bounds["ay"][0]])
    print("\nThe sensors' share of the width (steady state, no stiffness or speed mismatch), per mode:")
    print("| mode | speed (m/s) | vy width from the yaw rate's bound (m/s) | from ay's bound (m/s) "
          "| E[ay, ay] (>= 1 by LMI 36) |\n|---|---|---|---|---|")
    for m in data["modes"]:
        N, E, J = (np.asarray(m[k], float) for k in ("N", "E", "J"))
        w = [float(np.linalg.solve(-N, 2 * np.abs(J[:, q]) * nu[q])[0] + 2 * abs(E[0, q]) * nu[q]) for q in range(2)]
        print(f"| {m['index']} | {m['vx']:.4g} | {w[0]:.2f} | {w[1]:.2f} | {E[2, 1]:.4g} |")


def _more(fmu, cols, fit, yaw_bound: float) -> None:
    """The held-out figures as ay_error_bound alone varies, and with ay low-passed before the
    observer (first order, causal; its bound: the identify quantile of |filtered - zero-phase 5 Hz
    low-pass| on the tuning part)."""
    from scipy.signal import butter, filtfilt, lfilter

    t = cols["t"]
    names = ("t", "delta", "vx", "yaw_rate", "ay", "vy")
    print(f"\nay_error_bound alone (yaw_rate_error_bound {yaw_bound:.4g} rad/s), held-out part:")
    print("| ay_error_bound (m/s²) | vy enclosed | mean vy width (m/s) | restarts per minute |\n|---|---|---|---|")
    for ab in (1.0, 2.0, 3.0, 4.0):
        ho = scores(rp.drive(fmu, {k: cols[k] for k in names},
                             parameters={"yaw_rate_error_bound": yaw_bound, "ay_error_bound": ab}), t)["held-out"]
        print(f"| {ab:g} | {100 * ho[0]:.2f} % | {ho[1]:.2f} | {ho[2]:.2f} |", flush=True)
    dt = float(np.median(np.diff(t)))
    b, a = butter(2, min(ident.NOISE_CUTOFF_HZ * 2.0 * dt, 0.4))
    ay = np.asarray(cols["ay"], float)
    ref = filtfilt(b, a, ay)
    print("\nay low-passed before the observer (first order), held-out part:")
    print("| cutoff (Hz) | ay_error_bound (m/s²) | of it, the filtered noise alone (m/s²) | vy enclosed "
          "| mean vy width (m/s) | restarts per minute |\n|---|---|---|---|---|---|")
    for fc in (2.0, 3.0, 5.0, 8.0, 12.0):
        p = np.exp(-2 * np.pi * fc * dt)
        ayf = lfilter([1 - p], [1, -p], ay - ay[0]) + ay[0]
        ab = float(np.quantile(np.abs(ayf - ref)[fit], ident.NOISE_QUANTILE))
        noise = float(np.quantile(np.abs(lfilter([1 - p], [1, -p], ay - ref))[fit], ident.NOISE_QUANTILE))
        c = {**{k: cols[k] for k in names}, "ay": ayf}
        ho = scores(rp.drive(fmu, c, parameters={"yaw_rate_error_bound": yaw_bound, "ay_error_bound": ab}),
                    t)["held-out"]
        print(f"| {fc:g} | {ab:.3g} | {noise:.3g} | {100 * ho[0]:.2f} % | {ho[1]:.2f} | {ho[2]:.2f} |", flush=True)


if __name__ == "__main__":
    raise SystemExit(main())
