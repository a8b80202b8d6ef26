"""Mesh the parametric breast, tag its boundaries by name, report quality, write XDMF and PNG."""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from meshes.exceptions import GeometryError
from meshes.parametric import (
    ANATOMICAL_BREAST_VOLUME_ML,
    ANATOMICAL_MAX_PROJECTION_M,
    BreastGeometry,
    add_elliptic_cylinder,
    add_mound_ellipsoid,
    build_occ_model,
    round_fold,
)
from meshes.quality import quality_report
from meshes.sizing import MeshSize, add_size_field
from meshes.tags import TISSUE, Boundary

__all__ = [
    "MeshSize",
    "classify_surfaces",
    "gmsh_quality",
    "gmsh_session",
    "mesh_arrays",
    "mesh_parametric",
    "mound_volume",
    "set_meshing_options",
    "surface_predicates",
    "write_parametric_mesh",
    "write_parametric_surface",
]

log = logging.getLogger(__name__)

TETRA_TYPES = (4, 11)  # gmsh element types: 4-node and 10-node tetrahedra
TRIANGLE_TYPES = (2, 9)  # 3-node and 6-node triangles


@contextmanager
def gmsh_session(name: str = "breast") -> Iterator[Any]:
    """Initialise gmsh quietly, yield ``gmsh.model``, and always finalise."""
    import gmsh

    gmsh.initialize(interruptible=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.option.setNumber("General.Verbosity", 2)
        gmsh.model.add(name)
        yield gmsh.model
    finally:
        gmsh.finalize()


def surface_predicates(geometry: BreastGeometry, tol: float) -> dict[Boundary, Callable]:
    """Point tests for each analytic cut surface; the skin is whatever is left.

    A face belongs to a surface only if *every* one of its mesh nodes lies on it:
    the centre of mass of a curved face lies off the face and cannot be trusted.
    """
    return {
        Boundary.RIB: lambda x: np.abs(geometry.rib_level_set(x)) < tol,
        Boundary.STERNAL: lambda x: np.abs(x[:, 1]) < tol,
        Boundary.AXILLA: lambda x: np.abs(geometry.axilla_plane_distance(x)) < tol,
        Boundary.CAUDAL: lambda x: np.abs(x[:, 2] - geometry.z_caudal) < tol,
        Boundary.CRANIAL: lambda x: np.abs(x[:, 2] - geometry.z_cranial) < tol,
    }


def classify_surfaces(
    model: Any, predicates: dict[Boundary, Callable]
) -> dict[Boundary, list[int]]:
    """Assign every meshed surface of ``model`` to a named boundary.

    Raises:
        GeometryError: if a face lies on two analytic surfaces at once.
    """
    groups: dict[Boundary, list[int]] = {b: [] for b in Boundary}
    for _, tag in model.getEntities(2):
        _, coords, _ = model.mesh.getNodes(2, tag, includeBoundary=True)
        x = coords.reshape(-1, 3)
        hits = [b for b, on_surface in predicates.items() if np.all(on_surface(x))]
        if len(hits) > 1:
            raise GeometryError(f"surface {tag} lies on several cut surfaces: {hits}")
        groups[hits[0] if hits else Boundary.SKIN].append(tag)
    return groups


def set_meshing_options(size: MeshSize) -> None:
    """Set the options of every gmsh mesh this project makes: sizes from its field, one seed."""
    import gmsh

    # Sizes come from the background field only; gmsh's defaults (sizes from CAD
    # points, curvature, boundary extension) would override the laws of MeshSize.
    gmsh.option.setNumber("Mesh.MeshSizeExtendFromBoundary", 0)
    gmsh.option.setNumber("Mesh.MeshSizeFromPoints", 0)
    gmsh.option.setNumber("Mesh.MeshSizeFromCurvature", 0)
    gmsh.option.setNumber("Mesh.MeshSizeMax", size.global_size)
    gmsh.option.setNumber("Mesh.Algorithm", 6)  # Frontal-Delaunay for 2D
    gmsh.option.setNumber("Mesh.Algorithm3D", 1)  # Delaunay
    gmsh.option.setNumber("Mesh.Optimize", 1)
    # Same mesh on every run: the sweep's material points must not move between jobs.
    gmsh.option.setNumber("Mesh.RandomSeed", 1)


def mesh_parametric(
    model: Any, geometry: BreastGeometry, size: MeshSize
) -> dict[Boundary, list[int]]:
    """Build, mesh and tag the parametric breast in ``model``.

    Returns:
        The gmsh surface tags of each named boundary.
    """
    volume = build_occ_model(model, geometry)
    add_size_field(model, geometry, size)
    set_meshing_options(size)
    model.mesh.generate(3)
    if size.order == 2:
        # Curved tetrahedra: the mid-edge nodes are put on the CAD surfaces, so the
        # curved rib and skin are represented to third order in the element size.
        model.mesh.setOrder(2)

    tol = 1e-6 * max(geometry.rib_depth, geometry.rib_half_width)
    groups = classify_surfaces(model, surface_predicates(geometry, tol))
    missing = [b.label for b, tags in groups.items() if not tags]
    if missing:
        raise GeometryError(f"no faces were found for boundary surface(s): {', '.join(missing)}")
    model.addPhysicalGroup(3, [volume], TISSUE, name="tissue")
    for boundary, tags in groups.items():
        model.addPhysicalGroup(2, tags, int(boundary), name=boundary.label)
    log.info(
        "meshed parametric breast: %s",
        {b.label: len(tags) for b, tags in groups.items()},
    )
    return groups


def mesh_arrays(
    model: Any, groups: dict[Boundary, list[int]]
) -> tuple[np.ndarray, np.ndarray, dict[Boundary, np.ndarray]]:
    """Nodes, tetrahedra (vertex columns only) and boundary triangles of a meshed model.

    Returns:
        ``(x (N, 3), tets (n, 4), facets)`` where indices refer to rows of ``x`` and
        ``facets`` maps each boundary to its triangles (m, 3), possibly empty.
    """
    node_tags, coords, _ = model.mesh.getNodes()
    x = coords.reshape(-1, 3)
    index = np.zeros(int(node_tags.max()) + 1, dtype=np.int64)
    index[node_tags.astype(np.int64)] = np.arange(len(node_tags))
    tets = []
    for etype in TETRA_TYPES:
        _, nodes = model.mesh.getElementsByType(etype)
        if len(nodes):
            n = model.mesh.getElementProperties(etype)[3]
            tets.append(index[nodes.reshape(-1, n)[:, :4].astype(np.int64)])
    facets: dict[Boundary, np.ndarray] = {}
    for boundary in Boundary:
        tris = [np.empty((0, 3), dtype=np.int64)]
        for s in groups.get(boundary, []):
            types, _, nodes = model.mesh.getElements(2, s)
            for etype, enodes in zip(types, nodes, strict=True):
                if etype in TRIANGLE_TYPES:
                    n = model.mesh.getElementProperties(etype)[3]
                    tris.append(index[enodes.reshape(-1, n)[:, :3].astype(np.int64)])
        facets[boundary] = np.concatenate(tris)
    return x, np.concatenate(tets), facets


def curved_measures(model: Any, groups: dict[Boundary, list[int]]) -> dict[str, Any]:
    """Volume and boundary areas of a second-order mesh, integrated over its curved cells.

    The figures of :func:`meshes.quality.quality_report` use the straight-sided
    tetrahedra through the vertices; the solver integrates over the curved ones.
    """

    def integrate(etype: int, tag: int = -1) -> float:
        if len(model.mesh.getElementsByType(etype, tag)[0]) == 0:
            return 0.0
        local, weights = model.mesh.getIntegrationPoints(etype, "Gauss4")
        _, det, _ = model.mesh.getJacobians(etype, local, tag)
        return float(np.sum(np.abs(det.reshape(-1, len(weights))) @ weights))

    volume = integrate(11)
    return {
        "volume_m3": volume,
        "volume_ml": 1e6 * volume,
        "area_m2": {b.label: sum(integrate(9, s) for s in tags) for b, tags in groups.items()},
    }


def gmsh_quality(model: Any, groups: dict[Boundary, list[int]]) -> dict[str, Any]:
    """Quality figures of the meshed model (see :func:`meshes.quality.quality_report`).

    Adds ``nodes`` (geometry nodes: more than ``vertices`` for order 2) and, for a
    second-order mesh, its ``curved`` volume and areas.
    """
    x, tets, facets = mesh_arrays(model, groups)
    tags = np.concatenate([model.mesh.getElementsByType(t)[0] for t in TETRA_TYPES])
    measures = {
        name: np.asarray(model.mesh.getElementQualities(tags, name))
        for name in ("minSICN", "gamma")
    }
    report = quality_report(x, tets, facets, measures)
    report["nodes"] = int(len(x))
    if len(model.mesh.getElementsByType(11)[0]):
        report["curved"] = curved_measures(model, groups)
    return report


def cad_measures(model: Any, groups: dict[Boundary, list[int]]) -> dict[str, Any]:
    """Exact volume and boundary areas of the CAD model (what the mesh approximates)."""
    occ = model.occ
    return {
        "volume_m3": float(sum(occ.getMass(3, tag) for _, tag in model.getEntities(3))),
        "area_m2": {
            b.label: float(sum(occ.getMass(2, t) for t in tags)) for b, tags in groups.items()
        },
    }


def mound_volume(geometry: BreastGeometry) -> float:
    """Volume of the mound, m³: the ellipsoid and the rounded fold outside the skin layer.

    This is the "breast volume" the report quotes: the tissue that stands out
    beyond the layer over the chest wall, not the layer under it.
    """
    with gmsh_session("mound") as model:
        g = geometry
        # The layer cylinder, long enough to hold the whole mound, fused with the
        # ellipsoid and the fold rounded as in the mesh: the mound is what it added.
        z0 = g.mound_z - 2 * (g.mound_length + g.mound_radius_cranial)
        cylinder = add_elliptic_cylinder(model, g, g.layer_thickness, z0, 2 * (g.mound_z - z0))
        layer = model.occ.getMass(3, cylinder)
        body, _ = model.occ.fuse([(3, cylinder)], [(3, add_mound_ellipsoid(model, g))])
        body = round_fold(model, g, body[0][1])
        model.occ.synchronize()
        return float(model.occ.getMass(3, body) - layer)


def anatomy(geometry: BreastGeometry, x: np.ndarray) -> dict[str, Any]:
    """Breast volume and projection of a parametric mesh, and whether they are plausible.

    Args:
        geometry: shape parameters.
        x: mesh node coordinates (N, 3).
    """
    volume_ml = 1e6 * mound_volume(geometry)
    projection = float(geometry.rib_distance(x).max())
    lo, hi = ANATOMICAL_BREAST_VOLUME_ML
    plausible = lo <= volume_ml <= hi and projection <= ANATOMICAL_MAX_PROJECTION_M
    if not plausible:
        log.warning(
            "the breast is anatomically implausible: volume %.0f ml (expected %.0f-%.0f), "
            "projection %.1f cm from the chest wall (expected <= %.0f cm)",
            volume_ml,
            lo,
            hi,
            100 * projection,
            100 * ANATOMICAL_MAX_PROJECTION_M,
        )
    return {
        "breast_volume_ml": volume_ml,
        "breast_volume_definition": (
            "mound only: the tissue outside the skin layer's outer surface (the ellipsoid "
            "and the rounded fold, minus the layer cylinder); the layer over the chest wall "
            "is not counted"
        ),
        "projection_from_chest_wall_m": projection,
        "projection_definition": "largest distance of a mesh node from the rib-cage surface",
        "mound_projection_from_skin_layer_m": geometry.mound_projection,
        "plausible": bool(plausible),
    }


def write_parametric_mesh(
    geometry: BreastGeometry,
    size: MeshSize,
    xdmf_path: str | Path,
    png_path: str | Path | None = None,
) -> dict[str, Any]:
    """Mesh the parametric breast, write mesh, cell and facet tags to XDMF (and a PNG).

    Returns:
        The mesh quality report, with the geometry and size parameters, the
        anatomical figures and the wall time of meshing.
    """
    from meshes.io import write_gmsh_model

    start = time.perf_counter()
    with gmsh_session() as model:
        groups = mesh_parametric(model, geometry, size)
        mesh_s = time.perf_counter() - start
        report = gmsh_quality(model, groups)
        cad = cad_measures(model, groups)
        x, _, facets = mesh_arrays(model, groups)
        write_gmsh_model(model, xdmf_path)
    report["source"] = "parametric"
    report["cad"] = cad
    # how much volume the straight-sided (or curved) cells lose against the exact CAD
    meshed = report.get("curved", report)["volume_m3"]
    report["volume_error_vs_cad"] = meshed / cad["volume_m3"] - 1.0
    report["anatomy"] = anatomy(geometry, x)
    report["geometry"] = geometry.as_dict()
    report["size"] = size.as_dict()
    report["mound_projection_m"] = geometry.mound_projection
    report["mesh_wall_s"] = mesh_s
    if png_path is not None:
        from meshes.plot import plot_boundaries

        plot_boundaries(
            x,
            facets,
            png_path,
            title=f"parametric breast: {report['cells']} tetrahedra (order {size.order}), "
            f"{report['dofs']['P2/P1']} P2/P1 unknowns",
        )
    log.info(
        "parametric mesh: %d cells, %d vertices, %.0f ml, meshed in %.2f s",
        report["cells"],
        report["vertices"],
        report["volume_ml"],
        mesh_s,
    )
    return report


def write_parametric_surface(geometry: BreastGeometry, size: MeshSize, path: str | Path) -> None:
    """Write the closed outer surface of the parametric breast (STL, OBJ, PLY: by suffix).

    This is what a user's surface scan of this geometry would look like: one
    triangulated closed surface, with no boundary names.
    """
    import meshio

    with gmsh_session() as model:
        build_occ_model(model, geometry)
        add_size_field(model, geometry, size)
        set_meshing_options(size)
        model.mesh.generate(2)
        groups = {Boundary.SKIN: [tag for _, tag in model.getEntities(2)]}
        x, tris = _surface_triangles(model, groups[Boundary.SKIN])
    used = np.unique(tris)
    remap = np.full(len(x), -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    meshio.write(str(path), meshio.Mesh(x[used], [("triangle", remap[tris])]))


def _surface_triangles(model: Any, surfaces: list[int]) -> tuple[np.ndarray, np.ndarray]:
    node_tags, coords, _ = model.mesh.getNodes()
    x = coords.reshape(-1, 3)
    index = np.zeros(int(node_tags.max()) + 1, dtype=np.int64)
    index[node_tags.astype(np.int64)] = np.arange(len(node_tags))
    tris = []
    for s in surfaces:
        _, nodes = model.mesh.getElementsByType(2, s)
        tris.append(index[nodes.reshape(-1, 3).astype(np.int64)])
    return x, np.concatenate(tris)
