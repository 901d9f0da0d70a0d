"""Paper-000 runtime, issue 9 items 2-4: per-mode measured-speed models (LPV), first-order hold of
the measurements, the ``valid`` output with the integral freeze.

Exactness is checked against the independent numpy RK4 reference of ``test_fast_step_000``
(``ReferenceObserver``: model per mode at its fixed speed or at the measured speed clamped to the
mode's range, the hold's input at the RK4 stage times, the validity rule); the hold error
against an exact solution of the same linear ODE (scipy, rtol 1e-12). Every design dict here
sets the issue-9 keys explicitly (``variant``), whatever the design side emits by default; the
speed-mode design is the default's on eq. (1) (``design_speed_eq1``: fixed model speeds need it).
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from latobs.fmu_src.sideslip_bank_observer import SwitchedPIObserver
from test_sideslip_bank_observer_step_maps import OUT, ReferenceObserver, compare, legacy, measurements, observer, speed_run, \
    tire_run, variant, with_tables

VALIDITY = {"alpha_max": math.radians(4.0), "ay_max": 0.4 * 9.81, "release": 0.8, "lf": 1.0, "lr": 1.6,
            "freeze_integral": True}


def lockstep(design: dict, run) -> float:
    """Worst relative difference runtime vs reference over run [(h, u)]; modes and valid equal."""
    rt, ref = observer(design), ReferenceObserver(design)
    worst = 0.0
    for i, (h, u) in enumerate(run):
        rt.step(h, u)
        ref.step(h, u)
        assert (rt.y["mode"], rt.y["valid"]) == (ref.y["mode"], ref.y["valid"]), f"step {i}"
        worst = max(worst, max(abs(rt.y[k] - ref.y[k]) / max(1.0, abs(ref.y[k])) for k in OUT))
    return worst


# -- 1. per-mode measured-speed models ----------------------------------------------------------
def _speeds_at_and_around_edges(edges):
    """Speeds inside each band, at every edge, a hair either side of each edge, outside the grid."""
    out = [0.5 * (a + b) for a, b in zip(edges, edges[1:])]
    for e in edges:
        out += [e, math.nextafter(e, -math.inf), math.nextafter(e, math.inf), e - 1e-3, e + 1e-3]
    return out + [edges[0] - 3.0, 2.0, edges[-1] + 5.0, 60.0]


@pytest.mark.parametrize("ranges", ["bands", "narrower"])
def test_lpv_speed_modes_equal_rk4_at_the_clamped_measured_speed(design_speed_eq1, ranges):
    """Speed bands select the mode; its model is at the measured speed clamped to ITS OWN range
    (the band, or here also narrower ranges that are not the band), at 5 and 2 ms."""
    d = variant(legacy(design_speed_eq1), speeds="measured")
    edges = d["switching"]["edges"]
    if ranges == "narrower":
        for m, (a, b) in zip(d["modes"], zip(edges, edges[1:])):
            m["model_speed"]["range"] = [a + 0.25 * (b - a), b - 0.25 * (b - a)]
    run, t = [], 0.0
    for h in (0.005, 0.002):
        for vx in _speeds_at_and_around_edges(edges):
            for _ in range(3):                 # 5 ms: the tables; 2 ms: the RK4 substeps
                run.append((h, dict(measurements(t, 0.02), vx=vx)))
                t += h
    assert lockstep(d, run) <= 1e-12
    maps = with_tables(d)["tables"]["maps"]
    for m, mode in zip(maps, d["modes"]):      # each mode's table spans its own range of v = 1/vx
        lo, hi = mode["model_speed"]["range"]
        assert m["v_lo"] == 1.0 / hi and m["v_lo"] + len(m["intervals"]) / m["scale"] == pytest.approx(1.0 / lo)
    assert observer(d).model_v(1, edges[1] - 1.0) == 1.0 / d["modes"][1]["model_speed"]["range"][0]


def test_lpv_speed_modes_on_continuous_sweeps(design_speed_eq1):
    worst, modes, speeds = compare(variant(legacy(design_speed_eq1), speeds="measured"), speed_run()[:3600])
    assert modes == {1, 2, 3} and worst <= 1e-12


def test_fixed_and_measured_modes_mix(design_speed_eq1):
    """A speed design may keep eq. (25) literally for some modes and the measured speed for others."""
    d = variant(legacy(design_speed_eq1), speeds="measured")
    d["modes"][1]["model_speed"] = {"kind": "fixed", "value": d["modes"][1]["scheduling"]["value"]}
    worst, modes, _ = compare(d, speed_run()[:1600])
    assert modes == {1, 2, 3} and worst <= 1e-12


def test_bad_model_speed_and_keys_are_refused(design_speed_eq1):
    d = variant(legacy(design_speed_eq1), speeds="measured")
    d["modes"][0]["model_speed"]["range"] = [13.0, 6.0]
    with pytest.raises(ValueError, match="range"):
        observer(d)
    d = variant(legacy(design_speed_eq1), speeds="measured")
    d["modes"][0]["model_speed"] = {"kind": "scheduled"}
    with pytest.raises(ValueError, match="fixed' or 'measured"):
        observer(d)
    with pytest.raises(ValueError, match="input_hold"):
        observer(variant(design_speed_eq1, hold="second_order"))
    with pytest.raises(ValueError, match="release"):
        observer(variant(design_speed_eq1, validity=dict(VALIDITY, release=1.0)))


# -- 2. first-order hold --------------------------------------------------------------------------
def test_first_order_hold_equals_rk4_with_the_ramp_at_the_stage_times(design_speed_eq1, design_tire):
    """Fixed-speed maps, LPV tables and tire tables with the first-order hold: the tables at the
    default step, the maps built for other steps and the RK4 substeps; h changes (5, 2, 10 ms and
    random sizes), and the vx dip below vx_hold restarts the slope."""
    rng = np.random.default_rng(1)
    sizes = [float(x) for x in rng.choice([0.001, 0.0025, 0.004, 0.005, 0.007], 400)]
    t, random_h = 0.0, []
    for k, h in enumerate(sizes):
        random_h.append((h, dict(measurements(t, 0.02), vx=17.0 + 9.0 * math.sin(k / 40))))
        t += h
    for d, run in ((variant(legacy(design_speed_eq1), hold="first_order"), speed_run()[:3100] + random_h),
                   (variant(legacy(design_speed_eq1), hold="first_order", speeds="measured"), random_h),
                   (variant(legacy(design_tire), hold="first_order"),
                    tire_run(*design_tire["modes"][0]["model_speed"]["range"])[:2600] + random_h)):
        assert lockstep(d, run) <= 1e-12


def test_first_order_hold_slope_restarts(design_speed_eq1):
    """Slope 0 at the first step, after a frozen period and after initialize(): those steps equal
    the zero-order hold's from the same state; otherwise the slope is (w_k - w_{k-1}) / h_{k-1}."""
    foh = observer(variant(legacy(design_speed_eq1), hold="first_order"))
    zoh = observer(variant(legacy(design_speed_eq1), hold="zero_order"))
    u = [dict(measurements(0.005 * k, 0.02), vx=17.0) for k in range(40)]
    foh.step(0.005, u[0])
    zoh.step(0.005, u[0])
    # first step, slope 0: the augmented map's [Phi | Gam] and the plain one, equal to rounding
    assert max(abs(foh.y[k] - zoh.y[k]) for k in OUT) <= 1e-14 and foh.y["mode"] == zoh.y["mode"]

    def twin_step(u_k, h=0.005):
        """One zero-order-hold step from foh's state, then foh's own step."""
        zoh.s, zoh.mode, zoh._started = foh.s, foh.mode, True
        zoh.step(h, u_k)
        foh.step(h, u_k)
        return max(abs(foh.y[k] - zoh.y[k]) for k in OUT)

    for k in range(1, 10):
        foh.step(0.005, u[k])
    assert twin_step(u[10]) > 1e-6                          # a real slope
    foh.step(0.005, dict(u[11], vx=0.5))                     # frozen: the hold restarts
    assert foh._prev is None
    assert twin_step(u[12]) <= 1e-14
    assert twin_step(u[13]) > 1e-6
    foh.initialize(u[14])                                   # (re)initialisation restarts it too
    assert twin_step(u[15]) <= 1e-14
    foh.step(0.005, u[16])
    assert twin_step(u[17], 0.002) > 1e-6                   # slope over h_{k-1} = 5 ms, step 2 ms


