"""Independent checks of paper 003's observer tables: eq. (13)'s block matrices rebuilt with
numpy from the design's model and gains, the step maps against scipy's expm."""
from __future__ import annotations

import numpy as np

from ...fmu_src.spec import DEFAULT_STEP
from .sideslip_fixed_order_estimator import absent, bounded, rel_err, zoh_expm


def _switching(t: dict, sw: dict):
    return bounded("paper-003 observer tables: h0 = the FMU's default step, edges and hysteresis = the design's "
                   "switching (difference)",
                   lambda: max(abs(float(t["h0"]) - DEFAULT_STEP), rel_err(t["edges"], sw["edges"]),
                               abs(float(t["hysteresis"]) - float(sw.get("hysteresis", 0.0)))), 0.0)


def checks(data: dict) -> list:
    if absent(data, "paper-003 observer"):
        return absent(data, "paper-003 observer")
    t = data["tables"]
    modes = data["modes"]
    if data.get("method") == "measured_speed":
        return _measured(data, t, modes)

    def blocks_err():
        err = abs(len(t["modes"]) - len(modes))
        for tm, mode in zip(t["modes"], modes):
            A, Ef, C, Hx = (np.asarray(mode["model"][k], float) for k in ("A", "E_f", "C", "H_x"))
            L = np.vstack([np.asarray(mode["gains"]["L_P"], float), np.asarray(mode["gains"]["L_I"], float)])
            n, nf = A.shape[0], Ef.shape[1]
            Ct = np.hstack([C, np.zeros((C.shape[0], nf))])
            M = np.block([[A, Ef], [np.zeros((nf, n + nf))]]) - L @ Ct
            F = np.hstack([Hx, np.asarray(mode["model"]["H_phi"], float)[:, None], np.zeros((2, nf - 1))])
            err = max(err, rel_err(tm["M"], M), rel_err(tm["G"], L), rel_err(tm["C"], C), rel_err(tm["F"], F))
        return err

    def map_err():
        err = 0.0
        for tm in t["modes"]:
            Phi, Gam = zoh_expm(tm["M"], tm["G"], float(t["h0"]))
            err = max(err, rel_err(tm["map_h0"], np.hstack([Phi, Gam])))
        return err

    return [
        _switching(t, data["switching"]),
        bounded("paper-003 observer tables: eq. (13) M = [[A - L_P C, E_f], [-L_I C, 0]], G = [L_P; L_I], C, "
                "F = [H_x | H_phi | 0] (max rel. error)", blocks_err, 1e-12),
        bounded("paper-003 observer tables: step maps at h0 = scipy's expm (max rel. error)", map_err, 1e-10),
    ]


def _measured(data: dict, t: dict, modes: list) -> list:
    """The measured-speed design: per band and basis function M_b = A_b - L_b C, G_b = L_b,
    F_b = [H_b | 0], the ranges = the bands; M(v), G(v) rebuilt with numpy at speeds across the band."""
    mod = data["model"]
    A, C, H = ([np.asarray(c, float) for c in mod[k]] for k in ("A", "C", "H"))
    na, n = A[0].shape[0], H[0].shape[1]

    def blocks_err():
        err = abs(len(t["modes"]) - len(modes)) + (not t.get("measured"))
        for tm, mode in zip(t["modes"], modes):
            L = [np.asarray(x, float) for x in mode["gains"]["L"]]
            for b, sfx in enumerate(("", "_vx", "_ivx")):
                F = np.hstack([H[b], np.zeros((2, na - n))])
                err = max(err, rel_err(tm["M" + sfx], A[b] - L[b] @ C[0]), rel_err(tm["G" + sfx], L[b]),
                          rel_err(tm["F" + sfx], F))
            err = max(err, rel_err(tm["C"], C[0][:, :n]), rel_err(tm["vx_range"], mode["band"]))
            lo, hi = mode["band"]
            for v in np.linspace(lo, hi, 7):      # the runtime's M(v) against A(v) - L(v) C at v
                b = (1.0, v, 1.0 / v)
                Mv = sum(bk * np.asarray(tm[k], float) for bk, k in zip(b, ("M", "M_vx", "M_ivx")))
                ref = sum(bk * A[k] for k, bk in enumerate(b)) - sum(bk * L[k] for k, bk in enumerate(b)) @ C[0]
                err = max(err, rel_err(Mv, ref))
        return err

    return [
        _switching(t, data["switching"]),
        bounded("paper-003 observer tables (measured speed): M_b = A_b - L_b C, G_b = L_b, F_b = [H_b | 0] per basis "
                "function (1, vx, 1/vx), C, the bands; M(v) at 7 speeds per band (max rel. error)", blocks_err, 1e-12),
    ]
