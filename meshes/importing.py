"""Import a person's own geometry: a closed surface or a volume mesh, with named boundaries.

Accepted inputs (read with meshio):

* a **closed triangulated surface** (``.stl``, ``.obj``, ``.ply``, or a ``.msh``/``.vtu``
  holding only triangles), which gmsh fills with tetrahedra (keeping the surface
  triangles, or remeshing the surface to ``mesh.size`` with ``remesh: true``);
* a **tetrahedral volume mesh** (``.msh``, ``.vtu``, ``.xdmf``), used as it is.

The boundary is then named by rules (:class:`BoundaryRule`): the rib surface
(the fixed chest wall) must be selected, by a physical-group name or number of
the file, or as the facets lying within a distance of a plane or of another
surface (e.g. a segmented rib cage). Other named surfaces may be selected the
same way; every boundary facet no rule selects is skin.

Every kind of broken input stops with a typed error from :mod:`meshes.exceptions`
that names the problem: implausible size for the declared units, surface not
closed, self-intersecting, degenerate or inverted elements, no rib facets.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from meshes.checks import (
    UNITS,
    check_closed,
    check_face_manifold,
    check_no_self_intersections,
    check_plausible_size,
    check_tetrahedra,
    check_triangles,
    merge_duplicate_points,
    point_surface_distance,
)
from meshes.exceptions import (
    GeometryError,
    MeshInputError,
    NoRibFacetsError,
    SurfaceRuleError,
)
from meshes.quality import exterior_faces
from meshes.sizing import MeshSize
from meshes.tags import Boundary

log = logging.getLogger(__name__)

SURFACE_SUFFIXES = (".stl", ".obj", ".ply")
VOLUME_SUFFIXES = (".msh", ".vtu", ".xdmf")


@dataclass(frozen=True, slots=True)
class BoundaryRule:
    """How to find one named boundary among the boundary facets of an imported mesh.

    Exactly one of ``group``, ``plane`` or ``surface`` is set.

    Attributes:
        group: a physical-group name (gmsh ``.msh``) or an integer tag of the file's
            triangle cell data.
        plane: ``(point, normal)`` of a plane, metres after unit conversion.
        surface: path of a triangulated surface (STL/OBJ/PLY, same units as the model).
        distance: facets whose every vertex lies within this distance of the plane or
            surface are selected, metres.
    """

    group: str | int | None = None
    plane: tuple[tuple[float, float, float], tuple[float, float, float]] | None = None
    surface: str | None = None
    distance: float = 0.001

    def __post_init__(self) -> None:
        given = [k for k in ("group", "plane", "surface") if getattr(self, k) is not None]
        if len(given) != 1:
            raise GeometryError(
                "a boundary rule needs exactly one of group, plane or surface, "
                f"got {given or 'none'}"
            )
        if not (math.isfinite(self.distance) and self.distance > 0):
            raise GeometryError(
                f"a boundary rule's distance must be positive, got {self.distance!r}"
            )
        if self.plane is not None:
            point, normal = self.plane
            if len(point) != 3 or len(normal) != 3 or np.linalg.norm(normal) == 0:
                raise GeometryError(
                    "a plane rule needs a 3-vector point and a non-zero 3-vector normal"
                )

    @classmethod
    def from_mapping(cls, values: dict[str, Any], units: str = "m") -> BoundaryRule:
        """Build from a config mapping; lengths in the file's ``units`` become metres.

        Forms: ``{group: rib}``, ``{plane: {point: [x, y, z], normal: [nx, ny, nz]},
        distance: d}``, ``{surface: path.stl, distance: d}``.
        """
        known = {"group", "plane", "surface", "distance"}
        unknown = sorted(set(values) - known)
        if unknown:
            raise GeometryError(f"unknown boundary-rule key(s): {', '.join(unknown)}")
        scale = UNITS[units]
        plane = None
        if values.get("plane") is not None:
            p = values["plane"]
            if set(p) != {"point", "normal"}:
                raise GeometryError("a plane rule is {point: [x, y, z], normal: [nx, ny, nz]}")
            plane = (
                tuple(scale * float(v) for v in p["point"]),
                tuple(float(v) for v in p["normal"]),
            )
        # like the plane's point, the distance is in the file's units; 1 mm by default
        distance = scale * float(values["distance"]) if "distance" in values else 0.001
        return cls(
            group=values.get("group"),
            plane=plane,
            surface=str(values["surface"]) if values.get("surface") is not None else None,
            distance=distance,
        )

    def describe(self) -> str:
        """The rule in words, for messages."""
        if self.group is not None:
            return f"group {self.group!r}"
        if self.plane is not None:
            point, normal = self.plane
            return f"within {1e3 * self.distance:g} mm of the plane through {point} normal {normal}"
        return f"within {1e3 * self.distance:g} mm of the surface {self.surface}"


@dataclass(frozen=True, slots=True)
class ImportSpec:
    """What to import and how to name its boundary (the ``mesh.file`` config section).

    Attributes:
        path: the surface or volume mesh file.
        units: length unit of the file (``m``, ``cm`` or ``mm``).
        surfaces: a rule per named boundary; ``rib`` is required.
        remesh: for a surface input, remesh the surface to ``mesh.size`` (True) or
            keep its triangles as the boundary of the volume mesh (False).
    """

    path: str
    units: str = "m"
    surfaces: dict[Boundary, BoundaryRule] = field(default_factory=dict)
    remesh: bool = False

    def __post_init__(self) -> None:
        if self.units not in UNITS:
            raise GeometryError(
                f"mesh.file.units must be one of {sorted(UNITS)}, got {self.units!r}"
            )
        suffix = Path(self.path).suffix.lower()
        if suffix not in SURFACE_SUFFIXES + VOLUME_SUFFIXES:
            raise MeshInputError(
                f"mesh.file.path {self.path!r}: unsupported file type {suffix!r}; expected a "
                f"surface ({', '.join(SURFACE_SUFFIXES)}) or a volume mesh "
                f"({', '.join(VOLUME_SUFFIXES)})"
            )
        if Boundary.RIB not in self.surfaces:
            raise GeometryError(
                "mesh.file.surfaces must give a rule for the rib (the fixed chest-wall surface)"
            )

    @classmethod
    def from_mapping(cls, values: dict[str, Any]) -> ImportSpec:
        """Build from the ``mesh.file`` config mapping (boundary names as in :class:`Boundary`)."""
        known = {"path", "units", "surfaces", "remesh"}
        unknown = sorted(set(values) - known)
        if unknown:
            raise GeometryError(f"unknown mesh.file key(s): {', '.join(unknown)}")
        if "path" not in values:
            raise GeometryError("mesh.file.path is required when mesh.source is 'file'")
        units = values.get("units", "m")
        if units not in UNITS:
            raise GeometryError(f"mesh.file.units must be one of {sorted(UNITS)}, got {units!r}")
        surfaces = {
            Boundary.from_label(name): BoundaryRule.from_mapping(rule, units)
            for name, rule in (values.get("surfaces") or {}).items()
        }
        return cls(
            path=str(values["path"]),
            units=units,
            surfaces=surfaces,
            remesh=bool(values.get("remesh", False)),
        )

    def input_files(self) -> list[str]:
        """Every file the import reads (for the workflow's dependencies)."""
        return [self.path] + [r.surface for r in self.surfaces.values() if r.surface is not None]


@dataclass(frozen=True)
class InputMesh:
    """A file's content in metres: points, tetrahedra (possibly none), triangles and groups.

    Attributes:
        points: (N, 3) coordinates, metres.
        tets: (n, 4) tetrahedra, or (0, 4) for a surface.
        triangles: (m, 3) triangles of the file.
        triangle_groups: (m,) integer group of each triangle (-1: none).
        group_names: physical name -> group integer.
    """

    points: np.ndarray
    tets: np.ndarray
    triangles: np.ndarray
    triangle_groups: np.ndarray
    group_names: dict[str, int]

    @property
    def is_volume(self) -> bool:
        """Whether the file holds tetrahedra (else it is a surface)."""
        return len(self.tets) > 0


def read_input(path: str | Path, units: str) -> InputMesh:
    """Read a surface or volume mesh with meshio and convert it to metres.

    Raises:
        MeshInputError: if the file is missing, unreadable, or holds neither
            tetrahedra nor triangles.
    """
    import meshio

    path = Path(path)
    if not path.is_file():
        raise MeshInputError(f"mesh file {path} does not exist")
    try:
        mesh = meshio.read(str(path))
    # meshio raises many types (and its XDMF reader calls sys.exit): all mean "cannot read"
    except (Exception, SystemExit) as err:
        if path.suffix.lower() == ".xdmf":
            # meshio reads single-grid XDMF only; dolfinx writes mesh and tags as several
            return _read_dolfinx_xdmf(path, units, err)
        raise MeshInputError(f"cannot read {path}: {type(err).__name__}: {err}") from err
    scale = UNITS[units]
    points = np.asarray(mesh.points, dtype=float)[:, :3] * scale
    tets, tris, groups = [], [], []
    physical = mesh.cell_data.get("gmsh:physical")
    int_data = [
        name
        for name, blocks in mesh.cell_data.items()
        if name != "gmsh:geometrical"
        and all(np.issubdtype(np.asarray(b).dtype, np.integer) for b in blocks)
    ]
    tag_name = "gmsh:physical" if physical is not None else (int_data[0] if int_data else None)
    for k, block in enumerate(mesh.cells):
        data = np.asarray(block.data, dtype=np.int64)
        if block.type in ("tetra", "tetra10"):
            tets.append(data[:, :4])  # vertices only: imported meshes are linear
        elif block.type in ("triangle", "triangle6"):
            tris.append(data[:, :3])
            tags = np.asarray(mesh.cell_data[tag_name][k]).reshape(-1) if tag_name else None
            groups.append(tags.astype(np.int64) if tags is not None else np.full(len(data), -1))
        elif block.type == "quad":
            # split quads of a surface scan into two triangles each
            tris.append(np.concatenate([data[:, [0, 1, 2]], data[:, [0, 2, 3]]]))
            groups.append(np.full(2 * len(data), -1))
    if not tets and not tris:
        types = sorted({b.type for b in mesh.cells})
        raise MeshInputError(
            f"{path} holds no tetrahedra or triangles (cell types: {', '.join(types) or 'none'})"
        )
    names = {str(name): int(value[0]) for name, value in (mesh.field_data or {}).items()}
    return InputMesh(
        points=points,
        tets=np.concatenate(tets) if tets else np.empty((0, 4), dtype=np.int64),
        triangles=np.concatenate(tris) if tris else np.empty((0, 3), dtype=np.int64),
        triangle_groups=np.concatenate(groups) if groups else np.empty(0, dtype=np.int64),
        group_names=names,
    )


def _read_dolfinx_xdmf(path: Path, units: str, meshio_error: Exception) -> InputMesh:
    """Read an XDMF file as dolfinx writes it (this project's mesh.xdmf, for instance).

    The facet tags become groups, named after :class:`Boundary` (their values).
    """
    from dolfinx.cpp.mesh import entities_to_geometry
    from dolfinx.io import XDMFFile
    from mpi4py import MPI

    from meshes.io import geometry_nodes
    from meshes.tags import FACET_TAGS_NAME, MESH_NAME

    try:
        with XDMFFile(MPI.COMM_SELF, str(path), "r") as xdmf:
            mesh = xdmf.read_mesh(name=MESH_NAME)
            mesh.topology.create_connectivity(2, 3)
            try:
                tags = xdmf.read_meshtags(mesh, name=FACET_TAGS_NAME)
            except RuntimeError:
                tags = None
    except RuntimeError as err:
        raise MeshInputError(
            f"cannot read {path}: meshio reads single-grid XDMF only ({meshio_error}) and dolfinx "
            f"found no mesh named {MESH_NAME!r} in it ({err})"
        ) from err
    if mesh.topology.cell_name() != "tetrahedron":
        raise MeshInputError(f"{path} holds {mesh.topology.cell_name()} cells, not tetrahedra")
    if tags is not None and len(tags.indices):
        triangles = entities_to_geometry(mesh._mesh, 2, tags.indices, False).astype(np.int64)
        groups = tags.values.astype(np.int64)
    else:
        triangles, groups = np.empty((0, 3), dtype=np.int64), np.empty(0, dtype=np.int64)
    return InputMesh(
        points=np.asarray(mesh.geometry.x, dtype=float) * UNITS[units],
        tets=geometry_nodes(mesh)[:, :4].astype(np.int64),  # vertices only
        triangles=triangles,
        triangle_groups=groups,
        group_names={b.label: int(b) for b in Boundary},
    )


def read_surface(path: str | Path, units: str) -> tuple[np.ndarray, np.ndarray]:
    """Points (metres) and triangles of a surface file used by a ``surface`` rule."""
    surface = read_input(path, units)
    if len(surface.triangles) == 0:
        raise MeshInputError(f"{path} holds no triangles to measure distances from")
    extent = float(np.linalg.norm(np.ptp(surface.points, axis=0)))
    return merge_duplicate_points(surface.points, surface.triangles, 1e-9 * max(extent, 1e-12))


def tetrahedralise_surface(
    points: np.ndarray, tris: np.ndarray, size: MeshSize, remesh: bool
) -> tuple[np.ndarray, np.ndarray]:
    """Fill a closed surface with tetrahedra (gmsh).

    Args:
        points: vertices of the checked closed surface, metres.
        tris: its triangles.
        size: ``global_size`` bounds the tetrahedra (and the remeshed triangles).
        remesh: reparametrise and remesh the surface instead of keeping its triangles.

    Returns:
        ``(points, tets)`` of the volume mesh.
    """
    import gmsh

    from meshes.build import gmsh_session, mesh_arrays

    with gmsh_session("import") as model:
        surface = model.addDiscreteEntity(2)
        model.mesh.addNodes(2, surface, np.arange(1, len(points) + 1), points.ravel())
        model.mesh.addElementsByType(surface, 2, [], (tris + 1).ravel())
        if remesh:
            # Split the surface at sharp edges (> 40°) into patches gmsh can reparametrise.
            model.mesh.classifySurfaces(math.radians(40.0), True, True, math.pi)
            model.mesh.createGeometry()
        surfaces = [tag for _, tag in model.getEntities(2)]
        loop = model.geo.addSurfaceLoop(surfaces)
        model.geo.addVolume([loop])
        model.geo.synchronize()
        gmsh.option.setNumber("Mesh.MeshSizeMax", size.global_size)
        gmsh.option.setNumber("Mesh.MeshSizeMin", 0.0)
        gmsh.option.setNumber("Mesh.Algorithm3D", 1)
        gmsh.option.setNumber("Mesh.Optimize", 1)
        gmsh.option.setNumber("Mesh.RandomSeed", 1)
        model.mesh.generate(3)
        x, tets, _ = mesh_arrays(model, {})
    used = np.unique(tets)
    remap = np.full(len(x), -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    return x[used], remap[tets]


def _facet_distance(x: np.ndarray, faces: np.ndarray, rule: BoundaryRule, units: str) -> np.ndarray:
    """For each face, the largest distance of its vertices from the rule's plane/surface."""
    vertices = np.unique(faces)
    d = np.full(len(x), np.inf)
    if rule.plane is not None:
        point, normal = (np.asarray(v, dtype=float) for v in rule.plane)
        d[vertices] = np.abs((x[vertices] - point) @ (normal / np.linalg.norm(normal)))
    else:
        spts, stris = read_surface(rule.surface, units)
        # exact up to 10x the rule's distance, so a miss can say how far off it was
        d[vertices] = point_surface_distance(x[vertices], spts, stris, 10.0 * rule.distance)
    return d[faces].max(axis=1)


def classify_boundary(
    x: np.ndarray,
    faces: np.ndarray,
    rules: dict[Boundary, BoundaryRule],
    units: str,
    face_groups: np.ndarray | None = None,
    group_names: dict[str, int] | None = None,
) -> dict[Boundary, np.ndarray]:
    """Name the boundary faces by the rules; the faces no rule selects are skin.

    Args:
        x: points (N, 3), metres.
        faces: boundary triangles (m, 3).
        rules: a rule per boundary (``rib`` required).
        units: the model's units (surface rules read their file in them).
        face_groups: group integer of each face from the file (-1: none), or None.
        group_names: physical name -> group integer of the file.

    Returns:
        Boundary -> its faces (every boundary present, possibly empty).

    Raises:
        NoRibFacetsError: if the rib rule selects nothing, with how near the closest facet was.
        SurfaceRuleError: if another rule selects nothing, names an unknown group, or a
            facet is selected by two rules.
    """
    group_names = group_names or {}
    selected: dict[Boundary, np.ndarray] = {}
    for boundary, rule in rules.items():
        if rule.group is not None:
            if face_groups is None or np.all(face_groups < 0):
                raise SurfaceRuleError(
                    f"the {boundary.label} rule selects {rule.describe()}, but the input has no "
                    "boundary groups (only a volume mesh with tagged triangles, e.g. gmsh "
                    "physical groups, has them); use a plane or surface rule"
                )
            if isinstance(rule.group, str) and not rule.group.lstrip("-").isdigit():
                if rule.group not in group_names:
                    raise SurfaceRuleError(
                        f"the {boundary.label} rule names group {rule.group!r}, but the file's "
                        f"groups are: {', '.join(sorted(group_names)) or 'unnamed'}"
                    )
                value = group_names[rule.group]
            else:
                value = int(rule.group)
            mask = face_groups == value
            if not mask.any():
                present = sorted(set(face_groups[face_groups >= 0].tolist()))
                error = NoRibFacetsError if boundary == Boundary.RIB else SurfaceRuleError
                raise error(
                    f"no boundary facets found for the {boundary.label} surface: {rule.describe()} "
                    f"(tag {value}) holds no boundary triangles; tags on the boundary: {present}"
                )
        else:
            distance = _facet_distance(x, faces, rule, units)
            mask = distance <= rule.distance
            if not mask.any():
                nearest = float(np.min(distance))
                how_far = (
                    f"the closest facet lies {1e3 * nearest:.3g} mm from it"
                    if math.isfinite(nearest)
                    else f"no facet comes within {1e3 * 10 * rule.distance:.3g} mm of it"
                )
                error = NoRibFacetsError if boundary == Boundary.RIB else SurfaceRuleError
                raise error(
                    f"no boundary facets found for the {boundary.label} surface: none lies "
                    f"{rule.describe()}; {how_far}. Check the rule's position, the distance and "
                    f"mesh.file.units ({units})"
                )
        selected[boundary] = mask
    for i, first in enumerate(list(selected)):
        for second in list(selected)[i + 1 :]:
            both = int(np.sum(selected[first] & selected[second]))
            if both:
                raise SurfaceRuleError(
                    f"{both} boundary facet(s) match both the {first.label} and the "
                    f"{second.label} rules; make the rules exclusive (e.g. a smaller distance)"
                )
    taken = np.zeros(len(faces), dtype=bool)
    for mask in selected.values():
        taken |= mask
    out = {
        b: faces[selected[b]] if b in selected else np.empty((0, 3), dtype=np.int64)
        for b in Boundary
    }
    out[Boundary.SKIN] = np.concatenate([out[Boundary.SKIN], faces[~taken]])
    return out


def _face_groups(mesh: InputMesh, faces: np.ndarray) -> np.ndarray | None:
    """Group of each boundary face, looked up from the file's tagged triangles."""
    if len(mesh.triangles) == 0 or np.all(mesh.triangle_groups < 0):
        return None
    keys = {
        tuple(t): g
        for t, g in zip(
            np.sort(mesh.triangles, axis=1).tolist(), mesh.triangle_groups.tolist(), strict=True
        )
    }
    return np.array(
        [keys.get(tuple(f), -1) for f in np.sort(faces, axis=1).tolist()], dtype=np.int64
    )


def prepare_input(
    spec: ImportSpec, size: MeshSize
) -> tuple[np.ndarray, np.ndarray, dict[Boundary, np.ndarray], dict[str, Any]]:
    """Read, check, tetrahedralise (if a surface) and name the boundary of an input.

    Returns:
        ``(points, tets, facets, info)``: the tagged volume mesh and what was done.

    Raises:
        MeshInputError: (a subclass naming the problem) for any broken input.
    """
    what = f"the input {spec.path}"
    mesh = read_input(spec.path, spec.units)
    info: dict[str, Any] = {"path": str(spec.path), "units": spec.units}
    if mesh.is_volume:
        used = np.unique(mesh.tets)
        remap = np.full(len(mesh.points), -1, dtype=np.int64)
        remap[used] = np.arange(len(used))
        x = mesh.points[used]
        tets = remap[mesh.tets]
        tris = remap[mesh.triangles] if len(mesh.triangles) else mesh.triangles
        mesh = InputMesh(x, tets, tris, mesh.triangle_groups, mesh.group_names)
        info["extent_m"] = check_plausible_size(x, spec.units, what)
        tets = check_tetrahedra(x, tets, what)
        check_face_manifold(tets, what)
        faces = exterior_faces(tets)
        check_closed(x, faces, f"the boundary of {spec.path}")
        info["kind"] = "volume mesh"
        groups = _face_groups(mesh, faces)
    else:
        extent = float(np.linalg.norm(np.ptp(mesh.points, axis=0)))
        x, tris = merge_duplicate_points(mesh.points, mesh.triangles, 1e-9 * max(extent, 1e-12))
        info["extent_m"] = check_plausible_size(x, spec.units, what)
        check_triangles(x, tris, what)
        check_closed(x, tris, what)
        check_no_self_intersections(x, tris, what)
        info["kind"] = "closed surface"
        info["surface_triangles"] = int(len(tris))
        info["remeshed"] = spec.remesh
        x, tets = tetrahedralise_surface(x, tris, size, spec.remesh)
        tets = check_tetrahedra(x, tets, "the tetrahedralised surface")
        faces = exterior_faces(tets)
        groups = None
    facets = classify_boundary(x, faces, spec.surfaces, spec.units, groups, mesh.group_names)
    info["rules"] = {b.label: r.describe() for b, r in spec.surfaces.items()}
    return x, tets, facets, info


def imported_anatomy(x: np.ndarray, facets: dict[Boundary, np.ndarray]) -> dict[str, Any]:
    """Projection of an imported model from its chest wall (the rib facets)."""
    from scipy.spatial import cKDTree

    rib_vertices = np.unique(facets[Boundary.RIB])
    distance, _ = cKDTree(x[rib_vertices]).query(x)
    return {
        "projection_from_chest_wall_m": float(distance.max()),
        "projection_definition": (
            "largest distance of a mesh node from the nearest vertex of a rib facet (an upper "
            "bound of the distance from the rib surface, by at most the rib facets' size)"
        ),
    }


def write_imported_mesh(
    spec: ImportSpec,
    size: MeshSize,
    xdmf_path: str | Path,
    png_path: str | Path | None = None,
) -> dict[str, Any]:
    """Import, check and tag a user's geometry; write XDMF (and a PNG); return the quality report.

    Imported meshes are linear (``mesh.size.order`` 2 needs the CAD of the parametric
    model to place curved nodes on, so it is refused here).

    Raises:
        GeometryError: if ``size.order`` is 2 or ``size.fold_size`` is set.
        MeshInputError: (a subclass naming the problem) for any broken input.
    """
    from meshes.build import gmsh_quality, gmsh_session
    from meshes.io import add_tagged_mesh, write_gmsh_model

    if size.order != 1:
        raise GeometryError(
            "mesh.size.order 2 needs the parametric CAD to curve elements on; imported "
            "meshes are linear: set mesh.size.order: 1"
        )
    if size.fold_size is not None:
        raise GeometryError(
            "mesh.size.fold_size refines the parametric breast's inframammary fold, which an "
            "imported geometry does not name: set mesh.size.fold_size: null"
        )
    start = time.perf_counter()
    x, tets, facets, info = prepare_input(spec, size)
    mesh_s = time.perf_counter() - start
    with gmsh_session("imported") as model:
        groups = add_tagged_mesh(model, x, tets, facets)
        report = gmsh_quality(model, groups)
        write_gmsh_model(model, xdmf_path)
    report["source"] = "file"
    report["input"] = info
    report["anatomy"] = imported_anatomy(x, facets)
    report["size"] = size.as_dict()
    report["mesh_wall_s"] = mesh_s
    if png_path is not None:
        from meshes.plot import plot_boundaries

        plot_boundaries(
            x,
            facets,
            png_path,
            title=f"imported {Path(spec.path).name}: {report['cells']} tetrahedra, "
            f"{report['dofs']['P2/P1']} P2/P1 unknowns",
        )
    log.info(
        "imported %s: %d cells, %.0f ml, rib %.4g m², in %.2f s",
        spec.path,
        report["cells"],
        report["volume_ml"],
        report["area_m2"]["rib"],
        mesh_s,
    )
    return report
