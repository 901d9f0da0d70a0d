"""Reference results inside an FMU, in the FMI layered standard FMI-LS-REF
(``extra/org.fmi-standard.fmi-ls-ref/``: manifest, MA-HS-Experiments file, input and reference
CSVs as the Reference FMUs ship them; tolerances in a latobs annotation): written at build time,
read by ``latobs check``. The documentation's "Using an FMU in your tool" page says how an
experiment runs and what the tolerances are."""
from __future__ import annotations

import hashlib
import math
import posixpath
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from xml.etree import ElementTree as ET

import numpy as np

__all__ = ["LS_DIR", "MANIFEST", "Experiment", "ReferenceResultsError", "Comparison", "files", "read", "compare",
           "identity_of"]

LS_NAME = "org.fmi-standard.fmi-ls-ref"
LS_DIR = f"extra/{LS_NAME}"
MANIFEST = f"{LS_DIR}/fmi-ls-manifest.xml"
EXPERIMENTS = "experiments.exp"
DOCUMENTATION = "documentation/fmi-ls-ref.txt"
LS_NS = "http://fmi-standard.org/fmi-ls-manifest"
LS_VERSION = "1.0.0-alpha.1"
LS_DESCRIPTION = "Layered Standard providing information on related files included in an FMU."
EXPERIMENTS_TYPE = "application/x-ma-hs-experiments"
#: |y - y_ref| <= RELATIVE_TOLERANCE |y_ref| + RELATIVE_TOLERANCE max|y_ref| off the certifying platform
RELATIVE_TOLERANCE = 1e-12
RUN_RULE = ("fixed step h = stepSize; inputs of row 0 set in initialisation mode; at t_k = startTime + k h the "
            "inputs of row k are set, then doStep(t_k, h); output row 0 after initialisation, row k+1 after step k")


class ReferenceResultsError(ValueError):
    """An FMU holds no (readable) reference results: the message says which file and why."""


@dataclass
class Experiment:
    """One reference experiment: the inputs applied and the outputs recorded at ``time``.

    name         experiment name (file names ``NAME_in.csv``, ``NAME_ref.csv``)
    description  what it is (scenario, plant) and how it runs
    time         communication points t_k = start + k step, s, shape (n,)
    step         communication step h, s
    inputs       {input name: values at time}, in the FMU's order
    outputs      {output name: values at time} (Integer outputs as int arrays)
    platform     the certifying platform folder (bit for bit there)
    relative     relative tolerance elsewhere; ``absolute`` {output: floor} (default: relative x peak)
    """

    name: str
    description: str
    time: np.ndarray
    step: float
    inputs: dict[str, np.ndarray]
    outputs: dict[str, np.ndarray]
    platform: str
    relative: float = RELATIVE_TOLERANCE
    absolute: dict[str, float] = field(default_factory=dict)

    def __post_init__(self):
        if not self.absolute:
            self.absolute = {k: float(self.relative * np.max(np.abs(v))) if len(v) else 0.0
                             for k, v in self.outputs.items()}

    @property
    def start(self) -> float:
        return float(self.time[0])

    @property
    def stop(self) -> float:
        return float(self.time[-1])


# --------------------------------------------------------------------------------------------
# writing
# --------------------------------------------------------------------------------------------
def _num(x) -> str:
    """The shortest text that reads back as the same number (integers as integers)."""
    if isinstance(x, (int, np.integer)):
        return str(int(x))
    return repr(float(x))


def csv_bytes(time: np.ndarray, columns: dict[str, np.ndarray]) -> bytes:
    names = list(columns)
    lines = [",".join(["time", *names])]
    cols = [np.asarray(columns[n]) for n in names]
    for k, t in enumerate(time):
        lines.append(",".join([_num(float(t)), *(_num(c[k].item()) for c in cols)]))
    return ("\n".join(lines) + "\n").encode()


