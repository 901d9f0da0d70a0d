"""The datasheet of every FMU: ``documentation/index.html`` and the icon ``model.png`` inside it,
and the same page as Markdown for the documentation site (:func:`markdown`), generated from what
the model description is generated from (the model's ``ModelSpec`` and the design or plant file).
Byte-reproducible: no date, no path, a PNG written with zlib by hand. Over ~600 lines: the HTML
page, its Markdown twin and the icon share one reading of the spec, so they stay in one module."""
from __future__ import annotations

import html
import json
import math
import re
import struct
import zlib
from functools import lru_cache

from . import __version__
from .fmu_src import framework as _framework
from .fmu_src.spec import ModelSpec, Var, input_starts, max_step, refused_above, var_bounds

PAGE = "documentation/index.html"
ICON = "model.png"
FMI_STANDARD = "https://fmi-standard.org/"
MIT_TEXT = ("Permission is hereby granted, free of charge, to any person obtaining a copy of this software and "
            "associated documentation files (the \"Software\"), to deal in the Software without restriction, "
            "including without limitation the rights to use, copy, modify, merge, publish, distribute, "
            "sublicense, and/or sell copies of the Software, and to permit persons to whom the Software is "
            "furnished to do so, subject to the following conditions: the above copyright notice and this "
            "permission notice shall be included in all copies or substantial portions of the Software. "
            "THE SOFTWARE IS PROVIDED \"AS IS\", WITHOUT WARRANTY OF ANY KIND, EXPRESS OR IMPLIED.")
#: what each backend's binaries need on the importing machine
BACKEND_NOTE = {
    "c": "native C: self-contained binaries (C library and libm only), and the C sources in sources/ "
         "with sources/buildDescription.xml to compile the FMU for any other platform",
    "python": "pythonfmu: the binaries run the model (fmu_src, standard library only, in resources/) in the "
              "Python 3 interpreter of the importing machine",
}


def files(spec: ModelSpec, data: dict, model_identifier: str, *, data_kind: str, backend: str,
          platforms: list[str], generation_tool: str, copyright: str, license: str = "MIT",
          states: tuple[Var, ...] = (), fmi: int = 2) -> dict[str, bytes]:
    """{``documentation/index.html``: bytes, ``model.png``: bytes} of an FMU.

    ``data``: its design file (``data_kind`` "design") or plant file ("plant"); ``backend``: "c"
    or "python"; ``platforms``: the folders of ``binaries/`` the FMU holds; ``states``: the
    ModelExchange states of a native FMU (their derivatives are listed too); ``fmi``: its FMI version."""
    vehicle = data.get("vehicle") if isinstance(data.get("vehicle"), dict) else {}
    kind = "motorcycle" if vehicle.get("kind") == "motorcycle" else "car"
    page = _page(spec, data, model_identifier, data_kind=data_kind, backend=backend, platforms=list(platforms),
                 generation_tool=generation_tool, copyright=copyright, license=license, states=tuple(states), fmi=fmi)
    return {PAGE: page.encode("utf-8"), ICON: icon(kind, observer=data_kind == "design")}


# ---------------------------------------------------------------------------------------------
# the page
# ---------------------------------------------------------------------------------------------
CSS = """
body{font-family:system-ui,-apple-system,'Segoe UI',Roboto,sans-serif;margin:0 auto;max-width:1150px;
padding:1.5em;color:#1d2733;line-height:1.45}
header{display:flex;gap:1.2em;align-items:center;border-bottom:3px solid #2a6fb0;padding-bottom:.8em}
header img{width:96px;height:96px}
h1{margin:0;font-size:1.8em} h2{border-bottom:1px solid #c9d4df;padding-bottom:.2em;margin-top:1.6em}
nav ol{columns:3;font-size:.95em} code{background:#eef2f6;padding:0 .25em;border-radius:3px}
table{border-collapse:collapse;width:100%;font-size:.88em;margin:.5em 0}
th,td{border:1px solid #c9d4df;padding:.25em .45em;text-align:left;vertical-align:top}
th{background:#e3ebf3} tr:nth-child(even) td{background:#f6f8fa}
td.num{text-align:right;font-variant-numeric:tabular-nums;white-space:nowrap}
.pass{color:#17692b;font-weight:600} .fail{color:#a31515;font-weight:600}
.note{color:#4a5866;font-size:.92em} .big{font-size:1.15em}
"""


def _e(x) -> str:
    return html.escape(str(x), quote=True)


def _n(x) -> str:
    """A number as the page shows it (None: a dash)."""
    if x is None:
        return "—"
    if isinstance(x, bool):
        return str(int(x))
    if isinstance(x, int):
        return str(x)
    x = float(x)
    if math.isinf(x):
        return "∞" if x > 0 else "−∞"
    return f"{x:.6g}"


