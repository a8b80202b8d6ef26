"""A label volume's voxels, read and checked before any meshing.

:func:`read_labels` reads the voxels once the header has passed :func:`meshes.image_header.
read_header`; :func:`check_before_meshing` then runs every check of ``mesh.image`` that needs no
mesh, so that a config the import would refuse is refused in seconds, not after the meshing:

* the breast's and the chest's labels occur in the image;
* the breast's side is known (given, or told by the image);
* the breast's labels span a breast's size (the surface import's size check, on the voxels);
* they form one breast: a piece dropped as not the largest may be a segmentation's speck, but
  not more than :data:`PIECE_FRACTION` of the piece kept (two breasts, or one cut in two);
* the chest label touches the breast and lies posterior of it in the patient, within
  :data:`CHEST_ANGLE_DEG` (a header whose axes are wrong puts it elsewhere);
* where the breast's labels reach the edge of the image other than on the chest's side, the
  field of view cuts the breast and the cut face would be meshed as skin: a warning in the
  quality report (``input.warnings``) and the preview, not a refusal (see :func:`border_cuts`).
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import numpy as np

from meshes.checks import PLAUSIBLE_EXTENT_M
from meshes.exceptions import GeometryError, MeshInputError, UnitsError
from meshes.image_header import Grid, first_line, read_header
from meshes.orientation import DIRECTIONS

log = logging.getLogger(__name__)

#: A breast labelled this far off the centre of the image's field of view (m, left-right) is on
#: that side of a torso's image; nearer the centre the image cannot tell.
SIDE_OFFSET_M = 0.03
#: The largest piece of the breast's labels is meshed; another piece larger than this share of
#: it is refused (two breasts, or a breast cut in two), a smaller one dropped and recorded.
PIECE_FRACTION = 0.03
#: An image face whose outward direction lies within this angle of the patient's posterior is
#: on the chest's side: the breast's labels may reach it (a breast image cut at the chest).
CHEST_SIDE_DEG = 60.0
#: The chest label next to the breast lies posterior of the breast's centroid: the direction
#: from the centroid to it within this angle of the patient's posterior (a header whose axes
#: are wrong puts it at 90° or more).
CHEST_ANGLE_DEG = 75.0
#: The patient's direction each letter of an axes code names, for messages.
WORDS = {"L": "left", "R": "right", "A": "anterior", "P": "posterior", "S": "superior",
         "I": "inferior"}


def read_labels(path: str | Path, axes: str | None = None) -> tuple[np.ndarray, Grid]:
    """The label volume, indexed ``[i, j, k]`` as the header's indices, and its checked grid.

    Args:
        path: the image.
        axes: ``mesh.image.orientation`` (None: the header's direction).

    Raises:
        MeshInputError: for a missing or unreadable file, a header
            :func:`meshes.image_header.read_header` refuses, or an image that is not a label
            volume (not 3D, or non-integer values).
    """
    import SimpleITK as sitk

    grid = read_header(path, axes)
    try:
        image = sitk.ReadImage(str(path))
    except RuntimeError as err:
        raise MeshInputError(f"cannot read the image {path}: {first_line(err)}") from None
    if image.GetDimension() != 3 or image.GetNumberOfComponentsPerPixel() != 1:
        raise MeshInputError(f"{path} is not a 3D label volume: {image.GetDimension()}D with "
                             f"{image.GetNumberOfComponentsPerPixel()} component(s) per voxel")
    labels = sitk.GetArrayViewFromImage(image)  # [k, j, i]
    if not np.issubdtype(labels.dtype, np.integer):
        if not np.array_equal(labels, np.round(labels)):
            raise MeshInputError(f"{path} holds non-integer values ({labels.dtype}): a label "
                                 "volume (segmentation) holds one integer label per voxel")
        labels = labels.astype(np.int32)
    return np.array(labels).transpose(2, 1, 0), grid


def label_counts(labels: np.ndarray) -> dict[int, int]:
    """Voxels per label (0, the background, included)."""
    values, counts = np.unique(labels, return_counts=True)
    return {int(v): int(c) for v, c in zip(values, counts, strict=True)}


def bounds(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The first and last index of ``mask``'s True voxels along each axis (it has some)."""
    spans = [np.flatnonzero(mask.any(axis=tuple(a for a in range(3) if a != axis)))
             for axis in range(3)]
    return np.array([s[0] for s in spans]), np.array([s[-1] for s in spans])


def centroid(mask: np.ndarray) -> np.ndarray:
    """The mean index of ``mask``'s True voxels (without listing them)."""
    total = float(mask.sum())
    return np.array([
        float(mask.sum(axis=tuple(a for a in range(3) if a != axis)) @ np.arange(mask.shape[axis]))
        / total for axis in range(3)])


def check_labels(labels: np.ndarray, spec: Any) -> dict[int, int]:
    """Voxels per label, having checked that the breast's and the chest's labels occur.

    Raises:
        MeshInputError: naming the absent labels and the image's own.
    """
    counts = label_counts(labels)
    absent = [v for v in spec.breast_labels if v not in counts]
    if spec.chest_label is not None and spec.chest_label not in counts:
        absent.append(spec.chest_label)
    if absent:
        raise MeshInputError(
            f"{spec.path}: label(s) {', '.join(map(str, absent))} do not occur in the image; its "
            "labels (voxels): " + ", ".join(f"{v} ({n})" for v, n in counts.items()))
    return counts


def side_from_labels(breast: np.ndarray, grid: Grid) -> str | None:
    """``left`` or ``right`` where the breast lies off the field of view's centre, else None."""
    if not breast.any():
        return None
    centre = grid.to_physical(centroid(breast))
    corners = np.array([[i, j, k] for i in (0, grid.shape[0] - 1) for j in (0, grid.shape[1] - 1)
                        for k in (0, grid.shape[2] - 1)])
    fov = grid.to_physical(corners)[:, 0]
    offset = 1e-3 * (centre[0] - 0.5 * (fov.min() + fov.max()))  # +x of LPS: patient's left
    if abs(offset) < SIDE_OFFSET_M:
        return None
    return "left" if offset > 0 else "right"


#: The side each version of an image tells: (path, mtime, breast labels, axes) -> side.
_SIDES: dict[tuple[str, float, tuple[int, ...], str | None], str | None] = {}


def image_side(spec: Any, labels: np.ndarray | None = None, grid: Grid | None = None) -> str:
    """The breast's side: ``spec.side``, or what the image tells (read unless given).

    Raises:
        GeometryError: where the side is not given and the image cannot tell it.
    """
    if spec.side is not None:
        return spec.side
    path = Path(spec.path)
    key = (str(path), path.stat().st_mtime if path.exists() else 0.0, spec.breast_labels,
           spec.axes)
    if key not in _SIDES:
        if labels is None or grid is None:
            labels, grid = read_labels(path, spec.axes)
        _SIDES.clear()  # one image's answer kept, not every version's
        _SIDES[key] = side_from_labels(np.isin(labels, spec.breast_labels), grid)
    if _SIDES[key] is None:
        raise GeometryError(
            f"{spec.path}: the image does not tell the breast's side (it is labelled within "
            f"{1e3 * SIDE_OFFSET_M:g} mm of the field of view's centre, as in a dedicated breast "
            "image): give mesh.image.side (left or right)")
    return _SIDES[key]


def check_before_meshing(labels: np.ndarray, grid: Grid, spec: Any,
                         working_m: float) -> dict[str, Any]:
    """Every check of the label volume that needs no mesh (see the module's docstring).

    Args:
        labels: the label volume ``[i, j, k]``.
        grid: its checked header.
        spec: the ``mesh.image`` section (:class:`meshes.image.ImageSpec`).
        working_m: the working grid's spacing, m (pieces are counted on it, as the surface is
            taken from it).

    Returns:
        For the quality report: ``labels`` (voxels per label), ``side``, ``axes``
        (:meth:`Grid.describe`), ``pieces`` (the breast's pieces, ml, largest first),
        ``field_of_view_cut_cm2`` and ``warnings``.

    Raises:
        MeshInputError, GeometryError: naming the problem.
    """
    from scipy import ndimage
    from skimage.measure import block_reduce

    counts = check_labels(labels, spec)
    side = image_side(spec, labels, grid)
    breast = np.isin(labels, spec.breast_labels)
    first, last = bounds(breast)
    corners = grid.to_physical(np.array([[last[a] if (c >> a) & 1 else first[a]
                                          for a in range(3)] for c in range(8)]))
    extent = float(np.linalg.norm(np.ptp(corners, axis=0)))
    lo, hi = (1e3 * v for v in PLAUSIBLE_EXTENT_M)
    if not lo <= extent <= hi:
        raise UnitsError(
            f"{spec.path}: the breast's labels span {extent:.3g} mm (their box's diagonal) by the "
            f"header's voxel size ({' x '.join(f'{s:.3g}' for s in grid.spacing)} mm), but a "
            f"breast is {lo:g}-{hi:g} mm across: the voxel size is probably in other units; "
            "fix the header")
    lo_i, hi_i = np.maximum(first - 2, 0), np.minimum(last + 3, labels.shape)
    crop = tuple(slice(a, b) for a, b in zip(lo_i, hi_i, strict=True))
    factor = tuple(int(max(1, round(1e3 * working_m / s))) for s in grid.spacing)
    solid = block_reduce(breast[crop].astype(np.float32), factor, np.mean, cval=0.0) >= 0.5
    pieces, n = ndimage.label(solid)
    block_ml = 1e-3 * float(np.prod(grid.spacing * np.array(factor)))
    sizes = np.bincount(pieces.ravel())[1:]
    order = np.argsort(sizes)[::-1]
    volumes = [block_ml * float(sizes[i]) for i in order]
    if n > 1 and volumes[1] > PIECE_FRACTION * volumes[0]:
        centres = ndimage.center_of_mass(solid, pieces, [int(i) + 1 for i in order[:2]])
        at = [grid.to_physical(np.array(c) * factor + (np.array(factor) - 1) / 2 + lo_i)
              for c in centres]
        raise MeshInputError(
            f"{spec.path}: the breast's labels form {n} separate pieces: the largest "
            f"{volumes[0]:.1f} ml (centred at {_mm(at[0])} mm LPS), the next {volumes[1]:.1f} ml "
            f"(at {_mm(at[1])} mm, {100 * volumes[1] / volumes[0]:.0f} % of the largest); only the "
            f"largest would be meshed, and more than {100 * PIECE_FRACTION:g} % of it would be "
            "dropped: a mesh holds one breast: crop the image to one breast, or give the other "
            "piece's voxels a label not in mesh.image.breast_labels")
    info: dict[str, Any] = {"labels": {str(v): c for v, c in counts.items()}, "side": side,
                            "axes": grid.describe(), "pieces_ml": volumes, "warnings": []}
    if spec.chest_label is not None:
        _check_chest(labels[crop] == spec.chest_label, solid, factor, lo_i, grid, spec)
    cuts = border_cuts(breast, grid)
    info["field_of_view_cut_cm2"] = cuts
    if cuts:
        where = ", ".join(f"{WORDS[c]} ({c}) {a:.1f} cm²" for c, a in cuts.items())
        info["warnings"].append(
            f"the breast's labels reach the edge of the image on its {where}: the field of view "
            "cuts the breast there, and the cut face is meshed as skin (free to move, the "
            "tissue beyond it missing); check that the image holds the whole breast")
    for warning in info["warnings"]:
        log.warning("%s: %s", spec.path, warning)
    return info


def _mm(point: np.ndarray) -> str:
    return "(" + ", ".join(f"{v:.0f}" for v in point) + ")"


def _check_chest(chest: np.ndarray, solid: np.ndarray, factor: tuple[int, ...],
                 lo: np.ndarray, grid: Grid, spec: Any) -> None:
    """Refuse a chest label that does not touch the breast, or does not lie posterior of it.

    The chest's voxels within two working voxels of the breast (those its rib is made from)
    must lie posterior of the breast's centroid in the patient (LPS's +y, by the image's
    axes), within :data:`CHEST_ANGLE_DEG`.
    """
    from scipy import ndimage
    from skimage.measure import block_reduce

    near = block_reduce(chest, factor, np.max, cval=False)
    near &= ndimage.binary_dilation(solid, iterations=2)
    if not near.any():
        raise MeshInputError(f"{spec.path}: the chest label {spec.chest_label} does not touch "
                             "the breast (none of it lies within two working voxels of it)")

    def lps(mask: np.ndarray) -> np.ndarray:
        return grid.to_physical(centroid(mask) * factor + (np.array(factor) - 1) / 2 + lo)

    offset = lps(near) - lps(solid)
    distance = float(np.linalg.norm(offset))
    posterior = np.array(DIRECTIONS["P"])
    angle = float(np.degrees(np.arccos(np.clip(offset @ posterior / max(distance, 1e-12),
                                               -1.0, 1.0))))
    if angle <= CHEST_ANGLE_DEG:
        return
    towards = max(DIRECTIONS, key=lambda c: offset @ np.array(DIRECTIONS[c]))
    frame, remedy = spec.frame_words()
    raise GeometryError(
        f"the input {spec.path}: {frame}, the chest wall (its label {spec.chest_label} next to "
        f"the breast) lies {distance:.3g} mm from the breast's centroid towards the patient's "
        f"{WORDS[towards]} ({towards}), {angle:.0f}° from posterior, where it belongs posterior "
        f"of it: {remedy}")


def border_cuts(breast: np.ndarray, grid: Grid) -> dict[str, float]:
    """The area (cm²) of breast voxels on each face of the image but the chest's side.

    A face is on the chest's side where its outward direction lies within
    :data:`CHEST_SIDE_DEG` of the patient's posterior: a breast image cut at the chest wall
    holds the breast there. Elsewhere the field of view cuts the breast, and the cut face would
    be meshed as skin. A warning, not a refusal: a clinic's images often clip a few millimetres
    of the axillary tail or the fold, which cannot be imaged again; the area says how much.

    Returns:
        The patient direction of each cut face (a letter of an axes code) and its area, cm².
    """
    posterior = np.array(DIRECTIONS["P"])
    cuts: dict[str, float] = {}
    for axis in range(3):
        others = [a for a in range(3) if a != axis]
        face_cm2 = 1e-2 * float(np.prod(grid.spacing[others]))
        for end, sign in ((0, -1.0), (breast.shape[axis] - 1, 1.0)):
            outward = sign * grid.direction[:, axis]
            if outward @ posterior >= np.cos(np.radians(CHEST_SIDE_DEG)):
                continue
            count = int(np.take(breast, end, axis=axis).sum())
            if count:
                letter = min(DIRECTIONS, key=lambda c: -outward @ np.array(DIRECTIONS[c]))
                cuts[letter] = cuts.get(letter, 0.0) + count * face_cm2
    return cuts
