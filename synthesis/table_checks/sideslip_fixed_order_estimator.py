"""Independent checks of paper 002's fixed-order estimator tables (scipy: ss2tf, expm).

Also holds the helpers the other table checks share (:func:`bounded`, :func:`rel_err`).
"""
from __future__ import annotations

import math

import numpy as np

from ...fmu_src.spec import DEFAULT_STEP


def rel_err(a, b) -> float:
    """max |a - b| / max(1, max |b|); inf when the shapes differ or a is not finite."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    if a.shape != b.shape or not np.all(np.isfinite(a)):
        return math.inf
    return float(np.max(np.abs(a - b), initial=0.0) / max(1.0, float(np.max(np.abs(b), initial=0.0))))


def bounded(name: str, compute, limit: float):
    """Check that ``compute()`` (an error measure) is <= limit; a malformed table (any exception)
    fails it with the exception as detail."""
    from ..certificate import Check

    try:
        value, detail = float(compute()), ""
    except Exception as exc:       # a corrupted table of any shape fails the check, never crashes it
        value, detail = math.inf, repr(exc)
    if math.isnan(value):
        value = math.inf
    return Check(name, value, float(limit), bool(value <= limit), "<=", detail)


def absent(data: dict, runtime: str) -> list:
    """[a failing check] when ``data`` carries no tables (they are attached when a design or
    plant file is built), else []."""
    if isinstance(data.get("tables"), dict) and data["tables"]:
        return []
    return [bounded(f"{runtime} tables present (attached when the file is built)", lambda: math.inf, 0.0)]


def zoh_expm(A, B, h: float):
    """(Phi, Gam) of z' = A z + B u over h by scipy's expm of the Van Loan block matrix."""
    import scipy.linalg

    A, B = np.atleast_2d(np.asarray(A, float)), np.asarray(B, float).reshape(len(A), -1)
    n, m = B.shape
    E = scipy.linalg.expm(np.block([[A * h, B * h], [np.zeros((m, n + m))]]))
    return E[:n, :n], E[:n, n:]


def _estimators(data: dict) -> list[dict]:
    return [data["estimator"]] if "estimator" in data else list(data["estimators"])


def checks(data: dict) -> list:
    import scipy.signal

    if absent(data, "fixed-order estimator"):
        return absent(data, "fixed-order estimator")
    t = data["tables"]
    ests = _estimators(data)
    out = [bounded("fixed-order estimator tables: default step h0 = the FMU's default step (difference)",
                   lambda: abs(float(t["h0"]) - DEFAULT_STEP), 0.0),
           bounded("fixed-order estimator tables: one band per estimator and order n = deg den (difference)",
                   lambda: abs(len(t["bands"]) - len(ests)) + max(abs(int(t["n"]) - (len(e["den"]) - 1))
                                                                for e in ests), 0.0)]
    if "estimators" in data:
        edges = [float(e["vx_band"][0]) for e in ests] + [float(ests[-1]["vx_band"][1])]
        out.append(bounded("fixed-order estimator tables: band edges = the estimators' vx_band (difference)",
                           lambda: rel_err(t["edges"], edges), 0.0))
    else:
        out.append(bounded("fixed-order estimator tables: unscheduled (no edges) (0 = yes)",
                           lambda: 0.0 if t["edges"] is None else 1.0, 0.0))

    def tf_err():
        """Transfer function of the stored (A, B, C, D) (scipy ss2tf) vs num/den, and a0."""
        err = 0.0
        for band, est in zip(t["bands"], ests):
            num, den = np.asarray(est["num"], float), np.asarray(est["den"], float)
            n = len(den) - 1
            a0 = den[0] / den[-1] if n else 1.0
            err = max(err, abs(float(band["a0"]) - a0) / max(1.0, abs(a0)))
            if n == 0:
                err = max(err, abs(float(band["D"]) - num[0] / den[0]) / max(1.0, abs(num[0] / den[0])))
                continue
            bn, bd = scipy.signal.ss2tf(np.asarray(band["A"], float), np.asarray(band["B"], float)[:, None],
                                        np.asarray([band["C"]], float), np.asarray([[band["D"]]], float))
            want_n = np.zeros(n + 1)
            want_n[:len(num)] = num
            err = max(err, rel_err(bn[0], want_n[::-1] / den[-1]), rel_err(bd, den[::-1] / den[-1]))
        return err

    def map_err():
        """The stored maps at h0 vs scipy's expm of the stored (A, B)."""
        err = 0.0
        for band in t["bands"]:
            if not band["A"]:
                err = max(err, 0.0 if band["Phi_h0"] == [] and band["Gam_h0"] == [] else math.inf)
                continue
            Phi, Gam = zoh_expm(band["A"], band["B"], float(t["h0"]))
            err = max(err, rel_err(band["Phi_h0"], Phi), rel_err(band["Gam_h0"], Gam[:, 0]))
        return err

    out.append(bounded("fixed-order estimator tables: C (sI - A)^-1 B + D of every band = num/den (scipy ss2tf; "
                       "max rel. error)", tf_err, 1e-9))
    out.append(bounded("fixed-order estimator tables: step maps at h0 = scipy's expm (max rel. error)", map_err, 1e-10))
    return out
