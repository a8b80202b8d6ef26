"""Benchmark: where a sweep's gravity directions are too sparse, whatever the surrogate.

A surrogate answers between the sweep's directions by interpolating what the FE cases say at
them; where the field changes faster with direction than the directions are spaced, no model of
the data can be right between them. This measures that limit from the dataset alone, without a
network: at each C1 value, each direction's FE field is left out in turn and interpolated from
the other directions' fields at the same C1 by a radial-basis interpolant on the unit sphere of
directions (scipy's ``RBFInterpolator``, a cubic kernel with a linear tail: exact for a field
linear in ĝ, the small-deformation limit), each field divided by its case's compliance gain
1/C1 as the surrogate's targets are. The error at the left-out direction is the sweep's own
spacing error there, in a hole one direction wide: what the ``by_direction`` held-out split
measures of a trained model, which therefore cannot do much better where this is large.

Per C1 value the table gives the number of directions, the median and the largest over them of
the left-out direction's largest point error (mm), and the worst direction with the angle to
its nearest neighbour; the directions whose largest point error exceeds ``--limit`` are where
an adaptive sweep adds directions, and the C1 values at which they occur are where it needs
them. ``--propose K`` prints K such directions (:func:`propose`): the midpoints of the sweep's
direction triangles' edges whose ends err most, over the C1 values where any direction exceeds
the limit.

``python -m benchmarks.direction_spacing_error DATASET [--limit 0.5] [--propose K] [--json OUT]``
prints the table.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fem.adaptive import direction_angles
from fem.dataset import Dataset, read_dataset
from fem.directions import direction_keys
from fem.exceptions import DatasetError
from studies.results import Record, Result

KERNEL = "cubic"
"""The interpolant's radial function (with a linear polynomial tail)."""
DEFAULT_LIMIT_MM = 0.5
"""The largest point error (mm) a direction may have between its neighbours: issue 23's."""


@dataclass(frozen=True, slots=True)
class LeftOut(Record):
    """One direction at one C1, interpolated from the others.

    Attributes:
        case: the left-out case.
        phi, theta: its direction (degrees).
        nearest_deg: the angle to the nearest direction left in.
        mean_mm, max_mm: its point errors (mean, largest), mm.
        fe_max_mm: its largest FE displacement, mm.
    """

    case: str
    phi: float
    theta: float
    nearest_deg: float
    mean_mm: float
    max_mm: float
    fe_max_mm: float


@dataclass(frozen=True, slots=True)
class AtStiffness(Record):
    """Every direction of one C1 value left out in turn.

    Attributes:
        C1: kPa.
        directions: its converged directions.
        median_max_mm: the median over them of the largest point error.
        max_mm: the largest point error of any.
        over_limit: the directions whose largest point error exceeds the limit.
        rows: per direction, worst first.
    """

    C1: float
    directions: int
    median_max_mm: float
    max_mm: float
    over_limit: int
    rows: list[LeftOut]


@dataclass(frozen=True, slots=True)
class DirectionGaps(Result):
    """The sweep's spacing error between its directions, by C1 (the module's docstring)."""

    kernel: str
    limit_mm: float
    stiffness: list[AtStiffness]


def leave_one_out(ds: Dataset, C1: float, limit_mm: float = DEFAULT_LIMIT_MM) -> AtStiffness:
    """Each converged direction at ``C1`` interpolated from the others (see the module).

    Raises:
        ValueError: if fewer than five directions converged at ``C1`` (the interpolant's linear
            tail needs four, and one is left out).
    """
    from scipy.interpolate import RBFInterpolator

    cases = np.flatnonzero(np.isclose(ds.C1, C1) & ds.converged)
    # one case per direction: a direction under two names (the pole at every θ) is one node
    _, first = np.unique(direction_keys(ds.phi[cases], ds.theta[cases]), return_index=True)
    cases = cases[np.sort(first)]
    if len(cases) < 5:
        raise ValueError(f"C1 = {C1:g} kPa has {len(cases)} converged directions; leaving one "
                         "out needs five")
    g = ds.direction[cases] / np.linalg.norm(ds.direction[cases], axis=1)[:, None]
    scaled = (ds.displacement[cases] * C1).reshape(len(cases), -1)
    rows = []
    for k, case in enumerate(cases):
        keep = np.delete(np.arange(len(cases)), k)
        guess = RBFInterpolator(g[keep], scaled[keep], kernel=KERNEL, degree=1)(g[k:k + 1])
        error = np.linalg.norm((guess - scaled[k]).reshape(-1, 3), axis=1) / C1
        nearest = np.degrees(np.arccos(np.clip(g[keep] @ g[k], -1.0, 1.0))).min()
        rows.append(LeftOut(str(ds.ids[case]), float(ds.phi[case]), float(ds.theta[case]),
                            float(nearest), float(error.mean()), float(error.max()),
                            float(np.linalg.norm(ds.displacement[case], axis=1).max())))
    rows.sort(key=lambda r: -r.max_mm)
    worst = np.array([r.max_mm for r in rows])
    return AtStiffness(float(C1), len(rows), float(np.median(worst)), float(worst.max()),
                       int(np.sum(worst > limit_mm)), rows)