def _table(headers: list[str], rows: list[list[str]], attrs: str = "") -> str:
    """A table; ``rows`` hold HTML (already escaped) cells."""
    head = "".join(f"<th>{_e(h)}</th>" for h in headers)
    body = "".join(f"<tr>{''.join(r)}</tr>" for r in rows)
    return f"<table{attrs}><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"


def _variables(spec: ModelSpec, data: dict, states: tuple[Var, ...]) -> list[tuple[str, str, str, Var, dict]]:
    """(name, causality, type, Var, {unit, min, max, start}) of every variable of the model
    description, in its order, with the values it declares (framework.model_description)."""
    bounds = {}
    for group in (spec.parameters, spec.inputs, spec.outputs, spec.integer_outputs):
        bounds.update(var_bounds(spec, data, group))
    starts, in_starts = _framework.start_values(spec, data), input_starts(spec, data)
    out = []
    for _, typ, caus, v in _framework.variable_table(spec):
        lo, hi = bounds.get(v.name, (v.min, v.max))
        start = starts[v.name] if caus == "parameter" else in_starts[v.name] if caus == "input" else None
        out.append((v.name, caus, typ, v, {"unit": v.unit, "min": lo, "max": hi, "start": start}))
    for v in states:
        out.append((v.name, "local (state)", "Real", v, {"unit": v.unit, "min": None, "max": None, "start": None}))
    for v in states:
        unit = _framework.DERIVATIVE_UNITS.get(v.unit, "")
        dv = Var(f"der({v.name})", unit, f"time derivative of {v.name}")
        out.append((dv.name, "local (derivative)", "Real", dv, {"unit": unit, "min": None, "max": None,
                                                               "start": None}))
    return out


#: the columns of the variable tables (both renderers)
VAR_HEADERS = ["name", "causality", "type", "unit", "min", "max", "start", "description", "sign convention",
               "source (sensor)"]
VAR_TITLES = {"input": "Inputs", "output": "Outputs", "parameter": "Parameters (fixed: set before initialisation)",
              "local (state)": "ModelExchange states", "local (derivative)": "Their derivatives"}
VAR_NOTE = ("Every variable of modelDescription.xml, with the unit, range and start value it declares there; the "
            "model description's description of a variable is its description, sign convention and source joined. "
            "Angles are in rad (displayed in deg by the importers that read the display units), speeds in m/s. A "
            "step with an input outside its [min, max], or non-finite, is refused (error logged, state kept); so is "
            "a parameter outside its range at initialisation.")


def _interface_cells(spec: ModelSpec, data: dict, states: tuple[Var, ...]) -> dict[str, list[list[str]]]:
    """{causality: rows of plain-text cells in the order of :data:`VAR_HEADERS`}: the variable
    tables of both renderers (the HTML datasheet and the Markdown page)."""
    groups = {caus: [] for caus in VAR_TITLES}
    for name, caus, typ, v, d in _variables(spec, data, states):
        start = _n(d["start"]) if d["start"] is not None else ("calculated" if caus == "output" else "—")
        groups[caus].append([name, caus, typ, d["unit"], _n(d["min"]), _n(d["max"]), start, v.description,
                             v.sign or "—", v.sensor or "—"])
    return groups


def _interface(spec: ModelSpec, data: dict, states: tuple[Var, ...]) -> str:
    classes = ["", "causality", "", "unit", "num", "num", "num", "description", "sign", "sensor"]
    groups = {}
    for caus, rows in _interface_cells(spec, data, states).items():
        groups[caus] = [[f'<td id="var-{_e(r[0])}"><code class="name">{_e(r[0])}</code></td>']
                        + [f'<td class="{c}">{_e(x)}</td>' if c else f"<td>{_e(x)}</td>"
                           for c, x in zip(classes[1:], r[1:])] for r in rows]
    note = html.escape(VAR_NOTE, quote=False).replace("modelDescription.xml", "<code>modelDescription.xml</code>")
    parts = [f'<p class="note">{note}</p>']
    for caus, rows in groups.items():
        if rows:
            parts.append(f"<h3>{_e(VAR_TITLES[caus])}</h3>" + _table(VAR_HEADERS, rows, f' class="variables {caus}"'))
    return "".join(parts)


def _value(p):
    """A vehicle parameter's value (a parameter set stores {value, unit, description})."""
    return p.get("value") if isinstance(p, dict) else p


def _speed_range(data: dict):
    """(lo, hi) m/s of the design's speed grid, or None."""
    edges = data.get("switching", {}).get("edges") if isinstance(data.get("switching"), dict) else None
    if edges:
        return float(edges[0]), float(edges[-1])
    def band(m: dict):
        sched = m.get("scheduling") or {}
        for b in (m.get("vx_band"), (m.get("box") or {}).get("v"),
                  sched.get("range") if sched.get("variable") == "vx" else None,
                  (m.get("model_speed") or {}).get("range")):
            if isinstance(b, list) and len(b) == 2 and all(isinstance(x, (int, float)) for x in b):
                return b
        return None

    bands = [b for b in (band(m) for m in data.get("modes") or [] if isinstance(m, dict)) if b]
    if bands:
        return min(float(b[0]) for b in bands), max(float(b[1]) for b in bands)
    return None


