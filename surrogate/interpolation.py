"""Fields given at the mesh's vertices, between them: linear interpolation in its tetrahedra.

A ``pod`` surrogate's modes are known at the material points only (the mesh's vertices); it
answers at another point, such as a tumour's material position, by the linear shape functions of
the tetrahedron that holds it (:meth:`surrogate.predict.Surrogate.at`).
"""

from __future__ import annotations

import numpy as np

CANDIDATES = 24
"""Cells whose centroids are nearest a point, among which the one that holds it is sought."""
OUTSIDE_M = 1e-3
"""How far outside the mesh (m) a point may lie and still be answered, on its nearest cell's
face: a point on the curved skin lies up to a fraction of a millimetre outside the straight-sided
cells of its vertices."""


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
        ValueError: naming how many points lie farther outside the mesh, and the farthest.
    """
    from scipy.spatial import cKDTree

    X, points = np.asarray(X, dtype=float), np.asarray(points, dtype=float)
    corners = X[cells]  # (C, 4, 3)
    k = min(CANDIDATES, len(cells))
    _, near = cKDTree(corners.mean(axis=1)).query(points, k=k)
    near = near.reshape(len(points), k)
    T = corners[near]  # (M, k, 4, 3)
    edges = np.swapaxes(T[:, :, 1:, :] - T[:, :, :1, :], -1, -2)  # columns v_j - v_0
    rhs = (points[:, None, :] - T[:, :, 0, :])[..., None]
    size = np.abs(edges).max(axis=(-2, -1))
    flat = np.abs(np.linalg.det(edges)) <= 1e-12 * size**3  # no volume: holds no point
    edges[flat] = np.eye(3)
    lam = np.linalg.solve(edges, rhs)[..., 0]  # (M, k, 3)
    bary = np.concatenate([1.0 - lam.sum(-1, keepdims=True), lam], axis=-1)
    score = np.where(flat, -np.inf, bary.min(-1))
    best = np.argmax(score, axis=1)
    pick = np.arange(len(points))
    weights = np.clip(bary[pick, best], 0.0, None)
    weights /= weights.sum(axis=1, keepdims=True)
    rows = cells[near[pick, best]]
    gap = np.linalg.norm(np.einsum("mj,mjd->md", weights, X[rows]) - points, axis=1)
    outside = gap > OUTSIDE_M
    if outside.any():
        raise ValueError(
            f"{int(outside.sum())} of {len(points)} points lie outside the mesh by more than "
            f"{1e3 * OUTSIDE_M:g} mm (the farthest {1e3 * gap.max():.1f} mm, point "
            f"{int(np.argmax(gap))}): the model's modes are known inside the body only")
    return rows, weights


def interpolate(field: np.ndarray, rows: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """A field at the vertices (N, ...) at the located points (M, ...)."""
    return np.einsum("mj,mj...->m...", weights, field[rows])
