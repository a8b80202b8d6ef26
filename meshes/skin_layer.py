"""The parametric breast with its skin resolved: a layer of cells of the skin's thickness.

The skin is 1–2.5 mm thick and the cells of the default mesh 6–25 mm, so the solver carries it
as a membrane on the ``skin`` boundary (:class:`fem.materials.SkinLayer`). To check that
membrane on the breast itself, this module meshes the same breast with the skin as cells:

1. gmsh meshes the body under the skin (:func:`meshes.parametric.build_occ_model` with
   ``inset`` the skin's thickness t: the same rib and cut planes, the skin side moved into the
   body by t), graded to ``in_plane_size`` under its skin side where that is given;
2. each node of that inner skin surface is pushed out by the skin's thickness: along the
   surface's normal (gmsh's, of the CAD face), within the cut plane for a node on one (so
   that the layer's side faces lie in the cut planes), at a corner or a crease the least
   vector whose component along every adjacent face's normal is t;
3. the prisms between the two surfaces, ``cells_across`` of them per column, are split into
   three tetrahedra each by the smallest-index rule (each quadrilateral face cut by the
   diagonal through its smallest-index vertex, the same rule on both of its prisms), so that
   the layer conforms to itself and to the body under it.

The layer's cells are tagged :attr:`meshes.tags.Tissue.SKIN`, the body's fat; the outer
surface is the ``skin`` boundary, and the rib and cut planes keep their names (the layer's
side faces join the cut plane they lie in). The cells are anisotropic: in-plane as large as the
body's surface cells, across t / ``cells_across``. The mesh is straight-sided (order 1), and
the same on every run (gmsh's seed is fixed, the rest is arithmetic).
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from meshes.build import (
    classify_surfaces,
    gmsh_session,
    mesh_arrays,
    set_meshing_options,
    surface_predicates,
)
from meshes.exceptions import GeometryError
from meshes.parametric import BreastGeometry, build_occ_model
from meshes.quality import exterior_faces, quality_report, tet_volumes, triangle_areas
from meshes.sizing import MeshSize, add_size_field
from meshes.tags import Boundary, Tissue

__all__ = ["SkinLayerSpec", "layer_directions", "mesh_skin_layer", "prism_tets",
           "write_skin_layer_mesh"]

log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True)
class SkinLayerSpec:
    """How the skin's layer of cells is made.

    Attributes:
        thickness: the skin's thickness t, m.
        cells_across: cells across the layer (prisms per column, three tetrahedra each).
        in_plane_size: the cells' size along the skin, m, growing into the body by the
            mesh's ``grading``; None: the mesh's own size laws alone.
    """

    thickness: float = 0.0015
    cells_across: int = 1
    in_plane_size: float | None = None

    def __post_init__(self) -> None:
        if not (math.isfinite(self.thickness) and 0.0 < self.thickness <= 0.01):
            raise GeometryError(f"the skin layer's thickness must lie in (0, 0.01] m, got "
                                f"{self.thickness!r}")
        if not (isinstance(self.cells_across, int) and 1 <= self.cells_across <= 8):
            raise GeometryError(f"cells across the skin layer must be 1 to 8, got "
                                f"{self.cells_across!r}")
        if self.in_plane_size is not None and not (math.isfinite(self.in_plane_size)
                                                   and self.in_plane_size > 0):
            raise GeometryError(f"the skin layer's in-plane size must be positive, got "
                                f"{self.in_plane_size!r}")

    def as_dict(self) -> dict[str, Any]:
        """JSON-friendly."""
        return asdict(self)


def _plane_normals(geometry: BreastGeometry) -> dict[Boundary, np.ndarray]:
    """The unit normal of each cut plane (the rib is a cylinder the skin never reaches)."""
    d = geometry.radial_direction(geometry.axilla_angle)
    return {
        Boundary.STERNAL: np.array([0.0, 1.0, 0.0]),
        Boundary.CRANIAL: np.array([0.0, 0.0, 1.0]),
        Boundary.CAUDAL: np.array([0.0, 0.0, 1.0]),
        Boundary.AXILLA: np.array([-d[1], d[0], 0.0]),
    }


def _cad_skin_faces(model: Any, volume: int, predicates: dict) -> list[int]:
    """The volume's CAD faces on no named surface (its skin side), from points of each face."""
    faces = []
    for _, face in model.getBoundary([(3, volume)], oriented=False):
        lo, hi = model.getParametrizationBounds(2, face)
        grid = np.stack(np.meshgrid(np.linspace(lo[0], hi[0], 5), np.linspace(lo[1], hi[1], 5)),
                        -1).reshape(-1, 2)
        x = np.reshape(model.getValue(2, face, grid.ravel().tolist()), (-1, 3))
        if not any(np.all(on(x)) for on in predicates.values()):
            faces.append(face)
    return faces


