"""The skin as flat triangles through the displacement's nodes, for self-contact.

:mod:`fem.self_contact` looks for the skin's nodes behind facing parts of the skin. Its
surface is the skin's facets, each of degree k split into k² flat triangles through its nodes
(four for P2), with each node's state entries and tributary area.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import sparse

from fem.point_triangle import barycentric

__all__ = ["SkinSurface"]

# Per facet of the reference tetrahedron (dolfinx / basix numbering: facet i is opposite
# vertex i), its vertices in order.
_FACET_VERTICES = ((1, 2, 3), (0, 2, 3), (0, 1, 3), (0, 1, 2))
#: The reference tetrahedron's edges by their local number (basix's, as dolfinx numbers them).
_TET_EDGES = ((2, 3), (1, 3), (1, 2), (0, 3), (0, 2), (0, 1))


@dataclass
class SkinSurface:
    """The skin as triangles of displacement nodes, and where each node's values live.

    Attributes:
        X: reference coordinates of the nodes (n, 3).
        dofs: the state's local entries of each node's three displacement components (n, 3).
        triangles: node indices of each triangle (t, 3), outward by the right-hand rule.
        weights: each node's tributary reference area (n,), m².
        excluded: for each node, the triangles it never pairs with (those of which it is a
            corner), as a sorted array of ``node * t + triangle`` codes.
    """

    X: np.ndarray
    dofs: np.ndarray
    triangles: np.ndarray
    weights: np.ndarray
    excluded: np.ndarray

    @property
    def radii(self) -> np.ndarray:
        """Each triangle's reference size: its corners' largest distance from its centroid."""
        return triangle_radii(self.X[self.triangles])

    @classmethod
    def from_problem(cls, W: Any, mixed: bool, mesh: Any, facets: np.ndarray) -> SkinSurface:
        """The surface of the given skin ``facets`` in the state's space ``W``."""
        D = W.sub(0) if mixed else W
        spaces = [D.sub(c).collapse() for c in range(3)]
        V0 = spaces[0][0]
        coords = V0.tabulate_dof_coordinates()
        for Vc, _ in spaces[1:]:
            if not np.array_equal(Vc.tabulate_dof_coordinates(), coords):
                raise RuntimeError("the displacement's components are numbered differently")
        to_state = np.column_stack([np.asarray(m, dtype=np.int64) for _, m in spaces])

        tdim = mesh.topology.dim
        mesh.topology.create_connectivity(tdim - 1, tdim)
        mesh.topology.create_connectivity(tdim, tdim - 1)
        f2c = mesh.topology.connectivity(tdim - 1, tdim)
        c2f = mesh.topology.connectivity(tdim, tdim - 1)
        layout = V0.dofmap.dof_layout
        cell_dofs = V0.dofmap.list.array.reshape(-1, layout.num_dofs)
        vertex_dof = [layout.entity_dofs(0, v)[0] for v in range(4)]
        closure = [np.asarray(layout.entity_closure_dofs(2, i)) for i in range(4)]
        degree = int(round((np.sqrt(8 * len(closure[0]) + 1) - 3) / 2))  # (k+1)(k+2)/2 nodes
        lattice = _lattice_triangles(degree)
        entity_dof = _vertex_and_edge_dofs(layout) if degree <= 2 else {}

        triangles = []
        for f in np.asarray(facets, dtype=np.int64):
            cell = f2c.links(f)[0]
            local = int(np.flatnonzero(c2f.links(cell) == f)[0])
            dofs = cell_dofs[cell]
            a, b, c = _FACET_VERTICES[local]
            # outward: away from the cell's vertex opposite the facet
            va, vb, vc, vo = (coords[dofs[vertex_dof[i]]] for i in (a, b, c, local))
            if np.dot(np.cross(vb - va, vc - va), vo - va) > 0:
                b, c, vb, vc = c, b, vc, vb
            index = np.full((degree + 1, degree + 1), -1, dtype=np.int64)
            if degree <= 2:  # by the element's numbering: corners, then the edges' midpoints
                at = {(0, 0): (a,), (degree, 0): (b,), (0, degree): (c,)}
                if degree == 2:
                    at.update({(1, 0): (a, b), (0, 1): (a, c), (1, 1): (b, c)})
                for (i, j), entity in at.items():
                    index[i, j] = dofs[entity_dof[frozenset(entity)]]
            else:  # the facet's nodes on their lattice: (k λ_b, k λ_c) in the straight triangle
                nodes = dofs[closure[local]]
                lam = barycentric(coords[nodes], *(np.broadcast_to(v, (len(nodes), 3))
                                                   for v in (va, vb, vc)))
                ij = np.rint(degree * lam[:, 1:]).astype(np.int64)
                index[ij[:, 0], ij[:, 1]] = nodes
            if np.any(index[lattice[..., 0], lattice[..., 1]] < 0):
                raise RuntimeError(f"skin facet {f}: its nodes do not form a degree-{degree} "
                                   "lattice")
            triangles.append(index[lattice[..., 0], lattice[..., 1]])
        tri = np.concatenate(triangles).reshape(-1, 3)
        nodes, tri = np.unique(tri, return_inverse=True)
        tri = tri.reshape(-1, 3)
        X = coords[nodes]
        area = 0.5 * np.linalg.norm(np.cross(X[tri[:, 1]] - X[tri[:, 0]],
                                             X[tri[:, 2]] - X[tri[:, 0]]), axis=1)
        weights = np.bincount(tri.ravel(), np.repeat(area / 3.0, 3), minlength=len(nodes))
        return cls(X, to_state[nodes], tri, weights, _own_triangles(tri, len(nodes)))