def _xml(root: ET.Element) -> bytes:
    ET.indent(root, space="  ")
    return ('<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n").encode()


def files(experiments: list[Experiment], title: str, identity: str) -> dict[str, bytes]:
    """The FMU members of ``experiments`` ({archive name: bytes}): manifest, experiments file,
    CSVs. ``title`` names the set (the FMU); ``identity``: what the references were made from
    (:func:`identity_of` reads it back)."""
    out: dict[str, bytes] = {}
    ET.register_namespace("fmi-ls", LS_NS)
    man = ET.Element("fmiReferences", {f"{{{LS_NS}}}fmi-ls-name": LS_NAME, f"{{{LS_NS}}}fmi-ls-version": LS_VERSION,
                                       f"{{{LS_NS}}}fmi-ls-description": LS_DESCRIPTION})
    ET.SubElement(man, "Related", type=EXPERIMENTS_TYPE, source=EXPERIMENTS, role="experiment/validation",
                  description=f"reference experiments of {title}: a user re-runs them (`latobs check FMU`) to verify "
                              "that this FMU reproduces what was certified")
    exps = ET.Element("Experiments", name=f"{title} reference experiments",
                      description="Each experiment: the FMU alone on recorded inputs, its outputs as certified. "
                                  f"How it runs: {RUN_RULE}.")
    for e in experiments:
        in_name, ref_name = f"{e.name}_in.csv", f"{e.name}_ref.csv"
        out[f"{LS_DIR}/{in_name}"] = csv_bytes(e.time, e.inputs)
        out[f"{LS_DIR}/{ref_name}"] = csv_bytes(e.time, e.outputs)
        ET.SubElement(man, "Related", type="text/csv", source=in_name, role="other",
                      description=f"inputs (stimuli) of experiment {e.name}")
        ET.SubElement(man, "Related", type="text/csv", source=ref_name, role="result",
                      description=f"reference outputs of experiment {e.name}")
        x = ET.SubElement(exps, "Experiment", name=e.name, description=e.description)
        ET.SubElement(x, "TransientSimulation", startTime=_num(e.start), stopTime=_num(e.stop), stepSize=_num(e.step))
        ET.SubElement(x, "Stimuli", type="text/csv", source=in_name)
        ET.SubElement(x, "References", type="text/csv", source=ref_name)
        ann = ET.SubElement(ET.SubElement(x, "Annotations"), "Annotation", type="latobs")
        ET.SubElement(ann, "Comparison", platform=e.platform, relativeTolerance="0", absoluteTolerance="0",
                      description="the certifying platform: bit for bit")
        other = ET.SubElement(ann, "Comparison", relativeTolerance=_num(e.relative),
                              description="any other platform: |y - y_ref| <= relativeTolerance |y_ref| + "
                                          "absoluteTolerance, absoluteTolerance per variable = relativeTolerance x "
                                          "its largest |y_ref| (a last-bit libm difference scales with the signal's "
                                          "size, also at its zero crossings); Integer outputs exactly")
        for name, a in e.absolute.items():
            ET.SubElement(other, "Variable", name=name, absoluteTolerance=_num(a))
    ann = ET.SubElement(ET.SubElement(exps, "Annotations"), "Annotation", type="latobs")
    ET.SubElement(ann, "Identity", sha256=identity)
    out[MANIFEST] = _xml(man)
    out[f"{LS_DIR}/{EXPERIMENTS}"] = _xml(exps)
    out[DOCUMENTATION] = _documentation(experiments, title).encode()
    return out


def _documentation(experiments: list[Experiment], title: str) -> str:
    """``documentation/fmi-ls-ref.txt``: what the experiments are and how to re-run them (the
    documentation FMI-LS-REF recommends beside the related files)."""
    lines = [f"Reference experiments of {title} ({LS_DIR}/)", "",
             "Each experiment runs this FMU alone on recorded inputs (NAME_in.csv) and lists its outputs "
             "(NAME_ref.csv) as certified.", f"How it runs: {RUN_RULE}.", ""]
    for e in experiments:
        lines += [f"{e.name}: {e.description}",
                  f"  {len(e.time)} rows, t = {e.start:g} .. {e.stop:g} s, step {e.step:g} s; inputs "
                  f"{', '.join(e.inputs)}; outputs {', '.join(e.outputs)}",
                  f"  certified on {e.platform}: bit for bit there; elsewhere |y - y_ref| <= {e.relative:g} |y_ref| "
                  f"+ {e.relative:g} max|y_ref| per output (Integer outputs exactly).", ""]
    lines += ["Re-run them: latobs check FMU [--platform host|all|PLATFORM] (exit 0: all pass)."]
    return "\n".join(lines) + "\n"


# --------------------------------------------------------------------------------------------
# reading
# --------------------------------------------------------------------------------------------
def _members(fmu: Path) -> dict[str, bytes]:
    try:
        with zipfile.ZipFile(fmu) as z:
            return {n: z.read(n) for n in z.namelist() if n.startswith(LS_DIR + "/")}
    except zipfile.BadZipFile as exc:
        raise ReferenceResultsError(f"{fmu}: not an FMU (not a zip archive: {exc})") from None


def _parse_xml(fmu: Path, member: str, raw: bytes) -> ET.Element:
    try:
        return ET.fromstring(raw)
    except ET.ParseError as exc:
        raise ReferenceResultsError(f"{fmu}: {member} is not well-formed XML: {exc}") from None


def _experiments_member(fmu: Path, members: dict[str, bytes]) -> str:
    if MANIFEST not in members:
        raise ReferenceResultsError(f"{fmu}: no reference results ({MANIFEST} is missing)")
    man = _parse_xml(fmu, MANIFEST, members[MANIFEST])
    if man.tag != "fmiReferences" or man.get(f"{{{LS_NS}}}fmi-ls-name") != LS_NAME:
        raise ReferenceResultsError(f"{fmu}: {MANIFEST} is not an {LS_NAME} manifest")
    for rel in man.iter("Related"):
        if (rel.get("role") or "").split("/")[0] == "experiment" and (
                rel.get("type") == EXPERIMENTS_TYPE or (rel.get("source") or "").endswith(".exp")):
            return posixpath.normpath(posixpath.join(LS_DIR, rel.get("source") or ""))
    raise ReferenceResultsError(f"{fmu}: {MANIFEST} lists no experiments file (role experiment)")


def _read_csv(fmu: Path, member: str, raw: bytes | None) -> tuple[list[str], np.ndarray]:
    if raw is None:
        raise ReferenceResultsError(f"{fmu}: {member} is missing")
    lines = [ln for ln in raw.decode("utf-8").splitlines() if ln.strip()]
    if not lines:
        raise ReferenceResultsError(f"{fmu}: {member} is empty")
    header = [h.strip() for h in lines[0].split(",")]
    if header[0] != "time" or len(set(header)) != len(header):
        raise ReferenceResultsError(f"{fmu}: {member}: the header must be time,<distinct variable names>, got {lines[0]!r}")
    try:
        rows = [[float(x) for x in ln.split(",")] for ln in lines[1:]]
    except ValueError as exc:
        raise ReferenceResultsError(f"{fmu}: {member}: {exc}") from None
    if any(len(r) != len(header) for r in rows) or not rows:
        raise ReferenceResultsError(f"{fmu}: {member}: every row needs {len(header)} values")
    return header[1:], np.array(rows)


def read(fmu: str | Path) -> list[Experiment]:
    """The reference experiments an FMU carries; ReferenceResultsError (naming the file) when it has none
    or they cannot be read."""
    fmu = Path(fmu)
    members = _members(fmu)
    exp_name = _experiments_member(fmu, members)
    if exp_name not in members:
        raise ReferenceResultsError(f"{fmu}: {exp_name} (listed in the manifest) is missing")
    root = _parse_xml(fmu, exp_name, members[exp_name])
    base = posixpath.dirname(exp_name)
    out = []
    for x in root.findall("Experiment"):
        ts = x.find("TransientSimulation")
        attrs = ts.attrib if ts is not None else x.attrib     # both draft forms
        try:
            start, stop, step = (float(attrs[a]) for a in ("startTime", "stopTime", "stepSize"))
        except (KeyError, ValueError):
            raise ReferenceResultsError(f"{fmu}: experiment {x.get('name')!r} needs startTime, stopTime and stepSize") \
                from None
        src = {}
        for tag in ("Stimuli", "References"):
            el = x.find(tag)
            src[tag] = None if el is None else posixpath.normpath(posixpath.join(base, el.get("source", "")))
        if src["References"] is None:
            raise ReferenceResultsError(f"{fmu}: experiment {x.get('name')!r} has no References")
        out_names, ref = _read_csv(fmu, src["References"], members.get(src["References"]))
        in_names, inp = (_read_csv(fmu, src["Stimuli"], members.get(src["Stimuli"])) if src["Stimuli"]
                         else ([], ref[:, :1]))
        if inp.shape[0] != ref.shape[0] or not np.array_equal(inp[:, 0], ref[:, 0]):
            raise ReferenceResultsError(f"{fmu}: experiment {x.get('name')!r}: the stimuli and references have other times")
        time = ref[:, 0]
        if not (np.all(np.diff(time) > 0) and math.isclose(time[0], start) and math.isclose(time[-1], stop)):
            raise ReferenceResultsError(f"{fmu}: experiment {x.get('name')!r}: times must increase from startTime to stopTime")
        platform, rel, absolute = "", 0.0, {}
        for ann in x.iter("Annotation"):
            if ann.get("type") != "latobs":
                continue
            for c in ann.findall("Comparison"):
                if c.get("platform"):
                    platform = c.get("platform")
                else:
                    rel = float(c.get("relativeTolerance", "0"))
                    absolute = {v.get("name"): float(v.get("absoluteTolerance", "0")) for v in c.findall("Variable")}
        absolute = {n: absolute.get(n, 0.0) for n in out_names}
        out.append(Experiment(
            name=x.get("name", ""), description=x.get("description", ""), time=time, step=step,
            inputs={n: inp[:, j + 1] for j, n in enumerate(in_names)},
            outputs={n: ref[:, j + 1] for j, n in enumerate(out_names)},
            platform=platform, relative=rel, absolute=absolute))
    if not out:
        raise ReferenceResultsError(f"{fmu}: {exp_name} holds no experiment")
    return out


def identity_of(fmu: str | Path) -> str | None:
    """The identity the FMU's reference results were made from (:func:`files`), None if none."""
    try:
        members = _members(Path(fmu))
        root = ET.fromstring(members[_experiments_member(Path(fmu), members)])
    except (OSError, KeyError, ReferenceResultsError, ET.ParseError):
        return None
    for ann in root.findall("Annotations/Annotation"):
        ident = ann.find("Identity")
        if ann.get("type") == "latobs" and ident is not None:
            return ident.get("sha256")
    return None


def code_hash(*paths: Path) -> str:
    h = hashlib.sha256()
    for p in sorted(map(Path, paths)):
        h.update(p.name.encode() + b"\0" + hashlib.sha256(p.read_bytes()).digest())
    return h.hexdigest()


# --------------------------------------------------------------------------------------------
# comparing
# --------------------------------------------------------------------------------------------
@dataclass
class Comparison:
    """The outputs of one run against an experiment's references.

    passed     every output within its tolerance (bit for bit on the certifying platform)
    exact      every output bit for bit
    worst      (variable, time s, value, reference, |deviation|, allowed) of the worst row, or None
    rule       the tolerance applied, in words
    """

    passed: bool
    exact: bool
    worst: tuple | None
    rule: str


def _bits(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.float64).view(np.int64)


def compare(e: Experiment, got: dict[str, np.ndarray], platform: str) -> Comparison:
    """``got`` (the run's outputs at ``e.time``) against the references: bit for bit on the
    certifying platform ``e.platform``, else within the experiment's tolerances."""
    certifying = platform == e.platform
    rule = (f"bit for bit (the certifying platform {e.platform})" if certifying else
            f"|y - y_ref| <= {e.relative:g} |y_ref| + {e.relative:g} max|y_ref| (certified on {e.platform})")
    exact, passed, candidates = True, True, []
    for name, ref in e.outputs.items():
        if name not in got:
            return Comparison(False, False, (name, e.start, math.nan, float(ref[0]), math.inf, 0.0),
                              f"{rule}; the run has no output {name!r}")
        y = np.asarray(got[name], dtype=np.float64)
        ref = np.asarray(ref, dtype=np.float64)
        same = _bits(y) == _bits(ref)
        exact &= bool(same.all())
        dev = np.abs(y - ref)
        dev = np.where(np.isnan(y) & np.isnan(ref), 0.0, np.where(np.isnan(dev), np.inf, dev))
        allowed = np.zeros_like(ref) if certifying else e.relative * np.abs(ref) + e.absolute.get(name, 0.0)
        bad = ~same if certifying else dev > allowed
        passed &= not bool(bad.any())
        # this variable's worst row: the largest excess over the allowed deviation, else the largest deviation
        excess = np.where(bad, np.where(allowed > 0, dev / np.where(allowed > 0, allowed, 1.0), np.inf), 0.0)
        k = int(np.lexsort((dev, excess, bad))[-1])
        candidates.append(((bool(bad[k]), float(excess[k]), float(dev[k])),
                           (name, float(e.time[k]), float(y[k]), float(ref[k]), float(dev[k]), float(allowed[k]))))
    worst = max(candidates, key=lambda c: c[0])[1] if candidates else None
    return Comparison(passed, exact, worst, rule)