def _add_skin_size(model: Any, faces: list[int], size: float, grading: float,
                   background: int) -> None:
    """Cap the background size by ``size + grading * distance from faces``."""
    field = model.mesh.field
    extent = max(float(np.linalg.norm(np.subtract(*np.reshape(
        model.getBoundingBox(2, f), (2, 3))[::-1]))) for f in faces)
    distance = field.add("Distance")
    field.setNumbers(distance, "SurfacesList", faces)
    field.setNumber(distance, "Sampling", int(np.clip(math.ceil(2 * extent / size), 20, 400)))
    law = field.add("MathEval")
    field.setString(law, "F", f"{size!r} + {grading!r} * F{distance}")
    both = field.add("Min")
    field.setNumbers(both, "FieldsList", [background, law])
    field.setAsBackgroundMesh(both)


def layer_directions(normals: list[list[np.ndarray]], planes: list[list[np.ndarray]],
                     thickness: float) -> np.ndarray:
    """Each skin node's push through the layer: the least d with d·n = t, d·m = 0.

    Args:
        normals: per node, the outward unit normals of the skin faces it lies on.
        planes: per node, the unit normals of the cut planes it lies on.
        thickness: t.

    Returns:
        (nodes, 3): t n on a smooth face; within the plane on a cut plane; the mitred corner
        where faces meet at an angle.
    """
    out = np.empty((len(normals), 3))
    for i, (ns, ms) in enumerate(zip(normals, planes, strict=True)):
        A = np.array(list(ns) + list(ms))
        b = np.concatenate([np.full(len(ns), thickness), np.zeros(len(ms))])
        out[i] = np.linalg.lstsq(A, b, rcond=1e-8)[0]
    return out


def prism_tets(bottom: np.ndarray, top: np.ndarray, order: np.ndarray) -> np.ndarray:
    """The three tetrahedra of each prism, split by the smallest-index rule.

    Args:
        bottom: (prisms, 3) vertex ids of the lower triangles.
        top: (prisms, 3) vertex ids of the upper ones, column for column.
        order: (prisms, 3) the rank of each column (its skin node's index): every
            quadrilateral face is cut by the diagonal from its lower-ranked bottom vertex, which
            both prisms sharing it agree on.

    Returns:
        (3 prisms, 4) tetrahedra.
    """
    rank = np.argsort(order, axis=1)
    b = np.take_along_axis(bottom, rank, axis=1)
    t = np.take_along_axis(top, rank, axis=1)
    i, j, k = (0, 1, 2)
    return np.concatenate([
        np.stack([b[:, i], b[:, j], b[:, k], t[:, k]], 1),
        np.stack([b[:, i], b[:, j], t[:, j], t[:, k]], 1),
        np.stack([b[:, i], t[:, i], t[:, j], t[:, k]], 1),
    ])


def _skin_normals(model: Any, faces: list[int], x: np.ndarray, index: np.ndarray,
                  outward: np.ndarray, local: np.ndarray) -> list[list[np.ndarray]]:
    """Per skin node, the CAD normal of each skin face it lies on, turned outward.

    ``outward`` is the nodes' mesh normal (from the outward skin triangles), which gives the
    CAD normals' sign; ``local`` maps a node's row of ``x`` to its skin index.
    """
    normals: list[list[np.ndarray]] = [[] for _ in range(len(outward))]
    for face in faces:
        tags, _, _ = model.mesh.getNodes(2, face, includeBoundary=True)
        rows = index[tags.astype(np.int64)]
        _, uv = model.getClosestPoint(2, face, x[rows].ravel().tolist())
        n = np.reshape(model.getNormal(face, list(uv)), (-1, 3))
        n /= np.linalg.norm(n, axis=1)[:, None]
        s = local[rows]
        n *= np.sign(np.einsum("ij,ij->i", n, outward[s]))[:, None]
        for node, normal in zip(s, n, strict=True):
            normals[node].append(normal)
    return normals


