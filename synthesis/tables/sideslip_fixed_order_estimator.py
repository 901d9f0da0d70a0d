"""Tables of paper 002's fixed-order estimator beta^ = (y(s)/x(s)) r (one estimator or one per speed band).

Validates the design file's ``estimator`` / ``estimators`` (ascending coefficients, proper,
Hurwitz, contiguous bands, one order) and stores per band the controllable canonical form and its
exact zero-order-hold map at the FMU's default step (docs/runtime/sideslip_fixed_order_estimator.md).
"""
from __future__ import annotations

import math

from ...fmu_src.spec import DEFAULT_STEP
from ...fmu_src.linalg import zoh_map


def _vector(v, what: str) -> list[float]:
    if isinstance(v, (str, bytes)) or not hasattr(v, "__iter__"):
        raise ValueError(f"data file: {what} must be a list of numbers, got {v!r}")
    try:
        out = [float(x) for x in v]
    except (TypeError, ValueError) as exc:
        raise ValueError(f"data file: {what} must be a list of numbers ({exc})") from exc
    if not all(math.isfinite(x) for x in out):
        raise ValueError(f"data file: {what} has a non-finite entry: {out}")
    return out


def hurwitz(p) -> bool:
    """True iff the polynomial p (ascending, p[-1] != 0) has every root in Re s < 0 (Routh)."""
    c = [x / p[-1] for x in reversed(p)]           # descending, monic
    if any(x <= 0 for x in c):                     # necessary: all coefficients positive
        return False
    r0, r1 = c[0::2], c[1::2]
    while r1:
        if r1[0] <= 0:
            return False
        nxt = [r0[k + 1] - r0[0] / r1[0] * (r1[k + 1] if k + 1 < len(r1) else 0.0) for k in range(len(r0) - 1)]
        r0, r1 = r1, nxt
    return True


def realise(num, den, what: str = "estimator") -> dict:
    """Controllable canonical form {A, B, C, D, a0} of num/den (ascending lists), a0 the constant
    coefficient of the monic denominator (1.0 for a static gain, n = 0, where it is unused).
    Validates; errors name ``what``."""
    num = _vector(num, f"{what}.num")
    den = _vector(den, f"{what}.den")
    if not den:
        raise ValueError(f"data file: {what}.den is empty")
    if den[-1] == 0.0:
        raise ValueError(f"data file: {what}.den's leading (last, ascending order) coefficient is 0; "
                         f"coefficients are ascending in s: {den}")
    while num and num[-1] == 0.0:
        num.pop()
    n = len(den) - 1
    if len(num) - 1 > n:
        raise ValueError(f"data file: {what} is not proper: deg num = {len(num) - 1} > deg den = {n} "
                         "(coefficients are ascending in s)")
    if n >= 1 and not hurwitz(den):
        raise ValueError(f"data file: {what}.den = {den} is not Hurwitz (a root with Re s >= 0); "
                         "coefficients are ascending in s")
    lead = den[-1]
    a = [x / lead for x in den[:-1]]
    b = [x / lead for x in num] + [0.0] * (n + 1 - len(num))
    D = b[n]
    C = [b[k] - D * a[k] for k in range(n)]
    A = [[1.0 if j == i + 1 else 0.0 for j in range(n)] for i in range(n - 1)]
    if n:
        A.append([-x for x in a])
    B = [0.0] * (n - 1) + [1.0] if n else []
    return {"A": A, "B": B, "C": C, "D": D, "a0": a[0] if n else 1.0}


def _entries(data: dict) -> tuple[list, list | None]:
    """[(what, {num, den}), ...] and the band edges (None: one unscheduled estimator)."""
    if not isinstance(data, dict):
        raise ValueError(f"data file must be a JSON object, got {type(data).__name__}")
    if "estimator" in data and "estimators" in data:
        raise ValueError("data file: give either 'estimator' or 'estimators' (speed-scheduled), not both")
    if "estimator" in data:
        est = data["estimator"]
        if not isinstance(est, dict):
            raise ValueError("data file: estimator must be an object {num, den}")
        return [("estimator", est)], None
    if "estimators" not in data:
        raise ValueError("data file lacks 'estimator' ({num, den}, ascending in s) or 'estimators'")
    ests = data["estimators"]
    if not isinstance(ests, list) or not ests:
        raise ValueError("data file: estimators must be a non-empty list of {num, den, vx_band}")
    entries, edges = [], []
    for i, est in enumerate(ests):
        what = f"estimators[{i}]"
        if not isinstance(est, dict):
            raise ValueError(f"data file: {what} must be an object {{num, den, vx_band}}")
        if "vx_band" not in est:
            raise ValueError(f"data file: {what}.vx_band is missing (a speed-scheduled estimator needs it)")
        band = _vector(est["vx_band"], f"{what}.vx_band")
        if len(band) != 2 or not band[0] < band[1]:
            raise ValueError(f"data file: {what}.vx_band must be [lo, hi] with lo < hi, got {band}")
        if i == 0:
            edges.append(band[0])
        elif band[0] != edges[-1]:
            raise ValueError(f"data file: {what}.vx_band starts at {band[0]} m/s but the previous band "
                             f"ends at {edges[-1]} m/s (bands must be increasing and contiguous)")
        edges.append(band[1])
        entries.append((what, est))
    return entries, edges


def compute(data: dict) -> dict:
    """{"h0", "n", "edges" (None: unscheduled), "bands": [{A, B, C, D, a0, Phi_h0, Gam_h0}]}: the
    realisation of every band and its exact ZOH map over the default step h0 (Van Loan,
    ``linalg.zoh_map``, the map the runtimes use at any other step)."""
    entries, edges = _entries(data)
    bands = []
    for what, est in entries:
        for key in ("num", "den"):
            if key not in est:
                raise ValueError(f"data file: {what}.{key} is missing")
        bands.append(realise(est["num"], est["den"], what))
    n = len(bands[0]["A"])
    for (what, _), band in zip(entries, bands):
        if len(band["A"]) != n:
            raise ValueError(f"data file: {what}.den has degree {len(band['A'])}, the first estimator's "
                             f"{n}: scheduled estimators need the same order (bumpless switching)")
        E = zoh_map(band["A"], [[b] for b in band["B"]], DEFAULT_STEP) if n else []
        band["Phi_h0"] = [row[:n] for row in E]
        band["Gam_h0"] = [row[n] for row in E]
    return {"h0": DEFAULT_STEP, "n": n, "edges": edges, "bands": bands}
