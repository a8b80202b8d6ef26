"""Whether an equilibrium is stable: the inertia of its tangent.

A converged Newton solve is an equilibrium, not necessarily a stable one: on the far side of
a fold of the load path, or where a mesh lets a crease form, Newton can land on a state that
a small disturbance would leave. The second variation of the potential tells them apart. For
the Taylor–Hood element the tangent is a saddle-point matrix

    K = [[A, Bᵀ], [B, 0]],

whose inertia (Sylvester's law) is that of A restricted to incompressible motions, plus one
negative eigenvalue per pressure unknown (when B has full rank, which the inf-sup stable
element gives). So the state is stable exactly when K has as many negative eigenvalues as
there are pressure unknowns; each one more is an unstable mode of the body. For the P1
penalty element (no pressure field) K must be positive definite. Dirichlet rows (a unit
diagonal) and the chest contact penalty's curvature are positive and change nothing of this
count; the skin's self-contact (whose curvature includes the turning of the master's normal)
is added to the tangent as the solver adds it.

:func:`tangent_inertia` counts them from the MUMPS LDLᵀ factorisation of the assembled tangent
at the problem's current state (one assembly and factorisation, as much as one exact Newton
iteration), with MUMPS's null-pivot detection on so that it reports zero pivots as well: a
state on a fold has one. The matrix and the factorisation are kept with the problem
(:class:`InertiaCounter`), so that judging many states costs no more memory than judging one.
"""

from __future__ import annotations

import itertools
import weakref
from dataclasses import dataclass
from typing import Any

from petsc4py import PETSc

from fem.exceptions import InvalidParameterError


@dataclass(frozen=True, slots=True)
class Inertia:
    """The signs of the tangent's eigenvalues at one state.

    Attributes:
        negative: negative eigenvalues.
        zero: null pivots (MUMPS's detection, relative to the matrix's norm).
        positive: positive eigenvalues.
        pressure_dofs: the pressure unknowns, each of which adds one negative eigenvalue to a
            stable saddle-point tangent.
    """

    negative: int
    zero: int
    positive: int
    pressure_dofs: int

    def __post_init__(self) -> None:
        if min(self.negative, self.zero, self.positive, self.pressure_dofs) < 0:
            raise InvalidParameterError(f"an inertia counts eigenvalues, got {self}")

    @property
    def unstable_modes(self) -> int:
        """Negative eigenvalues beyond the pressure's: the body's unstable modes."""
        return self.negative - self.pressure_dofs

    @property
    def stable(self) -> bool:
        """No unstable mode and no null pivot: a strict local minimum of the potential."""
        return self.unstable_modes == 0 and self.zero == 0

    def as_dict(self) -> dict[str, Any]:
        """The counts and the verdict, for a JSON record."""
        return {"negative": self.negative, "zero": self.zero, "positive": self.positive,
                "pressure_dofs": self.pressure_dofs, "unstable_modes": self.unstable_modes,
                "stable": self.stable}


MUMPS_INERTIA_OPTIONS = {"mat_mumps_icntl_24": 1, "mat_mumps_icntl_13": 1}
"""Null-pivot detection (PETSc's inertia needs it) and, in parallel, the root front on one
process."""
_prefix_counter = itertools.count()


