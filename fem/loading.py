"""Adaptive incremental gravity loading.

Gravity is applied as a load fraction λ that goes from 0 to 1. The scheme tries
a large step first (by default the whole load); when Newton fails or an element
inverts (det F ≤ 0) it restores the last converged state and cuts the step (onto
``min_step`` where halving would pass it);
after an easy step it grows the step; each step starts from a linear
extrapolation of the last two converged states (quadratic, through three, at the start of a
path through known states). When the step has been cut below
``min_step``, a last resort starts again from rest with Newton's
:data:`fem.options.RESCUE_OPTIONS` before the case is declared failed; it gives an attempt up
once its residual sits on a plateau (``Loading.stall_window``), and itself up once its step is
cut below ``Loading.rescue_min_step``. With
``fixed_steps`` it becomes the classic fixed-increment scheme that it is
benchmarked against (no last resort).
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field

import numpy as np

from fem.exceptions import InvalidParameterError
from fem.options import RESCUE_OPTIONS
from fem.parameters import Loading
from fem.problem import GravityProblem
from fem.solver import NewtonSolver

log = logging.getLogger(__name__)

_FULL = 1.0 - 1e-12


@dataclass
class StepRecord:
    """One attempted load increment."""

    fraction: float
    step: float
    converged: bool
    iterations: int
    reason: str
    final_residual: float | None
    min_detF: float | None
    linear_iterations: int = 0
    rescue: bool = False
    exact_retry: bool = False
    #: The whole load tried at once from a given guess (a neighbouring case's solution).
    warm_start: bool = False
    #: A step of the walk back from the last resort's answer to the first pass's furthest
    #: state (:func:`_walk_back`), which checks that both lie on one branch of equilibria.
    walk_back: bool = False


@dataclass
class LoadingResult:
    """Outcome of the whole load path."""

    converged: bool
    fraction: float
    reason: str
    attempts: list[StepRecord] = field(default_factory=list)
    #: The load fraction the path started from (0: rest; above: a known state, ``path``).
    start_fraction: float = 0.0
    #: The attempts of the load path that the result holds (the last resort starts a
    #: second path from rest): ``attempts[path_start:path_end]``.
    path_start: int = 0
    path_end: int | None = None
    #: Where the last resort's answer, walked back down the load, met the first pass's
    #: furthest state: the load fraction and the largest distance of the two displacements in
    #: metres (None: the walk back failed); None without such a check (:func:`_walk_back`).
    branch_check: dict[str, float | None] | None = None

    @property
    def accepted(self) -> list[StepRecord]:
        """The converged increments of the load path the result holds, in order."""
        return [a for a in self.attempts[self.path_start:self.path_end] if a.converged]

    @property
    def newton_iterations(self) -> list[int]:
        """Newton iterations of each accepted increment."""
        return [a.iterations for a in self.accepted]

    @property
    def first_failure(self) -> str:
        """Reason of the first rejected increment ("" if none was rejected)."""
        return next((a.reason for a in self.attempts if not a.converged), "")

    @property
    def failure_kinds(self) -> dict[str, int]:
        """Rejected increments counted by :func:`failure_kind`."""
        kinds: dict[str, int] = {}
        for a in self.attempts:
            if not a.converged:
                kind = failure_kind(a.reason)
                kinds[kind] = kinds.get(kind, 0) + 1
        return kinds

    @property
    def linear_iterations(self) -> int:
        """Krylov iterations of all attempts (one per Newton iteration for a direct solver)."""
        return sum(a.linear_iterations for a in self.attempts)

    @property
    def exact_retries(self) -> int:
        """Increments that the inexact solve failed and exact Newton was tried on."""
        return sum(a.exact_retry for a in self.attempts)

    @property
    def rescued(self) -> bool:
        """Whether the last resort (:attr:`fem.parameters.Loading.rescue`) was needed."""
        return any(a.rescue for a in self.attempts)

    @property
    def warm_started(self) -> bool:
        """Whether the result is the guess's Newton solve (no load path from rest)."""
        return any(a.warm_start and a.converged for a in self.attempts)

    @property
    def total_iterations(self) -> int:
        """Newton iterations of all attempts, failed ones included (each costs work)."""
        return sum(a.iterations for a in self.attempts)

    def as_dict(self) -> dict:
        """JSON-friendly record."""
        return {
            "converged": self.converged,
            "fraction": self.fraction,
            "reason": self.reason,
            "attempts": [asdict(a) for a in self.attempts],
            "branch_check": self.branch_check,
        }