def _vertex_and_edge_dofs(layout: Any) -> dict[frozenset[int], int]:
    """A P1 or P2 tetrahedron's local dof at each vertex ({v}) and edge midpoint ({v, w}).

    By the element's own numbering rather than by where the nodes sit: on a curved (quadratic)
    mesh a facet's midside nodes lie off its straight triangle, on a strongly curved skin (a
    tight fold) too far to be told apart by position.
    """
    out = {frozenset((v,)): int(layout.entity_dofs(0, v)[0]) for v in range(4)}
    if layout.num_entity_dofs(1):
        for e, edge in enumerate(_TET_EDGES):
            out[frozenset(edge)] = int(layout.entity_dofs(1, e)[0])
    return out


def triangle_radii(corners: np.ndarray) -> np.ndarray:
    """The largest distance of each triangle's corners (t, 3, 3) from its centroid."""
    return np.linalg.norm(corners - corners.mean(axis=1)[:, None], axis=2).max(axis=1)


def _lattice_triangles(k: int) -> np.ndarray:
    """The k² triangles of a triangle's degree-k lattice, as (i, j) corners (k², 3, 2).

    Node (i, j) sits at barycentric coordinates (1 − (i + j)/k, i/k, j/k); every triangle
    turns as the facet (a, b, c) does.
    """
    out = []
    for i in range(k):
        for j in range(k - i):
            out.append([(i, j), (i + 1, j), (i, j + 1)])
            if i + j <= k - 2:
                out.append([(i + 1, j), (i + 1, j + 1), (i, j + 1)])
    return np.asarray(out, dtype=np.int64)


def _own_triangles(triangles: np.ndarray, n_nodes: int) -> np.ndarray:
    """Codes ``node * t + triangle`` of the triangles of which each node is a corner."""
    t = len(triangles)
    incidence = sparse.csr_matrix(
        (np.ones(triangles.size), (triangles.ravel(), np.repeat(np.arange(t), 3))),
        shape=(n_nodes, t),
    )
    ring = incidence.tocoo()  # the triangles of which the node is a corner
    return np.unique(ring.row.astype(np.int64) * t + ring.col)


