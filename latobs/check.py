"""``latobs check``: verify an FMU's seal (every member against the SHA-256 its manifest holds,
``packaging.MANIFEST_MEMBER``: a model description, design data or binary changed after the build
fails), then run its own reference experiments (FMI-LS-REF, inside the FMU) and compare its outputs
with the references (:mod:`latobs.reference`).

The host platform runs the FMU with fmpy (:func:`run_host`, the same run that made the
references at build time) in a child process of its own (:func:`run_isolated`: a binary that
crashes or hangs is a FAIL line, not the end of the command); another platform folder of the FMU
runs in the cross-platform runner (``latobs.cbackend.runner``: a small C host under Wine or qemu)
where that is available here.
"""
from __future__ import annotations

import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from . import reference

__all__ = ["CheckError", "Result", "run_host", "run_isolated", "platforms", "seal", "check"]


class CheckError(ValueError):
    """A user error of ``latobs check``: no such file, not an FMU, no reference results, an
    unknown platform or one that cannot run here (the message says why)."""


@dataclass
class Result:
    fmu: str
    experiment: str
    platform: str
    comparison: reference.Comparison
    rows: int
    outputs: int
    failure: str = ""           # the run itself failed (a call's error status, the host's crash)

    @property
    def passed(self) -> bool:
        return not self.failure and self.comparison.passed

    def line(self) -> str:
        c = self.comparison
        head = f"{'PASS' if self.passed else 'FAIL'}  {self.fmu}  {self.experiment}  {self.platform}: "
        if self.failure:
            return head + self.failure
        if self.experiment == "seal":
            return head + f"every member ({self.rows}) matches the SHA-256 of its manifest"
        if c.exact:
            return head + f"bit for bit ({self.rows} rows x {self.outputs} outputs)"
        name, t, y, ref, dev, allowed = c.worst
        return head + (f"{'within tolerance, ' if c.passed else ''}worst {name} at t = {t:.6g} s: {y!r} vs reference "
                       f"{ref!r} (deviation {dev:.3g}, allowed {allowed:.3g}; {c.rule})")


def run_host(fmu: str | Path, e: reference.Experiment) -> dict[str, np.ndarray]:
    """Run ``e`` on ``fmu`` in this process with fmpy, as :data:`reference.RUN_RULE` says: the
    outputs {name: values at e.time} (Integer outputs as integers)."""
    from .validation.harness import FmuInstance
    from .validation.instance import fmi_type

    f = FmuInstance("reference", Path(fmu))
    try:
        missing = sorted(set(e.inputs) - {v.name for v in f.inputs})
        if missing:
            raise CheckError(f"{fmu}: the reference inputs {', '.join(missing)} are not inputs of the FMU")
        n = len(e.time)
        row = lambda k: {name: float(v[k]) for name, v in e.inputs.items()}  # noqa: E731
        first = f.start(row(0), {}, start_time=e.start, stop_time=e.stop)
        out = {name: np.zeros(n, dtype=float if fmi_type(v) == "Real" else np.int64)
               for name, v in ((v.name, v) for v in f.outputs)}
        for name, val in first.items():
            out[name][0] = val
        for k in range(n - 1):
            try:
                f.set_inputs(row(k))
                f.do_step(float(e.time[k]), e.step)
                values = f.get_outputs()
            except Exception as exc:                # fmpy's error status: this run failed
                raise RuntimeError(f"at t = {e.time[k]:.6g} s: {exc}; log: {f.log_tail()}") from exc
            for name, val in values.items():
                out[name][k + 1] = val
        return out
    finally:
        f.close()


#: how long a host run of one reference experiment may take in its child process (s)
HOST_TIMEOUT = 600.0


