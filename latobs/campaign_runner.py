"""``latobs campaign``: Monte Carlo campaigns of built FMUs run on Dask, written to their folder.

The definition, draws, single run, journal and statistics are :mod:`latobs.validation.campaign`,
:mod:`~latobs.validation.campaign_run` and :mod:`~latobs.validation.campaign_stats`; this module
ships the FMUs to a local or remote Dask cluster, runs chunks of runs there, appends each finished
run to the journal, resumes an interrupted campaign and re-runs one run alone. docs/validation.md
describes the output folder.
"""
from __future__ import annotations

import dataclasses
import json
import logging
import os
import shutil
import sys
import time
from importlib import resources
from pathlib import Path
from typing import Any

from .validation import campaign as cp
from .validation import campaign_run as cr
from .validation import campaign_stats as cs
from .validation.campaign import Campaign, CampaignError

CAMPAIGN_DIR = Path(os.fspath(resources.files("latobs").joinpath("campaigns")))
#: errors of run 0 (run first, in this process) that stop a campaign before it is distributed:
#: the wiring or the definition is wrong, every run would fail the same way
_CONFIG_ERRORS = ("WiringError", "CampaignError", "ReplayError", "FileNotFoundError", "TypeError")


def shipped() -> dict[str, Path]:
    """The campaign definitions shipped with latobs, by name."""
    return {p.stem: p for p in sorted(CAMPAIGN_DIR.glob("*.toml"))}


def resolve(spec: str, observers: list[str] | None = None, runs: int | None = None,
            seed: int | None = None) -> Campaign:
    """The campaign ``spec`` names: a TOML file, a shipped campaign (:func:`shipped`), or a
    registered scenario. A scenario takes the distributions of the robustness campaign of its
    observers' paper (``robustness-PAPER``: plant parameters, signal transforms, sensors) on
    that scenario, with the scenario's own fields, duration, step and settle time; its observers
    default to those ``latobs validate SCENARIO`` runs. ``observers``, ``runs`` and ``seed``
    override the definition's."""
    from . import catalogue
    from .validation.scenarios import SCENARIOS

    if spec.endswith(".toml") or os.sep in spec:
        c = cp.load(spec)
    elif spec in shipped():
        c = cp.load(shipped()[spec])
    elif spec in SCENARIOS:
        sc = SCENARIOS[spec]
        names = observers or catalogue.default_observers(sc.plant)
        entries = [_design_of(n) for n in names]
        wrong = [n for n, e in zip(names, entries) if e.plant != sc.plant]
        if wrong:
            raise CampaignError(f"scenario {spec!r} drives {sc.plant}; observer(s) {', '.join(wrong)} are validated "
                                "beside another plant")
        template = shipped().get(catalogue.get(entries[0].name).campaign or "")
        if template is None:
            raise CampaignError(f"no robustness campaign for paper {entries[0].paper} to take distributions from")
        t = cp.load(template)
        c = dataclasses.replace(t, name=spec, scenario=spec, observers=tuple(names), scenario_fields={},
                                dt=None, settle_time=None, source=f"{template} on scenario {spec}",
                                description=f"{spec} with the distributions of {template.stem}")
    else:
        raise CampaignError(f"unknown campaign or scenario {spec!r}; shipped campaigns: {', '.join(shipped())}; "
                            f"scenarios: {', '.join(sorted(SCENARIOS))}; or a campaign .toml file")
    c = c.with_overrides(observers, runs, seed)
    if not c.observers:
        raise CampaignError(f"campaign {c.name}: no observers (give --observer NAME)")
    for n in c.observers:
        _design_of(n)
    if c.kind == "cosim" and c.plant_vehicle is None:
        from .packaging import PLANTS

        c = dataclasses.replace(c, plant_vehicle=PLANTS[c.base_scenario().plant].default_vehicle)
    return c


def _design_of(name: str):
    from .synthesis import designs

    design, _vehicle = designs.parse_artefact(name)
    return designs.get(design)


# --------------------------------------------------------------------------------------------
# FMUs and the record
# --------------------------------------------------------------------------------------------
_sha256 = cp.sha256_file


