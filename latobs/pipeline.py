"""The whole pipeline, as the CLI and the demo run it: design -> FMU -> validation. Over ~600
lines: one function per stage and command (design, build with its artefact cache, validate,
replay, reference experiments), each calling its package; no maths here."""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

from . import catalogue
from .identity import Identity
from .synthesis import designs  # the catalogue only: it imports the solver stack when designing

#: ``--noise`` per plant (std, bias) in SI units: the sensors its observers read (``latobs.catalogue``)
PLANT_NOISE = {name: dict(catalogue.get(name).noise) for name in catalogue.PLANTS}
# Sensor noise and bias of ``latobs validate --noise`` beside CarPlant
DEFAULT_NOISE = PLANT_NOISE["CarPlant"]


class PipelineError(RuntimeError):
    pass


def solve(name: str, vehicle: str | None, quiet: bool = False, runtime_facts: bool = True, **overrides) -> dict:
    """Design and certify (``designs.run``, with design-option ``overrides``) through the cache
    (``latobs.cache``: solved once per inputs); prints the headline figures. ``runtime_facts``:
    completed with what only running its runtime decides (``packaging.complete_runtime_data``, as
    ``latobs design`` writes it); False: the design as ``designs.run`` made it."""
    import json

    from . import cache, identity
    from .packaging import complete_runtime_data
    from .synthesis import certificate, design_file

    # solved once per design inputs, design-time code and solver versions (latobs.cache): a cached
    # design is what designs.run returned, as its design file holds it (certified again when packaged)
    ident = identity.of_design(name, vehicle, overrides)
    solved = []

    def compute() -> dict:
        solved.append(True)
        return json.loads(design_file.dumps(designs.run(name, vehicle, **overrides)))

    data = cache.remember("design", _design_cache_parts(ident), compute)
    if runtime_facts:
        data = complete_runtime_data(data)
    if not quiet and not solved:
        print(f"{data['name']}: the cached design of identical inputs (latobs.cache), not solved again")
    if not quiet:
        s = certificate.summary(data)    # its keys depend on the paper: print those present
        extra = "".join(f", {label} = {s[key]:{fmt}}" for key, label, fmt in
                        (("cond_P", "cond(P)", ".3g"), ("iss_gain", "ISS gain", ".4g"))
                        if isinstance(s.get(key), (int, float)))
        print(f"{data['name']}: certified ({len(data['checks'])} checks), gamma = {s['gamma']:.4g}{extra}, "
              f"{data['solver']['name']} {data['solver']['status']} in {data['solver']['seconds']:.2f} s")
        for m in s["per_mode"]:
            at = (f"{m['speed_kmh']:5.1f} km/h" if "speed_kmh" in m else
                  f"{m['speed_ms']:5.2f} m/s" if isinstance(m.get("speed_ms"), (int, float)) else
                  f"{m['vx_band'][0]:.4g}-{m['vx_band'][1]:.4g} m/s" if "vx_band" in m else "")
            parts = [f"{label} {m[key]:{fmt}}" for key, label, fmt in
                     (("hinf", "H-inf bank->beta error", ".4g"), ("slowest_bank_pole", "slowest bank pole", ".3f"),
                      ("slowest_pole", "slowest pole", ".3f"), ("largest_gain", "largest gain", ".4g"),
                      ("gamma_lmi", "LMI gamma", ".4g"), ("gamma_vertex", "certified vertex worst case", ".4g"),
                      ("gamma_grid", "certified grid worst case", ".4g"))
                     if isinstance(m.get(key), (int, float)) and not (key == "slowest_pole" and "slowest_bank_pole" in m)]
            print(f"  mode {m['mode']}{' @ ' + at if at else ''}: {', '.join(parts)}")
    return data


def design_one(name: str, vehicle: str | None, out: Path, quiet: bool = False) -> Path:
    """Design, certify and write ``out/NAME[_V].design.json``; prints the headline figures."""
    from .synthesis import design_file

    data = solve(name, vehicle, quiet)
    path = design_file.write(data, out)
    if not quiet:
        print(f"wrote {path}")
    return path


BACKEND_LABEL = {"c": "native C", "python": "pythonfmu"}


@dataclass
class _Artefact:
    """One FMU of a build, planned before anything is solved or written."""
    model: str                  # catalogue design or plant
    name: str                   # the FMU's name (NAME or NAME_V)
    vehicle: object             # as given (a set's name, a TOML path, None), for the solver
    base: Identity              # identity of its design or plant data
    backend: str                # "c" or "python"
    why: str | None             # why "auto" fell back to pythonfmu
    fmu: Path
    platforms: list[str] | None = None   # native FMUs: the platform folders it holds binaries for
    reference: str = ""         # identity of its reference results (:func:`reference_identity`)
    fmi: int = 2                # the FMI version (3: native only)

    @property
    def design_path(self) -> Path | None:
        return self.fmu.with_name(f"{self.name}.design.json") if self.model in designs.DESIGNS else None

    def current(self, design_file_needed: bool = True) -> tuple[bool, str]:
        """(True, "") if the FMU (and the design file beside it) is what this build would make,
        else (False, what to say). A design file beside an observer FMU that is not the design
        inside it is never current; a missing one only when ``design_file_needed``."""
        from . import identity

        if not self.fmu.is_file():
            return False, f"building {self.fmu.name}"
        expected = identity.of_fmu(self.base, self.backend, self.platforms, self.fmi)
        found = identity.read_fmu(self.fmu)
        if found is None or found.sha256 != expected.sha256:
            return False, f"rebuilding {self.fmu.name}: {expected.changes(found)}"
        from . import reference

        if reference.identity_of(self.fmu) != self.reference:
            return False, (f"rebuilding {self.fmu.name}: its reference results are missing or were made from another "
                           "plant, scenario or code")
        damaged = _manifest_problems(str(self.fmu), _file_key(self.fmu))
        if damaged:
            return False, f"rebuilding {self.fmu.name}: it is not what was built ({damaged[0]})"
        if self.design_path is not None and (design_file_needed or self.design_path.exists()):
            try:
                same = _design_inside(str(self.fmu), _file_key(self.fmu), str(self.design_path),
                                      _file_key(self.design_path), self.name)
            except OSError:
                same = False
            if not same:
                return False, (f"rebuilding {self.fmu.name}: {self.design_path.name} beside it is missing or is not "
                               "the design inside it")
        return True, ""


