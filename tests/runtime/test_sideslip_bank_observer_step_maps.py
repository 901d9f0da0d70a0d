"""Paper-000 runtime: the tables' step maps (and the maps built for other steps) equal classical RK4
substeps to 1e-12.

The reference below is independent of the runtime: numpy, eq. (5) written out from the design
file's T, N, C, K_P, K_I and the 1/Vx coefficient lists of A, B, F, integrated by classical RK4
with the runtime's substeps (n = ceil(h / max_step), inputs held), with the documented mode
selection, clamps and hold.
"""
from __future__ import annotations

import copy
import json
import math

import numpy as np
import pytest

from latobs.fmu_src.sideslip_bank_observer import SwitchedPIObserver
from latobs.synthesis import tables
from latobs.synthesis.tables import sideslip_bank_observer as tables_000

OUT = ("beta_hat", "yaw_rate_hat", "roll_angle_hat", "roll_rate_hat", "bank_angle_hat")

KEEP = object()


def variant(design: dict, *, hold=KEEP, validity=KEEP, speeds=KEEP) -> dict:
    """A copy of a paper-000 design dict with the issue-9 keys set explicitly (the tests do not
    depend on what the design side emits by default). hold: runtime.input_hold ("zero_order",
    "first_order", None: key absent); validity: the "validity" dict (None: absent); speeds:
    "fixed" (every speed mode at its grid speed, eq. 25 literally), "measured" (each speed mode's
    model at the measured speed clamped to its own band) or a (lo, hi) range for every mode."""
    d = copy.deepcopy(design)
    if hold is not KEEP:
        d["runtime"] = {k: v for k, v in d["runtime"].items() if k != "input_hold"}
        if hold is not None:
            d["runtime"]["input_hold"] = hold
    if validity is not KEEP:
        d.pop("validity", None)
        if validity is not None:
            d["validity"] = dict(validity)
    if speeds is not KEEP:
        for m in d["modes"]:
            if speeds == "fixed":
                m["model_speed"] = {"kind": "fixed", "value": m["scheduling"]["value"]}
            elif speeds == "measured":
                m["model_speed"] = {"kind": "measured", "range": list(m["scheduling"]["range"])}
            else:
                m["model_speed"] = {"kind": "measured", "range": list(speeds)}
    return d


_TABLES: dict = {}


def with_tables(design: dict) -> dict:
    """A copy of the design with the tables of ITS keys (a variant's own, never those it was copied
    with), cached by content: what ``designs.run`` and the packaging step attach."""
    key = json.dumps({k: design.get(k) for k in ("structure", "modes", "switching", "runtime", "validity")},
                     sort_keys=True, default=lambda o: o.tolist())
    if key not in _TABLES:
        _TABLES[key] = tables.compute(design)
    return dict(design, tables=_TABLES[key])


def observer(design: dict, params: dict | None = None) -> SwitchedPIObserver:
    """The runtime of a design dict (or a variant of one) with its own tables."""
    return SwitchedPIObserver(with_tables(design), params or {})


def legacy(design: dict) -> dict:
    """The design as the runtime read it before issue 9: zero-order hold (key absent), no validity,
    speed modes at their grid speed; tire modes keep their common measured range."""
    fixed = "fixed" if design["switching"]["kind"] == "speed_bands" else KEEP
    return variant(design, hold=None, validity=None, speeds=fixed)


