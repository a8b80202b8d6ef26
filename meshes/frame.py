"""Carry named points between an imported file's own frame and the project's frame.

    .venv/bin/python -m meshes.frame config.yaml points.csv out.csv --to project|file [--voxels]

A CSV of named points (a header ``name,x,y,z``, then one point per row) in the file's axes and
units (``--to project``: e.g. a tumour's centre and margin picked in the image the mesh was
segmented from) is written in the project's frame in metres, where the case folders' fields
and the surrogate live; ``--to file`` goes back, e.g. to overlay predicted positions on the
image. The config's ``mesh.file`` says the file's units and orientation; the import does not
translate, so points map by the same linear map as the mesh. For a label volume
(``mesh.source: image``) the file's frame is the scanner's LPS millimetres of the image's
header; with ``--voxels`` the points are (continuous) voxel indices i, j, k of the image
instead, in (``--to project``: each within the image, voxel centres at 0 to n - 1) or out
(``--to file``). Exit status 2 names a bad config or CSV, a voxel outside the image, or an
output that would overwrite an input (the points, the config, the files it imports); nothing
is written then. A missing output folder is made.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from meshes.arguments import output_file, refuse_overwriting
from meshes.config import read_mesh_config
from meshes.exceptions import GeometryError, MeshInputError
from meshes.image_header import read_header
from meshes.points import read_points, write_points


def check_voxel_indices(names: list[str], index: np.ndarray, shape: tuple[int, ...],
                        points: Path, image: str | Path) -> None:
    """Refuse voxel indices that lie outside the image.

    Voxel ``i`` covers the indices from ``i - 0.5`` to ``i + 0.5``: the image spans -0.5 to
    ``n - 0.5`` along each axis.

    Raises:
        MeshInputError: naming the first point outside, its indices, how many are, and the
            image's size in voxels.
    """
    upper = np.asarray(shape, dtype=float) - 0.5
    outside = np.flatnonzero(np.any((index < -0.5) | (index > upper), axis=1))
    if len(outside):
        first = outside[0]
        at = ", ".join(f"{v:g}" for v in index[first])
        raise MeshInputError(
            f"{points}: point {first + 1} ({names[first]!r}) at voxel indices ({at}) lies "
            f"outside the image {image} of {' x '.join(map(str, shape))} voxels (indices from "
            f"-0.5 to {', '.join(f'{u:g}' for u in upper)} along i, j, k); {len(outside)} of "
            f"{len(names)} point(s) do: give voxel indices of this image")


def main(argv: list[str] | None = None) -> int:
    """Convert the points and write them."""
    parser = argparse.ArgumentParser(prog="python -m meshes.frame",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("config", type=Path,
                        help="a config file whose mesh.source is file or image")
    parser.add_argument("points", type=Path, help="CSV name,x,y,z")
    parser.add_argument("out", type=output_file, help="CSV to write")
    parser.add_argument("--to", choices=("project", "file"), required=True,
                        help="project: from the file's frame into the project's (m); "
                             "file: back")
    parser.add_argument("--voxels", action="store_true",
                        help="the file-side points are voxel indices of the label volume")
    args = parser.parse_args(argv)
    try:
        config = read_mesh_config(args.config)
        spec = config.imported
        if spec is None:
            raise GeometryError(f"{args.config}: mesh.source is parametric: the project's frame "
                                "is the geometry's own")
        refuse_overwriting(parser, "out", [args.out], [
            ("points", args.points), ("config", args.config),
            *[("a file of the config's mesh section", Path(p)) for p in spec.input_files()]])
        if args.voxels and config.image is None:
            raise GeometryError(f"{args.config}: --voxels needs mesh.source image (a label "
                                "volume whose header maps voxels to millimetres)")
        names, points = read_points(args.points)
        if args.to == "project":
            if args.voxels:
                check_voxel_indices(names, points, read_header(spec.path, spec.axes).shape,
                                    args.points, spec.path)
                points = spec.voxels_to_file_frame(points)
            out = spec.to_project_frame(points)
        else:
            out = spec.to_file_frame(points)
            if args.voxels:
                out = spec.file_frame_to_voxels(out)
        args.out.parent.mkdir(parents=True, exist_ok=True)
        write_points(args.out, names, out)
    except (OSError, GeometryError, MeshInputError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    unit = "m" if args.to == "project" else ("voxels" if args.voxels else spec.units)
    print(f"wrote {len(names)} points to {args.out} ({args.to} frame, {unit})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