def _file_key(path: Path) -> tuple[int, int, int]:
    """(inode, size, modification time in ns) of a file: a file rewritten (as latobs writes them,
    atomically: a new inode) or changed in place has another key. OSError if it is missing."""
    st = path.stat()
    return st.st_ino, st.st_size, st.st_mtime_ns


@lru_cache(maxsize=256)
def _manifest_problems(fmu: str, fmu_key: tuple) -> tuple[str, ...]:
    """``packaging.manifest_problems`` of an FMU, once per version of the file (:func:`_file_key`)."""
    from .packaging import manifest_problems

    return tuple(manifest_problems(Path(fmu)))


@lru_cache(maxsize=256)
def _design_inside(fmu: str, fmu_key: tuple, design: str, design_key: tuple, name: str) -> bool:
    """Whether the design file ``design`` is the design inside the FMU ``fmu`` (its reproducible
    part), once per version of the two files (the keys of :func:`_file_key`) in a process: a design
    file is large and the commands check the same FMUs many times."""
    import json
    import zipfile

    from .synthesis import design_file

    try:
        with zipfile.ZipFile(fmu) as z:
            inner = json.loads(z.read(f"resources/{name}.design.json"))
        beside = json.loads(Path(design).read_text(encoding="utf-8"))
    except (OSError, KeyError, ValueError, zipfile.BadZipFile):
        return False
    return design_file.seal_state(beside) == "sealed" and design_file.reproducible(beside) == inner


def _plan(names: list[str], vehicle, out: Path, backend: str, platforms: list[str] | None = None,
          host_suffices: bool = False, fmi: int = 2) -> list[_Artefact]:
    """The artefacts of a build: names checked, identities known, backends and platforms chosen.
    "auto" keeps the backend of an FMU already in ``out`` (when it can be built here); an explicit
    backend that differs from an existing FMU's is refused (a folder never mixes two backends' FMUs
    of one name unnoticed): PipelineError before anything is written. Native FMUs are planned for
    ``platforms`` (None: all), or with ``host_suffices`` for the platforms of the native FMU already
    in ``out`` when they include this machine's."""
    from . import cbackend, identity, packaging
    from .cbackend import toolchain
    from .synthesis.params import load_vehicle

    plans, conflicts = [], []
    veh = load_vehicle(vehicle) if vehicle is not None else None
    for name in names:
        kind = packaging.OBSERVERS.get(name) or packaging.PLANTS[name]
        if name in designs.DESIGNS:
            base = identity.of_design(name, veh)
            artefact = base.parts["artefact"]
        else:
            _, _, artefact, base = packaging.plant_artefact(name, veh)
        fmu = out / f"{artefact}.fmu"
        existing = identity.fmu_backend(fmu) if fmu.is_file() else None
        if existing is not None and backend != "auto" and existing != backend:
            conflicts.append(f"{fmu} is a {BACKEND_LABEL[existing]} FMU")
        if backend == "auto" and existing is not None and (
                existing == "python" or cbackend.unavailable_reason(kind.model_module, platforms) is None):
            chosen, why = existing, None
        else:
            chosen, why = packaging.resolve_backend(backend, kind, platforms)
        planned = None
        if chosen == "c":
            planned = cbackend.platforms_of(platforms)
            held = _platforms_held(fmu) if host_suffices and existing == "c" else None
            if held and toolchain.host_platform() in held:
                planned = held
        if fmi != 2 and chosen != "c":
            raise PipelineError(f"{name}: FMI {fmi}.0 FMUs are native (the C backend), and "
                                + (why or "the pythonfmu backend was asked for") + " (pythonfmu makes FMI 2.0 FMUs only)")
        plans.append(_Artefact(name, artefact, vehicle, base, chosen, why, fmu, planned,
                               reference_identity(name, vehicle, chosen, fmi), fmi))
    if conflicts:
        raise PipelineError(f"{'; '.join(conflicts)}: refusing to replace {'it' if len(conflicts) == 1 else 'them'} "
                            f"with {BACKEND_LABEL[backend]} FMUs of the same name; build into another --out "
                            "(one folder per backend), or delete the FMU(s) first")
    return plans


def _platforms_held(fmu: Path) -> list[str] | None:
    """The platforms of a native FMU's identity (None: it carries none)."""
    from . import identity

    found = identity.read_fmu(fmu)
    held = found.parts.get("platforms") if found is not None else None
    return held.split(",") if isinstance(held, str) and held else None


def current(name: str, vehicle: str | None, out: Path, backend: str = "auto",
            platforms: list[str] | None = None, host_suffices: bool = False, fmi: int = 2) -> bool:
    """Whether ``out`` (for FMI 3.0: ``out/fmi3``) holds the FMU ``name`` (catalogue design or
    plant) for ``vehicle`` as :func:`build` would make it now (and would reuse it)."""
    plan = _plan([name], vehicle, fmi_folder(Path(out), fmi), backend, platforms, host_suffices, fmi)[0]
    return plan.current(design_file_needed=False)[0]


#: where the FMUs of each FMI version go in a build's ``out``: FMI 2.0 in ``out`` itself, FMI 3.0 in
#: ``out/fmi3`` (the same names: an FMI 3.0 FMU never overwrites its FMI 2.0 twin)
FMI_FOLDER = {2: "", 3: "fmi3"}


def fmi_folder(out: Path, fmi: int) -> Path:
    """The folder of ``out`` holding the FMI ``fmi`` FMUs (:data:`FMI_FOLDER`)."""
    if fmi not in FMI_FOLDER:
        raise PipelineError(f"unknown FMI version {fmi!r} (known: {', '.join(map(str, FMI_FOLDER))})")
    return Path(out) / FMI_FOLDER[fmi] if FMI_FOLDER[fmi] else Path(out)


