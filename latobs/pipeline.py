"""The whole pipeline, as the CLI and the demo run it: design -> FMU -> validation."""
from __future__ import annotations

from pathlib import Path

from .synthesis import designs  # the catalogue only: it imports the solver stack when designing

# Sensor noise and bias of ``latobs validate --noise``: (std, bias) per measured signal, SI units.
# Typical automotive-grade inertial and steering sensors.
DEFAULT_NOISE = {
    "yaw_rate": (0.002, 0.001),      # rad/s
    "roll_angle": (0.002, 0.0),      # rad
    "roll_rate": (0.003, 0.0005),    # rad/s
    "delta": (0.0005, 0.0),          # rad (road wheel)
    "vx": (0.05, 0.0),               # m/s
}


class PipelineError(RuntimeError):
    pass


def design_one(name: str, vehicle: str | None, out: Path, quiet: bool = False) -> Path:
    """Design, certify and write ``out/NAME[_V].design.json``; prints the headline figures."""
    from .synthesis import certificate, design_file

    data = designs.run(name, vehicle)
    path = design_file.write(data, out)
    if not quiet:
        s = certificate.summary(data)
        print(f"{data['name']}: certified ({len(data['checks'])} checks), gamma = {s['gamma']:.4g}, "
              f"cond(P) = {s['cond_P']:.3g}, Clarabel {data['solver']['status']} in "
              f"{data['solver']['seconds']:.2f} s -> {path}")
        for m in s["per_mode"]:
            print(f"  mode {m['mode']} @ {m['speed_kmh']:5.1f} km/h: H-inf bank->beta error {m['hinf']:.4g}, "
                  f"slowest bank pole {m['slowest_bank_pole']:.3f} 1/s, largest gain {m['largest_gain']:.4g}")
    return path


def build(names: list[str] | None, vehicle: str | None, out: Path, backend: str = "python") -> list[Path]:
    """Design + package the named FMUs (default: every observer and plant)."""
    from . import packaging

    if backend != "python":
        raise PipelineError(f"backend {backend!r} is not available yet: only the pythonfmu backend "
                            "('python') is implemented")
    names = names or [*designs.DESIGNS, *packaging.PLANTS]
    unknown = [n for n in names if n not in designs.DESIGNS and n not in packaging.PLANTS]
    if unknown:
        raise PipelineError(f"unknown FMU(s) {', '.join(unknown)}; known: "
                            f"{', '.join([*designs.DESIGNS, *packaging.PLANTS])}")
    built = []
    for name in names:
        if name in designs.DESIGNS:
            path = packaging.package_design(design_one(name, vehicle, out), out)
        else:
            path = packaging.package_plant(name, vehicle, out)
        print(f"built {path}")
        built.append(path)
    return built


def ensure_fmus(names: list[str], fmu_dir: Path) -> dict[str, Path]:
    """Paths of the named FMUs in ``fmu_dir``, building the missing ones."""
    missing = [n for n in names if not (fmu_dir / f"{n}.fmu").is_file()]
    if missing:
        print(f"building missing FMU(s): {', '.join(missing)}")
        build(missing, None, fmu_dir)
    return {n: fmu_dir / f"{n}.fmu" for n in names}


def run_validation(scenario: str, observers: list[str] | None, out: Path, fmu_dir: Path,
                   plant_parameters: dict | None = None, noise: bool = False, seed: int = 0,
                   tag: str = "", quiet: bool = False, plots: bool = True) -> dict:
    """Co-simulate plant + observers on a scenario; writes out/SCENARIO[_TAG]/metrics.json and PNGs
    (no PNGs with ``plots=False``)."""
    from .validation import get_scenario, validate
    from .validation.harness import NoiseSpec
    from .validation.report import text_table

    sc = get_scenario(scenario)
    observers = observers or [n for n, e in designs.DESIGNS.items() if e.paper in ("000",)]
    fmus = ensure_fmus([sc.plant, *observers], fmu_dir)
    out_dir = out / (f"{scenario}_{tag}" if tag else scenario)
    _, metrics, paths = validate(sc, fmus[sc.plant], {n: fmus[n] for n in observers}, out_dir,
                                 plant_parameters=plant_parameters or {},
                                 noise=NoiseSpec(signals=DEFAULT_NOISE) if noise else None, seed=seed,
                                 plots=plots)
    if not quiet:
        print(f"{scenario}{' [' + tag + ']' if tag else ''}: plant parameters {plant_parameters or 'nominal'}, "
              f"noise {'on' if noise else 'off'}")
        print(text_table(metrics))
        print(f"wrote {', '.join(str(p) for p in paths)}")
    return metrics
