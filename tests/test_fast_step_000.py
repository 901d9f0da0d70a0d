"""Paper-000 runtime: the compiled step maps equal classical RK4 substeps to 1e-12.

The reference below is independent of the runtime: numpy, eq. (5) written out from the design
file's T, N, C, K_P, K_I and the 1/Vx coefficient lists of A, B, F, integrated by classical RK4
with the runtime's substeps (n = ceil(h / max_step), inputs held), with the documented mode
selection, clamps and hold.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from latobs.fmu_src import pi_observer
from latobs.fmu_src.pi_observer import SwitchedPIObserver

OUT = ("beta_hat", "yaw_rate_hat", "roll_angle_hat", "roll_rate_hat", "bank_angle_hat")


class ReferenceObserver:
    """Eq. (5) of paper 000 with classical RK4 substeps, numpy."""

    def __init__(self, design: dict):
        st = design["structure"]
        self.T, self.N, self.C = (np.asarray(st[k], dtype=float) for k in ("T", "N", "C"))
        self.design = design
        self.sw = design["switching"]
        self.max_step = float(design["runtime"]["max_step"])
        self.vx_hold = float(design["runtime"]["vx_hold"])
        if self.sw["kind"] == "speed_bands":
            self.lo, self.hi = self.sw["edges"][0], self.sw["edges"][-1]
        else:
            self.lo, self.hi = design["modes"][0]["model_speed"]["range"]
        self.z, self.w, self.mode, self.started = np.zeros(4), 0.0, 0, False
        self.y = {}

    def model(self, i: int, vx: float):
        """A, B, F of mode i at speed vx from the stored coefficient lists (sum_k M_k vx**-k)."""
        coeffs = self.design["modes"][i]["model"]
        return tuple(sum(np.asarray(Mk, dtype=float) * vx**-k for k, Mk in enumerate(coeffs[key]))
                     for key in ("A", "B", "F"))

    def xhat(self, y):
        return self.z + self.N @ y

    def publish(self, y):
        xh = self.xhat(y)
        self.y = dict(zip(OUT[:4], xh), bank_angle_hat=self.w, mode=self.mode + 1)

    def step(self, h: float, u: dict):
        vx, delta = u["vx"], u["delta"]
        y = np.array([u["yaw_rate"], u["roll_angle"], u["roll_rate"]])
        if not self.started:           # initialize: x^ = [0, y], mode of the initial speed
            self.z = np.concatenate([[0.0], y]) - self.N @ y
            self.started = True
            if self.sw["kind"] == "speed_bands" and vx >= self.vx_hold:
                self.mode = self.band(vx)
            self.publish(y)
        if vx < self.vx_hold:          # frozen (standstill or reversing): every output held
            return
        if self.sw["kind"] == "speed_bands":
            self.mode = self.band(vx)
            model_speed = self.design["modes"][self.mode]["model_speed"]["value"]
        else:
            xh = self.xhat(y)
            a_f = delta - xh[0] - self.sw["lf"] * xh[1] / vx
            a_r = -xh[0] + self.sw["lr"] * xh[1] / vx
            premise = max(abs(a_f), abs(a_r))
            if self.mode == 0 and premise > self.sw["alpha_star"] + self.sw["hysteresis"]:
                self.mode = 1
            elif self.mode == 1 and premise < self.sw["alpha_star"] - self.sw["hysteresis"]:
                self.mode = 0
            model_speed = min(max(vx, self.lo), self.hi)
        A, B, F = self.model(self.mode, model_speed)
        gains = self.design["modes"][self.mode]["gains"]
        KP, KI = np.asarray(gains["K_P"], dtype=float), np.asarray(gains["K_I"], dtype=float)
        T, N, C = self.T, self.N, self.C

        def f(z, w):
            xh = z + N @ y
            innov = y - C @ xh
            dz = T @ A @ xh + (T @ B)[:, 0] * delta + (T @ F)[:, 0] * w + KP @ innov
            return dz, float((KI @ innov)[0])

        n = max(1, math.ceil(h / self.max_step - 1e-9))
        hs = h / n
        z, w = self.z, self.w
        for _ in range(n):
            k1 = f(z, w)
            k2 = f(z + hs / 2 * k1[0], w + hs / 2 * k1[1])
            k3 = f(z + hs / 2 * k2[0], w + hs / 2 * k2[1])
            k4 = f(z + hs * k3[0], w + hs * k3[1])
            z = z + hs / 6 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
            w = w + hs / 6 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
        self.z, self.w = z, w
        self.publish(y)

    def band(self, vx):
        edges = self.sw["edges"]
        for i in range(len(edges) - 1):
            if edges[i] <= vx < edges[i + 1]:
                return i
        return 0 if vx < edges[0] else len(edges) - 2


def measurements(t: float, steer: float) -> dict:
    """Smooth synthetic measurements of order 0.01..0.3 (not a vehicle: exactness only)."""
    return {"delta": steer * math.sin(1.7 * t) + 0.004 * math.sin(5.3 * t),
            "yaw_rate": 0.2 * math.sin(1.7 * t + 0.4) + 0.05 * math.sin(0.37 * t),
            "roll_angle": 0.03 * math.sin(1.7 * t + 0.9) + 0.01,
            "roll_rate": 0.05 * math.cos(1.7 * t + 0.9)}


def speed_run():
    """(h, u) over 5 ms, then 2 ms, then 10 ms: all three speed bands in each, excursions above
    and below the grid, and one dip below vx_hold."""
    out, t = [], 0.0
    for h, n in ((0.005, 1600), (0.002, 2000), (0.010, 800)):
        for k in range(n):
            phase = k / n
            vx = 18.0 + 13.0 * math.cos(2 * math.pi * phase)        # 31 .. 5 .. 31 m/s
            if h == 0.002 and 0.70 < phase < 0.71:
                vx = 0.5                                            # frozen, then resumes
            out.append((h, dict(measurements(t, 0.02), vx=vx)))
            t += h
    return out


def tire_run():
    """(h, u) over 5 ms, 2 ms, 10 ms: in each, the speed varies continuously over 10..25 m/s with
    excursions to 8 and 27 m/s, and the steering drives the slip premise across alpha* both ways."""
    out, t = [], 0.0
    for h, n in ((0.005, 2400), (0.002, 2500), (0.010, 1200)):
        for k in range(n):
            phase = k / n
            vx = 17.5 + 9.0 * math.sin(2 * math.pi * phase) + 0.5 * math.sin(14 * math.pi * phase)
            steer = 0.03 * (0.5 + 0.5 * math.sin(2 * math.pi * 3 * phase)) ** 2
            out.append((h, dict(measurements(t, steer), vx=vx)))
            t += h
    return out


def compare(design: dict, run) -> tuple[float, set, list]:
    rt, ref = SwitchedPIObserver(design, {}), ReferenceObserver(design)
    worst, modes, speeds = 0.0, set(), []
    for i, (h, u) in enumerate(run):
        rt.step(h, u)
        ref.step(h, u)
        assert rt.y["mode"] == ref.y["mode"], f"step {i}: mode {rt.y['mode']} != {ref.y['mode']}"
        for k in OUT:
            err = abs(rt.y[k] - ref.y[k]) / max(1.0, abs(ref.y[k]))
            worst = max(worst, err)
        modes.add(rt.y["mode"])
        speeds.append(u["vx"])
    return worst, modes, speeds


def clear_cache():
    pi_observer._MAPS.clear()
    pi_observer._HELD[0] = 0


@pytest.fixture
def empty_cache():
    """The runtime's map cache is shared by the instances of a process: start from empty."""
    clear_cache()
    yield
    clear_cache()


