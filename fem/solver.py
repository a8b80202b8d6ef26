"""PETSc SNES Newton solver for :class:`fem.problem.GravityProblem`: the Newton policy.

:class:`fem.snes_system.SnesSystem` sets up the SNES, its options and linear algebra;
:class:`NewtonSolver` decides, iteration by iteration, when to factorise the tangent afresh
and when to keep the last factorisation (``direct``'s kept factorisation, a chord iteration
from a nearby guess), when to give a solve up (the stall test, :mod:`fem.convergence`) and when
to retry a failed inexact solve exactly.
"""

from __future__ import annotations

import logging
import time
from typing import Any

from dolfinx.fem import petsc as fem_petsc
from petsc4py import PETSc

from fem.convergence import (
    KSP_REASONS,
    SolveResult,
    default_test,
    reason_name,
    stalled_near_solution,
    worth_retrying,
)
from fem.exceptions import InvalidParameterError
from fem.options import (
    LINE_SEARCHES,
    SOLVER_PRESETS,
    default_parameters,
    solver_options,
)
from fem.parameters import check_stall_window
from fem.problem import GravityProblem
from fem.snes_system import SOLVER_PREFIX, SnesSystem, Timings

log = logging.getLogger(__name__)


class NewtonSolver(SnesSystem):
    """A SNES Newton solver bound to one problem.

    Args:
        problem: the variational problem.
        options: PETSc options overriding the preset's :func:`default_parameters`.
        preset: linear-solver preset (see :mod:`fem.snes_system`).
    """

    def __init__(
        self,
        problem: GravityProblem,
        options: dict[str, Any] | None = None,
        preset: str = "direct",
    ) -> None:
        super().__init__(problem, options, preset)
        #: Re-factorise when the last Newton iteration left more of the residual (1: never).
        self.refactor_above_ratio = float(self.options.get("refactor_above_ratio", 1.0))
        #: Factorise at every iteration (the retry of a failed inexact increment).
        self._exact = False
        #: Keep the last factorisation at the first iteration too (a solve from a nearby guess).
        self._reuse_first = False
        #: From a nearby guess, keep the last tangent as well while the iteration contracts by
        #: at most this ratio (0: never).
        self.lag_below_ratio = float(self.options.get("lag_below_ratio", 0.0))
        #: The running solve keeps the last tangent and factorisation (a chord iteration).
        self._lagging = False
        #: The running solve's stall window (:func:`fem.convergence.stalled`; 0: none), a
        #: per-solve setting.
        self._window = 0
        #: The running solve was given up as stalled.
        self._stall = False
        #: The first residual of the running solve (PETSc's relative test is against it).
        self._first_norm = 0.0

    # -- SNES callbacks ---------------------------------------------------------------------
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

    def _converged(self, snes: PETSc.SNES, its: int, norms: tuple[float, float, float]) -> int:
        """:func:`fem.convergence.default_test` on this solve (a solve with a stall window)."""
        if its == 0:
            self._first_norm = norms[2]
        divtol = float(self.options.get("snes_divergence_tolerance", 1e4))
        reason, self._stall = default_test(snes, its, norms, self._first_norm, divtol,
                                           self._norms, self._window)
        return reason

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
            or stalled_near_solution(self._norms, self.refactor_above_ratio)
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

    # -- driver ---------------------------------------------------------------------------------
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

    def solve(
        self, newton: dict[str, Any] | None = None, reuse_factorisation: bool = False
    ) -> SolveResult:
        """Run Newton from the problem's current state; on success the state holds the solution.

        Args:
            newton: for this solve only, another line search (``snes_linesearch_type``)
                and iteration limit (``snes_max_it``), e.g.
                :data:`fem.options.RESCUE_OPTIONS`, the solver's own restored after; and a
                stall window (``stall_window``: give the solve up once that many iterations
                sit on a plateau of the residual, :func:`fem.convergence.stalled`).
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
        :data:`fem.convergence.RETRY_BELOW` of its first residual: the inexact solves no
        longer carry it) or whose Krylov solves failed is solved again from the same guess with
        a fresh factorisation at every iteration, so that the loader cuts the step only where exact
        Newton fails too. An increment that never got close is cut at once: there the stall
        refactorisation (``refactor_above_ratio``) has already made the iterations exact
        Newton's, which a retry would repeat. The result counts the work of both.
        """
        guess = self.problem.w.x.array.copy()
        first = self._newton()
        if first.converged or not self.refactor_above_its or not worth_retrying(first):
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
            self.renew_linear_solver()  # the error left the KSP mid-solve: start a clean one
            self._reuse_first = self._lagging = False  # nothing is factorised on the new one
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
            "diverged_stalled" if self._stall and not converged else reason_name(reason),
            iterations,
            residuals,
            linear_iterations=int(self.snes.getLinearSolveIterations()),
            linear_reason=KSP_REASONS.get(ksp.getConvergedReason(), str(ksp.getConvergedReason())),
        )


__all__ = [
    "LINE_SEARCHES",
    "SOLVER_PREFIX",
    "SOLVER_PRESETS",
    "NewtonSolver",
    "SolveResult",
    "Timings",
    "default_parameters",
    "solver_options",
]