def _box(data: dict):
    """{"Cf": (lo, hi), "Cr": (lo, hi)} N/rad per axle: the design's cornering-stiffness box, or None."""
    if data.get("stiffness_box"):
        return {k: tuple(data["stiffness_box"][k]) for k in ("Cf", "Cr")}
    boxes = [m["box"] for m in data.get("modes") or [] if isinstance(m, dict) and isinstance(m.get("box"), dict)
             and "Cf" in m["box"]]
    if boxes:
        return {k: (min(b[k][0] for b in boxes), max(b[k][1] for b in boxes)) for k in ("Cf", "Cr")}
    return None


def _ranges(spec: ModelSpec, data: dict, data_kind: str) -> str:
    rows = []
    declared = {**var_bounds(spec, data, spec.inputs), **var_bounds(spec, data, spec.parameters)}
    described = {v.name: v.description for v in (*spec.inputs, *spec.parameters)}
    speed = _speed_range(data)
    if speed:
        rows.append(("speed", f"{_n(speed[0])} … {_n(speed[1])} m/s ({_n(3.6 * speed[0])} … {_n(3.6 * speed[1])} "
                     "km/h)", "the design's speed grid: the certificate holds inside it; outside it the nearest "
                     "mode runs (with a warning where the model says so)"))
    if "vx" in declared:
        lo, hi = declared["vx"]
        rows.append(("speed accepted", f"{_n(lo)} … {_n(hi)} m/s", "the input vx's declared range (a step "
                     f"outside it is refused); vx: {described['vx']}"))
    hold = next((v for v in spec.parameters if v.name == "vx_hold"), None)
    if hold is not None:
        rows.append(("standstill", f"vx_hold = {_n(_framework.start_values(spec, data)['vx_hold'])} m/s (parameter)",
                     hold.description))
    box = _box(data)
    veh = {k: _value(x) for k, x in ((data.get("vehicle") or {}).get("parameters") or {}).items()}
    if box:
        rows.append(("cornering stiffness", f"front {_n(box['Cf'][0])} … {_n(box['Cf'][1])}, rear "
                     f"{_n(box['Cr'][0])} … {_n(box['Cr'][1])} N/rad per axle",
                     "the design's stiffness box: the certificate covers every stiffness inside it"))
    else:
        cf, cr = (("Cf", "Cr") if isinstance(veh.get("Cf"), (int, float)) else ("Cf1", "Cr1"))
        if isinstance(veh.get(cf), (int, float)) and isinstance(veh.get(cr), (int, float)):
            where = ("the vehicle's values" + (", scaled by the parameters scale_f, scale_r and the inputs "
                                               "stiffness_scale_f, stiffness_scale_r" if "scale_f" in declared else "")
                     if data_kind == "plant" else "the design model's nominal values")
            rows.append(("cornering stiffness", f"front {_n(veh[cf])}, rear {_n(veh[cr])} N/rad "
                         f"({cf}, {cr})", where))
    for name, r in ((data.get("vehicle") or {}).get("ranges") or {}).items():
        if isinstance(r, dict) and "min" in r and "max" in r:
            rows.append((f"vehicle range {name}", f"{_n(r['min'])} … {_n(r['max'])} {r.get('unit', '')}",
                         r.get("description", "")))
    for name in ("scale_f", "scale_r", "stiffness_scale_f", "stiffness_scale_r", "mu"):
        if name in declared:
            rows.append((name, f"{_n(declared[name][0])} … {_n(declared[name][1])}",
                         f"declared range; {described[name]}"))
    validity = data.get("validity") if isinstance(data.get("validity"), dict) else {}
    if "alpha_max" in validity:
        rows.append(("slip angle", f"|alpha_f|, |alpha_r| ≤ {_n(validity['alpha_max'])} rad "
                     f"({_n(math.degrees(validity['alpha_max']))} deg), |vx·yaw_rate| ≤ "
                     f"{_n(validity.get('ay_max'))} m/s2", "the design's linear domain: the output valid is 0 "
                     f"beyond it, 1 again below {_n(validity.get('release'))} × both limits"))
    star = (data.get("switching") or {}).get("alpha_star") if isinstance(data.get("switching"), dict) else None
    if isinstance(star, (int, float)):
        rows.append(("slip angle", f"tire modes switch at |alpha| = {_n(star)} rad ({_n(math.degrees(star))} deg)",
                     "linear (C1) below, reduced stiffness (C2) above"))
    if not any(r[0] == "slip angle" for r in rows):
        rows.append(("slip angle", "not bounded by the model",
                     "Magic Formula tires: any slip angle (force saturating at the friction limit)"
                     if data_kind == "plant" else
                     "a linear tire model: the estimates hold in the linear tire range (small slip angles)"))
    return _table(["quantity", "range", "meaning"], [[f"<td>{_e(a)}</td>", f"<td>{_e(b)}</td>", f"<td>{_e(c)}</td>"]
                                                     for a, b, c in rows], ' class="ranges"')


