"""Long records replayed in constant memory: ``latobs replay`` of a record larger than
:func:`stream_bytes` reads it in blocks, steps the FMU block by block, writes every output to
``outputs.parquet`` as it goes, and accumulates the metrics of :func:`latobs.validation.replay.score`
over the blocks; the figures are drawn from every k-th sample (at most :data:`PLOT_SAMPLES`).
What it holds is a block (:data:`latobs.data.records.BLOCK_ROWS` rows) and the figures' samples,
whatever the record's length: a 1 h record at 1 ms (3.6 million rows) replays in about 200 MB.

The metrics are those of the whole-array scoring, summed block by block (the same values up to
the rounding of the sums, ~1e-15 relative); the model baselines, which simulate a model over the
whole record (and fit one on its tuning part), are not computed for a streamed record: the
``baselines`` entry says so in ``skipped``. docs/validation.md describes it.

A long co-simulation is streamed the same way: :class:`CosimSink` receives its blocks
(:meth:`latobs.validation.master.CoSimulation._simulate_blocks`), writes ``outputs.parquet`` and
sums the metrics (:class:`latobs.validation.metrics.StreamedMetrics`)."""
from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from ..data import records as _records
from . import metrics as _metrics
from . import replay as rp

STREAM_ENV = "LATOBS_STREAM_ABOVE_MB"
#: a record file larger than this (MB; a .gz file's size counts 5 times, its text's usual ratio) is
#: streamed; $LATOBS_STREAM_ABOVE_MB sets it. The bundled record (1.3 MB) and every test record are below
STREAM_ABOVE_MB = 64.0
GZ_RATIO = 5
#: the figures of a streamed replay show at most this many samples (every k-th)
PLOT_SAMPLES = 200_000


def stream_bytes() -> float:
    text = os.environ.get(STREAM_ENV, "").strip()
    try:
        mb = float(text) if text else STREAM_ABOVE_MB
    except ValueError:
        raise rp.ReplayError(f"${STREAM_ENV} must be a number of MB, got {text!r}") from None
    return mb * 1024 * 1024


def streamed(path: str | os.PathLike) -> bool:
    """Whether the record at ``path`` is replayed block by block (its size above :func:`stream_bytes`)."""
    path = Path(path)
    try:
        size = path.stat().st_size
    except OSError:
        return False
    return size * (GZ_RATIO if path.name.lower().endswith(".gz") else 1) > stream_bytes()


def _blocks(path: Path):
    try:
        yield from _records.iter_blocks(path)
    except _records.RecordError as exc:
        raise rp.ReplayError(str(exc)) from None


def scan(path: str | os.PathLike, inputs, who: str = "the observer") -> dict[str, Any]:
    """The checks of ``latobs replay`` on a record read block by block (a ReplayError naming the
    culprit, before anything is built): the record's own (:func:`latobs.data.records.iter_blocks`),
    its inputs' (:func:`latobs.validation.replay.check_record`, each block) and a uniform time step
    (:func:`latobs.validation.replay.uniform_step`'s rule). Returns {"n", "columns", "t0", "t_end", "dt"}."""
    path = Path(path)
    n, names, t0, t_end, tmax = 0, None, None, None, 0.0
    dmin, dmax = math.inf, -math.inf
    prev = None
    for b in _blocks(path):
        if names is None:
            names = list(b)
            rp.check_record(b, inputs, path, who)      # (the missing columns named once)
        else:
            rp.check_record(b, inputs, path, who, first_row=n)
        t = b["t"]
        t0 = float(t[0]) if t0 is None else t0
        tau = (t if prev is None else np.concatenate([[prev], t])) - t0
        if tau.size > 1:
            d = np.diff(tau)
            dmin, dmax = min(dmin, float(d.min())), max(dmax, float(d.max()))
        prev = float(t[-1])
        tmax = max(tmax, float(np.max(np.abs(t))))
        n += t.size
    t_end = prev
    dt = (t_end - t0) / (n - 1)
    tol = rp.UNIFORM_RTOL * dt + rp.UNIFORM_ULPS * float(np.spacing(tmax))
    if dmax - dt > tol or dt - dmin > tol:
        worst = dmax if dmax - dt > dt - dmin else dmin
        raise rp.ReplayError(f"{path}: the time step is not uniform: {'a gap' if worst > dt else 'a short step'} of "
                             f"{worst:.6g} s where the mean step is {dt:.6g} s (allowed deviation {tol:.3g} s); "
                             "resample the record to a fixed step")
    return {"n": n, "columns": names, "t0": t0, "t_end": t_end, "dt": dt}