class ReferenceObserver:
    """Eq. (5) of paper 000 with classical RK4 substeps, numpy.

    Model speed per mode: its fixed speed, or the measured speed clamped to the mode's own range.
    Input hold (design runtime.input_hold): zero-order (inputs held over the step) or first-order
    (w(t + tau) = w_k + tau (w_k - w_{k-1}) / h_{k-1}, evaluated at the RK4 stage times; slope 0 at
    the first step and after a frozen period; the outputs use the hold's y at t + h). Validity
    (design "validity"): the slip angles from beta^, r^ at the start of the step and |vx yaw_rate|
    against their limits with the release hysteresis, and vx inside the design grid; while invalid
    with freeze_integral, w^' = 0.
    """

    def __init__(self, design: dict):
        st = design["structure"]
        self.T, self.N, self.C = (np.asarray(st[k], dtype=float) for k in ("T", "N", "C"))
        self.design = design
        self.sw = design["switching"]
        self.max_step = float(design["runtime"]["max_step"])
        self.vx_hold = float(design["runtime"]["vx_hold"])
        self.foh = design["runtime"].get("input_hold", "zero_order") == "first_order"
        self.validity = design.get("validity")
        self.n = self.T.shape[0]          # 4, or 6 with the relaxed axle forces
        self.p0 = int(st.get("first_power", 0))     # the coefficient lists start at vx**-p0
        self.z, self.w, self.mode, self.started = np.zeros(self.n), 0.0, 0, False
        self.prev = None               # first-order hold: (w_{k-1}, h_{k-1})
        self.valid = 1
        self.y = {}

    def model(self, i: int, vx: float):
        """A, B, F of mode i at speed vx from the stored coefficient lists (sum_k M_k vx**-(k + p0))."""
        coeffs = self.design["modes"][i]["model"]
        return tuple(sum(np.asarray(Mk, dtype=float) * vx ** -(k + self.p0) for k, Mk in enumerate(coeffs[key]))
                     for key in ("A", "B", "F"))

    def model_speed(self, i: int, vx: float) -> float:
        ms = self.design["modes"][i]["model_speed"]
        if ms["kind"] == "fixed":
            return ms["value"]
        lo, hi = ms["range"]
        return min(max(vx, lo), hi)

    def xhat(self, y):
        return self.z + self.N @ y

    def publish(self, y):
        xh = self.xhat(y)
        self.y = dict(zip(OUT[:4], xh), bank_angle_hat=self.w, mode=self.mode + 1, valid=self.valid)

    def check_validity(self, xh, vx, delta, yaw_rate):
        v = self.validity
        a_f = delta - xh[0] - v["lf"] * xh[1] / vx
        a_r = -xh[0] + v["lr"] * xh[1] / vx
        alpha, ay = max(abs(a_f), abs(a_r)), abs(vx * yaw_rate)
        # the design grid: the speed bands' ends, or the union of the tire modes' measured ranges
        if self.sw["kind"] == "speed_bands":
            lo, hi = self.sw["edges"][0], self.sw["edges"][-1]
        else:
            ranges = [m["model_speed"]["range"] for m in self.design["modes"]]
            lo, hi = min(r[0] for r in ranges), max(r[1] for r in ranges)
        inside = lo <= vx <= hi
        if self.valid and (alpha > v["alpha_max"] or ay > v["ay_max"] or not inside):
            self.valid = 0
        elif (not self.valid and alpha < v["release"] * v["alpha_max"] and ay < v["release"] * v["ay_max"]
              and inside):
            self.valid = 1

    def step(self, h: float, u: dict):
        vx, delta = u["vx"], u["delta"]
        y = np.array([u["yaw_rate"], u["roll_angle"], u["roll_rate"]])
        if not self.started:           # initialize: x^ = [0, y], mode of the initial speed
            self.z = np.concatenate([[0.0], y, np.zeros(self.n - 4)]) - self.N @ y
            self.started = True
            if self.sw["kind"] == "speed_bands" and vx >= self.vx_hold:
                self.mode = self.band(vx)
            self.publish(y)
        if vx < self.vx_hold:          # frozen (standstill or reversing): every output held
            self.prev = None
            return
        xh = self.xhat(y)
        if self.sw["kind"] == "speed_bands":
            self.mode = self.band(vx)
        else:
            a_f = delta - xh[0] - self.sw["lf"] * xh[1] / vx
            a_r = -xh[0] + self.sw["lr"] * xh[1] / vx
            premise = max(abs(a_f), abs(a_r))
            if self.mode == 0 and premise > self.sw["alpha_star"] + self.sw["hysteresis"]:
                self.mode = 1
            elif self.mode == 1 and premise < self.sw["alpha_star"] - self.sw["hysteresis"]:
                self.mode = 0
        if self.validity is not None:
            self.check_validity(xh, vx, delta, u["yaw_rate"])
        frozen = not self.valid and self.validity is not None and self.validity.get("freeze_integral", False)
        A, B, F = self.model(self.mode, self.model_speed(self.mode, vx))
        gains = self.design["modes"][self.mode]["gains"]
        KP, KI = np.asarray(gains["K_P"], dtype=float), np.asarray(gains["K_I"], dtype=float)
        T, N, C = self.T, self.N, self.C
        w_k = np.concatenate([y, [delta]])
        slope = np.zeros(4)
        if self.foh:
            if self.prev is not None:
                slope = (w_k - self.prev[0]) / self.prev[1]
            self.prev = (w_k, h)

        def f(tau, z, w):
            ww = w_k + tau * slope     # the hold at the stage time
            yy, dd = ww[:3], ww[3]
            xh = z + N @ yy
            innov = yy - C @ xh
            dz = T @ A @ xh + (T @ B)[:, 0] * dd + (T @ F)[:, 0] * w + KP @ innov
            return dz, 0.0 if frozen else float((KI @ innov)[0])

        n = max(1, math.ceil(h / self.max_step - 1e-9))
        hs = h / n
        z, w = self.z, self.w
        for j in range(n):
            t0 = j * hs
            k1 = f(t0, z, w)
            k2 = f(t0 + hs / 2, z + hs / 2 * k1[0], w + hs / 2 * k1[1])
            k3 = f(t0 + hs / 2, z + hs / 2 * k2[0], w + hs / 2 * k2[1])
            k4 = f(t0 + hs, z + hs * k3[0], w + hs * k3[1])
            z = z + hs / 6 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
            w = w + hs / 6 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
        self.z, self.w = z, w
        self.publish(y + h * slope[:3])

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