def _step(spec: ModelSpec, data: dict, fmi: int = 2) -> str:
    longest = max_step(spec, data)
    return (f'<p class="big">Largest communication step: <strong id="max-step" data-value="{longest!r}">'
            f"{_n(longest)} s</strong></p><p>A longer step is refused by both FMI interfaces (fmi{fmi}Error, the state "
            f"kept): above {_n(refused_above(spec, data))} s, the slack covering a host that computes its step as a "
            f"difference of times. The accuracy is measured up to this step. The default experiment suggests "
            f"{_n(min(_framework.DEFAULT_STEP, longest))} s. Any shorter step, variable from step to step, is "
            "accepted.</p>")


def _initialisation(spec: ModelSpec, data: dict) -> str:
    starts = input_starts(spec, data)
    pars = _framework.start_values(spec, data)
    rows = [[f"<td><code>{_e(n)}</code></td>", f'<td class="num">{_n(x)}</td>', "<td>input</td>"]
            for n, x in starts.items()]
    rows += [[f"<td><code>{_e(n)}</code></td>", f'<td class="num">{_n(x)}</td>', "<td>parameter</td>"]
             for n, x in pars.items()]
    text = spec.initialization or "the model starts from its start values"
    grid = (" (a vx start inside the design's speed grid, so that the FMU run unconnected steps without a "
            "warning)" if spec.starts is not None else "")
    return (f"<p>At the start time {_e(text)}.</p><p>The parameters are fixed: set them between instantiation and "
            "the end of the initialisation mode. The inputs set during initialisation are the ones the model "
            f"starts from; unset inputs keep the start values below{grid}. Outputs are calculated at the end of "
            "initialisation; in co-simulation they change only in a step (no output depends directly on an "
            "input).</p>"
            + _table(["variable", "start", "causality"], rows, ' class="starts"'))


def _status(spec: ModelSpec, data: dict) -> str:
    if not spec.integer_outputs:
        return "<p>This FMU has no status output (no <code>valid</code>, <code>consistent</code> or <code>mode</code>).</p>"
    bounds = var_bounds(spec, data, spec.integer_outputs)
    rows = [[f"<td><code>{_e(v.name)}</code></td>", f'<td class="num">{_n(bounds[v.name][0])} … '
             f"{_n(bounds[v.name][1])}</td>", f"<td>{_e(v.description)}</td>"] for v in spec.integer_outputs]
    return _table(["Integer output", "values", "meaning"], rows, ' class="status"')


def _slug(text: str) -> str:
    """An HTML id made of ``text`` (no white space)."""
    return re.sub(r"[^A-Za-z0-9_]+", "-", text).strip("-")


def _margin(c: dict):
    v, lim = c.get("value"), c.get("limit")
    if not all(isinstance(x, (int, float)) for x in (v, lim)):
        return None
    return v - lim if c.get("sense") == ">=" else lim - v


def _headline(data: dict) -> list[tuple[str, object]]:
    """The certificate's headline figures the design file holds (gamma and its companions)."""
    keys = ("gamma", "gamma_grid", "iss_gain", "beta", "epsilon", "eta", "alpha")
    out = [(k, data[k]) for k in keys if isinstance(data.get(k), (int, float)) and not isinstance(data[k], bool)]
    dw = data.get("dwell_time")
    if isinstance(dw, dict) and isinstance(dw.get("tau_a"), (int, float)):
        out.append(("average dwell time tau_a (s)", dw["tau_a"]))
    cert = data.get("certificate")
    if isinstance(cert, dict):
        out += [(f"certificate {k}", x) for k, x in cert.items() if isinstance(x, (int, float))]
    return out


