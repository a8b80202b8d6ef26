"""Mesh a segmented image directly: a label volume from 3D Slicer, ITK-SNAP or a scanner's tools.

    mesh:
      source: image
      image:
        path: patient_labels.nii.gz   # NIfTI, NRRD (.nrrd, .nhdr) or MetaImage (.mha, .mhd)
        breast_labels: [1, 2]         # the labels that make up the breast (fat, gland, tumour)
        tissues: {gland: [2]}         # optional: the tissue of each label (the rest are fat)
        chest_label: 3                # optional: pectoral muscle or rib cage; its boundary
                                      # with the breast becomes the rib
        side: left                    # optional where the image tells it
        mesher: ftetwild              # optional: ftetwild (default) or cgal
        orientation: SLA              # optional: where the voxel axes i, j, k point, for a
                                      # header whose direction is wrong

The image is read with SimpleITK, which gives every format's voxels in the scanner's physical
space in ITK's LPS convention (NIfTI's RAS sform/qform is converted on reading): the map from a
voxel index to millimetres is the header's origin, direction cosines and spacing, so no axes
need declaring; the header is checked first (:mod:`meshes.image_header`), and ``orientation``
replaces its direction cosines. A breast's side is taken from the image where it can tell (the
breast labelled off the centre of a torso's field of view), and asked for where it cannot (a
dedicated breast image, centred on the breast). Every check that needs no mesh runs before the
meshing (:func:`meshes.label_volume.check_before_meshing`).

Meshing (see docs/geometry.md for the measurement behind the choice): with ``mesher: cgal``
CGAL's labelled-image mesher meshes the labels themselves, one subdomain per tissue, the same
cells on every run (:mod:`meshes.cgal_image`). By default (``mesher: ftetwild``) the
breast's labels are cropped to the breast, averaged in blocks onto a working grid of about
``global_size / 6`` (at most :data:`WORKING_SPACING_M`), the largest connected piece kept and
its inner holes filled; lightly smoothed, the 0.5 level set is the surface (scikit-image's
marching cubes), filled with tetrahedra by :func:`meshes.remesh.fill_surface` (fTetWild within
a working voxel of it, remeshed to ``global_size``, to the quality floor). Facets within
a working voxel and a half of the chest label form the file group ``chest_wall``, which the
rib rule selects; without a chest label the rib comes from a rule in ``surfaces`` (a posterior
rule, in LPS millimetres).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from meshes.boundary_rules import POSTERIOR, BoundaryRule
from meshes.checks import (
    UNITS,
)
from meshes.exceptions import GeometryError, MeshInputError, reject_unknown
from meshes.image_header import Grid, read_header
from meshes.image_tissues import cell_tissues, tissue_labels
from meshes.importing import InputVolume, fill_checked_surface
from meshes.label_volume import bounds, check_before_meshing, image_side, read_labels
from meshes.orientation import Orientation, axes_code
from meshes.quality import exterior_faces, tet_volumes
from meshes.sizing import MeshSize
from meshes.tags import Boundary, Tissue

log = logging.getLogger(__name__)

IMAGE_SUFFIXES = (".nii", ".nii.gz", ".nrrd", ".nhdr", ".mha", ".mhd")

#: The coarsest working grid the surface is taken from, m (finer for a finer global_size).
WORKING_SPACING_M = 0.002

#: The file group of the facets next to the chest label, which the rib rule selects.
CHEST_GROUP = "chest_wall"

#: The meshers of ``mesh.image.mesher``.
MESHERS = ("cgal", "ftetwild")
#: The default: CGAL's mesh is the same file on every run and keeps every tissue's volume; it
#: may leave a few cells below the floor (a warning) and resolves a thin skin label with many
#: small cells. fTetWild's meets the floor but differs between runs (docs/geometry.md).
DEFAULT_MESHER = "cgal"


def image_suffix(path: str | Path) -> str:
    """The image suffix of ``path`` (``.nii.gz`` counts as one), or ``""``."""
    name = str(path).lower()
    return next((s for s in sorted(IMAGE_SUFFIXES, key=len, reverse=True)
                 if name.endswith(s)), "")


@dataclass(frozen=True, slots=True)
class ImageSpec:
    """What to mesh from a label volume (the ``mesh.image`` config section).

    Attributes:
        path: the label volume.
        breast_labels: the labels that make up the breast.
        chest_label: the chest wall's label (its boundary with the breast is the rib), or None.
        side: ``left`` or ``right``, or None to take it from the image.
        surfaces: rules for named boundaries, in LPS millimetres (the rib's, without a
            chest label).
        tissues: each tissue's labels, among the breast's; a breast label in none is fat.
            Every cell is tagged with the tissue the image holds where it lies.
        mesher: ``cgal`` (CGAL's labelled-image mesher, :mod:`meshes.cgal_image`: one
            subdomain per tissue, deterministic) or ``ftetwild`` (marching cubes and fTetWild,
            each cell tagged by a vote of the labels it covers).
        axes: ``mesh.image.orientation``: where the voxel axes i, j, k point in the patient,
            an axes code (as ``mesh.file.orientation.axes``) that replaces the header's
            direction cosines; None: the header's.
    """

    path: str
    breast_labels: tuple[int, ...]
    chest_label: int | None = None
    side: str | None = None
    surfaces: dict[Boundary, BoundaryRule] = field(default_factory=dict)
    tissues: dict[Tissue, tuple[int, ...]] = field(default_factory=dict)
    mesher: str = DEFAULT_MESHER
    axes: str | None = None

    #: The scanner's millimetres: positions and rules are in them.
    units = "mm"
    #: The surface is always remeshed.
    remesh = True
    #: The key that says where the image's axes point (named in refusals).
    orientation_key = "mesh.image.orientation"

    def __post_init__(self) -> None:
        if not image_suffix(self.path):
            raise MeshInputError(f"mesh.image.path {self.path!r}: not a label volume; expected "
                                 f"one of {', '.join(IMAGE_SUFFIXES)}")
        if not self.breast_labels:
            raise GeometryError("mesh.image.breast_labels must name at least one label")
        if self.chest_label is not None and self.chest_label in self.breast_labels:
            raise GeometryError(f"mesh.image.chest_label {self.chest_label} is also a breast label")
        if self.mesher not in MESHERS:
            raise GeometryError(f"mesh.image.mesher must be one of {', '.join(MESHERS)}, got "
                                f"{self.mesher!r}")
        if self.side is not None and self.side not in ("left", "right"):
            raise GeometryError("mesh.image.side must be left or right")
        if self.axes is not None:
            object.__setattr__(self, "axes", axes_code(self.axes, "mesh.image.orientation"))
        if self.chest_label is None and Boundary.RIB not in self.surfaces:
            raise GeometryError(
                "mesh.image needs the rib: a chest_label (the pectoral muscle or rib cage "
                "whose boundary with the breast is fixed), or a rule in mesh.image.surfaces "
                "(e.g. rib: {posterior: {angle: 60, band: 25}})")
        if self.chest_label is not None and Boundary.RIB in self.surfaces:
            raise GeometryError("mesh.image: the rib comes from chest_label; drop the rib rule "
                                "from mesh.image.surfaces (or the chest_label)")
        seen: dict[int, Tissue] = {}
        for tissue, labels in self.tissues.items():
            for label in labels:
                if label not in self.breast_labels:
                    raise GeometryError(
                        f"mesh.image.tissues.{tissue.label}: label {label} is not one of the "
                        f"breast_labels {list(self.breast_labels)}")
                if label in seen:
                    raise GeometryError(
                        f"mesh.image.tissues: label {label} is both {seen[label].label} and "
                        f"{tissue.label}")
                seen[label] = tissue

    def label_tissues(self) -> dict[int, Tissue]:
        """The tissue of each breast label (fat where :attr:`tissues` names none)."""
        out = dict.fromkeys(self.breast_labels, Tissue.FAT)
        for tissue, labels in self.tissues.items():
            out.update(dict.fromkeys(labels, tissue))
        return out

    @classmethod
    def from_mapping(cls, values: dict[str, Any]) -> ImageSpec:
        """Build from the ``mesh.image`` config mapping."""
        reject_unknown(values, {"path", "breast_labels", "chest_label", "side", "surfaces",
                                "tissues", "mesher", "orientation"}, "mesh.image key(s)")
        if "path" not in values or "breast_labels" not in values:
            raise GeometryError("mesh.image needs path and breast_labels")
        labels = values["breast_labels"]
        labels = [labels] if isinstance(labels, int) else list(labels)
        chest = values.get("chest_label")
        return cls(
            path=str(values["path"]),
            breast_labels=tuple(int(v) for v in labels),
            chest_label=None if chest is None else int(chest),
            side=values.get("side"),
            surfaces={Boundary.from_label(name): BoundaryRule.from_mapping(rule, cls.units)
                      for name, rule in (values.get("surfaces") or {}).items()},
            tissues=tissue_labels(values.get("tissues")),
            mesher=str(values.get("mesher", DEFAULT_MESHER)),
            axes=None if values.get("orientation") is None else str(values["orientation"]),
        )

    def rules(self) -> dict[Boundary, BoundaryRule]:
        """Every boundary rule: the chest label's group as the rib, and ``surfaces``."""
        if self.chest_label is None:
            return dict(self.surfaces)
        return {Boundary.RIB: BoundaryRule(group=CHEST_GROUP), **self.surfaces}

    @property
    def orientation(self) -> Orientation:
        """LPS, the breast's side given or taken from the image.

        Raises:
            GeometryError: where the side is not given and the image cannot tell it.
        """
        return Orientation("LPS", image_side(self))

    def frame_words(self) -> tuple[str, str]:
        """How the image's frame is named in a refusal, and what to change."""
        axes = (f"the axes {self.axes} of mesh.image.orientation" if self.axes is not None
                else "the axes of its header's direction cosines")
        side = self.side or "taken from the image"
        return (f"with {axes}, side {side}",
                "check where the image's voxel axes i, j, k point in the patient (give them as "
                "mesh.image.orientation where the header is wrong, e.g. SLA for i superior, j "
                "left, k anterior) and mesh.image.side")

    def input_files(self) -> list[str]:
        """Every file the mesh is made from (for the workflow's dependencies)."""
        files = [self.path]
        if self.path.lower().endswith((".nhdr", ".mhd")):
            files += _detached_data(Path(self.path))
        return files + [r.surface for r in self.surfaces.values() if r.surface is not None]

    def to_project_frame(self, values: np.ndarray) -> np.ndarray:
        """Positions or displacements in LPS millimetres into the project's frame (m)."""
        return self.orientation.to_project(np.asarray(values, dtype=float) * UNITS[self.units])

    def to_file_frame(self, values: np.ndarray) -> np.ndarray:
        """Positions or displacements (m, project's frame) in LPS millimetres."""
        return self.orientation.to_file(values) / UNITS[self.units]

    def voxels_to_file_frame(self, index: np.ndarray) -> np.ndarray:
        """Voxel indices (i, j, k; continuous) to LPS millimetres, by the header."""
        return read_header(self.path, self.axes).to_physical(index)

    def file_frame_to_voxels(self, physical: np.ndarray) -> np.ndarray:
        """LPS millimetres to voxel indices, by the header."""
        return read_header(self.path, self.axes).to_index(physical)

    def select_posterior(self) -> np.ndarray:
        """The patient's posterior in LPS (for a posterior rule)."""
        return self.orientation.to_file(POSTERIOR)

    def read_volume(self, size: MeshSize) -> InputVolume:
        """The breast meshed from the image by :attr:`mesher` (see the module's docstring).

        The header and every check that needs no mesh come first
        (:func:`meshes.label_volume.check_before_meshing`).
        """
        start = time.perf_counter()
        labels, grid = read_labels(self.path, self.axes)
        checked = check_before_meshing(labels, grid, self, working_spacing(size))
        read_s = time.perf_counter() - start
        if self.mesher == "cgal":
            from meshes.cgal_image import cgal_volume

            counts = {int(v): c for v, c in checked["labels"].items()}
            volume = cgal_volume(self, size, labels, grid, counts, CHEST_GROUP,
                                 WORKING_SPACING_M, read_s=read_s)
        else:
            volume = image_volume(self, size, labels, grid, checked, read_s)
        volume.info.update(checked)
        return volume