def failure_kind(reason: str) -> str:
    """Class of a rejected increment's reason.

    ``inversion`` (det F ≤ 0 at a quadrature point of a converged state), ``nan``
    (the residual became NaN/Inf: an element inverted during the iteration),
    ``line_search`` (no acceptable step length), ``linear_solver`` (factorisation or
    Krylov failure), ``petsc_error`` (PETSc raised, e.g. AMG set-up on a garbage
    state), ``stalled`` (the residual sat on a plateau: the last resort's stall test),
    ``newton`` (iteration limit or divergence), ``other``.
    """
    if reason.startswith("inverted"):
        return "inversion"
    if reason == "diverged_fnorm_nan":
        return "nan"
    if reason.startswith("petsc_error"):
        return "petsc_error"
    if "line_search" in reason:
        return "line_search"
    if "linear_solve" in reason:
        return "linear_solver"
    if reason == "diverged_stalled":
        return "stalled"
    if reason.startswith("diverged"):
        return "newton"
    return "other"


def solve_incrementally(
    problem: GravityProblem,
    solver: NewtonSolver,
    loading: Loading = Loading(),
    guess: np.ndarray | None = None,
    path: Sequence[tuple[float, np.ndarray]] = (),
) -> LoadingResult:
    """Drive the problem from zero load to full gravity.

    The problem's state must hold the solution at λ = 0 (zero for a fresh case).
    On return the state holds the last converged load fraction.

    With ``guess`` (mixed-field values, e.g. a neighbouring case's solution), Newton first
    solves the whole load from it; where that fails or inverts an element, the load path
    starts from rest as without it. Either way the answer satisfies the same stopping test,
    so it does not depend on the guess beyond the solver's tolerance.

    With ``path`` (equilibrium states of this very case at load fractions in (0, 1),
    increasing, e.g. a stiffer neighbour's solution: see :mod:`fem.chain`), the load path
    starts from the last of them instead of from rest, extrapolating from the last three
    (with rest, where only two are given), and the first step keeps the last factorisation;
    where it fails, the last resort (from rest) is tried only with
    ``loading.rescue_after_neighbours``.

    Raises:
        InvalidParameterError: for a ``path`` whose fractions are not increasing in (0, 1),
            or a ``path`` given with a ``guess``.
    """
    solver.scale_to_load()
    state = problem.w.x.array
    history: list[tuple[float, np.ndarray]] = [(0.0, state.copy())]
    rest = history[0]
    fraction = 0.0
    step = 1.0 / loading.fixed_steps if loading.fixed_steps else loading.initial_step
    result = LoadingResult(converged=False, fraction=0.0, reason="")
    reuse = False  # the first step from a known state keeps the last factorisation
    if path:
        fractions = [f for f, _ in path]
        if (guess is not None or any(not 0.0 < f < 1.0 for f in fractions)
                or any(b <= a for a, b in zip(fractions, fractions[1:], strict=False))):
            raise InvalidParameterError(
                f"a load path's known fractions must increase within (0, 1), without a guess; "
                f"got {fractions}{' and a guess' if guess is not None else ''}")
        history = [history[-1], *((f, w.copy()) for f, w in path)][-3:]
        fraction = result.start_fraction = history[-1][0]
        state[:] = history[-1][1]
        reuse = True
    if guess is not None and not loading.fixed_steps:
        if _solve_from_guess(problem, solver, guess, result):
            fraction = 1.0
        else:
            state[:] = rest[1]
            result.path_start = len(result.attempts)
    newton: dict | None = None  # RESCUE_OPTIONS once the last resort has begun
    first_pass: tuple[float, np.ndarray] | None = None  # where the loading got without it

    while fraction < _FULL:
        if len(result.attempts) >= loading.max_steps:
            result.reason = f"load-step budget of {loading.max_steps} attempts exhausted"
            break
        step = min(step, 1.0 - fraction)
        target = fraction + step
        _predict(problem, history, step, loading.extrapolate)
        problem.set_load_fraction(target)
        outcome = solver.solve(newton, reuse_factorisation=reuse)
        reuse = False
        min_det = problem.min_detF() if outcome.converged else None
        inverted = min_det is not None and not min_det > 0
        ok = outcome.converged and not inverted
        reason = outcome.reason if not inverted else f"inverted element (min det F = {min_det:.3g})"
        result.attempts.append(
            StepRecord(
                fraction=target,
                step=step,
                converged=ok,
                iterations=outcome.iterations,
                reason=reason,
                final_residual=outcome.residuals[-1] if outcome.residuals else None,
                min_detF=min_det,
                linear_iterations=outcome.linear_iterations,
                rescue=newton is not None,
                exact_retry=outcome.exact_retry,
            )
        )
        log.info("load step to λ=%.4f (step %.4f): %s in %d Newton iterations", target, step,
                 reason, outcome.iterations)
        if ok:
            fraction = target
            history = [history[-1], (fraction, state.copy())]
            if not loading.fixed_steps and outcome.iterations <= loading.easy_iterations:
                step *= loading.growth
            continue
        state[:] = history[-1][1]
        if loading.fixed_steps:
            result.reason = f"fixed step at λ={target:.4f} failed: {reason}"
            break
        step = _cut(step, loading.cutback, loading.rescue_min_step if newton else loading.min_step)
        if step is None:
            if loading.rescue and newton is None and (
                    not path or loading.rescue_after_neighbours):
                # From the stalled state the creasing fold does not let Newton through; from
                # rest, the whole load at once with another line search can get past it.
                newton = {**RESCUE_OPTIONS, "stall_window": loading.stall_window}
                log.info("λ=%.4f: steps below min_step fail (%s); last resort: from rest with %s",
                         fraction, reason, newton)
                first_pass = (fraction, state.copy())
                result.path_start = len(result.attempts)
                state[:] = rest[1]
                history, fraction, step = [rest], 0.0, loading.initial_step
                continue
            where = f"at λ={fraction:.4f}"
            if first_pass is not None:
                where = (f"at λ={first_pass[0]:.4f}, and the last resort's below "
                         f"rescue_min_step={loading.rescue_min_step:g} {where}")
            if loading.rescue and newton is None:
                where += (" (no last resort after a start from the neighbours' solutions: "
                          "loading.rescue_after_neighbours)")
            result.reason = (f"step cut below min_step={loading.min_step:g} {where}; "
                             f"last failure: {reason}")
            break

    if first_pass is not None and fraction >= _FULL and first_pass[0] > 0 \
            and loading.check_branch and not _continues(problem, solver, loading, first_pass,
                                                        result):
        fraction, state[:] = first_pass[0], first_pass[1]  # another branch: not this case's
        result.path_start, result.path_end = 0, result.path_start
        stopped = (f"λ={first_pass[0]:.4f}, where the first pass stopped (step cut below "
                   f"min_step={loading.min_step:g})")
        distance = (result.branch_check or {}).get("distance_m")
        result.reason = (
            f"the last resort's answer could not be walked back to {stopped}: it may be another "
            f"equilibrium than the load path's" if distance is None else
            f"the last resort's answer is another equilibrium than the load path's: walked back "
            f"to {stopped}, it lies {1e3 * distance:.3g} mm from that pass's state")
        log.info("%s", result.reason)
    if first_pass is not None and fraction < _FULL and first_pass[0] > fraction:
        fraction, state[:] = first_pass[0], first_pass[1]  # the last resort got less far
        result.path_start, result.path_end = 0, result.path_start
    problem.set_load_fraction(fraction)
    result.fraction = fraction
    result.converged = fraction >= _FULL
    if result.converged:
        result.fraction = 1.0
        result.reason = "converged"
    return result


