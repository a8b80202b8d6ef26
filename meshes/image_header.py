"""A label volume's header: the map from voxel indices to the scanner's millimetres, checked.

SimpleITK reads every format's header (NIfTI, NRRD, MetaImage) into an origin, a voxel size and
direction cosines in ITK's LPS convention. Where that map would be wrong, ITK goes on with a
warning on the console or none, so the header is checked here before a voxel is read, and a
refusal names the header field:

* the voxel size (NIfTI ``pixdim``, MetaImage ``ElementSpacing``, NRRD ``space directions``)
  must be finite and positive: ITK takes a NIfTI ``pixdim`` of 0 or NaN as 1 mm, and a negative
  one (NIfTI or MetaImage) as a positive size along a flipped axis, a mirror image;
* the direction cosines must be orthonormal within :data:`ORTHONORMAL_TOLERANCE`: ITK keeps a
  MetaImage ``TransformMatrix`` scaled by 2 as it is, which makes the breast 8 times its volume;
* a NIfTI's ``pixdim`` must agree with its sform (the lengths of its columns), which ITK sets
  aside for the qform where they differ;
* the field of view must be large enough to hold a breast: a voxel size in other units (1e-6
  mm) is refused as the surface import refuses a file in other units;
* the file must hold every voxel its header promises: ITK reads a truncated NIfTI (``.nii``, or
  ``.nii.gz`` cut short) as whole, the missing voxels as background.

``mesh.image.orientation`` (an axes code, as ``mesh.file.orientation.axes``) replaces the
header's direction cosines, for an image whose header says the wrong thing: the header's
direction is then neither used nor checked.
"""

from __future__ import annotations

import functools
import gzip
import struct
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from meshes.checks import PLAUSIBLE_EXTENT_M
from meshes.exceptions import ImageHeaderError, MeshInputError, UnitsError
from meshes.orientation import axes_directions, nearest_code

#: How far the direction cosines' columns may be from orthonormal (|DᵀD - I|, any entry).
ORTHONORMAL_TOLERANCE = 1e-3
#: How far a NIfTI's pixdim may differ from its sform's column lengths, relatively.
SFORM_TOLERANCE = 1e-3

#: Each format's header fields, named in refusals: the voxel size, the direction cosines.
FIELDS = {
    "nifti": ("pixdim", "sform/qform"),
    "nrrd": ("space directions", "space directions"),
    "metaimage": ("ElementSpacing", "TransformMatrix"),
}
FORMATS = {".nii": "nifti", ".nii.gz": "nifti", ".nrrd": "nrrd", ".nhdr": "nrrd",
           ".mha": "metaimage", ".mhd": "metaimage"}

#: Where NIfTI-1 (a 348-byte header) and NIfTI-2 (540 bytes) keep the fields checked here:
#: offset and struct format.
NIFTI_LAYOUT = {
    348: {"dim": (40, "8h"), "bitpix": (72, "h"), "pixdim": (76, "8f"), "vox_offset": (108, "f"),
          "sform_code": (254, "h"), "srow": (280, "12f")},
    540: {"dim": (16, "8q"), "bitpix": (14, "h"), "pixdim": (104, "8d"), "vox_offset": (168, "q"),
          "sform_code": (348, "i"), "srow": (400, "12d")},
}
#: Bytes per voxel of MetaImage's element types.
MET_BYTES = {"MET_CHAR": 1, "MET_UCHAR": 1, "MET_SHORT": 2, "MET_USHORT": 2, "MET_INT": 4,
             "MET_UINT": 4, "MET_LONG": 4, "MET_ULONG": 4, "MET_LONG_LONG": 8,
             "MET_ULONG_LONG": 8, "MET_FLOAT": 4, "MET_DOUBLE": 8}


