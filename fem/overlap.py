"""Self-overlap of the deformed body: has the solution pushed tissue through itself?

The model has no contact: nothing stops one part of the body from passing through
another. Where the mound folds onto the skin layer (supine, soft tissue, a sharp
crease) a mesh fine enough to resolve the fold shows the mound's underside moving
into the layer, a solution of the equations that no real breast can take. This
module detects it after a solve: a boundary vertex of the deformed mesh that lies
inside a deformed cell it is not a vertex of.
"""

from __future__ import annotations

import logging
from typing import Any

import numpy as np

from meshes.io import geometry_nodes
from meshes.quadratic import curved_coordinates, edge_order

log = logging.getLogger(__name__)

__all__ = ["geometry_displacement", "self_overlap"]

_INSIDE = 1e-9
"""Smallest barycentric coordinate of a point strictly inside a cell (not on its faces)."""


def geometry_displacement(mesh: Any, displacement: Any) -> np.ndarray:
    """``displacement`` at the mesh's geometry nodes, shape (nodes, 3).

    The field is interpolated into the Lagrange space of the coordinate element, whose
    per-cell dofs sit on the cell's geometry nodes in the same order (checked).
    """
    from dolfinx import fem

    degree = mesh.geometry.cmap.degree
    V = fem.VectorFunctionSpace(mesh, ("Lagrange", degree))
    w = fem.Function(V)
    w.interpolate(displacement)
    nodes = geometry_nodes(mesh)
    dofs = V.dofmap.list.array.reshape(nodes.shape[0], -1)
    x = mesh.geometry.x
    if nodes.shape != dofs.shape or not np.allclose(
        V.tabulate_dof_coordinates()[dofs], x[nodes], rtol=0, atol=1e-12
    ):
        raise RuntimeError("the displacement's dofs do not sit on the mesh's geometry nodes")
    values = np.zeros_like(x)
    values[nodes] = w.x.array.reshape(-1, 3)[dofs]
    return values


def self_overlap(mesh: Any, displacement: Any) -> dict[str, Any]:
    """Boundary vertices of the deformed mesh that lie inside a cell they do not belong to.

    Candidate cells come from dolfinx's bounding-box tree of the deformed mesh (which is
    moved by ``displacement`` for the search and restored afterwards); a vertex is inside
    a cell if its barycentric coordinates in the cell are all positive: in the straight
    tetrahedron through the cell's deformed vertices, and, for a curved (second-order) cell,
    in the cell's own quadratic map (Newton's method from the straight coordinates), which a
    crease bends: a vertex inside the straight tetrahedron of a curved cell but outside the
    cell is not inside, and one inside a cell that bulges past its straight tetrahedron is.

    Args:
        mesh: a serial dolfinx mesh (the reference configuration).
        displacement: a vector field on it (any Lagrange degree).

    Returns:
        ``boundary_vertices`` (how many were tested), ``overlapping_vertices`` (how many
        lie inside a cell of which they are not a vertex) and ``examples_m`` (up to five of
        them, in the reference configuration, metres).

    Raises:
        ValueError: if the mesh is distributed (a vertex could overlap a cell of another
            process, which this search does not see).
    """
    from dolfinx import geometry
    from dolfinx import mesh as dmesh
    from dolfinx.cpp.mesh import entities_to_geometry

    if mesh.comm.size > 1:
        raise ValueError("self_overlap() is serial only")
    tdim = mesh.topology.dim
    mesh.topology.create_connectivity(tdim - 1, tdim)
    facets = dmesh.exterior_facet_indices(mesh.topology)
    boundary = np.unique(entities_to_geometry(mesh._mesh, tdim - 1, facets, False)[:, :tdim])
    nodes = geometry_nodes(mesh)
    cell_vertices = nodes[:, : tdim + 1]  # a cell's vertices are its first nodes

    x0 = mesh.geometry.x.copy()
    x = x0 + geometry_displacement(mesh, displacement)
    points = np.ascontiguousarray(x[boundary])
    try:  # the bounding boxes of the deformed cells
        mesh.geometry.x[:] = x
        candidates = geometry.compute_collisions(geometry.BoundingBoxTree(mesh, tdim), points)
    finally:
        mesh.geometry.x[:] = x0
    # every (boundary vertex, candidate cell) pair, minus the cells the vertex belongs to
    point = np.repeat(np.arange(len(boundary)), np.diff(candidates.offsets))
    cell = candidates.array.astype(np.int64)
    own = np.any(cell_vertices[cell] == boundary[point][:, None], axis=1)
    point, cell = point[~own], cell[~own]
    # barycentric coordinates in the straight tetrahedron through the cell's deformed vertices
    corners = x[cell_vertices[cell]]  # (pairs, 4, 3)
    edges = np.transpose(corners[:, 1:] - corners[:, :1], (0, 2, 1))  # columns x1-x0, x2-x0, x3-x0
    ok = np.abs(np.linalg.det(edges)) > 0
    lam = np.zeros((len(cell), 3))
    lam[ok] = np.linalg.solve(edges[ok], (points[point[ok]] - corners[ok, 0])[..., None])[..., 0]
    bary = np.column_stack([1 - lam.sum(axis=1), lam])
    if mesh.geometry.cmap.degree == 2:  # the curved cell's own map decides
        pairs = edge_order(x0, nodes[:1])
        bary, gap = curved_coordinates(x[nodes[cell]], points[point], bary, pairs)
        size = np.linalg.norm(np.ptp(x[nodes[cell]], axis=1), axis=1)
        ok = np.isfinite(gap) & (gap <= 1e-9 * size)  # the map reaches the point
    strictly_inside = ok & (bary.min(axis=1) > _INSIDE)
    overlapping = np.unique(boundary[point[strictly_inside]])
    if len(overlapping):
        log.warning(
            "the deformed body overlaps itself: %d of %d boundary vertices lie inside other cells",
            len(overlapping), len(boundary),
        )
    return {
        "boundary_vertices": int(len(boundary)),
        "overlapping_vertices": int(len(overlapping)),
        "examples_m": [x0[v].tolist() for v in overlapping[:5]],
    }
