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
import csv
import math
import sys
from pathlib import Path

import numpy as np

from meshes.config import read_mesh_config
from meshes.exceptions import GeometryError, MeshInputError

HEADER = ["name", "x", "y", "z"]


def read_points(path: Path) -> tuple[list[str], np.ndarray]:
    """Names and coordinates (n, 3) of a ``name,x,y,z`` CSV.

    Raises:
        MeshInputError: naming the file and the row for a missing header, a short row or a
            coordinate that is not a finite number.
    """
    with path.open(newline="") as f:
        rows = list(csv.reader(f))
    if not rows or [c.strip().lower() for c in rows[0]] != HEADER:
        raise MeshInputError(f"{path}: the first row must be the header {','.join(HEADER)}")
    names, points = [], []
    for number, row in enumerate(rows[1:], start=2):
        if not row:
            continue
        if len(row) != 4:
            raise MeshInputError(f"{path}, row {number}: expected name,x,y,z, got {row!r}")
        try:
            xyz = [float(v) for v in row[1:]]
        except ValueError:
            xyz = [math.nan]
        if not all(math.isfinite(v) for v in xyz):
            raise MeshInputError(f"{path}, row {number} ({row[0]!r}): coordinates must be "
                                 f"finite numbers, got {row[1:]!r}")
        names.append(row[0])
        points.append(xyz)
    if not names:
        raise MeshInputError(f"{path}: no points below the header")
    return names, np.array(points)


def write_points(path: Path, names: list[str], points: np.ndarray) -> None:
    """Write a ``name,x,y,z`` CSV."""
    with path.open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(HEADER)
        for name, p in zip(names, points, strict=True):
            writer.writerow([name, *(repr(float(v)) for v in p)])


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
