"""See what the boundary rules of an import select, before meshing for the solver or solving.

    .venv/bin/python -m meshes.preview config.yaml [--png rules.png]

Reads the config's ``mesh`` section (``source: file`` or ``image``), reads and checks the file
(for a label volume: its header checked, where its voxel axes point and whether the header or
``mesh.image.orientation`` says so, its labels, their voxels and volumes, which make up the
breast and which is the chest, the breast meshed, and any warning: a field of view that cuts
the breast), and prints, for each rule, the facets it selects, their
area and their share of the boundary's area; then
whether the import would stop (two rules claim a facet, the rib is more than 70 % or less than
2 % of the boundary). The ``mesh`` section is checked by the config's schema first, as a run
checks it. ``--png`` draws the boundary coloured by rule, in the project's frame.
Exit status: 0 if the rules would do, 1 if not, 2 for a config or file that cannot be read.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from meshes.config import read_mesh_config
from meshes.configfile import read_config_file
from meshes.exceptions import GeometryError, MeshInputError
from meshes.importing import preview_rules
from meshes.schema import load_schema, schema_errors


def main(argv: list[str] | None = None) -> int:
    """Print what each rule selects (and draw it with ``--png``)."""
    parser = argparse.ArgumentParser(prog="python -m meshes.preview",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("config", type=Path,
                        help="a config file whose mesh.source is file or image")
    parser.add_argument("--png", type=Path, help="draw the boundary, coloured by rule")
    args = parser.parse_args(argv)
    try:
        # the mesh section checked as the run checks it (the schema), then read
        problems = [p for p in schema_errors(read_config_file(args.config), load_schema())
                    if p.startswith(("mesh.", "mesh:"))]
        if problems:
            raise GeometryError(f"{args.config}: invalid mesh section: " + "; ".join(problems))
        config = read_mesh_config(args.config)
        spec = config.imported
        if spec is None:
            raise GeometryError(f"{args.config}: mesh.source is parametric: there is no import")
        summary, problem, info = preview_rules(spec, config.size, args.png)
    except (OSError, GeometryError, MeshInputError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    if "labels" in info:
        _print_labels(info)
    print(f"{'boundary':<10} {'facets':>7} {'area cm²':>10} {'share':>7}  rule")
    for boundary, rule in spec.rules().items():
        row = summary[boundary.label]
        print(f"{boundary.label:<10} {row['facets']:>7d} {1e4 * row['area_m2']:>10.1f} "
              f"{100 * row['share']:>6.1f}%  {rule.describe()}")
    if args.png:
        print(f"picture: {args.png}")
    if problem:
        print(f"the import would stop: {problem}")
        return 1
    print("the rules would do")
    return 0


def _print_labels(info: dict) -> None:
    """The label volume's labels, and what each is to the mesh."""
    voxel_ml = 1e-3 * float(np.prod(info["voxel_size_mm"]))
    roles = {str(v): "breast" for v in info["breast_labels"]}
    if info["chest_label"] is not None:
        roles[str(info["chest_label"])] = "chest wall (its boundary with the breast: rib)"
    print(f"label volume {info['path']}: {' x '.join(map(str, info['image_shape']))} voxels of "
          f"{' x '.join(f'{v:.3g}' for v in info['voxel_size_mm'])} mm")
    axes = info["axes"]
    source = ("mesh.image.orientation (the header's direction set aside)"
              if axes["from"] != "header" else "the header's direction cosines")
    print(f"voxel axes i, j, k point {axes['code']}, by {source}; breast side {info['side']}")
    print(f"{'label':>6} {'voxels':>11} {'volume ml':>10}  role")
    for label, count in info["labels"].items():
        role = roles.get(label, "background" if label == "0" else "not used")
        print(f"{label:>6} {count:>11d} {count * voxel_ml:>10.1f}  {role}")
    print(f"meshed: {info['meshed_volume_ml']:.1f} ml of the labelled "
          f"{info['labelled_volume_ml']:.1f} ml, {info['fill']['method']}, worst dihedral "
          f"{info['quality_floor']['min_dihedral_deg']:.1f}°")
    for warning in info["warnings"]:
        print(f"warning: {warning}")


if __name__ == "__main__":
    sys.exit(main())