def build(names: list[str] | None, vehicle: str | None, out: Path, backend: str = "auto",
          design_files: bool = True, platforms: list[str] | None = None, host_suffices: bool = False,
          fmi: int | list[int] = 2) -> list[Path]:
    """Design + package the named FMUs (default: every observer and plant) with ``backend``:
    "c" (native, ``latobs.cbackend``), "python" (pythonfmu) or "auto" (the backend of the FMU
    already there, else C where a C compiler is present and the runtime has a C model, else
    pythonfmu, saying why). Native FMUs hold binaries for ``platforms`` (FMI platform folders of
    ``latobs.cbackend.toolchain.PLATFORMS``; None: all); with ``host_suffices`` (the commands that
    only run the FMUs here) a native FMU already in ``out`` holding this machine's platform is
    reused (if otherwise current) whatever its other platforms. Platforms are refused with the
    pythonfmu backend (its binaries are pythonfmu's).

    An FMU already in ``out`` is reused only when it carries the identity of what would be built
    now (``latobs.identity``: design or plant inputs, backend, code, toolchain) and, for an
    observer, its design file beside it is the design inside it (or, without ``design_files``,
    is absent: an FMU carries its design); otherwise it is rebuilt, saying what changed. A
    design file whose identity matches is packaged without solving again. The folder is locked
    while anything is written (``latobs.atomic.locked_folder``); each design file and its FMU
    are written as one unit (``latobs.packaging.install``).

    ``fmi``: the FMI version(s) to build, 2 (default) and/or 3 (native only: "auto" is the C
    backend then, "python" is refused): the FMI 3.0 FMUs and their design files go to ``out/fmi3``
    (:func:`fmi_folder`), each made and reused as above; returns the FMI 2.0 FMUs, then the FMI 3.0
    ones."""
    versions = sorted(set([fmi] if isinstance(fmi, int) else fmi))
    if not versions or any(v not in FMI_FOLDER for v in versions):
        raise PipelineError(f"unknown FMI version(s) {fmi!r} (known: {', '.join(map(str, FMI_FOLDER))})")
    if 3 in versions and backend == "python":
        raise PipelineError("FMI 3.0 FMUs are native (--backend c): pythonfmu makes FMI 2.0 FMUs only")
    out = Path(out)
    built = []
    for v in versions:
        built += _build(names, vehicle, fmi_folder(out, v), backend if v == 2 else "c", design_files, platforms,
                        host_suffices, v)
    return built


def _build(names: list[str] | None, vehicle: str | None, out: Path, backend: str, design_files: bool,
           platforms: list[str] | None, host_suffices: bool, fmi: int,
           reference_plants: Path | None = None) -> list[Path]:
    """:func:`build` of one FMI version into ``out`` (``reference_plants``: the folder shared by
    the parallel workers for the plants of the reference runs, :class:`_ReferencePlants`)."""
    from . import packaging
    from .atomic import locked_folder
    from .cbackend.fmi3 import folders as fmi3_folders

    if backend not in ("auto", *packaging.BACKENDS):
        raise PipelineError(f"unknown backend {backend!r}; known: auto, {', '.join(packaging.BACKENDS)}")
    names = names or [*designs.DESIGNS, *packaging.PLANTS]
    unknown = [n for n in names if n not in designs.DESIGNS and n not in packaging.PLANTS]
    if unknown:
        raise PipelineError(f"unknown FMU(s) {', '.join(unknown)}; known: "
                            f"{', '.join([*designs.DESIGNS, *packaging.PLANTS])}")
    if platforms is not None:
        from . import cbackend

        if backend == "python":
            raise PipelineError("platforms are chosen for native FMUs only: the pythonfmu backend ships "
                                "pythonfmu's binaries")
        try:
            platforms = cbackend.platforms_of(platforms)
        except cbackend.NativeBuildError as exc:
            raise PipelineError(str(exc)) from exc
    out = Path(out)
    plans = _plan(names, vehicle, out, backend, platforms, host_suffices, fmi)
    if all(p.current(design_files)[0] for p in plans):       # nothing to write: no lock to wait for
        for p in plans:
            print(f"reusing {p.fmu.name} (identical inputs)")
        return [p.fmu for p in plans]
    _refuse_edited(plans)                                     # before anything is made or written
    built = {}
    with locked_folder(out, "build"), _ReferencePlants(out, reference_plants) as plants:
        plans = _plan(names, vehicle, out, backend, platforms, host_suffices, fmi)   # again: another build may have written
        _refuse_edited(plans)
        made = _make_in_parallel(plans, design_files)
        # plants first: an observer's reference experiment runs beside the plant built here
        for p in sorted(plans, key=lambda p: p.design_path is not None):
            ok, what = p.current(design_files)
            if ok and p.name in made:
                built[p.name] = p.fmu
                continue
            if ok:
                print(f"reusing {p.fmu.name} (identical inputs)")
                built[p.name] = p.fmu
                continue
            if p.why:
                print(f"{p.name}: pythonfmu backend ({p.why})")
            print(what)
            # an observer's FMU is keyed by its design's content too: known before the cache is read
            data = None if p.design_path is None else (_current_design(p) or solve(p.model, p.vehicle))
            if _from_cache(p, data):
                print(f"installed {p.fmu} from the cache (identical inputs)")
                built[p.name] = p.fmu
                continue
            if data is None:
                path = package_plant(p.model, p.vehicle, out, p.backend, plants, platforms=p.platforms, fmi=fmi)
            else:
                path = package_design_data(data, out, p.backend, p.vehicle, write_design=True,
                                           origin=str(p.design_path), plants=plants, platforms=p.platforms, fmi=fmi)
            _to_cache(p, data)
            folders = (p.platforms if fmi == 2 else fmi3_folders(p.platforms)) if p.platforms else []
            print(f"built {path} ({BACKEND_LABEL[p.backend]}{', FMI 3.0' if fmi == 3 else ''}"
                  f"{': ' + ', '.join(folders) if folders else ''})")
            built[p.name] = path
    return [built[p.name] for p in plans]


def build_seconds(model: str) -> float:
    """The catalogue's estimate of a design's or plant's cold build (``Entry.build_seconds``, its
    FMU for any vehicle; 10 s for a name it does not hold): the parallel builds start the longest
    first, so that the longest one does not start last."""
    from . import catalogue

    try:
        return catalogue.get(model).build_seconds
    except KeyError:
        return catalogue.Entry.build_seconds


