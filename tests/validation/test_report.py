"""The markdown report and its figures, built from a synthetic co-simulation result (no FMU): every
link and image of the written report resolves from the report's own folder whatever the working
directory; one unit convention (degrees); violations of one event counted once; no empty figure;
the bold legend consistent; a table of contents; figures that a diverging design cannot flatten."""
from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

from latobs.validation import metrics, plots, report
from latobs.validation.harness import SimResult

N_VIOLATING = 20


def _result(observers=("Good", "Diverging", "Interval")) -> SimResult:
    """6 s at 10 ms: a good estimator of beta and bank (its `valid` output 0 for 1 s), one that
    diverges, and an interval observer of vy and beta = atan(vy / vx) whose bounds miss the truth
    on N_VIOLATING samples (its `consistent` output 0 there)."""
    t = np.arange(601) * 0.01
    beta = 0.03 * np.sin(t)
    vx = np.full_like(t, 20.0)
    bank = np.where(t > 2, 0.02, 0.0)
    vy = vx * np.tan(beta)
    lo, hi = vy - 0.1, vy + 0.1
    lo[300:300 + N_VIOLATING] = vy[300:300 + N_VIOLATING] + 0.01
    consistent = np.ones_like(t)
    consistent[300:300 + N_VIOLATING] = 0
    obs = {"Good": {"beta_hat": beta + 0.001 * np.cos(3 * t), "bank_angle_hat": bank + 0.001,
                    "valid": (np.abs(t - 3) > 0.5).astype(float)},
           "Diverging": {"beta_hat": beta - 0.5 * np.exp(t - 3), "bank_angle_hat": bank - np.exp(t - 3)},
           "Interval": {"vy_lower": lo, "vy_upper": hi, "beta_lower": np.arctan(lo / vx),
                        "beta_upper": np.arctan(hi / vx), "consistent": consistent}}
    units = {"beta_hat": "rad", "bank_angle_hat": "rad", "beta_lower": "rad", "beta_upper": "rad",
             "vy_lower": "m/s", "vy_upper": "m/s"}
    return SimResult(time=t, bus={"beta": beta, "bank_angle": bank, "vx": vx, "delta": 0.01 * np.sin(t), "vy": vy},
                     observers={k: obs[k] for k in observers}, logs={}, scenario="synthetic", dt=0.01,
                     settle_time=1.0, units=units)


def _run(result: SimResult, folder: Path) -> report.ReportSection:
    m = metrics.compute(result, settle_time=1.0)
    metrics.write(m, folder)
    plots.plot_all(result, folder)
    return report.section_from_dir(folder, title="synthetic run")


def _slug(heading: str) -> str:
    """GitHub's heading anchor, written independently of the module: lower case, characters other
    than letters, digits, '_', '-' and ' ' dropped, spaces to '-'."""
    return "".join(c for c in heading.lower() if c.isalnum() or c in "_- ").replace(" ", "-")


def test_every_link_of_a_report_written_from_a_relative_folder_resolves(tmp_path, monkeypatch):
    """`latobs demo` writes build/report/ relative to the working directory: every image and every
    link of index.md resolves from index.md's own folder (no `build/report/build/report/...`), the
    table of contents links every section, a repeated title included."""
    monkeypatch.chdir(tmp_path)
    sec = _run(_result(), Path("build/report/synthetic"))
    again = report.ReportSection(title="synthetic run", metrics=sec.metrics, images=sec.images)
    index = report.write_index(Path("build/report"), ["## Designs\n\ncertified", sec, again], title="demo")
    text = index.read_text(encoding="utf-8")
    base = index.parent
    headings = re.findall(r"^#{1,3} (.+)$", text, flags=re.M)
    anchors, seen = set(), {}
    for h in headings:
        a = _slug(h)
        anchors.add(a if a not in seen else f"{a}-{seen[a]}")
        seen[a] = seen.get(a, 0) + 1
    links = re.findall(r"!?\[[^\]]*\]\(([^)]+)\)", text)
    images = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", text)
    assert len(images) == 2 * len(sec.images) >= 4
    for link in links:
        if link.startswith("#"):
            assert link[1:] in anchors, link
        else:
            assert (base / link).is_file(), link
    toc = text.split("## Contents", 1)[1].split("\n## ", 1)[0]
    assert {h for h in headings[1:] if h != "Contents"} <= set(re.findall(r"- \[([^\]]+)\]", toc))
    assert "(#synthetic-run)" in toc and "(#synthetic-run-1)" in toc
    with pytest.raises(ValueError, match="no such file"):          # never a link to nothing
        report.write_index(Path("build/report"), [report.ReportSection(title="x", images=["build/nope.png"])])


