"""Pressure values that no equation of the free displacements sees, pinned.

In the mixed (Taylor–Hood) problem a pressure dof enters the equations through the cells
around its vertex. Where every one of those cells has all its displacement dofs fixed (a cell
whose four vertices lie on the fixed chest wall, as an image mesher makes at a sharp rim where
the chest wall meets the skin), the incompressibility rows of that dof read ``0 = 0`` and its
column meets only fixed rows: the tangent is singular (MUMPS INFOG(1) = -10) and no Newton
step is taken. The displacement does not depend on that pressure at all, so fixing it (to
zero) changes no displacement and makes the system regular; the pressure there is left
undetermined by the discrete problem anyway. :func:`pinned_pressure_bcs` finds such dofs and
returns one Dirichlet condition for them, or none on a mesh without them.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from typing import Any

import numpy as np
from dolfinx import fem

log = logging.getLogger(__name__)


def undetermined_pressure_dofs(W: fem.FunctionSpace, bcs: Sequence[Any]) -> np.ndarray:
    """The pressure dofs (``W``'s numbering) whose every cell has only fixed displacements.

    ``W`` is the mixed space (displacement, pressure); ``bcs`` the Dirichlet conditions on
    the displacement. Owned and ghost dofs of this process's cells are both considered.
    """
    cells = W.mesh.topology.index_map(W.mesh.topology.dim)
    num_cells = cells.size_local + cells.num_ghosts
    # the sub-spaces' cell dofs in W's numbering, one row a cell (block size 1 in W)
    u_cells = W.sub(0).dofmap.list.array.reshape(num_cells, -1)
    p_cells = W.sub(1).dofmap.list.array.reshape(num_cells, -1)
    size = W.dofmap.index_map.size_local + W.dofmap.index_map.num_ghosts
    fixed = np.zeros(size * W.dofmap.index_map_bs, dtype=bool)
    for bc in bcs:
        fixed[bc.dof_indices()[0]] = True
    free_cell = ~np.all(fixed[u_cells], axis=1)
    seen = np.unique(p_cells[free_cell])
    return np.setdiff1d(np.unique(p_cells), seen).astype(np.int32)


def pinned_pressure_bcs(W: fem.FunctionSpace, bcs: Sequence[Any]) -> list[Any]:
    """A Dirichlet condition fixing the undetermined pressure dofs to zero ([] if none)."""
    dofs = undetermined_pressure_dofs(W, bcs)
    if not len(dofs):
        return []
    log.info("%d pressure value(s) meet no free displacement (cells with every node fixed): "
             "pinned to zero", len(dofs))
    # as the displacement's conditions are given (a zero Function on the collapsed space), so
    # that every reader of ``bc.g`` sees one kind of condition
    pressure, collapsed_to_W = W.sub(1).collapse()
    position = np.full(max(collapsed_to_W) + 1, -1, dtype=np.int32)
    position[np.asarray(collapsed_to_W)] = np.arange(len(collapsed_to_W), dtype=np.int32)
    pairs = [dofs, position[dofs]]
    return [fem.dirichletbc(fem.Function(pressure), pairs, W.sub(1))]


__all__ = ["pinned_pressure_bcs", "undetermined_pressure_dofs"]
