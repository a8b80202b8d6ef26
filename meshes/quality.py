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
    return 0.5 * np.linalg.norm(np.cross(x[tris[:, 1]] - x[tris[:, 0]], x[tris[:, 2]] - x[tris[:, 0]]), axis=1)


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
    report: dict[str, Any] = {
        "cells": int(len(tets)),
        "vertices": int(len(np.unique(tets))),
        "volume_m3": float(np.abs(volumes).sum()),
        "volume_ml": float(np.abs(volumes).sum() * 1e6),
        "inverted_cells": int(min(np.sum(volumes < 0), np.sum(volumes > 0))),
        "area_m2": areas,
        "boundary_area_m2": float(sum(areas.values())),
        "min_dihedral_deg": float(dihedral.min()),
        "max_dihedral_deg": float(dihedral.max()),
    }
    for name, values in (element_quality or {}).items():
        report[f"min_{name}"] = float(np.min(values))
        report[f"mean_{name}"] = float(np.mean(values))
    return report