def _make_in_parallel(plans: list[_Artefact], design_files: bool) -> set[str]:
    """Make the FMUs of ``plans`` (those not current, and not in the cache) at once in parallel
    processes (``lmi.parallel_map``: bounded by the cores and ``$LATOBS_JOBS``) when there are two
    or more: each worker builds one FMU, designed and packaged exactly as this process would, into
    a scratch folder of its own; each result is installed here (under this folder's lock, as one
    unit, the FMU last: :func:`_install`) and kept only if current. Returns the names installed;
    one that failed is left to the build's own sequential step, which reports the failure. The
    plants of the observers' reference runs are built once, in a folder the workers share."""
    import os
    import tempfile

    from . import cache
    from .synthesis import lmi

    remove_stale_folders()
    states = {p.name: p.current(design_files) for p in plans}
    todo = [p for p in plans if not states[p.name][0] and not _in_cache(p)]
    todo.sort(key=lambda p: -build_seconds(p.model))        # the longest first (a stable sort)
    n = lmi.jobs(len(todo))
    if len(todo) < 2 or n < 2:
        return set()
    for p in todo:
        print(states[p.name][1])                           # building / rebuilding, saying what changed
    print(f"making {len(todo)} FMUs in {n} processes", flush=True)
    made = set()
    # the workers' reference plants; removed on every exit of this block (an error, Ctrl-C, SIGTERM:
    # lmi.parallel_map), and by the next build when this process was killed (its PID in the name)
    with tempfile.TemporaryDirectory(prefix=f"{TEMP_PREFIX}reference-{os.getpid()}-") as shared:
        items = [(p.model, p.vehicle, p.backend, p.platforms, p.fmi, shared) for p in todo]
        for p, (printed, scratch, files) in zip(todo, lmi.parallel_map(_make_worker, items)):
            if files is not None and _install(p, files):
                # what the worker's build said, of this folder
                lines = [line.replace(scratch, str(p.fmu.parent)) for line in printed.splitlines()
                         if line != f"building {p.fmu.name}"]
                print("\n".join(lines), flush=True)
                made.add(p.name)
    return made


#: the temporary folders of the parallel build: TEMP_PREFIX + "reference-" or "part-", the PID of
#: the process that made it, "-", tempfile's random suffix
TEMP_PREFIX = "latobs-"
_TEMP_RE = r"latobs-(?:reference|part|c)-(?:(\d+)-)?[A-Za-z0-9_]+"    # (latobs-c-*: a compilation's, no PID)
#: a temporary folder of the parallel build without a PID in its name (made by an older latobs) is
#: stale after this long, s
STALE_S = 24 * 3600.0


def remove_stale_folders(where: str | Path | None = None) -> list[Path]:
    """Remove the parallel build's temporary folders (``latobs-reference-PID-*``,
    ``latobs-part-PID-*`` in the temporary folder) left by a process that no longer runs (killed:
    no ``finally`` ran), and those without a PID in the name (an older latobs's; a compilation's
    ``latobs-c-*``, whose thread a killed process took with it) older than :data:`STALE_S`;
    returns those removed. A folder of a running process is kept."""
    import os
    import re
    import shutil
    import tempfile
    import time

    root = Path(where or tempfile.gettempdir())
    removed = []
    try:
        entries = list(root.iterdir())
    except OSError:
        return removed
    for d in entries:
        m = re.fullmatch(_TEMP_RE, d.name)
        if m is None or not d.is_dir() or d.is_symlink():
            continue
        try:
            if m.group(1) is not None:
                pid = int(m.group(1))
                if pid == os.getpid() or _alive(pid):
                    continue
            elif time.time() - d.stat().st_mtime < STALE_S:
                continue
            if d.stat().st_uid != os.getuid():
                continue
        except OSError:
            continue
        shutil.rmtree(d, ignore_errors=True)
        removed.append(d)
    return removed


def _alive(pid: int) -> bool:
    """Whether process ``pid`` exists (another user's counts as alive)."""
    import os

    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError):
        return True
    return True


def _make_worker(item: tuple) -> tuple[str, str, dict[str, bytes] | None]:
    """One FMU of :func:`_make_in_parallel` in a worker: (what its build printed, the folder it
    built in, {file name: bytes} of the FMU and its design file, or None when the build failed)."""
    import contextlib
    import io
    import shutil
    import tempfile

    model, vehicle, backend, platforms, fmi, shared = item
    import os

    from .synthesis import lmi

    # the build's processes already use the cores: this one's design runs its own parallel parts
    # (paper 002's speed bands) in itself, not in processes of its own (each would import the
    # solver stack again; the results are those of the parallel map, tested)
    os.environ[lmi.JOBS_ENV] = "1"
    scratch = Path(tempfile.mkdtemp(prefix=f"{TEMP_PREFIX}part-{os.getpid()}-"))   # (remove_stale_folders)
    out = fmi_folder(scratch, fmi)
    buf = io.StringIO()
    try:
        with contextlib.redirect_stdout(buf):
            path, = _build([model], vehicle, out, backend, True, platforms, False, fmi, Path(shared))
        design = path.with_name(f"{path.stem}.design.json")
        return buf.getvalue(), str(out), {f.name: f.read_bytes() for f in (design, path) if f.is_file()}
    except Exception:                              # (reported by the build's own sequential step)
        return "", str(out), None
    finally:
        shutil.rmtree(scratch, ignore_errors=True)


def _install(p: _Artefact, found: dict[str, bytes]) -> bool:
    """Install ``found`` ({file name: bytes}: ``p``'s FMU and design file) into ``p``'s folder (the
    caller holds its lock) as one unit, the FMU last; True if ``p`` is then current."""
    from .atomic import atomic_paths

    paths = _cache_files(p)
    if sorted(found) != sorted(q.name for q in paths):
        return False
    with atomic_paths(paths) as tmps:
        for tmp, path in zip(tmps, paths):
            tmp.write_bytes(found[path.name])
    return p.current(True)[0]


def _design_cache_parts(ident: Identity) -> dict:
    """What a cached design is made from: its identity (inputs and design-time code) and the
    versions of the solver stack."""
    from . import cache

    return {"identity": ident.sha256, "solvers": cache.solver_versions()}


def _cache_parts(p: _Artefact, design: dict | None) -> dict:
    """What an FMU of the cache is made from: its identity (design or plant inputs, backend, code,
    toolchain, platforms, FMI version), that of its reference results, and an observer's
    ``design`` content (every figure the FMU is made from, not only the inputs the design was
    solved from: ``design_file.reproducible`` without its runtime tables, which are computed from
    it by code its identity holds)."""
    from . import identity
    from .synthesis import design_file, tables

    parts = {"fmu": identity.of_fmu(p.base, p.backend, p.platforms, p.fmi).sha256, "reference": p.reference,
             "name": p.name}
    if design is not None:
        parts["design"] = identity.sha256_json(
            design_file.reproducible({k: v for k, v in design.items() if k != tables.TABLES_KEY}))
    return parts


def _cache_files(p: _Artefact) -> list[Path]:
    return [*([p.design_path] if p.design_path is not None else []), p.fmu]