def test_speed_modes_equal_rk4_substeps(design_speed, empty_cache):
    worst, modes, speeds = compare(design_speed, speed_run())
    assert modes == {1, 2, 3}
    edges = design_speed["switching"]["edges"]
    assert min(speeds) < edges[0] and max(speeds) > edges[-1]       # clamped excursions
    assert worst <= 1e-12, worst


def test_tire_modes_equal_rk4_substeps(design_tire, empty_cache):
    worst, modes, speeds = compare(design_tire, tire_run())
    assert modes == {1, 2}
    lo, hi = design_tire["modes"][0]["model_speed"]["range"]
    assert min(speeds) < lo and max(speeds) > hi
    assert worst <= 1e-12, worst
    # the tables in use are Taylor polynomials (not the RK4 fallback) of bounded degree
    tables = [m for m in pi_observer._MAPS.values() if isinstance(m, pi_observer._TireTable)]
    assert len(tables) == 6
    fns = [f for tab in tables for f in tab.fns if f is not None]
    assert fns and all(getattr(f, "degree", 99) <= SwitchedPIObserver.TAYLOR_DEGREE + 1 for f in fns)


def test_each_step_map_is_built_once(design_speed, empty_cache, monkeypatch):
    calls = []
    real = pi_observer._compile
    monkeypatch.setattr(pi_observer, "_compile", lambda *a, **k: calls.append(1) or real(*a, **k))
    rt = SwitchedPIObserver(design_speed, {})
    for k in range(3000):
        rt.step(0.005, dict(measurements(k * 0.005, 0.02), vx=18.0 + 13.0 * math.cos(k / 300)))
    assert len(calls) == 3                                              # one map per mode
    rt2 = SwitchedPIObserver(design_speed, {})                          # same design: shared
    for k in range(600):
        rt2.step(0.005, dict(measurements(k * 0.005, 0.02), vx=18.0 + 13.0 * math.cos(k / 60)))
    assert len(calls) == 3