def _hold_errors(design: dict, h: float, t_end: float = 3.0, settle: float = 1.0) -> float:
    """Max |s - s_exact| over [settle, t_end] (s = [z; w^]) for smooth measurements at a fixed
    speed in mode 2, s_exact from solve_ivp of the same linear ODE with the inputs w(t)."""
    st = design["structure"]
    T, N, C = (np.asarray(st[k], dtype=float) for k in ("T", "N", "C"))
    vx = design["modes"][1]["scheduling"]["value"]
    ref = ReferenceObserver(design)
    A, B, F = ref.model(1, vx)
    gains = design["modes"][1]["gains"]
    KP, KI = np.asarray(gains["K_P"], dtype=float), np.asarray(gains["K_I"], dtype=float)

    def w_of(t):
        m = measurements(t, 0.02)
        return np.array([m["yaw_rate"], m["roll_angle"], m["roll_rate"]]), m["delta"]

    def rhs(t, s):
        y, dl = w_of(t)
        xh = s[:4] + N @ y
        innov = y - C @ xh
        return np.concatenate([T @ A @ xh + (T @ B)[:, 0] * dl + (T @ F)[:, 0] * s[4] + KP @ innov, KI @ innov])

    obs = observer(design)
    obs.initialize(dict(measurements(0.0, 0.02), vx=vx))
    n = int(round(t_end / h))
    ts = np.arange(n + 1) * h
    exact = solve_ivp(rhs, (0.0, t_end), np.array(obs.s), t_eval=ts, method="DOP853", rtol=1e-12, atol=1e-14).y.T
    worst = 0.0
    for k in range(n):
        obs.step(h, dict(measurements(ts[k], 0.02), vx=vx))
        assert obs.y["mode"] == 2
        if ts[k + 1] >= settle:
            worst = max(worst, float(np.max(np.abs(np.array(obs.s) - exact[k + 1]))))
    return worst