def _in_cache(p: _Artefact) -> bool:
    """Whether the cache holds ``p``'s FMU, as far as can be told without solving: a plant's by its
    identity; an observer's when its design is known (the sealed design file of the same inputs
    beside it, or the cached design of its inputs) and the FMU of that design content is held."""
    from . import cache

    if p.design_path is None:
        return cache.files("fmu", _cache_parts(p, None)) is not None
    design = _current_design(p, quiet=True)
    if design is None and cache.peek("design", _design_cache_parts(p.base)) is not None:
        design = solve(p.model, p.vehicle, quiet=True)   # the cached design, completed as a build completes it
    return design is not None and cache.files("fmu", _cache_parts(p, design)) is not None


def _from_cache(p: _Artefact, design: dict | None) -> bool:
    """Install ``p``'s FMU (and its design file) made from ``design`` (None: a plant) from the
    cache (under the folder's lock, as one unit, the FMU last); True if it is then current, else (a
    miss, or an entry that is not what its key says) False and the caller builds it."""
    from . import cache

    found = cache.files("fmu", _cache_parts(p, design))
    return found is not None and _install(p, found)


def _to_cache(p: _Artefact, design: dict | None) -> None:
    """Store the FMU just built for ``p`` from ``design`` (and its design file) in the cache."""
    from . import cache

    if not cache.enabled() or not p.current(True)[0]:
        return
    try:
        content = {path.name: path.read_bytes() for path in _cache_files(p)}
    except OSError:
        return
    cache.store_files("fmu", _cache_parts(p, design), content)


#: The reference experiment an FMU carries: the first ``seconds`` of its own validation
#: ``scenario``, with the scenario fields ``overrides`` (``note`` says why).
ReferenceSpec = catalogue.Reference
#: Each FMU's reference experiment (``latobs check``, from ``latobs.catalogue``): its own validation
#: scenario, two seconds at the FMU's default step. An observer's inputs are its plant's signals in
#: that scenario (the plant of the same backend, for the observer's vehicle; for the plant's default
#: vehicle when the plant cannot be built for it, e.g. a vehicle without roll data); a plant's are
#: the scenario's.
REFERENCE_EXPERIMENTS = {e.name: e.reference for e in catalogue.ENTRIES}


def _reference_spec(model: str) -> ReferenceSpec:
    spec = REFERENCE_EXPERIMENTS.get(model)
    if spec is None:
        raise PipelineError(f"{model}: no reference experiment (latobs.pipeline.REFERENCE_EXPERIMENTS)")
    return spec


def reference_plant(model: str, vehicle) -> tuple[str, object] | None:
    """(plant, its vehicle as given to :func:`build`) beside which the observer ``model`` for
    ``vehicle`` (None: its default) runs its reference experiment; None for a plant."""
    from importlib import import_module

    from . import fmu_src, packaging
    from .synthesis.params import load_vehicle

    if model not in designs.DESIGNS:
        return None
    plant = designs.DESIGNS[model].plant
    kind = packaging.PLANTS[plant]
    given = vehicle or designs.DESIGNS[model].default_vehicle
    veh = load_vehicle(given)
    if veh.name == kind.default_vehicle:
        return plant, None
    spec = import_module(f"{fmu_src.__name__}.models.{kind.model_module}").SPEC
    try:
        spec.runtime(packaging.plant_data(veh), {})
    except (ValueError, KeyError, TypeError):
        return plant, None            # e.g. a vehicle without the plant's roll data
    return plant, given


def reference_identity(model: str, vehicle, backend: str, fmi: int = 2) -> str:
    """What the reference results of ``model``'s FMU for ``vehicle`` are made from besides the FMU
    itself: the experiment, the plant FMU's identity (observers: the plant of the same FMI
    version) and the code that runs them."""
    from . import check, identity, packaging, reference
    from .cbackend.toolchain import host_platform
    from .validation import harness, scenarios

    beside = reference_plant(model, vehicle)
    plant = None
    if beside is not None:            # the plant's binary that runs here
        _, _, _, base = packaging.plant_artefact(*beside)
        plant = identity.of_fmu(base, backend, [host_platform()] if backend == "c" else None, fmi).sha256
    code = reference.code_hash(*(Path(m.__file__) for m in (check, reference, harness, scenarios)))
    return identity.sha256_json({"experiment": _reference_spec(model), "plant": plant, "code": code})


class _ReferencePlants:
    """The plant FMUs of one build's reference runs: the one in ``out`` when it is current, else
    built once into a scratch folder (removed at the end), or into ``shared``: a folder the parallel
    workers of one build share (its owner removes it), where each plant is built once under the
    folder's lock and reused by the other workers (``build`` reuses a current FMU)."""

    def __init__(self, out: Path, shared: Path | None = None):
        self.out = Path(out)
        self.shared = None if shared is None else Path(shared)
        self._tmp = None
        self._made: dict[tuple, Path] = {}

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        if self._tmp is not None:
            self._tmp.cleanup()

    def get(self, plant: str, vehicle, backend: str, fmi: int = 2) -> Path:
        import contextlib
        import io
        import tempfile

        from .cbackend.toolchain import host_platform

        key = (plant, str(vehicle), backend, fmi)
        if key not in self._made:
            try:                          # any platforms, so long as this machine's is among them
                p, = _plan([plant], vehicle, self.out, backend, host_suffices=True, fmi=fmi)
                here = p.current(design_file_needed=False)[0]
            except PipelineError:         # e.g. an FMU of the other backend there
                here = False
            if here:
                self._made[key] = p.fmu
            else:
                if self.shared is not None:
                    where = self.shared
                else:
                    if self._tmp is None:
                        self._tmp = tempfile.TemporaryDirectory(prefix="latobs-reference-")
                    where = Path(self._tmp.name)
                host = [host_platform()] if backend == "c" else None    # the reference runs here
                buf = io.StringIO()
                with contextlib.redirect_stdout(buf):
                    self._made[key], = build([plant], vehicle, where / backend, backend,
                                             design_files=False, platforms=host, fmi=fmi)
                if not buf.getvalue().startswith("reusing"):
                    print(f"{plant}: built for the observers' reference experiments")
        return self._made[key]