def mesh_skin_layer(
    model: Any, geometry: BreastGeometry, size: MeshSize, layer: SkinLayerSpec
) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict[Boundary, np.ndarray], dict[str, Any]]:
    """Mesh the breast with its skin as a layer of cells, in ``model`` (the body under it).

    Returns:
        ``(x, tets, tissues, facets, figures)``: vertices (N, 3), positively oriented
        tetrahedra (n, 4), each cell's :class:`Tissue` value, each boundary's triangles, and
        the layer's figures (cells, thickness, in-plane edges).

    Raises:
        GeometryError: for curved cells asked (order 2), or a layer that does not fit.
    """
    if size.order != 1:
        raise GeometryError("the skin layer's mesh is straight-sided: mesh.size.order must be 1")
    t = layer.thickness
    volume = build_occ_model(model, geometry, inset=t)
    tol = 1e-6 * max(geometry.rib_depth, geometry.rib_half_width)
    predicates = surface_predicates(geometry, tol)
    background = add_size_field(model, geometry, size)
    if layer.in_plane_size is not None:
        faces = _cad_skin_faces(model, volume, predicates)
        _add_skin_size(model, faces, layer.in_plane_size, size.grading, background)
    set_meshing_options(size)
    model.mesh.generate(3)
    groups = classify_surfaces(model, predicates)
    x, tets, facets = mesh_arrays(model, groups)
    tets = _positive(x, tets)

    # the body's skin side: its nodes, outward triangles and mesh normals
    outward_tris = {tuple(sorted(f)): f for f in exterior_faces(tets)}
    base = np.array([outward_tris[tuple(sorted(f))] for f in facets[Boundary.SKIN]])
    skin_nodes = np.unique(base)
    local = np.full(len(x), -1, dtype=np.int64)
    local[skin_nodes] = np.arange(len(skin_nodes))
    tri_normal = np.cross(x[base[:, 1]] - x[base[:, 0]], x[base[:, 2]] - x[base[:, 0]])
    mesh_normal = np.zeros((len(skin_nodes), 3))
    for corner in range(3):
        np.add.at(mesh_normal, local[base[:, corner]], tri_normal)
    node_tags, _, _ = model.mesh.getNodes()
    index = np.zeros(int(node_tags.max()) + 1, dtype=np.int64)
    index[node_tags.astype(np.int64)] = np.arange(len(node_tags))
    normals = _skin_normals(model, groups[Boundary.SKIN], x, index, mesh_normal, local)
    plane_normals = _plane_normals(geometry)
    on_plane = {b: predicates[b](x[skin_nodes]) for b in plane_normals}
    planes = [[m for b, m in plane_normals.items() if on_plane[b][i]]
              for i in range(len(skin_nodes))]
    push = layer_directions(normals, planes, t)

    # the layers of nodes and their prisms
    n_across, n_nodes, m = layer.cells_across, len(x), len(skin_nodes)
    new = [x[skin_nodes] + (k / n_across) * push for k in range(1, n_across + 1)]
    x_all = np.concatenate([x, *new])

    def ids(k: int, s: np.ndarray) -> np.ndarray:  # layer k's node of skin index s (0: body's)
        return skin_nodes[s] if k == 0 else n_nodes + (k - 1) * m + s

    tri = local[base]
    layer_tets = [prism_tets(ids(k, tri), ids(k + 1, tri), tri) for k in range(n_across)]
    layer_tets = _positive(x_all, np.concatenate(layer_tets))
    # the layer's side faces on the cut planes: the quadrilaterals under the skin's rim edges,
    # cut as the prisms are
    edges = np.sort(tri[:, [[0, 1], [1, 2], [2, 0]]].reshape(-1, 2), axis=1)
    rim, counts = np.unique(edges, axis=0, return_counts=True)
    rim = rim[counts == 1]
    out_facets = {b: [f] for b, f in facets.items() if b is not Boundary.SKIN}
    for b in plane_normals:
        on = rim[on_plane[b][rim[:, 0]] & on_plane[b][rim[:, 1]]]
        for k in range(n_across):
            lo, hi = ids(k, on[:, 0]), ids(k, on[:, 1])
            lo_up, hi_up = ids(k + 1, on[:, 0]), ids(k + 1, on[:, 1])
            out_facets[b] += [np.stack([lo, hi, hi_up], 1), np.stack([lo, hi_up, lo_up], 1)]
    out_facets[Boundary.SKIN] = [ids(n_across, tri)]
    all_facets = {b: np.concatenate(f) for b, f in out_facets.items()}
    all_tets = np.concatenate([tets, layer_tets])
    tissues = np.concatenate([np.full(len(tets), int(Tissue.FAT)),
                              np.full(len(layer_tets), int(Tissue.SKIN))])
    across = np.array([p @ n[0] for p, n in zip(push, normals, strict=True)])
    unique_edges = np.unique(edges, axis=0)
    edge_lengths = np.linalg.norm(x[skin_nodes[unique_edges[:, 0]]]
                                  - x[skin_nodes[unique_edges[:, 1]]], axis=1)
    figures = {
        "spec": layer.as_dict(),
        "skin_cells": int(len(layer_tets)),
        "skin_volume_ml": float(1e6 * np.abs(tet_volumes(x_all, layer_tets)).sum()),
        "skin_area_m2": float(triangle_areas(x_all, all_facets[Boundary.SKIN]).sum()),
        "thickness_along_normal_m": [float(across.min()), float(across.max())],
        "push_length_m": [float(np.linalg.norm(push, axis=1).min()),
                          float(np.linalg.norm(push, axis=1).max())],
        "in_plane_edge_m": {"min": float(edge_lengths.min()),
                            "mean": float(edge_lengths.mean()),
                            "max": float(edge_lengths.max())},
        "aspect_ratio_mean": float(edge_lengths.mean() * n_across / t),
    }
    return x_all, all_tets, tissues, all_facets, figures


