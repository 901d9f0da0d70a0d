"""Tables of paper 001's switched interval observer (``fmu_src/lateral_interval_observer.py`` and its native C
twin): the design file checked and turned, once at build time, into the numbers both runtimes
evaluate (see docs/runtime/lateral_interval_observer.md).

``compute(data)`` checks that the design file is what the observer needs (eq. 23/30/33 relations,
N Metzler, the relaxation model of eq. 9 around the stiffness box), with a ValueError naming the
culprit, and returns plain JSON data: the model, the structured stiffness bound's constants, each
mode's gains with the step maps (Phi, Gam, Gam1, Gam2) of eq. (23) at the FMU's default step, the
enclosure's substep bound and the runtime's tuning. Pure Python on purpose: the step maps must be
the very doubles the runtimes would compute (``phi_gamma``: the same operations in the same order).
"""
from __future__ import annotations

import math
from fractions import Fraction

from ...fmu_src.linalg import dot, matrix as _matrix, phi_gamma   # the runtime's own arithmetic
from ...fmu_src.spec import DEFAULT_STEP   # s: the FMU's default communication step (the maps stored for it)

NX = 4                        # states x = [vy, r, ay, x4]
TOL = 1e-9                    # relative tolerance of the design file's structural relations

#: the runtime's tuning (both backends); see the runtime page for what each one does
TUNING = {
    "consistency_tol": 4 * 2.0 ** -52,   # a gap of at most 4 ulps (x (1 + |y|)) is not an inconsistency
    "enclosure_tries": 10,        # a priori enclosure attempts before the comparison bound
    "enclosure_grow": 2.0,        # inflation of the extents of T(X_k), then of the last T(S) ..
    "enclosure_mult": 1.0,        # .. times this per failed attempt
    "substep_rho_h": 0.3,         # enclosure substeps so that hs rho(|A|) <= this
    "sampled": True,              # the sampled-measurement correction, intersected with eq. (23)'s
    "sampled_substep": 0.005,     # s
    "sampled_min_step": 0.01,     # s: below this step it is not used
    "sampled_max_substeps": 32,
    "sampled_dv": 0.1,            # m/s: the model speed of its maps, vx rounded to this grid
    "sampled_max_norm": 1e6,      # ||A hs||_inf above which it has no map
}


# -- small dense helpers (lists of rows; sums from the left, as the runtimes) ---------------------
def _matmul(A, B):
    cols = list(zip(*B))
    return [[dot(row, col) for col in cols] for row in A]


def _matvec(A, v):
    return [dot(row, v) for row in A]


def _rel(a, b) -> float:
    """max |a - b| / max(1, max |b|) over two equal-shape matrices."""
    fa = [x for r in a for x in (r if isinstance(r, list) else [r])]
    fb = [x for r in b for x in (r if isinstance(r, list) else [r])]
    return max(abs(x - y) for x, y in zip(fa, fb)) / max(1.0, max(abs(y) for y in fb))


def _vector(x, n: int, what: str):
    try:
        v = [float(a) for a in x]
    except (TypeError, ValueError) as exc:
        raise ValueError(f"design file: {what} must be a vector of {n} numbers ({exc})") from exc
    if len(v) != n:
        raise ValueError(f"design file: {what} must have {n} entries, got {len(v)}")
    if not all(math.isfinite(a) for a in v):
        raise ValueError(f"design file: {what} has a non-finite entry")
    return v


# -- step maps ------------------------------------------------------------------------------------
def _perron(M) -> float:
    """Spectral radius of |M| (power iteration on a nonnegative matrix; an upper estimate)."""
    A = [[abs(x) for x in row] for row in M]
    v = [1.0] * len(A)
    lam = 0.0
    for _ in range(200):
        w = [dot(row, v) + 1e-300 for row in A]
        lam = max(w) / max(v)
        s = max(w)
        v = [x / s for x in w]
    return lam