def reference_finish(model: str, vehicle, backend: str, ident: str, plants: _ReferencePlants, fmi: int = 2):
    """``finish`` of ``packaging.install`` for ``model``'s FMU: runs the sealed FMU on its
    reference experiment (:data:`REFERENCE_EXPERIMENTS`) and returns its FMI-LS-REF members; an
    observer beside the plant FMU of its own FMI version ``fmi``."""

    def finish(fmu: Path) -> dict[str, bytes]:
        from fmpy import read_model_description

        from . import packaging, reference
        from .cbackend.fmi3 import host_folder
        from .cbackend.toolchain import host_platform
        from .check import run_host
        from .synthesis.params import load_vehicle
        from .validation import get_scenario
        from .validation.harness import run as cosimulate

        spec = _reference_spec(model)
        h = float(read_model_description(str(fmu)).defaultExperiment.stepSize)
        sc = get_scenario(spec.scenario, duration=spec.seconds, **dict(spec.overrides))
        beside = reference_plant(model, vehicle)
        if beside is None:                # a plant: the scenario's driver inputs
            veh = load_vehicle(vehicle or packaging.PLANTS[model].default_vehicle)
            t = sc.time_grid(h)
            signals = sc.sampled(t, veh)
            names = [v.name for v in read_model_description(str(fmu)).modelVariables if v.causality == "input"]
            inputs = {n: signals[n] for n in names if n in signals}
            source = f"the scenario's inputs (vehicle {veh.name})"
        else:                             # an observer: its plant's signals in the scenario
            plant, pveh = beside
            veh = load_vehicle(pveh or packaging.PLANTS[plant].default_vehicle)
            run = cosimulate(sc, plants.get(plant, pveh, backend, fmi), {"observer": fmu}, dt=h, vehicle=veh)
            t = run.time
            inputs = {n: run.measured[n] for n in run.inputs["observer"]}
            source = f"the signals of {plant} (vehicle {veh.name}) at the communication points"
        what = (f"scenario {spec.scenario}, first {spec.seconds:g} s" + (f" ({spec.note})" if spec.note else "")
                + f": inputs {source}; outputs this FMU's own, on them.")
        host = (host_platform() if fmi == 2 else host_folder()) or ""
        probe = reference.Experiment(spec.scenario, what, t, h, inputs, {}, host)
        outputs = run_host(fmu, probe)
        e = reference.Experiment(spec.scenario, what, t, h, inputs, outputs, host)
        return reference.files([e], model_identifier(fmu), ident)

    return finish


def package_design_data(data: dict, out: Path, backend: str, vehicle=None, write_design: bool = False,
                        origin: str | None = None, plants: _ReferencePlants | None = None,
                        platforms: list[str] | None = None, fmi: int = 2) -> Path:
    """``packaging.package_design_data`` with the FMU's reference experiment inside it (the
    observer designed for ``vehicle``, None: its default); the plant it runs beside comes from
    ``plants`` (default: ``out`` if current there, else built into a scratch folder)."""
    from contextlib import nullcontext

    from . import packaging

    model = data.get("design", "")
    if model not in designs.DESIGNS:
        raise PipelineError(f"{origin or data.get('name')}: no catalogue design {model!r} (known: "
                            f"{', '.join(designs.DESIGNS)})")
    with nullcontext(plants) if plants else _ReferencePlants(out) as pl:
        finish = reference_finish(model, vehicle, backend, reference_identity(model, vehicle, backend, fmi), pl, fmi)
        return packaging.package_design_data(data, out, backend, write_design=write_design, origin=origin,
                                             platforms=platforms, finish=finish, fmi=fmi)


def package_plant(name: str, vehicle, out: Path, backend: str, plants: _ReferencePlants | None = None,
                  platforms: list[str] | None = None, fmi: int = 2) -> Path:
    """``packaging.package_plant`` with the FMU's reference experiment inside it."""
    from contextlib import nullcontext

    from . import packaging

    with nullcontext(plants) if plants else _ReferencePlants(out) as pl:
        finish = reference_finish(name, vehicle, backend, reference_identity(name, vehicle, backend, fmi), pl, fmi)
        return packaging.package_plant(name, vehicle, out, backend, platforms=platforms, finish=finish, fmi=fmi)


def model_identifier(path: Path) -> str:
    """The modelIdentifier of a (temporary) FMU file."""
    from fmpy import read_model_description

    return read_model_description(str(path)).coSimulation.modelIdentifier


def _design_paths(p: _Artefact) -> list[Path]:
    """Where a design file of ``p`` may stand: beside its FMU; for an FMI 3.0 FMU also beside its
    FMI 2.0 twin (the same design either way)."""
    return [p.design_path, *([p.fmu.parent.parent / p.design_path.name] if p.fmi != 2 else [])]


def _refuse_edited(plans: list[_Artefact]) -> None:
    """PipelineError if a design file a build would read or replace was edited by hand (its content
    does not match its seal, ``design_file.seal_state``): it is neither packaged nor silently
    overwritten, and nothing is stored in the cache from it."""
    from .synthesis import design_file

    for p in plans:
        for path in (_design_paths(p) if p.design_path is not None else []):
            try:
                data = design_file.read(path)
            except ValueError:
                continue                                  # missing or not a design file: made anew
            if design_file.seal_state(data) == "broken":
                raise PipelineError(design_file.edited_message(path))


def _current_design(p: _Artefact, quiet: bool = False) -> dict | None:
    """The design file beside ``p``'s FMU (:func:`_design_paths`) if it was made from the same
    inputs, certified and sealed (not solved again); PipelineError if it names the same inputs
    but its content is not what latobs wrote (:func:`_refuse_edited`)."""
    from .synthesis import design_file

    for path in _design_paths(p):
        try:
            data = design_file.read(path)
        except ValueError:
            continue
        if (data.get("identity") or {}).get("sha256") != p.base.sha256 or not data.get("certified"):
            continue
        if design_file.seal_state(data) != "sealed":      # the same inputs named, another content
            raise PipelineError(design_file.edited_message(path))
        if not quiet:
            print(f"{p.name}: {path} was made from the same inputs: packaged without solving again")
        return data
    return None


#: ``schema`` of :func:`build_summary`'s document (``latobs build --json``).
BUILD_SUMMARY_SCHEMA = "latobs.build-summary/1"