def _detached_data(header: Path) -> list[str]:
    """The data file a detached header (``.nhdr``, ``.mhd``) names, where it names one."""
    key, separator = (("data file", ":") if header.suffix.lower() == ".nhdr"
                      else ("elementdatafile", "="))
    lines = header.read_text(errors="replace").splitlines() if header.exists() else []
    for line in lines:
        name, _, value = line.partition(separator)
        value = value.strip()
        if name.strip().lower() == key and value and value.upper() not in ("LOCAL", "LIST"):
            return [str(header.parent / value)]
    return []


def working_spacing(size: MeshSize) -> float:
    """The working grid's spacing for ``size``, m: ``global_size / 6``, at most 2 mm."""
    return min(size.global_size / 6.0, WORKING_SPACING_M)


def breast_surface(labels: np.ndarray, grid: Grid, spec: ImageSpec, size: MeshSize,
                   counts: dict[int, int]) -> tuple[np.ndarray, np.ndarray, dict[str, Any], Any]:
    """The breast's surface (LPS, metres) from the label volume, and the chest's distance.

    ``counts`` are the voxels per label (:func:`meshes.label_volume.check_labels`).

    Returns:
        ``(points, triangles, info, chest_distance)``: ``chest_distance(points_m)`` gives the
        distance (m) of LPS points from the chest label (None without one).
    """
    from scipy import ndimage
    from skimage.measure import block_reduce, marching_cubes

    breast = np.isin(labels, spec.breast_labels)
    first, last = bounds(breast)
    lo = np.maximum(first - 2, 0)
    hi = np.minimum(last + 3, labels.shape)
    crop = tuple(slice(a, b) for a, b in zip(lo, hi, strict=True))
    spacing_m = 1e-3 * grid.spacing
    target = working_spacing(size)
    factor = tuple(int(max(1, round(target / s))) for s in spacing_m)
    fraction = block_reduce(breast[crop].astype(np.float32), factor, np.mean, cval=0.0)
    solid = fraction >= 0.5
    pieces, n = ndimage.label(solid)
    if n == 0:
        raise MeshInputError(f"{spec.path}: the breast labels cover less than half of every "
                             f"working voxel ({1e3 * target:.2g} mm): the breast is too small")
    sizes = np.bincount(pieces.ravel())[1:]
    kept = pieces == 1 + int(np.argmax(sizes))
    filled = ndimage.binary_fill_holes(kept)
    fraction = np.where(ndimage.binary_dilation(kept), fraction, 0.0)
    fraction[filled & ~kept] = 1.0
    working = spacing_m * np.array(factor)
    fraction = ndimage.gaussian_filter(fraction, sigma=0.7)
    fraction = np.pad(fraction, 2)
    verts, tris, _, _ = marching_cubes(fraction, level=0.5, allow_degenerate=False)
    index = (verts - 2) * np.array(factor) + (np.array(factor) - 1) / 2.0 + lo
    points = 1e-3 * grid.to_physical(index)
    tris = np.asarray(tris, dtype=np.int64)
    a, b, c = (points[tris[:, i]] for i in range(3))
    if float(np.einsum("ij,ij->", a, np.cross(b, c))) < 0:  # outward, whatever the header
        tris = tris[:, [0, 2, 1]]
    voxel_ml = 1e6 * float(np.prod(spacing_m))
    info = {
        "labels": {str(v): n for v, n in counts.items()},
        "breast_labels": list(spec.breast_labels), "chest_label": spec.chest_label,
        "voxel_size_mm": grid.spacing.tolist(), "image_shape": list(grid.shape),
        "working_voxel_mm": (1e3 * working).tolist(),
        "labelled_volume_ml": voxel_ml * float(breast.sum()),
        "pieces_dropped": int(n - 1),
        "dropped_volume_ml": 1e6 * float(np.prod(working)) * float(sizes.sum() - sizes.max()),
        "holes_filled_ml": 1e6 * float(np.prod(working)) * float((filled & ~kept).sum()),
    }
    chest_distance = None
    if spec.chest_label is not None:
        chest = block_reduce((labels[crop] == spec.chest_label), factor, np.max, cval=False)
        if not chest.any():
            raise MeshInputError(f"{spec.path}: the chest label {spec.chest_label} does not "
                                 "touch the breast (none of it lies in the breast's box)")
        distance = ndimage.distance_transform_edt(~chest, sampling=working)

        def chest_distance(physical_m: np.ndarray) -> np.ndarray:
            at = (grid.to_index(1e3 * physical_m) - lo - (np.array(factor) - 1) / 2.0) / factor
            return ndimage.map_coordinates(distance, at.T, order=1, mode="nearest")

    return points, tris, info, chest_distance