#: The last resort's answer continues the load path when, walked back to where the first pass
#: stopped, it lies within this fraction of the largest displacement of that pass's state there.
#: Two solves of one equilibrium to Newton's tolerance agreed to within 1e-8 of it (the coarse
#: test mesh, supine, prone and lying on the side); the other equilibria that the last resort
#: reached from rest on the default breast lay percents away.
BRANCH_TOLERANCE = 1e-3


def _continues(
    problem: GravityProblem,
    solver: NewtonSolver,
    loading: Loading,
    first_pass: tuple[float, np.ndarray],
    result: LoadingResult,
) -> bool:
    """Whether the last resort's answer (the state, at the full load) continues the load path.

    The last resort starts again from rest in large steps, and where equilibria are not unique
    (a soft mound rolling over its fold) it can reach another one than the load path leads to:
    the case's answer would then depend on how it was solved. The answer is walked back down
    the load (:func:`_walk_back`) to where the first pass stopped and compared with that pass's
    state there. Records the check in ``result.branch_check``; the state is the answer again
    on return.
    """
    answer = problem.w.x.array.copy()
    result.path_end = len(result.attempts)
    goal, reference = first_pass
    distance = scale = None
    if _walk_back(problem, solver, loading, goal, result):
        back = _node_displacements(problem)
        problem.w.x.array[:] = reference
        there = _node_displacements(problem)
        distance = float(np.linalg.norm(back - there, axis=1).max())
        scale = float(np.linalg.norm(there, axis=1).max())
    problem.w.x.array[:] = answer
    result.branch_check = {"fraction": goal, "distance_m": distance}
    log.info("the last resort's answer walked back to λ=%.4f: %s", goal,
             "failed" if distance is None else f"{1e3 * distance:.3g} mm from the load path")
    return distance is not None and distance <= BRANCH_TOLERANCE * scale


def _node_displacements(problem: GravityProblem) -> np.ndarray:
    """The state's displacement, one row per node."""
    return problem.displacement().x.array.reshape(-1, 3)