def test_the_report_gives_angles_in_degrees_and_counts_one_event_once(tmp_path):
    r = _result()
    m = metrics.compute(r, settle_time=1.0)
    rad = m["observers"]["Good"]["estimates"]["beta_hat"]["rms_after_settle"]
    md = report.metrics_markdown(m)
    row = next(line for line in md.splitlines() if line.startswith("| Good | beta_hat |"))
    cells = [c.strip().strip("*") for c in row.split("|")[1:-1]]
    assert cells[3] == "deg" and float(cells[6]) == pytest.approx(math.degrees(rad), rel=1e-3)
    assert "| rad |" not in md and "[rad]" not in md
    assert m["observers"]["Interval"]["intervals"]["vy"]["enclosure_violations"] == N_VIOLATING
    assert m["observers"]["Interval"]["intervals"]["beta"]["enclosure_violations"] == N_VIOLATING
    header, rows = report.overview_rows([report.ReportSection(title="s", metrics=m)])
    viol = {r[1]: r[header.index("violations (bound)")] for r in rows}
    assert viol["Interval"] == f"{N_VIOLATING} (vy, beta)"           # one event: not 2 x 20
    est = {r[1]: r[header.index("observer RMS")] for r in rows}
    assert est["Good"] == f"{report._fmt(math.degrees(rad))} deg"
    assert m["observers"]["Good"]["estimates"]["beta_hat"]["unit"] == "rad"    # the metrics stay SI


def test_the_lowest_rms_of_a_row_is_bold_also_when_the_observer_has_it():
    m = metrics.compute(_result(("Good",)), settle_time=1.0)
    summ = m["observers"]["Good"]["baselines"]["summary"]["beta_hat"]
    assert summ["observer_rms"] < summ["best_baseline_rms"]
    md = report.metrics_markdown(m)
    row = next(line for line in md.splitlines() if line.startswith("| Good | beta_hat |"))
    cells = [c.strip() for c in row.split("|")[1:-1]]
    assert cells[6].startswith("**") and not any(c.startswith("**") for c in cells[8:])


def test_no_bank_figure_without_a_bank_estimate(tmp_path):
    paths = plots.plot_all(_result(("Interval",)), tmp_path / "a")
    assert {p.name for p in paths} == {"estimates.png", "inputs.png"}       # bank_angle.png would be empty
    paths = plots.plot_all(_result(("Good",)), tmp_path / "b")
    assert "bank_angle.png" in {p.name for p in paths}


def test_y_limits_follow_the_truth_and_a_diverging_curve_is_clipped_and_marked():
    from matplotlib.figure import Figure

    t = np.linspace(0, 5, 501)
    truth = np.sin(t)
    diverging = np.sin(t) - np.exp(2 * t)                         # reaches -2.2e4
    lo, hi = plots.clip_limits([truth], [truth + 0.01, diverging])
    assert -3.25 < lo < -3.0 and 1.0 < hi < 1.25                 # the truth range (2) and 1 span below it, 5 % pad
    ax = Figure().subplots()
    ax.set_ylim(lo, hi)
    far = plots.mark_clipped(ax, t, diverging, "C1")
    assert far == pytest.approx(diverging.min())
    assert plots.mark_clipped(ax, t, truth, "C0") is None
    assert len(ax.lines) >= 1                                      # the marker at the edge
    flat = plots.clip_limits([np.zeros(5)], [np.array([0.0, 1e6])])  # nothing to scale on: nothing clipped
    assert flat[1] > 1e6


def test_spans_of_valid_and_consistent_zero_are_shaded():
    from matplotlib.figure import Figure

    r = _result()
    ax = Figure().subplots()
    handles = plots.shade_flags([ax], r, ["Good", "Interval"])
    labels = [h.get_label() for h in handles]
    assert any(lab.startswith("valid = 0") for lab in labels) and any(lab.startswith("consistent = 0") for lab in labels)
    spans = plots._flag_spans(r.time, r.observers["Interval"]["consistent"])
    assert spans == [(pytest.approx(3.0), pytest.approx(3.0 + N_VIOLATING * 0.01))]
    assert len(ax.patches) == 2                                   # one span per flag


def test_the_demo_summary_is_one_line_per_observer_and_run_with_its_best_baseline(tmp_path):
    from latobs import demo

    sec = _run(_result(), tmp_path / "r")
    header, rows = report.overview_rows([sec])
    lines = demo.summary_text(header, rows).splitlines()
    assert len(lines) == 2 + 3 and "best baseline RMS" in lines[0]
    good = next(line for line in lines if "Good" in line)
    assert "linear bicycle" in good or "zero" in good
    titles = [demo.run_title(*r) for r in demo.RUNS]
    assert len(set(titles)) == len(titles)                        # no heading twice in the demo report
