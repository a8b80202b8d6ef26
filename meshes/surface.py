"""The skin as a triangulated surface, and the distance of observed points from it.

An observation of the skin (a surface scan, the skin segmented from another image) is a point
cloud that does not sample the mesh's nodes; it is compared with a predicted shape by each
point's distance from the predicted skin surface. The skin is taken as the flat triangles on the
mesh's vertices (the nodes every prediction has), named by node index in the mesh file, so that
any set of node positions in file order (an FE field, a surrogate's prediction) gives the
surface.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from meshes.exceptions import MeshInputError
from meshes.io import boundary_facets
from meshes.tags import Boundary

#: Triangles (by nearest centroid) whose exact distance is computed for each point.
CANDIDATES = 16


def skin_triangles(mesh: Any, facet_tags: Any) -> np.ndarray:
    """The skin's triangles (T, 3) as vertex indices in the mesh file (serial mesh).

    Raises:
        MeshInputError: if no facet is tagged skin.
    """
    from dolfinx.cpp.mesh import entities_to_geometry

    facets = boundary_facets(facet_tags, [Boundary.SKIN])
    if facets.size == 0:
        raise MeshInputError("the mesh has no facet tagged skin")
    nodes = entities_to_geometry(mesh._mesh, mesh.topology.dim - 1, facets, False)[:, :3]
    index = np.asarray(mesh.geometry.input_global_indices, dtype=np.int64)
    return index[nodes]


def _segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    ab = b - a
    t = np.clip(np.einsum("ij,ij->i", p - a, ab) / np.maximum(np.einsum("ij,ij->i", ab, ab),
                                                               1e-300), 0.0, 1.0)
    return np.linalg.norm(p - (a + t[:, None] * ab), axis=1)


def point_triangle_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray
                            ) -> np.ndarray:
    """Distance of each point ``p[i]`` from the triangle ``(a[i], b[i], c[i])`` (all (n, 3)).

    The closest point is the projection onto the plane where that falls inside the triangle,
    else the closest point of one of its edges.
    """
    n = np.cross(b - a, c - a)
    area2 = np.einsum("ij,ij->i", n, n)
    inside = np.zeros(len(p), dtype=bool)
    plane = np.full(len(p), np.inf)
    ok = area2 > 0
    if np.any(ok):
        q = p[ok] - a[ok]
        nn = n[ok]
        s = np.einsum("ij,ij->i", q, nn) / area2[ok]
        x = p[ok] - s[:, None] * nn  # the projection
        # barycentric signs from the sub-triangle orientations
        w = [np.einsum("ij,ij->i", np.cross(v1 - x, v2 - x), nn)
             for v1, v2 in ((b[ok], c[ok]), (c[ok], a[ok]), (a[ok], b[ok]))]
        inside[ok] = (w[0] >= 0) & (w[1] >= 0) & (w[2] >= 0)
        plane[ok] = np.abs(s) * np.sqrt(area2[ok])
    edges = np.minimum(np.minimum(_segment_distance(p, a, b), _segment_distance(p, b, c)),
                       _segment_distance(p, c, a))
    return np.where(inside, np.minimum(plane, edges), edges)


def distance_to_surface(points: np.ndarray, nodes: np.ndarray, triangles: np.ndarray,
                        candidates: int = CANDIDATES) -> np.ndarray:
    """Each point's distance from the triangulated surface.

    Args:
        points: (n, 3) observed points.
        nodes: (N, 3) node positions, indexed by ``triangles``.
        triangles: (T, 3) node indices.
        candidates: triangles, nearest by centroid, tested exactly per point.
    """
    from scipy.spatial import cKDTree

    points = np.asarray(points, dtype=float)
    corners = nodes[triangles]  # (T, 3, 3)
    k = min(candidates, len(triangles))
    _, near = cKDTree(corners.mean(axis=1)).query(points, k=k)
    near = near.reshape(len(points), k)
    p = np.repeat(points, k, axis=0)
    tri = corners[near.ravel()]
    d = point_triangle_distance(p, tri[:, 0], tri[:, 1], tri[:, 2])
    return d.reshape(len(points), k).min(axis=1)


__all__ = ["CANDIDATES", "distance_to_surface", "point_triangle_distance", "skin_triangles"]
