"""The 10-node (quadratic) tetrahedron: its shape functions and the order of its edge nodes.

Shared by everything that evaluates a field or a map inside a curved cell: the surrogate's
modes between the mesh's nodes (:mod:`surrogate.interpolation`) and the test of a deformed
boundary vertex against a deformed curved cell (:mod:`fem.overlap`).
"""

from __future__ import annotations

import numpy as np

CONVERGED = 1e-12
"""A Newton step on a curved cell's reference coordinates this small (each one, in every point
of a block) ends it: the map is nearly affine, so the steps shrink quadratically to the
rounding floor of a few 1e-14 within three or four."""

EDGES = ((0, 1), (1, 2), (0, 2), (0, 3), (1, 3), (2, 3))
"""Corner pairs of a tetrahedron's six edges; a 10-node cell's edge nodes follow its corners in
an order of these that :func:`edge_order` reads from the nodes' positions."""


def edge_order(X: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """Which corner pair each edge node of a 10-node cell sits between: (6, 2) corner slots.

    Read from the nodes' positions (each edge node lies nearest the midpoint of its corners,
    curved or not), so that any writer's node order will do, as long as every cell shares it.

    Raises:
        ValueError: if ``cells`` are not 10-node tetrahedra, or their edge nodes are not in one
            order.
    """
    if cells.ndim != 2 or cells.shape[1] != 10:
        raise ValueError(f"quadratic cells have 10 nodes, got cells of shape {cells.shape}")
    corners, edge_nodes = X[cells[:, :4]], X[cells[:, 4:]]
    midpoints = np.stack([(corners[:, a] + corners[:, b]) / 2 for a, b in EDGES], axis=1)
    distance = np.linalg.norm(edge_nodes[:, :, None, :] - midpoints[:, None, :, :], axis=-1)
    nearest = np.argmin(distance, axis=2)  # (C, 6): the pair of each edge node
    order = nearest[0]
    if not np.all(nearest == order) or len(set(order.tolist())) != 6:
        raise ValueError("the cells' edge nodes are not in one order of their corner pairs")
    return np.asarray(EDGES)[order]


def quadratic_weights(bary: np.ndarray, pairs: np.ndarray) -> np.ndarray:
    """The 10-node tetrahedron's shape functions at barycentric coordinates (M, 4): (M, 10).

    Corner i: λ_i (2 λ_i − 1); the edge node between corners i and j: 4 λ_i λ_j.
    """
    corner = bary * (2.0 * bary - 1.0)
    edge = 4.0 * bary[:, pairs[:, 0]] * bary[:, pairs[:, 1]]
    return np.concatenate([corner, edge], axis=1)


def quadratic_gradients(bary: np.ndarray, pairs: np.ndarray) -> np.ndarray:
    """d(shape functions)/d(λ1, λ2, λ3), with λ0 = 1 − λ1 − λ2 − λ3: (M, 10, 3)."""
    dbary = np.array([[-1.0, -1.0, -1.0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])  # dλ_i/dξ
    corner = (4.0 * bary - 1.0)[:, :, None] * dbary[None]
    a, b = pairs[:, 0], pairs[:, 1]
    edge = 4.0 * (bary[:, a, None] * dbary[None, b] + bary[:, b, None] * dbary[None, a])
    return np.concatenate([corner, edge], axis=1)


def curved_coordinates(nodes: np.ndarray, points: np.ndarray, start: np.ndarray,
                       pairs: np.ndarray, steps: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """Barycentric coordinates of ``points`` (m, 3) in curved cells ``nodes`` (m, 10, 3).

    Newton's method on each cell's quadratic map, from ``start`` (m, 4), e.g. the coordinates
    in the straight cell of the corners. Returns the coordinates (m, 4) and how far the map
    there lies from the point (m,), NaN where Newton did not converge (a point the map does not
    reach).
    """
    xi = np.asarray(start, dtype=float)[:, 1:].copy()
    with np.errstate(all="ignore"):
        for _ in range(steps):
            bary = np.concatenate([1.0 - xi.sum(1, keepdims=True), xi], axis=1)
            residual = np.einsum("mk,mkd->md", quadratic_weights(bary, pairs), nodes) - points
            jacobian = np.einsum("mkd,mke->mde", nodes, quadratic_gradients(bary, pairs))
            step = np.linalg.solve(jacobian, residual[..., None])[..., 0]
            xi -= step
            if not np.any(np.abs(step) > CONVERGED):  # NaN steps stop it too: unreachable
                break
        bary = np.concatenate([1.0 - xi.sum(1, keepdims=True), xi], axis=1)
        gap = np.linalg.norm(np.einsum("mk,mkd->md", quadratic_weights(bary, pairs), nodes)
                             - points, axis=1)
    return bary, np.where(np.isfinite(gap), gap, np.nan)
