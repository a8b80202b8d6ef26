"""Checks of user geometry: units, closed surfaces, self-intersections, element validity.

Pure numpy/scipy functions on arrays (points in metres, 0-based connectivity),
so every check is testable without gmsh or files. Each ``check_*`` function
raises a typed :mod:`meshes.exceptions` error whose message says what is wrong,
how much of it there is, where, and what to do.
"""

from __future__ import annotations

import logging

import numpy as np
from scipy.spatial import cKDTree

from meshes.exceptions import (
    InvalidElementsError,
    SelfIntersectionError,
    SurfaceNotClosedError,
    UnitsError,
)
from meshes.quality import TET_FACES, tet_volumes, triangle_areas, unique_rows

log = logging.getLogger(__name__)

UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001}
"""Length units a file may be written in, and their size in metres."""

PLAUSIBLE_EXTENT_M = (0.03, 1.0)
"""Range of the bounding-box diagonal of a breast-on-chest-wall model, metres: a single
breast is about 10 cm across and a whole torso under 1 m, so anything outside this range
is almost certainly in other units."""


def _fmt(x: np.ndarray) -> str:
    return "(" + ", ".join(f"{v:.4g}" for v in x) + ")"


def check_plausible_size(points: np.ndarray, units: str, what: str) -> float:
    """Reject a model whose size is implausible for a breast in the declared units.

    Args:
        points: coordinates already converted to metres with ``units``.
        units: the declared units (for the message).
        what: the file, for the message.

    Returns:
        The bounding-box diagonal, metres.

    Raises:
        UnitsError: naming the size found and the units that would make it plausible.
    """
    extent = float(np.linalg.norm(points.max(axis=0) - points.min(axis=0)))
    lo, hi = PLAUSIBLE_EXTENT_M
    if lo <= extent <= hi:
        return extent
    native = extent / UNITS[units]
    fits = [u for u, f in UNITS.items() if lo <= native * f <= hi]
    hint = (
        f"; read in {' or '.join(fits)} it would be {native * UNITS[fits[0]]:.3g} m across: "
        f"set mesh.file.units: {fits[0]}"
        if fits
        else ""
    )
    raise UnitsError(
        f"{what} is {extent:.3g} m across (bounding-box diagonal) with units {units!r}, but a "
        f"breast model is {lo:g}-{hi:g} m across: the file is probably in other units{hint}"
    )


PLAUSIBLE_VOLUME_ML = (5.0, 10_000.0)
"""Range of the tissue volume of a breast model, millilitres: the smallest breasts hold some
tens of ml, the largest a few litres each, so that a model of 32 l (a 50 mm model read in cm)
is in other units."""


def enclosed_volume(points: np.ndarray, tris: np.ndarray) -> float:
    """Volume enclosed by a closed triangulated surface (divergence theorem), m³."""
    a, b, c = (points[tris[:, i]] for i in range(3))
    return abs(float(np.einsum("ij,ij->", a, np.cross(b, c)))) / 6.0


def check_plausible_volume(volume_m3: float, units: str, what: str) -> float:
    """Reject a model whose volume is implausible for a breast in the declared units.

    The extent alone lets a factor of ten through (a 5 cm model read in cm is 0.5 m across,
    within :data:`PLAUSIBLE_EXTENT_M`), the volume does not: it scales with the cube.

    Args:
        volume_m3: the model's volume, in m³ (converted with ``units``).
        units: the declared units (for the message).
        what: the file, for the message.

    Returns:
        The volume in millilitres.

    Raises:
        UnitsError: naming the volume found and the units that would make it plausible.
    """
    ml = 1e6 * volume_m3
    lo, hi = PLAUSIBLE_VOLUME_ML
    if lo <= ml <= hi:
        return ml
    native = ml / UNITS[units] ** 3
    fits = [u for u, f in UNITS.items() if lo <= native * f**3 <= hi]
    hint = (
        f"; read in {' or '.join(fits)} it would hold {native * UNITS[fits[0]] ** 3:.3g} ml: "
        f"set mesh.file.units: {fits[0]}"
        if fits
        else ""
    )
    raise UnitsError(
        f"{what} holds {_volume(ml)} of tissue with units {units!r}, but a breast model holds "
        f"{lo:g} ml to {hi / 1000:g} l: the file is probably in other units{hint}"
    )


