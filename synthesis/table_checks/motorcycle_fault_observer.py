"""Independent checks of paper 003's observer tables: eq. (13)'s block matrices rebuilt with
numpy from the design's model and gains, the step maps against scipy's expm."""
from __future__ import annotations

import numpy as np

from ...fmu_src.spec import DEFAULT_STEP
from .sideslip_fixed_order_estimator import absent, bounded, rel_err, zoh_expm


def checks(data: dict) -> list:
    if absent(data, "paper-003 observer"):
        return absent(data, "paper-003 observer")
    t = data["tables"]
    modes = data["modes"]

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

    sw = data["switching"]
    return [
        bounded("paper-003 observer tables: h0 = the FMU's default step, edges and hysteresis = the design's "
                "switching (difference)",
                lambda: max(abs(float(t["h0"]) - DEFAULT_STEP), rel_err(t["edges"], sw["edges"]),
                            abs(float(t["hysteresis"]) - float(sw.get("hysteresis", 0.0)))), 0.0),
        bounded("paper-003 observer tables: eq. (13) M = [[A - L_P C, E_f], [-L_I C, 0]], G = [L_P; L_I], C, "
                "F = [H_x | H_phi | 0] (max rel. error)", blocks_err, 1e-12),
        bounded("paper-003 observer tables: step maps at h0 = scipy's expm (max rel. error)", map_err, 1e-10),
    ]