def _positive(x: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """The tetrahedra, each with its first two vertices swapped where it was negative."""
    tets = np.array(tets, dtype=np.int64)
    negative = tet_volumes(x, tets) < 0
    tets[negative, :2] = tets[negative, 1::-1]
    return tets


def write_skin_layer_mesh(
    geometry: BreastGeometry, size: MeshSize, layer: SkinLayerSpec, xdmf_path: str | Path,
    fat_path: str | Path | None = None,
) -> dict[str, Any]:
    """Mesh the breast with its skin as cells (:func:`mesh_skin_layer`); write it as XDMF.

    ``fat_path``: also write the same mesh with every cell fat there, for the skin membrane
    on the same cells (a mesh with skin cells gets no membrane).

    Returns:
        The quality report (:func:`meshes.quality.quality_report`, gmsh's element qualities),
        with the layer's figures under ``skin_layer``, the geometry, size and wall time.
    """
    from meshes.io import add_tagged_mesh, write_gmsh_model

    start = time.perf_counter()
    with gmsh_session("skin_layer") as model:
        x, tets, tissues, facets, figures = mesh_skin_layer(model, geometry, size, layer)
    mesh_s = time.perf_counter() - start
    with gmsh_session("skin_layer_cells") as model:
        add_tagged_mesh(model, x, tets, facets, tissues)
        elements = model.mesh.getElementsByType(4)[0]
        measures = {name: np.asarray(model.mesh.getElementQualities(elements, name))
                    for name in ("minSICN", "gamma")}
        write_gmsh_model(model, xdmf_path)
    if fat_path is not None:
        with gmsh_session("skin_layer_fat") as model:
            add_tagged_mesh(model, x, tets, facets, np.full(len(tets), int(Tissue.FAT)))
            write_gmsh_model(model, fat_path)
    report = quality_report(x, tets, facets, measures)
    report["source"] = "parametric, skin layer"
    report["skin_layer"] = figures
    report["tissue_cells"] = {Tissue(int(v)).label: int(n) for v, n in
                              zip(*np.unique(tissues, return_counts=True), strict=True)}
    report["geometry"] = geometry.as_dict()
    report["size"] = size.as_dict()
    report["mesh_wall_s"] = mesh_s
    log.info("skin layer mesh: %d cells (%d of skin, %d across), %d vertices, %.1f s",
             report["cells"], figures["skin_cells"], layer.cells_across, report["vertices"],
             mesh_s)
    return report
