"""The tissues of a label volume's cells: ``mesh.image.tissues`` and each cell's label.

:mod:`meshes.image` meshes the breast's labels as one body (marching cubes and fTetWild);
each cell then takes the tissue of the label the image holds where it lies.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from meshes.exceptions import GeometryError
from meshes.tags import Tissue

__all__ = ["cell_tissues", "tissue_labels"]


def tissue_labels(values: Any) -> dict[Tissue, tuple[int, ...]]:
    """``mesh.image.tissues`` (tissue name → label or labels), typed."""
    if values is None:
        return {}
    if not isinstance(values, dict):
        raise GeometryError(f"mesh.image.tissues must map tissues to labels, got {values!r}")
    out = {}
    for name, labels in values.items():
        try:
            tissue = Tissue.from_label(name)
        except ValueError as err:
            raise GeometryError(f"mesh.image.tissues: {err}") from None
        labels = [labels] if isinstance(labels, int) else labels
        if not isinstance(labels, list) or not all(
                isinstance(v, int) and not isinstance(v, bool) for v in labels):
            raise GeometryError(f"mesh.image.tissues.{name} must be a label or a list of labels, "
                                f"got {values[name]!r}")
        out[tissue] = tuple(labels)
    return out


def cell_tissues(labels: np.ndarray, grid: Any, x: np.ndarray, tets: np.ndarray,
                 tissue_of: dict[int, Tissue]) -> tuple[np.ndarray, int]:
    """The tissue of each tetrahedron: the label the image holds where the cell lies.

    Each cell samples the label volume (nearest voxel) at its centroid and at points a quarter,
    a half and three quarters of the way from it to each vertex; the most frequent breast label
    among the samples wins (the centroid's on a tie). A cell none of whose samples falls on a
    breast label (a sliver along the smoothed surface) is fat.

    Args:
        labels: the label volume ``[i, j, k]``.
        grid: its header's map from voxel indices to LPS millimetres (a
            :class:`meshes.image.Grid`).
        x: the mesh's points, LPS metres.
        tets: its cells.
        tissue_of: each breast label's tissue.

    Returns:
        ``(tissue per cell, cells that found no breast label)``.
    """
    corners = x[tets]  # (n, 4, 3)
    centre = corners.mean(axis=1)
    samples = [centre] + [centre + t * (corners[:, v] - centre)
                          for t in (0.25, 0.5, 0.75) for v in range(4)]
    points = np.stack(samples, axis=1)  # (n, 13, 3)
    index = np.rint(grid.to_index(1e3 * points)).astype(np.int64)
    index = np.clip(index, 0, np.array(labels.shape) - 1)
    found = labels[index[..., 0], index[..., 1], index[..., 2]]
    known = np.array(sorted(tissue_of))
    votes = np.stack([np.sum(found == label, axis=1) for label in known], axis=1)
    # the centroid's label breaks ties: it counts half a vote more
    votes = votes + 0.5 * (found[:, :1] == known[None, :])
    best = known[np.argmax(votes, axis=1)]
    none = votes.max(axis=1) == 0
    tissue = np.array([int(tissue_of[int(label)]) for label in best], dtype=np.int64)
    tissue[none] = int(Tissue.FAT)
    return tissue, int(none.sum())