def damped_rows(model) -> list[int]:
    """Rows i whose diagonal d_i(vx) = A0_ii + vx A1_ii is known (no stiffness uncertainty on it)
    and not identically 0: the a priori enclosure integrates them exactly."""
    A0, A1, dAl, dAu = (model[k] for k in ("A0", "A1", "dA_lower", "dA_upper"))
    return [i for i in range(NX) if dAl[i][i] == 0.0 and dAu[i][i] == 0.0 and (A0[i][i] != 0.0 or A1[i][i] != 0.0)]


def smooth_rows(model, meas) -> list[int]:
    """Measured states j with x_j' a known linear form of x (no stiffness, no input, no
    disturbance): their second derivative is bounded by that form over the hull of x'."""
    dAl, dAu, B1, dBl, dBu, w = (model[k] for k in ("dA_lower", "dA_upper", "B1", "dB1_lower", "dB1_upper", "w"))
    return [j for j in meas if not any(dAl[j]) and not any(dAu[j]) and B1[j] == 0.0 and dBl[j] == 0.0
            and dBu[j] == 0.0 and w[j] == 0.0]


def majorant(model, vx: float, damped=()):
    """Metzler majorant of A(vx, c) over the stiffness box: the largest diagonal entries and the
    largest |off-diagonal| entries (the rows in ``damped``: diagonal set to 0)."""
    M = [[0.0] * NX for _ in range(NX)]
    for i in range(NX):
        for j in range(NX):
            a = model["A0"][i][j] + vx * model["A1"][i][j]
            lo, hi = a + model["dA_lower"][i][j], a + model["dA_upper"][i][j]
            M[i][j] = hi if i == j else max(abs(lo), abs(hi))
        if i in damped:
            M[i][i] = 0.0
    return M


# -- the design file ------------------------------------------------------------------------------
def _read_model(data: dict):
    md = data["model"]
    model = {k: _matrix(md[k], NX, NX, f"model.{k}") for k in ("A0", "A1", "dA_lower", "dA_upper")}
    model.update({k: _vector(md[k], NX, f"model.{k}") for k in ("B1", "dB1_lower", "dB1_upper")})
    C = _matrix(md["C"], 2, NX, "model.C")
    meas = []
    for k, row in enumerate(C):
        ones = [j for j, c in enumerate(row) if c == 1.0]
        if len(ones) != 1 or any(c != 0.0 for j, c in enumerate(row) if j != ones[0]):
            raise ValueError(f"design file: model.C row {k + 1} must select one state (zeros and one 1), got {row}")
        meas.append(ones[0])
    if meas != [1, 2]:
        raise ValueError(f"design file: model.C must measure [r, ay] = states 2 and 3, got states "
                         f"{[j + 1 for j in meas]}")
    for lo, hi in (("dA_lower", "dA_upper"), ("dB1_lower", "dB1_upper")):
        a, b = model[lo], model[hi]
        flat = zip(sum(a, []), sum(b, [])) if lo == "dA_lower" else zip(a, b)
        if any(x > y for x, y in flat):
            raise ValueError(f"design file: model.{lo} must be <= model.{hi} elementwise")
    for k in ("m", "Iz", "lf", "lr"):
        v = float(md[k])
        if not (v > 0 and math.isfinite(v)):
            raise ValueError(f"design file: model.{k} must be finite and > 0, got {md[k]!r}")
        model[k] = v
    rt = data["runtime"]
    model["w"] = _vector(rt.get("disturbance_bound", [0.0] * NX), NX, "runtime.disturbance_bound")
    return model, C, meas