def tire_run(lo: float = 10.0, hi: float = 25.0):
    """(h, u) over 5 ms, 2 ms, 10 ms: in each, the speed varies continuously over the model range
    lo..hi m/s with excursions 2 m/s beyond both ends, and the steering drives the slip premise
    across alpha* both ways."""
    out, t = [], 0.0
    for h, n in ((0.005, 2400), (0.002, 2500), (0.010, 1200)):
        for k in range(n):
            phase = k / n
            vx = 0.5 * (lo + hi) + (0.5 * (hi - lo) + 1.5) * math.sin(2 * math.pi * phase) \
                + 0.5 * math.sin(14 * math.pi * phase)
            steer = 0.03 * (0.5 + 0.5 * math.sin(2 * math.pi * 3 * phase)) ** 2
            out.append((h, dict(measurements(t, steer), vx=vx)))
            t += h
    return out


def compare(design: dict, run) -> tuple[float, set, list]:
    rt, ref = observer(design), ReferenceObserver(design)
    worst, modes, speeds = 0.0, set(), []
    for i, (h, u) in enumerate(run):
        rt.step(h, u)
        ref.step(h, u)
        assert rt.y["mode"] == ref.y["mode"], f"step {i}: mode {rt.y['mode']} != {ref.y['mode']}"
        assert rt.y["valid"] == ref.y["valid"], f"step {i}: valid {rt.y['valid']} != {ref.y['valid']}"
        for k in OUT:
            err = abs(rt.y[k] - ref.y[k]) / max(1.0, abs(ref.y[k]))
            worst = max(worst, err)
        modes.add(rt.y["mode"])
        speeds.append(u["vx"])
    return worst, modes, speeds


@pytest.mark.parametrize("form", ["legacy", "eq. 1 as designed", "as designed"])
def test_speed_modes_equal_rk4_substeps(design_speed, design_speed_eq1, form):
    """legacy: grid-speed models (eq. 1), inputs held, no validity; as designed: whatever the design
    emits (issue 9: models at the measured speed per band, first-order hold, validity with freeze;
    the default's model with relaxed axle forces, or eq. 1)."""
    design = {"legacy": legacy(design_speed_eq1), "eq. 1 as designed": design_speed_eq1,
              "as designed": design_speed}[form]
    worst, modes, speeds = compare(design, speed_run())
    assert modes == {1, 2, 3}
    edges = design_speed["switching"]["edges"]
    assert min(speeds) < edges[0] and max(speeds) > edges[-1]       # clamped excursions
    assert worst <= 1e-12, worst


