"""How an imported file's axes lie in the patient, and the map into the project's frame.

The project's frame (the paper's, see docs/geometry.md) is anatomical and the same for every
geometry: x runs anterior to posterior, y medial to lateral, z caudal to cranial (inferior to
superior), so that Φ and θ mean the same posture whatever the file. Image-derived meshes come
in scanner axes instead: a three-letter code names the patient direction each file axis points
to (DICOM's LPS: +x to the patient's Left, +y Posterior, +z Superior; RAS for NIfTI and most
surface tools), and the breast's side says which way is lateral.

The map is a rotation, or for one side a reflection: (posterior, lateral, superior) is a
right-handed frame for a right breast and a left-handed one for a left breast, so a left breast
is mirrored into the project's frame (the import then reorders each element's vertices so that
cells stay positively oriented). Positions and displacements go back with :meth:`to_file`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from meshes.exceptions import GeometryError, reject_unknown

#: Patient directions in one fixed basis (Left, Posterior, Superior).
DIRECTIONS = {
    "L": (1.0, 0.0, 0.0), "R": (-1.0, 0.0, 0.0),
    "P": (0.0, 1.0, 0.0), "A": (0.0, -1.0, 0.0),
    "S": (0.0, 0.0, 1.0), "I": (0.0, 0.0, -1.0),
}
PAIRS = ("LR", "AP", "SI")
SIDES = ("left", "right")
PROJECT = "project"
"""The file is already in the project's frame (the default): no map."""


def axes_code(axes: str, key: str) -> str:
    """An anatomical axes code, upper case: three letters, one of each pair L/R, A/P, S/I.

    Raises:
        GeometryError: naming ``key`` where ``axes`` is not such a code.
    """
    code = str(axes).upper()
    pairs = sorted(i for c in code for i, pair in enumerate(PAIRS) if c in pair)
    if len(code) != 3 or pairs != [0, 1, 2]:
        raise GeometryError(
            f"{key} {axes!r} is not an anatomical code: three letters, one of each pair L/R, "
            "A/P, S/I, naming where each axis points (e.g. LPS for DICOM, RAS for NIfTI)"
        )
    return code


def axes_directions(code: str) -> np.ndarray:
    """Each axis of ``code`` as a column of unit vectors in (Left, Posterior, Superior)."""
    return np.array([DIRECTIONS[c] for c in code]).T


def nearest_code(directions: np.ndarray) -> str:
    """The axes code nearest to direction cosines (columns in LPS): each column's largest part."""
    letters = []
    for column in np.asarray(directions, dtype=float).T:
        axis = int(np.argmax(np.abs(column)))
        letters.append("LPS"[axis] if column[axis] > 0 else "RAI"[axis])
    return "".join(letters)


@dataclass(frozen=True, slots=True)
class Orientation:
    """The file's axes in the patient (``mesh.file.orientation``).

    Attributes:
        axes: ``project`` (the file is in the project's frame), or a three-letter code of the
            patient direction each file axis points to, one letter of each pair L/R, A/P, S/I
            (e.g. ``LPS``, ``RAS``).
        side: ``left`` or ``right``: the breast's side (required with a code).
    """

    axes: str = PROJECT
    side: str | None = None

    def __post_init__(self) -> None:
        if self.axes == PROJECT:
            if self.side is not None and self.side not in SIDES:
                raise GeometryError(f"mesh.file.orientation.side must be one of {SIDES}")
            return
        code = axes_code(self.axes, "mesh.file.orientation.axes")
        object.__setattr__(self, "axes", code)
        if self.side not in SIDES:
            raise GeometryError(
                f"mesh.file.orientation.side must be left or right with axes {code}: it says "
                "which way is lateral"
            )

    @classmethod
    def from_mapping(cls, values: dict[str, Any] | None) -> Orientation:
        """Build from the ``mesh.file.orientation`` mapping (None: the project's frame)."""
        values = dict(values or {})
        reject_unknown(values, {"axes", "side"}, "mesh.file.orientation key(s)")
        return cls(axes=values.get("axes", PROJECT), side=values.get("side"))

    @property
    def declared(self) -> bool:
        """Whether the file's axes were declared (else they are taken as the project's)."""
        return self.axes != PROJECT

    @property
    def matrix(self) -> np.ndarray:
        """M (3, 3) with project = M @ file: M[i, j] is project axis i · file axis j."""
        if not self.declared:
            return np.eye(3)
        lateral = "L" if self.side == "left" else "R"
        project = np.array([DIRECTIONS[c] for c in ("P", lateral, "S")])
        file = np.array([DIRECTIONS[c] for c in self.axes])
        return project @ file.T

    @property
    def mirrors(self) -> bool:
        """Whether the map is a reflection (cells must be reordered to keep their orientation)."""
        return bool(np.linalg.det(self.matrix) < 0)

    def to_project(self, values: np.ndarray) -> np.ndarray:
        """Points or vectors (..., 3) from the file's axes into the project's frame."""
        return np.asarray(values, dtype=float) @ self.matrix.T

    def to_file(self, values: np.ndarray) -> np.ndarray:
        """Points or vectors (..., 3) from the project's frame back into the file's axes."""
        return np.asarray(values, dtype=float) @ self.matrix

    def describe(self) -> dict[str, Any]:
        """For the mesh's quality report."""
        return {"axes": self.axes, "side": self.side, "file_to_project": self.matrix.tolist(),
                "mirrored": self.mirrors}


def file_frame_words(orientation: Orientation) -> tuple[str, str]:
    """How a surface or volume file's frame is named in a refusal, and what to change."""
    frame = (f"with mesh.file.orientation axes {orientation.axes}, side {orientation.side}"
             if orientation.declared else
             "taken to be in the project's frame (x anterior to posterior: no "
             "mesh.file.orientation axes)")
    remedy = ("check the axes code (where each file axis points) and the side"
              if orientation.declared else
              "declare the file's axes and the breast's side (mesh.file.orientation)")
    return frame, remedy


def check_chest_wall_posterior(
    x: np.ndarray, rib_facets: np.ndarray, orientation: Orientation, what: str,
    words: tuple[str, str] | None = None,
) -> float:
    """Refuse an orientation, declared or not, that puts the chest wall anterior of the breast.

    In the project's frame the chest wall is posterior (+x) of the tissue it holds: the rib
    facets' centroid must lie at a larger x than the body's. A file without an orientation is
    taken to be in that frame, and is checked the same way.

    Args:
        x: the mesh's points in the project's frame.
        rib_facets: the rib's triangles.
        orientation: the map the points came through.
        what: the input, for the message.
        words: how the frame is named and what to change (default
            :func:`file_frame_words`: ``mesh.file.orientation``'s).

    Returns:
        How far posterior of the body's centroid the chest wall lies, m.

    Raises:
        GeometryError: naming the orientation and the positions found.
    """
    rib_x = float(x[np.unique(rib_facets)][:, 0].mean())
    body_x = float(x[:, 0].mean())
    if rib_x > body_x:
        return rib_x - body_x
    frame, remedy = words or file_frame_words(orientation)
    raise GeometryError(
        f"{what}: {frame}, the chest wall (the rib facets) lies "
        f"{1e3 * (body_x - rib_x):.3g} mm anterior of the breast's centroid, where it belongs "
        f"posterior of it: {remedy}"
    )