def _certificate(data: dict, data_kind: str) -> str:
    if data_kind != "design":
        return ("<p>A plant is a truth model for validation: it carries no design certificate. Its vehicle "
                "parameters are below.</p>")
    checks = [c for c in data.get("checks") or [] if isinstance(c, dict)]
    passed = sum(1 for c in checks if c.get("passed"))
    ok = bool(data.get("certified")) and passed == len(checks) and checks
    parts = [f'<p class="big">Certified: <strong id="certified" class="{"pass" if ok else "fail"}">'
             f'{"yes" if ok else "no"}</strong> — <span id="checks-passed">{passed}</span> of '
             f'<span id="checks-count">{len(checks)}</span> checks passed.</p>',
             "<p>The certificate is computed independently of the design solver, from the design file alone "
             "(re-checked at packaging: an uncertified design is never packaged). A margin is how far a value "
             "lies inside its limit (limit − value for ≤, value − limit for ≥).</p>"]
    if data.get("gamma_meaning"):
        parts.append(f"<p>γ: {_e(data['gamma_meaning'])}</p>")
    head = _headline(data)
    if head:
        parts.append(_table(["figure", "value"], [[f"<td>{_e(k)}</td>", f'<td class="num" id="fig-{_slug(k)}" '
                                                   f'data-value="{float(x)!r}">{_n(x)}</td>'] for k, x in head],
                            ' class="headline"'))
    rows = []
    for k, c in enumerate(checks, 1):
        cls = "pass" if c.get("passed") else "fail"
        detail = f'<br><span class="note">{_e(c["detail"])}</span>' if c.get("detail") else ""
        rows.append([f'<td class="num">{k}</td>', f"<td>{_e(c.get('name', ''))}{detail}</td>",
                     f'<td class="num">{_n(c.get("value"))}</td>', f"<td>{_e(c.get('sense', '<='))}</td>",
                     f'<td class="num">{_n(c.get("limit"))}</td>', f'<td class="num">{_n(_margin(c))}</td>',
                     f'<td class="{cls}">{"pass" if c.get("passed") else "FAIL"}</td>'])
    parts.append(_table(["#", "check", "value", "", "limit", "margin", ""], rows, ' class="checks"'))
    return "".join(parts)


def _data(data: dict, data_kind: str) -> str:
    veh = data.get("vehicle") if isinstance(data.get("vehicle"), dict) else {}
    parts = []
    if veh:
        parts.append(f"<p>Vehicle <code>{_e(veh.get('name', '?'))}</code>: {_e(veh.get('description', ''))}</p>")
        params = veh.get("parameters") or {}
        rows = []
        for k, p in params.items():
            x, unit, desc = _value(p), p.get("unit", "") if isinstance(p, dict) else "", \
                p.get("description", "") if isinstance(p, dict) else ""
            shown = _n(x) if isinstance(x, (int, float)) else _e(json.dumps(x))
            rows.append([f"<td><code>{_e(k)}</code></td>", f'<td class="num">{shown}</td>', f"<td>{_e(unit)}</td>",
                         f"<td>{_e(desc)}</td>"])
        if rows:
            parts.append(_table(["parameter", "value", "unit", "description"], rows, ' class="vehicle"'))
    name = "resources/<name>.{}.json".format(data_kind)
    parts.append(f"<p>The complete {_e(data_kind)} file is inside the FMU, for the record: <code>{_e(name)}</code>"
                 " (the model's data as built in; the binaries do not read it back).</p>")
    for note in data.get("notes") or []:
        parts.append(f'<p class="note">{_e(note)}</p>')
    return "".join(parts)


def _page(spec: ModelSpec, data: dict, model_identifier: str, *, data_kind: str, backend: str,
          platforms: list[str], generation_tool: str, copyright: str, license: str, states: tuple[Var, ...], fmi: int = 2) -> str:
    sections = []

    def section(ident: str, title: str, body: str) -> None:
        sections.append((ident, title, f'<section id="{ident}"><h2>{_e(title)}</h2>{body}</section>'))

    role = "observer" if data_kind == "design" else "plant (truth model)"
    outs = ", ".join(f"<code>{_e(v.name)}</code>" for v in (*spec.outputs, *spec.integer_outputs))
    verb = "It estimates" if data_kind == "design" else "It simulates"
    section("what", "What it is", f"<p>{_e(_framework.model_text(spec, data))}</p><p>{verb}: {outs}, from "
            f"{', '.join(f'<code>{_e(v.name)}</code>' for v in spec.inputs)}.</p>")
    if spec.paper is not None:
        p = spec.paper
        doi = (f' DOI: <a href="https://doi.org/{_e(p.doi)}">{_e(p.doi)}</a>.' if p.doi else "")
        title = f"<p>Design: {_e(data['title'])}.</p>" if data.get("title") else ""
        section("paper", "Source paper", f'<p class="paper">{_e(", ".join(p.authors))}: <cite>{_e(p.title)}</cite>. '
                f"{_e(p.venue)}, <span class=\"year\">{p.year}</span>.{doi}</p>{title}<p class=\"note\">Every "
                "departure from the paper's printed equations is commented in the sources where it is "
                "implemented.</p>")
    else:
        section("paper", "Source", "<p>latobs's own model (no single source paper); its equations are documented "
                "in the runtime sources.</p>")
    section("interface", "Inputs, outputs, parameters", _interface(spec, data, states))
    section("range", "Valid speed, stiffness and slip range", _ranges(spec, data, data_kind))
    section("step", "Communication step", _step(spec, data, fmi))
    section("init", "Initialisation", _initialisation(spec, data))
    section("status", "Status outputs: valid, consistent, mode", _status(spec, data))
    section("certificate", "Certificate", _certificate(data, data_kind))
    section("data", "Design data" if data_kind == "design" else "Plant data", _data(data, data_kind))
    plat = "\n".join(f"<li><code>binaries/{_e(p)}</code></li>" for p in platforms)
    section("platforms", "Platforms", f'<ul id="platform-list">{plat}</ul><p>Backend: {_e(BACKEND_NOTE[backend])}.'
            "</p>")
    section("licence", "Licence", f"<p>{_e(copyright)}. Licence: <strong id=\"license\">{_e(license)}</strong>.</p>"
            + (f'<p class="note">{_e(MIT_TEXT)}</p>' if license == "MIT" else ""))
    nav = "".join(f'<li><a href="#{ident}">{_e(title)}</a></li>' for ident, title, _ in sections)
    return ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            f"<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\"><title>{_e(model_identifier)}"
            f" — datasheet</title><style>{CSS}</style></head><body>"
            f'<header><img src="../{ICON}" alt="{_e(model_identifier)} icon"><div><h1>{_e(model_identifier)}</h1>'
            f"<div>FMI {fmi}.0 {_e(role)} · {_e(generation_tool)}</div></div></header>"
            f"<nav><ol>{nav}</ol></nav>{''.join(s for _, _, s in sections)}"
            f'<footer><p class="note">Generated by latobs {_e(__version__)} from the declarations the FMU\'s '
            f'modelDescription.xml is generated from. <a href="{FMI_STANDARD}">The FMI standard</a>.</p></footer>'
            "</body></html>\n")