def image_volume(spec: ImageSpec, size: MeshSize, labels: np.ndarray, grid: Grid,
                 checked: dict[str, Any], read_s: float = 0.0) -> InputVolume:
    """Take the breast's surface from the label volume, fill it with tetrahedra, group the rib.

    Args:
        spec: the ``mesh.image`` section.
        size: ``global_size`` bounds the cells.
        labels: the label volume ``[i, j, k]``, checked (``checked``).
        grid: its header's map to LPS millimetres.
        checked: what :func:`meshes.label_volume.check_before_meshing` found.
        read_s: the seconds reading and checking took, for the report.

    Raises:
        MeshInputError: (a subclass naming the problem) for a surface that cannot be meshed.
    """
    what = f"the breast of {spec.path}"
    start = time.perf_counter() - read_s
    counts = {int(v): c for v, c in checked["labels"].items()}
    x, tris, info, chest_distance = breast_surface(labels, grid, spec, size, counts)
    tissue_of = spec.label_tissues()
    if any(t is not Tissue.FAT for t in tissue_of.values()):
        # the breast's voxels (and a voxel's margin) kept for the cells' tissues
        first, last = bounds(np.isin(labels, spec.breast_labels))
        lo, hi = np.maximum(first - 1, 0), np.minimum(last + 2, labels.shape)
        kept = labels[tuple(slice(a, b) for a, b in zip(lo, hi, strict=True))].copy()
        kept_grid = Grid(grid.to_physical(lo), grid.spacing, grid.direction, kept.shape)
    else:
        kept = kept_grid = None
    del labels
    surface_s = time.perf_counter() - start - read_s
    info.update({"path": spec.path, "units": spec.units, "kind": "label volume"})
    # fTetWild within a working voxel of the surface (the surface's own precision), then two,
    # then four, relative to its diagonal; gmsh's reparametrisation is not tried: every voxel
    # step is an edge to it
    voxel = 1e-3 * float(np.max(info["working_voxel_mm"])) / float(
        np.linalg.norm(np.ptp(x, axis=0)))
    x, tets = fill_checked_surface(x, tris, size, spec.units, what, what, info, remesh=True,
                                   crossings=False, reparametrise=False,
                                   envelopes=(voxel, 2 * voxel, 4 * voxel))
    info["meshed_volume_ml"] = 1e6 * float(np.abs(tet_volumes(x, tets)).sum())
    info["volume_kept"] = info["meshed_volume_ml"] / info["labelled_volume_ml"]
    faces = exterior_faces(tets)
    groups = np.full(len(faces), -1, dtype=np.int64)
    names: dict[str, int] = {}
    if chest_distance is not None:
        reach = 1.5 * 1e-3 * float(np.max(info["working_voxel_mm"]))
        near = chest_distance(x[faces].mean(axis=1)) <= reach
        groups[near] = 1
        names[CHEST_GROUP] = 1
        info["chest_facets"] = int(near.sum())
    tissues = None
    if kept is not None:
        tissues, unresolved = cell_tissues(kept, kept_grid, x, tets, tissue_of)
        info["tissue_cells"] = {t.label: int(np.sum(tissues == t)) for t in Tissue
                                if np.any(tissues == t)}
        info["cells_without_a_breast_label"] = unresolved
    info["seconds"] = {"read": round(read_s, 3), "surface": round(surface_s, 3),
                       "fill": round(time.perf_counter() - start - read_s - surface_s, 3)}
    return InputVolume(x, tets, faces, groups, names, info, tissues)