def _read_modes(data: dict, model, C):
    sw = data["switching"]
    if sw.get("kind") != "speed_bands":
        raise ValueError(f"design file: switching.kind must be 'speed_bands', got {sw.get('kind')!r}")
    edges = [float(e) for e in sw["edges"]]
    if len(edges) < 2 or not all(math.isfinite(e) for e in edges) or any(b <= a for a, b in zip(edges, edges[1:])):
        raise ValueError(f"design file: switching.edges must be >= 2 finite increasing speeds, got {sw['edges']}")
    eta = float(data["runtime"].get("eta", 0.0))
    if not (math.isfinite(eta) and eta >= 0):
        raise ValueError(f"design file: runtime.eta must be finite and >= 0, got {data['runtime'].get('eta')!r}")
    if len(data["modes"]) != len(edges) - 1:
        raise ValueError(f"design file: {len(edges) - 1} speed bands need as many modes, got {len(data['modes'])}")
    modes = []
    eye = [[1.0 if i == j else 0.0 for j in range(NX)] for i in range(NX)]
    A0, A1, B1 = model["A0"], model["A1"], model["B1"]
    for k, m in enumerate(data["modes"]):
        where = f"mode {k + 1}"
        if int(m["index"]) != k + 1:
            raise ValueError(f"design file: {where} has index {m['index']!r}, expected {k + 1}")
        vx = float(m["vx"])
        if not math.isfinite(vx):
            raise ValueError(f"design file: {where} field vx must be finite, got {m['vx']!r}")
        g = {key: _matrix(m[key], NX, NX, f"{where} field {key}") for key in ("N", "P")}
        g.update({key: _matrix(m[key], NX, 2, f"{where} field {key}") for key in ("E", "J", "K")})
        g["H"] = _vector(m["H"], NX, f"{where} field H")
        N, P, E, J, K, H = (g[key] for key in ("N", "P", "E", "J", "K", "H"))
        scale = max(abs(x) for r in N for x in r)
        for i in range(NX):
            for j in range(NX):
                if i != j and N[i][j] < 0:
                    if N[i][j] < -TOL * scale:
                        raise ValueError(f"design file: {where} field N is not Metzler: N[{i + 1}][{j + 1}] = "
                                         f"{N[i][j]!r} < 0 (the bounds would not stay ordered, Lemma 2)")
                    N[i][j] = 0.0    # rounding-level negative: exactly 0 (order preservation)
        EC = _matmul(E, C)
        Aj = [[a + vx * b for a, b in zip(r0, r1)] for r0, r1 in zip(A0, A1)]
        KC, PA = _matmul(K, C), _matmul(P, Aj)
        checks = (("P", P, [[eye[i][j] - EC[i][j] for j in range(NX)] for i in range(NX)], "P = I - E C"),
                  ("J", J, [[a + b for a, b in zip(rk, rne)] for rk, rne in zip(K, _matmul(N, E))],
                   "J = K + N E (30a)"),
                  ("N", N, [[PA[i][j] - KC[i][j] for j in range(NX)] for i in range(NX)],
                   "N = P A_j - K C (33), A_j = A0 + vx_j A1"),
                  ("H", [H], [_matvec(P, [vx * b for b in B1])], "H = P B_j (30b), B_j = vx_j B1"))
        for field, got, want, rel in checks:
            err = _rel(got, want)
            if not err <= TOL:
                raise ValueError(f"design file: {where} field {field} violates {rel}: relative error {err:.3g} "
                                 f"> {TOL:g}")
        modes.append({"vx": vx, "N": N, "P": P, "E": E, "J": J, "H": H,
                      "eta": max(eta, max(-N[i][i] for i in range(NX)), 0.0)})   # N + eta I >= 0
    return edges, modes