@dataclass(frozen=True)
class Grid:
    """The header's map from voxel indices (i, j, k) to the scanner's LPS millimetres.

    Attributes:
        origin: voxel (0, 0, 0)'s centre, mm.
        spacing: the voxel size along i, j, k, mm.
        direction: the axes i, j, k as columns of unit vectors in LPS.
        shape: voxels along i, j, k.
        axes_from: ``header`` or ``mesh.image.orientation`` (which gave ``direction``).
    """

    origin: np.ndarray
    spacing: np.ndarray
    direction: np.ndarray
    shape: tuple[int, int, int]
    axes_from: str = "header"

    def to_physical(self, index: np.ndarray) -> np.ndarray:
        """Continuous voxel indices (..., 3) to LPS millimetres."""
        return self.origin + (np.asarray(index, dtype=float) * self.spacing) @ self.direction.T

    def to_index(self, physical: np.ndarray) -> np.ndarray:
        """LPS millimetres (..., 3) to continuous voxel indices."""
        return ((np.asarray(physical, dtype=float) - self.origin) @ self.direction) / self.spacing

    def describe(self) -> dict[str, Any]:
        """Where the voxel axes point, and who said so (for the quality report and preview)."""
        return {"code": nearest_code(self.direction), "from": self.axes_from,
                "direction": self.direction.tolist()}


def image_format(path: str | Path) -> str | None:
    """``nifti``, ``nrrd`` or ``metaimage`` by the file's suffix (``.nii.gz`` counts as one)."""
    name = str(path).lower()
    return next((FORMATS[s] for s in sorted(FORMATS, key=len, reverse=True)
                 if name.endswith(s)), None)


def first_line(err: Exception) -> str:
    """The line of an ITK error that says what is wrong."""
    lines = [line.strip() for line in str(err).splitlines() if line.strip()]
    described = [line for line in lines if "Description" in line or "ERROR" in line.upper()]
    return (described or lines or [type(err).__name__])[-1]


def read_header(path: str | Path, axes: str | None = None) -> Grid:
    """The checked voxel-to-millimetre map of an image, from its header alone.

    Args:
        path: the label volume.
        axes: ``mesh.image.orientation``, an axes code that replaces the header's direction
            cosines (None: the header's, checked).

    Raises:
        MeshInputError: for a missing or unreadable file; :class:`ImageHeaderError` (or
            :class:`UnitsError` for the field of view's size) naming the header field.
    """
    import SimpleITK as sitk

    path = Path(path)
    if not path.is_file():
        raise MeshInputError(f"image file {path} does not exist")
    kind = image_format(path)
    size_field, direction_field = FIELDS.get(kind, ("spacing", "direction"))
    stat = path.stat()
    if kind == "nifti":
        _check_nifti(str(path), stat.st_mtime, stat.st_size)
    elif kind == "metaimage":
        _check_metaimage(path)
    reader = sitk.ImageFileReader()
    reader.SetFileName(str(path))
    try:
        reader.ReadImageInformation()
    except RuntimeError as err:
        said = first_line(err)
        if "spacing" in said.lower():  # ITK's refusal of a zero or NaN size, in its words
            raise ImageHeaderError(f"{path}: the header's voxel size ({size_field}) is not "
                                   f"finite and positive: {said}") from None
        raise MeshInputError(f"cannot read the image {path}: {said}") from None
    grid = Grid(np.array(reader.GetOrigin(), dtype=float),
                np.array(reader.GetSpacing(), dtype=float),
                np.array(reader.GetDirection(), dtype=float).reshape(3, 3),
                tuple(int(n) for n in reader.GetSize()))
    if axes is not None:
        grid = Grid(grid.origin, grid.spacing, axes_directions(axes), grid.shape,
                    "mesh.image.orientation")
    else:
        check_direction(grid.direction, f"{path}: the header's direction cosines "
                        f"({direction_field})")
    check_field_of_view(grid, f"{path}", size_field)
    return grid


def check_spacing(values: Any, what: str) -> np.ndarray:
    """Refuse a voxel size that is not finite and positive along every axis.

    Raises:
        ImageHeaderError: naming ``what`` (the file and header field) and the values.
    """
    spacing = np.asarray(values, dtype=float)
    bad = [i for i, s in enumerate(spacing) if not (np.isfinite(s) and s > 0)]
    if bad:
        raise ImageHeaderError(
            f"{what} = ({', '.join(f'{s:g}' for s in spacing)}) mm is not a finite, positive "
            f"voxel size (axis {', '.join('ijk'[i] for i in bad)}): ITK would take another "
            "size (1 mm for a 0 or NaN, a mirror image for a negative one); fix the header")
    return spacing


