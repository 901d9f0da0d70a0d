"""Independent checks of the interval observer's tables (``synthesis.tables.lateral_interval_observer``):
each stored number is recomputed from the design by another route (numpy/scipy, the relaxation
model of eq. 9) and the difference bounded; what the guarantee needs to be nonnegative (the step
maps of eq. 23, N's off-diagonal entries: Lemma 2) is checked to be so.
"""
from __future__ import annotations

import numpy as np
import scipy.linalg

from .. import relaxation_model as rm
from ..certificate import Check

REL = 1e-12          # relative agreement of the stored numbers with their recomputation
H0 = 0.005           # s: the FMU's default step, at which the step maps are stored


def _le(name, value, limit, detail=""):
    return Check(name, float(value), float(limit), bool(value <= limit), "<=", detail)


def _rel(a, b, floor: float = 1.0) -> float:
    """max |a - b| / max(floor, max |b|) (inf for different shapes)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    if a.shape != b.shape:
        return float("inf")
    return float(np.max(np.abs(a - b)) / max(floor, float(np.max(np.abs(b)))))


def _van_loan(N, h: float, blocks: int = 4):
    """(Phi, Gam, Gam1, Gam2) of eq. (23)'s exact discretisation: the top blocks of exp(M h),
    M = [[N, I, 0, 0], [0, 0, I, 0], [0, 0, 0, I], [0, 0, 0, 0]] (scipy's Pade expm)."""
    n = N.shape[0]
    M = np.zeros((blocks * n, blocks * n))
    M[:n, :n] = N
    for b in range(1, blocks):
        M[(b - 1) * n:b * n, b * n:(b + 1) * n] = np.eye(n)
    E = scipy.linalg.expm(M * h)
    return [E[:n, b * n:(b + 1) * n] for b in range(blocks)]


def checks(data: dict) -> list:
    tb = data.get("tables")
    if not tb:
        return [Check("tables: interval observer tables present", 0.0, 1.0, False, ">=", "no tables")]
    out = []
    md = data["model"]
    v = {k: float(md[k]) for k in rm.PARAMETERS}
    A0, A1, B1 = rm.coefficients(v["m"], v["Iz"], v["lf"], v["lr"], v["sigma"], v["Cf"], v["Cr"])
    cfb, crb = data["stiffness_box"]["Cf"], data["stiffness_box"]["Cr"]
    dAl, dAu, dBl, dBu = rm.stiffness_bounds(v, cfb, crb)
    t = tb["model"]
    err = max(_rel(t["A0"], A0), _rel(t["A1"], A1), _rel(t["B1"], B1), _rel(t["dA_lower"], dAl),
              _rel(t["dA_upper"], dAu), _rel(t["dB1_lower"], dBl), _rel(t["dB1_upper"], dBu),
              _rel([t[k] for k in ("m", "Iz", "lf", "lr")], [v[k] for k in ("m", "Iz", "lf", "lr")]))
    out.append(_le("tables: model = relaxation model (eq. 9) of the design's vehicle and stiffness box", err, 1e-9))
    sk = tb["stiffness"]
    ms, Is = v["m"] * v["sigma"], v["Iz"] * v["sigma"]
    want = [1 / ms, v["lf"] / Is, v["lr"] / Is, cfb[0] - v["Cf"], cfb[1] - v["Cf"], crb[0] - v["Cr"],
            crb[1] - v["Cr"]]
    got = [sk["k3"], sk["k4f"], sk["k4r"], *sk["dcf"], *sk["dcr"]]
    out.append(_le("tables: structured stiffness constants (1/(m sigma), lf/(Iz sigma), lr/(Iz sigma), box)",
                   _rel(got, want), REL))
    sym = bool(np.isclose(sum(sk["dcf"]), 0, atol=1e-9 * (cfb[1] - cfb[0]))
               and np.isclose(sum(sk["dcr"]), 0, atol=1e-9 * (crb[1] - crb[0])))
    out.append(_le("tables: symmetric-box flag", float(sym != bool(sk["symmetric"])), 0.0))
    # rows with a known diagonal (exact integration) and measured rows with a known derivative
    dA_zero = np.all(np.asarray(dAl) == 0.0, axis=1) & np.all(np.asarray(dAu) == 0.0, axis=1)
    damped = [i for i in range(4) if dAl[i, i] == 0 and dAu[i, i] == 0 and (A0[i, i] != 0 or A1[i, i] != 0)]
    w = np.asarray(data["runtime"].get("disturbance_bound", [0.0] * 4), float)
    smooth = [j for j in (1, 2) if dA_zero[j] and B1[j] == 0 and dBl[j] == 0 and dBu[j] == 0 and w[j] == 0]
    out.append(_le("tables: damped and smooth rows", float(damped != list(tb["damped"]) or
                                                           smooth != list(tb["smooth"])), 0.0))
    out.append(_le("tables: step maps stored at the default step 0.005 s", abs(float(tb["h0"]) - H0), 0.0))
    for k, (m, tm) in enumerate(zip(data["modes"], tb["modes"])):
        name = f"tables: mode {k + 1}"
        N = np.asarray(tm["N"], float)
        err = max(_rel(N, m["N"]), _rel(tm["P"], m["P"]), _rel(tm["E"], m["E"]), _rel(tm["J"], m["J"]),
                  _rel(tm["H"], m["H"]), abs(float(tm["vx"]) - float(m["vx"])))
        out.append(_le(f"{name} gains N, P, E, J, H = the design's", err, 1e-9))
        off = N - np.diag(np.diag(N))
        out.append(Check(f"{name} N Metzler (Lemma 2): min off-diagonal entry", float(off.min()), 0.0,
                         bool(off.min() >= 0.0), ">="))
        out.append(Check(f"{name} N + eta I >= 0: min diagonal entry", float(np.min(np.diag(N)) + tm["eta"]),
                         0.0, bool(np.min(np.diag(N)) + tm["eta"] >= 0.0), ">="))
        maps = np.asarray(tm["maps_h0"], float)
        ref = _van_loan(N, H0)
        out.append(_le(f"{name} step maps (Phi, Gam, Gam1, Gam2) at 0.005 s = exp of the Van Loan block matrix",
                       max(_rel(a, b, 1e-300) for a, b in zip(maps, ref)), REL))
        out.append(Check(f"{name} step maps >= 0 (order preserving)", float(maps.min()), 0.0,
                         bool(maps.min() >= 0.0), ">="))
        # the maps' bracket (rigorous rounding): at least the reference's distance, and tight
        gap = max(float(np.max(np.abs(a - b))) for a, b in zip(maps, ref))
        e = float(tm["maps_h0_error"])
        out.append(Check(f"{name} step maps' error bound >= |maps - reference| - 4 ulps", e,
                         gap - 4 * np.spacing(float(np.max(maps))), bool(e >= gap - 4 * np.spacing(float(np.max(maps)))),
                         ">="))
        out.append(_le(f"{name} step maps' error bound relative to the largest entry", e / float(np.max(maps)), 1e-12))
        # the design residuals' bounds (R1 = P A_j - N P - J C, R2 = P B_j - H, R3 = I - E C - P)
        P_, E_, J_ = (np.asarray(tm[k], float) for k in ("P", "E", "J"))
        Aj = A0 + float(tm["vx"]) * A1
        C_ = np.zeros((2, 4))
        C_[0, 1] = C_[1, 2] = 1.0
        scale = max(1.0, float(np.max(np.abs(N))))
        R1 = np.abs(P_ @ Aj - N @ P_ - J_ @ C_).sum(axis=1).max()
        rho = [float(x) for x in tm["residual"]]
        out.append(Check(f"{name} design residual bound rho1 >= ||P A_j - N P - J C|| (float64) - 1e-13 scale",
                         rho[0], float(R1) - 1e-13 * scale, bool(rho[0] >= R1 - 1e-13 * scale), ">="))
        out.append(_le(f"{name} design residual bounds (rho1, rho2, rho3) relative to max |N|",
                       max(rho) / scale if all(np.isfinite(rho)) else float("inf"), 1e-9))
        # the enclosure's substeps: rho bounds the spectral radius of the band's Metzler majorant
        vx = max(abs(float(m["vx"])), float(data["switching"]["edges"][k + 1]))
        a = A0 + vx * A1
        M = np.where(np.eye(4, dtype=bool), a + dAu, np.maximum(np.abs(a + dAl), np.abs(a + dAu)))
        for i in damped:
            M[i, i] = 0.0
        rad = float(np.max(np.abs(np.linalg.eigvals(np.abs(M)))))
        out.append(Check(f"{name} rho >= spectral radius of |majorant| (enclosure substeps)",
                         float(tm["rho"]), rad * (1 - 1e-9), bool(tm["rho"] >= rad * (1 - 1e-9)), ">="))
    out.append(_le("tables: one entry per mode", abs(len(tb["modes"]) - len(data["modes"])), 0.0))
    return out