# ---------------------------------------------------------------------------------------------
# the same datasheet as a Markdown page of the documentation site, from the spec alone
# ---------------------------------------------------------------------------------------------
def _md(x) -> str:
    """Text as a Markdown table cell or paragraph shows it literally."""
    text = html.escape(str(x), quote=False)
    for ch in ("\\", "|", "*", "[", "]", "`"):
        text = text.replace(ch, "\\" + ch)
    return text.replace("\n", " ")


def _md_table(headers: list[str], rows: list[list[str]]) -> str:
    """A Markdown table; ``rows`` hold Markdown cells (already escaped)."""
    lines = ["| " + " | ".join(headers) + " |", "|" + "---|" * len(headers)]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines)


def markdown(spec: ModelSpec, model_identifier: str, *, data_kind: str, summary: str = "",
             paper_page: str = "", data: dict | None = None) -> str:
    """The FMU's datasheet as a Markdown page (the documentation site's page of the FMU).

    The same sections and tables as the HTML datasheet inside the FMU, from the same declarations,
    for the data file ``data`` (None: the spec alone, before any design: the values that depend on
    the design, such as data-dependent ranges and start values and the certificate, are left to
    the built FMU's own datasheet). ``summary``: a line of Markdown on what this FMU of the model file is;
    ``paper_page``: a relative link to the documentation page of its paper. Each variable table is one
    causality's: its rows are the HTML datasheet's cells without the causality column."""
    data = data or {}
    role = "observer" if data_kind == "design" else "plant (truth model)"
    verb = "It estimates" if data_kind == "design" else "It simulates"
    outs = ", ".join(f"`{v.name}`" for v in (*spec.outputs, *spec.integer_outputs))
    ins = ", ".join(f"`{v.name}`" for v in spec.inputs)
    text = _framework.model_text(spec, data) if data else spec.description
    out = [f"# {model_identifier}", "", f"*FMI 2.0 {role}, generated from the FMU's declarations.*", ""]
    if summary:
        out += [summary, ""]
    out += ["## What it is", "", _md(text), "", f"{verb}: {outs}, from {ins}.", ""]
    out += ["## Source paper", ""]
    if spec.paper is not None:
        p = spec.paper
        doi = f" DOI: [{p.doi}](https://doi.org/{p.doi})." if p.doi else ""
        out.append(f"{_md(', '.join(p.authors))}: *{_md(p.title)}*. {_md(p.venue)}, {p.year}.{doi}")
        out.append("")
        link = f" ([the paper's page]({paper_page}))" if paper_page else ""
        out += [f"Every departure from the paper's printed equations is commented in the sources where it is "
                f"implemented{link}.", ""]
    else:
        out += ["latobs's own model (no single source paper); its equations are documented in the runtime sources.",
                ""]
    out += ["## Inputs, outputs, parameters", "", _md(VAR_NOTE), ""]
    if not data:
        out += ["Ranges and start values are those the model declares; where they depend on the design (the "
                "number of modes, a speed start value inside the design's grid) the built FMU's datasheet gives "
                "its own.", ""]
    for caus, rows in _interface_cells(spec, data, ()).items():
        if rows:
            cells = [[f"`{r[0]}`"] + [_md(x) for x in r[2:]] for r in rows]
            out += [f"### {VAR_TITLES[caus]}", "", _md_table(VAR_HEADERS[:1] + VAR_HEADERS[2:], cells), ""]
    out += ["## Communication step", ""]
    if data or not callable(spec.max_step):
        longest = max_step(spec, data)
        out.append(f"Largest communication step: **{_n(longest)} s**. A longer step is refused by both FMI "
                   f"interfaces (fmi2Error, the state kept). The default experiment suggests "
                   f"{_n(min(_framework.DEFAULT_STEP, longest))} s; any shorter step, variable from step to step, "
                   "is accepted.")
    else:
        out.append("The largest communication step is a property of the design: computed when the design is "
                   "solved, stored in its design file and declared in the FMU's model description "
                   "(`VendorAnnotations`, tool `latobs`). A longer step is refused by both FMI interfaces "
                   "(fmi2Error, the state kept).")
    out += ["", "## Initialisation", "",
            f"At the start time {_md(spec.initialization or 'the model starts from its start values')}. The "
            "parameters are fixed: set them between instantiation and the end of the initialisation mode. Outputs "
            "are calculated at the end of initialisation; in co-simulation they change only in a step.", ""]
    out += ["## Status outputs: valid, consistent, mode", ""]
    if spec.integer_outputs:
        bounds = var_bounds(spec, data, spec.integer_outputs)
        rows = [[f"`{v.name}`", f"{_n(bounds[v.name][0])} … {_n(bounds[v.name][1])}", _md(v.description)]
                for v in spec.integer_outputs]
        out += [_md_table(["Integer output", "values", "meaning"], rows), ""]
    else:
        out += ["This FMU has no status output (no `valid`, `consistent` or `mode`).", ""]
    out += ["## Certificate, ranges, vehicle data", "",
            "Every built FMU carries this datasheet with its own design's figures: `documentation/index.html` "
            "(open it from your FMI tool's documentation menu, or `unzip X.fmu documentation/index.html`) adds the "
            "valid speed, stiffness and slip range, the certificate (every check with its value, limit and "
            "margin), the vehicle parameters and the platforms of `binaries/`.", ""]
    return "\n".join(out)