def check_direction(direction: np.ndarray, what: str) -> None:
    """Refuse direction cosines whose columns are not orthonormal within the tolerance.

    Raises:
        ImageHeaderError: naming ``what``, the columns' lengths and the angles between them.
    """
    d = np.asarray(direction, dtype=float)
    gram = d.T @ d
    error = float(np.max(np.abs(gram - np.eye(3)))) if np.all(np.isfinite(d)) else np.inf
    if error <= ORTHONORMAL_TOLERANCE:
        return
    lengths = np.sqrt(np.abs(np.diag(gram)))
    with np.errstate(invalid="ignore", divide="ignore"):
        cosine = gram / np.outer(lengths, lengths)
    angles = [np.degrees(np.arccos(np.clip(cosine[a, b], -1, 1))) for a, b in ((0, 1), (0, 2),
                                                                             (1, 2))]
    raise ImageHeaderError(
        f"{what} are not orthonormal (beyond {ORTHONORMAL_TOLERANCE:g}): its columns are "
        f"{', '.join(f'{v:.4g}' for v in lengths)} long, at {', '.join(f'{a:.4g}' for a in angles)}"
        " degrees (i-j, i-k, j-k), where they must be 1 long and at 90 degrees: the voxels "
        "cannot be placed; fix the header, or give mesh.image.orientation (where the voxel axes "
        "i, j, k point, e.g. LPS) to set the header's direction aside")


def check_field_of_view(grid: Grid, what: str, size_field: str) -> float:
    """Refuse a field of view too small to hold a breast: a voxel size in other units.

    Returns:
        The field of view's diagonal, mm.

    Raises:
        UnitsError: naming the voxel size and the field of view's size.
    """
    diagonal = float(np.linalg.norm((np.array(grid.shape) - 1) * grid.spacing))
    smallest = 1e3 * PLAUSIBLE_EXTENT_M[0]
    if diagonal >= smallest:
        return diagonal
    raise UnitsError(
        f"{what}: by its header's voxel size ({size_field}: "
        f"{' x '.join(f'{s:.3g}' for s in grid.spacing)} mm) the image is {diagonal:.3g} mm "
        f"across (its field of view's diagonal), but a breast alone is {smallest:g} mm across "
        "or more: the voxel size is probably in other units; fix the header")


# -- NIfTI ------------------------------------------------------------------------------------


@functools.lru_cache(maxsize=8)
def _check_nifti(path: str, mtime: float, size: int) -> None:
    """:func:`check_nifti`, once per version of a file (its name, time and size)."""
    check_nifti(path)


def check_nifti(path: str | Path) -> None:
    """A NIfTI file's pixdim (finite, positive, as its sform) and its data's length.

    Raises:
        ImageHeaderError: naming the field (``pixdim``, the sform) or the missing bytes.
    """
    path = Path(path)
    compressed = str(path).lower().endswith(".gz")
    try:
        with (gzip.open(path, "rb") if compressed else path.open("rb")) as stream:
            head = stream.read(540)
    except (OSError, EOFError, zlib.error) as err:
        raise ImageHeaderError(f"{path}: not a readable NIfTI file ({err})") from None
    fields = _nifti_fields(head)
    if fields is None:
        return  # not a NIfTI header: ITK names it
    dim = [int(v) for v in fields["dim"]]
    n = min(max(dim[0], 1), 7)
    where = f"{path}: the header's pixdim[1:{min(n, 3) + 1}]"
    spacing = check_spacing(fields["pixdim"][1:min(n, 3) + 1], where)
    if fields["sform_code"] > 0 and n >= 3:
        srow = np.asarray(fields["srow"], dtype=float).reshape(3, 4)[:, :3]
        if not np.all(np.isfinite(srow)):
            raise ImageHeaderError(f"{path}: the header's sform (srow_x, srow_y, srow_z) holds "
                                   "a NaN or an infinity; fix the header")
        lengths = np.linalg.norm(srow, axis=0)
        if np.any(np.abs(lengths - spacing[:3]) > SFORM_TOLERANCE * np.maximum(lengths, 1e-12)):
            raise ImageHeaderError(
                f"{where} = ({', '.join(f'{s:g}' for s in spacing)}) mm disagrees with its "
                f"sform (srow_x, srow_y, srow_z), whose columns make voxels of "
                f"{' x '.join(f'{v:.4g}' for v in lengths)} mm: ITK would set the sform aside; "
                "one of them is wrong: fix the header")
        check_direction(srow / np.where(lengths > 0, lengths, 1.0),
                        f"{path}: the header's sform (srow_x, srow_y, srow_z) directions")
    voxels = int(np.prod([max(d, 1) for d in dim[1:n + 1]], dtype=np.int64))
    needed = int(fields["vox_offset"]) + voxels * max(int(fields["bitpix"]), 8) // 8
    held = _gzip_length(path) if compressed else path.stat().st_size
    if held < needed:
        raise ImageHeaderError(
            f"{path} is truncated: it holds {held} bytes where its header (dim "
            f"{' x '.join(map(str, dim[1:n + 1]))}, bitpix {fields['bitpix']}) needs {needed}; "
            "ITK would read the missing voxels as background: copy the file again")


