"""Import a person's own geometry: a closed surface or a volume mesh, with named boundaries.

Accepted inputs (read by :mod:`meshes.reading`):

* a **closed triangulated surface** (``.stl``, ``.obj``, ``.ply``, ``.off``, ``.vtp``, or a
  ``.vtk``/``.msh``/``.vtu`` holding only triangles), repaired where the repair is small
  (:mod:`meshes.repair`) and filled with tetrahedra (:mod:`meshes.remesh`: keeping the surface
  triangles, or remeshing the surface to ``mesh.size`` with ``remesh: true``);
* a **tetrahedral volume mesh** (``.msh``, ``.vtu``, ``.vtk``, ``.xdmf``), used as it is.

A label volume (``mesh.source: image``) is meshed by :mod:`meshes.image` and named by the same
rules.

The boundary is then named by rules (:class:`meshes.boundary_rules.BoundaryRule`): the
rib surface (the fixed chest wall) must be selected, by a physical-group name or number of
the file, or as the facets lying within a distance of a plane or of another
surface (e.g. a segmented rib cage). Other named surfaces may be selected the
same way; every boundary facet no rule selects is skin.

Every kind of broken input stops with a typed error from :mod:`meshes.exceptions`
that names the problem: implausible size for the declared units, surface not
closed, more than one body (:mod:`meshes.bodies`), self-intersecting, degenerate or inverted
elements, no rib facets.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from meshes.bodies import check_one_body
from meshes.boundary_rules import (
    POSTERIOR,
    BoundaryRule,
    check_selection,
    face_groups,
    name_facets,
    select_facets,
    selection_summary,
)
from meshes.checks import (
    UNITS,
    check_closed,
    check_face_manifold,
    check_no_self_intersections,
    check_plausible_size,
    check_plausible_volume,
    check_tetrahedra,
    check_triangles,
    enclosed_volume,
    merge_duplicate_points,
)
from meshes.exceptions import (
    GeometryError,
    MeshInputError,
    SurfaceRuleError,
    reject_unknown,
)
from meshes.orientation import Orientation, check_chest_wall_posterior, file_frame_words
from meshes.quality import exterior_faces, tet_volumes
from meshes.reading import SURFACE_SUFFIXES, VOLUME_SUFFIXES, InputMesh, read_input
from meshes.remesh import check_dihedral_floor, fill_surface
from meshes.repair import repair_surface
from meshes.sizing import MeshSize
from meshes.tags import Boundary, Tissue

log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True)
class ImportSpec:
    """What to import and how to name its boundary (the ``mesh.file`` config section).

    Attributes:
        path: the surface or volume mesh file.
        units: length unit of the file (``m``, ``cm`` or ``mm``).
        surfaces: a rule per named boundary; ``rib`` is required.
        remesh: for a surface input, remesh the surface to ``mesh.size`` (True) or
            keep its triangles as the boundary of the volume mesh (False).
        orientation: how the file's axes lie in the patient (default: the project's frame);
            the boundary rules are in the file's axes and units.
    """

    path: str
    units: str = "m"
    surfaces: dict[Boundary, BoundaryRule] = field(default_factory=dict)
    remesh: bool = False
    orientation: Orientation = field(default_factory=Orientation)

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
        reject_unknown(values, {"path", "units", "surfaces", "remesh", "orientation"},
                       "mesh.file key(s)")
        if "path" not in values:
            raise GeometryError("mesh.file.path is required when mesh.source is 'file'")
        units = values.get("units", "m")
        if units not in UNITS:
            raise GeometryError(f"mesh.file.units must be one of {sorted(UNITS)}, got {units!r}")
        surfaces = {
            Boundary.from_label(name): BoundaryRule.from_mapping(rule, units)
            for name, rule in (values.get("surfaces") or {}).items()
        }
        posterior = sorted(b.label for b, r in surfaces.items() if r.posterior is not None)
        if posterior and values.get("orientation") is None:
            raise GeometryError(
                f"mesh.file.surfaces.{posterior[0]}: a posterior rule needs to know where the "
                "patient's posterior is in the file: give mesh.file.orientation (axes and side, "
                "e.g. {axes: LPS, side: left}, or {axes: project} for a file already in the "
                "project's frame); without it the file's +x would be taken as posterior")
        return cls(
            path=str(values["path"]),
            units=units,
            surfaces=surfaces,
            remesh=bool(values.get("remesh", False)),
            orientation=Orientation.from_mapping(values.get("orientation")),
        )

    #: The key that says where the file's axes point (named in refusals).
    orientation_key = "mesh.file.orientation"

    def rules(self) -> dict[Boundary, BoundaryRule]:
        """The boundary rules (the file's axes and units)."""
        return dict(self.surfaces)

    def frame_words(self) -> tuple[str, str]:
        """How the file's frame is named in a refusal, and what to change."""
        return file_frame_words(self.orientation)

    def select_posterior(self) -> np.ndarray:
        """The patient's posterior in the file's axes (for a posterior rule)."""
        return self.orientation.to_file(POSTERIOR)

    def read_volume(self, size: MeshSize) -> InputVolume:
        """The file read, checked and filled with tetrahedra (:func:`read_volume`)."""
        return read_volume(self, size)

    def input_files(self) -> list[str]:
        """Every file the import reads (for the workflow's dependencies)."""
        return [self.path] + [r.surface for r in self.surfaces.values() if r.surface is not None]

    def to_project_frame(self, values: np.ndarray) -> np.ndarray:
        """Positions or displacements in the file's axes and units into the project's frame (m)."""
        return self.orientation.to_project(np.asarray(values, dtype=float) * UNITS[self.units])

    def to_file_frame(self, values: np.ndarray) -> np.ndarray:
        """Positions or displacements (m, project's frame) in the file's axes and units.

        The import does not translate, so points and vectors go back by the same linear map.
        """
        return self.orientation.to_file(values) / UNITS[self.units]


@dataclass(frozen=True)
class InputVolume:
    """An input read, checked and filled with tetrahedra, in the file's axes (metres).

    Attributes:
        x: points (N, 3).
        tets: tetrahedra (n, 4), positively oriented.
        faces: boundary triangles (m, 3), facing outwards.
        groups: the file's group of each boundary triangle (-1: none), or None.
        group_names: physical name -> group integer of the file.
        info: what was read and done, for the quality report.
        tissues: each cell's :class:`meshes.tags.Tissue` value (None: all fat).
    """

    x: np.ndarray
    tets: np.ndarray
    faces: np.ndarray
    groups: np.ndarray | None
    group_names: dict[str, int]
    info: dict[str, Any]
    tissues: np.ndarray | None = None

    def select(self, spec: Any) -> dict[Boundary, np.ndarray]:
        """The boundary faces each of ``spec``'s rules selects (in the file's axes and units).

        ``spec`` is an :class:`ImportSpec` or a :class:`meshes.image.ImageSpec`.

        Raises:
            NoRibFacetsError, SurfaceRuleError: for a rule that selects nothing or names an
                unknown group (:func:`meshes.boundary_rules.select_facets`).
        """
        return select_facets(self.x, self.faces, spec.rules(), spec.units, self.groups,
                             self.group_names, spec.select_posterior(), spec.orientation_key)


def prepare_input(
    spec: Any, size: MeshSize
) -> tuple[np.ndarray, np.ndarray, dict[Boundary, np.ndarray], dict[str, Any], np.ndarray | None]:
    """Read, check, tetrahedralise (if a surface) and name the boundary of an input.

    The boundary is named in the file's axes (the rules are written in them); the mesh is then
    carried into the project's frame (``spec.orientation``).

    Returns:
        ``(points, tets, facets, info, tissues)``: the tagged volume mesh, what was done, and
        each cell's tissue (None: all fat).

    Raises:
        MeshInputError: (a subclass naming the problem) for any broken input.
    """
    volume = spec.read_volume(size)
    x, tets, info = volume.x, volume.tets, volume.info
    selected = volume.select(spec)
    check_selection(x, volume.faces, selected, spec.rules())
    facets = name_facets(volume.faces, selected)
    info["rules"] = {b.label: r.describe() for b, r in spec.rules().items()}
    x, tets, facets = into_project_frame(x, tets, facets, spec.orientation)
    info["orientation"] = spec.orientation.describe()
    check_chest_wall_posterior(x, facets[Boundary.RIB], spec.orientation,
                               f"the input {spec.path}", spec.frame_words())
    return x, tets, facets, info, volume.tissues


def read_volume(spec: ImportSpec, size: MeshSize) -> InputVolume:
    """Read and check an input, and fill a surface with tetrahedra (gmsh).

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
        info["volume_ml"] = check_plausible_volume(
            float(np.abs(tet_volumes(x, tets)).sum()), spec.units, what
        )
        check_face_manifold(tets, what)
        faces = exterior_faces(tets)
        check_closed(x, faces, f"the boundary of {spec.path}")
        check_one_body(x, faces, what, cells=tets)
        info["quality_floor"] = check_dihedral_floor(x, tets, what, strict=False)
        info["kind"] = "volume mesh"
        groups = face_groups(mesh, faces)
    else:
        extent = float(np.linalg.norm(np.ptp(mesh.points, axis=0)))
        x, tris = merge_duplicate_points(mesh.points, mesh.triangles, 1e-9 * max(extent, 1e-12))
        info["kind"] = "closed surface"
        info["remeshed"] = spec.remesh
        x, tets = fill_checked_surface(x, tris, size, spec.units, what,
                                       "the tetrahedralised surface", info, remesh=spec.remesh)
        faces = exterior_faces(tets)
        groups = None
    return InputVolume(x, tets, faces, groups, mesh.group_names, info)


def fill_checked_surface(x: np.ndarray, tris: np.ndarray, size: MeshSize, units: str, what: str,
                         filled: str, info: dict[str, Any], remesh: bool,
                         crossings: bool = True, **fill: Any) -> tuple[np.ndarray, np.ndarray]:
    """Check a surface, repair it where the repair is small, fill it with tetrahedra, check them.

    The one path of a surface file and of a label volume's surface. Records ``extent_m``,
    ``repair``, ``volume_ml``, ``surface_triangles``, ``fill`` and ``quality_floor`` in ``info``.

    Args:
        x: the surface's points (duplicates merged), metres.
        tris: its triangles.
        size: ``global_size`` bounds the tetrahedra.
        units: the input's declared units (for the plausibility messages).
        what: the surface, for messages.
        filled: the tetrahedra, for messages.
        info: the quality report's input record, filled in.
        remesh: remesh the surface (the floor is then strict: a remesh is the import's own
            work; kept triangles bound what the optimisers can do, so there it warns).
        crossings: check that the surface bounds one body and that no two triangles cross (a
            label volume's surface is one piece, its holes filled, by marching cubes, which
            crosses nothing).
        **fill: passed to :func:`meshes.remesh.fill_surface` (envelopes, reparametrise).

    Returns:
        ``(points, tets)`` of the volume mesh.
    """
    info["extent_m"] = check_plausible_size(x, units, what)
    check_triangles(x, tris, what)
    x, tris, info["repair"] = repair_surface(x, tris, what)
    check_closed(x, tris, what)
    info["volume_ml"] = check_plausible_volume(enclosed_volume(x, tris), units, what)
    if crossings:
        check_one_body(x, tris, what)
        check_no_self_intersections(x, tris, what)
    info["surface_triangles"] = int(len(tris))
    result = fill_surface(x, tris, size, remesh, **fill)
    info["fill"] = result.describe()
    tets = check_tetrahedra(result.x, result.tets, filled)
    info["quality_floor"] = check_dihedral_floor(
        result.x, tets, filled + (" (remeshed)" if remesh else ""), strict=remesh)
    return result.x, tets


def preview_rules(
    spec: Any, size: MeshSize, png_path: str | Path | None = None
) -> tuple[dict[str, dict[str, float]], str | None, dict[str, Any]]:
    """What each boundary rule selects, without meshing for the solver or solving.

    Returns:
        ``(summary, problem, info)``: per boundary its facets, area (m²) and share of the
        boundary's area (:func:`meshes.boundary_rules.selection_summary`); why the import would
        stop (two rules claim a facet, the rib is too much or too little), or None; and what
        was read and done (:attr:`InputVolume.info`).

    Raises:
        MeshInputError: for broken input, or a rule that selects nothing.
    """
    volume = spec.read_volume(size)
    selected = volume.select(spec)
    summary = selection_summary(volume.x, volume.faces, selected)
    x, _, facets = into_project_frame(
        volume.x, volume.tets, name_facets(volume.faces, selected), spec.orientation
    )
    try:  # the run's checks of the selection and of the frame, in its order
        check_selection(volume.x, volume.faces, selected, spec.rules())
        check_chest_wall_posterior(x, facets[Boundary.RIB], spec.orientation,
                                   f"the input {spec.path}", spec.frame_words())
        problem = None
    except (SurfaceRuleError, GeometryError) as err:
        problem = str(err)
    if png_path is not None:
        from meshes.plot import plot_boundaries

        plot_boundaries(x, facets, png_path, title=f"rules on {Path(spec.path).name}")
    return summary, problem, volume.info


def into_project_frame(
    x: np.ndarray, tets: np.ndarray, facets: dict[Boundary, np.ndarray], orientation: Orientation
) -> tuple[np.ndarray, np.ndarray, dict[Boundary, np.ndarray]]:
    """Carry a tagged mesh from the file's axes into the project's frame.

    A reflection (a left breast) reverses every cell's and facet's orientation: two vertices of
    each are swapped back, so that tetrahedra stay positive and facets face outwards.
    """
    if not orientation.declared:
        return x, tets, facets
    x = orientation.to_project(x)
    if orientation.mirrors:
        tets = tets[:, [0, 2, 1, 3]]
        facets = {b: f[:, [0, 2, 1]] for b, f in facets.items()}
    return x, tets, facets


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


def import_size(size: MeshSize) -> MeshSize:
    """The part of ``mesh.size`` that applies to an imported geometry.

    ``order: 2`` curves cells onto the parametric CAD and ``fold_size`` refines the parametric
    fold; an import has neither, so switching ``mesh.source`` to ``file`` keeps the config's
    sizes and says in one line which keys it leaves aside.
    """
    ignored = []
    if size.order != 1:
        ignored.append(f"order: {size.order}")
    if size.fold_size is not None:
        ignored.append(f"fold_size: {size.fold_size}")
    if ignored:
        log.info("mesh.size %s: parametric only; the import is meshed linear with "
                 "global_size %g m", ", ".join(ignored), size.global_size)
    return replace(size, order=1, fold_size=None)


def write_imported_mesh(
    spec: Any,
    size: MeshSize,
    xdmf_path: str | Path,
    png_path: str | Path | None = None,
) -> dict[str, Any]:
    """Import, check and tag a user's geometry; write XDMF (and a PNG); return the quality report.

    Imported meshes are linear and have no fold to refine (:func:`import_size`).

    Raises:
        MeshInputError: (a subclass naming the problem) for any broken input.
    """
    from meshes.build import gmsh_quality, gmsh_session
    from meshes.io import add_tagged_mesh, write_gmsh_model

    size = import_size(size)
    start = time.perf_counter()
    x, tets, facets, info, tissues = prepare_input(spec, size)
    mesh_s = time.perf_counter() - start
    with gmsh_session("imported") as model:
        groups = add_tagged_mesh(model, x, tets, facets, tissues)
        report = gmsh_quality(model, groups)
        write_gmsh_model(model, xdmf_path)
    report["source"] = "image" if info.get("kind") == "label volume" else "file"
    report["input"] = info
    report["anatomy"] = imported_anatomy(x, facets)
    report["size"] = size.as_dict()
    report["mesh_wall_s"] = mesh_s
    if tissues is not None:
        volumes = np.abs(tet_volumes(x, tets))
        report["tissue_volume_ml"] = {t.label: 1e6 * float(volumes[tissues == t].sum())
                                      for t in Tissue if np.any(tissues == t)}
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
