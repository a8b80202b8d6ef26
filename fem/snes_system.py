"""A PETSc SNES and its linear algebra, bound to one problem: the set-up beneath Newton.

The options (Newton settings and the named linear-solver presets ``direct``,
``direct-refactor``, ``direct-lu``, ``iterative``) live in
:func:`fem.options.default_parameters`; :class:`SnesSystem` applies them to a SNES, sets up
what the presets need beyond options (the field split of the mixed space, the rigid-body
near-nullspace, the preconditioning matrix; :mod:`fem.linear_setup`), assembles the residual
and tangent (self-contact's entries added), scales Newton's tolerance to the load, measures
the unit of cost (:meth:`SnesSystem.time_linear_system`) and times the solver's phases.
:class:`fem.solver.NewtonSolver` adds the Newton policy: when to factorise, when to give up,
when to retry.
"""

from __future__ import annotations

import itertools
import logging
import time
from dataclasses import dataclass
from typing import Any

import numpy as np
from dolfinx.fem import petsc as fem_petsc
from petsc4py import PETSc

from fem.linear_setup import (
    homogeneous_dofs,
    linear_path,
    rigid_body_modes,
    single_field,
    split_index_sets,
)
from fem.options import BLR_OPTIONS, SOLVER_KEYS, solver_options
from fem.parameters import STANDARD_GRAVITY
from fem.problem import GravityProblem

log = logging.getLogger(__name__)

#: Every solver's options live in PETSc's database under this prefix and a counter.
SOLVER_PREFIX = "breast_"
_prefix_counter = itertools.count()


@dataclass
class Timings:
    """Accumulated wall-clock seconds (and counts) of one solver's phases."""

    residual: float = 0.0
    jacobian: float = 0.0
    snes: float = 0.0
    residual_evaluations: int = 0
    jacobian_evaluations: int = 0
    preconditioner_builds: int = 0

    @property
    def assembly(self) -> float:
        """Residual plus Jacobian assembly."""
        return self.residual + self.jacobian

    @property
    def linear_solve(self) -> float:
        """SNES time outside assembly: factorisation, solves and vector work."""
        return max(self.snes - self.assembly, 0.0)