# ---------------------------------------------------------------------------------------------
# the icon: 128 x 128 RGBA, drawn by coverage sampling (3 x 3 per pixel), written with zlib
# ---------------------------------------------------------------------------------------------
SIZE = 128
_SS = 3


def _png(width: int, height: int, rgba: bytearray) -> bytes:
    def chunk(tag: bytes, body: bytes) -> bytes:
        return struct.pack(">I", len(body)) + tag + body + struct.pack(">I", zlib.crc32(tag + body) & 0xFFFFFFFF)

    stride = 4 * width
    raw = b"".join(b"\x00" + bytes(rgba[y * stride:(y + 1) * stride]) for y in range(height))
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 6, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(raw, 9)) + chunk(b"IEND", b""))


class _Canvas:
    def __init__(self):
        self.px = bytearray(4 * SIZE * SIZE)

    def fill(self, inside, bbox, color) -> None:
        """Blend ``color`` (r, g, b) over the pixels in ``bbox`` (x0, y0, x1, y1) by the fraction of
        their samples where ``inside(x, y)``."""
        x0, y0, x1, y1 = (max(0, int(math.floor(bbox[0]))), max(0, int(math.floor(bbox[1]))),
                          min(SIZE, int(math.ceil(bbox[2])) + 1), min(SIZE, int(math.ceil(bbox[3])) + 1))
        offs = [(k + 0.5) / _SS for k in range(_SS)]
        for y in range(y0, y1):
            for x in range(x0, x1):
                a = sum(1 for oy in offs for ox in offs if inside(x + ox, y + oy)) / (_SS * _SS)
                if a:
                    i = 4 * (y * SIZE + x)
                    old_a = self.px[i + 3] / 255
                    out_a = a + old_a * (1 - a)
                    for c in range(3):
                        self.px[i + c] = round((color[c] * a + self.px[i + c] * old_a * (1 - a)) / out_a)
                    self.px[i + 3] = round(255 * out_a)

    def polygon(self, pts, color) -> None:
        def inside(x, y):
            c = False
            for (xa, ya), (xb, yb) in zip(pts, pts[1:] + pts[:1]):
                if (ya > y) != (yb > y) and x < xa + (y - ya) * (xb - xa) / (yb - ya):
                    c = not c
            return c
        xs, ys = [p[0] for p in pts], [p[1] for p in pts]
        self.fill(inside, (min(xs), min(ys), max(xs), max(ys)), color)

    def line(self, a, b, width, color) -> None:
        (xa, ya), (xb, yb), r = a, b, width / 2
        dx, dy = xb - xa, yb - ya
        L2 = dx * dx + dy * dy or 1.0

        def inside(x, y):
            t = min(1.0, max(0.0, ((x - xa) * dx + (y - ya) * dy) / L2))
            return (x - xa - t * dx) ** 2 + (y - ya - t * dy) ** 2 <= r * r
        self.fill(inside, (min(xa, xb) - r, min(ya, yb) - r, max(xa, xb) + r, max(ya, yb) + r), color)

    def ring(self, c, r_out, r_in, color) -> None:
        def inside(x, y):
            d2 = (x - c[0]) ** 2 + (y - c[1]) ** 2
            return r_in * r_in <= d2 <= r_out * r_out
        self.fill(inside, (c[0] - r_out, c[1] - r_out, c[0] + r_out, c[1] + r_out), color)

    def rounded(self, box, r, color) -> None:
        x0, y0, x1, y1 = box

        def inside(x, y):
            dx = max(x0 + r - x, 0.0, x - (x1 - r))
            dy = max(y0 + r - y, 0.0, y - (y1 - r))
            return dx * dx + dy * dy <= r * r
        self.fill(inside, box, color)

    def arrow(self, a, b, width, head, color) -> None:
        dx, dy = b[0] - a[0], b[1] - a[1]
        L = math.hypot(dx, dy)
        ux, uy = dx / L, dy / L
        base = (b[0] - head * ux, b[1] - head * uy)
        self.line(a, base, width, color)
        self.polygon([b, (base[0] - 0.6 * head * uy, base[1] + 0.6 * head * ux),
                      (base[0] + 0.6 * head * uy, base[1] - 0.6 * head * ux)], color)


