"""The FE displacement of a solved case at named points inside the body.

    .venv/bin/python -m studies.reference_state.fe_at_points results/cases/c1=1.00_phi=0.0_theta=0.0
    tumour.csv \
        [-o tumour_supine_fe.csv] [--from results/cases/c1=1.00_phi=180.0_theta=0.0]

The FE counterpart of ``surrogate.cli predict --points``: the case's displacement (its
``fields.h5``, given at every node of the mesh) interpolated at the points by the mesh's own
shape functions (quadratic on a quadratic mesh, as the FE field is), printed in the same table,
and the points' positions in the case's posture written with ``-o`` as a ``name,x,y,z`` CSV. Any
case folder will do: the sweep's, one of ``fem.cli`` or of ``fem.chain`` (where the surrogate
warns). The points are material points in the mesh's frame, m. A case that did not converge is
refused: its fields are those of a part of the load. With ``--from`` another solved case (of
the same body, usually the same C1 in another posture) it also prints each point's movement
from that case's posture to this one's, as ``surrogate.cli predict --from-phi`` does. Exit
status 2 names what cannot be used.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from fem.case_files import read_node_displacement
from fem.exceptions import DatasetError
from fem.io import SUMMARY_NAME
from meshes.exceptions import MeshInputError
from meshes.points import moved_table, movement_table, read_points, write_points
from surrogate.exceptions import OutsideMeshError
from surrogate.interpolation import interpolate, locate_in


class CasePointsError(ValueError):
    """The case folder cannot answer: no summary, or a solve that did not converge."""


def fe_at_points(case: str | Path, points: np.ndarray) -> np.ndarray:
    """The converged case's FE displacement (mm) at material points ``points`` (M, 3), m.

    Raises:
        CasePointsError: for a folder without ``summary.json`` or a case that did not converge.
        fem.exceptions.DatasetError: for fields that cannot be read.
        surrogate.exceptions.OutsideMeshError: for a point more than 1 mm outside the mesh.
    """
    case = Path(case)
    try:
        summary = json.loads((case / SUMMARY_NAME).read_text())
    except (OSError, ValueError) as err:
        raise CasePointsError(f"{case}: not a solved case ({err})") from None
    if summary.get("status") != "converged":
        raise CasePointsError(
            f"{case}: the case did not converge ({summary.get('reason')}): its fields are at "
            f"{100 * float(summary.get('load_fraction') or 0):.0f} % of the load")
    u, cells, nodes = read_node_displacement(case / "fields.h5")
    return 1e3 * interpolate(u, *locate_in(nodes, cells, points))


def main(argv: list[str] | None = None) -> int:
    """Print (and write) the points' FE displacement; returns the exit status."""
    parser = argparse.ArgumentParser(prog="python -m studies.reference_state.fe_at_points",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("case", type=Path, help="a solved case's folder")
    parser.add_argument("points", type=Path, help="CSV name,x,y,z of material points, m")
    parser.add_argument("-o", "--output", type=Path,
                        help="write the points' positions in the case's posture (CSV)")
    parser.add_argument("--from", dest="since", type=Path, metavar="CASE",
                        help="another solved case: also print the points' movement from its "
                             "posture to this case's")
    args = parser.parse_args(argv)
    if args.output is not None and (args.output.suffix != ".csv"
                                    or not args.output.parent.is_dir()):
        print(f"error: --output {args.output} must be a .csv in a folder that exists",
              file=sys.stderr)
        return 2
    names: list[str] = []
    try:
        names, points = read_points(args.points)
        u = fe_at_points(args.case, points)
        u_since = None if args.since is None else fe_at_points(args.since, points)
    except OutsideMeshError as err:
        print(f"error: {err.naming(names)}", file=sys.stderr)
        return 2
    except (CasePointsError, DatasetError, MeshInputError, OSError, ValueError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    print(moved_table(names, points, u))
    if u_since is not None:
        print(f"\nmoved from {args.since.name} to {args.case.name}:")
        print(movement_table(names, u - u_since))
    if args.output is not None:
        write_points(args.output, names, points + 1e-3 * u)
        print(f"wrote {args.output}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