def run_isolated(fmu: Path, e: reference.Experiment, timeout: float = HOST_TIMEOUT) -> dict[str, np.ndarray]:
    """:func:`run_host` of ``e`` in a child process (this interpreter): the outputs, or
    RuntimeError saying how the run failed: an error status, a crash (the signal that ended the
    child), no answer within ``timeout`` s."""
    import signal
    import subprocess
    import sys
    import tempfile

    with tempfile.TemporaryDirectory(prefix="latobs-check-") as tmp:
        out = Path(tmp) / "outputs.npz"
        cmd = [sys.executable, "-c", "import sys; from latobs.check import _child; sys.exit(_child(sys.argv[1:]))",
               str(Path(fmu).resolve()), e.name, str(out)]
        try:
            proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, cwd=tmp,
                                  stdin=subprocess.DEVNULL)
        except subprocess.TimeoutExpired:
            raise RuntimeError(f"no answer within {timeout:g} s (the FMU hangs)") from None
        if proc.returncode < 0:
            try:
                name = signal.Signals(-proc.returncode).name
            except ValueError:
                name = f"signal {-proc.returncode}"
            raise RuntimeError(f"the FMU crashed the host process ({name})")
        if proc.returncode != 0 or not out.is_file():
            said = [line for line in proc.stderr.splitlines() if line.strip()]
            raise RuntimeError(said[-1] if said else f"the host process exited {proc.returncode}")
        with np.load(out) as z:
            return {name: z[name] for name in z.files}


def _child(argv: list[str]) -> int:
    """The child process of :func:`run_isolated`: FMU, experiment name, output file (.npz)."""
    import sys

    fmu, name, out = argv
    e = next(x for x in reference.read(Path(fmu)) if x.name == name)
    try:
        got = run_host(fmu, e)
    except Exception as exc:              # its message, the parent's FAIL line
        print(f"{type(exc).__name__}: {exc}", file=sys.stderr)
        return 3
    np.savez(out, **got)
    return 0


def _runner():
    try:
        from .cbackend import runner
    except ImportError:
        return None
    return runner


def _vocabulary(fmu: Path) -> tuple[list[str], str | None, dict[str, str]]:
    """(the platform folders an FMU of this FMI version may hold, in order; this machine's; {folder:
    the ``toolchain.PLATFORMS`` platform whose binaries the cross-platform runner runs for it}):
    FMI 2.0's linux64, win64, ... or FMI 3.0's x86_64-linux, x86_64-windows, ..."""
    from .cbackend import fmi3
    from .cbackend.toolchain import PLATFORMS, host_platform

    from .identity import fmu_fmi_version

    if fmu_fmi_version(fmu) == 3:
        return ([f for fs in fmi3.FOLDERS.values() for f in fs], fmi3.host_folder(),
                {fs[0]: p for p, fs in fmi3.FOLDERS.items() if len(fs) == 1})
    return list(PLATFORMS), host_platform(), {p: p for p in PLATFORMS}


def _folders(fmu: Path) -> list[str]:
    """The platform folders under ``binaries/``, the FMI platforms first in their order."""
    with zipfile.ZipFile(fmu) as z:
        held = {n.split("/")[1] for n in z.namelist() if n.startswith("binaries/") and n.count("/") >= 2}
    order = _vocabulary(fmu)[0]
    return sorted(held - {""}, key=lambda p: (order.index(p) if p in order else len(order), p))


def _why_not(fmu: Path, platform: str, host: str | None) -> str | None:
    """Why ``platform`` of ``fmu`` cannot run here (None: it can)."""
    if platform == host:
        return None
    with zipfile.ZipFile(fmu) as z:
        if "resources/slavemodule.txt" in z.namelist():
            return "a pythonfmu FMU runs only where its Python runtime is (the host)"
    runner = _runner()
    if runner is None:
        return "no cross-platform runner in this installation"
    cross = _vocabulary(fmu)[2].get(platform)
    if cross is None:
        return "the cross-platform runner does not run this platform's binaries"
    return runner.available(cross)