def _volume(ml: float) -> str:
    return f"{ml / 1000:.3g} l" if ml >= 1000 else f"{ml:.3g} ml"


def merge_duplicate_points(
    points: np.ndarray, cells: np.ndarray, tol: float
) -> tuple[np.ndarray, np.ndarray]:
    """Merge points closer than ``tol`` (STL stores every triangle's corners separately).

    Returns:
        ``(points, cells)`` with unused points dropped and cells renumbered.
    """
    key = np.round(points / tol).astype(np.int64)
    _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    merged = points[first]
    cells = inverse.reshape(-1)[cells]
    used = np.unique(cells)
    remap = np.full(len(merged), -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    return merged[used], remap[cells]


def check_triangles(points: np.ndarray, tris: np.ndarray, what: str) -> None:
    """Reject zero-area triangles (repeated corners or collinear points).

    Raises:
        InvalidElementsError: with the count and the location of the first.
    """
    repeated = (tris[:, 0] == tris[:, 1]) | (tris[:, 1] == tris[:, 2]) | (tris[:, 0] == tris[:, 2])
    areas = triangle_areas(points, tris)
    scale = float(np.median(areas)) if len(areas) else 0.0
    bad = np.flatnonzero(repeated | (areas <= 1e-12 * max(scale, 1e-300)))
    if len(bad):
        where = points[tris[bad[0]]].mean(axis=0)
        raise InvalidElementsError(
            f"{what} has {len(bad)} degenerate (zero-area) triangle(s), the first (#{bad[0]}) "
            f"near {_fmt(where)} m; repair the surface (e.g. remove duplicate or collinear "
            "vertices) before importing it"
        )


def check_closed(points: np.ndarray, tris: np.ndarray, what: str) -> None:
    """Require a closed, manifold surface: every edge shared by exactly two triangles.

    Raises:
        SurfaceNotClosedError: with the number of open and non-manifold edges and where.
    """
    edges, counts = unique_rows(tris[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2))
    open_edges = edges[counts == 1]
    nonmanifold = edges[counts > 2]
    if len(open_edges) == 0 and len(nonmanifold) == 0:
        return
    parts = []
    if len(open_edges):
        where = points[open_edges].reshape(-1, 3).mean(axis=0)
        length = float(
            np.linalg.norm(points[open_edges[:, 0]] - points[open_edges[:, 1]], axis=1).sum()
        )
        parts.append(
            f"{len(open_edges)} edge(s) belong to one triangle only (holes with a total rim of "
            f"{100 * length:.3g} cm, centred near {_fmt(where)} m)"
        )
    if len(nonmanifold):
        parts.append(
            f"{len(nonmanifold)} edge(s) are shared by three or more triangles (non-manifold, "
            f"the first at {_fmt(points[nonmanifold[0]].mean(axis=0))} m)"
        )
    raise SurfaceNotClosedError(
        f"{what} is not a closed surface: {'; '.join(parts)}. The surface must bound a volume: "
        "fill the holes (or export the solid, not an open patch)"
    )


def _segment_hits_triangle(
    p0: np.ndarray, p1: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray
) -> np.ndarray:
    """Whether segments p0-p1 cross triangles abc, strictly inside both (vectorised).

    Möller–Trumbore with small exclusion margins, so that triangles that merely
    touch (round-off) do not count; coplanar overlaps are not detected.
    """
    e1, e2, d = b - a, c - a, p1 - p0
    h = np.cross(d, e2)
    det = np.einsum("ij,ij->i", e1, h)
    scale = np.linalg.norm(e1, axis=1) * np.linalg.norm(e2, axis=1) * np.linalg.norm(d, axis=1)
    ok = np.abs(det) > 1e-12 * scale
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    s = p0 - a
    u = inv * np.einsum("ij,ij->i", s, h)
    q = np.cross(s, e1)
    v = inv * np.einsum("ij,ij->i", d, q)
    t = inv * np.einsum("ij,ij->i", e2, q)
    eps = 1e-9
    return ok & (u > eps) & (v > eps) & (u + v < 1 - eps) & (t > eps) & (t < 1 - eps)


def self_intersections(points: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """Pairs of triangles that cross each other, shape (k, 2).

    Candidate pairs come from a k-d tree on the centroids (two triangles can only
    meet if their centroids are closer than the sum of their radii, and the larger
    triangle's query finds the pair); pairs that share a vertex are neighbours in a
    valid surface and are skipped. A pair intersects if an edge of one crosses the
    other.
    """
    a, b, c = points[tris[:, 0]], points[tris[:, 1]], points[tris[:, 2]]
    centre = (a + b + c) / 3.0
    radius = np.max(np.stack([np.linalg.norm(v - centre, axis=1) for v in (a, b, c)]), axis=0)
    tree = cKDTree(centre)
    neighbours = tree.query_ball_point(centre, 2.0 * radius)
    counts = np.fromiter((len(n) for n in neighbours), dtype=np.int64, count=len(neighbours))
    i = np.repeat(np.arange(len(tris)), counts)
    j = np.fromiter((k for n in neighbours for k in n), dtype=np.int64, count=int(counts.sum()))
    keep = i < j
    i, j = i[keep], j[keep]
    close = np.linalg.norm(centre[i] - centre[j], axis=1) <= radius[i] + radius[j]
    i, j = i[close], j[close]
    shares = (tris[i][:, :, None] == tris[j][:, None, :]).any(axis=(1, 2))
    i, j = i[~shares], j[~shares]
    hit = np.zeros(len(i), dtype=bool)
    for first, second in ((i, j), (j, i)):
        ta, tb, tc = (points[tris[second, k]] for k in range(3))
        for e0, e1 in ((0, 1), (1, 2), (2, 0)):
            p0, p1 = points[tris[first, e0]], points[tris[first, e1]]
            hit |= _segment_hits_triangle(p0, p1, ta, tb, tc)
    pairs = np.stack([i[hit], j[hit]], axis=1)
    return np.unique(np.sort(pairs, axis=1), axis=0) if len(pairs) else pairs


def check_no_self_intersections(points: np.ndarray, tris: np.ndarray, what: str) -> None:
    """Reject a surface whose triangles cross each other.

    Raises:
        SelfIntersectionError: with the number of crossing pairs and where the first is.
    """
    pairs = self_intersections(points, tris)
    if len(pairs):
        where = points[tris[pairs[0]].ravel()].mean(axis=0)
        n_tris = len(np.unique(pairs))
        raise SelfIntersectionError(
            f"{what} intersects itself: {len(pairs)} pair(s) of triangles cross "
            f"({n_tris} triangles involved), the first near {_fmt(where)} m. A surface that "
            "crosses itself does not bound one volume: repair it (e.g. a boolean union of the "
            "overlapping parts)"
        )


def check_tetrahedra(points: np.ndarray, tets: np.ndarray, what: str) -> np.ndarray:
    """Reject degenerate or inverted tetrahedra; return them consistently positive.

    A mesh whose cells are *all* negatively oriented is only written with the other
    convention, so it is flipped rather than rejected.

    Raises:
        InvalidElementsError: naming how many cells are degenerate or inverted, and where.
    """
    vol = tet_volumes(points, tets)
    scale = float(np.median(np.abs(vol))) if len(vol) else 0.0
    degenerate = np.flatnonzero(np.abs(vol) <= 1e-9 * max(scale, 1e-300))
    if len(degenerate):
        where = points[tets[degenerate[0]]].mean(axis=0)
        raise InvalidElementsError(
            f"{what} has {len(degenerate)} degenerate (zero-volume) tetrahedra, the first "
            f"(#{degenerate[0]}) near {_fmt(where)} m; such elements have no stiffness and "
            "make the FE system singular"
        )
    positive, negative = np.flatnonzero(vol > 0), np.flatnonzero(vol < 0)
    if len(positive) and len(negative):
        minority = negative if len(negative) <= len(positive) else positive
        where = points[tets[minority[0]]].mean(axis=0)
        raise InvalidElementsError(
            f"{what} has {len(minority)} inverted tetrahedra (oriented opposite to the other "
            f"{len(tets) - len(minority)}), the first (#{minority[0]}) near {_fmt(where)} m; "
            "an inverted element has negative volume and the mesh is not a valid "
            "triangulation: regenerate or untangle it"
        )
    if len(negative):
        log.info("%s: all tetrahedra are negatively oriented; flipping them", what)
        tets = tets[:, [0, 2, 1, 3]]
    return tets


def check_face_manifold(tets: np.ndarray, what: str) -> None:
    """Require every triangular face to belong to at most two tetrahedra.

    Raises:
        InvalidElementsError: if faces are shared by three or more cells (overlapping cells).
    """
    _, counts = unique_rows(tets[:, TET_FACES].reshape(-1, 3))
    bad = int(np.sum(counts > 2))
    if bad:
        raise InvalidElementsError(
            f"{what} has {bad} face(s) shared by three or more tetrahedra: cells overlap"
        )


def point_surface_distance(
    query: np.ndarray, points: np.ndarray, tris: np.ndarray, cutoff: float
) -> np.ndarray:
    """Distance of each query point from a triangulated surface, exact up to ``cutoff``.

    Points farther than ``cutoff`` from every triangle get ``inf``: only triangles
    whose centroid is within ``cutoff`` plus the largest triangle radius are tried.
    """
    a, b, c = points[tris[:, 0]], points[tris[:, 1]], points[tris[:, 2]]
    centre = (a + b + c) / 3.0
    radius = float(np.max([np.linalg.norm(v - centre, axis=1).max() for v in (a, b, c)]))
    tree = cKDTree(centre)
    candidates = tree.query_ball_point(query, cutoff + radius)
    counts = np.fromiter((len(n) for n in candidates), dtype=np.int64, count=len(candidates))
    qi = np.repeat(np.arange(len(query)), counts)
    ti = np.fromiter((k for n in candidates for k in n), dtype=np.int64, count=int(counts.sum()))
    d = _point_triangle_distance(query[qi], a[ti], b[ti], c[ti])
    out = np.full(len(query), np.inf)
    np.minimum.at(out, qi, d)
    out[out > cutoff] = np.inf
    return out


def _point_triangle_distance(
    p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray
) -> np.ndarray:
    """Distance from points to triangles, pairwise.

    After Ericson, *Real-Time Collision Detection*, section 5.1.5.
    """

    def dot(u: np.ndarray, v: np.ndarray) -> np.ndarray:
        return np.einsum("ij,ij->i", u, v)

    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = dot(ab, ap), dot(ac, ap)
    bp = p - b
    d3, d4 = dot(ab, bp), dot(ac, bp)
    cp = p - c
    d5, d6 = dot(ab, cp), dot(ac, cp)
    va = d3 * d6 - d5 * d4
    vb = d5 * d2 - d1 * d6
    vc = d1 * d4 - d3 * d2
    denom = va + vb + vc
    safe = np.where(np.abs(denom) > 0, denom, 1.0)
    # Interior projection by default; the Voronoi regions of vertices and edges override it.
    closest = a + ab * (vb / safe)[:, None] + ac * (vc / safe)[:, None]

    def edge(mask: np.ndarray, start: np.ndarray, direction: np.ndarray, t: np.ndarray) -> None:
        t = np.clip(np.nan_to_num(t), 0.0, 1.0)
        closest[mask] = (start + direction * t[:, None])[mask]

    def vertex(mask: np.ndarray, corner: np.ndarray) -> None:
        closest[mask] = corner[mask]

    # Ericson tests the regions in the order A, B, AB, C, AC, BC; assigning them in the
    # reverse order lets the earlier tests win on shared borders, as in his code.
    with np.errstate(divide="ignore", invalid="ignore"):
        edge(
            (va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0),
            b,
            c - b,
            (d4 - d3) / ((d4 - d3) + (d5 - d6)),
        )
        edge((vb <= 0) & (d2 >= 0) & (d6 <= 0), a, ac, d2 / (d2 - d6))
        vertex((d6 >= 0) & (d5 <= d6), c)
        edge((vc <= 0) & (d1 >= 0) & (d3 <= 0), a, ab, d1 / (d1 - d3))
        vertex((d3 >= 0) & (d4 <= d3), b)
        vertex((d1 <= 0) & (d2 <= 0), a)
    return np.linalg.norm(p - closest, axis=1)
