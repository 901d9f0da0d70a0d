"""The journal of a Monte Carlo campaign (one JSON line per finished run, append-only) and its
summary statistics."""
from __future__ import annotations

import json
import math
import os
import time
from pathlib import Path
from typing import Any, Mapping

import numpy as np


from .campaign import Campaign, CampaignError

#: percentiles of every metric in the summary
PERCENTILES = (5, 50, 95, 99)
#: resamples of the bootstrap confidence interval of each metric's mean
BOOTSTRAP_RESAMPLES = 2000
WORST_RUNS = 5


# --------------------------------------------------------------------------------------------
# the journal: one JSON line per finished run, append-only
# --------------------------------------------------------------------------------------------
class Journal:
    """``runs.jsonl``: the rows of finished runs, appended one line per run and flushed at once
    (fsync at most every second, and at close), so an interrupted campaign keeps every run that
    finished. :meth:`read` skips a torn last line (a kill in the middle of a write; the next
    :meth:`append` cuts it off) and keeps the first row of a run index seen twice."""

    FSYNC_EVERY_S = 1.0

    def __init__(self, path: str | os.PathLike):
        self.path = Path(path)
        self._f = None
        self._synced = 0.0
        self.duplicates = 0

    def read(self) -> dict[int, dict[str, Any]]:
        rows: dict[int, dict[str, Any]] = {}
        if not self.path.is_file():
            return rows
        lines = self.path.read_text(encoding="utf-8").split("\n")
        for i, line in enumerate(lines):
            if not line.strip():
                continue
            try:
                row = json.loads(line)
                k = int(row["run"])
            except (ValueError, KeyError, TypeError):
                if i == len(lines) - 1:          # the last line, cut short by a kill: dropped
                    continue
                raise CampaignError(f"{self.path}: line {i + 1} is not a run row; the journal is damaged "
                                    "(remove the folder to start again)") from None
            if k in rows:
                self.duplicates += 1
                continue
            rows[k] = row
        return rows

    def append(self, row: Mapping[str, Any]) -> None:
        if self._f is None:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            if self.path.is_file():              # a torn last line (a kill mid-write) is cut off
                data = self.path.read_bytes()
                if data and not data.endswith(b"\n"):
                    with open(self.path, "r+b") as f:
                        f.truncate(data.rfind(b"\n") + 1)
            self._f = open(self.path, "a", encoding="utf-8")
        self._f.write(json.dumps(row, allow_nan=False, separators=(",", ":")) + "\n")
        self._f.flush()
        now = time.monotonic()
        if now - self._synced >= self.FSYNC_EVERY_S:
            os.fsync(self._f.fileno())
            self._synced = now

    def close(self) -> None:
        if self._f is not None:
            self._f.flush()
            os.fsync(self._f.fileno())
            self._f.close()
            self._f = None


# --------------------------------------------------------------------------------------------
# summary
# --------------------------------------------------------------------------------------------
def metric_columns(rows: list[Mapping[str, Any]]) -> list[str]:
    cols: dict[str, None] = {}
    for r in rows:
        for k in r.get("metrics", {}):
            cols.setdefault(k, None)
    return list(cols)


def headline_columns(metrics: Mapping[str, Any], inputs: Mapping[str, list[str]]) -> list[str]:
    """The metric columns ranked for the worst runs and plotted: the RMS error of each estimate of
    a quantity the observer does not measure (``beta``, ``bank_angle``, ``Fyf``, ``beta_filtered``; not
    the estimate of the ``yaw_rate`` it reads), and each interval's violation count and mean width (the widest runs:
    an interval that never misses the truth is judged by how wide it is). ``inputs``: {label:
    its inputs}."""
    from .metrics import quantity_of

    out = []
    for col in metrics:
        label, _, rest = col.partition(".")
        q, _, what = rest.rpartition(".")
        if what in ("violations", "mean_width") or (what == "rms" and quantity_of(q) not in inputs.get(label, ())):
            out.append(col)
    return out


def _stats(x: np.ndarray, rng: np.random.Generator) -> dict[str, Any]:
    """Statistics of the finite values of ``x`` (:func:`stats_table` of one column)."""
    return stats_table({"x": x}, rng)["x"]