def build_summary(fmus: list[Path]) -> dict:
    """The machine-readable summary of built FMUs (``latobs build --json``)::

        {"schema": "latobs.build-summary/1", "latobs_version": str, "fmus": [{
            "name": FMU name (NAME or NAME_V), "kind": "observer" | "plant",
            "model": catalogue design or plant name, "paper": "000".."003" | null (plants),
            "vehicle": vehicle set name, "path": str, "sha256": hex of the .fmu, "size": bytes,
            "backend": "c" (native) | "python" (pythonfmu), "fmi": "2.0" | "3.0",
            "platforms": [FMI platform folders the FMU has binaries for: "linux64", "win64",
                          "darwin64", "aarch64-linux" (native FMUs: those built; pythonfmu FMUs:
                          pythonfmu's); FMI 3.0: "x86_64-linux", "x86_64-windows", "x86_64-darwin",
                          "aarch64-darwin", "aarch64-linux"],
            # observers (null for plants), read from NAME.design.json beside the FMU:
            "design_file": str, "design_sha256": hex of that file, "gamma": the design's "gamma",
            "model_error_gamma": its "model_error"."gamma" (paper 000's default designs) | null,
            "certificate": {"certified": bool, "passed": int, "total": int}}, ...]}

    The design file beside an observer FMU must be the one inside it (the same but for its
    wall-clock figures, ``design_file.reproducible``), else PipelineError: a summary never
    describes a design the FMU does not carry."""
    import hashlib
    import json
    import zipfile

    from . import __version__
    from .cbackend.fmi3 import FOLDERS
    from .cbackend.toolchain import PLATFORMS
    from .identity import fmu_fmi_version
    from .packaging import PLANTS
    from .synthesis.design_file import reproducible

    def sha(raw: bytes) -> str:
        return hashlib.sha256(raw).hexdigest()

    entries = []
    for fmu in map(Path, fmus):
        raw = fmu.read_bytes()
        with zipfile.ZipFile(fmu) as z:
            names = z.namelist()
            members = {n: z.read(n) for n in names
                       if n.startswith("resources/") and n.endswith((".design.json", ".plant.json"))
                       and n.count("/") == 1}
        fmi = f"{fmu_fmi_version(fmu)}.0"
        held = {n.split("/")[1] for n in names if n.startswith("binaries/") and n.count("/") == 2}
        order = list(PLATFORMS) if fmi == "2.0" else [f for fs in FOLDERS.values() for f in fs]
        entry = {"name": fmu.stem, "path": str(fmu), "sha256": sha(raw), "size": len(raw),
                 "backend": "python" if "resources/slavemodule.txt" in names else "c", "fmi": fmi,
                 "platforms": [p for p in order if p in held] + sorted(held - set(order))}
        inner = members.get(f"resources/{fmu.stem}.design.json")
        if inner is not None:
            design_path = fmu.with_name(f"{fmu.stem}.design.json")
            d = json.loads(inner)
            try:
                raw_beside = design_path.read_bytes()
                beside = json.loads(raw_beside)
            except (OSError, ValueError):
                beside = None
            if beside is None or reproducible(beside) != d:
                raise PipelineError(f"{design_path} is missing or is not the design file inside {fmu}")
            me = d.get("model_error")
            entry.update(kind="observer", model=d.get("design"), paper=d.get("paper"),
                         vehicle=(d.get("vehicle") or {}).get("name"), design_file=str(design_path),
                         design_sha256=sha(raw_beside), gamma=d.get("gamma"),
                         model_error_gamma=me.get("gamma") if isinstance(me, dict) else None,
                         certificate={"certified": bool(d.get("certified")),
                                      "passed": sum(bool(c.get("passed")) for c in d.get("checks", [])),
                                      "total": len(d.get("checks", []))})
        else:
            plant = members.get(f"resources/{fmu.stem}.plant.json")
            if plant is None:
                raise PipelineError(f"{fmu} carries neither a design nor a plant data file: not a latobs FMU")
            veh = json.loads(plant).get("vehicle") or {}
            model = next((k for k in sorted(PLANTS, key=len, reverse=True)
                          if fmu.stem == k or fmu.stem.startswith(k + "_")), None)
            entry.update(kind="plant", model=model, paper=None, vehicle=veh.get("name"), design_file=None,
                         design_sha256=None, gamma=None, model_error_gamma=None, certificate=None)
        order = ("name", "kind", "model", "paper", "vehicle", "path", "sha256", "size", "backend", "fmi", "platforms",
                 "design_file", "design_sha256", "gamma", "model_error_gamma", "certificate")
        entries.append({k: entry[k] for k in order})
    return {"schema": BUILD_SUMMARY_SCHEMA, "latobs_version": __version__, "fmus": entries}


def ensure_fmus(names: list[str], fmu_dir: Path, platforms: list[str] | None = None) -> dict[str, Path]:
    """Paths of the named observer FMUs in ``fmu_dir``: ``NAME`` or ``NAME_V`` (V a shipped
    vehicle set), each reused if current (a native one if it holds this machine's platform), else
    built (:func:`build` says which; native ones for ``platforms``, None: all). An FMU of another
    name found there (made by hand) is used as it is."""
    fmu_dir = Path(fmu_dir)
    out = {}
    for n in names:
        try:
            design, vehicle = designs.parse_artefact(n)
        except KeyError:
            if not (fmu_dir / f"{n}.fmu").is_file():
                raise
            print(f"using {n}.fmu as found (not a catalogue design: its inputs cannot be checked)")
            out[n] = fmu_dir / f"{n}.fmu"
            continue
        out[n], = _build_in(fmu_dir, [design], vehicle, platforms)
    return out


def folder_fmi(fmu_dir: Path, fmu: Path | None = None) -> int:
    """The FMI version of the FMUs of ``fmu_dir`` a command builds when missing or stale: that of
    ``fmu`` when it is there (its identity, else its model description), else 3 in a folder named
    ``fmi3`` (:data:`FMI_FOLDER`), else 2."""
    from .identity import fmu_fmi_version

    found = fmu_fmi_version(fmu) if fmu is not None and fmu.is_file() else None
    if found is not None:
        return found
    return 3 if Path(fmu_dir).name == FMI_FOLDER[3] else 2


def _build_in(fmu_dir: Path, names: list[str], vehicle, platforms) -> list[Path]:
    """:func:`build` of ``names`` in ``fmu_dir`` itself (no design files, this machine's binaries
    suffice), in the FMI version of the FMU already there (:func:`folder_fmi`)."""
    from . import packaging

    name = names[0]
    if name in designs.DESIGNS:
        artefact = designs.fmu_name(name, None if vehicle is None else _vehicle_name(vehicle),
                                    designs.DESIGNS[name].default_vehicle)
    else:
        artefact = packaging.plant_artefact(name, vehicle)[2]
    fmi = folder_fmi(fmu_dir, Path(fmu_dir) / f"{artefact}.fmu")
    return _build(names, vehicle, Path(fmu_dir), "auto" if fmi == 2 else "c", False, platforms, True, fmi)


def _vehicle_name(vehicle) -> str:
    from .synthesis.params import load_vehicle

    return load_vehicle(vehicle).name