def test_first_order_hold_error_is_second_order(design_speed_eq1):
    """Against the exact solution: the zero-order hold's error halves with h (O(h)), the
    first-order hold's quarters (O(h^2)) and is far smaller (see the runtime's docstring)."""
    base = variant(legacy(design_speed_eq1), validity=None)
    zoh = [_hold_errors(variant(base, hold="zero_order"), h) for h in (0.005, 0.0025)]
    foh = [_hold_errors(variant(base, hold="first_order"), h) for h in (0.005, 0.0025)]
    assert 1.7 < zoh[0] / zoh[1] < 2.4, zoh
    assert foh[0] / foh[1] > 3.0, foh
    assert foh[0] < zoh[0] / 20, (zoh, foh)


# -- 3. validity and the integral freeze ----------------------------------------------------------
class ValidityRule:
    """The documented rule, independently: slip angles from beta^, r^ at the start of the step."""

    def __init__(self, design):
        self.v, self.N = design["validity"], np.asarray(design["structure"]["N"], dtype=float)
        self.valid = 1

    def estimates(self, s, u):
        y = np.array([u["yaw_rate"], u["roll_angle"], u["roll_rate"]])
        return (np.asarray(s[:4]) + self.N @ y)[:2]

    def premise(self, s, u):
        beta, r = self.estimates(s, u)
        a_f = u["delta"] - beta - self.v["lf"] * r / u["vx"]
        a_r = -beta + self.v["lr"] * r / u["vx"]
        return max(abs(a_f), abs(a_r)), abs(u["vx"] * u["yaw_rate"])

    def update(self, s, u):
        alpha, ay = self.premise(s, u)
        v = self.v
        if self.valid and (alpha > v["alpha_max"] or ay > v["ay_max"]):
            self.valid = 0
        elif not self.valid and alpha < v["release"] * v["alpha_max"] and ay < v["release"] * v["ay_max"]:
            self.valid = 1
        return self.valid


