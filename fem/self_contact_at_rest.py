"""The skin's self-contact pairs in a mesh's reference configuration, before any solve.

Where an imported skin faces itself within reach at rest (a sharp chest-wall rim, a thin
region, a crease the surface was made with), :mod:`fem.self_contact` leaves those pairs out
or measures them from their rest gap (``fe.self_contact.at_rest``). This module finds them on
a mesh file, as the workflow's ``self_contact_at_rest`` job does for every mesh it solves on,
so that a user sees them before the first case.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from fem.parameters import Discretisation
from fem.rest_pairs import RestPairs
from fem.self_contact import SelfContact, SelfContactAssembler
from fem.skin_surface import SkinSurface

__all__ = ["MeshRestPairs", "rest_pairs", "rest_pairs_of_mesh"]


@dataclass(frozen=True, slots=True)
class MeshRestPairs:
    """A mesh's skin pairs at rest (``results/mesh/self_contact_at_rest.json``).

    Attributes:
        self_contact: whether the config solves with self-contact; without it the pairs are
            those its defaults would meet.
        degree: the displacement's degree, through whose nodes the skin is triangulated.
        found: the pairs, as found and as the treatment leaves them.
    """

    self_contact: bool
    degree: int
    found: RestPairs

    def to_json(self) -> dict[str, Any]:
        """JSON-friendly fields, the pairs' own at the top level."""
        return {"self_contact": self.self_contact, "degree": self.degree,
                **self.found.to_json()}

    @classmethod
    def from_json(cls, values: dict[str, Any]) -> MeshRestPairs:
        """Inverse of :meth:`to_json`."""
        values = dict(values)
        return cls(bool(values.pop("self_contact")), int(values.pop("degree")),
                   RestPairs.from_json(values))

    def write(self, path: str | Path) -> None:
        """Write the record to ``path`` (renamed into place)."""
        target = Path(path)
        target.parent.mkdir(parents=True, exist_ok=True)
        tmp = target.with_name(f".{target.name}.{os.getpid()}.tmp")
        tmp.write_text(json.dumps(self.to_json(), indent=2))
        os.replace(tmp, target)

    @classmethod
    def read(cls, path: str | Path) -> MeshRestPairs:
        """The record written by :meth:`write`."""
        return cls.from_json(json.loads(Path(path).read_text()))


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
                       discretisation: Discretisation = Discretisation()) -> MeshRestPairs:
    """:func:`rest_pairs` of a mesh file, its skin through the discretisation's nodes.

    With self-contact off (``settings`` None) the defaults' pairs are recorded, with
    ``self_contact`` false, so that a user who turns it on knows what it would meet.
    """
    from meshes.io import read_mesh

    # the displacement's degree (fem.problem.GravityProblem: P1 for the penalty element)
    degree = discretisation.degree if discretisation.element == "taylor-hood" else 1
    mesh, _, facet_tags = read_mesh(path)
    found = rest_pairs(mesh, facet_tags, settings or SelfContact(), degree)
    return MeshRestPairs(settings is not None, degree, found)
