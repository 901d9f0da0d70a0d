"""Certificate of the sideslip fixed-order estimator (paper 002: a fixed-order transfer function
y/x per speed band): the plant coefficients re-derived from the state-space model, the coefficient
polytope from its box corners, every worst case by a plain frequency sweep. What is checked and
why: ``docs/certificates.md``.
"""
from __future__ import annotations

import itertools
import math

import numpy as np

from ..params import parse_vehicle
from .checks import REL_TOL, Check, _le


def _bicycle_coefficients_002(m, Iz, lf, lr, Cf, Cr, v):
    """(b1, b2, a) ascending, a monic, of beta/delta and r/delta, derived here from the state-space
    force equations in (vy, r) and ``scipy.signal.ss2tf`` (independent of the design module's
    closed form): m (vy' + v r) = Fyf + Fyr, Iz r' = lf Fyf - lr Fyr, Fyf = Cf (delta - (vy + lf r)/v),
    Fyr = Cr (lr r - vy)/v, beta = vy / v."""
    import scipy.signal
    A = np.array([[-(Cf + Cr) / (m * v), (lr * Cr - lf * Cf) / (m * v) - v],
                  [(lr * Cr - lf * Cf) / (Iz * v), -(lf ** 2 * Cf + lr ** 2 * Cr) / (Iz * v)]])
    B = np.array([[Cf / m], [lf * Cf / Iz]])
    C = np.array([[1.0 / v, 0.0], [0.0, 1.0]])
    num, den = scipy.signal.ss2tf(A, B, C, np.zeros((2, 1)))
    den = np.asarray(den, float)
    num = np.asarray(num, float) / den[0]
    den = den / den[0]
    # descending (s^2, s, 1) -> ascending; the s^2 terms of num are 0 (strictly proper)
    return num[0][::-1][:2], num[1][::-1][:2], den[::-1]


def _weighted_error_002(b1, b2, a, y, x, W1, W2, w):
    """|W1 W2 (b1 - b2 y/x)/a| (jw) for plant rows (N, .) and frequencies w: (N, W)."""
    s = 1j * np.asarray(w, float)
    pv = lambda c: np.polyval(np.asarray(c, float)[::-1], s)
    Wt = pv(W1["num"]) / pv(W1["den"]) * pv(W2["num"]) / pv(W2["den"])
    k = pv(y) / pv(x)
    rows = lambda M: np.array([np.polyval(np.asarray(c, float)[::-1], s) for c in M])
    return np.abs(Wt * (rows(b1) - rows(b2) * k) / rows(a))


def _peak_002(b1, b2, a, y, x, W1, W2, wmin=1e-5, wmax=1e3, n=4000):
    """Worst |G(jw)| over the plants: a dense log sweep plus w = 0, then a 400-point linear
    re-sweep between the neighbours of the largest sample (a plain sweep, no optimiser)."""
    w = np.concatenate([[0.0], np.logspace(math.log10(wmin), math.log10(wmax), n)])
    M = _weighted_error_002(b1, b2, a, y, x, W1, W2, w)
    i, j = np.unravel_index(int(np.argmax(M)), M.shape)
    lo, hi = w[max(j - 1, 0)], w[min(j + 1, len(w) - 1)]
    fine = _weighted_error_002(b1[i:i + 1], b2[i:i + 1], a[i:i + 1], y, x, W1, W2, np.linspace(lo, hi, 400))
    return float(max(M.max(), fine.max()))


