"""``latobs demo``: build every FMU, run the default scenarios, write build/report/index.md.

Covers what exists and grows with the project: today paper 000's two observers on CarPlant,
nominal and with +-20 % cornering-stiffness mismatch in the plant, with and without sensor noise.
"""
from __future__ import annotations

import time
from pathlib import Path

from .pipeline import build, run_validation
from .synthesis import certificate, design_file, designs

# (scenario, tag, plant parameters, noise)
RUNS = [
    ("bank-braking", "", {}, False),
    ("bank-braking", "stiffness-20pct", {"scale_f": 0.8, "scale_r": 0.8}, False),
    ("bank-braking", "stiffness+20pct", {"scale_f": 1.2, "scale_r": 1.2}, False),
    ("bank-braking", "noise", {}, True),
    ("double-lane-change", "", {}, False),
    ("sine-with-dwell", "", {}, False),
    ("fishhook", "", {}, False),
]


def _design_section(path: Path) -> str:
    d = design_file.read(path)            # its checks are the certificate packaging just re-ran
    ok, checks = d["certified"], d["checks"]
    s = certificate.summary(d)
    o = d["options"]
    lines = [f"**{d['name']}** (paper {d['paper']}, vehicle `{d['vehicle']['name']}`): "
             f"{'certified' if ok else 'NOT CERTIFIED'}, {sum(c['passed'] for c in checks)}/{len(checks)} checks "
             f"passed; gamma = {s['gamma']:.4g}; cond(P) = {s['cond_P']:.3g}; pole region Re < -{o['alpha']:g}, "
             f"|lambda| < {o['radius']:g}; Clarabel {d['solver']['status']} in {d['solver']['seconds']:.2f} s.",
             "",
             "| mode | label | speed (km/h) | H-inf bank->beta error | slowest bank pole (1/s) | largest gain |",
             "|---|---|---|---|---|---|"]
    labels = {m["index"]: m["label"] for m in d["modes"]}
    for m in s["per_mode"]:
        lines.append(f"| {m['mode']} | {labels[m['mode']]} | {m['speed_kmh']:.1f} | {m['hinf']:.4g} | "
                     f"{m['slowest_bank_pole']:.3f} | {m['largest_gain']:.4g} |")
    lines += ["", *(f"- {n}" for n in d["notes"]), ""]
    return "\n".join(lines)


def _headline(report: Path) -> str:
    """Paper 000's figures on bank-braking for every variant that ran."""
    import json

    rows = ["| run | observer | beta RMS (rad) | beta max (rad) | ||beta err||/||bank|| (paper: 9.5e-4 speed, "
            "8.85e-3 tire) | bank RMS after 3 s (rad) | bank RMS after 3 s (deg) |",
            "|---|---|---|---|---|---|---|"]
    for scen, tag, params, noise in RUNS:
        if scen != "bank-braking":
            continue
        f = report / (f"{scen}_{tag}" if tag else scen) / "metrics.json"
        m = json.loads(f.read_text())
        for lab, o in m["observers"].items():
            b, w = o["estimates"]["beta_hat"], o["estimates"]["bank_angle_hat"]
            rows.append(f"| {tag or 'nominal'} | {lab} | {b['rms']:.3g} | {b['max_abs']:.3g} | "
                        f"{o['beta_error_to_bank_l2_ratio']:.3g} | {w['rms_after_settle']:.3g} | "
                        f"{w['rms_after_settle'] * 57.29578:.3g} |")
    return "\n".join(rows)


def demo(out: Path) -> Path:
    from .validation.report import ReportSection, section_from_dir, write_index

    t0 = time.perf_counter()
    out = Path(out)
    report = out / "report"
    build(None, None, out)
    for scen, tag, params, noise in RUNS:
        run_validation(scen, None, report, out, plant_parameters=params, noise=noise, tag=tag)
    sections = [ReportSection(title="Designs and their certificates",
                              markdown="\n".join(_design_section(out / f"{n}.design.json") for n in designs.DESIGNS)),
                ReportSection(title="bank-braking: paper 000's figures", markdown=_headline(report))]
    for scen, tag, params, noise in RUNS:
        d = report / (f"{scen}_{tag}" if tag else scen)
        what = ", ".join([f"{k} = {v:g}" for k, v in params.items()] + (["sensor noise and bias"] if noise else []))
        sections.append(section_from_dir(d, title=f"{scen} ({what or 'nominal plant'})"))
    intro = ("Built by `latobs demo`: every FMU designed, certified and packaged, then co-simulated with fmpy "
             "beside the nonlinear CarPlant FMU (sedan, a representative parameter set, not a paper's). "
             "Angles in rad unless stated. The common Lyapunov matrix proves stability under arbitrary "
             "switching among the grid models only.")
    path = write_index(report, sections, title="latobs demo report", intro=intro)
    print(f"report: {path} ({time.perf_counter() - t0:.0f} s)")
    return path