class _Err:
    """error_stats of estimate - truth, summed block by block."""

    def __init__(self):
        self.n, self.s1, self.s2, self.mx, self.nonfinite = 0, 0.0, 0.0, None, 0

    def add(self, y, x):
        e = np.asarray(y, dtype=float) - np.asarray(x, dtype=float)
        if not e.size:
            return
        self.n += e.size
        self.s1 += float(np.sum(e))
        self.s2 += float(np.sum(e ** 2))
        m = float(np.max(np.abs(e)))
        self.mx = m if self.mx is None else float(np.maximum(self.mx, m))     # (NaN kept)
        self.nonfinite += int(np.sum(~np.isfinite(e)))

    def result(self) -> dict[str, Any]:
        f = _metrics._f
        n = self.n
        return {"n_samples": n, "rms": f(math.sqrt(self.s2 / n)) if n and not self.s2 < 0 else None,
                "max_abs": f(self.mx) if n else None, "mean_error": f(self.s1 / n) if n else None,
                "nonfinite_samples": self.nonfinite}


class _Enc:
    """enclosure_stats of [lower, upper] around truth, summed block by block."""

    def __init__(self):
        self.n, self.nv, self.over, self.width, self.nonfinite = 0, 0, None, 0.0, 0

    def add(self, lo, hi, x, tol: float = _metrics.ENCLOSURE_TOL):
        lo, hi, x = (np.asarray(a, dtype=float) for a in (lo, hi, x))
        if not x.size:
            return
        self.n += x.size
        self.nv += int(np.sum((x < lo - tol) | (x > hi + tol) | ~np.isfinite(lo) | ~np.isfinite(hi)))
        over = np.maximum(lo - x, x - hi)
        if np.any(np.isfinite(over)):
            m = float(np.nanmax(over))
            self.over = m if self.over is None else max(self.over, m)
        width = hi - lo
        self.width += float(np.sum(width))
        self.nonfinite += int(np.sum(~np.isfinite(width)))

    def result(self) -> dict[str, Any]:
        f, n = _metrics._f, self.n
        return {"n_samples": n, "enclosure_violations": self.nv,
                "violation_rate": self.nv / n if n else None, "enclosure_rate": 1.0 - self.nv / n if n else None,
                "max_violation": f(max(0.0, self.over)) if n and self.over is not None else None,
                "mean_width": f(self.width / n) if n else None, "nonfinite_samples": self.nonfinite}


class _Modes:
    """mode_occupancy and switches of one segment, summed block by block (zero-order hold)."""

    def __init__(self):
        self.w: dict[int, float] = {}
        self.switches, self.first, self.last, self.n, self.modes = 0, None, None, 0, set()

    def add(self, t, mo, prev):
        """``t``, ``mo``: the segment's samples of a block; ``prev``: (t, mode) of its sample before."""
        if not t.size:
            return
        if self.first is None:
            self.first = float(t[0])
        tt, mm = (t, mo) if prev is None else (np.concatenate([[prev[0]], t]), np.concatenate([[prev[1]], mo]))
        w = np.diff(tt)
        for m in np.unique(mm[:-1]):
            self.w[int(m)] = self.w.get(int(m), 0.0) + float(np.sum(w[mm[:-1] == m]))
        self.switches += int(np.sum(mm[1:] != mm[:-1]))
        self.modes.update(int(m) for m in np.unique(mo))
        self.last = float(t[-1])
        self.n += t.size

    def result(self):
        if not self.n:
            return None
        if self.n < 2:
            return {"occupancy": {str(m): 1.0 for m in sorted(self.modes)}, "switches": 0}
        total = self.last - self.first
        return {"occupancy": {str(m): w / total for m, w in sorted(self.w.items())}, "switches": self.switches}


