"""The mesh's quality report, ``results/mesh/quality.json``, as the studies read it.

The report is written by the mesh layer (:func:`meshes.build.write_parametric_mesh`,
:func:`meshes.importing.write_imported_mesh`), which cannot import the studies; this is the
reader's declaration of the keys it relies on. The record is open: the keys that differ
between a parametric and an imported mesh (CAD values, the import's input) are kept in
``extras``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from studies.results import Result


@dataclass(frozen=True, slots=True)
class MeshQuality(Result):
    """Size, volume and quality of the tetrahedral mesh (lengths in m, angles in degrees)."""

    cells: int
    vertices: int
    dofs: dict[str, int]
    volume_ml: float
    inverted_cells: int
    degenerate_cells: int
    area_m2: dict[str, float]
    min_dihedral_deg: float
    max_dihedral_deg: float
    min_minSICN: float
    mean_minSICN: float
    source: str
    anatomy: dict[str, Any]
    mesh_wall_s: float
    extras: dict[str, Any] = field(default_factory=dict)