def certify(d: dict) -> list[Check]:
    """The checks of a paper-002 design file, independent of Lemma 5 and of the design module
    (``docs/certificates.md``)."""
    checks: list[Check] = []
    vehicle = parse_vehicle(d["vehicle"], f"design file {d['name']}")
    par = vehicle.require(("m", "Iz", "lf", "lr"), f"certificate of {d['name']} (bicycle model, eq. 2)")
    model = d.get("model", {})
    checks.append(_le("bicycle model m, Iz, lf, lr = the design file's vehicle (max relative difference)",
                      max(abs(float(model.get(k, math.nan)) - par[k]) / par[k] for k in par)
                      if all(k in model for k in par) else math.inf, 1e-9))
    m, Iz, lf, lr = (float(par[k]) for k in ("m", "Iz", "lf", "lr"))
    W1, W2 = d["weights"]["W1"], d["weights"]["W2"]
    grid = tuple(int(k) for k in d.get("certificate_grid", (9, 9, 9)))
    ests = d["estimators"] if d.get("scheduled") else [d["estimator"]]
    if len(ests) != len(d["modes"]):
        checks.append(_le("runtime estimators match the modes (count difference)",
                          abs(len(ests) - len(d["modes"])), 0))
        return checks
    for mode, est in zip(d["modes"], ests):
        where = f"mode {mode['index']} (v in [{mode['box']['v'][0]:.4g}, {mode['box']['v'][1]:.4g}] m/s)"
        y, x = np.asarray(est["num"], float), np.asarray(est["den"], float)
        same = max(float(np.max(np.abs(np.asarray(mode["estimator"][k], float) - np.asarray(est[k], float))))
                   for k in ("num", "den")) if all(len(mode["estimator"][k]) == len(est[k]) for k in ("num", "den")) \
            else math.inf
        checks.append(_le(f"runtime estimator = the mode's estimator (max coefficient difference), {where}", same, 0.0))
        xr = float(np.max(np.roots(x[::-1]).real)) if len(x) > 1 else -math.inf
        checks.append(_le(f"estimator denominator x(s) Hurwitz (max Re root), {where}", xr, -1e-9))
        cf, cr, vv = mode["box"]["Cf"], mode["box"]["Cr"], mode["box"]["v"]
        corners = [_bicycle_coefficients_002(m, Iz, lf, lr, a_, b_, c_) for a_ in cf for b_ in cr for c_ in vv]
        flat = lambda t: np.concatenate([t[0], t[1], t[2][:2]])        # b1_0 b1_1 b2_0 b2_1 a_0 a_1
        C = np.array([flat(t) for t in corners])
        lo, hi = C.min(axis=0), C.max(axis=0)
        verts = np.array([[(lo, hi)[p][k] for k, p in enumerate(pick)] for pick in itertools.product((0, 1), repeat=6)])
        vb1, vb2 = verts[:, 0:2], verts[:, 2:4]
        va = np.column_stack([verts[:, 4:6], np.ones(len(verts))])
        axes = [np.linspace(lo_, hi_, k) for (lo_, hi_), k in zip((cf, cr, vv), grid)]
        pts = list(itertools.product(*axes))
        gt = [_bicycle_coefficients_002(m, Iz, lf, lr, *p) for p in pts]
        gb1, gb2, ga = (np.array([t[i] for t in gt]) for i in range(3))
        G = np.array([flat(t) for t in gt])
        tol = 1e-9 * np.maximum(np.abs(lo), np.abs(hi))
        outside = float(np.max(np.maximum(lo - tol - G, G - hi - tol).clip(min=0)))
        checks.append(_le(f"coefficient polytope contains the grid's true plants (max excess), {where}", outside, 0.0))
        for tag, (b1, b2, a), claim in (("64 polytope vertices", (vb1, vb2, va), mode["gamma_vertex"]),
                                        (f"{len(pts)} true plants on the grid", (gb1, gb2, ga), mode["gamma_grid"])):
            # a monic quadratic is Hurwitz iff its two lower coefficients are > 0
            worst_plant = float(-np.min(a[:, :2]))
            checks.append(_le(f"plants stable ({tag}): -min(a_0, a_1), {where}", worst_plant, 0.0))
            g = _peak_002(b1, b2, a, y, x, W1, W2) if worst_plant < 0 and xr < 0 else math.inf
            checks.append(_le(f"worst weighted H-inf error over the {tag} <= claimed, {where}", g,
                              float(claim) * (1 + REL_TOL)))
            checks.append(_le(f"claimed worst case over the {tag} is tight (relative gap), {where}",
                              abs(float(claim) - g) / max(g, 1e-300) if math.isfinite(g) else math.inf, 1e-2))
    checks.append(_le("gamma = max over the modes of the vertex worst case (difference)",
                      abs(d["gamma"] - max(mm["gamma_vertex"] for mm in d["modes"])), 0.0))
    checks.append(_le("gamma_grid = max over the modes of the grid worst case (difference)",
                      abs(d["gamma_grid"] - max(mm["gamma_grid"] for mm in d["modes"])), 0.0))
    if d.get("scheduled"):
        bands = [e["vx_band"] for e in ests]
        gap = max([abs(b1_[0] - b0[1]) for b0, b1_ in zip(bands, bands[1:])] + [0.0])
        checks.append(_le("speed bands contiguous (max gap or overlap, m/s)", gap, 0.0))
        rv = d["vehicle"].get("ranges", {}).get("speed")
        if rv:
            k = {"m/s": 1.0, "km/h": 1 / 3.6}.get(rv.get("unit", "m/s"), 1.0)
            cover = max(bands[0][0] - k * rv["min"], k * rv["max"] - bands[-1][1], 0.0)
            checks.append(_le("speed bands cover the vehicle's speed range (uncovered, m/s)", cover, 0.0))
        checks.append(_le("each mode's box speed range = its band (max difference, m/s)",
                          max(abs(e["vx_band"][i] - mm["box"]["v"][i]) for e, mm in zip(ests, d["modes"])
                              for i in (0, 1)), 0.0))
    return checks


def summary(data: dict) -> dict:
    """Headline figures of a certified design (for notes and reports)."""
    return {"gamma": data["gamma"], "gamma_grid": data["gamma_grid"],
            "per_mode": [{"mode": m["index"], "vx_band": m["vx_band"], "gamma_lmi": m["gamma_lmi"],
                          "gamma_vertex": m["gamma_vertex"], "gamma_grid": m["gamma_grid"],
                          "grid_dc_floor": m["grid_dc_floor"], "estimator": m["estimator"]}
                         for m in data["modes"]]}