class SnesSystem:
    """A SNES and its matrices, vectors and options bound to one problem.

    Args:
        problem: the variational problem.
        options: PETSc options overriding the preset's :func:`fem.options.default_parameters`.
        preset: linear-solver preset (see the module docstring).
    """

    def __init__(
        self,
        problem: GravityProblem,
        options: dict[str, Any] | None = None,
        preset: str = "direct",
    ) -> None:
        self.problem = problem
        self.preset = preset
        self.options = solver_options(preset, options)
        if self.options.get("pc_type") == "fieldsplit" and not problem.mixed:
            self.options = single_field(self.options)
        if self.options.get("pc_type") == "cholesky" and not problem.symmetric:
            # LDLᵀ needs a symmetric tangent (e.g. not the inverse-motion problem's): LU
            self.options = {**self.options, "pc_type": "lu"}
        self.timings = Timings()
        #: Re-factorise when the previous Krylov solve took more iterations (0: always).
        self.refactor_above_its = int(self.options.get("refactor_above_its", 0))
        #: Newton's absolute tolerance over the full gravity load's norm (:meth:`scale_to_load`).
        self.load_atol = float(self.options.get("load_atol", 0.0))
        #: Newton's absolute tolerance, once :meth:`scale_to_load` has set it.
        self._atol: float | None = None
        #: The full load's norm per (geometry, density, gravity): a chain's cases share it.
        self._load_norms: dict[tuple[Any, ...], float] = {}
        #: The state's clamped entries, where every Dirichlet value is zero (None where one is
        #: not). While the state is zero there too, the residual's lifting term is exactly
        #: zero, and skipping it saves assembling the tangent on the clamped cells at every
        #: residual (about a tenth of a chain's time on the default mesh). Newton keeps those
        #: entries zero: the tangent's clamped rows and columns are the identity's.
        self._fixed_dofs = homogeneous_dofs(problem.bcs)
        #: Residual norms of the running Newton solve (its monitor).
        self._norms: list[float] = []
        comm = problem.mesh.comm
        self.A = self._create_matrix(problem.tangent)
        #: The tangent's own nonzeros (self-contact adds to them as pairs appear).
        self._nonzeros = self.A.getInfo()["nz_allocated"]
        blr_above = self.options.get("blr_above_dofs")
        #: The kept factorisation is block low-rank (large problems: :data:`BLR_OPTIONS`).
        self.low_rank = bool(self.refactor_above_its) and blr_above is not None \
            and self.A.getSize()[0] > blr_above
        if self.low_rank:  # the config's own values of these options win
            self.options = {**BLR_OPTIONS, **self.options}
        self.P = self._preconditioning_matrix()
        self.b = fem_petsc.create_vector(problem.residual)
        self.x = problem.w.vector.duplicate()
        self._split, self._u_order = split_index_sets(problem) if self._fieldsplit else (None, None)
        self._near_nullspace = rigid_body_modes(problem, self._u_order) if self._uses_amg \
            else None
        if self._split is not None and self._near_nullspace is not None:
            # fieldsplit hands the modes to the displacement block's AMG
            self._split[0].compose("nearnullspace", self._near_nullspace)

        self.snes = PETSc.SNES().create(comm)
        self.prefix = f"{SOLVER_PREFIX}{next(_prefix_counter)}_"
        self.snes.setOptionsPrefix(self.prefix)
        # The options stay in PETSc's database (under this solver's unique prefix) until
        # destroy(): fieldsplit creates its sub-solvers, and reads their options, only at
        # the first PCSetUp.
        opts = PETSc.Options()
        for key, value in self._petsc_options.items():
            opts[f"{self.prefix}{key}"] = value
        self.snes.setFunction(self._residual, self.b)
        self.snes.setJacobian(self._jacobian, self.A, self.P if self.P is not None else self.A)
        self.snes.setFromOptions()
        self._configure_pc(self.snes.getKSP(), self.A)
        self.snes.setConvergenceHistory(reset=True)
        self.snes.setMonitor(self._monitor)

    # -- set-up ---------------------------------------------------------------------------
    @property
    def _self_contact(self) -> Any:
        """The problem's self-contact assembler (:mod:`fem.self_contact`), if it has one.

        Read at each use: moving the problem's geometry rebuilds it. A problem of another
        kind (the solver takes any with forms, conditions and a state) has none.
        """
        return getattr(self.problem, "self_contact", None)

    def _create_matrix(self, form: Any) -> PETSc.Mat:
        """A matrix of ``form``'s sparsity; with self-contact, one that takes new entries.

        Self-contact couples skin nodes that no cell shares, found only as the body deforms:
        its entries are added where the pairs are, and the pattern grows to hold them.
        """
        A = fem_petsc.create_matrix(form)
        A.setOption(PETSc.Mat.Option.SYMMETRIC, self.problem.symmetric)
        if self._self_contact is not None:
            A.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
        return A

    def _preconditioning_matrix(self) -> PETSc.Mat | None:
        """The matrix the preconditioner is built from, where it is not the tangent A.

        With a field split, the preconditioner's form; with a kept factorisation, the
        factorised copy of the tangent (PCSetUp re-factorises only when this matrix changes,
        so leaving it untouched keeps the factors); else None.
        """
        if self._fieldsplit:
            return self._create_matrix(self.problem.preconditioner)
        if self.refactor_above_its:
            return self._create_matrix(self.problem.tangent)
        return None

    @property
    def linear_path(self) -> str:
        """The linear solver this problem got, in words (recorded in every case's summary)."""
        return linear_path(self.options, self.refactor_above_its, self.low_rank)

    @property
    def _petsc_options(self) -> dict[str, Any]:
        return {k: v for k, v in self.options.items() if k not in SOLVER_KEYS}

    @property
    def _fieldsplit(self) -> bool:
        return self.options.get("pc_type") == "fieldsplit"

    @property
    def _uses_amg(self) -> bool:
        amg = ("gamg", "ml", "hypre")
        return self.options.get("pc_type") in amg or self.options.get("fieldsplit_u_pc_type") in amg

    def renew_linear_solver(self) -> None:
        """Give the SNES a fresh KSP in place of one a PETSc error left in the middle of a solve.

        An error raised inside ``KSPSolve`` (a failed MUMPS factorisation met in the solve
        phase, say) skips PETSc's ``PCPostSolve``, so its pre-solve count stays raised; after two
        such errors every later solve on that KSP fails with "Cannot embed PCPreSolve() more
        than twice", whatever its state, and the loader's cut-backs can never succeed. A new KSP
        with the same options prefix, operators and preconditioner set-up starts clean.
        """
        old = self.snes.getKSP()
        ksp = PETSc.KSP().create(old.getComm())
        ksp.setOptionsPrefix(old.getOptionsPrefix())
        self.snes.setKSP(ksp)
        self.snes.setJacobian(self._jacobian, self.A, self.P if self.P is not None else self.A)
        self._set_from_options()
        self._configure_pc(ksp, self.A)

    def _configure_pc(self, ksp: PETSc.KSP, A: PETSc.Mat) -> None:
        """Tell the preconditioner the field split and the rigid-body modes."""
        pc = ksp.getPC()
        if self._split is not None:
            pc.setFieldSplitIS(("u", self._split[0]), ("p", self._split[1]))
        elif self._near_nullspace is not None:
            A.setNearNullSpace(self._near_nullspace)

    # -- SNES callbacks ---------------------------------------------------------------------
    def _update_state(self, x: PETSc.Vec) -> None:
        x.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
        x.copy(self.problem.w.vector)
        self.problem.w.vector.ghostUpdate(
            addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD
        )

    def _residual(self, snes: PETSc.SNES, x: PETSc.Vec, b: PETSc.Vec) -> None:
        start = time.perf_counter()
        self._update_state(x)
        with b.localForm() as b_local:
            b_local.set(0.0)
        fem_petsc.assemble_vector(b, self.problem.residual)
        if self._fixed_dofs is None or np.any(self.problem.w.x.array[self._fixed_dofs]):
            fem_petsc.apply_lifting(
                b, [self.problem.tangent], bcs=[self.problem.bcs], x0=[x], scale=-1.0
            )
        b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        if self._self_contact is not None:
            with b.localForm() as b_local:
                self.problem.add_self_contact_residual(b_local.array)
        fem_petsc.set_bc(b, self.problem.bcs, x, -1.0)
        self.timings.residual += time.perf_counter() - start
        self.timings.residual_evaluations += 1

    def _assemble_operators(self, A: PETSc.Mat, P: PETSc.Mat | None) -> None:
        """Assemble the tangent into A and, with a field split, the preconditioner into P."""
        A.zeroEntries()
        fem_petsc.assemble_matrix(A, self.problem.tangent, bcs=self.problem.bcs)
        if self._self_contact is not None:
            self.problem.add_self_contact_tangent(A)
        A.assemble()
        # petsc4py hands callbacks fresh wrappers, so P is never A by identity: ask the flag.
        if self._fieldsplit and P is not None:
            P.zeroEntries()
            fem_petsc.assemble_matrix(P, self.problem.preconditioner, bcs=self.problem.bcs)
            if self._self_contact is not None:
                self.problem.add_self_contact_tangent(P)
            P.assemble()

    def _jacobian(self, snes: PETSc.SNES, x: PETSc.Vec, A: PETSc.Mat, P: PETSc.Mat) -> None:
        """Assemble the tangent at every iteration (full Newton; a subclass may keep it)."""
        start = time.perf_counter()
        self._assemble_operators(A, P)
        self.timings.preconditioner_builds += 1
        self.timings.jacobian += time.perf_counter() - start
        self.timings.jacobian_evaluations += 1

    def _monitor(self, snes: PETSc.SNES, its: int, norm: float) -> None:
        if its == 0:
            self._norms = []
        self._norms.append(float(norm))
        # as it happens: a Newton iteration of a large mesh can take minutes
        log.info("Newton iteration %d: residual %.3e", its, norm)

    # -- tolerances -------------------------------------------------------------------------------
    def scale_to_load(self) -> float:
        """Set Newton's absolute tolerance to ``load_atol`` times the full gravity load's norm.

        Call after :meth:`fem.problem.GravityProblem.set_case`. The load is the residual at
        rest under the full body force (the internal forces vanish there), assembled once;
        the state and the load fraction are left as they were. Returns the tolerance.
        """
        problem = self.problem
        # the weight under the case's gravity (under standard gravity where it is zero, so that
        # a case without load still has a tolerance above round-off)
        gravity = np.asarray(problem.gravity, dtype=float)
        if not np.any(gravity):
            gravity = np.array([STANDARD_GRAVITY, 0.0, 0.0])
        key = (problem.geometry_version, float(problem.density), *map(float, gravity))
        load = self._load_norms.get(key)
        if load is None:
            state = problem.w.x.array.copy()
            body_force = problem.body_force.value.copy()
            problem.w.x.array[:] = 0.0
            problem.body_force.value[:] = problem.density * gravity
            counts = (self.timings.residual, self.timings.residual_evaluations)
            b = self.b.duplicate()
            self._residual(self.snes, problem.w.vector, b)
            load = self._load_norms[key] = b.norm()
            b.destroy()
            self.timings.residual, self.timings.residual_evaluations = counts
            problem.w.x.array[:] = state
            problem.body_force.value[:] = body_force
        self._atol = max(float(self.options.get("snes_atol", 0.0)), self.load_atol * load)
        self._set_from_options()
        return self._atol

    def _set_from_options(self) -> None:
        """Read the options database into the SNES, keeping the load-scaled tolerance."""
        self.snes.setFromOptions()
        if self._atol is not None:
            rtol, _, stol, max_it = self.snes.getTolerances()
            self.snes.setTolerances(rtol=rtol, atol=self._atol, stol=stol, max_it=max_it)

    # -- the unit of cost, and the end ----------------------------------------------------------
    def time_linear_system(self) -> float:
        """Seconds for one Jacobian assembly + factorisation + solve at the current state.

        This is the unit of cost of a Newton solve, measured in the same process with
        the same options (a fresh KSP, so the symbolic analysis or AMG set-up is
        included), so that `nonlinear time / this` is a machine-independent ratio.
        With ``direct`` the fresh factorisation makes the Krylov solve converge in
        one or two iterations.
        """
        A = self._create_matrix(self.problem.tangent)
        P = self._create_matrix(self.problem.preconditioner) if self._fieldsplit else None
        ksp = PETSc.KSP().create(self.problem.mesh.comm)
        # Same option prefix as the SNES's own KSP, so every linear-solver option applies.
        ksp.setOptionsPrefix(self.snes.getKSP().getOptionsPrefix())
        x = self.b.duplicate()
        b = self.b.duplicate()
        saved = (
            self.timings.residual,
            self.timings.jacobian,
            self.timings.residual_evaluations,
            self.timings.jacobian_evaluations,
        )
        self._residual(self.snes, self.problem.w.vector, b)
        start = time.perf_counter()
        self._assemble_operators(A, P)
        ksp.setOperators(A, P if P is not None else A)
        ksp.setFromOptions()
        self._configure_pc(ksp, A)
        ksp.solve(b, x)
        elapsed = time.perf_counter() - start
        (
            self.timings.residual,
            self.timings.jacobian,
            self.timings.residual_evaluations,
            self.timings.jacobian_evaluations,
        ) = saved
        ksp.destroy()
        A.destroy()
        if P is not None:
            P.destroy()
        x.destroy()
        b.destroy()
        return elapsed

    def destroy(self) -> None:
        """Free PETSc objects and this solver's entries in the options database."""
        opts = PETSc.Options()
        for key in self._petsc_options:
            opts.delValue(f"{self.prefix}{key}")
        self.snes.destroy()
        for obj in (self.A, self.P, self.b, self.x):
            if obj is not None:
                obj.destroy()
