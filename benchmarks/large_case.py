"""Benchmark: one clinical case at image resolution, each linear-solver path in its own process.

``python -m benchmarks.large_case [--mesh MESH] [--size 0.0031] [--c1 1.0] [--phi 180]``

Without ``--mesh`` it writes the corpus's scan-like anatomy (:mod:`meshes.corpus`) and imports
it remeshed to ``--size`` metres (0.0031 m gives about 97k tetrahedra, 447k P2/P1 unknowns, the
size of a breast-CT phantom). Then it solves the case with ``python -m fem.cli`` twice, in
fresh processes one after the other: with the default ``direct`` preset as it chooses its path
by size (block low-rank above ``blr_above_dofs``) and with the full-rank factorisation forced
(``blr_above_dofs`` out of reach). It prints each run's wall time, peak resident memory (the
child process's maximum RSS), Newton and Krylov iterations, the path its summary records and the
largest difference of the two displacement fields.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
from pathlib import Path

import numpy as np
import yaml

from benchmarks.child import run_measured
from fem.case_files import read_points

#: The two paths: the preset's own choice, and full rank forced.
PATHS = {"by size (default)": {}, "full rank": {"blr_above_dofs": 10**12}}


def build_mesh(folder: Path, size: float) -> Path:
    """The corpus's scan-like anatomy imported at element size ``size`` (m)."""
    from meshes.config import MeshConfig, make_mesh
    from meshes.corpus import write_anatomy

    section = write_anatomy("scan", folder / "input", {}, import_size=size)
    make_mesh(MeshConfig.from_mapping(section), folder / "mesh.xdmf", folder / "quality.json",
              folder / "mesh.png")
    return folder / "mesh.xdmf"


def run_path(mesh: Path, c1: float, phi: float, options: dict, folder: Path) -> dict:
    """Solve the case in a child process with ``options``; its summary plus wall time and RSS."""
    config = folder / "config.yaml"
    config.write_text(yaml.safe_dump({"fe": {"petsc_options": options}}))
    out = folder / "case"
    cmd = [sys.executable, "-m", "fem.cli", str(mesh), "--c1", str(c1), "--phi", str(phi),
           "--out", str(out), "--config", str(config)]
    wall, peak_gb = run_measured(cmd, folder / "solve.log")
    summary = json.loads((out / "summary.json").read_text())
    summary["process_wall_s"] = wall
    summary["peak_rss_gb"] = peak_gb
    return summary


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark and print its table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mesh", type=Path, help="mesh XDMF (default: build the scan)")
    parser.add_argument("--size", type=float, default=0.0031, help="element size (m) to build")
    parser.add_argument("--c1", type=float, default=1.0)
    parser.add_argument("--phi", type=float, default=180.0)
    args = parser.parse_args(argv)
    load_before = os.getloadavg()[0]
    with tempfile.TemporaryDirectory(prefix="large_case_") as tmp:
        folder = Path(tmp)
        mesh = args.mesh or build_mesh(folder / "mesh", args.size)
        runs, fields = {}, {}
        for name, options in PATHS.items():
            path_folder = folder / name.split()[0]
            path_folder.mkdir()
            runs[name] = run_path(mesh, args.c1, args.phi, options, path_folder)
            fields[name] = read_points(path_folder / "case" / "points.h5")["u"]
    first, second = (fields[name] for name in PATHS)
    print(f"case C1 = {args.c1:g} kPa, Φ = {args.phi:g}°; mesh {mesh}; "
          f"{os.cpu_count()} cores; load average before: {load_before:.2f}, after: "
          f"{os.getloadavg()[0]:.2f}")
    print(f"{'path':<20} {'unknowns':>9} {'status':>9} {'wall (s)':>9} {'solve (s)':>9} "
          f"{'peak (GB)':>9} {'Newton':>7} {'Krylov':>7}  linear solver")
    for name, s in runs.items():
        print(f"{name:<20} {s['dofs']:>9d} {s['status']:>9} {s['process_wall_s']:>9.1f} "
              f"{s['wall_s']['solve']:>9.1f} {s['peak_rss_gb']:>9.2f} "
              f"{sum(s['newton_iterations']):>7d} {s['linear_iterations']:>7d}  "
              f"{s['linear_path']}")
    a, b = (runs[name] for name in PATHS)
    print(f"ratio by size / full rank: wall {a['process_wall_s'] / b['process_wall_s']:.2f}, "
          f"peak memory {a['peak_rss_gb'] / b['peak_rss_gb']:.2f}; largest difference of the "
          f"displacements {1e3 * np.abs(first - second).max():.2e} mm")
    return 0


if __name__ == "__main__":
    sys.exit(main())
