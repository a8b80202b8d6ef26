"""Benchmark: a label volume of a dedicated breast CT's size meshed, and its clinical cases solved.

``python -m benchmarks.image_mesh [--shape 600 600 400] [--spacing 0.27] [--format .nii.gz]
[--size 0.025] [--no-solve]``

Writes the segmented phantom (:mod:`meshes.phantom`: fat, gland, tumour, pectoral muscle) at
``--shape`` voxels of ``--spacing`` mm, its axes as a prone breast CT lays them out (i to the
patient's left, j inferior, k anterior: a direction matrix that is not the identity), then
meshes it with ``mesh.source: image`` at ``--size`` in a fresh process (the workflow's
``make_mesh``) and prints that process's wall time and peak resident memory, the mesh's cells,
worst dihedral angle and the volume kept. Then it solves the config's four clinical cases on
the mesh with ``python -m fem.cli`` (default solver) and prints each one's status and largest
displacement.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

#: The image axes of a prone dedicated breast CT in LPS: i left, j inferior, k anterior.
BREAST_CT_AXES = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, -1.0, 0.0]]).T

CLINICAL = ((1.0, 180.0), (5.0, 180.0), (1.0, 0.0), (5.0, 0.0))


MESH_SCRIPT = """
import json, sys
from meshes.config import MeshConfig, make_mesh
section = json.loads(sys.argv[1])
folder = sys.argv[2]
make_mesh(MeshConfig.from_mapping(section), folder + "/mesh.xdmf",
          folder + "/quality.json", folder + "/mesh.png")
"""


def main(argv: list[str] | None = None) -> int:
    """Write the phantom, mesh it in a child process, solve the clinical cases; print."""
    from benchmarks.child import run_measured
    from meshes.phantom import BREAST_LABELS, PECTORAL, write_phantom

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--shape", type=int, nargs=3, default=[600, 600, 400])
    parser.add_argument("--spacing", type=float, default=0.27, help="voxel size, mm")
    parser.add_argument("--format", default=".nii.gz", help="the image's suffix")
    parser.add_argument("--size", type=float, default=0.025, help="mesh.size.global_size, m")
    parser.add_argument("--no-solve", action="store_true", help="mesh only")
    args = parser.parse_args(argv)
    load_before = os.getloadavg()[0]
    with tempfile.TemporaryDirectory(prefix="image_mesh_") as tmp:
        folder = Path(tmp)
        start = time.perf_counter()
        image = write_phantom(folder / f"phantom{args.format}", tuple(args.shape),
                              (args.spacing,) * 3, side="left", direction=BREAST_CT_AXES)
        print(f"phantom {image.name}: {' x '.join(map(str, args.shape))} voxels of "
              f"{args.spacing:g} mm, {image.stat().st_size / 1e6:.1f} MB, written in "
              f"{time.perf_counter() - start:.1f} s")
        section = {"source": "image", "size": {"global_size": args.size},
                   "image": {"path": str(image), "breast_labels": list(BREAST_LABELS),
                             "chest_label": PECTORAL, "side": "left"}}
        wall, rss = run_measured([sys.executable, "-c", MESH_SCRIPT, json.dumps(section),
                                  str(folder)], folder / "mesh.log")
        quality = json.loads((folder / "quality.json").read_text())
        info = quality["input"]
        print(f"meshed at global_size {args.size:g} m: {wall:.1f} s wall, {rss:.2f} GB peak "
              f"(child process); stages {info['seconds']}; {quality['cells']} cells, worst "
              f"dihedral {info['quality_floor']['min_dihedral_deg']:.1f}°, "
              f"{info['meshed_volume_ml']:.0f} of {info['labelled_volume_ml']:.0f} ml "
              f"({100 * info['volume_kept']:.1f} %), {info['fill']['method']}; rib "
              f"{1e4 * quality['area_m2']['rib']:.0f} cm²")
        if not args.no_solve:
            for c1, phi in CLINICAL:
                out = folder / f"case_{c1:g}_{phi:g}"
                wall, rss = run_measured([sys.executable, "-m", "fem.cli",
                                          str(folder / "mesh.xdmf"), "--c1", str(c1), "--phi",
                                          str(phi), "--out", str(out)], folder / f"{out.name}.log")
                summary = json.loads((out / "summary.json").read_text())
                print(f"C1 = {c1:g} kPa, Φ = {phi:g}°: {summary['status']}, "
                      f"max |u| {summary['max_disp_mm']:.1f} mm, Newton "
                      f"{summary['total_newton_iterations']}, {wall:.1f} s, {rss:.2f} GB")
    print(f"{os.cpu_count()} cores; load average before {load_before:.2f}, after "
          f"{os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
