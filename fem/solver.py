"""PETSc SNES Newton solver for :class:`fem.problem.GravityProblem`.

The options (Newton settings and the named linear-solver presets ``direct``,
``direct-refactor``, ``direct-lu``, ``iterative``) live in
:func:`fem.options.default_parameters`; this module applies them to a SNES, sets
up what the presets need beyond options (the field split of the mixed space, the
rigid-body near-nullspace, the preconditioning matrix, the kept factorisation of
``direct``) and times the solver's phases.
"""

from __future__ import annotations

import itertools
import logging
import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from dolfinx.fem import petsc as fem_petsc
from petsc4py import PETSc

from fem.exceptions import InvalidParameterError
from fem.options import (
    BLR_OPTIONS,
    LINE_SEARCHES,
    SOLVER_KEYS,
    SOLVER_PRESETS,
    default_parameters,
    solver_options,
)
from fem.parameters import STANDARD_GRAVITY, check_stall_window
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


@dataclass
class SolveResult:
    """Outcome of one SNES solve.

    Attributes:
        converged: SNES reported convergence.
        reason: PETSc's converged/diverged reason, lower case; ``diverged_stalled`` for a
            solve given up by the stall test (``stall_window``).
        iterations: Newton iterations.
        residuals: residual norm before the first and after every iteration.
        linear_iterations: Krylov iterations summed over the Newton iterations
            (1 per iteration for the direct solvers).
        linear_reason: the last linear solve's reason (e.g. a failed factorisation).
        exact_retry: the inexact solve failed and the increment was solved again with a
            fresh factorisation at every iteration (the figures add both attempts).
    """

    converged: bool
    reason: str
    iterations: int
    residuals: list[float] = field(default_factory=list)
    linear_iterations: int = 0
    linear_reason: str = ""
    exact_retry: bool = False


