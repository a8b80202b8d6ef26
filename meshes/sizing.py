"""Element-size control of the parametric breast.

The target size at a point is the smallest of up to four laws, capped by
``global_size``::

    h(x) = min(global_size,
               mound_size + grading * d_mound(x),
               rib_size   + grading * d_rib(x),        (only if rib_size is set)
               fold_size  + grading * d_fold(x))       (only if fold_size is set)

``d_mound`` is an approximate distance outside the mound ellipsoid (0 inside it),
``d_rib`` the distance from the rib-cage surface and ``d_fold`` the distance from
the crease where the mound meets the skin layer (the inframammary fold).
Displacements peak at the tip of the mound and their gradients at its base, so
refining the mound pays most; the sharp crease is a re-entrant edge where the
displacement gradient is singular and whose under-resolution pollutes the error
everywhere, so a mesh graded towards it (``fold_size``) pays; ``rib_size`` refines
the clamped chest wall. ``grading`` bounds how fast the size may grow (metres of
size per metre of distance), which keeps neighbouring elements of similar size.

The mound and rib laws are gmsh ``MathEval`` fields: written once as
expressions, evaluated in compiled code while gmsh meshes, and exact for the
analytic surfaces. The crease has no closed-form distance, so the fold law is a
``Distance`` field sampled along the crease's CAD curves, finer than
``fold_size``.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from meshes.exceptions import GeometryError
from meshes.parametric import BreastGeometry, fold_curves


@dataclass(frozen=True, slots=True)
class MeshSize:
    """Element sizes (metres), their grading and the geometric order.

    Attributes:
        global_size: largest element size (far from the mound and the chest wall).
        mound_size: element size inside the mound.
        order: geometric order of the tetrahedra (1 straight, 2 curved: nodes on the CAD).
        grading: growth of the size with distance from a refined region (m per m).
        rib_size: element size on the rib (chest-wall) surface; ``None`` leaves it to
            the other laws.
        fold_size: element size at the crease where the mound meets the skin layer;
            ``None`` leaves it to the other laws. Needs the sharp crease
            (``BreastGeometry.fold_radius == 0``).
    """

    global_size: float = 0.015
    mound_size: float = 0.010
    order: int = 1
    grading: float = 0.3
    rib_size: float | None = None
    fold_size: float | None = None

    def __post_init__(self) -> None:
        for name in ("global_size", "mound_size", "grading"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise GeometryError(f"mesh.size.{name} must be positive, got {value!r}")
        for name in ("rib_size", "fold_size"):
            value = getattr(self, name)
            if value is not None and not (
                isinstance(value, (int, float)) and math.isfinite(value) and value > 0
            ):
                raise GeometryError(f"mesh.size.{name} must be positive or null, got {value!r}")
        if self.order not in (1, 2):
            raise GeometryError(f"mesh.size.order must be 1 or 2, got {self.order!r}")
        if self.mound_size > self.global_size:
            raise GeometryError(
                f"mesh.size.mound_size ({self.mound_size}) must not exceed global_size "
                f"({self.global_size})"
            )

    @classmethod
    def from_mapping(cls, values: dict[str, Any]) -> MeshSize:
        """Build from the ``mesh.size`` config mapping, rejecting unknown keys by name."""
        known = {"global_size", "mound_size", "order", "grading", "rib_size", "fold_size"}
        unknown = sorted(set(values) - known)
        if unknown:
            raise GeometryError(f"unknown mesh.size parameter(s): {', '.join(unknown)}")
        return cls(**values)

    def as_dict(self) -> dict[str, Any]:
        """Parameters as a plain mapping (for JSON metadata)."""
        return asdict(self)


def _num(value: float) -> str:
    # repr of a plain float round-trips exactly (numpy scalars may print their type);
    # MathEval rejects a unary minus after an operator ("x - -1"), so negatives go in brackets.
    text = repr(float(value))
    return f"({text})" if text.startswith("-") else text


def _positive_part(expr: str) -> str:
    # MathEval has no max(); (e + |e|) / 2 is max(e, 0).
    return f"(({expr}) + Fabs({expr})) / 2"


def mound_distance_expression(geometry: BreastGeometry) -> str:
    """MathEval expression of an approximate distance outside the mound ellipsoid.

    With ``q`` the ellipsoid's normalised radius (1 on its surface), ``(q - 1)``
    times the smallest semi-axis underestimates the true distance, so the size
    grows no faster than ``grading`` asks.
    """
    base, axis = geometry.mound_frame()
    centre = base + geometry.mound_offset * axis
    e1 = axis
    e2 = np.array([-axis[1], axis[0], 0.0])
    rel = f"(x - {_num(centre[0])})", f"(y - {_num(centre[1])})", f"(z - {_num(centre[2])})"

    def along(e: np.ndarray) -> str:
        return f"({_num(e[0])}*{rel[0]} + {_num(e[1])}*{rel[1]} + {_num(e[2])}*{rel[2]})"

    g = geometry
    q = (
        f"Sqrt(({along(e1)}/{_num(g.mound_length)})^2"
        f" + ({along(e2)}/{_num(g.mound_radius_lateral)})^2"
        f" + ({rel[2]}/{_num(g.mound_radius_cranial)})^2)"
    )
    r_min = min(g.mound_length, g.mound_radius_lateral, g.mound_radius_cranial)
    return f"{_num(r_min)} * {_positive_part(f'{q} - 1')}"


def rib_distance_expression(geometry: BreastGeometry) -> str:
    """MathEval expression of the distance from the elliptic rib cylinder (first order)."""
    a, b = geometry.rib_depth, geometry.rib_half_width
    u, v = f"((x - {_num(a)}) / {_num(a)})", f"(y / {_num(b)})"
    f = f"({u}^2 + {v}^2 - 1)"
    grad = f"Sqrt((2*{u}/{_num(a)})^2 + (2*{v}/{_num(b)})^2 + 1e-30)"
    return f"Fabs({f} / {grad})"


def fold_distance_field(model: Any, geometry: BreastGeometry, volume: int, spacing: float) -> int:
    """A gmsh ``Distance`` field to the crease curves of ``volume``; returns its tag.

    The curves are sampled every ``spacing`` metres (at least 20 points each).

    Raises:
        GeometryError: if ``volume`` has no sharp crease (e.g. a rounded fold).
    """
    model.occ.synchronize()
    curves = fold_curves(model, geometry, volume)
    if not curves:
        raise GeometryError(
            "mesh.size.fold_size refines the sharp crease where the mound meets the skin layer, "
            f"and this geometry has none (geometry.fold_radius = {geometry.fold_radius}); "
            "set fold_size to null"
        )
    length = sum(model.occ.getMass(1, c) for c in curves)
    tag = model.mesh.field.add("Distance")
    model.mesh.field.setNumbers(tag, "CurvesList", curves)
    samples = max(20, int(math.ceil(length / len(curves) / spacing)))
    model.mesh.field.setNumber(tag, "Sampling", samples)
    return tag


def add_size_field(
    model: Any, geometry: BreastGeometry, size: MeshSize, volume: int | None = None
) -> int:
    """Install the size laws of :class:`MeshSize` as the background field of ``model``.

    Args:
        model: ``gmsh.model`` holding the breast.
        geometry: its shape parameters.
        size: the size laws.
        volume: the breast's volume tag; needed only when ``size.fold_size`` is set.

    Returns:
        The tag of the background field.
    """
    field = model.mesh.field
    laws = [(size.mound_size, mound_distance_expression(geometry))]
    if size.rib_size is not None:
        laws.append((size.rib_size, rib_distance_expression(geometry)))
    if size.fold_size is not None:
        if volume is None:
            raise ValueError("add_size_field needs the volume tag to refine the crease")
        distance = fold_distance_field(model, geometry, volume, size.fold_size / 4)
        laws.append((size.fold_size, f"F{distance}"))
    tags = []
    for h0, distance in laws:
        tag = field.add("MathEval")
        field.setString(tag, "F", f"{_num(h0)} + {_num(size.grading)} * {distance}")
        tags.append(tag)
    if len(tags) == 1:
        background = tags[0]
    else:
        background = field.add("Min")
        field.setNumbers(background, "FieldsList", tags)
    field.setAsBackgroundMesh(background)
    return background
