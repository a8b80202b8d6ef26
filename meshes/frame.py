"""Carry named points between an imported file's own frame and the project's frame.

    .venv/bin/python -m meshes.frame config.yaml points.csv out.csv --to project|file

A CSV of named points (a header ``name,x,y,z``, then one point per row) in the file's axes and
units (``--to project``: e.g. a tumour's centre and margin picked in the image the mesh was
segmented from) is written in the project's frame in metres, where the case folders' fields
and the surrogate live; ``--to file`` goes back, e.g. to overlay predicted positions on the
image. The config's ``mesh.file`` says the file's units and orientation; the import does not
translate, so points map by the same linear map as the mesh. Exit status 2 names a bad config
or CSV.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from meshes.config import read_mesh_config
from meshes.exceptions import GeometryError, MeshInputError
from meshes.points import read_points, write_points


def main(argv: list[str] | None = None) -> int:
    """Convert the points and write them."""
    parser = argparse.ArgumentParser(prog="python -m meshes.frame",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("config", type=Path, help="a config file whose mesh.source is file")
    parser.add_argument("points", type=Path, help="CSV name,x,y,z")
    parser.add_argument("out", type=Path, help="CSV to write")
    parser.add_argument("--to", choices=("project", "file"), required=True,
                        help="project: from the file's frame into the project's (m); "
                             "file: back")
    args = parser.parse_args(argv)
    try:
        config = read_mesh_config(args.config)
        if config.file is None:
            raise GeometryError(f"{args.config}: mesh.source is not file: the project's frame "
                                "is the geometry's own")
        names, points = read_points(args.points)
    except (OSError, GeometryError, MeshInputError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    spec = config.file
    out = spec.to_project_frame(points) if args.to == "project" else spec.to_file_frame(points)
    write_points(args.out, names, out)
    unit = "m" if args.to == "project" else spec.units
    print(f"wrote {len(names)} points to {args.out} ({args.to} frame, {unit})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