@pytest.mark.parametrize("hold", ["zero_order", "first_order"])
def test_valid_switches_with_hysteresis_and_freezes_the_bank_estimate(design_speed_eq1, hold):
    d = variant(legacy(design_speed_eq1), hold=hold, validity=VALIDITY)
    rt, rule = observer(d), ValidityRule(d)
    a_max, ay_max, rel = VALIDITY["alpha_max"], VALIDITY["ay_max"], VALIDITY["release"]
    vx = 17.0
    # (what, steps, yaw_rate, delta): ay = vx yaw_rate; alpha_f ~ delta - beta^ - lf r^ / vx
    phases = [("valid", 200, 0.05, 0.01),
              ("ay above ay_max", 60, 1.1 * ay_max / vx, 0.01),
              ("ay between release and limit", 60, 0.9 * ay_max / vx, 0.01),
              ("ay below release", 220, 0.5 * rel * ay_max / vx, 0.01),   # > 1 s: next entry logged
              ("alpha above alpha_max", 3, 0.02, 1.3),           # delta: alpha_f = this x alpha_max
              ("alpha between release and limit", 10, 0.02, 0.5 * (1 + rel)),
              ("alpha below release", 100, 0.02, 0.5 * rel)]
    t, seen, log = 0.0, {}, []
    for what, n, yaw, delta in phases:
        bank, valid, beta = [], [], []
        for _ in range(n):
            u = dict(measurements(t, 0.0), yaw_rate=yaw, delta=delta, vx=vx)
            if what.startswith("alpha"):           # steer so that alpha_f is the wanted multiple
                b_hat, r_hat = rule.estimates(rt.s, u)
                u["delta"] = b_hat + VALIDITY["lf"] * r_hat / vx + delta * a_max
            alpha, ay = rule.premise(rt.s, u)
            want = rule.update(rt.s, u)
            rt.step(0.005, u)
            t += 0.005
            assert rt.y["valid"] == want, (what, alpha, ay)
            bank.append(rt.y["bank_angle_hat"])
            beta.append(rt.y["beta_hat"])
            valid.append(want)
            log.append((what, alpha, ay, want))
        seen[what] = (valid, bank, beta)
    # the phases did what their names say: entries on each limit, hysteresis on each, release
    assert seen["valid"][0] == [1] * 200 and seen["ay above ay_max"][0] == [0] * 60
    assert seen["ay between release and limit"][0] == [0] * 60            # hysteresis: still invalid
    assert seen["ay below release"][0] == [1] * 220
    assert seen["alpha above alpha_max"][0] == [0] * 3
    assert seen["alpha between release and limit"][0] == [0] * 10         # hysteresis in alpha
    assert seen["alpha below release"][0] == [1] * 100
    assert all(rel * a_max < al <= a_max and ay < rel * ay_max for w, al, ay, _ in log
               if w == "alpha between release and limit")
    # while invalid: the bank estimate is constant to the bit, beta^ (z) keeps moving
    frozen = seen["ay above ay_max"][1] + seen["ay between release and limit"][1]
    assert len(set(frozen)) == 1                                          # bitwise the same value
    for what in ("ay above ay_max", "ay between release and limit"):
        assert len(set(seen[what][2])) > 10
    # valid again: the integral action resumes
    assert len(set(seen["ay below release"][1])) > 10 and len(set(seen["valid"][1])) > 10
    assert rt.invalid_entries == 2
    msgs = [m for _, m in rt.events if "valid = 0" in m]
    assert len(msgs) == 2 and all("bank estimate held" in m for m in msgs)


def test_frozen_maps_equal_rk4_with_validity_chattering(design_speed_eq1, design_tire):
    """Against the reference (w^' = 0 while invalid), through the frozen maps of every kind."""
    for d in (variant(legacy(design_speed_eq1), hold="first_order", speeds="measured", validity=VALIDITY),
              variant(legacy(design_speed_eq1), hold="zero_order", validity=VALIDITY),
              variant(legacy(design_tire), hold="first_order", validity=VALIDITY)):
        run, t = [], 0.0
        for k in range(1500):
            u = measurements(t, 0.02)
            u["yaw_rate"] = 0.3 * math.sin(0.8 * t) + 0.01       # ay crosses 3.9 m/s^2 both ways
            run.append((0.005 if k < 900 else 0.002, dict(u, vx=15.0 + 6.0 * math.sin(0.3 * t))))
            t += run[-1][0]
        rt, used = observer(d), set()
        advance = rt.advance
        rt.advance = lambda idx, *a: used.add(idx) or advance(idx, *a)
        assert lockstep(d, run) <= 1e-12
        for h, u in run:
            rt.step(h, u)
        assert rt.invalid_entries >= 2
        assert max(used) >= len(d["modes"])                                       # frozen maps in use


