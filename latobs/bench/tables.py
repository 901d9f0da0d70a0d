"""The Markdown tables of ``latobs bench``'s figures (the dict :func:`latobs.bench.measure.bench`
returns, or its JSON file): one table per section, and :func:`markdown`, the whole speed page."""
from __future__ import annotations

import math

from .measure import BACKEND_LABEL, SOLVER_LABEL


def _us(x) -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "—"
    return f"{x:.3g}" if x < 1 else f"{x:.1f}" if x < 1000 else f"{x:.0f}"


def _s(x, digits: int = 2) -> str:
    return "—" if x is None else f"{x:.{digits}f}"


def _g(x) -> str:
    return "—" if x is None else f"{x:.4g}"


def _cell(text: str) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def build_table(rows: list[dict]) -> str:
    lines = ["Whole `latobs build` (every observer at its default vehicle and every plant, native FMUs for every "
             "platform), each a fresh process (`python -m latobs build --out DIR --backend B`): cold with an empty "
             "cache (`LATOBS_CACHE_DIR`: every design solved, every FMU compiled; zig's per-target C runtime "
             "already built, a one-time cost of minutes on a fresh machine), then warm into a new folder (every FMU "
             "from the cache) and again into that folder (every FMU reused in place):", "",
             "| backend | cold (s) | warm, new folder (s) | warm, same folder (s) | FMUs built | LMI solver time "
             "inside (s) | result |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        result = "ok" if r["returncode"] == 0 else _cell(f"exit {r['returncode']}: {r['error']}")
        lines.append(f"| {BACKEND_LABEL.get(r['backend'], r['backend'])} | {_s(r['seconds'], 1)} | "
                     f"{_s(r.get('warm_new_folder_seconds'), 2)} | {_s(r.get('warm_same_folder_seconds'), 2)} | "
                     f"{r['fmus']} | {_s(r.get('lmi_solver_seconds'), 1)} | {result} |")
    return "\n".join(lines)


def _lmi_cell(r: dict | None) -> tuple[str, str]:
    """(time cell, result cell) of one design x solver row."""
    if r is None:
        return "—", "not run"
    if r.get("uses_lmi") is False and r["result"] == "certified":
        timing = f"{_s(r['design_seconds'])} (no LMI)"
    else:
        timing = f"{_s(r['design_seconds'])} ({_s(r['lmi_seconds'])}, {r['lmi_solves']})"
    if r.get("timed_out"):
        timing = f"> {r['design_seconds']:.0f} (stopped)"
    result = r["result"] or "?"
    statuses = [s for s in r.get("lmi_statuses", []) if s != "optimal"]
    if r["result"] == "certified":
        result += f" {r['checks_passed']}/{r['checks_total']}, γ = {_g(r['gamma'])}"
    else:
        if r.get("checks_total"):
            result += f" ({r['checks_total'] - r['checks_passed']} of {r['checks_total']} checks)"
        result += (f", γ = {_g(r['gamma'])}" if r.get("gamma") is not None else "") + f": {r['reason']}"
    if statuses:
        result += f" [solver: {', '.join(statuses)}]"
    return timing, _cell(result)


def lmi_table(section: dict) -> str:
    rows = section["rows"]
    solvers = section["solvers"]
    settings = section.get("settings", {})
    scs = settings.get("SCS")
    lines = ["LMI designs at their default vehicle, each solver's result through the independent certificate "
             "(`certificate.certify`, as `latobs design`/`build`). Time: wall time of the design function in s, "
             "in one process (`LATOBS_JOBS=1`: paper 002's bands in turn) (of it, its LMI solves in s, and their number, fallbacks and infeasibility diagnostics included); "
             "certificate time separate. Clarabel: its defaults (with paper 002's fallback on a numerical failure)"
             + (f"; SCS: eps_abs = {scs.get('eps_abs'):g}, eps_rel = {scs.get('eps_rel'):g}, "
                f"max_iters = {scs.get('max_iters')}" if scs else "")
             + (f". Each design x solver in a fresh process, stopped after {section['timeout_seconds']:g} s"
                if section.get("timeout_seconds") else "") + ".", ""]
    head = "| design (paper, vehicle) |"
    sep = "|---|"
    for s in solvers:
        head += f" {SOLVER_LABEL.get(s, s)}: design s (LMI s, solves) | {SOLVER_LABEL.get(s, s)}: result |"
        sep += "---|---|"
    if len(solvers) == 2:
        a, b = (SOLVER_LABEL.get(x, x) for x in solvers)
        head += f" LMI time {b} ÷ {a} | γ relative difference |"
        sep += "---|---|"
    head += " certificate s |"
    sep += "---|"
    lines += [head, sep]
    by = {(r["design"], r["solver"]): r for r in rows}
    for name in dict.fromkeys(r["design"] for r in rows):
        first = next(r for r in rows if r["design"] == name)
        line = f"| {name} ({first['paper']}, {first['vehicle']}) |"
        for s in solvers:
            timing, result = _lmi_cell(by.get((name, s)))
            line += f" {timing} | {result} |"
        if len(solvers) == 2:
            a, b = by.get((name, solvers[0])), by.get((name, solvers[1]))
            ratio = (f"{b['lmi_seconds'] / a['lmi_seconds']:.1f}" if a and b and a.get("lmi_solves")
                     and b.get("lmi_solves") and a["lmi_seconds"] > 0 else "—")
            diff = (f"{abs(b['gamma'] - a['gamma']) / abs(a['gamma']):.1e}"
                    if a and b and a.get("uses_lmi") and a.get("gamma") and b.get("gamma") is not None else "—")
            line += f" {ratio} | {diff} |"
        certs = [_s(by[(name, s)].get("certificate_seconds")) for s in solvers if (name, s) in by]
        line += f" {' / '.join(certs)} |"
        lines.append(line)
    totals = []
    for s in solvers:
        sel = [r for r in rows if r["solver"] == s]
        ok = sum(r["result"] == "certified" for r in sel)
        stopped = sum(bool(r.get("timed_out")) for r in sel)
        totals.append(f"{SOLVER_LABEL.get(s, s)}: {ok}/{len(sel)} certified"
                      + (f", {stopped} stopped at the cap" if stopped else "") + ", LMI solves "
                      f"{sum(r['lmi_seconds'] for r in sel):.1f} s, design functions "
                      f"{sum(r['design_seconds'] or 0 for r in sel):.1f} s" + (" (the stopped ones at the cap)"
                                                                                if stopped else ""))
    lines += ["", "Totals: " + "; ".join(totals) + "."]
    return "\n".join(lines)


def fmu_table(r: dict) -> str:
    fm = r["fmus"]
    backends = r["backends"]
    lines = [f"µs per communication step (dt = {r['dt'] * 1e3:g} ms), each FMU driven by the bus of its pairing "
             f"(up to {r['n_steps']} steps). fmpy: set inputs + doStep + get outputs through fmpy's FMU2Slave, best of "
             f"{r['repeats']} fresh instances (first instance in the process). C host: a plain C program, no Python in "
             "the loop (a pythonfmu FMU with libpython preloaded), best (median) of 5 fresh instances: fmi2DoStep alone "
             "/ set + doStep + get. Reference: for pythonfmu the FMU's runtime class of `fmu_src/` stepped directly in "
             "Python (same arithmetic, no FMI; first instance in parentheses), for native C the C host's fmi2DoStep.",
             "", "| FMU | driven by | backend | µs/step via fmpy | µs/doStep in a C host | µs/step in a C host (with I/O) "
             "| reference µs/step | fmpy ÷ reference |", "|---|---|---|---|---|---|---|---|"]
    for name, f in fm.items():
        where = f"{f['scenario']} ({f.get('n_steps', '—')} steps)"
        if "error" in f:
            lines.append(f"| {name} | {where} | — | {_cell(f['error'])} | | | | |")
            continue
        for b in backends:
            e = f["backends"].get(b)
            if e is None:
                continue
            if "error" in e:
                lines.append(f"| {name} | {where} | {BACKEND_LABEL[b]} | {_cell(e['error'])} | — | — | — | — |")
                continue
            if b == "c":
                ref = f"{_us(e.get('reference_us_per_step'))} (C host doStep)"
            else:
                ref = (f"{_us(f.get('python_runtime_us_per_step'))} ({_us(f.get('python_runtime_us_per_step_first'))}) "
                       "(Python runtime)")
            ratio = "—" if e.get("fmpy_over_reference") is None else f"{e['fmpy_over_reference']:.1f}"
            host = ("—" if "c_host_error" in e else
                    f"{_us(e.get('c_host_us_per_doStep'))} ({_us(e.get('c_host_median_us_per_doStep'))})")
            host_io = ("—" if "c_host_error" in e else
                       f"{_us(e.get('c_host_us_per_step'))} ({_us(e.get('c_host_median_us_per_step'))})")
            lines.append(f"| {name} | {where} | {BACKEND_LABEL[b]} | {_us(e['fmpy_us_per_step'])} "
                         f"({_us(e['fmpy_us_per_step_first'])}) | {host} | {host_io} | {ref} | {ratio} |")
    if "python" in backends and "c" in backends:
        lines += ["", "| FMU | pythonfmu ÷ native C via fmpy | pythonfmu ÷ native C, doStep in a C host |",
                  "|---|---|---|"]
        for name, f in fm.items():
            py, c = f.get("backends", {}).get("python", {}), f.get("backends", {}).get("c", {})
            if "fmpy_us_per_step" not in py or "fmpy_us_per_step" not in c:
                continue
            host = (f"{py['c_host_us_per_doStep'] / c['c_host_us_per_doStep']:.0f}"
                    if py.get("c_host_us_per_doStep") and c.get("c_host_us_per_doStep") else "—")
            lines.append(f"| {name} | {py['fmpy_us_per_step'] / c['fmpy_us_per_step']:.1f} | {host} |")
    ref = r.get("numpy_reference")
    if ref:
        lines += ["", f"numpy in the same run: the affine map of one paper-000 observer step (5 states, 4 inputs) "
                      f"{_us(ref['numpy_affine_map_us'])} µs, the RK4 substeps it replaces "
                      f"{_us(ref['numpy_rk4_substeps_us'])} µs."]
    return "\n".join(lines)


def coupled_table(rows: list[dict], fmus: dict | None = None) -> str:
    lines = ["Coupled runs through the validation harness (`harness.run`, direct FMI calls), best of the repeats "
             "(first run in parentheses). µs per step: the whole run (extraction, instantiation, initialisation, "
             "results) per communication step; stepping loop: the steps alone (every FMU's set + doStep + get and "
             "the routes; `compiled`: the master's C loop, `python`: its Python loop), and, for native FMUs, its "
             "ratio to the sum of the same FMUs' fmi2DoStep in the plain C host (\"One FMU step\", this run):", "",
             "| pairing | scenario (s simulated) | plant + observers | backend | wall time (s) | µs per step | "
             "stepping loop µs per step | loop ÷ Σ doStep in a C host | real time |", "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        fmus_cell = f"{r['plant']} + {', '.join(r['observers'])}"
        if "error" in r:
            lines.append(f"| {r['pairing']} | {r['scenario']} | {fmus_cell} | "
                         f"{BACKEND_LABEL.get(r['backend'], r['backend'])} | {_cell(r['error'])} | — | — | — | — |")
            continue
        fresh = (f" (fresh process: {r['fresh_process_real_time_factor']:.0f}×)"
                 if "fresh_process_real_time_factor" in r else "")
        loop = (f"{r['loop_us_per_step']:.2f} ({r.get('master_loop', '?')})"
                if isinstance(r.get("loop_us_per_step"), (int, float)) else "—")
        ratio = _loop_ratio(r, fmus or {})
        lines.append(f"| {r['pairing']} | {r['scenario']} ({r['scenario_seconds']:g}) | {fmus_cell} | "
                     f"{BACKEND_LABEL.get(r['backend'], r['backend'])} | {r['seconds']:.2f} ({r['first_seconds']:.2f}) | "
                     f"{r['us_per_step']:.0f} | {loop} | {ratio} | {r['real_time_factor']:.0f}×{fresh} |")
    return "\n".join(lines)


def _loop_ratio(r: dict, fmus: dict) -> str:
    """The stepping loop's µs per step over the sum of its FMUs' C-host fmi2DoStep µs (native only)."""
    if r.get("backend") != "c" or not isinstance(r.get("loop_us_per_step"), (int, float)):
        return "—"
    total = 0.0
    for name in (r["plant"], *r["observers"]):
        e = ((fmus.get(name) or {}).get("backends") or {}).get("c") or {}
        if not isinstance(e.get("c_host_us_per_doStep"), (int, float)):
            return "—"
        total += e["c_host_us_per_doStep"]
    return f"{r['loop_us_per_step'] / total:.1f}" if total > 0 else "—"


def demo_table(d: dict) -> str:
    """The demo section: cold and warm wall times."""
    lines = ["`latobs demo` in a fresh process: cold with an empty cache (`LATOBS_CACHE_DIR`: every design "
             "solved, every FMU built for this machine; zig's C runtime already built), then warm into a new "
             "folder (designs and FMUs from the cache; every run, figure and replay made again):", "",
             "| cold (s) | warm, new folder (s) | result |", "|---|---|---|"]
    result = "ok" if not d.get("returncode") else f"failed: {_cell(d.get('error') or '?')}"
    lines.append(f"| {_s(d.get('seconds'), 1)} | {_s(d.get('warm_new_folder_seconds'), 1)} | {result} |")
    return "\n".join(lines)


def campaign_table(c: dict) -> str:
    """The campaign section: the whole command and the runs on the local cluster, per run."""
    if c.get("error") and c.get("returncode") is None:
        return f"Campaign: not measured ({c['error']})."
    lines = [f"`latobs {c['command']}` in a fresh process, the native FMUs reused (each run: a drawn car, "
             "drive and sensors, CarPlant beside the campaign's observers for the scenario's 10 s at 5 ms, its "
             "metrics): the whole command, and the runs alone on the local Dask cluster as the campaign's summary "
             "times them.", "",
             "| campaign | runs ok | workers | whole command (s) | cluster start (s) | runs on the cluster (s) | "
             "runs/s | ms per run per worker |", "|---|---|---|---|---|---|---|---|"]
    if c.get("returncode"):
        lines.append(f"| {c['campaign']} | failed: {_cell(c.get('error') or '?')} | {c['workers']} | "
                     f"{c['seconds']:.1f} | — | — | — | — |")
        return "\n".join(lines)
    ex, rate = c.get("execution_s"), c.get("runs_per_s")
    per_run = (f"{1e3 * c['workers'] / rate:.1f}" if isinstance(rate, (int, float)) and rate > 0 else "—")
    lines.append(f"| {c['campaign']} | {c.get('ok', '?')} of {c['runs']} | {c['workers']} | {c['seconds']:.1f} | "
                 f"{_s(c.get('cluster_start_s'), 1)} | {_s(ex, 1)} | {_s(rate, 0)} | {per_run} |")
    return "\n".join(lines)


def scaling_table(s: dict) -> str:
    if "error" in s:
        return f"Scaling: not measured ({s['error']})."
    b = BACKEND_LABEL.get(s["backend"], s["backend"])
    lines = [f"Cost of one coupled run, {b} FMUs, best of the repeats: wall seconds per run with the FMUs extracted "
             "for every run (`harness.run` alone) and extracted once (`unzipped=`, as a campaign worker), and µs per "
             "step (extracted once).", "",
             f"| {s['scenario']} length (s) | steps | observers | s per run (extract per run) | s per run (extracted once) "
             "| µs per step | real time |", "|---|---|---|---|---|---|---|"]
    for r in s["lengths"]:
        lines.append(f"| {r['duration']:g} | {r['steps']} | {r['n_observers']} | {r['seconds_extract_per_run']:.3f} | "
                     f"{r['seconds_extracted_once']:.3f} | {r['us_per_step_extracted_once']:.1f} | "
                     f"{r['real_time_factor_extracted_once']:.0f}× |")
    lines += ["", f"| observers beside CarPlant ({s['observers_duration']:g} s) | s per run (extract per run) | "
                  "s per run (extracted once) | µs per step |", "|---|---|---|---|"]
    for r in s["n_observers"]:
        lines.append(f"| {r['n_observers']} | {r['seconds_extract_per_run']:.3f} | {r['seconds_extracted_once']:.3f} | "
                     f"{r['us_per_step_extracted_once']:.1f} |")
    fl, fo = s["fit_lengths"], s["fit_n_observers"]
    lines += ["", f"Straight lines (least squares): per run {fl['seconds_extract_per_run']['intercept']:.3f} s + "
                  f"{fl['seconds_extract_per_run']['slope'] * 1e3:.2f} ms per simulated second (extract per run), "
                  f"{fl['seconds_extracted_once']['intercept']:.3f} s + {fl['seconds_extracted_once']['slope'] * 1e3:.2f} "
                  f"ms per simulated second (extracted once); per observer added "
                  f"{fo['seconds_extracted_once']['slope'] * 1e3:.1f} ms per {s['observers_duration']:g} s run "
                  f"(extracted once; CarPlant alone {s['n_observers'][0]['seconds_extracted_once']:.3f} s)."]
    return "\n".join(lines)


def table(r: dict) -> str:
    """Every measured section as Markdown."""
    parts = []
    if r.get("build"):
        parts.append(build_table(r["build"]))
    if r.get("demo"):
        parts.append(demo_table(r["demo"]))
    if r.get("lmi"):
        parts.append(lmi_table(r["lmi"]))
    if r.get("fmus"):
        parts.append(fmu_table(r))
    if r.get("coupled"):
        parts.append(coupled_table(r["coupled"], r.get("fmus")))
    if r.get("campaign"):
        parts.append(campaign_table(r["campaign"]))
    if r.get("scaling"):
        parts.append(scaling_table(r["scaling"]))
    return "\n\n".join(parts)


def machine_statement(r: dict) -> str:
    """One paragraph: the machine and its load when the figures were measured (no date)."""
    m = r.get("machine")
    if not m:
        return "Machine: not recorded with these figures."
    load = m.get("load_average")
    load_text = (f"load average {load[0]:.2f} / {load[1]:.2f} / {load[2]:.2f} (1 / 5 / 15 min) at the start"
                 if load else "load average unknown")
    return (f"Measured on {m.get('cpu', '?')} ({m.get('logical_cores', '?')} logical cores), {m.get('system', '?')}, "
            f"Python {m.get('python', '?')}, numpy {m.get('numpy', '?')}; {load_text}. Absolute times depend on the "
            "machine and its load: compare the ratios measured in the same run.")


def markdown(r: dict) -> str:
    """The speed page: the machine statement, then each measured section under its heading."""
    sections = (("build", "Whole build", lambda: build_table(r["build"])),
                ("demo", "The demo", lambda: demo_table(r["demo"])),
                ("lmi", "LMI designs: Clarabel and SCS", lambda: lmi_table(r["lmi"])),
                ("fmus", "One FMU step", lambda: fmu_table(r)),
                ("coupled", "Coupled runs", lambda: coupled_table(r["coupled"], r.get("fmus"))),
                ("campaign", "A 1000-run campaign", lambda: campaign_table(r["campaign"])),
                ("scaling", "Scaling with length and observers", lambda: scaling_table(r["scaling"])))
    parts = ["# Speed",
             "This page is the output of `latobs bench --markdown` (to regenerate it: `latobs bench --markdown "
             "--json bench.json > docs/speed.md`; `latobs bench --from-json bench.json --markdown` renders a saved "
             "run again). Each figure stands beside a reference measured in the same run: compare the ratios "
             "within one run, not the times across machines.",
             machine_statement(r)]
    parts += [f"## {title}\n\n{render()}" for key, title, render in sections if r.get(key)]
    return "\n\n".join(parts) + "\n"
