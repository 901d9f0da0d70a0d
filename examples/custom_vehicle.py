"""Design and build an observer for your own vehicle, from a vehicle TOML file.

What it shows: `--vehicle` takes a path to a TOML parameter set as well as a shipped set's name.
This script writes a modified copy of the shipped `sedan` set (a heavier car: mass and the yaw
and roll inertias times --mass-factor) to OUT/<name>.toml, then runs

    latobs build SideslipBankObserver --vehicle OUT/<name>.toml --out OUT --json OUT/summary.json

which solves the LMIs for that car, certifies the design independently and packages the FMU
(`latobs design ...` with the same arguments stops after the design file). It prints the design's
gamma, the certificate's verdict and the FMU's path, read from the --json summary.

The FMU is named NAME_V after the `name` inside the TOML file (here
SideslipBankObserver_sedan_heavy.fmu), not after the file name: give every set its own name.
Format of a set: latobs/synthesis/vehicles/sedan.toml (SI units, a unit per value; values must be
positive unless marked `sign = "any"`). A set that lacks a parameter, or a car the LMIs cannot
serve, makes latobs exit with status 2 and a message naming the culprit; this script then exits 2.

Run it:

    python examples/custom_vehicle.py                      # 1.3 x the sedan's mass, into build/custom
    python examples/custom_vehicle.py --mass-factor 1.6 --observer SideslipBankObserverTire
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tomllib
from importlib import resources
from pathlib import Path


def toml_value(v) -> str:
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{k} = {toml_value(x)}" for k, x in v.items()) + " }"
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return json.dumps(v)          # a TOML basic string for these texts
    return repr(v)                    # float or int


def write_vehicle(path: Path, data: dict) -> None:
    """Write a vehicle set (top-level strings, then [parameters] and [ranges] of inline tables)."""
    lines = [f"{k} = {toml_value(v)}" for k, v in data.items() if not isinstance(v, dict)]
    for table in ("parameters", "ranges"):
        if data.get(table):
            lines += ["", f"[{table}]", *(f"{k} = {toml_value(v)}" for k, v in data[table].items())]
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines) + "\n")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--observer", default="SideslipBankObserver", help="design name (default SideslipBankObserver)")
    p.add_argument("--base", default="sedan", help="shipped vehicle set to start from (default sedan)")
    p.add_argument("--name", default=None, help="name of the new set (default <base>_heavy)")
    p.add_argument("--mass-factor", type=float, default=1.3, help="scales m, Iz and Ix (default 1.3)")
    p.add_argument("--out", default="build/custom", help="folder of the TOML, design, FMU (default build/custom)")
    args = p.parse_args(argv)

    base = resources.files("latobs.synthesis") / "vehicles" / f"{args.base}.toml"
    data = tomllib.loads(base.read_text())
    name = args.name or f"{args.base}_heavy"
    data.update(name=name, description=f"{data['description']}, mass and inertias x {args.mass_factor:g}",
                source=f"examples/custom_vehicle.py from the shipped set {args.base!r}")
    for key in ("m", "Iz", "Ix"):
        if key in data["parameters"]:
            entry = data["parameters"][key]
            entry["value"] = round(entry["value"] * args.mass_factor, 6)
            entry["source"] = f"{args.base} x {args.mass_factor:g}"
    out = Path(args.out)
    toml_path = out / f"{name}.toml"
    write_vehicle(toml_path, data)
    print(f"vehicle {name!r}: m = {data['parameters']['m']['value']:g} kg -> {toml_path}")

    summary = out / "summary.json"
    cmd = [sys.executable, "-m", "latobs", "build", args.observer, "--vehicle", str(toml_path),
           "--out", str(out), "--json", str(summary)]
    print("$ latobs " + " ".join(cmd[3:]))
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        print(proc.stdout + proc.stderr, end="", file=sys.stderr)
        print(f"latobs build exited with status {proc.returncode}", file=sys.stderr)
        return proc.returncode
    (fmu,) = json.loads(summary.read_text())["fmus"]
    c = fmu["certificate"]
    print(f"{fmu['name']} (paper {fmu['paper']}, vehicle {fmu['vehicle']}): gamma = {fmu['gamma']:.4g}"
          + (f", model-error gamma = {fmu['model_error_gamma']:.4g}" if fmu["model_error_gamma"] is not None else ""))
    verdict = "certified" if c["certified"] else "NOT certified"
    print(f"certificate: {verdict}, {c['passed']}/{c['total']} checks passed")
    print(f"FMU: {fmu['path']} ({fmu['size']} bytes, sha256 {fmu['sha256'][:16]}...)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
