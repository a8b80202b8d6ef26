"""Mesh the parametric breast, tag its boundaries by name and write dolfinx XDMF."""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from meshes.parametric import BreastGeometry, GeometryError, build_occ_model
from meshes.quality import quality_report
from meshes.tags import TISSUE, Boundary

log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True)
class MeshSize:
    """Element sizes (metres) and geometric order.

    Attributes:
        global_size: target element size away from the mound.
        mound_size: target element size inside the mound.
        order: geometric order of the mesh (1: straight tetrahedra, 2: curved).
    """

    global_size: float = 0.012
    mound_size: float = 0.008
    order: int = 1

    def __post_init__(self) -> None:
        for name in ("global_size", "mound_size"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise GeometryError(f"mesh.{name} must be a positive length, got {value!r}")
        if self.order not in (1, 2):
            raise GeometryError(f"mesh.order must be 1 or 2, got {self.order!r}")

    def as_dict(self) -> dict[str, Any]:
        """Parameters as a plain mapping (for JSON metadata)."""
        return asdict(self)


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


def mesh_parametric(model: Any, geometry: BreastGeometry, size: MeshSize) -> dict[Boundary, list[int]]:
    """Build, mesh and tag the parametric breast in ``model``.

    Returns:
        The gmsh surface tags of each named boundary.
    """
    volume = build_occ_model(model, geometry)

    # Size field: fine inside (and just around) the mound, where displacements peak.
    base, axis = geometry.mound_frame()
    centre = base + 0.5 * geometry.mound_projection * axis
    radius = 0.5 * geometry.mound_projection + max(
        geometry.mound_radius_lateral, geometry.mound_radius_cranial
    )
    field = model.mesh.field
    ball = field.add("Ball")
    field.setNumber(ball, "Radius", radius)
    field.setNumber(ball, "Thickness", radius)
    field.setNumber(ball, "VIn", size.mound_size)
    field.setNumber(ball, "VOut", size.global_size)
    for key, value in zip(("XCenter", "YCenter", "ZCenter"), centre, strict=True):
        field.setNumber(ball, key, float(value))
    field.setAsBackgroundMesh(ball)

    import gmsh

    gmsh.option.setNumber("Mesh.MeshSizeExtendFromBoundary", 0)
    gmsh.option.setNumber("Mesh.MeshSizeFromPoints", 0)
    gmsh.option.setNumber("Mesh.MeshSizeFromCurvature", 0)
    gmsh.option.setNumber("Mesh.MeshSizeMax", size.global_size)
    gmsh.option.setNumber("Mesh.Algorithm", 6)  # Frontal-Delaunay for 2D
    gmsh.option.setNumber("Mesh.Algorithm3D", 1)  # Delaunay
    gmsh.option.setNumber("Mesh.Optimize", 1)
    model.mesh.generate(3)
    if size.order == 2:
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


def gmsh_quality(model: Any, groups: dict[Boundary, list[int]]) -> dict[str, Any]:
    """Quality figures of the meshed model (see :func:`meshes.quality.quality_report`)."""
    node_tags, coords, _ = model.mesh.getNodes()
    x = coords.reshape(-1, 3)
    index = np.zeros(int(node_tags.max()) + 1, dtype=np.int64)
    index[node_tags.astype(np.int64)] = np.arange(len(node_tags))
    tets, tet_tags = [], []
    for etype in (4, 11):  # linear and quadratic tetrahedra
        tags, nodes = model.mesh.getElementsByType(etype)
        if len(tags):
            n = model.mesh.getElementProperties(etype)[3]
            tets.append(index[nodes.reshape(-1, n)[:, :4].astype(np.int64)])
            tet_tags.append(tags)
    tet_array, tag_array = np.concatenate(tets), np.concatenate(tet_tags)
    facets = {}
    for boundary, surfaces in groups.items():
        tris = []
        for s in surfaces:
            types, _, nodes = model.mesh.getElements(2, s)
            for etype, enodes in zip(types, nodes, strict=True):
                n = model.mesh.getElementProperties(etype)[3]
                tris.append(index[enodes.reshape(-1, n)[:, :3].astype(np.int64)])
        facets[boundary] = np.concatenate(tris)
    measures = {
        name: np.asarray(model.mesh.getElementQualities(tag_array, name))
        for name in ("minSICN", "gamma")
    }
    return quality_report(x, tet_array, facets, measures)


def write_parametric_mesh(
    geometry: BreastGeometry, size: MeshSize, xdmf_path: str | Path
) -> dict[str, Any]:
    """Mesh the parametric breast, write mesh, cell and facet tags to XDMF.

    Returns:
        The mesh quality report, with the geometry and size parameters.
    """
    from meshes.io import write_gmsh_model

    with gmsh_session() as model:
        groups = mesh_parametric(model, geometry, size)
        report = gmsh_quality(model, groups)
        write_gmsh_model(model, xdmf_path)
    report["geometry"] = geometry.as_dict()
    report["size"] = size.as_dict()
    report["mound_projection_m"] = geometry.mound_projection
    return report
