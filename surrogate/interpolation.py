"""Fields given at a mesh's nodes, between them: its tetrahedra's shape functions.

A ``pod`` surrogate's modes are known at the mesh's nodes; it answers at another point, such as
a tumour's material position, by the shape functions of the tetrahedron that holds it
(:meth:`surrogate.predict.Surrogate.at`): the linear ones of its corners (:func:`locate`) where
the modes are known at the vertices only, the quadratic ones of its ten nodes
(:func:`locate_quadratic`) where they are known at every node of a quadratic mesh, as the FE
field is. The quadratic cells may be curved (edge nodes on the skin): a point's reference
coordinates in its cell are then found by Newton's method on the cell's map.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from meshes.quadratic import curved_coordinates, edge_order, quadratic_weights
from surrogate.exceptions import OutsideMeshError

CANDIDATES = 8
"""Cells whose centroids are nearest a point, among which the one that holds it is sought
when the nearest does not; eight times as many each time none of them does
(:func:`_cells_holding`)."""
BLOCK = 65_536
"""Points searched at once: bounds the search's memory to a few tens of megabytes a block."""
INSIDE = 1e-9
"""How far below zero a barycentric coordinate may fall for its cell still to hold a point."""
OUTSIDE_M = 1e-3
"""How far outside the mesh (m) a point may lie and still be answered, on its nearest cell's
face: a point on the curved skin lies up to a fraction of a millimetre outside the straight-sided
cells of its vertices."""


NEWTON_STEPS = 8
"""Newton steps that invert a curved cell's map (it is nearly affine: two or three suffice)."""