def _zero_baseline(o: Mapping[str, Any], zero: Mapping[tuple[str, str], _Err], segs: list[str], seg: str,
                   n: int) -> dict[str, Any]:
    """The ``baselines`` entry of a streamed replay: the zero baseline (every estimate 0) beside
    each scored estimate and interval midpoint, summed over the blocks; the model baselines, which
    simulate the whole record (and fit one on its tuning part), are not computed: ``skipped``, and
    ``not_computed`` in each verdict (so no verdict that the observer is best)."""
    why = (f"not computed for a streamed record ({n} samples, replayed block by block): it simulates the whole "
           "record")
    missing = {"bicycle": why, **({"regression": why} if seg == "after_split" else {})}
    out: dict[str, Any] = {"zero": {}}
    summary = {}
    for kind in ("estimates", "intervals"):
        for name, e in o[kind].items():
            out["zero"][name] = {"truth": e["truth"], "unit": e.get("unit"),
                                 **{s: zero[(name, s)].result() for s in segs}}
            stats = e if kind == "estimates" else e["midpoint"]
            summary[name] = {"segment": seg, **_metrics.baseline_summary(
                (stats.get(seg) or {}).get("rms"), {"zero": out["zero"][name][seg]["rms"]}, "rms",
                "estimate" if kind == "estimates" else "interval midpoint", missing)}
    out["summary"] = summary
    out["skipped"] = dict(missing)
    out["about"] = {"zero": {"what": "every estimate 0, summed over the blocks"}}
    return out