def direction_spacing_error(ds: Dataset, C1s: Sequence[float] | None = None,
                   limit_mm: float = DEFAULT_LIMIT_MM) -> DirectionGaps:
    """:func:`leave_one_out` at every C1 value of the dataset (or ``C1s``), softest first."""
    values = np.unique(np.round(ds.C1[ds.converged], 6)) if C1s is None else C1s
    return DirectionGaps(KERNEL, float(limit_mm),
                         [leave_one_out(ds, float(c), limit_mm) for c in sorted(values)])


SEPARATION_DEG = 5.0
"""Proposed directions closer than this to one another or to the sweep's are dropped."""


def propose(ds: Dataset, gaps: DirectionGaps, k: int) -> list[tuple[float, float]]:
    """``k`` directions (Φ, θ in degrees) to add where the sweep's spacing errs most.

    The sweep's directions are triangulated on the sphere (the facets of their convex hull; the
    flat facets across a hemisphere the sweep leaves out are skipped), and each edge's midpoint
    is a candidate, scored by the larger of its two ends' largest point error, the worst over
    the C1 values at which any direction exceeds the limit. The best ``k`` are taken, none
    within :data:`SEPARATION_DEG` of another or of the sweep's directions.
    """
    from scipy.spatial import ConvexHull

    soft = [s for s in gaps.stiffness if s.over_limit]
    if not soft or k < 1:
        return []
    score: dict[str, float] = {}
    for s in soft:
        angles = np.array([(r.phi, r.theta) for r in s.rows])
        for key, row in zip(direction_keys(angles[:, 0], angles[:, 1]), s.rows, strict=True):
            score[key] = max(score.get(key, 0.0), row.max_mm)
    keys = direction_keys(ds.phi, ds.theta)
    _, first = np.unique(keys, return_index=True)
    g = ds.direction[first] / np.linalg.norm(ds.direction[first], axis=1)[:, None]
    errs = np.array([score.get(keys[i], 0.0) for i in first])
    hull = ConvexHull(g)
    edges: dict[tuple[int, int], float] = {}
    for simplex, normal in zip(hull.simplices, hull.equations[:, :3], strict=True):
        if abs(normal @ g[simplex].mean(axis=0)) < 0.5:  # a flat facet across a missing half
            continue
        for a, b in ((0, 1), (1, 2), (0, 2)):
            i, j = sorted((int(simplex[a]), int(simplex[b])))
            edges[(i, j)] = max(errs[i], errs[j])
    chosen: list[np.ndarray] = []
    separation = np.cos(np.radians(SEPARATION_DEG))
    for (i, j), _ in sorted(edges.items(), key=lambda item: -item[1]):
        mid = (g[i] + g[j]) / np.linalg.norm(g[i] + g[j])
        if np.max(g @ mid) > separation or any(mid @ c > separation for c in chosen):
            continue
        chosen.append(mid)
        if len(chosen) == k:
            break
    return [direction_angles(c) for c in chosen]


def main(argv: list[str] | None = None) -> int:
    """Command line: see the module's docstring."""
    parser = argparse.ArgumentParser(prog="python -m benchmarks.direction_spacing_error",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("dataset", type=Path)
    parser.add_argument("--c1", type=float, nargs="+", help="these C1 values only (kPa)")
    parser.add_argument("--limit", type=float, default=DEFAULT_LIMIT_MM,
                        help="largest point error (mm) a direction may have between the others")
    parser.add_argument("--propose", type=int, default=0, metavar="K",
                        help="print K directions to add where the spacing errs most")
    parser.add_argument("--json", type=Path, help="write the table here too")
    args = parser.parse_args(argv)
    try:
        ds = read_dataset(args.dataset)
        gaps = direction_spacing_error(ds, args.c1, args.limit)
    except (DatasetError, ValueError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    print(f"each direction left out and interpolated from the others at its C1 ({gaps.kernel} "
          f"RBF on the sphere of directions); largest point error in mm")
    print(f"{'C1 kPa':>7} {'dirs':>5} {'median':>7} {'max':>7} {'> ' + str(args.limit):>6}  "
          "worst direction (phi/theta, nearest neighbour)")
    for s in gaps.stiffness:
        w = s.rows[0]
        print(f"{s.C1:7.2f} {s.directions:5d} {s.median_max_mm:7.3f} {s.max_mm:7.3f} "
              f"{s.over_limit:6d}  {w.phi:.1f}/{w.theta:.1f} ({w.nearest_deg:.0f}°)")
    if args.propose:
        added = propose(ds, gaps, args.propose)
        print(f"{len(added)} directions to add (phi, theta in degrees), for the C1 values above "
              f"with a direction over {args.limit} mm: {[list(d) for d in added]}")
    if args.json:
        gaps.write(args.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())
