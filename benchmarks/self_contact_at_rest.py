"""Benchmark: self-contact on a surface whose skin faces itself at rest, each way of treating it.

``python -m benchmarks.self_contact_at_rest [--config config.yaml] [--angle 30] [--size M]
[--out DIR] [--limit-s 600] [--settings off by_side ...] [--mesh MESH]``

It writes the corpus's closed surface with a sharp chest-wall rim
(:func:`meshes.corpus.rim_surface`), imports it remeshed at the config's ``mesh.size`` (or at
``--size`` metres everywhere) with the posterior rule, and prints the skin's pairs at rest
(:class:`fem.self_contact.RestPairs`).
Then it solves the config's clinical cases without self-contact (``off``) and with it under
each ``fe.self_contact.at_rest`` (``none`` is the treatment-free model, whose pairs at rest
push from the start), each setting in a fresh process one after the other (``--limit-s``
seconds each, for a setting that stalls), and prints per case and setting the outcome, load
steps, wall seconds, max |u|, and the displacement's largest difference from ``off`` with the
ratio of the wall times. ``--settings`` runs only those (``off`` is always among them, the
reference); ``--mesh`` solves on a mesh already imported instead. Run it with nothing else on
the machine, and compare the times of settings measured in one run.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from fem.configfile import read_config_file
from fem.parameters import SolverSettings
from fem.self_contact import AT_REST, self_contact_from_mapping
from fem.sweep import clinical_cases

SETTINGS = ("off", *AT_REST)


def import_rim(config: dict[str, Any], folder: Path, angle: float,
               size: float | None = None) -> Path:
    """Write and import the rim surface into ``folder``; the mesh's XDMF."""
    from meshes.config import MeshConfig, make_mesh
    from meshes.corpus import rim_section

    sizes = dict(config["mesh"]["size"])
    if size is not None:
        sizes.update(global_size=size, mound_size=size)
    section = {"source": "file", "file": rim_section(folder / "rim.stl", angle),
               "size": sizes, "fixed": {"rib": "all"}}
    xdmf = folder / "mesh.xdmf"
    make_mesh(MeshConfig.from_mapping(section), xdmf, folder / "quality.json",
              folder / "mesh.png")
    return xdmf


def settings_for(config: dict[str, Any], setting: str) -> SolverSettings:
    """The config's solver settings with self-contact off, or on with ``at_rest`` = setting."""
    settings = SolverSettings.from_config(config)
    if setting == "off":
        return replace(settings, self_contact=None)
    base = (config.get("fe") or {}).get("self_contact") or {}
    return replace(settings, self_contact=self_contact_from_mapping({**base, "at_rest": setting}))


def solve_setting(mesh: Path, config_path: Path, setting: str, out: Path) -> None:
    """Child: solve the clinical cases with one setting; write their summaries to ``out``."""
    from fem.case import CaseRunner

    config = read_config_file(config_path)
    rows = []
    with CaseRunner(mesh, settings_for(config, setting)) as runner:
        rest = runner.problem.self_contact.rest.to_json() if runner.problem.self_contact \
            else None
        for case in clinical_cases(config["clinical"]):
            result, timings = runner.solve(case)
            summary = runner.summary(case, result, timings, measure_unit=False)
            rows.append({"case": case.id, "status": summary["status"],
                         "steps": summary["load_steps"], "wall_s": summary["wall_s"]["solve"],
                         "max_disp_mm": summary["max_disp_mm"],
                         "u": gather(runner)})
            (out / f"{setting}.json").write_text(json.dumps({"rest": rest, "rows": rows}))


def gather(runner: Any) -> list[list[float]]:
    """The displacement at the mesh's vertices (serial)."""
    from fem.io import gather_vertex_values

    _, u = gather_vertex_values(runner.mesh, runner.problem.displacement())
    return u.tolist()


def main(argv: list[str] | None = None) -> int:
    """Command line: see the module docstring."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--config", type=Path, default=Path("config.yaml"))
    parser.add_argument("--angle", type=float, default=30.0,
                        help="the posterior rule's angle, degrees")
    parser.add_argument("--size", type=float, help="element size everywhere, metres")
    parser.add_argument("--out", type=Path, help="working folder (a temporary one by default)")
    parser.add_argument("--limit-s", type=float, default=600.0,
                        help="seconds each setting may take")
    parser.add_argument("--settings", nargs="+", choices=SETTINGS, default=list(SETTINGS),
                        help="the settings to solve with (off is always solved)")
    parser.add_argument("--mesh", type=Path, help="a mesh already imported (its XDMF)")
    parser.add_argument("--child", nargs=2, metavar=("MESH", "SETTING"), help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    out = args.out or Path(tempfile.mkdtemp(prefix="at_rest_"))
    out.mkdir(parents=True, exist_ok=True)
    if args.child:
        solve_setting(Path(args.child[0]), args.config, args.child[1], out)
        return 0
    config = read_config_file(args.config)
    mesh = args.mesh or import_rim(config, out, args.angle, args.size)
    if args.mesh is None:
        quality = json.loads((out / "quality.json").read_text())
        print(f"rim surface: {quality['cells']} cells, min dihedral "
              f"{quality['min_dihedral_deg']:.1f}°, rib {1e4 * quality['area_m2']['rib']:.1f} "
              f"cm², skin {1e4 * quality['area_m2']['skin']:.1f} cm²")
    settings = [s for s in SETTINGS if s == "off" or s in args.settings]
    results: dict[str, Any] = {}
    for setting in settings:
        try:
            subprocess.run([sys.executable, "-m", "benchmarks.self_contact_at_rest", "--config",
                            str(args.config), "--out", str(out), "--child", str(mesh), setting],
                           check=True, timeout=args.limit_s, capture_output=True)
        except subprocess.TimeoutExpired:
            print(f"{setting}: stopped after {args.limit_s:.0f} s")
        except subprocess.CalledProcessError as err:
            print(f"{setting}: failed: {err.stderr.decode()[-400:]}")
        path = out / f"{setting}.json"
        results[setting] = json.loads(path.read_text()) if path.is_file() else {"rows": []}
    rest = next((r["rest"] for r in results.values() if r.get("rest")), None)
    print(f"pairs at rest without a treatment: {rest}")
    off = {r["case"]: r for r in results["off"]["rows"]}
    print(f"{'case':34} {'setting':9} {'status':10} {'steps':>5} {'wall s':>7} "
          f"{'max|u| mm':>9} {'Δu mm':>8} {'time ×':>6}")
    for setting in settings:
        for r in results[setting]["rows"]:
            ref = off.get(r["case"])
            both = ref is not None and ref["status"] == r["status"] == "converged"
            diff = 1e3 * float(np.abs(np.array(r["u"]) - np.array(ref["u"])).max()) if both \
                else None
            ratio = r["wall_s"] / ref["wall_s"] if both else None
            print(f"{r['case']:34} {setting:9} {r['status']:10} {r['steps']:5d} "
                  f"{r['wall_s']:7.2f} {r['max_disp_mm']:9.3f} "
                  f"{'-' if diff is None else format(diff, '.2e'):>8} "
                  f"{'-' if ratio is None else format(ratio, '.3f'):>6}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