def _rot(p, c, ang):
    s, co = math.sin(ang), math.cos(ang)
    x, y = p[0] - c[0], p[1] - c[1]
    return (c[0] + co * x - s * y, c[1] + s * x + co * y)


def _rect(cx, cy, w, h, ang=0.0):
    pts = [(cx - w / 2, cy - h / 2), (cx + w / 2, cy - h / 2), (cx + w / 2, cy + h / 2), (cx - w / 2, cy + h / 2)]
    return [_rot(p, (cx, cy), ang) for p in pts]


INK, RED, PAPER = (29, 39, 51), (200, 40, 40), (250, 251, 252)
BODY = {True: (42, 111, 176), False: (120, 128, 138)}       # observer: blue; plant: grey


@lru_cache(maxsize=None)
def icon(kind: str, observer: bool) -> bytes:
    """``model.png``: a car seen from above (heading up) with its velocity at a sideslip angle, or
    a motorcycle seen from the side; blue with a hat (an estimate) for an observer, grey for a plant."""
    cv = _Canvas()
    cv.rounded((2, 2, SIZE - 2, SIZE - 2), 18, PAPER)
    body = BODY[observer]
    if kind == "motorcycle":
        for cx in (32, 98):
            cv.ring((cx, 90), 19, 13, INK)
        cv.polygon([(32, 90), (52, 62), (84, 58), (98, 90), (88, 90), (78, 70), (56, 72), (40, 90)], body)
        cv.polygon([(48, 58), (62, 48), (82, 50), (84, 60), (52, 64)], body)            # tank and seat
        cv.line((84, 42), (98, 90), 5, INK)                                             # fork
        cv.line((76, 40), (90, 38), 5, INK)                                             # handlebar
        cv.line((56, 48), (70, 24), 9, INK)                                             # rider
        cv.ring((74, 18), 7, 0, INK)
        cv.line((68, 30), (82, 40), 5, INK)
        cv.arrow((20, 116), (60, 116), 4, 11, RED)                                      # forward speed
    else:
        c = (64, 66)
        cv.rounded((44, 22, 84, 110), 12, body)
        cv.polygon([(48, 46), (80, 46), (76, 58), (52, 58)], INK)                       # windscreen
        steer = -0.3                                                                    # steered left
        for (x, y) in ((40, 40), (88, 40)):
            cv.polygon(_rect(x, y, 7, 18, steer), INK)
        for (x, y) in ((40, 94), (88, 94)):
            cv.polygon(_rect(x, y, 7, 18), INK)
        cv.line((64, 66), (64, 8), 2, INK)                                              # heading
        beta = -0.45                                                                    # sideslip, to the left
        tip = _rot((64, 14), c, beta)
        cv.arrow(c, tip, 4, 12, RED)                                                    # velocity
        cv.ring(c, 4, 0, RED)
    if observer:
        cv.ring((108, 20), 15, 0, (255, 255, 255))
        cv.ring((108, 20), 15, 12, body)
        cv.line((100, 24), (108, 15), 4, body)                                          # the hat of an estimate
        cv.line((108, 15), (116, 24), 4, body)
    return _png(SIZE, SIZE, cv.px)