def run(path: str | os.PathLike, fmu_path: str | os.PathLike, out_dir: str | os.PathLike, split: float | None,
        observer: str, vehicle: str | None, mass: float | None, plots: bool = True,
        progress: bool = True, info: Mapping[str, Any] | None = None) -> tuple[dict[str, Any], list[Path]]:
    """``replay.run`` of a long record, block by block (module docstring): writes
    ``out_dir/metrics.json``, ``out_dir/outputs.parquet`` (t and every output) and the figures;
    returns (metrics, paths). ``info``: what :func:`scan` returned for the record (else it is read
    once more to know it)."""
    import pyarrow as pa
    import pyarrow.parquet as pq
    from tqdm import tqdm

    from ..atomic import atomic_path, sha256_file
    from .harness import FmuInstance, WiringError, _unit_of
    from .instance import fmi_type

    path, fmu_path, out_dir = Path(path), Path(fmu_path), Path(out_dir)
    info = scan(path, [], observer) if info is None else info
    n, dt = info["n"], info["dt"]
    label = fmu_path.stem
    try:
        f = FmuInstance(label, fmu_path, None)
    except WiringError as exc:
        raise rp.ReplayError(str(exc)) from None
    except Exception as exc:  # not a zip, not an FMU
        raise rp.ReplayError(f"cannot open FMU {fmu_path}: {exc}") from None
    out_dir.mkdir(parents=True, exist_ok=True)
    every = max(1, math.ceil(n / PLOT_SAMPLES))
    kept: dict[str, list[np.ndarray]] = {}
    try:
        in_names = [v.name for v in f.inputs]
        units = {v.name: u for v in f.md.modelVariables if (u := _unit_of(v)) and v.causality in ("input", "output")}
        out_types = {v.name: (float if fmi_type(v) == "Real" else np.int64) for v in f.outputs}
        outs = list(out_types)
        hats, pairs = _metrics.estimated_quantities(outs)
        filtered = _metrics.filtered_outputs(outs)
        cols = [c for c in info["columns"] if c != "t"]
        truth = {q: _metrics.truth_signal(q, cols, f.model_name) for q in
                 [*hats, *pairs, *(_metrics.quantity_of(x) for x in filtered)]}
        force = all(b in outs for b in rp.FORCE_BOUNDS) and "ay" in cols
        segs = ["all"] + (["before_split", "after_split"] if split is not None else [])

        def in_seg(s, t):
            return np.ones(t.size, bool) if s == "all" else (t < split) if s == "before_split" else (t >= split)

        est = {(q + "_hat", s): _Err() for q in hats if truth[q] for s in segs}
        fil = {(x, s): _Err() for x in filtered if truth[_metrics.quantity_of(x)] for s in segs}
        enc = {(q, s): _Enc() for q in pairs if truth[q] for s in segs}
        mid = {(q, s): _Err() for q in pairs if truth[q] for s in segs}
        zero = {k: _Err() for k in [*est, *fil, *mid]}       # the zero baseline beside each: -truth
        fsum = {s: _Enc() for s in segs} if force and mass is not None else {}
        modes = {s: _Modes() for s in segs} if "mode" in outs else {}
        seg_t = {s: [None, None, 0] for s in segs}
        prev = None                                    # the previous block's last row: (t, {col}, {out})
        schema = pa.schema([("t", pa.float64())] + [(x, pa.float64() if typ is float else pa.int64())
                                                    for x, typ in out_types.items()])
        bar = tqdm(total=n, unit="row", desc=f"replay {path.name}", disable=None if progress else True, leave=False,
                   mininterval=0.5)
        row = 0
        with atomic_path(out_dir / "outputs.parquet", suffix=".parquet") as tmp, \
                pq.ParquetWriter(str(tmp), schema) as writer:
            for b in _blocks(path):
                t = b["t"]
                m = t.size
                if prev is None:
                    tb, cb = t, {x: b[x] for x in in_names}
                    first = rp.start(f, {x: float(b[x][0]) for x in in_names}, None, float(t[0]), info["t_end"])
                else:   # the previous block's last row first: its outputs are row 0 of this stepping
                    tb = np.concatenate([[prev[0]], t])
                    first = prev[2]
                    cb = {x: np.concatenate([[prev[1][x]], b[x]]) for x in in_names}
                y = rp.step_rows(f, in_names, tb, dt, cb, first)
                if prev is not None:
                    y = {x: v[1:] for x, v in y.items()}
                writer.write_table(pa.table({"t": t, **y}, schema=schema))
                # the metrics of this block's rows
                for s in segs:
                    sel = in_seg(s, t)
                    if sel.any():
                        st = seg_t[s]
                        st[0] = float(t[sel][0]) if st[0] is None else st[0]
                        st[1] = float(t[sel][-1])
                        st[2] += int(sel.sum())
                    for (name, s2), acc in est.items():
                        if s2 == s:
                            x = b[truth[_metrics.quantity_of(name)]][sel]
                            acc.add(y[name][sel], x)
                            zero[(name, s)].add(np.zeros(x.size), x)
                    for (q, s2), acc in enc.items():
                        if s2 == s:
                            lo, hi, x = y[q + "_lower"][sel], y[q + "_upper"][sel], b[truth[q]][sel]
                            acc.add(lo, hi, x)
                            mid[(q, s)].add(0.5 * (np.asarray(lo, float) + np.asarray(hi, float)), x)
                            zero[(q, s)].add(np.zeros(x.size), x)
                    if s in fsum:
                        lo = np.asarray(y["Fyf_lower"], float) + np.asarray(y["Fyr_lower"], float)
                        hi = np.asarray(y["Fyf_upper"], float) + np.asarray(y["Fyr_upper"], float)
                        fsum[s].add(lo[sel], hi[sel], float(mass) * b["ay"][sel])
                    if s in modes:
                        p = None
                        if prev is not None and in_seg(s, np.array([prev[0]]))[0]:
                            p = (prev[0], prev[2]["mode"])
                        modes[s].add(t[sel], np.asarray(y["mode"])[sel], p)
                    # X_filtered at row k + 1 against the truth at row k: the pairs (k, k + 1) in the block
                    for (name, s2), acc in fil.items():
                        if s2 == s:
                            tr = truth[_metrics.quantity_of(name)]
                            yy = y[name] if prev is None else np.concatenate([[prev[2][name]], y[name]])
                            xx = b[tr] if prev is None else np.concatenate([[prev[1][tr]], b[tr]])
                            tt = t if prev is None else np.concatenate([[prev[0]], t])
                            ok = in_seg(s, tt)[:-1]
                            acc.add(np.asarray(yy, float)[1:][ok], xx[:-1][ok])
                            zero[(name, s)].add(np.zeros(int(ok.sum())), xx[:-1][ok])
                if plots:                              # every k-th row, for the figures
                    pick = (row + np.arange(m)) % every == 0
                    for k, v in [*b.items(), *(("out:" + x, v) for x, v in y.items())]:
                        kept.setdefault(k, []).append(v[pick])
                prev = (float(t[-1]), {k: float(v[-1]) for k, v in b.items()}, {x: y[x][-1] for x in outs})
                row += m
                bar.update(m)
        bar.close()
        logs = list(f.logs)
        if f.dropped_logs:
            logs.append(f"[INFO] replay: {f.dropped_logs} further log messages dropped")
        model_name = f.model_name
    finally:
        f.close()
    o: dict[str, Any] = {"estimates": {}, "intervals": {}}
    for q in hats:
        if truth[q]:
            name = q + "_hat"
            o["estimates"][name] = {"truth": truth[q], "unit": units.get(name) or units.get(truth[q]),
                                    **{s: est[(name, s)].result() for s in segs}}
    for name in filtered:
        tr = truth[_metrics.quantity_of(name)]
        if tr:
            o["estimates"][name] = {"truth": tr, "unit": units.get(name) or units.get(tr), "lag_steps": 1,
                                    **{s: fil[(name, s)].result() for s in segs}}
    for q in pairs:
        if truth[q]:
            o["intervals"][q] = {"truth": truth[q], "lower": q + "_lower", "upper": q + "_upper",
                                 "unit": units.get(q + "_lower") or units.get(truth[q]),
                                 **{s: enc[(q, s)].result() for s in segs},
                                 "midpoint": {s: mid[(q, s)].result() for s in segs}}
    scored = set(o["estimates"]) | {x for q in o["intervals"] for x in (q + "_lower", q + "_upper")}
    if all(b in outs for b in rp.FORCE_BOUNDS) and "ay" in cols:
        entry = rp.force_sum_entry(mass, vehicle)
        if mass is not None:
            entry.update({s: fsum[s].result() for s in segs})
            scored.add("may_in_force_sum")
        o["may_in_force_sum"] = entry
    if modes:
        o["modes"] = {s: modes[s].result() for s in segs}
    o["baselines"] = _zero_baseline(o, zero, segs, "after_split" if split is not None else "all", n)
    o["unscored_outputs"] = sorted(set(outs) - scored - {"mode"})
    o["log_messages"] = len(logs)
    o["log_excerpt"] = logs[:10]
    metrics = {"kind": "replay", "scenario": f"replay {rp.csv_stem(path)}", "csv": str(path),
               "csv_sha256": sha256_file(path), "observer": observer, "label": label, "fmu": str(fmu_path),
               "fmu_model": model_name, "vehicle": vehicle, "dt_s": dt, "n_samples": n,
               "t_start_s": info["t0"], "t_end_s": info["t_end"], "duration_s": info["t_end"] - info["t0"],
               "split_s": split,
               "segments": {s: {"t_from_s": seg_t[s][0], "t_to_s": seg_t[s][1], "n_samples": seg_t[s][2]}
                            for s in segs},
               "inputs": in_names, "columns": ["t", *cols], "scored": sorted(scored), "nothing_scored": not scored,
               "streamed": {"blocks_of_rows": _records.BLOCK_ROWS, "outputs": "outputs.parquet",
                            "figures_every_kth_sample": every},
               "observers": {label: o}}
    paths = [_metrics.write(metrics, out_dir), out_dir / "outputs.parquet"]
    if plots:
        joined = {k: np.concatenate(v) for k, v in kept.items()}
        kept.clear()
        t_k = joined.pop("t")
        run_k = rp.ReplayRun(time=t_k, columns={k: v for k, v in joined.items() if not k.startswith("out:")},
                             outputs={k[4:]: v for k, v in joined.items() if k.startswith("out:")},
                             inputs=in_names, dt=dt * every, fmu=fmu_path, model_name=model_name, label=label,
                             units=units, logs=logs, design=None)
        paths += rp.write_plots(run_k, metrics, out_dir, mass=mass)
    return metrics, paths




