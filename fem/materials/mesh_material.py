"""The material laws bound to one mesh: each cell's solid, the skin's membrane.

:class:`MeshMaterial` is what :class:`fem.problem.GravityProblem` takes its material terms from:
the solid's strain energy per unit reference volume (:func:`fem.materials.solid.strain_energy`
with each cell's C1: the case's, the fat's, times the cell's tissue ratio, one DG0 field:
:func:`stiffness_field`) and the skin membrane's per unit reference area of the ``skin``
boundary (:class:`fem.materials.membrane.Membrane`), with the constants a case sets. This
module imports dolfinx, so the package's ``__init__`` leaves it out: the config's tissue map
(:mod:`fem.materials.tissues`) is read in processes that never solve.
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING, Any

import numpy as np
import ufl
from dolfinx import fem
from mpi4py import MPI
from petsc4py import PETSc

from fem.materials.membrane import Membrane
from fem.materials.solid import DEFAULT_LAW, strain_energy
from fem.materials.tissues import SkinLayer, Tissues
from meshes.tags import Tissue

if TYPE_CHECKING:
    from fem.parameters import Discretisation

log = logging.getLogger(__name__)


def has_skin_cells(mesh: Any, cell_tags: Any) -> bool:
    """Whether any cell is tagged skin (on any process)."""
    local = cell_tags is not None and bool(np.any(np.asarray(cell_tags.values)
                                                  == int(Tissue.SKIN)))
    return bool(mesh.comm.allreduce(local, op=MPI.LOR))


def stiffness_field(mesh: Any, cell_tags: Any, tissues: Tissues) -> fem.Function | None:
    """The cells' stiffness ratios as a DG0 field; None where all are 1 (one tissue, fat)."""
    if cell_tags is None:
        return None
    n_local = mesh.topology.index_map(mesh.topology.dim).size_local
    tags = np.full(n_local, int(Tissue.FAT), dtype=np.int64)
    indices = np.asarray(cell_tags.indices)
    owned = indices < n_local
    tags[indices[owned]] = np.asarray(cell_tags.values)[owned]
    ratios = tissues.cell_ratios(tags)
    heterogeneous = mesh.comm.allreduce(bool(np.any(ratios != 1.0)), op=MPI.LOR)
    if not heterogeneous:
        return None
    V = fem.FunctionSpace(mesh, ("DG", 0))
    field = fem.Function(V, name="stiffness_ratio")
    dofs = np.asarray(V.dofmap.list.array).reshape(-1)[:n_local]  # one per cell
    field.x.array[dofs] = ratios
    field.x.scatter_forward()
    return field


class MeshMaterial:
    """The material of one mesh's body: the solid law in each cell and the skin membrane.

    Args:
        mesh: dolfinx mesh.
        discretisation: the element, which sets the volumetric term (and ``isochoric``).
        cell_tags: cell tags with :class:`meshes.tags.Tissue` values (None: all fat).
        tissues: each tissue's stiffness over the fat's (None: the defaults).
        skin: the skin as a membrane on the skin boundary (None: none); left out, with a
            note in the log, where the cell tags already hold skin cells.
        law: the solid law's name (:data:`fem.materials.solid.LAWS`).

    Attributes:
        C1: the case's C1 (Pa), the fat's: a constant, so that one compiled form serves a
            whole sweep; the contact penalties take it (:mod:`fem.materials.tissues`).
        stiffness_ratio: each cell's stiffness over the fat's (a DG0 field), or None where
            every cell has the ratio 1: the homogeneous forms are kept.
        local_C1: each cell's C1, what the strain energy and the pressure preconditioner take.
        skin: the skin membrane in force (None: none, or the mesh's skin cells carry it).
    """

    def __init__(
        self,
        mesh: Any,
        discretisation: Discretisation,
        cell_tags: Any = None,
        tissues: Tissues | None = None,
        skin: SkinLayer | None = None,
        law: str = DEFAULT_LAW,
    ) -> None:
        # The constants are made in the order the forms have always numbered them (C1, the
        # skin's, then the problem's load, then κ: :attr:`kappa`), so that their signatures,
        # and dolfinx's cache of compiled forms, stay the same.
        scalar = PETSc.ScalarType
        self.mesh = mesh
        self.discretisation = discretisation
        self.law = law
        self.C1 = fem.Constant(mesh, scalar(1.0))
        tissues = tissues or Tissues()
        self.stiffness_ratio = stiffness_field(mesh, cell_tags, tissues)
        self.skin = None if skin is None or has_skin_cells(mesh, cell_tags) else skin
        if skin is not None and self.skin is None:
            log.info("the mesh's cells carry the skin: no skin membrane is added")
        self._skin_ratio = fem.Constant(mesh, scalar(tissues.ratio(Tissue.SKIN) if self.skin
                                                     else 1.0))
        self._skin_thickness = fem.Constant(mesh, scalar(self.skin.thickness if self.skin
                                                         else 0.0))
        self.local_C1 = self.C1 if self.stiffness_ratio is None \
            else self.C1 * self.stiffness_ratio
        self._kappa: fem.Constant | None = None

    @property
    def kappa(self) -> fem.Constant:
        """κ / C1 of the P1 penalty (``discretisation.bulk_ratio``), made on first use."""
        if self._kappa is None:
            self._kappa = fem.Constant(self.mesh, PETSc.ScalarType(self.discretisation.bulk_ratio))
        return self._kappa

    def strain_energy(self, F: ufl.core.expr.Expr,
                      p: ufl.core.expr.Expr | None) -> ufl.core.expr.Expr:
        """The solid's energy per unit reference volume, each cell's C1 (``p``: the pressure)."""
        return strain_energy(F, p, self.local_C1, self.discretisation, self.kappa, self.law)

    def skin_energy(self, F: ufl.core.expr.Expr,
                    N: ufl.core.expr.Expr) -> ufl.core.expr.Expr | None:
        """The skin membrane's energy per unit reference area (``N``: the reference normal).

        None without a membrane; integrate it over the ``skin`` boundary.
        """
        if self.skin is None:
            return None
        membrane = Membrane(self._skin_ratio * self.C1, self._skin_thickness, self.skin.wrinkles)
        return membrane.strain_energy(F, N)