class NewtonSolver:
    """A SNES solver bound to one problem.

    Args:
        problem: the variational problem.
        options: PETSc options overriding the preset's :func:`default_parameters`.
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
            self.options = _single_field(self.options)
        if self.options.get("pc_type") == "cholesky" and not problem.symmetric:
            # LDLᵀ needs a symmetric tangent (e.g. not the inverse-motion problem's): LU
            self.options = {**self.options, "pc_type": "lu"}
        self.timings = Timings()
        #: Re-factorise when the previous Krylov solve took more iterations (0: always).
        self.refactor_above_its = int(self.options.get("refactor_above_its", 0))
        #: Re-factorise when the last Newton iteration left more of the residual (1: never).
        self.refactor_above_ratio = float(self.options.get("refactor_above_ratio", 1.0))
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
        self._fixed_dofs = _homogeneous_dofs(problem.bcs)
        #: Factorise at every iteration (the retry of a failed inexact increment).
        self._exact = False
        #: Keep the last factorisation at the first iteration too (a solve from a nearby guess).
        self._reuse_first = False
        #: From a nearby guess, keep the last tangent as well while the iteration contracts by
        #: at most this ratio (0: never).
        self.lag_below_ratio = float(self.options.get("lag_below_ratio", 0.0))
        #: The running solve keeps the last tangent and factorisation (a chord iteration).
        self._lagging = False
        #: Residual norms of the running Newton solve (its monitor).
        self._norms: list[float] = []
        #: The running solve's stall window (:func:`_stalled`; 0: none), a per-solve setting.
        self._window = 0
        #: The running solve was given up as stalled.
        self._stall = False
        #: The first residual of the running solve (PETSc's relative test is against it).
        self._first_norm = 0.0
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
        self._split, self._u_order = self._split_index_sets() if self._fieldsplit else (None, None)
        self._near_nullspace = self._rigid_body_modes() if self._uses_amg else None
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
        pc = self.options.get("pc_type")
        if pc == "fieldsplit":
            return "FGMRES, fieldsplit Schur complement with AMG"
        if pc in _FACTORISATION_NAMES:
            name = f"MUMPS {_FACTORISATION_NAMES[pc]}"
            if not self.refactor_above_its:
                return f"{name} at every Newton iteration"
            low_rank = f", block low-rank (ε {self.options['mat_mumps_cntl_7']:g})" \
                if self.low_rank else ""
            return f"GMRES on a kept {name}{low_rank}"
        return f"{self.options.get('ksp_type')} with {pc}"

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

    def _rigid_body_modes(self) -> PETSc.NullSpace:
        """The six rigid-body modes of the displacement space, orthonormalised.

        AMG builds its coarse spaces from them; without them smoothed aggregation
        sees only translations and converges poorly for elasticity.
        """
        from dolfinx import la

        V = self.problem.V
        comm = self.problem.mesh.comm
        n = V.dofmap.index_map.size_local  # owned nodes; 3 dofs each
        x = V.tabulate_dof_coordinates()[:n]
        modes = np.zeros((6, n, 3))
        for i in range(3):
            modes[i, :, i] = 1.0
        for k, (a, b) in enumerate([(0, 1), (1, 2), (2, 0)]):  # rotation in the (a, b) plane
            modes[3 + k, :, a] = -x[:, b]
            modes[3 + k, :, b] = x[:, a]
        modes = modes.reshape(6, -1)
        if self._u_order is not None:
            # the displacement block of the mixed space, in its index set's (sorted) order
            modes = modes[:, self._u_order]
        # Fresh PETSc vectors that own their memory (a dolfinx Function's vector would
        # dangle once the Function is collected).
        vectors = []
        for mode in modes:
            v = PETSc.Vec().createMPI((3 * n, PETSc.DECIDE), comm=comm)
            v.array[:] = mode
            vectors.append(v)
        la.orthonormalize(vectors)
        return PETSc.NullSpace().create(vectors=vectors, comm=self.problem.mesh.comm)

    def _split_index_sets(self) -> tuple[tuple[PETSc.IS, PETSc.IS], np.ndarray]:
        """Global indices of the owned displacement and pressure dofs of the mixed space.

        Returns:
            The two (sorted, as fieldsplit requires) index sets, and the permutation
            that sorts the collapsed displacement space's owned dofs into the first.
        """
        W = self.problem.W
        comm = self.problem.mesh.comm
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
        refresh = False
        if self._lagging and snes.getIterationNumber() > 0:
            if not self._chord_slow(snes):
                return  # this solve's first tangent and the kept factors serve again
            self._lagging = False  # too slow: Newton from here, on a fresh factorisation
            refresh = True
        start = time.perf_counter()
        self._assemble_operators(A, P)
        if not self.refactor_above_its:
            self.timings.preconditioner_builds += 1
        elif refresh or self._factorisation_stale(snes):
            self._keep_for_factorisation(A)
            self.timings.preconditioner_builds += 1
        self.timings.jacobian += time.perf_counter() - start
        self.timings.jacobian_evaluations += 1

    def _monitor(self, snes: PETSc.SNES, its: int, norm: float) -> None:
        if its == 0:
            self._norms = []
        self._norms.append(float(norm))

    def _converged(self, snes: PETSc.SNES, its: int, norms: tuple[float, float, float]) -> int:
        """PETSc 3.18's default convergence test, plus the stall test.

        Installed only for a solve with a stall window, so that every other solve keeps PETSc's
        own test. The tests and their order are ``SNESConvergedDefault``'s; the iteration limit
        stays with the Newton loop. The monitor has already recorded this iteration's norm.
        """
        xnorm, step_norm, fnorm = norms
        reasons = PETSc.SNES.ConvergedReason
        rtol, atol, stol, _ = snes.getTolerances()
        if its == 0:
            self._first_norm = fnorm
        if not math.isfinite(fnorm):
            return reasons.DIVERGED_FNORM_NAN
        if fnorm < atol:
            return reasons.CONVERGED_FNORM_ABS
        max_funcs = snes.getMaxFunctionEvaluations()
        if max_funcs >= 0 and snes.getFunctionEvaluations() >= max_funcs:
            return reasons.DIVERGED_FUNCTION_COUNT
        if its:
            divtol = float(self.options.get("snes_divergence_tolerance", 1e4))
            if fnorm <= rtol * self._first_norm:
                return reasons.CONVERGED_FNORM_RELATIVE
            if step_norm < stol * xnorm:
                return reasons.CONVERGED_SNORM_RELATIVE
            if divtol > 0 and fnorm > divtol * self._first_norm:
                return reasons.DIVERGED_DTOL
            if _stalled(self._norms, self._window):
                self._stall = True
                return reasons.DIVERGED_LOCAL_MIN
        return reasons.ITERATING

    def _factorisation_stale(self, snes: PETSc.SNES) -> bool:
        """Whether the next Krylov solve needs a fresh factorisation.

        At a load step's first iteration (unless the solve reuses the last factorisation and
        there is one), after a slow or failed Krylov solve, after a Newton iteration that
        stalled close to the solution, and always in the exact retry.
        """
        ksp = snes.getKSP()
        first = snes.getIterationNumber() == 0
        return (
            self._exact
            or (first and not self._reuse_first)
            or ksp.getIterationNumber() > self.refactor_above_its
            or ksp.getConvergedReason() < 0
            or _stalled_near_solution(self._norms, self.refactor_above_ratio)
        )

    def _chord_slow(self, snes: PETSc.SNES) -> bool:
        """Whether the chord iteration must end.

        After a slow or failed Krylov solve, or an iteration that left more than
        ``lag_below_ratio`` of the residual.
        """
        ksp = snes.getKSP()
        norms = self._norms
        return (
            ksp.getIterationNumber() > self.refactor_above_its
            or ksp.getConvergedReason() < 0
            or (len(norms) >= 2 and norms[-1] > self.lag_below_ratio * norms[-2])
        )

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

    def _keep_for_factorisation(self, A: PETSc.Mat) -> None:
        """Copy the fresh tangent into P, so that the next PCSetUp factorises it."""
        if not self.P.isAssembled():  # the first time: MatCopy needs an assembled target
            fem_petsc.assemble_matrix(self.P, self.problem.tangent, bcs=self.problem.bcs)
            self.P.assemble()
            if self._self_contact is None:
                return  # it is A already
        # self-contact may have grown A's pattern since the last copy
        same = self._self_contact is None \
            or A.getInfo()["nz_allocated"] == self.P.getInfo()["nz_allocated"]
        structure = PETSc.Mat.Structure.SAME_NONZERO_PATTERN if same \
            else PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN
        A.copy(self.P, structure)

    # -- driver ---------------------------------------------------------------------------------
    def solve(
        self, newton: dict[str, Any] | None = None, reuse_factorisation: bool = False
    ) -> SolveResult:
        """Run Newton from the problem's current state; on success the state holds the solution.

        Args:
            newton: for this solve only, another line search (``snes_linesearch_type``)
                and iteration limit (``snes_max_it``), e.g.
                :data:`fem.options.RESCUE_OPTIONS`, the solver's own restored after; and a
                stall window (``stall_window``: give the solve up once that many iterations
                sit on a plateau of the residual, :func:`_stalled`).
            reuse_factorisation: with a kept factorisation, precondition the first iteration
                with the last one instead of factorising afresh: for a guess near the last
                solve (a neighbouring case), whose tangent is near the kept one. A slow
                Krylov solve re-factorises as always, so this changes the cost, not the
                answer's stopping test.

        Raises:
            InvalidParameterError: if ``newton`` has another key or an unknown line search.
        """
        kept = self.P is not None and self.P.isAssembled()
        self._reuse_first = reuse_factorisation and kept
        self._lagging = self._reuse_first and self.lag_below_ratio > 0
        try:
            return self._solve_with(newton)
        finally:
            self._reuse_first = self._lagging = False

    def _solve_with(self, newton: dict[str, Any] | None) -> SolveResult:
        if not newton:
            return self._solve()
        unknown = sorted(set(newton) - {"snes_linesearch_type", "snes_max_it", "stall_window"})
        if unknown:
            raise InvalidParameterError(
                f"per-solve Newton settings take snes_linesearch_type, snes_max_it and "
                f"stall_window, not {', '.join(unknown)}"
            )
        window = check_stall_window(newton.get("stall_window", 0))
        newton = {k: v for k, v in newton.items() if k != "stall_window"}
        line_search = newton.get("snes_linesearch_type")
        if line_search is not None and line_search not in LINE_SEARCHES:
            raise InvalidParameterError(
                f"unknown line search {line_search!r}; choose one of {', '.join(LINE_SEARCHES)}"
            )
        # petsc4py 3.18 has no handle on the line search: go through the options database
        opts = PETSc.Options()
        own = {key: self.options[key] for key in newton}
        self._window = window
        try:
            for key, value in newton.items():
                opts[f"{self.prefix}{key}"] = value
            self._set_from_options()
            return self._solve()
        finally:
            self._window = 0
            for key, value in own.items():
                opts[f"{self.prefix}{key}"] = value
            self._set_from_options()

    def _solve(self) -> SolveResult:
        """Newton from the problem's state; an inexact solve that fails is retried exact.

        With a kept factorisation, an increment whose Newton got close and stalled (below
        :data:`RETRY_BELOW` of its first residual: the inexact solves no longer carry it) or
        whose Krylov solves failed is solved again from the same guess with a fresh
        factorisation at every iteration, so that the loader cuts the step only where exact
        Newton fails too. An increment that never got close is cut at once: there the stall
        refactorisation (``refactor_above_ratio``) has already made the iterations exact
        Newton's, which a retry would repeat. The result counts the work of both.
        """
        guess = self.problem.w.x.array.copy()
        first = self._newton()
        if first.converged or not self.refactor_above_its or not _worth_retrying(first):
            return first
        log.info("inexact Newton failed (%s after %d its, residual %s): again with a fresh "
                 "factorisation at every iteration", first.reason, first.iterations,
                 f"{first.residuals[-1]:.3g}" if first.residuals else "?")
        self.problem.w.x.array[:] = guess  # the residual callbacks moved the state
        self._exact, self._lagging = True, False
        try:
            second = self._newton()
        finally:
            self._exact = False
        return SolveResult(
            second.converged,
            second.reason,
            first.iterations + second.iterations,
            first.residuals + second.residuals,
            linear_iterations=first.linear_iterations + second.linear_iterations,
            linear_reason=second.linear_reason,
            exact_retry=True,
        )

    def _drop_stale_pattern(self) -> None:
        """Start a solve on matrices without the self-contact entries of earlier solves.

        The pairs of a failed iterate (a body passed through itself) may couple nodes far
        apart; kept in the pattern, they would cost every later factorisation fill-in.
        """
        if self._self_contact is None or self.A.getInfo()["nz_allocated"] <= self._nonzeros:
            return
        stale = (self.A, self.P)
        self.A = self._create_matrix(self.problem.tangent)
        self.P = self._preconditioning_matrix()
        self.snes.setJacobian(self._jacobian, self.A, self.P if self.P is not None else self.A)
        self._configure_pc(self.snes.getKSP(), self.A)
        self._reuse_first = self._lagging = False  # nothing is factorised on them yet
        for matrix in stale:
            if matrix is not None:
                matrix.destroy()

    def _newton(self) -> SolveResult:
        self._drop_stale_pattern()
        if self._self_contact is not None:
            self._self_contact.begin_solve()
        self.problem.w.vector.copy(self.x)
        self.snes.setConvergenceHistory(reset=True)
        self._stall = False
        self.snes.setConvergenceTest(self._converged if self._window else "default")
        start = time.perf_counter()
        try:
            self.snes.solve(None, self.x)
        except PETSc.Error as err:
            # A PETSc error inside one Newton solve (e.g. an AMG set-up on a state full
            # of NaN) fails this increment only; the loader cuts back from the last
            # converged state, which the caller still holds.
            self.timings.snes += time.perf_counter() - start
            log.warning("PETSc error in SNES solve: %s", str(err).splitlines()[-1])
            return SolveResult(False, f"petsc_error {err.ierr}", self.snes.getIterationNumber())
        self.timings.snes += time.perf_counter() - start
        reason = self.snes.getConvergedReason()
        iterations = self.snes.getIterationNumber()
        history = self.snes.getConvergenceHistory()[0]
        residuals = [float(r) for r in history[: iterations + 1]]
        converged = reason > 0
        if converged:
            self._update_state(self.x)
        ksp = self.snes.getKSP()
        return SolveResult(
            converged,
            "diverged_stalled" if self._stall and not converged else _reason_name(reason),
            iterations,
            residuals,
            linear_iterations=int(self.snes.getLinearSolveIterations()),
            linear_reason=_KSP_REASONS.get(ksp.getConvergedReason(), str(ksp.getConvergedReason())),
        )

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


def _homogeneous_dofs(bcs: list[Any]) -> np.ndarray | None:
    """The local entries the Dirichlet conditions fix, if every value they fix is zero."""
    if any(np.any(bc.g.x.array) for bc in bcs):
        return None
    dofs = [bc.dof_indices()[0] for bc in bcs]
    return np.unique(np.concatenate(dofs)) if dofs else np.zeros(0, dtype=np.int32)


def _single_field(options: dict[str, Any]) -> dict[str, Any]:
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


_REASONS = {
    getattr(PETSc.SNES.ConvergedReason, name): name
    for name in dir(PETSc.SNES.ConvergedReason)
    if name.isupper() or name.startswith(("CONVERGED", "DIVERGED"))
}
_KSP_REASONS = {
    getattr(PETSc.KSP.ConvergedReason, name): name.lower()
    for name in dir(PETSc.KSP.ConvergedReason)
    if name.isupper() or name.startswith(("CONVERGED", "DIVERGED"))
}


_FACTORISATION_NAMES = {"cholesky": "LDLᵀ", "lu": "LU"}

#: A failed inexact solve whose residual fell below this fraction of its first one is retried
#: exactly (:meth:`NewtonSolver._solve`).
RETRY_BELOW = 1e-3


def _stalled_near_solution(norms: list[float], ratio: float) -> bool:
    """Whether Newton stalled close to the solution.

    Close: within :data:`RETRY_BELOW` of its first residual; stalled: its last iteration left
    more than ``ratio`` of the residual. Far from the solution (the line search's global phase)
    a slow iteration is the nonlinearity's, not the kept factorisation's, and a fresh
    factorisation there only costs time (measured on the default mesh, C1 = 0.8 kPa at
    Φ = −90°: the same load path, 40 % more time per failed step); close to it, a slow
    iteration is the inexact solve stalling.
    """
    return (len(norms) >= 2 and norms[-1] <= RETRY_BELOW * norms[0]
            and norms[-1] > ratio * norms[-2])


#: The stall test (:func:`_stalled`): a window of iterations whose residuals lie within this
#: factor of each other (a plateau), ...
STALL_SPREAD = 1.1
#: ... and whose best residual is not below this fraction of the best one before it.
STALL_RATIO = 0.5


def _stalled(norms: list[float], window: int) -> bool:
    """Whether Newton sits on a plateau of the residual: the last ``window`` iterations.

    Stalled: the residuals after those iterations lie within :data:`STALL_SPREAD` of each other
    and none is below :data:`STALL_RATIO` of the best residual before them. ``norms`` holds the
    residual before the first iteration and after each one. On such a plateau the line search
    finds no descent along Newton's direction (a local minimum of the residual's norm). A
    residual that still moves is not a plateau: Newton on its way over a fold creeps and jumps
    like that for a dozen iterations and more before converging (traced on the default mesh's
    soft medial and caudal cases: attempts of the last resort that converged after 20 to 41
    iterations spent up to 15 of them within a factor 1.7, and 8 within a factor 1.25).
    """
    if not window or len(norms) <= window:
        return False
    last = norms[-window:]
    return max(last) <= STALL_SPREAD * min(last) and min(last) > STALL_RATIO * min(norms[:-window])


def _worth_retrying(result: SolveResult) -> bool:
    """Whether exact Newton from the same guess may succeed where the inexact solve failed."""
    if result.reason == "diverged_fnorm_nan" or result.reason.startswith("petsc_error"):
        return False  # the state itself is bad: exact Newton meets it as well
    if "linear_solve" in result.reason or result.linear_reason.startswith("diverged"):
        return True
    residuals = result.residuals
    return len(residuals) >= 2 and residuals[-1] <= RETRY_BELOW * residuals[0]


def _reason_name(reason: int) -> str:
    return _REASONS.get(reason, str(reason)).lower()


__all__ = [
    "LINE_SEARCHES",
    "SOLVER_PRESETS",
    "NewtonSolver",
    "SolveResult",
    "Timings",
    "default_parameters",
    "solver_options",
]