def stats_table(columns: Mapping[str, np.ndarray], rng: np.random.Generator) -> dict[str, dict[str, Any]]:
    """Per column: n, mean, min, max, the :data:`PERCENTILES` and the 95 % bootstrap interval of the
    mean over the column's finite values (:data:`BOOTSTRAP_RESAMPLES` resamples). The columns with
    the same finite samples share their resamples (each column's interval is a bootstrap interval
    of its own; the resampling counts of a group are one matrix W, the means W x / n)."""
    out: dict[str, dict[str, Any]] = {}
    groups: dict[bytes, list[str]] = {}
    finite = {}
    for name, x in columns.items():
        x = np.asarray(x, dtype=float)
        m = np.isfinite(x)
        finite[name] = x[m]
        if not m.any():
            out[name] = {"n": 0}
            continue
        groups.setdefault(np.packbits(m).tobytes() + len(m).to_bytes(8, "little"), []).append(name)
    for names in groups.values():
        n = finite[names[0]].size
        idx = rng.integers(0, n, size=(BOOTSTRAP_RESAMPLES, n))
        W = np.bincount((idx + n * np.arange(BOOTSTRAP_RESAMPLES)[:, None]).ravel(),
                        minlength=BOOTSTRAP_RESAMPLES * n).reshape(BOOTSTRAP_RESAMPLES, n)
        means = (W @ np.column_stack([finite[k] for k in names])) / n
        for j, name in enumerate(names):
            x = finite[name]
            d: dict[str, Any] = {"n": int(n), "mean": float(np.mean(x)), "max": float(np.max(x)),
                                 "min": float(np.min(x))}
            d.update({f"p{p}": float(v) for p, v in zip(PERCENTILES, np.percentile(x, PERCENTILES))})
            d["mean_ci95"] = [float(v) for v in np.percentile(means[:, j], (2.5, 97.5))]
            out[name] = d
    return {name: out[name] for name in columns}


def summarize(c: Campaign, rows: list[Mapping[str, Any]]) -> dict[str, Any]:
    """Percentiles (5, 50, 95, 99), min, max, mean and its 95 % bootstrap interval of every metric
    over the successful runs (and per part of the record for a replay campaign); the failed
    runs with their errors; for every interval, the runs whose bounds missed the truth; and the
    :data:`WORST_RUNS` worst runs of every headline metric with their seeds and parameters."""
    ok = [r for r in rows if r["status"] == "ok"]
    failed = [r for r in rows if r["status"] != "ok"]
    cols = metric_columns(ok)
    rng = np.random.default_rng(0)        # the bootstrap's resampling: fixed, the summary is reproducible

    def table(sel):
        return stats_table({col: np.array([np.nan if r["metrics"].get(col) is None else r["metrics"][col]
                                           for r in sel], dtype=float) for col in cols}, rng)

    out: dict[str, Any] = {"campaign": c.name, "runs": len(rows), "ok": len(ok), "failed": len(failed),
                           "failures": [{"run": r["run"], "seed": r["seed"], "error": r["error"]}
                                        for r in sorted(failed, key=lambda r: r["run"])][:50],
                           "metrics": table(ok)}
    if c.kind == "replay":
        out["by_part"] = {p: table([r for r in ok if r["params"].get("segment.part") == p])
                          for p in ("train", "test") if any(r["params"].get("segment.part") == p for r in ok)}
    enclosure = {}
    for col in cols:
        if col.endswith(".violations"):
            v = [(r["metrics"].get(col) or 0.0, r) for r in ok]
            bad = [r for x, r in v if x > 0]
            enclosure[col[: -len(".violations")]] = {
                "runs_with_violations": len(bad), "runs": len(v), "violating_samples": int(sum(x for x, _ in v)),
                "runs_violating": [{"run": r["run"], "seed": r["seed"]} for r in sorted(bad, key=lambda r: r["run"])][:20]}
    out["enclosure"] = enclosure
    heads = headlines(ok)
    worst = {}
    for col in heads:
        vals = [(r["metrics"].get(col), r) for r in ok if r["metrics"].get(col) is not None]
        vals.sort(key=lambda p: (-p[0], p[1]["run"]))
        worst[col] = [{"run": r["run"], "seed": r["seed"], "value": x, "params": r["params"]}
                      for x, r in vals[:WORST_RUNS] if not (col.endswith(".violations") and x == 0)]
    out["worst"] = worst
    out["headline"] = heads
    out["versus_baselines"] = versus_baselines(ok, rng)
    return out


