"""How a Newton solve ends: its result, PETSc's reasons in words, and the tests on its residuals.

:class:`fem.solver.NewtonSolver` returns a :class:`SolveResult`; its convergence test is
PETSc's default plus a stall test on a plateau of the residual (:func:`stalled`, for a solve
with a stall window), and a failed inexact solve is retried exact where that may help
(:func:`worth_retrying`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from petsc4py import PETSc


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


SNES_REASONS = {
    getattr(PETSc.SNES.ConvergedReason, name): name
    for name in dir(PETSc.SNES.ConvergedReason)
    if name.isupper() or name.startswith(("CONVERGED", "DIVERGED"))
}
KSP_REASONS = {
    getattr(PETSc.KSP.ConvergedReason, name): name.lower()
    for name in dir(PETSc.KSP.ConvergedReason)
    if name.isupper() or name.startswith(("CONVERGED", "DIVERGED"))
}


#: A failed inexact solve whose residual fell below this fraction of its first one is retried
#: exactly (:meth:`fem.solver.NewtonSolver.solve`).
RETRY_BELOW = 1e-3


def stalled_near_solution(norms: list[float], ratio: float) -> bool:
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


#: The stall test (:func:`stalled`): a window of iterations whose residuals lie within this
#: factor of each other (a plateau), ...
STALL_SPREAD = 1.1
#: ... and whose best residual is not below this fraction of the best one before it.
STALL_RATIO = 0.5


def stalled(norms: list[float], window: int) -> bool:
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


def worth_retrying(result: SolveResult) -> bool:
    """Whether exact Newton from the same guess may succeed where the inexact solve failed."""
    if result.reason == "diverged_fnorm_nan" or result.reason.startswith("petsc_error"):
        return False  # the state itself is bad: exact Newton meets it as well
    if "linear_solve" in result.reason or result.linear_reason.startswith("diverged"):
        return True
    residuals = result.residuals
    return len(residuals) >= 2 and residuals[-1] <= RETRY_BELOW * residuals[0]


def reason_name(reason: int) -> str:
    """A SNES converged/diverged reason in PETSc's words, lower case."""
    return SNES_REASONS.get(reason, str(reason)).lower()


def default_test(snes: PETSc.SNES, its: int, norms: tuple[float, float, float],
                 first_norm: float, divtol: float, history: list[float],
                 window: int) -> tuple[int, bool]:
    """PETSc 3.18's default convergence test, plus the stall test: (reason, stalled).

    Installed only for a solve with a stall window, so that every other solve keeps PETSc's
    own test. The tests and their order are ``SNESConvergedDefault``'s; the iteration limit
    stays with the Newton loop. ``first_norm`` is the solve's first residual, ``history``
    every residual so far (this iteration's included), ``window`` the stall window
    (:func:`stalled`); ``divtol`` PETSc's divergence tolerance.
    """
    xnorm, step_norm, fnorm = norms
    reasons = PETSc.SNES.ConvergedReason
    rtol, atol, stol, _ = snes.getTolerances()
    if not math.isfinite(fnorm):
        return reasons.DIVERGED_FNORM_NAN, False
    if fnorm < atol:
        return reasons.CONVERGED_FNORM_ABS, False
    max_funcs = snes.getMaxFunctionEvaluations()
    if max_funcs >= 0 and snes.getFunctionEvaluations() >= max_funcs:
        return reasons.DIVERGED_FUNCTION_COUNT, False
    if its:
        if fnorm <= rtol * first_norm:
            return reasons.CONVERGED_FNORM_RELATIVE, False
        if step_norm < stol * xnorm:
            return reasons.CONVERGED_SNORM_RELATIVE, False
        if divtol > 0 and fnorm > divtol * first_norm:
            return reasons.DIVERGED_DTOL, False
        if stalled(history, window):
            return reasons.DIVERGED_LOCAL_MIN, True
    return reasons.ITERATING, False

