"""Small repairs of a surface as real tools write it: inconsistent winding and small holes.

A surface from a modelling tool, a scanner or a segmentation is often nearly, but not quite,
what the import needs: some triangles wound the other way, a few small holes where a tool
dropped faces. Those are repaired, and the repair is recorded (how many triangles were turned,
how many holes were filled and their area). A hole larger than :data:`HOLE_AREA_FRACTION` of
the surface's area is no small repair: it is refused with its size and place, since filling it
would invent tissue. Duplicate vertices are merged before
(:func:`meshes.checks.merge_duplicate_points`).

Winding is made consistent with trimesh (``repair.fix_winding``) and outward by the sign of the
enclosed volume; holes are filled with MeshFix (pymeshfix), which triangulates and refines
the patch to the surrounding triangles' size.
"""

from __future__ import annotations

import logging
from typing import Any

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from meshes.exceptions import SurfaceNotClosedError
from meshes.quality import triangle_areas, unique_rows

log = logging.getLogger(__name__)

#: The largest hole filled, as a fraction of the surface's area; a larger one is refused.
HOLE_AREA_FRACTION = 0.01


def holes(points: np.ndarray, tris: np.ndarray) -> list[dict[str, Any]]:
    """The surface's holes: loops of edges that belong to one triangle only.

    Returns:
        Per hole, largest first: its edges, rim length (m), area (m², of the loop's vector
        area) and centre (m).
    """
    edges = tris[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    _, inverse, counts = np.unique(np.sort(edges, axis=1), axis=0, return_inverse=True,
                                   return_counts=True)
    rim = edges[counts[inverse.reshape(-1)] == 1]
    if len(rim) == 0:
        return []
    n = len(points)
    graph = coo_matrix((np.ones(len(rim)), (rim[:, 0], rim[:, 1])), shape=(n, n))
    _, label = connected_components(graph, directed=False)
    found = []
    for loop in np.unique(label[rim[:, 0]]):
        edge = rim[label[rim[:, 0]] == loop]
        a, b = points[edge[:, 0]], points[edge[:, 1]]
        centre = points[np.unique(edge)].mean(axis=0)
        area = 0.5 * float(np.linalg.norm(np.cross(a - centre, b - centre).sum(axis=0)))
        found.append({"edges": int(len(edge)), "rim_m": float(np.linalg.norm(b - a, axis=1).sum()),
                      "area_m2": area, "centre_m": centre.tolist()})
    return sorted(found, key=lambda h: -h["area_m2"])


def repair_surface(points: np.ndarray, tris: np.ndarray,
                   what: str) -> tuple[np.ndarray, np.ndarray, dict[str, Any]]:
    """Make the winding consistent and outward, and fill small holes.

    Args:
        points: vertices (duplicates merged), metres.
        tris: triangles.
        what: the file, for messages.

    Returns:
        ``(points, tris, record)``: the repaired surface and what was done (triangles turned,
        holes filled and their area).

    Raises:
        SurfaceNotClosedError: for a hole larger than :data:`HOLE_AREA_FRACTION` of the area,
            naming its size and place (non-manifold edges are left to
            :func:`meshes.checks.check_closed`, which names them).
    """
    import trimesh

    record: dict[str, Any] = {"triangles_turned": 0, "holes_filled": 0, "filled_area_m2": 0.0}
    _, counts = unique_rows(tris[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2))
    if (counts > 2).any():
        return points, tris, record  # non-manifold: check_closed names it
    mesh = trimesh.Trimesh(points, tris, process=False)
    before = mesh.faces.copy()
    trimesh.repair.fix_winding(mesh)  # first: the holes' areas need one winding
    tris = np.asarray(mesh.faces, dtype=np.int64)
    turned = int((tris != before).any(axis=1).sum())
    found = holes(points, tris)
    area = float(triangle_areas(points, tris).sum())
    if found:
        largest = found[0]
        if largest["area_m2"] > HOLE_AREA_FRACTION * area:
            centre = ", ".join(f"{1e3 * c:.1f}" for c in largest["centre_m"])
            raise SurfaceNotClosedError(
                f"{what} is not a closed surface: {len(found)} hole(s), the largest "
                f"{1e4 * largest['area_m2']:.3g} cm² ({100 * largest['area_m2'] / area:.2g} % of "
                f"the surface; rim {1e3 * largest['rim_m']:.0f} mm in {largest['edges']} edges) "
                f"centred at ({centre}) mm in the file's axes: too large to fill without "
                f"inventing tissue (holes up to {100 * HOLE_AREA_FRACTION:g} % of the area are "
                "filled); export the closed solid, or close the surface where it was cut"
            )
        points, tris = _fill_holes(points, tris)
        record["holes_filled"] = len(found)
        record["filled_area_m2"] = float(triangle_areas(points, tris).sum()) - area
        record["holes"] = found
    a, b, c = (points[tris[:, i]] for i in range(3))
    if float(np.einsum("ij,ij->", a, np.cross(b, c))) < 0:  # inward: turn every triangle
        tris = tris[:, [0, 2, 1]]
        turned = len(tris) - turned
    record["triangles_turned"] = turned
    if record["holes_filled"] or turned:
        log.warning("%s: repaired: %d triangle(s) turned to a consistent outward winding, "
                    "%d hole(s) filled (%.3g cm²)", what, turned, record["holes_filled"],
                    1e4 * record["filled_area_m2"])
    return points, tris, record


def _fill_holes(points: np.ndarray, tris: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Every hole filled by MeshFix, its patch refined to the surrounding triangles."""
    import pymeshfix

    mesh = pymeshfix.PyTMesh()
    mesh.set_quiet(True)
    mesh.load_array(np.asarray(points, dtype=np.float64), np.asarray(tris, dtype=np.int32))
    mesh.fill_small_boundaries(nbe=0, refine=True)
    filled_points, filled_tris = mesh.return_arrays()
    return np.asarray(filled_points, dtype=float), np.asarray(filled_tris, dtype=np.int64)
