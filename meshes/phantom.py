"""A segmented breast phantom written as a label volume, as a segmentation tool writes one.

The anatomy is set in the project's frame (x anterior to posterior, y medial to lateral, z
caudal to cranial, metres): the chest wall is a surface curving posteriorly away from the
breast's base (radius :data:`CHEST_RADIUS_M`), the pectoral muscle a slab of
:data:`PECTORAL_M` behind it, the breast the part of an ellipsoid anterior of the chest (so
that the skin meets the chest at a sharp rim, as in every image), with a glandular core and a
tumour inside. The voxels are laid out in the scanner's LPS millimetres by an image header
(origin, spacing, direction cosines): a field of view of a dedicated breast CT, or of a torso
with the breast off its centre, with any rotation and anisotropic spacing.

Labels: 0 background, 1 fat, 2 glandular tissue, 3 pectoral muscle, 4 tumour, 5 the rest of
the body (in a torso's field of view), and, where asked for, 6 the skin: a shell of given
thickness under the breast's surface (not on the chest wall).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from meshes.orientation import Orientation

FAT, GLAND, PECTORAL, TUMOUR, BODY, SKIN = 1, 2, 3, 4, 5, 6
BREAST_LABELS = (FAT, GLAND, TUMOUR)
#: The tissue of each breast label but fat's, as ``mesh.image.tissues`` names them.
TISSUE_LABELS = {"gland": [GLAND], "tumour": [TUMOUR], "skin": [SKIN]}

#: The breast's semi-axes (anterior, lateral, cranial), m.
SEMI_AXES_M = (0.055, 0.07, 0.065)
CHEST_RADIUS_M = 0.2
PECTORAL_M = 0.012
TUMOUR_CENTRE_M = (-0.025, 0.01, 0.005)
TUMOUR_RADIUS_M = 0.008


def labels_at(x: np.ndarray, skin_m: float = 0.0) -> np.ndarray:
    """The phantom's label at points ``x`` (..., 3) in the project's frame, m.

    ``skin_m`` > 0 labels a skin of that thickness under the breast's surface.
    """
    px, py, pz = x[..., 0], x[..., 1], x[..., 2]
    chest = (py**2 + pz**2) / (2 * CHEST_RADIUS_M)  # the chest wall's x, curving posteriorly
    a, b, c = SEMI_AXES_M
    inside = (px / a) ** 2 + (py / b) ** 2 + (pz / c) ** 2 <= 1.0
    breast = inside & (px < chest)
    gland = breast & ((px / (0.6 * a)) ** 2 + (py / (0.5 * b)) ** 2 + (pz / (0.5 * c)) ** 2 <= 1)
    tumour = np.linalg.norm(x - np.array(TUMOUR_CENTRE_M), axis=-1) <= TUMOUR_RADIUS_M
    behind = (px >= chest) & (px < chest + PECTORAL_M) & (np.abs(py) < 1.3 * b) & (
        np.abs(pz) < 1.3 * c)
    body = (px >= chest + PECTORAL_M) & (px < chest + 0.12)
    out = np.zeros(px.shape, dtype=np.uint8)
    out[body] = BODY
    out[behind] = PECTORAL
    out[breast] = FAT
    out[gland] = GLAND
    out[breast & tumour] = TUMOUR
    if skin_m > 0:
        inner = (px / (a - skin_m)) ** 2 + (py / (b - skin_m)) ** 2 + (pz / (c - skin_m)) ** 2
        out[breast & (inner > 1.0)] = SKIN
    return out


def rotation(degrees: tuple[float, float, float]) -> np.ndarray:
    """Direction cosines: rotations about the x, y and z axes, in turn."""
    out = np.eye(3)
    for axis, angle in enumerate(np.radians(degrees)):
        c, s = np.cos(angle), np.sin(angle)
        r = np.eye(3)
        i, j = [k for k in range(3) if k != axis]
        r[i, i], r[i, j], r[j, i], r[j, j] = c, -s, s, c
        out = r @ out
    return out


def write_phantom(path: str | Path, shape: tuple[int, int, int],
                  spacing_mm: tuple[float, float, float], side: str = "left",
                  direction: np.ndarray | None = None, breast_offset_mm: float = 0.0,
                  scanner_origin_mm: tuple[float, float, float] = (0.0, 0.0, 0.0),
                  skin_mm: float = 0.0) -> Path:
    """Write the phantom as a label volume (the format by the suffix, with SimpleITK).

    Args:
        path: ``.nii``/``.nii.gz``, ``.nrrd``/``.nhdr`` or ``.mha``/``.mhd``.
        shape: voxels along the image's i, j, k.
        spacing_mm: voxel size along i, j, k.
        side: the breast's side.
        direction: the image axes' direction cosines in LPS (columns), default identity.
        breast_offset_mm: how far the field of view's centre lies medial of the breast's
            centre (0: centred on the breast, as a dedicated breast image).
        scanner_origin_mm: where the breast's base centre lies in the scanner's LPS.
        skin_mm: the skin label's thickness (0: no skin label, the skin is fat's).

    Returns:
        ``path``.
    """
    import SimpleITK as sitk

    frame = Orientation("LPS", side)
    direction = np.eye(3) if direction is None else np.asarray(direction, dtype=float)
    spacing = np.asarray(spacing_mm, dtype=float)
    base = np.asarray(scanner_origin_mm, dtype=float)
    # the field of view's centre: the breast's centre (anterior of the base), moved medially
    centre = base + frame.to_file(np.array([-0.025, -1e-3 * breast_offset_mm, 0.0])) * 1e3
    extent = (np.asarray(shape) - 1) * spacing
    origin = centre - direction @ (extent / 2)
    labels = np.zeros(tuple(reversed(shape)), dtype=np.uint8)  # [k, j, i]
    ii, jj = np.meshgrid(np.arange(shape[0]), np.arange(shape[1]), indexing="xy")
    for k in range(shape[2]):
        index = np.stack([ii, jj, np.full_like(ii, k)], axis=-1).astype(float)
        lps = origin + (index * spacing) @ direction.T
        labels[k] = labels_at(frame.to_project(1e-3 * (lps - base)), 1e-3 * skin_mm)
    image = sitk.GetImageFromArray(labels)
    image.SetSpacing(tuple(float(s) for s in spacing))
    image.SetOrigin(tuple(float(o) for o in origin))
    image.SetDirection(tuple(float(d) for d in direction.ravel()))
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    sitk.WriteImage(image, str(path), useCompression=str(path).endswith((".gz", ".nrrd", ".mha")))
    return path