class InertiaCounter:
    """Counts the inertia of one problem's tangent, state after state, on one factorisation.

    It keeps its own tangent matrix and MUMPS LDLᵀ solver for the problem: each count
    re-assembles the tangent in place and re-factorises it numerically (the symbolic analysis
    is kept). A MUMPS solver created and destroyed per count gives its memory back only in
    part (PETSc 3.18: about 0.3 GB a count on the default mesh), so a study that judges many
    states keeps one counter. :func:`tangent_inertia` keeps one per problem.

    Raises:
        InvalidParameterError: if the problem's tangent is not symmetric (the inertia of an
            LDLᵀ factorisation needs it).
    """

    def __init__(self, problem: Any) -> None:
        import dolfinx.fem.petsc as fem_petsc

        if not problem.symmetric:
            raise InvalidParameterError("the inertia needs a symmetric tangent (LDLᵀ)")
        # the form and the conditions, not the problem: the counters of tangent_inertia are
        # dropped with their problems
        self.tangent, self.bcs = problem.tangent, problem.bcs
        #: the skin's self-contact adds to the tangent outside the form (a weak reference)
        self._self_contact = None
        if getattr(problem, "self_contact", None) is not None:
            self._self_contact = weakref.WeakMethod(problem.add_self_contact_tangent)
        self.A = fem_petsc.create_matrix(problem.tangent)
        self.A.setOption(PETSc.Mat.Option.SYMMETRIC, True)
        if self._self_contact is not None:
            self.A.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
        self.ksp = PETSc.KSP().create(problem.mesh.comm)
        self.ksp.setOperators(self.A)
        self.ksp.setType("preonly")
        # MUMPS's settings in PETSc's database under this counter's own prefix, not on the
        # factor alone: where self-contact adds entries to the tangent, PETSc factorises anew
        # in a new factor matrix, which reads them from there
        self._prefix = f"inertia{next(_prefix_counter)}_"
        self.ksp.setOptionsPrefix(self._prefix)
        opts = PETSc.Options()
        for key, value in MUMPS_INERTIA_OPTIONS.items():
            opts[f"{self._prefix}{key}"] = value
        pc = self.ksp.getPC()
        pc.setType("cholesky")
        pc.setFactorSolverType("mumps")
        pc.setFactorSetUpSolverType()
        factor = pc.getFactorMatrix()
        factor.setMumpsIcntl(24, 1)  # null-pivot detection: PETSc's inertia needs it
        factor.setMumpsIcntl(13, 1)  # and, in parallel, the root front on one process
        #: the pressure unknowns, counted over the processes, each shared unknown once; a
        #: pinned one (fem.pressure_modes: a unit diagonal, like a Dirichlet row) is not one
        self.pressure_dofs = 0
        if problem.mixed:
            self.pressure_dofs = int(problem.W.sub(1).collapse()[0].dofmap.index_map.size_global)
            self.pressure_dofs -= problem.pinned_pressure_dofs

    def __call__(self) -> Inertia:
        """The inertia of the tangent at the problem's current state."""
        import dolfinx.fem.petsc as fem_petsc

        self.A.zeroEntries()
        fem_petsc.assemble_matrix(self.A, self.tangent, bcs=self.bcs)
        add_self_contact = self._self_contact() if self._self_contact is not None else None
        if add_self_contact is not None:
            add_self_contact(self.A)
        self.A.assemble()
        pc = self.ksp.getPC()
        pc.setUp()  # the matrix changed: a numeric factorisation (KSPSetUp runs it only once)
        factor = pc.getFactorMatrix()
        negative, zero, positive = (int(n) for n in factor.getInertia())
        return Inertia(negative, zero, positive, self.pressure_dofs)

    def destroy(self) -> None:
        """Free the matrix, the factorisation and the options."""
        self.ksp.destroy()
        self.A.destroy()
        opts = PETSc.Options()
        for key in MUMPS_INERTIA_OPTIONS:
            opts.delValue(f"{self._prefix}{key}")


#: One counter per live problem (dropped with it).
_COUNTERS: weakref.WeakKeyDictionary[Any, InertiaCounter] = weakref.WeakKeyDictionary()


def tangent_inertia(problem: Any) -> Inertia:
    """The inertia of ``problem``'s tangent at its current state (:mod:`fem.stability`).

    The problem's :class:`InertiaCounter` is made at the first call and kept with it.

    Args:
        problem: a :class:`fem.problem.GravityProblem` whose case and load are set (its
            state ``w`` is the one judged).

    Raises:
        InvalidParameterError: if the problem's tangent is not symmetric (the inertia of an
            LDLᵀ factorisation needs it).
    """
    counter = _COUNTERS.get(problem)
    if counter is None:
        counter = _COUNTERS[problem] = InertiaCounter(problem)
    return counter()


__all__ = ["Inertia", "InertiaCounter", "tangent_inertia"]
