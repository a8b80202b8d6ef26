"""Boundary and cell tags, defined once by name for the whole project.

Every stage (meshing, the FE solver, the dataset, the surrogate) refers to
surfaces through :class:`Boundary` and to the tissues of the volume through
:class:`Tissue`; the integer values are what is stored as gmsh physical groups
and dolfinx facet and cell tags.
"""

from __future__ import annotations

from enum import IntEnum
from typing import Any


class _Named:
    """Tags looked up by their lower-case names (:class:`Boundary`, :class:`Tissue`)."""

    name: str

    @property
    def label(self) -> str:
        """Lower-case name used in configs, files and gmsh physical groups."""
        return self.name.lower()

    @classmethod
    def from_label(cls, label: str) -> Any:
        """Look a tag up by its lower-case name.

        Raises:
            ValueError: if ``label`` names none.
        """
        try:
            return cls[str(label).upper()]  # type: ignore[index]
        except KeyError:
            names = ", ".join(t.label for t in cls)  # type: ignore[attr-defined]
            kind = cls.__name__.lower()  # what a tag names: boundary, tissue
            raise ValueError(f"unknown {kind} {label!r}; expected one of: {names}") from None


class Boundary(_Named, IntEnum):
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


class Tissue(_Named, IntEnum):
    """The breast's tissues (cell tag values); a homogeneous breast is all fat."""

    FAT = 1
    """Adipose tissue: the reference whose C1 the sweep varies."""
    GLAND = 2
    """Fibroglandular tissue."""
    SKIN = 3
    """The skin, where a mesh resolves it as cells."""
    TUMOUR = 4
    """A lesion."""


TISSUE = int(Tissue.FAT)
"""Cell tag of a homogeneous breast's single tissue volume (all fat)."""

MESH_NAME = "mesh"
CELL_TAGS_NAME = "cell_tags"
FACET_TAGS_NAME = "facet_tags"