def platforms(fmu: Path, requested: str) -> tuple[list[str], list[tuple[str, str]]]:
    """(platforms to run, [(platform, why skipped)]) for ``--platform requested``: "host", "all"
    (every platform folder of the FMU that can run here) or one platform folder. CheckError for an
    unknown platform, one the FMU does not hold, or one that cannot run here (saying why)."""
    known, host, _ = _vocabulary(fmu)
    held = _folders(fmu)
    if requested == "all":
        run, skipped = [], []
        for p in held:
            why = _why_not(fmu, p, host)
            (skipped.append((p, why)) if why else run.append(p))
        if not run:
            raise CheckError(f"{fmu}: none of its platforms ({', '.join(held) or 'none'}) can run here: "
                             + "; ".join(f"{p}: {w}" for p, w in skipped))
        return run, skipped
    p = host if requested == "host" else requested
    if p is None:
        raise CheckError("this machine is none of the FMU platforms " + ", ".join(known))
    if p not in known:
        raise CheckError(f"unknown platform {requested!r} (host, all, or one of: {', '.join(known)})")
    if p not in held:
        raise CheckError(f"{fmu} holds no binaries/{p} (it holds: {', '.join(held) or 'none'})")
    why = _why_not(fmu, p, host)
    if why:
        raise CheckError(f"{fmu}: platform {p} cannot run here: {why}")
    return [p], []


def run_on(fmu: Path, e: reference.Experiment, platform: str, host: str | None) -> dict[str, np.ndarray]:
    """The outputs of ``e`` run on ``platform``'s binary: in this process with fmpy on the host,
    else in the cross-platform runner with the experiment's fixed step. RuntimeError saying why
    when the run fails."""
    if platform == host:
        return run_isolated(fmu, e)
    runner = _runner()
    try:
        r = runner.run(fmu, _vocabulary(fmu)[2][platform], e.time, e.inputs, list(e.outputs), {}, step=e.step)
    except runner.RunnerError as exc:
        raise RuntimeError(str(exc)) from None
    if not r.ok:
        raise RuntimeError(r.failure())
    return r.outputs


def seal(fmu: str | Path) -> Result:
    """The FMU's seal against its content (``packaging.manifest_problems``): a Result whose
    experiment is "seal", failed (saying which members) when a member changed, is missing or was
    added after the build. ``latobs check`` prints it before the experiments' lines."""
    from .packaging import MANIFEST_MEMBER, manifest_problems

    fmu = Path(fmu)
    damaged = manifest_problems(fmu)
    try:
        with zipfile.ZipFile(fmu) as z:
            members = len([n for n in z.namelist() if not n.endswith("/") and n != MANIFEST_MEMBER])
    except (OSError, zipfile.BadZipFile):
        members = 0
    whole = reference.Comparison(not damaged, not damaged, None, f"every member's SHA-256 as {MANIFEST_MEMBER} holds")
    return Result(fmu.stem, "seal", "all", whole, members, 0, "; ".join(damaged))


def check(fmu: str | Path, platform: str = "host") -> tuple[list[Result], list[tuple[str, str]]]:
    """Run every reference experiment of ``fmu`` on ``platform`` ("host", "all" or a platform
    folder): the results (one per experiment and platform) and the platforms skipped (with why).
    CheckError for a user error (the message says which)."""
    fmu = Path(fmu)
    if not fmu.is_file():
        raise CheckError(f"{fmu}: no such file")
    if not zipfile.is_zipfile(fmu):
        raise CheckError(f"{fmu}: not an FMU (not a zip archive)")
    with zipfile.ZipFile(fmu) as z:
        if "modelDescription.xml" not in z.namelist():
            raise CheckError(f"{fmu}: not an FMU (no modelDescription.xml)")
    try:
        experiments = reference.read(fmu)
    except reference.ReferenceResultsError as exc:
        damaged = seal(fmu).failure
        raise CheckError(str(exc) + (f" (and its seal: {damaged})" if damaged else "")) from None
    run, skipped = platforms(fmu, platform)
    host = _vocabulary(fmu)[1]
    results = []
    for p in run:
        for e in experiments:
            try:
                got, failure = run_on(fmu, e, p, host), ""
            except RuntimeError as exc:         # the FMU or the host failed: this run fails
                got, failure = {}, f"the run failed: {' '.join(str(exc).split())}"
            results.append(Result(fmu.stem, e.name, p, reference.compare(e, got, p), len(e.time), len(e.outputs),
                                  failure))
    return results, skipped
