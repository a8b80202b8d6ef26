"""Point evaluation of FE fields on other meshes, and displacement error measures.

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
    n_cells = mesh.topology.index_map(tdim).size_local
    tree = geometry.BoundingBoxTree(mesh, tdim)
    candidates = geometry.compute_collisions(tree, points)
    colliding = geometry.compute_colliding_cells(mesh, candidates, points)
    cells = np.full(len(points), -1, dtype=np.int32)
    for i in range(len(points)):
        links = colliding.links(i)
        if len(links):
            cells[i] = links[0]
    distance = np.zeros(len(points))
    outside = np.flatnonzero(cells < 0)
    if outside.size:
        midpoints = geometry.create_midpoint_tree(mesh, tdim, np.arange(n_cells, dtype=np.int32))
        nearest = geometry.compute_closest_entity(tree, midpoints, mesh, points[outside])
        cells[outside] = nearest
        distance[outside] = np.sqrt(
            geometry.squared_distance(mesh, tdim, nearest, points[outside])
        )
        log.debug(
            "%d of %d points outside the mesh, at most %.3g m away",
            outside.size, len(points), distance.max(),
        )
    values = u.eval(points, cells)
    return np.asarray(values).reshape(len(points), -1), distance


def vertex_values(problem: Any, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Displacement of a solved :class:`fem.problem.GravityProblem` at ``points``."""
    return evaluate(problem.displacement(), points)


def displacement_errors(u: np.ndarray, reference: np.ndarray) -> dict[str, float]:
    """Pointwise displacement errors against a reference (both (N, 3), metres).

    Returns:
        ``max_error_mm``, ``rms_error_mm``, ``mean_error_mm`` (the paper's Eq. 3),
        the reference's ``max_disp_mm`` and ``relative_max_error`` = max error /
        max |u_ref| (the accuracy target is 1 %).
    """
    err = np.linalg.norm(np.asarray(u) - np.asarray(reference), axis=1)
    scale = float(np.linalg.norm(reference, axis=1).max())
    return {
        "max_error_mm": 1e3 * float(err.max()),
        "rms_error_mm": 1e3 * float(np.sqrt(np.mean(err**2))),
        "mean_error_mm": 1e3 * float(err.mean()),
        "max_disp_mm": 1e3 * scale,
        "relative_max_error": float(err.max()) / scale if scale > 0 else float("nan"),
    }


def observed_rates(sizes: list[float], errors: list[float]) -> list[float]:
    """Convergence rates log(e_i / e_(i+1)) / log(h_i / h_(i+1)) between successive meshes."""
    rates = []
    for (h0, e0), (h1, e1) in zip(zip(sizes, errors), zip(sizes[1:], errors[1:])):
        rates.append(float(np.log(e0 / e1) / np.log(h0 / h1)) if e0 > 0 and e1 > 0 else float("nan"))
    return rates


def fitted_rate(sizes: list[float], errors: list[float]) -> float:
    """Least-squares slope of log(error) against log(h)."""
    h, e = np.log(np.asarray(sizes)), np.log(np.asarray(errors))
    return float(np.polyfit(h, e, 1)[0])


__all__ = ["displacement_errors", "evaluate", "fitted_rate", "observed_rates", "vertex_values"]