def _nifti_fields(head: bytes) -> dict[str, Any] | None:
    """The checked fields of a NIfTI-1 or NIfTI-2 header (either byte order), or None."""
    if len(head) < 4:
        return None
    for order in "<>":
        size = struct.unpack_from(order + "i", head, 0)[0]
        layout = NIFTI_LAYOUT.get(size)
        if layout is None or len(head) < size:
            continue
        out = {}
        for name, (offset, form) in layout.items():
            values = struct.unpack_from(order + form, head, offset)
            out[name] = values if len(values) > 1 else values[0]
        return out
    return None


def _gzip_length(path: Path) -> int:
    """The bytes a gzip file decompresses to, read through (a truncated stream is refused)."""
    held = 0
    try:
        with gzip.open(path, "rb") as stream:
            while chunk := stream.read(1 << 24):
                held += len(chunk)
    except (EOFError, OSError, zlib.error) as err:
        raise ImageHeaderError(
            f"{path} is truncated or corrupt: its compressed data ends after {held} bytes, "
            f"before the end of the gzip stream ({err}); ITK would read the missing voxels as "
            "background: copy the file again") from None
    return held


# -- MetaImage --------------------------------------------------------------------------------


def _metaimage_header(path: Path) -> tuple[dict[str, str], int]:
    """A MetaImage header's ``key = value`` fields, and its length in bytes (up to the data)."""
    fields: dict[str, str] = {}
    length = 0
    with path.open("rb") as stream:
        for raw in stream:
            length += len(raw)
            key, _, value = raw.decode("latin-1").partition("=")
            fields[key.strip()] = value.strip()
            if key.strip() == "ElementDataFile" or length > 1 << 16:
                break
    return fields, length


def _check_metaimage(path: Path) -> None:
    """A MetaImage's ElementSpacing (finite, positive) and its data's length.

    Raises:
        ImageHeaderError: naming the field, or the missing bytes.
    """
    fields, header_bytes = _metaimage_header(path)
    spacing = fields.get("ElementSpacing", fields.get("ElementSize"))
    if spacing is not None:
        try:
            values = [float(v) for v in spacing.split()]
        except ValueError:
            raise ImageHeaderError(f"{path}: the header's ElementSpacing {spacing!r} is not "
                                   "three numbers") from None
        check_spacing(values, f"{path}: the header's ElementSpacing")
    data = fields.get("ElementDataFile", "")
    try:
        shape = [int(v) for v in fields.get("DimSize", "").split()]
        channels = int(fields.get("ElementNumberOfChannels", "1"))
        header_size = int(fields.get("HeaderSize", "0"))
    except ValueError:
        return  # ITK names a header it cannot parse
    if data.upper() == "LOCAL":
        held = path.stat().st_size - header_bytes
    elif data and "%" not in data and data.upper() != "LIST" and header_size >= 0:
        target = path.parent / data
        held = (target.stat().st_size - header_size) if target.is_file() else None
    else:
        held = None
    if fields.get("CompressedData", "False").lower() == "true":
        needed = int(fields["CompressedDataSize"]) if fields.get(
            "CompressedDataSize", "").isdigit() else None
    else:
        needed = (int(np.prod(shape, dtype=np.int64)) * channels
                  * MET_BYTES.get(fields.get("ElementType", ""), 0)) or None
    if held is not None and needed is not None and held < needed:
        raise ImageHeaderError(
            f"{path} is truncated: its data ({data}) holds {held} bytes where its header "
            f"(DimSize {' x '.join(map(str, shape))}, ElementType "
            f"{fields.get('ElementType')}) needs {needed}: copy the file again")
