"""Paper 001's guarantee in floating point: every bound the runtime publishes contains the EXACT value.

The truth here is not a double-precision simulation with a tolerance: it is the plant family the
runtime certifies, x' = (A0 + vx A1) x + vx B1 delta + [0, 0, k3 (p + q), k4f p - k4r q] (p = dcf
(vx delta - x1 - lf x2), q = dcr (-x1 + lr x2), the tables' doubles read as exact numbers), stepped
exactly with inputs held (mpmath, 40 digits: its own error ~1e-38). The measurements given to the
observer are the doubles nearest to the exact y, so the measurement-error bounds are set just above
half an ulp of |y| (a measurement rounded to a double IS an error). Zero tolerance: a bound that
excludes the exact value by any amount fails, including with the true state on the initial box's
edge (where the bounds were once 1.7e-12 N short of the exact force).
"""
from __future__ import annotations

import copy
import math

import mpmath as mp
import pytest

from latobs.fmu_src.lateral_interval_observer import IntervalObserver
from latobs.synthesis.tables import lateral_interval_observer as tables

mp.mp.dps = 40
NU = (1e-15, 1e-14)     # > half an ulp of |r| < 4 rad/s and |ay| < 32 m/s^2


def _plant(tb, vx: float, dcf: float, dcr: float):
    """(A, b) exact (mpmath) of the plant family at speed vx and stiffness deviations (dcf, dcr): x' =
    A x + b delta."""
    md, sk = tb["model"], tb["stiffness"]
    f = mp.mpf
    v = f(vx)
    A = mp.matrix(4, 4)
    b = mp.matrix(4, 1)
    for i in range(4):
        for j in range(4):
            A[i, j] = f(md["A0"][i][j]) + v * f(md["A1"][i][j])
        b[i] = v * f(md["B1"][i])
    lf, lr, k3, k4f, k4r = (f(sk[k]) for k in ("lf", "lr", "k3", "k4f", "k4r"))
    cf, cr = f(dcf), f(dcr)
    p = [-cf, -cf * lf]           # p = cf (v delta - x1 - lf x2): x-part (x1, x2) and delta-part
    q = [-cr, cr * lr]            # q = cr (-x1 + lr x2)
    for j in range(2):
        A[2, j] += k3 * (p[j] + q[j])
        A[3, j] += k4f * p[j] - k4r * q[j]
    b[2] += k3 * cf * v
    b[3] += k4f * cf * v
    return A, b


def _step_map(A, b, h: float):
    """(Phi, gam): x(t + h) = Phi x(t) + gam delta, exactly (exp of [[A, b], [0, 0]] h)."""
    M = mp.matrix(5, 5)
    for i in range(4):
        for j in range(4):
            M[i, j] = A[i, j] * mp.mpf(h)
        M[i, 4] = b[i] * mp.mpf(h)
    E = mp.expm(M)
    return E[:4, :4], E[:4, 4]


def _forces(md, x3, x4):
    f = mp.mpf
    L = f(md["lf"]) + f(md["lr"])
    return ((f(md["m"]) * f(md["lr"]) * x3 + f(md["Iz"]) * x4) / L,
            (f(md["m"]) * f(md["lf"]) * x3 - f(md["Iz"]) * x4) / L)