def _walk_back(
    problem: GravityProblem, solver: NewtonSolver, loading: Loading, goal: float,
    result: LoadingResult,
) -> bool:
    """Continue the state from the full load down to the load fraction ``goal``.

    Adaptive as the load path is, in the other direction: the whole way at once first, cut
    back on failure down to ``loading.min_step``, the guess extrapolated from the last states.
    Each attempt is recorded (``walk_back``); at most ``loading.max_steps`` of them. Returns
    whether the state got to ``goal``.
    """
    state = problem.w.x.array
    budget = len(result.attempts) + loading.max_steps
    # the fractions negated, so that the known states' abscissae increase as _predict expects
    history: list[tuple[float, np.ndarray]] = [(-1.0, state.copy())]
    fraction, step = 1.0, 1.0 - goal
    while fraction > goal + 1e-12:
        if len(result.attempts) >= budget:
            return False
        step = min(step, fraction - goal)
        _predict(problem, history, step, loading.extrapolate)
        problem.set_load_fraction(fraction - step)
        outcome = solver.solve()
        min_det = problem.min_detF() if outcome.converged else None
        ok = outcome.converged and min_det is not None and min_det > 0
        result.attempts.append(StepRecord(
            fraction=fraction - step, step=step, converged=ok, iterations=outcome.iterations,
            reason=outcome.reason if min_det is None or min_det > 0 else
            f"inverted element (min det F = {min_det:.3g})",
            final_residual=outcome.residuals[-1] if outcome.residuals else None,
            min_detF=min_det, linear_iterations=outcome.linear_iterations,
            exact_retry=outcome.exact_retry, walk_back=True))
        if ok:
            fraction -= step
            history = [history[-1], (-fraction, state.copy())]
            if outcome.iterations <= loading.easy_iterations:
                step *= loading.growth
            continue
        state[:] = history[-1][1]
        step = _cut(step, loading.cutback, loading.min_step)
        if step is None:
            return False
    return True


def _cut(step: float, cutback: float, floor: float) -> float | None:
    """The step after a failed one: cut back, but the floor itself is tried before giving up.

    A path from rest halves 1 → 1/64 onto the floor; a path from a neighbour's state at λ = 0.8
    halves 0.2 → 0.025 → 0.0125, past it: without the clamp such a path would be given up one
    cut sooner than a path from rest. None: the floor itself (or less) has failed.
    """
    cut = step * cutback
    if cut >= floor:
        return cut
    return floor if step > floor * (1 + 1e-9) else None


def _solve_from_guess(
    problem: GravityProblem, solver: NewtonSolver, guess: np.ndarray, result: LoadingResult
) -> bool:
    """Newton on the whole load from ``guess``; records the attempt, returns whether it holds."""
    problem.w.x.array[:] = guess
    problem.set_load_fraction(1.0)
    record = StepRecord(fraction=1.0, step=1.0, converged=False, iterations=0,
                        reason="the guess inverts an element", final_residual=None,
                        min_detF=None, warm_start=True)
    if problem.min_detF() > 0:
        outcome = solver.solve(reuse_factorisation=True)
        min_det = problem.min_detF() if outcome.converged else None
        inverted = min_det is not None and not min_det > 0
        record.converged = outcome.converged and not inverted
        record.iterations = outcome.iterations
        record.reason = (f"inverted element (min det F = {min_det:.3g})" if inverted
                         else outcome.reason)
        record.final_residual = outcome.residuals[-1] if outcome.residuals else None
        record.min_detF = min_det
        record.linear_iterations = outcome.linear_iterations
        record.exact_retry = outcome.exact_retry
    result.attempts.append(record)
    if not record.converged:
        log.info("the guess failed (%s): the load path from rest", record.reason)
    return record.converged


def _predict(
    problem: GravityProblem, history: list[tuple[float, np.ndarray]], step: float, extrapolate: bool
) -> None:
    """Set the initial guess: the polynomial through the known states, extrapolated by ``step``.

    Through two states the line, through three the quadratic; where it would invert an
    element, the line through the last two, then the last state. Three states are known at
    the start of a path through stiffer neighbours: there the quadratic saves Newton
    iterations on cases whose guess already needs few.
    """
    state = problem.w.x.array
    lam1, w1 = history[-1]
    state[:] = w1
    if not extrapolate or len(history) < 2:
        return
    target = lam1 + step
    for known in (history[-3:], history[-2:]) if len(history) > 2 else (history,):
        lams = [lam for lam, _ in known]
        if any(b <= a for a, b in zip(lams, lams[1:], strict=False)):
            continue
        state[:] = sum(_lagrange(lams, k, target) * w for k, (_, w) in enumerate(known))
        if problem.min_detF() > 0:
            return
    state[:] = w1


def _lagrange(nodes: list[float], k: int, x: float) -> float:
    """The k-th Lagrange basis polynomial through ``nodes``, at ``x``."""
    value = 1.0
    for j, node in enumerate(nodes):
        if j != k:
            value *= (x - node) / (nodes[k] - node)
    return value