def fmu_refs(c: Campaign, fmu_dir: Path) -> list[cp.FmuRef]:
    """The campaign's FMUs in ``fmu_dir`` (each reused if built from identical inputs, else built:
    ``pipeline.build``): the plant first (cosim), then the observers."""
    from .pipeline import ensure_fmus, ensure_plant

    paths: list[tuple[str, Path]] = []
    if c.kind == "cosim":
        paths.append(("plant", ensure_plant(c.base_scenario().plant, c.plant_vehicle, fmu_dir)))
    obs = ensure_fmus(list(c.observers), fmu_dir)
    paths += [(n, obs[n]) for n in c.observers]
    return [cp.FmuRef(role, p.name, _sha256(p), path=str(p)) for role, p in paths]


def load_record(c: Campaign) -> tuple[dict | None, float | None, str | None]:
    """(columns, split time, sha256 of the file) of a replay campaign's record; Nones for cosim."""
    if c.kind != "replay":
        return None, None, None
    from .validation import replay as rp

    path = rp.resolve_csv(c.replay["csv"])
    return rp.load_csv(path), rp.default_split(path), _sha256(path)


# --------------------------------------------------------------------------------------------
# the folder
# --------------------------------------------------------------------------------------------
def campaign_dir(c: Campaign, out: Path, tag: str = "") -> Path:
    return Path(out) / (f"campaign_{c.name}_{tag}" if tag else f"campaign_{c.name}")


def _open_folder(c: Campaign, folder: Path, fingerprint: str, refs, fresh: bool) -> cs.Journal:
    from .atomic import atomic_write_text

    meta = folder / "campaign.json"
    if fresh and folder.is_dir():
        for name in ("runs.jsonl", "runs.parquet", "summary.json", "report.md", "campaign.json", "invocations.jsonl"):
            (folder / name).unlink(missing_ok=True)
        shutil.rmtree(folder / "figures", ignore_errors=True)
    if meta.is_file():
        old = json.loads(meta.read_text(encoding="utf-8"))
        if old.get("fingerprint") != fingerprint:
            raise CampaignError(
                f"{folder} holds another campaign (definition, seed or FMUs differ from this one's): give --tag TAG "
                "or another --out for this one, or --fresh to discard that one")
    folder.mkdir(parents=True, exist_ok=True)
    atomic_write_text(meta, json.dumps({"fingerprint": fingerprint, "definition": c.as_dict(),
                                        "fmus": [{"role": r.role, "file": r.filename, "sha256": r.sha256}
                                                 for r in refs]}, indent=1) + "\n")
    return cs.Journal(folder / "runs.jsonl")


# --------------------------------------------------------------------------------------------
# running
# --------------------------------------------------------------------------------------------
def run_campaign(spec: str, observers: list[str] | None = None, runs: int | None = None,
                 out: Path = Path("build"), fmu_dir: Path = Path("build"), scheduler: str | None = None,
                 workers: int | None = None, seed: int | None = None, tag: str = "", fresh: bool = False,
                 plots: bool = True, progress: bool = True, dashboard: str | None = None) -> dict[str, Any]:
    """Run (or resume) a campaign and write its folder; returns the summary (with ``timing``).
    ``dashboard``: the address of the local cluster's Dask dashboard (e.g. ``":8787"``); None, the
    default, serves none."""
    c = resolve(spec, observers, runs, seed)
    # memory and time estimated before anything is built or run; a local cluster runs a run per core
    cp.check_resources(c, workers=(workers or os.cpu_count() or 1) if scheduler is None else None)
    refs = fmu_refs(c, Path(fmu_dir))
    cr.check_supports(c, refs)                  # a draw outside an FMU's declared range: refused now
    record, split, record_sha = load_record(c)
    hashes = {r.role: r.sha256 for r in refs}
    if record_sha:
        hashes["record"] = record_sha
    fingerprint = c.fingerprint(hashes)
    folder = campaign_dir(c, out, tag)
    journal = _open_folder(c, folder, fingerprint, refs, fresh)
    done = {k: r for k, r in journal.read().items() if k < c.runs}
    todo = [k for k in range(c.runs) if k not in done]
    print(f"campaign {c.name}: {c.runs} runs ({len(done)} already in {journal.path}), "
          f"{'scenario ' + c.scenario if c.kind == 'cosim' else 'record ' + str(c.replay['csv'])}, "
          f"observers {', '.join(c.observers)}")
    timing: dict[str, Any] = {"runs_this_invocation": len(todo)}   # run 0 here, the rest on Dask
    try:
        if todo and 0 in todo:                   # run 0 here first: a wiring mistake stops it now
            row = cr.run_case(c, 0, cp.run_seed(c.seed, 0), refs, record=record, split=split)
            if row["status"] != "ok" and row["error"].startswith(_CONFIG_ERRORS):
                raise CampaignError(f"campaign {c.name}: run 0 failed, every run would: {row['error']}")
            journal.append(row)
            done[0] = row
            todo.remove(0)
        if todo:
            timing.update(_distribute(c, todo, refs, record, split, fingerprint, journal, done, scheduler,
                                      workers, progress, dashboard))
    except KeyboardInterrupt:
        journal.close()
        print(f"\ninterrupted: {len(journal.read())} of {c.runs} runs kept in {journal.path}; the same command "
              "resumes", file=sys.stderr)
        raise
    finally:
        journal.close()
    rows = [r for k, r in sorted(journal.read().items()) if k < c.runs]
    missing = sorted(set(range(c.runs)) - {r["run"] for r in rows})
    if missing:
        raise CampaignError(f"campaign {c.name}: runs {missing[:10]}{'...' if len(missing) > 10 else ''} have no "
                            f"result in {journal.path}; run the same command again to complete them")
    summary = cs.summarize(c, rows)
    summary["timing"] = timing
    summary["invocations"] = _invocations(folder, timing)
    summary["folder"] = str(folder)
    summary["rerun_command"] = rerun_command(spec, observers, out, fmu_dir, tag, "SEED")
    _write_outputs(c, folder, rows, summary, plots)
    print(_headline(c, summary, folder))
    if not summary["ok"]:
        first = summary["failures"][0]
        raise CampaignFailed(f"campaign {c.name}: all {summary['runs']} runs failed (run {first['run']}, seed "
                             f"{first['seed']}: {first['error']}); the failures are listed in {folder / 'report.md'}")
    return summary