def _run(design, h: float, steps: int, corner, x0_edge, speeds, seed: int):
    """Steps of the runtime beside the exact plant; a list of (where, lower, exact, upper) that fail."""
    d = copy.deepcopy(design)
    d["runtime"]["y_error_bound"] = list(NU)
    tb = tables.compute(d)
    obs = IntervalObserver({**d, "tables": tb}, {})
    sk, md = tb["stiffness"], tb["model"]
    dcf, dcr = sk["dcf"][corner[0]], sk["dcr"][corner[1]]
    w0 = tb["x0_halfwidth"]
    # the truth at a corner of the initial box: vy and x4 at +-x0_halfwidth, r and ay at the measured
    # doubles -+ nu (the edges of [y - nu, y + nu])
    y0 = (0.05, 1.0)
    x = mp.matrix([x0_edge[0] * w0[0], mp.mpf(y0[0]) + x0_edge[0] * mp.mpf(NU[0]),
                   mp.mpf(y0[1]) + x0_edge[1] * mp.mpf(NU[1]), x0_edge[1] * w0[3]])
    maps = {}
    bad = []

    def check(k, vx):
        out, box = obs.y, obs.box
        Fyf, Fyr = _forces(md, x[2], x[3])
        truth = {"vy": x[0], "yaw_rate": x[1], "Fyf": Fyf, "Fyr": Fyr, "beta": mp.atan(x[0] / mp.mpf(vx))}
        for name, val in truth.items():
            lo, hi = out[f"{name}_lower"], out[f"{name}_upper"]
            if not (mp.mpf(lo) <= val <= mp.mpf(hi)):
                bad.append((k, name, lo, float(val), hi))
        for i in range(4):
            if not (mp.mpf(box[i]) <= x[i] <= mp.mpf(box[4 + i])):
                bad.append((k, f"x{i + 1}", box[i], float(x[i]), box[4 + i]))

    def delta(k):
        t = k * h
        return 0.03 * math.sin(2 * math.pi * 0.5 * t + seed) + 0.01 * math.sin(2 * math.pi * 2.3 * t)

    def vx_at(k):
        return speeds[min(len(speeds) - 1, k * len(speeds) // steps)]

    obs.initialize({"delta": delta(0), "vx": vx_at(0), "yaw_rate": y0[0], "ay": y0[1]})
    check(-1, vx_at(0))
    for k in range(steps):
        vx, dl = vx_at(k), delta(k)
        obs.step(h, {"delta": dl, "vx": vx, "yaw_rate": float(x[1]), "ay": float(x[2])})
        if vx not in maps:
            maps[vx] = _step_map(*_plant(tb, vx, dcf, dcr), h)
        Phi, gam = maps[vx]
        x = Phi * x + gam * mp.mpf(dl)
        assert obs.y["consistent"] == 1, (k, obs.events)
        check(k, vx)
    return bad, obs


@pytest.fixture(scope="module")
def design(built_fmus) -> dict:
    return copy.deepcopy(built_fmus.design("LateralIntervalObserver"))


@pytest.mark.parametrize("corner", [(0, 0), (0, 1), (1, 0), (1, 1)])
def test_bounds_contain_the_exact_state_from_the_initial_box_edge(design, corner):
    """The stiffness at each corner of its box, the true vy and x4 on the initial box's edges, the
    speed stepping through the three bands, default step: no bound excludes the exact value."""
    edge = (1.0 if corner[0] else -1.0, -1.0 if corner[1] else 1.0)
    bad, obs = _run(design, 0.005, 360, corner, edge, (11.0, 14.5, 18.0), seed=corner[0] + 2 * corner[1])
    assert bad == [], bad[:5]
    assert not any(e[0] == "warning" for e in obs.events), obs.events


@pytest.mark.parametrize("h", [0.02, 0.05])
def test_bounds_contain_the_exact_state_with_long_steps(design, h):
    """Steps with enclosure substeps (20 ms) and with the sampled-measurement correction (50 ms)."""
    bad, obs = _run(design, h, int(round(3.0 / h)), (1, 0), (1.0, 1.0), (12.0, 17.0), seed=3)
    assert bad == [], bad[:5]


def test_the_check_sees_a_rounding_error(design, monkeypatch):
    """The check above has teeth: the same run with the runtime's outward rounding switched off
    (round to nearest, no margins) excludes the exact value somewhere."""
    from latobs.fmu_src import lateral_interval_observer as io

    monkeypatch.setattr(io, "_na", lambda x, direction: x)
    monkeypatch.setattr(io, "_radius", lambda t, a, e, n: t)
    monkeypatch.setattr(io, "_outward_sum", lambda t1, t2, side: t1 + t2)
    monkeypatch.setattr(io, "_outward_atan", lambda q, side: math.atan(q))
    found = []
    for corner in ((0, 0), (0, 1), (1, 0), (1, 1)):
        edge = (1.0 if corner[0] else -1.0, -1.0 if corner[1] else 1.0)
        found += _run(design, 0.005, 40, corner, edge, (11.0,), seed=0)[0]
    assert found


def test_the_consistency_tolerance_is_a_few_ulps():
    """A measurement outside the bounds is an inconsistency unless the gap is a few ulps of (1 + |y|)."""
    assert tables.TUNING["consistency_tol"] <= 8 * 2.0 ** -52


def test_design_residuals_are_bounded_exactly(design):
    """rho1..3 bound the exact residuals of eq. (30)/(33) for the doubles stored (checked here in
    mpmath at 60 digits, independently of the tables' rational arithmetic), and they are tiny."""
    tb = tables.compute(design)
    with mp.workdps(60):
        for m in tb["modes"]:
            f = mp.mpf
            P, N, J, E = (mp.matrix([[f(x) for x in row] for row in m[k]]) for k in ("P", "N", "J", "E"))
            A = mp.matrix([[f(a) + f(m["vx"]) * f(b) for a, b in zip(r0, r1)]
                           for r0, r1 in zip(tb["model"]["A0"], tb["model"]["A1"])])
            Bj = mp.matrix([f(m["vx"]) * f(b) for b in tb["model"]["B1"]])
            C = mp.matrix([[0, 1, 0, 0], [0, 0, 1, 0]])
            R1 = P * A - N * P - J * C
            R2 = P * Bj - mp.matrix([f(x) for x in m["H"]])
            R3 = mp.eye(4) - E * C - P
            for R, rho in zip((R1, R2, R3), m["residual"]):
                norm = max(sum(abs(R[i, j]) for j in range(R.cols)) for i in range(R.rows))
                assert norm <= rho <= norm * (1 + 1e-15) + 1e-300
            scale = max(abs(x) for row in m["N"] for x in row)
            assert m["residual"][0] <= 1e-12 * scale


# -- the pieces, each against exact arithmetic ----------------------------------------------------
def _mp_phi_gamma(N, h, order):
    n = len(N)
    M = mp.zeros((order + 1) * n)
    for i in range(n):
        for j in range(n):
            M[i, j] = mp.mpf(N[i][j]) * mp.mpf(h)
        for b in range(1, order + 1):
            M[(b - 1) * n + i, b * n + i] = mp.mpf(h)
    E = mp.expm(M)
    return [[[E[i, b * n + j] for j in range(n)] for i in range(n)] for b in range(order + 1)]


@pytest.mark.parametrize("h", [0.001, 0.005, 0.05, 0.3])
def test_phi_gamma_brackets_contain_the_exact_maps(design, h):
    """phi_gamma's e: |map - exact| <= e for every entry of Phi, Gam, Gam1, Gam2 of every mode, and
    e is within a small factor of the doubles' own resolution at the default step."""
    from latobs.fmu_src.linalg import phi_gamma

    tb = tables.compute(design)
    for m in tb["modes"]:
        *maps, e = phi_gamma(m["N"], h, m["eta"], order=3, with_error=True)
        exact = _mp_phi_gamma(m["N"], h, 3)
        worst = max(abs(mp.mpf(maps[b][i][j]) - exact[b][i][j]) for b in range(4) for i in range(4) for j in range(4))
        assert worst <= e
        big = max(abs(x) for M in maps for row in M for x in row)
        if h == 0.005:
            assert e <= 1e-13 * big


def test_sampled_maps_brackets_contain_the_exact_maps(design):
    """The sampled correction's maps at a model speed: phi[m] = exp(A m hs), gamb[m], pg[m] within
    their brackets of the exact values (mpmath)."""
    tb = tables.compute(design)
    obs = IntervalObserver({**design, "tables": tb}, {})
    vx, h = 14.0, 0.04
    n, hs, phi, aphi, gamb, pg, apg, gains, ephi, egamb, epg, eapg = obs._sampled_maps(vx, h)
    assert n * hs == h
    md = tb["model"]
    A = mp.matrix([[mp.mpf(a) + mp.mpf(vx) * mp.mpf(b) for a, b in zip(r0, r1)]
                   for r0, r1 in zip(md["A0"], md["A1"])])
    Bv = mp.matrix([mp.mpf(vx) * mp.mpf(b) for b in md["B1"]])
    M = mp.zeros(8)
    for i in range(4):
        for j in range(4):
            M[i, j] = A[i, j] * mp.mpf(hs)
        M[i, 4 + i] = mp.mpf(hs)
    E = mp.expm(M)
    Phi1, Gam1 = E[:4, :4], E[:4, 4:]
    P = mp.eye(4)
    G = mp.zeros(4, 1)
    for m in range(n + 1):
        assert max(abs(mp.mpf(phi[m][i][j]) - P[i, j]) for i in range(4) for j in range(4)) <= ephi[m]
        assert max(abs(mp.mpf(gamb[m][i]) - G[i]) for i in range(4)) <= egamb[m]
        if m < n:
            PG = P * Gam1
            assert max(abs(mp.mpf(pg[m][i][j]) - PG[i, j]) for i in range(4) for j in range(4)) <= epg[m]
        G = G + P * Gam1 * Bv
        P = P * Phi1
    assert ephi[n] <= 1e-9 * max(abs(x) for row in phi[n] for x in row)


def _rhs_violations(design, seed: int, runs: int = 300) -> list:
    """F over point boxes [x, x] against the exact A(vx, c) x + B(vx, c) d (rationals) at every corner
    of the stiffness box: the (row, exact, lower, upper) outside."""
    import random
    from fractions import Fraction as Fr

    tb = tables.compute(design)
    obs = IntervalObserver({**design, "tables": tb}, {})
    md, sk = tb["model"], tb["stiffness"]
    rng = random.Random(seed)
    bad = []
    for _ in range(runs):
        x = [rng.uniform(-3, 3), rng.uniform(-1, 1), rng.uniform(-10, 10), rng.uniform(-40, 40)]
        vx, d = rng.uniform(5, 30), rng.uniform(-0.1, 0.1)
        f = obs.F(vx, d, x + x)
        X, V, D = [Fr(v) for v in x], Fr(vx), Fr(d)
        for dcf in sk["dcf"]:
            for dcr in sk["dcr"]:
                p = Fr(dcf) * (V * D - X[0] - Fr(sk["lf"]) * X[1])
                q = Fr(dcr) * (-X[0] + Fr(sk["lr"]) * X[1])
                extra = [0, 0, Fr(sk["k3"]) * (p + q), Fr(sk["k4f"]) * p - Fr(sk["k4r"]) * q]
                for i in range(4):
                    exact = sum((Fr(md["A0"][i][j]) + V * Fr(md["A1"][i][j])) * X[j] for j in range(4)) \
                        + V * Fr(md["B1"][i]) * D + extra[i]
                    if not Fr(f[i]) <= exact <= Fr(f[4 + i]):
                        bad.append((i, float(exact), f[i], f[4 + i]))
    return bad


@pytest.mark.parametrize("seed", range(3))
def test_rhs_hull_contains_the_exact_value_on_point_boxes(design, seed):
    """F over a point box: the exact value at every stiffness corner inside, no tolerance (a point
    box leaves no slack for rounding; round to nearest without margins fails here hundreds of times:
    ``test_the_point_box_check_sees_a_rounding_error``)."""
    assert tables.compute(design)["model"]["w"] == [0.0] * 4      # no disturbance bound: no slack
    bad = _rhs_violations(design, seed)
    assert bad == [], bad[:5]


def test_the_point_box_check_sees_a_rounding_error(design, monkeypatch):
    from latobs.fmu_src import lateral_interval_observer as io

    monkeypatch.setattr(io, "_na", lambda x, direction: x)
    monkeypatch.setattr(io, "_radius", lambda t, a, e, n: t)
    assert len(_rhs_violations(design, 0, 50)) > 10
