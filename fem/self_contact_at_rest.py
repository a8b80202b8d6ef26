"""The skin's self-contact pairs in a mesh's reference configuration, before any solve.

Where an imported skin faces itself within reach at rest (a sharp chest-wall rim, a thin
region, a crease the surface was made with), :mod:`fem.self_contact` leaves those pairs out
or measures them from their rest gap (``fe.self_contact.at_rest``). This module finds them on
a mesh file, as the workflow's ``self_contact_at_rest`` job does for every mesh it solves on,
so that a user sees them before the first case.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from fem.self_contact import RestPairs, SelfContact, SelfContactAssembler
from fem.skin_surface import SkinSurface

__all__ = ["rest_pairs", "rest_pairs_of_mesh"]


def rest_pairs(mesh: Any, facet_tags: Any, settings: SelfContact, degree: int = 2) -> RestPairs:
    """The pairs at rest of the skin of ``mesh`` (a dolfinx mesh with its facet tags).

    Args:
        mesh: the dolfinx mesh, serial.
        facet_tags: its boundaries' tags (:class:`meshes.tags.Boundary`).
        settings: the self-contact settings (their ``at_rest`` the treatment).
        degree: the displacement's degree, whose nodes the skin's triangles run through.
    """
    from dolfinx import fem

    from meshes.io import boundary_facets
    from meshes.tags import Boundary

    V = fem.VectorFunctionSpace(mesh, ("Lagrange", degree))
    facets = boundary_facets(facet_tags, [Boundary.SKIN])
    surface = SkinSurface.from_problem(V, False, mesh, facets)
    return SelfContactAssembler(settings, surface).rest


def rest_pairs_of_mesh(path: str | Path, settings: SelfContact | None,
                       degree: int = 2) -> dict[str, Any]:
    """:func:`rest_pairs` of a mesh file, as a JSON-friendly record.

    With self-contact off (``settings`` None) the defaults' pairs are recorded, under
    ``"self_contact": false``, so that a user who turns it on knows what it would meet.
    """
    from meshes.io import read_mesh

    mesh, _, facet_tags = read_mesh(path)
    found = rest_pairs(mesh, facet_tags, settings or SelfContact(), degree)
    return {"self_contact": settings is not None, "degree": degree, **found.to_json()}