def _read_stiffness(data: dict, model) -> dict:
    """The structured stiffness bound's constants, after checking that the file's model IS the
    relaxation model of eq. (9) around (model.Cf, model.Cr) with the stiffness box: A0's stiffness
    entries (rows 3, 4, columns 1, 2) and B1 at (Cf, Cr), dA, dB1's bounds = their extremes over
    the box's vertices. Then dA(dc) x + vx dB1(dc) delta = [0, 0, k3 (p + q), k4f p - k4r q] with
    p = dcf (vx delta - x1 - lf x2), q = dcr (-x1 + lr x2) for every dc in [dcf] x [dcr]."""
    md, sb = data["model"], data["stiffness_box"]
    vals = {}
    for k in ("sigma", "Cf", "Cr"):
        vals[k] = v = float(md[k])
        if not (v > 0 and math.isfinite(v)):
            raise ValueError(f"design file: model.{k} must be finite and > 0, got {md[k]!r}")
    box = {}
    for k in ("Cf", "Cr"):
        b = _vector(sb[k], 2, f"stiffness_box.{k}")
        if not 0 < b[0] <= b[1]:
            raise ValueError(f"design file: stiffness_box.{k} must be 0 < lower <= upper, got {sb[k]!r}")
        box[k] = b
    m, Iz, lf, lr, sg = model["m"], model["Iz"], model["lf"], model["lr"], vals["sigma"]
    ms, Is = m * sg, Iz * sg

    def block(cf, cr):    # A0's stiffness entries (rows 3, 4; columns 1, 2) and B1's (rows 3, 4)
        return ([[-(cf + cr) / ms, (cr * lr - cf * lf) / ms],
                 [(cr * lr - cf * lf) / Is, -(cf * lf * lf + cr * lr * lr) / Is]],
                [cf / ms, cf * lf / Is])

    Cf, Cr = vals["Cf"], vals["Cr"]
    A0n, B1n = block(Cf, Cr)
    corners = [block(cf, cr) for cf in box["Cf"] for cr in box["Cr"]]
    rows, cols = (2, 3), (0, 1)
    want = {k: [[0.0] * NX for _ in range(NX)] for k in ("dA_lower", "dA_upper")}
    want.update({k: [0.0] * NX for k in ("dB1_lower", "dB1_upper")})
    for a, i in enumerate(rows):
        for b, j in enumerate(cols):
            vs = [c[0][a][b] - A0n[a][b] for c in corners]
            want["dA_lower"][i][j], want["dA_upper"][i][j] = min(vs), max(vs)
        vs = [c[1][a] - B1n[a] for c in corners]
        want["dB1_lower"][i], want["dB1_upper"][i] = min(vs), max(vs)
    checks = [("model.A0", [[model["A0"][i][j] for j in cols] for i in rows], A0n),
              ("model.B1", [[model["B1"][i] for i in rows]], [B1n])]
    checks += [(f"model.{k}", model[k] if k.startswith("dA") else [model[k]],
                want[k] if k.startswith("dA") else [want[k]]) for k in want]
    for what, got, ref in checks:
        err = _rel(got, ref)
        if not err <= TOL:
            raise ValueError(f"design file: {what} is not the relaxation model (eq. 9) of model.Cf, model.Cr "
                             f"and stiffness_box (relative error {err:.3g}): the structured stiffness bound "
                             "needs it")
    dcf, dcr = [box["Cf"][0] - Cf, box["Cf"][1] - Cf], [box["Cr"][0] - Cr, box["Cr"][1] - Cr]

    def symmetric(lo, hi):
        return abs(lo + hi) <= 1e-9 * (hi - lo)

    return {"lf": lf, "lr": lr, "k3": 1.0 / ms, "k4f": lf / Is, "k4r": lr / Is, "dcf": dcf, "dcr": dcr,
            "symmetric": symmetric(*dcf) and symmetric(*dcr)}


def _norm_up(R) -> float:
    """||R||_inf of an exact rational matrix, as the next double above (a bound)."""
    x = max(sum((abs(v) for v in row), Fraction(0)) for row in R)
    f = float(x)
    return f if Fraction(f) >= x else math.nextafter(f, math.inf)


