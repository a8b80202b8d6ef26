"""How many bodies a closed surface bounds, and how they lie: apart, one inside another, crossing.

The import fills one closed surface, the breast on its chest wall, with tissue. A file that
holds two (a left and a right breast exported together, a segmented lesion beside the skin, a
second copy of the breast moved by a tool) would be filled as one mesh of two bodies, or, where
they cross, as their union: neither is the breast the user meant. So the pieces are counted
(triangles or tetrahedra joined by a shared vertex) and more than one is refused, naming each
piece's volume and centre and, where two cross, a point where they do.

Two pieces cross where a triangle of one passes through a triangle of the other
(:func:`meshes.checks.self_intersections`) or where a vertex of one lies inside the other (its
winding number): the second finds crossings whose triangles meet exactly along their edges,
as two mirror-image spheres do, which a test of edges through triangles' interiors misses.
"""

from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from meshes.checks import enclosed_volume, point_surface_distance, self_intersections
from meshes.exceptions import SeveralBodiesError

#: Vertices of a piece whose winding number about another is computed (evenly sampled).
SAMPLED_VERTICES = 500
#: Query point × triangle pairs evaluated at once (bounds the memory of a winding number).
CHUNK = 2_000_000


def vertex_pieces(cells: np.ndarray, n_points: int) -> np.ndarray:
    """Each point's connected piece of ``cells`` (triangles or tetrahedra sharing a vertex).

    Returns:
        The piece of every point, (n_points,); points of no cell get pieces of their own.
    """
    corners = cells.shape[1]
    first = np.repeat(cells[:, 0], corners - 1)
    other = cells[:, 1:].ravel()
    graph = coo_matrix((np.ones(len(first)), (first, other)), shape=(n_points, n_points))
    return connected_components(graph, directed=False)[1]


def winding_numbers(query: np.ndarray, points: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """The winding number of a closed triangulated surface about each query point.

    About 1 inside a closed outward surface (-1 for an inward one), 0 outside; the sum of the
    triangles' solid angles (van Oosterom and Strackee, IEEE Trans. Biomed. Eng. 30, 1983).
    """
    result = np.zeros(len(query))
    step = max(1, CHUNK // max(len(tris), 1))
    corners = [points[tris[:, k]] for k in range(3)]
    for start in range(0, len(query), step):
        q = query[start:start + step, None, :]
        a, b, c = (v[None, :, :] - q for v in corners)
        la, lb, lc = (np.linalg.norm(v, axis=2) for v in (a, b, c))
        det = np.einsum("qtk,qtk->qt", a, np.cross(b, c))
        denominator = (la * lb * lc + np.einsum("qtk,qtk->qt", a, b) * lc
                       + np.einsum("qtk,qtk->qt", a, c) * lb + np.einsum("qtk,qtk->qt", b, c) * la)
        result[start:start + step] = np.arctan2(det, denominator).sum(axis=1) / (2.0 * np.pi)
    return result


def _inside(points: np.ndarray, vertices: np.ndarray,
            tris: np.ndarray) -> tuple[np.ndarray, bool]:
    """The sampled ``vertices`` (indices) of one piece that lie inside the surface ``tris``.

    Returns:
        Those vertices, and whether every sampled vertex does (the piece lies wholly inside).
    """
    box = points[np.unique(tris)]
    in_box = np.all((points[vertices] > box.min(axis=0)) & (points[vertices] < box.max(axis=0)),
                    axis=1)
    near = vertices[in_box]
    if len(near) > SAMPLED_VERTICES:
        near = near[np.linspace(0, len(near) - 1, SAMPLED_VERTICES).astype(np.int64)]
    if len(near) == 0:
        return near, False
    inside = near[np.abs(winding_numbers(points[near], points, tris)) > 0.5]
    return inside, bool(in_box.all()) and len(inside) == len(near)


def _mm(x: np.ndarray) -> str:
    return "(" + ", ".join(f"{round(1e3 * v, 1) + 0.0:.1f}" for v in x) + ")"  # no "-0.0"


def _relation(points: np.ndarray, tris: np.ndarray, body: np.ndarray) -> str:
    """How the pieces lie: the first crossing found, else the first piece inside another."""
    pairs = self_intersections(points, tris)
    across = pairs[body[pairs[:, 0]] != body[pairs[:, 1]]] if len(pairs) else pairs
    if len(across):
        i, j = sorted(body[across[0]])
        where = points[tris[across[0]].ravel()].mean(axis=0)
        return f"bodies {i + 1} and {j + 1} cross each other near {_mm(where)} mm"
    n = int(body.max()) + 1
    vertices = [np.unique(tris[body == k]) for k in range(n)]
    lo = np.array([points[v].min(axis=0) for v in vertices])
    hi = np.array([points[v].max(axis=0) for v in vertices])
    nested = None
    for i in range(n):
        for j in range(n):
            if i == j or np.any(lo[j] > hi[i]) or np.any(hi[j] < lo[i]):
                continue  # boxes apart: neither can reach into the other
            inside, whole = _inside(points, vertices[j], tris[body == i])
            if len(inside) and not whole:  # partly inside: the surfaces cross
                # where: the vertex inside nearest the other's surface, by the crossing line
                depth = point_surface_distance(points[inside], points, tris[body == i],
                                               float(np.linalg.norm(hi[i] - lo[i])))
                return (f"bodies {min(i, j) + 1} and {max(i, j) + 1} cross each other near "
                        f"{_mm(points[inside[np.argmin(depth)]])} mm")
            if whole:
                nested = nested or f"body {j + 1} lies inside body {i + 1}"
    return nested or "they lie apart"


def check_one_body(points: np.ndarray, tris: np.ndarray, what: str,
                   cells: np.ndarray | None = None) -> None:
    """Require a closed surface to bound one body.

    Args:
        points: vertices, metres, in the file's axes.
        tris: the closed surface's triangles (of a volume mesh: its exterior faces).
        what: the input, for the message.
        cells: the cells whose pieces are the bodies (a volume mesh's tetrahedra, so that a
            cavity's surface does not count as a body); default the triangles.

    Raises:
        SeveralBodiesError: naming the number of bodies, each one's volume and centre (mm, in
            the file's axes), and where two cross or which lies inside which.
    """
    piece = vertex_pieces(tris if cells is None else cells, len(points))
    labels, body = np.unique(piece[tris[:, 0]], return_inverse=True)
    body = body.reshape(-1)
    if len(labels) < 2:
        return
    volumes = np.array([enclosed_volume(points, tris[body == k]) for k in range(len(labels))])
    order = np.argsort(-volumes, kind="stable")
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    body = rank[body]  # body 1 is the largest
    listed = [f"body {rank[k] + 1} of {1e6 * volumes[k]:.4g} ml around "
              f"{_mm(points[np.unique(tris[body == rank[k]])].mean(axis=0))} mm"
              for k in order[:3]]
    more = f" and {len(labels) - 3} more" if len(labels) > 3 else ""
    raise SeveralBodiesError(
        f"{what} holds {len(labels)} closed bodies, not one: {', '.join(listed)}{more} (in the "
        f"file's axes); {_relation(points, tris, body)}. The import fills one closed surface, "
        "the breast on its chest wall: export the breast alone, or join bodies that belong "
        "together into one surface (a boolean union)"
    )