class CampaignFailed(CampaignError):
    """Every run of a campaign failed (its folder is written): ``latobs campaign`` exits 2, as for an
    FMU that fails in a co-simulation. A campaign where some runs fail exits 0 and lists them."""


def local_cluster(workers: int, dashboard: str | None = None):
    """A LocalCluster of ``workers`` processes (one thread each). Its scheduler serves HTTP in any
    case (health and metrics routes): without a dashboard it listens on a free port of localhost
    (port 0), not on Dask's default 8787, so neither a second campaign nor another Dask user on
    the machine makes it warn "Port 8787 is already in use"."""
    from dask.distributed import LocalCluster

    kw: dict[str, Any] = {"dashboard_address": dashboard} if dashboard else {
        "dashboard_address": None, "scheduler_kwargs": {"dashboard_address": "127.0.0.1:0"}}
    return LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, silence_logs=logging.ERROR, **kw)


def _distribute(c, todo, refs, record, split, fingerprint, journal, done, scheduler, workers, progress,
                dashboard=None) -> dict:
    """Run the runs ``todo`` on Dask, appending each row to the journal as it arrives."""
    from dask.distributed import Client, as_completed
    from distributed.scheduler import KilledWorker
    from tqdm import tqdm

    t0 = time.perf_counter()
    cluster = None
    if scheduler:
        try:
            client = Client(scheduler, timeout="20s")
        except (OSError, TimeoutError) as exc:
            raise CampaignError(f"--scheduler {scheduler}: cannot connect to a dask scheduler there: {exc}") from None
    else:
        cluster = local_cluster(workers or os.cpu_count() or 1, dashboard)
        client = Client(cluster)
        if dashboard:
            print(f"dask dashboard: {cluster.dashboard_link}")
    futures = []
    try:
        if scheduler:
            try:
                client.wait_for_workers(1, timeout=WAIT_FOR_WORKERS_S)
            except TimeoutError:
                raise CampaignError(f"--scheduler {scheduler}: no worker joined within {WAIT_FOR_WORKERS_S:g} s "
                                    "(start some: dask worker ADDRESS --nthreads 1)") from None
        n_workers = len(client.scheduler_info(n_workers=-1)["workers"]) if scheduler else (workers or os.cpu_count())
        t_ready = time.perf_counter()
        light = [dataclasses.replace(r, path=None) for r in refs]    # workers get the bytes, not a path
        blobs = client.scatter([Path(r.path).read_bytes() for r in refs], broadcast=True)
        rec = client.scatter([record], broadcast=True)[0] if record is not None else None
        size = chunk_size(len(todo), n_workers)
        chunks = [todo[i:i + size] for i in range(0, len(todo), size)]
        futures = [client.submit(cr.run_cases, c, ks, [cp.run_seed(c.seed, k) for k in ks], light, blobs, rec, split,
                                 key=f"latobs-runs-{fingerprint[:16]}-{ks[0]}-{ks[-1]}", retries=0) for ks in chunks]
        by_key = {f.key: ks for f, ks in zip(futures, chunks)}
        bar = tqdm(total=c.runs, initial=len(done), unit="run", desc=f"campaign {c.name}", mininterval=0.5,
                   disable=not progress, file=sys.stderr)
        for fut in as_completed(futures):
            ks = by_key[fut.key]
            try:
                rows = fut.result()
            except KilledWorker as exc:          # the runs killed their workers: failed runs, recorded
                rows = [{"run": k, "seed": cp.run_seed(c.seed, k), "status": "failed", "worker": None,
                         "error": f"KilledWorker: {exc}", "params": {}, "metrics": {}, "seconds": None} for k in ks]
            except Exception as exc:             # run_cases never raises: the cluster failed (scheduler lost)
                raise CampaignError(f"campaign {c.name}: the Dask cluster failed ({type(exc).__name__}: {exc}); "
                                    f"{len(done)} of {c.runs} runs are kept in {journal.path}: the same command "
                                    "resumes") from exc
            for row in rows:
                if row["run"] not in done:       # one row per run, whatever Dask retried
                    journal.append(row)
                    done[row["run"]] = row
            bar.update(len(rows))
            fut.release()
        bar.close()
        t_end = time.perf_counter()
    finally:
        for f in futures:
            f.release()
        client.close()
        if cluster is not None:
            cluster.close()
    return {"runs_on_dask": len(todo), "workers": n_workers, "scheduler": scheduler or "local",
            "cluster_start_s": t_ready - t0,
            "execution_s": t_end - t_ready, "runs_per_s": len(todo) / (t_end - t_ready)}


