"""Typed errors of the geometry and meshing stage.

Every error names the problem in words a user can act on (which file, which
check, how many facets or elements, what to change in the config). Callers that
only care that *some* input was bad catch :class:`MeshInputError`; tests and
tools that react to one kind catch the subclass.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any


class GeometryError(ValueError):
    """A geometry or meshing parameter is out of range or the parameters are inconsistent."""


def reject_unknown(values: Mapping[str, Any], known: set[str], what: str) -> None:
    """Raise :class:`GeometryError` naming the keys of ``values`` not in ``known``.

    ``what`` names them in the message, e.g. ``mesh.size parameter(s)``.
    """
    unknown = sorted(set(values) - known)
    if unknown:
        raise GeometryError(f"unknown {what}: {', '.join(unknown)}")


class MeshInputError(ValueError):
    """A mesh or surface file is missing, unreadable or lacks what the solver needs."""


class UnitsError(MeshInputError):
    """The model's size is implausible for a breast in the declared units (e.g. mm read as m)."""


class SurfaceNotClosedError(MeshInputError):
    """A surface has holes (edges with one triangle) or non-manifold edges (three or more)."""


class SelfIntersectionError(MeshInputError):
    """Triangles of a surface cross each other."""


class InvalidElementsError(MeshInputError):
    """Elements are degenerate (zero volume or area) or inverted (opposite orientation)."""


class NoRibFacetsError(MeshInputError):
    """The rule that selects the rib (fixed chest-wall) surface matched no boundary facet."""


class ImageHeaderError(MeshInputError):
    """A label volume's header cannot place its voxels, or its data is shorter than it says.

    A voxel size that is not finite and positive, direction cosines that are not orthonormal,
    a NIfTI ``pixdim`` that disagrees with its sform, a field of view too small for a breast,
    or a truncated file: each is named by its header field.
    """


class SurfaceRuleError(MeshInputError):
    """A boundary rule is inconsistent with the input (unknown group, facets matched twice)."""


class SeveralBodiesError(MeshInputError):
    """A surface or volume mesh holds more than one body (apart, nested or crossing)."""