def residuals(model, mode) -> list[float]:
    """[rho1, rho2, rho3]: upper bounds of ||R1||, ||R2||, ||R3|| (inf-norm), evaluated exactly in
    rationals from the doubles the runtime uses: R1 = P A_j - N P - J C, R2 = P B_j - H, R3 = I - E C
    - P (A_j = A0 + vx_j A1, B_j = vx_j B1, C = [e2, e3]). Eq. (30)/(33) make them 0; the solved
    and rounded design leaves them ~1e-16 relative: the runtime bounds their effect (``_correct``)."""
    F = Fraction
    vx = F(mode["vx"])
    A = [[F(a) + vx * F(b) for a, b in zip(r0, r1)] for r0, r1 in zip(model["A0"], model["A1"])]
    Bj = [vx * F(b) for b in model["B1"]]
    P = [[F(x) for x in row] for row in mode["P"]]
    N = [[F(x) for x in row] for row in mode["N"]]
    J = [[F(x) for x in row] for row in mode["J"]]
    E = [[F(x) for x in row] for row in mode["E"]]
    H = [F(x) for x in mode["H"]]
    meas = (1, 2)
    r = range(NX)
    PA = [[sum((P[i][k] * A[k][j] for k in r), F(0)) for j in r] for i in r]
    NP = [[sum((N[i][k] * P[k][j] for k in r), F(0)) for j in r] for i in r]
    JC = [[J[i][meas.index(j)] if j in meas else F(0) for j in r] for i in r]
    EC = [[E[i][meas.index(j)] if j in meas else F(0) for j in r] for i in r]
    R1 = [[PA[i][j] - NP[i][j] - JC[i][j] for j in r] for i in r]
    R2 = [[sum((P[i][k] * Bj[k] for k in r), F(0)) - H[i]] for i in r]
    R3 = [[(1 if i == j else 0) - EC[i][j] - P[i][j] for j in r] for i in r]
    return [_norm_up(R1), _norm_up(R2), _norm_up(R3)]


def compute(data: dict) -> dict:
    """The interval observer's tables from its design dict (ValueError naming a bad field)."""
    try:
        model, C, meas = _read_model(data)
        edges, modes = _read_modes(data, model, C)
        stiff = _read_stiffness(data, model)
        rt = data["runtime"]
    except (KeyError, TypeError, IndexError) as exc:
        raise ValueError(f"design file lacks {exc} needed by the paper-001 interval observer runtime") from exc
    nu = _vector(rt.get("y_error_bound", [0.0, 0.0]), 2, "runtime.y_error_bound")
    w0 = _vector(rt["x0_halfwidth"], NX, "runtime.x0_halfwidth")
    if any(v < 0 for v in nu + w0 + model["w"]):
        raise ValueError("design file: runtime.y_error_bound, runtime.x0_halfwidth and "
                         "runtime.disturbance_bound must be >= 0")
    hmax = rt.get("max_communication_step")
    if hmax is not None:
        hmax = float(hmax)
        if not (math.isfinite(hmax) and hmax >= 0):
            raise ValueError(f"design file: runtime.max_communication_step must be finite and >= 0 s, got "
                             f"{rt['max_communication_step']!r}")
    vx_hold = float(rt.get("vx_hold", 1.0))
    damped, smooth = damped_rows(model), smooth_rows(model, meas)
    probe_smooth = smooth_rows({**model, "w": [0.0] * NX}, meas)     # the decay probes run without w
    for i, m in enumerate(modes):
        # enclosure substeps: hs rho(|A|) <= substep_rho_h at the band's top speed (the damped
        # diagonal, integrated exactly, left out)
        m["rho"] = _perron(majorant(model, max(abs(m["vx"]), edges[i + 1]), damped))
        *maps, m["maps_h0_error"] = phi_gamma(m["N"], DEFAULT_STEP, m["eta"], order=3, with_error=True)
        m["maps_h0"] = maps
        m["residual"] = residuals(model, m)
    return {"h0": DEFAULT_STEP, "model": model, "meas": meas, "damped": damped, "smooth": smooth,
            "probe_smooth": probe_smooth,
            "stiffness": stiff, "edges": edges, "modes": modes, "nu": nu, "x0_halfwidth": w0,
            "vx_hold": vx_hold, "max_communication_step": hmax, "tuning": dict(TUNING)}