def at_centroids(u: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """A quadratic field given at the nodes, at each cell's centroid: (..., cells, 3).

    ``u`` (..., nodes, 3) is given at the nodes of 10-node tetrahedra ``cells`` (C, 10),
    corners first. At the barycentre every corner shape function is -1/8 and every edge one
    1/4, whatever the order of the edges; a curved cell's centroid (the image of the reference
    cell's) is the same combination of its nodes' positions.

    Raises:
        ValueError: if ``cells`` are not 10-node tetrahedra.
    """
    cells = np.asarray(cells)
    if cells.ndim != 2 or cells.shape[1] != 10:
        raise ValueError(f"centroids of a quadratic field need 10-node cells, got shape "
                         f"{cells.shape}")
    return -0.125 * u[..., cells[:, :4], :].sum(-2) + 0.25 * u[..., cells[:, 4:], :].sum(-2)


def locate(X: np.ndarray, cells: np.ndarray, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each point's tetrahedron corners and their linear shape functions there.

    Args:
        X: the mesh's vertices (N, 3), m.
        cells: its tetrahedra as rows of ``X`` (C, 4).
        points: where to interpolate (M, 3), m.

    Returns:
        ``(rows (M, 4), weights (M, 4))``: a field ``f`` (N, ...) at the points is
        ``Σ_j weights[:, j] f[rows[:, j]]``. A point inside no cell but within
        :data:`OUTSIDE_M` of one gets that cell's weights clipped to it.

    Raises:
        OutsideMeshError: naming how many points lie farther outside the mesh, and the
            farthest.
    """
    which, weights = _cells_holding(X, cells, points)
    return cells[which], weights


def _cells_holding(X: np.ndarray, cells: np.ndarray, points: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Each point's cell (M,) and its barycentric coordinates there (M, 4): see :func:`locate`.

    A search that cannot miss: a cell that holds a point has its centroid within the mesh's
    largest centroid-to-corner distance (its reach) of it, so each point's candidates, nearest
    centroid first, are widened (1, then :data:`CANDIDATES`, then eight times as many each
    round) until one holds the point or every centroid within the reach (and
    :data:`OUTSIDE_M` beyond it) has been tried; the latter points lie outside the mesh, and
    the cell they are nearest inside is kept for the gap. Each cell's affine map is inverted
    once; points go in blocks of :data:`BLOCK`, so memory stays bounded for any number.
    """
    from scipy.spatial import cKDTree

    X, points = np.asarray(X, dtype=float), np.asarray(points, dtype=float)
    cells_map = _CellMaps(X[cells])
    tree = cKDTree(cells_map.centroids)
    which = np.zeros(len(points), dtype=np.int64)
    bary = np.zeros((len(points), 4))
    for start in range(0, len(points), BLOCK):
        block = slice(start, start + BLOCK)
        which[block], bary[block] = cells_map.search(tree, points[block])
    weights = np.clip(bary, 0.0, None)
    weights /= weights.sum(axis=1, keepdims=True)
    rows = cells[which]
    gap = np.linalg.norm(np.einsum("mj,mjd->md", weights, X[rows]) - points, axis=1)
    outside = gap > OUTSIDE_M
    if outside.any():
        raise OutsideMeshError(
            f"{int(outside.sum())} of {len(points)} points lie outside the mesh by more than "
            f"{1e3 * OUTSIDE_M:g} mm (the farthest {1e3 * gap.max():.1f} mm, point "
            f"{int(np.argmax(gap))}): fields are known inside the body only",
            {int(i): float(gap[i]) for i in np.flatnonzero(outside)}, OUTSIDE_M)
    return which, weights


class _CellMaps:
    """The tetrahedra's affine maps, inverted once: barycentric coordinates by a product."""

    def __init__(self, corners: np.ndarray) -> None:
        self.origin = corners[:, 0]
        self.centroids = corners.mean(axis=1)
        self.reach = float(np.linalg.norm(corners - self.centroids[:, None], axis=-1).max()) \
            + OUTSIDE_M
        e = corners[:, 1:] - corners[:, :1]  # rows v_j - v_0
        # the inverse of the matrix whose columns are the edges, by cross products (no LAPACK
        # call per cell): its rows are (e2 × e3, e3 × e1, e1 × e2) / det
        rows = np.stack([np.cross(e[:, 1], e[:, 2]), np.cross(e[:, 2], e[:, 0]),
                         np.cross(e[:, 0], e[:, 1])], axis=1)
        det = np.einsum("cj,cj->c", e[:, 0], rows[:, 0])
        self.flat = np.abs(det) <= 1e-12 * np.abs(e).max(axis=(1, 2))**3  # no volume
        self.inverse = rows / np.where(self.flat, 1.0, det)[:, None, None]

    def coordinates(self, cell: np.ndarray, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Barycentric coordinates of ``points`` (..., 3) in ``cell`` (...), and their least.

        The least is -inf in a cell without volume.
        """
        lam = np.einsum("...ij,...j->...i", self.inverse[cell], points - self.origin[cell])
        coords = np.concatenate([1.0 - lam.sum(-1, keepdims=True), lam], axis=-1)
        return coords, np.where(self.flat[cell], -np.inf, coords.min(-1))

    def search(self, tree: Any, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:func:`_cells_holding` for one block of points: each one's cell and coordinates."""
        n_cells = len(self.origin)
        which = np.zeros(len(points), dtype=np.int64)
        bary = np.full((len(points), 4), -np.inf)
        todo = np.arange(len(points))
        k = 1
        while len(todo):
            _, near = tree.query(points[todo], k=k, distance_upper_bound=self.reach)
            near = near.reshape(len(todo), k)
            valid = near < n_cells  # beyond the reach: no such neighbour
            coords, score = self.coordinates(np.where(valid, near, 0), points[todo, None, :])
            score[~valid] = -np.inf
            best = np.argmax(score, axis=1)
            pick = np.arange(len(todo))
            better = score[pick, best] > bary[todo].min(axis=1)
            which[todo[better]] = near[pick, best][better]
            bary[todo[better]] = coords[pick, best][better]
            # done: held by a cell, or every centroid within the reach tried (the k-th beyond)
            held = score[pick, best] >= -INSIDE
            exhausted = ~valid[:, -1] | (k == n_cells)
            todo = todo[~(held | exhausted)]
            k = min(CANDIDATES if k == 1 else 8 * k, n_cells)
        lost = ~np.isfinite(bary[:, 0])  # far outside: no centroid within the reach
        if lost.any():
            which[lost] = tree.query(points[lost])[1]
            bary[lost] = self.coordinates(which[lost], points[lost])[0]
        return which, bary


def locate_quadratic(
    X: np.ndarray, cells: np.ndarray, points: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Each point's 10-node tetrahedron and its quadratic shape functions there.

    The point is found among the straight cells of the corners (:func:`locate`), then its
    reference coordinates in that cell's curved map by Newton's method.

    Args:
        X: the mesh's nodes (K, 3), m.
        cells: its 10-node tetrahedra as rows of ``X`` (C, 10), corners first.
        points: where to interpolate (M, 3), m.

    Returns:
        ``(rows (M, 10), weights (M, 10))`` for :func:`interpolate`.

    Raises:
        ValueError: as :func:`locate`, or for cells that are not 10-node tetrahedra.
    """
    X, points = np.asarray(X, dtype=float), np.asarray(points, dtype=float)
    pairs = edge_order(X, cells)
    which, bary = _cells_holding(X, cells[:, :4], points)
    rows = cells[which]
    # a cell whose edge nodes sit at their corners' midpoints maps affinely: the straight
    # coordinates are its own, and only the points of curved cells need Newton's method
    curved = np.flatnonzero(_curved(X, cells, pairs)[which])
    weights = quadratic_weights(bary, pairs)
    for start in range(0, len(curved), BLOCK):
        block = curved[start:start + BLOCK]
        weights[block] = _curved_weights(X[rows[block]], bary[block], points[block], pairs)
    return rows, weights


def _curved(X: np.ndarray, cells: np.ndarray, pairs: np.ndarray) -> np.ndarray:
    """Whether each 10-node cell (C,) is curved.

    Curved: an edge node lies off its corners' midpoint by more than a rounding error of the
    cell's size.
    """
    corners = X[cells[:, :4]]
    midpoints = 0.5 * (corners[:, pairs[:, 0]] + corners[:, pairs[:, 1]])
    off = np.abs(X[cells[:, 4:]] - midpoints).max(axis=(1, 2))
    size = np.abs(corners - corners[:, :1]).max(axis=(1, 2))
    return off > 1e-12 * size


def _curved_weights(nodes: np.ndarray, straight: np.ndarray, points: np.ndarray,
                    pairs: np.ndarray) -> np.ndarray:
    """:func:`locate_quadratic`'s shape functions for one block: Newton on each cell's map.

    ``nodes`` (m, 10, 3) are each point's cell, ``straight`` its coordinates in the straight
    cell of the corners.
    """
    bary, gap = curved_coordinates(nodes, points, straight, pairs, NEWTON_STEPS)
    # a point the curved map does not reach (outside the body, clipped to a face by locate):
    # the straight cell's coordinates
    lost = ~np.isfinite(gap) | (gap > 1e-3 * OUTSIDE_M)
    bary[lost] = straight[lost]
    return quadratic_weights(bary, pairs)


def locate_in(X: np.ndarray, cells: np.ndarray, points: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray]:
    """Each point's cell and its shape functions there, by the cells' own order.

    10-node cells: the quadratic ones (:func:`locate_quadratic`); otherwise the linear ones of
    the corners (:func:`locate`).

    Raises:
        OutsideMeshError: as :func:`locate`.
    """
    if cells.shape[1] == 10:
        return locate_quadratic(X, cells, points)
    return locate(X, cells[:, :4], points)


def interpolation_matrix(rows: np.ndarray, weights: np.ndarray, nodes: int) -> Any:
    """The located points' shape functions as a sparse (M, ``nodes``) matrix (CSR).

    ``matrix @ f`` is :func:`interpolate`'s ``f`` (nodes, k) at the points, in M × nodes-a-cell
    products: the way to carry a field to many more points than the mesh has nodes.
    """
    from scipy.sparse import csr_matrix

    m, k = rows.shape
    return csr_matrix((weights.ravel(), rows.ravel(), np.arange(0, m * k + 1, k)),
                      shape=(m, nodes))


def interpolate(field: np.ndarray, rows: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """A field at the nodes (N, ...) at the located points (M, ...), in the field's type.

    Points go in blocks of :data:`BLOCK`: the gathered nodes of all of them at once would
    take (M, nodes a cell, ...) values.
    """
    out = np.empty((len(rows), *field.shape[1:]), dtype=np.result_type(field, np.float32))
    for start in range(0, len(rows), BLOCK):
        block = slice(start, start + BLOCK)
        out[block] = np.einsum("mj,mj...->m...", weights[block], field[rows[block]])
    return out
