"""Point evaluation of FE fields at arbitrary points, on this or another mesh of the same body.

Discretisations are compared at the *material points* (the vertices of the
default mesh, as in the dataset): every solution, whatever its mesh and element,
is evaluated at those points and compared with a reference evaluated there.

Two meshes of the same curved geometry do not cover exactly the same region (each
approximates the curved skin by its own facets), so a material point on the skin
of one mesh may lie a fraction of an element outside the other. Such points are
evaluated in the nearest cell, i.e. by extrapolating its polynomial over that
small distance, and the distance is reported.
"""

from __future__ import annotations

import logging
from typing import Any

import numpy as np
from dolfinx import fem, geometry

log = logging.getLogger(__name__)


def evaluate(u: fem.Function, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Values of ``u`` at ``points`` (serial meshes only).

    Args:
        u: a function on a mesh held entirely by this process.
        points: (N, 3) coordinates.

    Returns:
        ``(values, distance)``: (N, value size) values and, per point, its distance
        from the cell it was evaluated in (0 inside the mesh).

    Raises:
        ValueError: under MPI with more than one process (cells would be split).
    """
    mesh = u.function_space.mesh
    if mesh.comm.size > 1:
        raise ValueError("evaluate() needs the whole mesh on one process")
    points = np.ascontiguousarray(points, dtype=np.float64)
    tdim = mesh.topology.dim
    tree = geometry.BoundingBoxTree(mesh, tdim)
    cells = _colliding_cells(mesh, tree, points)
    distance = np.zeros(len(points))
    outside = np.flatnonzero(cells < 0)
    if outside.size:
        nearest = _closest_cells(mesh, tree, points[outside])
        cells[outside] = nearest
        try:
            distance[outside] = np.sqrt(
                geometry.squared_distance(mesh, tdim, nearest, points[outside])
            )
        except RuntimeError:  # GJK again: the distance is only reported, so bound it
            distance[outside] = [
                np.linalg.norm(mesh.geometry.x[mesh.geometry.dofmap.links(c)] - x, axis=1).min()
                for c, x in zip(nearest, points[outside], strict=True)
            ]
        log.debug(
            "%d of %d points outside the mesh, at most %.3g m away",
            outside.size,
            len(points),
            distance.max(),
        )
    values = u.eval(points, cells)
    return np.asarray(values).reshape(len(points), -1), distance


def _most_inside_cell(mesh: Any, tree: Any, x: np.ndarray) -> int:
    """The candidate cell that holds ``x`` best, or the nearest by centroid.

    Best: the largest smallest barycentric coordinate of ``x`` in the cell's vertex
    tetrahedron, among the bounding-box candidates.

    The fallback for a point whose exact (GJK) location fails: it needs no GJK, it is
    exact for straight cells, and for a curved cell it picks a cell at or next to the
    point, whose polynomial extends continuously to it.
    """
    dofmap, nodes = mesh.geometry.dofmap, mesh.geometry.x
    candidates = geometry.compute_collisions(tree, x[None, :]).links(0)
    if len(candidates) == 0:
        candidates = np.arange(mesh.topology.index_map(mesh.topology.dim).size_local)
    best, score = -1, -np.inf
    for cell in candidates:
        v = nodes[dofmap.links(cell)[:4]]
        try:
            lam = np.linalg.solve((v[1:] - v[0]).T, x - v[0])
        except np.linalg.LinAlgError:
            continue
        inside = min(1.0 - lam.sum(), lam.min())
        if inside > score:
            best, score = int(cell), inside
    return best


def _colliding_cells(mesh: Any, tree: Any, points: np.ndarray) -> np.ndarray:
    """A cell containing each point, -1 where none does.

    dolfinx's exact point-in-cell test (GJK) can fail to converge ("max iteration limit
    reached"), and the whole call fails with it; the points are then located one by one,
    and a point that still fails by :func:`_most_inside_cell`.
    """

    def first(colliding: Any, n: int) -> np.ndarray:
        return np.array(
            [colliding.links(i)[0] if len(colliding.links(i)) else -1 for i in range(n)],
            dtype=np.int32,
        )

    try:
        candidates = geometry.compute_collisions(tree, points)
        return first(geometry.compute_colliding_cells(mesh, candidates, points), len(points))
    except RuntimeError as err:
        log.debug("point location failed (%s); locating points one by one", err)
    cells = np.full(len(points), -1, dtype=np.int32)
    for i, x in enumerate(points):
        one = points[i : i + 1]
        try:
            candidates = geometry.compute_collisions(tree, one)
            cells[i] = first(geometry.compute_colliding_cells(mesh, candidates, one), 1)[0]
        except RuntimeError:
            cells[i] = _most_inside_cell(mesh, tree, x)
    return cells


def _closest_cells(mesh: Any, tree: Any, points: np.ndarray) -> np.ndarray:
    """The nearest cell to each point (for points outside the mesh), GJK-failure safe."""
    tdim = mesh.topology.dim
    n_cells = mesh.topology.index_map(tdim).size_local
    midpoints = geometry.create_midpoint_tree(mesh, tdim, np.arange(n_cells, dtype=np.int32))
    try:
        return np.asarray(
            geometry.compute_closest_entity(tree, midpoints, mesh, points), dtype=np.int32
        )
    except RuntimeError as err:
        log.debug("closest-cell search failed (%s); using the most-inside cell", err)
    return np.array([_most_inside_cell(mesh, tree, x) for x in points], dtype=np.int32)


def vertex_values(problem: Any, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Displacement of a solved :class:`fem.problem.GravityProblem` at ``points``."""
    return evaluate(problem.displacement(), points)


__all__ = ["evaluate", "vertex_values"]
