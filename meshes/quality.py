"""Mesh quality figures: counts, volume, area per named surface, element quality."""

from __future__ import annotations

from typing import Any

import numpy as np

from meshes.tags import Boundary


def tet_volumes(x: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Signed volumes of tetrahedra (vertex coordinates ``x``, connectivity (n, 4))."""
    e1, e2, e3 = (x[tets[:, i]] - x[tets[:, 0]] for i in (1, 2, 3))
    return np.einsum("ij,ij->i", np.cross(e1, e2), e3) / 6.0


def triangle_areas(x: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """Areas of triangles (connectivity (n, 3))."""
    return 0.5 * np.linalg.norm(
        np.cross(x[tris[:, 1]] - x[tris[:, 0]], x[tris[:, 2]] - x[tris[:, 0]]), axis=1
    )


def dihedral_angles(x: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """The six interior dihedral angles of each tetrahedron, degrees, shape (n, 6)."""
    faces = np.array([[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]])
    normals = []
    for f, opposite in zip(faces, range(4), strict=True):
        a, b, c = (x[tets[:, i]] for i in f)
        n = np.cross(b - a, c - a)
        # orient outward: away from the opposite vertex
        sign = np.sign(np.einsum("ij,ij->i", n, a - x[tets[:, opposite]]))
        normals.append(n * sign[:, None] / np.linalg.norm(n, axis=1)[:, None])
    angles = []
    for i in range(4):
        for j in range(i + 1, 4):
            cos = -np.einsum("ij,ij->i", normals[i], normals[j])
            angles.append(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))
    return np.stack(angles, axis=1)


TET_FACES = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]])
"""Faces of a tetrahedron, each opposite one vertex, ordered so that their normal points
out of a positively oriented tetrahedron."""
TET_EDGES = np.array([[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]])


def unique_rows(rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distinct rows of sorted index tuples and how often each occurs."""
    keyed = np.sort(rows, axis=1)
    return np.unique(keyed, axis=0, return_counts=True)


def exterior_faces(tets: np.ndarray) -> np.ndarray:
    """Triangles that belong to exactly one tetrahedron, oriented outward.

    Outward means: for positively oriented tetrahedra (see :func:`tet_volumes`) the
    right-hand normal of each returned triangle points out of the mesh.
    """
    faces = tets[:, TET_FACES].reshape(-1, 3)
    _, first, counts = np.unique(
        np.sort(faces, axis=1), axis=0, return_index=True, return_counts=True
    )
    return faces[first[counts == 1]]


def taylor_hood_dofs(n_vertices: int, n_edges: int, n_faces: int) -> dict[str, int]:
    """Unknowns of the Taylor–Hood pairs on a tetrahedral mesh (vector u, scalar p).

    P2 has a node per vertex and edge, P3 per vertex, two per edge and one per face.
    """
    p2 = n_vertices + n_edges
    p3 = n_vertices + 2 * n_edges + n_faces
    return {"P2/P1": 3 * p2 + n_vertices, "P3/P2": 3 * p3 + p2}


def quality_report(
    x: np.ndarray,
    tets: np.ndarray,
    facets: dict[Boundary, np.ndarray],
    element_quality: dict[str, np.ndarray] | None = None,
) -> dict[str, Any]:
    """Summary figures of a tetrahedral mesh with named boundary triangles.

    Args:
        x: vertex coordinates (N, 3), metres.
        tets: tetrahedron vertex indices (n, 4).
        facets: boundary -> triangle vertex indices (m, 3).
        element_quality: optional per-element measures (e.g. gmsh's ``minSICN``, ``gamma``).
    """
    volumes = tet_volumes(x, tets)
    dihedral = dihedral_angles(x, tets)
    areas = {b.label: float(triangle_areas(x, t).sum()) for b, t in facets.items()}
    exterior = exterior_faces(tets)
    tagged = np.concatenate([t for t in facets.values() if len(t)] or [np.empty((0, 3), int)])
    tagged_keys = {tuple(f) for f in np.sort(tagged, axis=1)}
    exterior_keys = {tuple(f) for f in np.sort(exterior, axis=1)}
    n_edges = len(unique_rows(tets[:, TET_EDGES].reshape(-1, 2))[0])
    n_faces = len(unique_rows(tets[:, TET_FACES].reshape(-1, 3))[0])
    n_vertices = int(len(np.unique(tets)))
    scale = float(np.abs(volumes).max(initial=0.0))
    report: dict[str, Any] = {
        "cells": int(len(tets)),
        "vertices": n_vertices,
        "edges": int(n_edges),
        "dofs": taylor_hood_dofs(n_vertices, n_edges, n_faces),
        "volume_m3": float(np.abs(volumes).sum()),
        "volume_ml": float(np.abs(volumes).sum() * 1e6),
        "inverted_cells": int(min(np.sum(volumes < 0), np.sum(volumes > 0))),
        "degenerate_cells": int(np.sum(np.abs(volumes) <= 1e-10 * scale)),
        "area_m2": areas,
        "boundary_area_m2": float(sum(areas.values())),
        "exterior_area_m2": float(triangle_areas(x, exterior).sum()),
        "untagged_exterior_facets": len(exterior_keys - tagged_keys),
        "tagged_interior_facets": len(tagged_keys - exterior_keys),
        "min_dihedral_deg": float(dihedral.min()),
        "max_dihedral_deg": float(dihedral.max()),
    }
    for name, values in (element_quality or {}).items():
        report[f"min_{name}"] = float(np.min(values))
        report[f"mean_{name}"] = float(np.mean(values))
    return report
