"""Benchmark: a label volume of a dedicated breast CT's size meshed, and its clinical cases solved.

``python -m benchmarks.image_mesh [--shape 600 600 400] [--spacing 0.27] [--format .nii.gz]
[--size 0.025] [--skin 1.5] [--mesher cgal ftetwild] [--no-solve]``

Writes the segmented phantom (:mod:`meshes.phantom`: fat, gland, tumour, pectoral muscle and,
with ``--skin`` > 0 mm, a skin label; each a tissue of ``mesh.image.tissues``) at
``--shape`` voxels of ``--spacing`` mm, its axes as a prone breast CT lays them out (i to the
patient's left, j inferior, k anterior: a direction matrix that is not the identity), then
meshes it with ``mesh.source: image`` at ``--size`` by each ``--mesher``, twice, each in a
fresh process (the workflow's ``make_mesh``), and prints each process's wall time and peak
resident memory, the mesh's cells, worst dihedral angle and cells below the floor, the volume
kept (and each tissue's, meshed over labelled), and whether the two runs wrote byte-identical
``mesh.h5`` files. Then it solves the config's four clinical cases on
the first mesher's mesh with ``python -m fem.cli`` (default solver; the tumour ``--tumour``
times the fat's stiffness, the other tissues at their defaults) and prints each one's status,
largest displacement, Newton iterations, wall time and peak memory; beside each, the same case
on the same image meshed by the same mesher as one tissue (every breast label fat).
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
    """Write the phantom, mesh it by each mesher twice in child processes, solve; print."""
    from benchmarks.child import run_measured
    from meshes.phantom import BREAST_LABELS, PECTORAL, SKIN, TISSUE_LABELS, write_phantom

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--shape", type=int, nargs=3, default=[600, 600, 400])
    parser.add_argument("--spacing", type=float, default=0.27, help="voxel size, mm")
    parser.add_argument("--format", default=".nii.gz", help="the image's suffix")
    parser.add_argument("--size", type=float, default=0.025, help="mesh.size.global_size, m")
    parser.add_argument("--skin", type=float, default=1.5, help="skin label thickness, mm")
    parser.add_argument("--mesher", nargs="+", default=["cgal", "ftetwild"],
                        choices=["cgal", "ftetwild"], help="mesh.image.mesher, in turn")
    parser.add_argument("--no-solve", action="store_true", help="mesh only")
    parser.add_argument("--tumour", type=float, default=5.0,
                        help="material.tissues.tumour: the tumour's C1 over the fat's")
    args = parser.parse_args(argv)
    load_before = os.getloadavg()[0]
    with tempfile.TemporaryDirectory(prefix="image_mesh_") as tmp:
        folder = Path(tmp)
        start = time.perf_counter()
        image = write_phantom(folder / f"phantom{args.format}", tuple(args.shape),
                              (args.spacing,) * 3, side="left", direction=BREAST_CT_AXES,
                              skin_mm=args.skin)
        print(f"phantom {image.name}: {' x '.join(map(str, args.shape))} voxels of "
              f"{args.spacing:g} mm, skin {args.skin:g} mm, {image.stat().st_size / 1e6:.1f} MB, "
              f"written in {time.perf_counter() - start:.1f} s")
        labels = list(BREAST_LABELS) + ([SKIN] if args.skin > 0 else [])
        tissues = {name: values for name, values in TISSUE_LABELS.items()
                   if args.skin > 0 or name != "skin"}

        def mesh_section(mesher: str, tissues: dict) -> dict:
            """The ``mesh`` section of the phantom meshed by ``mesher`` with ``tissues``."""
            return {"source": "image", "size": {"global_size": args.size},
                    "image": {"path": str(image), "breast_labels": labels,
                              "chest_label": PECTORAL, "side": "left", "tissues": tissues,
                              "mesher": mesher}}

        for mesher in args.mesher:
            section = mesh_section(mesher, tissues)
            runs = [folder / mesher / run for run in ("a", "b")]
            for run in runs:
                run.mkdir(parents=True)
                wall, rss = run_measured([sys.executable, "-c", MESH_SCRIPT,
                                          json.dumps(section), str(run)], run / "mesh.log")
                quality = json.loads((run / "quality.json").read_text())
                info = quality["input"]
                floor = info["quality_floor"]
                labelled = info.get("labelled_tissue_ml", {})
                kept = ", ".join(f"{name} {ml:.1f}" + (f"/{labelled[name]:.1f}" if name in
                                                        labelled else "")
                                 for name, ml in quality.get("tissue_volume_ml", {}).items())
                print(f"{mesher} run {run.name} at global_size {args.size:g} m: {wall:.1f} s "
                      f"wall, {rss:.2f} GB peak (child process); stages {info['seconds']}; "
                      f"{quality['cells']} cells, worst dihedral "
                      f"{floor['min_dihedral_deg']:.1f}°, {floor['cells_below_floor']} below "
                      f"{floor['floor_deg']:g}°, {info['meshed_volume_ml']:.0f} of "
                      f"{info['labelled_volume_ml']:.0f} ml ({100 * info['volume_kept']:.1f} %), "
                      f"tissues ml (meshed/labelled) {kept or '-'}; {info['fill']['method']}; "
                      f"rib {1e4 * quality['area_m2']['rib']:.0f} cm²")
            same = (runs[0] / "mesh.h5").read_bytes() == (runs[1] / "mesh.h5").read_bytes()
            print(f"{mesher}: the two runs' mesh.h5 {'are' if same else 'are not'} "
                  "byte-identical")
        if not args.no_solve:
            meshes = {"tissues": folder / args.mesher[0] / "a"}
            one = folder / args.mesher[0] / "one_tissue"
            one.mkdir()
            one_tissue = mesh_section(args.mesher[0], {})  # every breast label fat
            run_measured([sys.executable, "-c", MESH_SCRIPT, json.dumps(one_tissue), str(one)],
                         one / "mesh.log")
            meshes["one tissue"] = one
            config = folder / "material.yaml"
            config.write_text(json.dumps({"material": {"tissues": {"tumour": args.tumour}}}))
            for c1, phi in CLINICAL:
                line = [f"C1 = {c1:g} kPa, Φ = {phi:g}°:"]
                for name, mesh_dir in meshes.items():
                    out = folder / f"case_{c1:g}_{phi:g}_{name.replace(' ', '_')}"
                    wall, rss = run_measured(
                        [sys.executable, "-m", "fem.cli", str(mesh_dir / "mesh.xdmf"), "--c1",
                         str(c1), "--phi", str(phi), "--out", str(out), "--config", str(config)],
                        folder / f"{out.name}.log")
                    summary = json.loads((out / "summary.json").read_text())
                    line.append(f"{name} ({summary['dofs']} unknowns) {summary['status']}, "
                                f"max |u| {summary['max_disp_mm']:.1f} mm, Newton "
                                f"{summary['total_newton_iterations']}, {wall:.1f} s, "
                                f"{rss:.2f} GB;")
                print(" ".join(line))
    print(f"{os.cpu_count()} cores; load average before {load_before:.2f}, after "
          f"{os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
