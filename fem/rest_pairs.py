"""The skin's self-contact pairs that face each other already at rest, and what becomes of them.

A skin may face itself before any load: at a sharp chest-wall rim or a thin region (a node
behind the other side's skin, across the tissue) or a crease the surface was made with (a
node nearer the other side than the offset). :mod:`fem.self_contact` would push them apart at
zero displacement; :func:`rest_treatment` leaves them out or measures them from their rest gap
(``fe.self_contact.at_rest``, docs/contact.md), and :class:`RestPairs` records them.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["REST_FACING", "REST_REACH", "TOUCHING", "RestPairs", "rest_treatment",
           "surface_normals"]

#: A pair faces at rest (:func:`rest_treatment`) when its normals are
#: more than 90° apart in the reference configuration: neighbours on a smooth skin, even a
#: strongly curved one, are nearer parallel; the two sides of a thin region, a sharp rim or a
#: crease are not.
REST_FACING = 0.0
#: How near (in bands) a node lies to a triangle at rest for their pair to be one at rest: a
#: node on the other side of a thin region may slide that far along it and stay left out.
REST_REACH = 2.0
#: Nearer a triangle's plane at rest than this fraction of the offset, a node touches it.
TOUCHING = 1e-3


def surface_normals(x: np.ndarray, tri: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit normals of the triangles and (area-weighted) of the nodes at ``x``."""
    corners = x[tri]
    normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    length = np.linalg.norm(normal, axis=1)
    normal = normal / np.where(length > 0, length, 1.0)[:, None]
    weighted = np.repeat(normal * length[:, None], 3, axis=0)  # area-weighted, per corner
    node_normal = np.column_stack([
        np.bincount(tri.ravel(), weighted[:, k], minlength=len(x)) for k in range(3)
    ])
    node_normal /= np.maximum(np.linalg.norm(node_normal, axis=1), 1e-300)[:, None]
    return normal, node_normal


@dataclass(frozen=True, slots=True)
class RestPairs:
    """The skin's self-contact pairs in the reference configuration (at zero displacement).

    Attributes:
        treatment: ``settings.at_rest``, what became of them.
        pairs: node–triangle pairs that would push at rest, without a treatment (their node
            nearer a facing triangle's plane than the offset, or behind it within the band).
        nodes: the skin nodes among them.
        behind, in_front: of those pairs, the node behind the triangle (the other side of a
            thin region or a sharp rim) or in front of it (a crease nearer than the offset).
        deepest_mm: how far the deepest node lies behind a facing triangle (0 if none).
        closest_gap_mm: the smallest gap in front (None if no pair lies in front).
        deepest_at_m: reference position of the deepest node (None without pairs).
        pairs_left: the pairs still pushing at rest after the treatment (0).
    """

    treatment: str
    pairs: int
    nodes: int
    behind: int
    in_front: int
    deepest_mm: float
    closest_gap_mm: float | None
    deepest_at_m: list[float] | None
    pairs_left: int

    def to_json(self) -> dict[str, Any]:
        """JSON-friendly fields."""
        return {name: getattr(self, name) for name in self.__slots__}

    @classmethod
    def found(cls, treatment: str, offset: float, X: np.ndarray, node: np.ndarray,
              g0: np.ndarray, pairs_left: int) -> RestPairs:
        """The record of the pairs that push at rest: their nodes and rest gaps ``g0`` (m)."""
        behind = g0 < -TOUCHING * offset
        deepest = node[np.argmin(g0)] if len(g0) else None
        return cls(
            treatment=treatment,
            pairs=int(len(node)),
            nodes=int(len(np.unique(node))),
            behind=int(behind.sum()),
            in_front=int((~behind).sum()),
            deepest_mm=1e3 * float(max(0.0, -g0.min(initial=0.0))),
            closest_gap_mm=1e3 * float(g0[~behind].min()) if np.any(~behind) else None,
            deepest_at_m=None if deepest is None else X[deepest].tolist(),
            pairs_left=pairs_left,
        )

    @classmethod
    def from_json(cls, values: dict[str, Any]) -> RestPairs:
        """Inverse of :meth:`to_json`."""
        return cls(**values)


def rest_treatment(treatment: str, offset: float, band: float, X: np.ndarray,
                   tri: np.ndarray, triangle_normal: np.ndarray, node_normal: np.ndarray,
                   node: np.ndarray, triangle: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Which candidate pairs take part, and the offset each is measured from (m).

    A pair is one *at rest* when, in the reference configuration, the node lies within
    :data:`REST_REACH` bands of the triangle, nearer its plane than ``offset`` (or behind
    it), and their normals are more than 90° apart: the pair would push at rest, and no
    smooth skin has such neighbours. The test is the pair's own, in reference coordinates,
    so it is the same at every iterate: a node that slides along the other side of a thin
    region stays left out. Behind the triangle at rest, the node is the other side of the
    tissue (a thin region, a sharp rim), which no contact separates; in front, the two sides
    of a crease that the surface was made with, which may close no further than they are.

    Args:
        treatment: ``by_side``, ``exclude``, ``rest_gap`` or ``none`` (``at_rest``).
        offset: the self-contact's offset, m.
        band: its band, m.
        X: the skin nodes' reference coordinates.
        tri: the skin's triangles.
        triangle_normal: the triangles' reference unit normals (:func:`surface_normals`).
        node_normal: the nodes' reference unit normals.
        node: the candidate pairs' nodes.
        triangle: the candidate pairs' triangles.
    """
    offsets = np.full(len(node), float(offset))
    if not len(node) or treatment == "none":
        return np.ones(len(node), dtype=bool), offsets
    rest_normal = triangle_normal[triangle]
    g0 = np.einsum("ij,ij->i", rest_normal, X[node] - X[tri[triangle, 0]])
    facing0 = -np.einsum("ij,ij->i", node_normal[node], rest_normal)
    d0 = np.min(np.linalg.norm(X[tri[triangle]] - X[node][:, None], axis=2), axis=1)
    at_rest = (g0 < offset) & (facing0 > REST_FACING) & (d0 <= REST_REACH * band)
    # touching at rest (|g0| at rounding's scale, as two bodies of one mesh do) is in front
    behind = at_rest & (g0 < -TOUCHING * offset)
    if treatment == "exclude":
        return ~at_rest, offsets
    measured = at_rest if treatment == "rest_gap" else at_rest & ~behind
    offsets[measured] = g0[measured]
    kept = np.ones(len(node), dtype=bool) if treatment == "rest_gap" else ~behind
    return kept, offsets