@pytest.mark.parametrize("form", ["legacy", "as designed"])
def test_tire_modes_equal_rk4_substeps(design_tire, form):
    design = legacy(design_tire) if form == "legacy" else design_tire
    lo, hi = design["modes"][0]["model_speed"]["range"]
    worst, modes, speeds = compare(design, tire_run(lo, hi))
    assert modes == {1, 2}
    assert min(speeds) < lo and max(speeds) > hi
    assert worst <= 1e-12, worst
    # the tables at the default step are Taylor polynomials (no RK4 fallback) of bounded degree, one
    # per map index (the modes, and the frozen-integral maps if the design has them)
    maps = with_tables(design)["tables"]["maps"]
    assert len(maps) == len(design["modes"]) * (2 if (design.get("validity") or {}).get("freeze_integral") else 1)
    coefs = [iv["coef"] for m in maps for iv in m["intervals"]]
    assert all(c is not None and len(c) <= tables_000.TAYLOR_DEGREE + 2 for c in coefs)


def test_each_step_map_is_built_once(design_speed_eq1, monkeypatch):
    """Fixed model speeds: the default step evaluates the tables (nothing built); another step
    builds each mode's composite map once, in the instance, one step size at a time."""
    calls = []
    real = SwitchedPIObserver.fixed_map
    monkeypatch.setattr(SwitchedPIObserver, "fixed_map", lambda self, *a: calls.append(a) or real(self, *a))
    rt = observer(legacy(design_speed_eq1))                             # grid-speed models: one map per mode
    for k in range(3000):
        rt.step(0.005, dict(measurements(k * 0.005, 0.02), vx=18.0 + 13.0 * math.cos(k / 300)))
    assert calls == []
    for h in (0.002, 0.003, 0.002):
        for k in range(3000):
            rt.step(h, dict(measurements(k * h, 0.02), vx=18.0 + 13.0 * math.cos(k / 300)))
        assert len(rt._fixed) == 3
    assert [a[1] for a in calls] == [0.002] * 3 + [0.003] * 3 + [0.002] * 3


def test_many_step_sizes_equal_rk4_substeps(design_speed, design_speed_eq1, design_tire):
    """Random step sizes, each used twice: composite maps (fixed speeds) and RK4 substeps (measured
    speeds; the default's relaxed model at every step) against the reference; the instance keeps the
    maps of one step size."""
    rng = np.random.default_rng(0)
    for design, n, lo, hi in ((legacy(design_speed_eq1), 400, 3.0, 32.0), (design_tire, 72, 8.0, 27.0),
                              (design_speed, 72, 3.0, 32.0)):
        rt, ref = observer(design), ReferenceObserver(design)
        worst = 0.0
        for i in range(n):
            h = float(rng.uniform(0.0005, 0.02))
            for j in range(2):
                u = dict(measurements(0.01 * i, 0.02), vx=float(rng.uniform(lo, hi)))
                rt.step(h, u)
                ref.step(h, u)
                worst = max(worst, max(abs(rt.y[k] - ref.y[k]) for k in OUT))
            assert rt._map_h in (None, h) and len(rt._fixed) <= len(design["modes"])
        assert worst <= 1e-12


def test_results_do_not_depend_on_other_instances(design_tire):
    """Bitwise: two instances of one design, one after the other, give the same outputs."""
    run = tire_run()[:3000]                      # 5 ms then 2 ms

    def outputs():
        rt = observer(design_tire)
        out = []
        for h, u in run:
            rt.step(h, u)
            out.append(tuple(rt.y[k] for k in (*OUT, "mode")))
        return out

    assert outputs() == outputs()