class CosimSink:
    """What a long co-simulation (:meth:`latobs.validation.master.CoSimulation._simulate_blocks`,
    more than :func:`latobs.validation.master.stream_steps` steps) hands its rows to, block by
    block: the metrics summed over the blocks (:class:`latobs.validation.metrics.StreamedMetrics`),
    with ``out_dir`` every row written to ``out_dir/outputs.parquet`` (columns ``t``, every bus
    signal by name, ``measured.X`` for what the observers received, ``LABEL.OUTPUT`` for every
    observer output; written in place when the ``with`` block ends without an error), and with
    ``keep`` every k-th sample kept for the figures (at most :data:`PLOT_SAMPLES`). A short run
    never calls it (``used`` stays False): it keeps the whole-array path.

    Use ``with CosimSink(...) as sink: result = master.run(..., sink=sink)``; then
    ``sink.metrics(result)`` is :func:`latobs.validation.metrics.compute`'s dict of the whole run
    (``streamed`` says how), ``sink.flat(result)`` the campaign's flat metrics, and ``result``
    holds the kept samples (none without ``keep``)."""

    def __init__(self, out_dir: str | os.PathLike | None = None, keep: bool = True,
                 settle_time: float | None = None, flat_settle: float | None = None):
        self.out_dir = Path(out_dir) if out_dir is not None else None
        self.keep = keep
        self.acc = _metrics.StreamedMetrics(settle_time)     # settle_time None: the scenario's
        # the campaign's flat metrics after its own settle time (a --rerun writes both)
        self.flat_acc = _metrics.StreamedMetrics(flat_settle) if flat_settle is not None else self.acc
        self.used = False
        self.every = 1
        self.kept: dict[str, list[np.ndarray]] = {}
        self.writer = None
        self.schema = None
        self._stack = None

    def __enter__(self):
        from contextlib import ExitStack

        self._stack = ExitStack().__enter__()
        return self

    def __exit__(self, *exc):
        return self._stack.__exit__(*exc)

    @property
    def outputs_path(self) -> Path | None:
        return self.out_dir / "outputs.parquet" if self.out_dir is not None else None

    def _columns(self, part) -> dict[str, np.ndarray]:
        cols = {"t": part.time, **part.bus, **{f"measured.{x}": v for x, v in part.measured.items()}}
        for label, outs in part.observers.items():
            cols.update({f"{label}.{x}": v for x, v in outs.items()})
        return cols

    def block(self, k0: int, part) -> None:
        """The rows k0 .. k0 + m of the run (``part``, a SimResult; row 0 the previous block's
        last row, for k0 > 0 already handed over)."""
        import pyarrow as pa

        if not self.used:
            self.used = True
            steps = int((part.info or {}).get("steps", 0))
            self.every = max(1, math.ceil((steps + 1) / PLOT_SAMPLES))
        self.acc.add(k0, part)
        if self.flat_acc is not self.acc:
            self.flat_acc.add(k0, part)
        new = slice(0 if k0 == 0 else 1, None)
        cols = {k: np.asarray(v)[new] for k, v in self._columns(part).items()}
        if self.out_dir is not None:
            if self.writer is None:
                import pyarrow.parquet as pq

                from ..atomic import atomic_path

                self.out_dir.mkdir(parents=True, exist_ok=True)
                self.schema = pa.schema([(k, pa.float64() if v.dtype.kind == "f" else pa.int64())
                                         for k, v in cols.items()])
                tmp = self._stack.enter_context(atomic_path(self.outputs_path, suffix=".parquet"))
                self.writer = self._stack.enter_context(pq.ParquetWriter(str(tmp), self.schema))
            self.writer.write_table(pa.table({k: pa.array(v, type=self.schema.field(k).type)
                                              for k, v in cols.items()}, schema=self.schema))
        if self.keep:
            first = k0 + (0 if k0 == 0 else 1)
            pick = (first + np.arange(len(cols["t"]))) % self.every == 0
            for k, v in cols.items():
                self.kept.setdefault(k, []).append(v[pick])

    def finish(self, result):
        """The streamed run's SimResult (``result``: info, logs, units) with the kept samples."""
        if self.keep and self.kept:
            joined = {k: np.concatenate(v) for k, v in self.kept.items()}
            self.kept.clear()
            labels = list((result.info or {}).get("observer_fmus", {}))
            result.time = joined.pop("t")
            result.measured = {k[9:]: joined.pop(k) for k in list(joined) if k.startswith("measured.")}
            result.observers = {lab: {k[len(lab) + 1:]: joined.pop(k) for k in list(joined)
                                      if k.startswith(lab + ".")} for lab in labels}
            result.bus = joined
        result.info["streamed"] = {**result.info.get("streamed", {}),
                                   "outputs": "outputs.parquet" if self.out_dir is not None else None,
                                   "figures_every_kth_sample": self.every if self.keep else None}
        return result

    def metrics(self, result) -> dict[str, Any]:
        """:func:`latobs.validation.metrics.compute`'s dict of the streamed run."""
        m = self.acc.compute(result)
        m["streamed"] = result.info["streamed"]
        return m

    def flat(self, result) -> dict[str, float]:
        """The campaign's flat metrics of the streamed run (after ``flat_settle``, else ``settle_time``)."""
        return self.flat_acc.flat(result)
