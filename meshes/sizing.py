"""Element-size control of the parametric breast.

The target size at a point is the smallest of up to four laws, capped by
``global_size``::

    h(x) = min(global_size,
               mound_size + grading * d_mound(x),
               rib_size   + grading * d_rib(x),        (only if rib_size is set)
               fold_size  + grading * d_fold(x))       (only if fold_size is set)

``d_mound`` is an approximate distance outside the mound ellipsoid (0 inside it),
``d_rib`` the distance from the rib-cage surface and ``d_fold`` the distance from
the inframammary fold, where the mound meets the skin layer (0 over the fillet
that rounds it, ``geometry.fold_radius``). Displacements peak at the tip of the
mound and their gradients at its base, so refining the mound pays most. The fold
is where the mesh must resolve the geometry: a sharp crease is a re-entrant edge
where the displacement gradient is singular, a fillet a curvature of radius
``fold_radius``, often below the element size; under-resolved, either pollutes
the error everywhere, so a mesh graded towards it (``fold_size``) pays.
``rib_size`` refines the clamped chest wall. ``grading`` bounds how fast the size
may grow (metres of size per metre of distance), which keeps neighbouring
elements of similar size.

The laws are gmsh ``MathEval`` fields: written once as expressions of analytic
(first-order) distances, evaluated in compiled code while gmsh meshes.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from meshes.exceptions import GeometryError, reject_unknown
from meshes.parametric import BreastGeometry


@dataclass(frozen=True, slots=True)
class MeshSize:
    """Element sizes (metres), their grading and the geometric order.

    The defaults are the plain law that any geometry, parametric or imported, accepts;
    ``config.yaml`` grades the default breast's mesh to its fold with curved cells.

    Attributes:
        global_size: largest element size (far from the mound and the chest wall).
        mound_size: element size inside the mound.
        order: geometric order of the tetrahedra (1 straight, 2 curved: nodes on the CAD).
        grading: growth of the size with distance from a refined region (m per m).
        rib_size: element size on the rib (chest-wall) surface; ``None`` leaves it to
            the other laws.
        fold_size: element size over the inframammary fold (the crease where the
            mound meets the skin layer, or the fillet rounding it); ``None`` leaves
            it to the other laws.
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
        reject_unknown(values, known, "mesh.size parameter(s)")
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


def _mound_coordinates(geometry: BreastGeometry) -> list[tuple[str, float]]:
    """MathEval coordinates along the mound ellipsoid's three axes, each with its semi-axis.

    The coordinates are measured from the ellipsoid's centre.
    """
    base, axis = geometry.mound_frame()
    centre = base + geometry.mound_offset * axis
    rel = f"(x - {_num(centre[0])})", f"(y - {_num(centre[1])})", f"(z - {_num(centre[2])})"

    def along(e: np.ndarray) -> str:
        return f"({_num(e[0])}*{rel[0]} + {_num(e[1])}*{rel[1]} + {_num(e[2])}*{rel[2]})"

    g = geometry
    return [
        (along(axis), g.mound_length),
        (along(np.array([-axis[1], axis[0], 0.0])), g.mound_radius_lateral),
        (rel[2], g.mound_radius_cranial),
    ]


def mound_distance_expression(geometry: BreastGeometry) -> str:
    """MathEval expression of an approximate distance outside the mound ellipsoid.

    With ``q`` the ellipsoid's normalised radius (1 on its surface), ``(q - 1)``
    times the smallest semi-axis underestimates the true distance, so the size
    grows no faster than ``grading`` asks.
    """
    coords = _mound_coordinates(geometry)
    q = "Sqrt(" + " + ".join(f"({c}/{_num(r)})^2" for c, r in coords) + ")"
    r_min = min(r for _, r in coords)
    return f"{_num(r_min)} * {_positive_part(f'{q} - 1')}"


def _elliptic_cylinder_distance(geometry: BreastGeometry, offset: float) -> str:
    """First-order distance |f| / |grad f| from the rib's elliptic cylinder, offset outwards.

    ``offset`` 0 is the rib; ``layer_thickness`` is the layer's skin.
    """
    c, a, b = geometry.rib_depth, geometry.rib_depth + offset, geometry.rib_half_width + offset
    u, v = f"((x - {_num(c)}) / {_num(a)})", f"(y / {_num(b)})"
    f = f"({u}^2 + {v}^2 - 1)"
    grad = f"Sqrt((2*{u}/{_num(a)})^2 + (2*{v}/{_num(b)})^2 + 1e-30)"
    return f"Fabs({f} / {grad})"


def rib_distance_expression(geometry: BreastGeometry) -> str:
    """MathEval expression of the distance from the elliptic rib cylinder (first order)."""
    return _elliptic_cylinder_distance(geometry, 0.0)


def fold_distance_expression(geometry: BreastGeometry) -> str:
    """MathEval expression of the distance from the inframammary fold.

    The fold is where the mound ellipsoid meets the skin layer's outer cylinder. Near
    that curve the distance from it is about ``sqrt(d_e**2 + d_c**2)``, with ``d_e``
    and ``d_c`` the first-order distances ``|f| / |grad f|`` from the two surfaces
    (exact where they meet at right angles). A fold rounded by a fillet of radius
    ``r`` lies within about ``r`` of that curve, so ``r`` is subtracted: the size
    is ``fold_size`` over the whole fillet.
    """
    coords = _mound_coordinates(geometry)
    f = "(" + " + ".join(f"({c}/{_num(r)})^2" for c, r in coords) + " - 1)"
    grad = "Sqrt(" + " + ".join(f"(2*{c}/{_num(r * r)})^2" for c, r in coords) + " + 1e-30)"
    d_mound = f"({f} / {grad})"
    d_skin = _elliptic_cylinder_distance(geometry, geometry.layer_thickness)
    return _positive_part(f"Sqrt({d_mound}^2 + {d_skin}^2) - {_num(geometry.fold_radius)}")


def add_size_field(model: Any, geometry: BreastGeometry, size: MeshSize) -> int:
    """Install the size laws of :class:`MeshSize` as the background field of ``model``.

    Args:
        model: ``gmsh.model`` holding the breast.
        geometry: its shape parameters.
        size: the size laws.

    Returns:
        The tag of the background field.
    """
    field = model.mesh.field
    laws = [(size.mound_size, mound_distance_expression(geometry))]
    if size.rib_size is not None:
        laws.append((size.rib_size, rib_distance_expression(geometry)))
    if size.fold_size is not None:
        laws.append((size.fold_size, fold_distance_expression(geometry)))
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
