"""The linear algebra a Newton solver sets up for a problem beyond PETSc's options.

The field split of the mixed space (its index sets), the rigid-body near-nullspace that AMG
builds its coarse spaces from, the Dirichlet entries that stay zero, the options of a
displacement-only problem, and the linear path in words (:class:`fem.solver.NewtonSolver`).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from petsc4py import PETSc

FACTORISATION_NAMES = {"cholesky": "LDLᵀ", "lu": "LU"}
"""The direct presets' factorisations, in words."""


def rigid_body_modes(problem: Any, u_order: np.ndarray | None) -> PETSc.NullSpace:
    """The six rigid-body modes of ``problem``'s displacement space, orthonormalised.

    ``u_order``: with a field split, the permutation of :func:`split_index_sets` (the modes
    are then given in the displacement block's order).

    AMG builds its coarse spaces from them; without them smoothed aggregation
    sees only translations and converges poorly for elasticity.
    """
    from dolfinx import la

    V = problem.V
    comm = problem.mesh.comm
    n = V.dofmap.index_map.size_local  # owned nodes; 3 dofs each
    x = V.tabulate_dof_coordinates()[:n]
    modes = np.zeros((6, n, 3))
    for i in range(3):
        modes[i, :, i] = 1.0
    for k, (a, b) in enumerate([(0, 1), (1, 2), (2, 0)]):  # rotation in the (a, b) plane
        modes[3 + k, :, a] = -x[:, b]
        modes[3 + k, :, b] = x[:, a]
    modes = modes.reshape(6, -1)
    if u_order is not None:
        # the displacement block of the mixed space, in its index set's (sorted) order
        modes = modes[:, u_order]
    # Fresh PETSc vectors that own their memory (a dolfinx Function's vector would
    # dangle once the Function is collected).
    vectors = []
    for mode in modes:
        v = PETSc.Vec().createMPI((3 * n, PETSc.DECIDE), comm=comm)
        v.array[:] = mode
        vectors.append(v)
    la.orthonormalize(vectors)
    return PETSc.NullSpace().create(vectors=vectors, comm=problem.mesh.comm)

def split_index_sets(problem: Any) -> tuple[tuple[PETSc.IS, PETSc.IS], np.ndarray]:
    """Global indices of the owned displacement and pressure dofs of ``problem``'s mixed space.

    Returns:
        The two (sorted, as fieldsplit requires) index sets, and the permutation
        that sorts the collapsed displacement space's owned dofs into the first.
    """
    W = problem.W
    comm = problem.mesh.comm
    owned = W.dofmap.index_map.size_local * W.dofmap.index_map_bs
    offset = W.dofmap.index_map.local_range[0] * W.dofmap.index_map_bs
    index_sets, orders = [], []
    for i in (0, 1):
        Vi, dofs = W.sub(i).collapse()
        n = Vi.dofmap.index_map.size_local * Vi.dofmap.index_map_bs
        dofs = np.asarray(dofs[:n], dtype=np.int64)
        if np.any(dofs >= owned):
            raise RuntimeError("collapsed sub-space owns dofs its parent does not")
        order = np.argsort(dofs, kind="stable")
        iset = PETSc.IS().createGeneral((dofs[order] + offset).astype(PETSc.IntType), comm=comm)
        index_sets.append(iset)
        orders.append(order)
    return (index_sets[0], index_sets[1]), orders[0]


def homogeneous_dofs(bcs: list[Any]) -> np.ndarray | None:
    """The local entries the Dirichlet conditions fix, if every value they fix is zero."""
    if any(np.any(bc.g.x.array) for bc in bcs):
        return None
    dofs = [bc.dof_indices()[0] for bc in bcs]
    return np.unique(np.concatenate(dofs)) if dofs else np.zeros(0, dtype=np.int32)


def single_field(options: dict[str, Any]) -> dict[str, Any]:
    """Turn fieldsplit options into options for a displacement-only problem.

    The P1-penalty element has no pressure block: its tangent is preconditioned
    directly with the displacement block's solver.
    """
    out = {k: v for k, v in options.items() if not k.startswith(("pc_fieldsplit_", "fieldsplit_"))}
    prefix = "fieldsplit_u_"
    out.update(
        {
            k[len(prefix) :]: v
            for k, v in options.items()
            if k.startswith(prefix) and k != prefix + "ksp_type"
        }
    )
    return out


def linear_path(options: dict[str, Any], refactor_above_its: int, low_rank: bool) -> str:
    """The linear solver of these options, in words (recorded in every case's summary)."""
    pc = options.get("pc_type")
    if pc == "fieldsplit":
        return "FGMRES, fieldsplit Schur complement with AMG"
    if pc in FACTORISATION_NAMES:
        name = f"MUMPS {FACTORISATION_NAMES[pc]}"
        if not refactor_above_its:
            return f"{name} at every Newton iteration"
        low = f", block low-rank (ε {options['mat_mumps_cntl_7']:g})" if low_rank else ""
        return f"GMRES on a kept {name}{low}"
    return f"{options.get('ksp_type')} with {pc}"