def ensure_plant(plant: str, vehicle: str | None, fmu_dir: Path, platforms: list[str] | None = None) -> Path:
    """Path of the plant FMU ``plant`` for ``vehicle`` (a name or a TOML file; None: the plant's
    default vehicle) in ``fmu_dir``: ``PLANT.fmu`` for the default vehicle, ``PLANT_VEHICLE.fmu``
    otherwise (VEHICLE the set's ``name``), reused if current, else built (as :func:`ensure_fmus`)."""
    path, = _build_in(fmu_dir, [plant], vehicle, platforms)
    return path


def run_validation(scenario: str, observers: list[str] | None, out: Path, fmu_dir: Path,
                   plant_parameters: dict | None = None, noise: bool = False, seed: int = 0,
                   tag: str = "", quiet: bool = False, plots=True,
                   plant_vehicle: str | None = None, platforms: list[str] | None = None) -> dict:
    """Co-simulate plant + observers on a scenario; writes out/SCENARIO[_TAG]/metrics.json and PNGs
    (no PNGs with ``plots=False``; ``plots(result, folder)`` draws them instead, as in
    ``validation.validate``). ``plant_vehicle``: the plant FMU's vehicle (its FMU is
    ``PLANT_V``, built if missing); default the plant's default vehicle. ``platforms``: of the
    native FMUs built when missing (:func:`ensure_fmus`)."""
    from . import packaging
    from .validation import get_scenario, validate
    from .validation.harness import NoiseSpec
    from .validation.report import text_table

    sc = get_scenario(scenario)
    # default: paper 000's observers beside CarPlant, every observer of the plant otherwise
    observers = observers or catalogue.default_observers(sc.plant)
    fmus = ensure_fmus(observers, fmu_dir, platforms)
    plant_vehicle = plant_vehicle or packaging.PLANTS[sc.plant].default_vehicle
    plant = ensure_plant(sc.plant, plant_vehicle, fmu_dir, platforms)
    out_dir = out / (f"{scenario}_{tag}" if tag else scenario)
    _, metrics, paths = validate(sc, plant, {n: fmus[n] for n in observers}, out_dir, vehicle=plant_vehicle,
                                 plant_parameters=plant_parameters or {},
                                 noise=NoiseSpec(signals=PLANT_NOISE[sc.plant]) if noise else None, seed=seed,
                                 plots=plots)
    if not quiet:
        print(f"{scenario}{' [' + tag + ']' if tag else ''}: plant parameters {plant_parameters or 'nominal'}, "
              f"noise {'on' if noise else 'off'}")
        print(text_table(metrics))
        print(f"wrote {', '.join(str(p) for p in paths)}")
    return metrics


def _observer_spec(observer: str):
    """The model file's SPEC of observer ``observer``'s FMU: known without building the FMU."""
    from importlib import import_module

    from . import fmu_src, packaging

    return import_module(f"{fmu_src.__name__}.models.{packaging.OBSERVERS[observer].model_module}").SPEC


def observer_inputs(observer: str):
    """The inputs (name, unit, declared min/max) of observer ``observer``'s FMU, as its model file
    declares them: known without building the FMU."""
    from .validation.replay import InputSpec

    return [InputSpec(v.name, v.unit, v.min, v.max) for v in _observer_spec(observer).inputs]


def observer_outputs(observer: str) -> list[str]:
    """The output names of observer ``observer``'s FMU, as its model file declares them."""
    return [v.name for v in _observer_spec(observer).outputs]


def replay(csv, observer: str, vehicle: str | None = None, out: Path = Path("build"),
           fmu_dir: Path = Path("build"), split: float | None | str = "auto", plots=True,
           quiet: bool = False, platforms: list[str] | None = None) -> dict:
    """Drive the built observer FMU ``fmu_dir/NAME[_V].fmu`` (built if missing) with the columns of
    ``csv`` (a .csv/.csv.gz path, or ``"mbds"`` for the bundled MBDS record) and score it against
    the reference columns present; writes ``out/replay_<csv stem>_<NAME[_V]>/metrics.json`` and
    PNGs (none with ``plots=False``; a callable draws them instead, as in ``replay.run``). ``split``:
    a time in s scored separately before and after,
    None for none, ``"auto"`` for the file's default (425 s for the MBDS record, else none).
    ``platforms``: of the native FMU when built (:func:`ensure_fmus`). Returns the metrics
    (structure in :func:`latobs.validation.replay.score`)."""
    from .synthesis.params import load_vehicle
    from .validation import replay as rp
    from .validation.report import text_table

    if observer not in designs.DESIGNS:
        raise rp.ReplayError(f"unknown observer {observer!r}; known: {', '.join(designs.DESIGNS)}")
    from .validation import stream

    path = rp.resolve_csv(csv)
    long = stream.streamed(path)                # replayed block by block, in constant memory
    if long:                                    # read once to check it, before anything is built
        data, scanned = None, stream.scan(path, observer_inputs(observer), observer)
    else:
        data = rp.load_csv(path)                # a bad file fails before anything is built
        rp.uniform_step(data["t"], path)
        # the record must carry every input the observer reads, in range, before anything is built
        rp.check_record(data, observer_inputs(observer), path, observer)
        rp.check_resources(data, len(observer_outputs(observer)), path)   # memory, before anything is built
    veh = load_vehicle(vehicle or designs.DESIGNS[observer].default_vehicle)
    if rp.default_split(path) is not None and veh.name != rp.MBDS_VEHICLE and not quiet:
        print(f"note: the MBDS record is of vehicle {rp.MBDS_VEHICLE!r}; replaying {observer} designed for "
              f"{veh.name!r} (use --vehicle {rp.MBDS_VEHICLE} for the dataset's own parameters)")
    name = designs.artefact_name(observer, veh.name)   # a TOML path: named after the set's `name`
    fmu, = build([observer], vehicle, Path(fmu_dir), design_files=False, platforms=platforms,
                 host_suffices=True)    # reused if current (and holds this machine's platform), else built
    mass = veh.parameters["m"].value if "m" in veh.parameters else None
    out_dir = Path(out) / f"replay_{rp.csv_stem(path)}_{name}"
    if long:
        if split == "auto":
            split = rp.default_split(path)
        metrics, paths = stream.run(path, fmu, out_dir, split, observer, veh.name, mass, plots=bool(plots),
                                    progress=not quiet, info=scanned)
    else:
        metrics, paths = rp.run(path, fmu, out_dir, split=split, observer=observer, vehicle=veh.name, mass=mass,
                                plots=plots, data=data)
    if not quiet:
        print(text_table(metrics))
        print(f"wrote {', '.join(str(p) for p in paths)}")
    return metrics