def versus_baselines(ok: list[Mapping[str, Any]], rng: np.random.Generator | None = None) -> dict[str, Any]:
    """Per observer and estimated quantity (``LABEL.X``, the columns ``LABEL.X.ratio`` of
    :func:`latobs.validation.campaign_run.baseline_metrics`): the distribution of observer RMS /
    best baseline RMS over the runs (:func:`_stats`), the fraction of runs the observer wins
    (better than every baseline), how often each baseline was the best, the :data:`WORST_RUNS`
    runs of the highest ratio with their seeds and drawn quantities; and the same over the samples
    where the observer declares itself valid (``valid``: its ratio, win fraction and the mean share
    of valid samples), when it has a validity flag."""
    rng = rng if rng is not None else np.random.default_rng(0)
    out: dict[str, Any] = {}
    keys = list(dict.fromkeys(c[: -len(".ratio")] for c in metric_columns(ok)
                              if c.endswith(".ratio") and not c.endswith(".valid_ratio")))

    def col(r, name):
        x = r["metrics"].get(name)
        return np.nan if x is None else float(x)

    for key in keys:
        label, _, q = key.partition(".")
        bases = sorted({c[len(key) + len(".rms_"):] for r in ok for c in r["metrics"]
                        if c.startswith(key + ".rms_")})

        def part(pre):
            ratio = np.array([col(r, f"{key}.{pre}ratio") for r in ok], dtype=float)
            wins = np.array([col(r, f"{key}.{pre}wins") for r in ok], dtype=float)
            scored = np.isfinite(wins)
            return ratio, {"runs": int(np.sum(scored)), "ratio": _stats(ratio, rng),
                           "win_fraction": float(np.mean(wins[scored])) if np.any(scored) else None,
                           "wins": int(np.sum(wins[scored] == 1.0))}

        ratio, entry = part("")
        entry.update({"observer": label, "quantity": q, "baselines": bases})
        best: dict[str, int] = {}
        for r in ok:
            rs = {b: col(r, f"{key}.rms_{b}") for b in bases}
            rs = {b: v for b, v in rs.items() if math.isfinite(v)}
            if rs:
                b = min(rs, key=rs.get)
                best[b] = best.get(b, 0) + 1
        entry["best_baseline_runs"] = best
        order = sorted((i for i in range(len(ok)) if math.isfinite(ratio[i])), key=lambda i: (-ratio[i], ok[i]["run"]))
        entry["worst"] = [{"run": ok[i]["run"], "seed": ok[i]["seed"], "ratio": float(ratio[i]),
                           "params": ok[i]["params"]} for i in order[:WORST_RUNS]]
        if any(f"{key}.valid_ratio" in r["metrics"] for r in ok):
            _, v = part("valid_")
            frac = np.array([col(r, f"{label}.valid_fraction") for r in ok], dtype=float)
            v["mean_valid_fraction"] = float(np.nanmean(frac)) if np.any(np.isfinite(frac)) else None
            entry["valid"] = v
        out[key] = entry
    return out


def headlines(rows: list[Mapping[str, Any]]) -> list[str]:
    """The headline columns of the runs (:func:`headline_columns`, recorded in each row)."""
    return list(dict.fromkeys(c for r in rows for c in r.get("headline", ())))


def rows_table(rows: list[Mapping[str, Any]]):
    """The runs as a pyarrow Table: run, seed, status, error, seconds, worker, one column per
    drawn quantity (``param.NAME``) and per metric."""
    import pyarrow as pa

    rows = sorted(rows, key=lambda r: r["run"])
    params: dict[str, None] = {}
    for r in rows:
        for k in r["params"]:
            params.setdefault(k, None)
    cols: dict[str, list] = {k: [r.get(k) for r in rows] for k in ("run", "seed", "status", "error", "seconds", "worker")}
    for p in params:
        cols[f"param.{p}"] = [r["params"].get(p) for r in rows]
    for m in metric_columns(rows):
        cols[m] = [r["metrics"].get(m) for r in rows]
    return pa.table(cols)
