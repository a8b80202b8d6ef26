"""Boundary and cell tags, defined once by name for the whole project.

Every stage (meshing, the FE solver, the dataset, the surrogate) refers to
surfaces through :class:`Boundary`; the integer values are what is stored as
gmsh physical groups and dolfinx facet tags.
"""

from __future__ import annotations

from enum import IntEnum


class Boundary(IntEnum):
    """Named boundary surfaces of the breast domain (facet tag values)."""

    RIB = 1
    """Posterior surface on the rib cage / chest wall (fixed in the paper)."""
    SKIN = 2
    """Anterior skin surface, including the breast mound."""
    STERNAL = 3
    """Medial cut at the sternum (mid-sagittal plane)."""
    CRANIAL = 4
    """Superior cut towards the clavicle."""
    CAUDAL = 5
    """Inferior cut below the inframammary fold."""
    AXILLA = 6
    """Lateral cut towards the axilla."""

    @property
    def label(self) -> str:
        """Lower-case name used in configs, files and gmsh physical groups."""
        return self.name.lower()

    @classmethod
    def from_label(cls, label: str) -> Boundary:
        """Look a boundary up by its lower-case name.

        Raises:
            ValueError: if ``label`` names no boundary.
        """
        try:
            return cls[label.upper()]
        except KeyError:
            names = ", ".join(b.label for b in cls)
            raise ValueError(f"unknown boundary {label!r}; expected one of: {names}") from None


TISSUE = 1
"""Cell tag of the (single, homogeneous) breast tissue volume."""

MESH_NAME = "mesh"
CELL_TAGS_NAME = "cell_tags"
FACET_TAGS_NAME = "facet_tags"