#: how long a campaign waits for a first worker of a running scheduler, s
WAIT_FOR_WORKERS_S = 60.0
#: runs per Dask task: at most this many, and at least CHUNKS_PER_WORKER tasks per worker. One task
#: per run costs the scheduler (in the client's process on a local cluster) a few ms per run, which
#: on a 2-core machine competes with the workers; a chunk's rows still reach the journal one per run
MAX_CHUNK = 8
CHUNKS_PER_WORKER = 8


def chunk_size(runs: int, workers: int) -> int:
    return max(1, min(MAX_CHUNK, runs // (max(workers, 1) * CHUNKS_PER_WORKER)))


def rerun_command(spec: str, observers, out: Path, fmu_dir: Path, tag: str, seed) -> str:
    """The command that re-runs one run of this campaign alone (``--rerun SEED``)."""
    parts = ["latobs campaign", spec]
    parts += [f"--observer {o}" for o in (observers or [])]
    if str(out) != "build":
        parts.append(f"--out {out}")
    if str(fmu_dir) != "build":
        parts.append(f"--fmu-dir {fmu_dir}")
    if tag:
        parts.append(f"--tag {tag}")
    parts.append(f"--rerun {seed}")
    return " ".join(parts)


def rerun(spec: str, run_seed: int, observers: list[str] | None = None, out: Path = Path("build"),
          fmu_dir: Path = Path("build"), tag: str = "", plots: bool = True) -> dict[str, Any]:
    """Run one run of a campaign alone from its seed, with the full validation output (metrics.json
    and plots) in ``OUT/campaign_NAME[_TAG]/rerun_SEED/``; its campaign metrics go to ``row.json``
    and are compared with the journal's row of the same seed when there is one."""
    from .atomic import atomic_write_text

    c = resolve(spec, observers)
    refs = fmu_refs(c, Path(fmu_dir))
    cr.check_supports(c, refs)
    record, split, _ = load_record(c)
    folder = campaign_dir(c, out, tag)
    target = folder / f"rerun_{run_seed}"
    paths = {r.role: Path(r.path) for r in refs}
    if c.kind == "cosim":
        from .validation import stream, validate

        params = cp.draw(c, run_seed)
        sc, kwargs = cr.cosim_setup(c, params, run_seed)
        # a long run streamed: its metrics.json and the campaign's flat metrics summed over the blocks
        sink = stream.CosimSink(target, keep=bool(plots), flat_settle=cr.settle_time(c, sc))
        result, _, written = validate(sc, paths["plant"], {o: paths[o] for o in c.observers}, target, plots=plots,
                                      sink=sink, **kwargs)
        metrics = sink.flat(result) if sink.used else cr.result_metrics(result, cr.settle_time(c, sc))
    else:
        from .validation import replay as rp

        t = record["t"]
        params = cp.draw(c, run_seed, record_span=(float(t[0]), float(t[-1])), split=split)
        data = cr.replay_segment(c, params, record, run_seed)
        metrics, written = {}, []
        for o in c.observers:
            metrics.update(cr.replay_metrics(rp.drive(paths[o], data, label=o), c))
            _, w = rp.run(rp.resolve_csv(c.replay["csv"]), paths[o], target / o, split=None, observer=o,
                          plots=plots, data=data)
            written += w
    row = {"seed": run_seed, "params": params,
           "metrics": {k: (None if v != v else v) for k, v in metrics.items()}}
    atomic_write_text(target / "row.json", json.dumps(row, indent=1) + "\n")
    journal = {r["seed"]: r for r in cs.Journal(folder / "runs.jsonl").read().values()}
    same = journal.get(run_seed)
    if same is not None:
        equal = same["status"] == "ok" and same["metrics"] == row["metrics"]
        row["journal_run"] = same["run"]
        row["identical_to_journal"] = equal
        print(f"run {same['run']} of {folder / 'runs.jsonl'} has this seed: the re-run's metrics are "
              f"{'identical' if equal else 'DIFFERENT (FMUs rebuilt since?)'}")
    print(json.dumps(row["metrics"], indent=1))
    print(f"wrote {target / 'row.json'}, {', '.join(str(p) for p in written)}")
    return row


# --------------------------------------------------------------------------------------------
# outputs
# --------------------------------------------------------------------------------------------
def _invocations(folder: Path, timing: dict) -> list[dict]:
    """Every invocation's timing, this one appended (``invocations.jsonl``): a resumed or extended
    campaign keeps the figures of the invocations that ran its runs."""
    path = folder / "invocations.jsonl"
    with open(path, "a", encoding="utf-8") as f:
        f.write(json.dumps({"finished": time.strftime("%Y-%m-%dT%H:%M:%S"), **timing}) + "\n")
    return [json.loads(x) for x in path.read_text(encoding="utf-8").splitlines() if x.strip()]


def _write_outputs(c: Campaign, folder: Path, rows, summary, plots: bool) -> None:
    import pyarrow.parquet as pq

    from .atomic import atomic_path, atomic_write_text
    from .validation import campaign_report

    with atomic_path(folder / "runs.parquet", suffix=".parquet") as tmp:
        pq.write_table(cs.rows_table(rows), tmp)
    atomic_write_text(folder / "summary.json", json.dumps(summary, indent=1, allow_nan=False) + "\n")
    campaign_report.write(folder, c, summary, rows, plots=plots)


def _headline(c: Campaign, s: dict, folder: Path) -> str:
    t = s.get("timing", {})
    lines = [f"campaign {c.name}: {s['ok']} runs ok, {s['failed']} failed"]
    if t.get("execution_s"):
        lines[0] += (f"; {t['runs_on_dask']} runs in {t['execution_s']:.1f} s on {t['workers']} worker(s) "
                     f"({t['runs_per_s']:.1f} runs/s; cluster start {t['cluster_start_s']:.1f} s)")
    from .validation.campaign_report import display

    for col, st in s["metrics"].items():
        if col in s["headline"] and st.get("n") and not col.endswith(".violations"):   # the enclosure lines say
            k, unit = display(col)
            lines.append(f"  {col}: p50 {k * st['p50']:.4g}, p95 {k * st['p95']:.4g}, max {k * st['max']:.4g}"
                         + (f" {unit}" if unit else ""))
    for base, e in s["enclosure"].items():
        lines.append(f"  {base}: enclosure violated in {e['runs_with_violations']} of {e['runs']} runs")
    lines.append(f"wrote {folder / 'report.md'}, {folder / 'runs.parquet'}, {folder / 'summary.json'}")
    return "\n".join(lines)