def _held_consistent() -> bool:
    held = sum(m.built if isinstance(m, pi_observer._TireTable) else 1 for m in pi_observer._MAPS.values())
    return held == pi_observer._HELD[0]


def test_map_cache_stays_bounded_under_many_step_sizes(design_speed, design_tire, empty_cache, monkeypatch):
    rng = np.random.default_rng(0)
    # speed modes, default limits: 400 distinct step sizes, each used twice (so that a map is built)
    rt, ref = SwitchedPIObserver(design_speed, {}), ReferenceObserver(design_speed)
    worst = 0.0
    for i in range(400):
        h = float(rng.uniform(0.0005, 0.02))
        for j in range(2):
            u = dict(measurements(0.01 * i, 0.02), vx=float(rng.uniform(3.0, 32.0)))
            rt.step(h, u)
            ref.step(h, u)
            worst = max(worst, max(abs(rt.y[k] - ref.y[k]) for k in OUT))
        assert len(pi_observer._MAPS) <= SwitchedPIObserver.MAP_CACHE_SIZE
        assert pi_observer._HELD[0] <= SwitchedPIObserver.MAX_COMPILED
        assert len(rt._seen) <= 4 * SwitchedPIObserver.MAP_CACHE_SIZE
    assert len(pi_observer._MAPS) == SwitchedPIObserver.MAP_CACHE_SIZE and _held_consistent()
    assert worst <= 1e-12
    # tire modes with small limits: the number of compiled intervals is bounded too
    monkeypatch.setattr(SwitchedPIObserver, "MAP_CACHE_SIZE", 3)
    monkeypatch.setattr(SwitchedPIObserver, "MAX_COMPILED", 10)
    clear_cache()
    rt, ref = SwitchedPIObserver(design_tire, {}), ReferenceObserver(design_tire)
    worst = 0.0
    for i in range(12):
        h = float(rng.uniform(0.001, 0.006))
        for j in range(6):
            u = dict(measurements(0.03 * (6 * i + j), 0.03), vx=float(rng.uniform(8.0, 27.0)))
            rt.step(h, u)
            ref.step(h, u)
            worst = max(worst, max(abs(rt.y[k] - ref.y[k]) for k in OUT))
            assert len(pi_observer._MAPS) <= 3 and pi_observer._HELD[0] <= 10 and _held_consistent()
    assert worst <= 1e-12


def test_results_do_not_depend_on_what_other_instances_cached(design_tire, empty_cache):
    """Bitwise: an instance that finds every map cached gives what the one that built them gave."""
    run = tire_run()[:3000]                      # 5 ms then 2 ms

    def outputs():
        rt = SwitchedPIObserver(design_tire, {})
        out = []
        for h, u in run:
            rt.step(h, u)
            out.append(tuple(rt.y[k] for k in (*OUT, "mode")))
        return out

    cold = outputs()
    assert pi_observer._MAPS
    assert outputs() == cold