def test_invalid_messages_are_rate_limited(design_speed_eq1):
    d = variant(legacy(design_speed_eq1), validity=VALIDITY)
    rt = observer(d)
    vx, ay_max = 17.0, VALIDITY["ay_max"]
    for k in range(600):                                   # 3 s, ay above / far below every 2 steps
        yaw = (1.2 if (k // 2) % 2 else 0.1) * ay_max / vx
        rt.step(0.005, dict(measurements(0.005 * k, 0.0), delta=0.0, yaw_rate=yaw, vx=vx))
    msgs = [m for _, m in rt.events if "valid = 0" in m]
    assert rt.invalid_entries == 150
    assert len(msgs) == 3                                  # t = 0.01, 1.01, 2.01 s
    assert "(entry 1)" in msgs[0] and "more entries since the last message not logged" in msgs[1]


def test_valid_is_held_below_vx_hold_and_always_1_without_validity(design_speed_eq1):
    d = variant(legacy(design_speed_eq1), validity=VALIDITY)
    rt = observer(d)
    u = dict(measurements(0.0, 0.0), delta=0.0, yaw_rate=0.4, vx=17.0)      # ay = 6.8 m/s^2
    rt.step(0.005, u)
    assert rt.y["valid"] == 0
    held = dict(rt.y)
    rt.step(0.005, dict(u, vx=0.5, yaw_rate=0.0))                         # frozen: held, valid too
    assert rt.y == held
    rt.step(0.005, dict(u, yaw_rate=0.0))
    assert rt.y["valid"] == 1
    rt = observer(variant(d, validity=None))
    for k in range(10):
        rt.step(0.005, dict(u, yaw_rate=2.0, delta=0.5))
        assert rt.y["valid"] == 1
    assert not rt.events


def test_no_freeze_keeps_integrating(design_speed_eq1):
    d = variant(legacy(design_speed_eq1), validity=dict(VALIDITY, freeze_integral=False))
    rt = observer(d)
    bank = []
    for k in range(50):
        rt.step(0.005, dict(measurements(0.005 * k, 0.02), yaw_rate=0.4, vx=17.0))
        assert rt.y["valid"] == 0
        bank.append(rt.y["bank_angle_hat"])
    assert len(set(bank)) > 40 and "held" not in rt.events[0][1]


# -- 4. the FMU -------------------------------------------------------------------------------------
@pytest.mark.slow
def test_fmu_exposes_valid(tmp_path, design_speed_eq1):
    """An FMU built from a design dict with the issue-9 keys has the Integer output ``valid`` and
    equals its runtime; a refused (NaN) step changes nothing, the first-order hold included."""
    from fmpy import read_model_description

    from latobs import packaging
    from latobs.synthesis import design_file
    from latobs.validation.harness import FmuInstance

    d = with_tables(variant(design_speed_eq1, hold="first_order", speeds="measured", validity=VALIDITY))
    path = packaging.package_design(design_file.write(d, tmp_path), tmp_path)
    md = read_model_description(str(path))
    var = {v.name: v for v in md.modelVariables}
    assert var["valid"].type == "Integer" and var["valid"].causality == "output"
    assert (var["valid"].start, var["valid"].min, var["valid"].max) in ((None, "0", "1"), (None, 0, 1))

    def inputs(k):
        t = 0.005 * k
        m = measurements(t, 0.02)
        return dict(m, yaw_rate=0.35 * math.sin(1.5 * t), vx=17.0 + 5.0 * math.sin(0.4 * t))

    fmu = FmuInstance("obs", path)
    fmu.start(inputs(0))
    rt = observer(d)
    rt.initialize(inputs(0))
    worst, valid = 0.0, set()
    try:
        for k in range(800):
            if k == 400:                                   # a refused step: nothing changes
                before = fmu.get_outputs()
                fmu.set_inputs(dict(inputs(k), roll_rate=math.nan))
                with pytest.raises(Exception, match="discard"):
                    fmu.slave.doStep(k * 0.005, 0.005)
                assert fmu.get_outputs() == before
            fmu.set_inputs(inputs(k))
            fmu.slave.doStep(k * 0.005, 0.005)
            rt.step(0.005, inputs(k))
            got = fmu.get_outputs()
            assert got["valid"] == rt.y["valid"]
            valid.add(got["valid"])
            worst = max(worst, max(abs(got[q] - rt.y[q]) for q in OUT))
    finally:
        fmu.close()
    assert valid == {0, 1} and worst <= 1e-9
    assert any("valid = 0" in m for m in fmu.logs)
