"""Timing one FE solve: wall and CPU seconds, the cost unit, and the load path.

The cost unit is one Jacobian assembly + factorisation + solve
(:meth:`fem.solver.NewtonSolver.time_linear_system`), so that
``factorization_equivalents`` = solve time / unit is free of the machine's speed.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from fem.parameters import Loading
from fem.sweep import Case
from studies.results import Record


@dataclass(frozen=True, slots=True)
class Accuracy(Record):
    """Errors at the material points against the refined reference (mm; relative to max |u_ref|)."""

    max_error_mm: float
    rms_error_mm: float
    mean_error_mm: float
    max_disp_mm: float
    relative_max_error: float
    max_outside_m: float


@dataclass(frozen=True, slots=True)
class SelfOverlap(Record):
    """Boundary vertices of the deformed body that lie inside another of its cells."""

    boundary_vertices: int
    overlapping_vertices: int
    examples_m: list[Any] = field(default_factory=list)


@dataclass(frozen=True, slots=True)
class TimedSolve(Record):
    """One solve from rest, timed (:func:`studies.fe_study.fe_timing.timed_solve`)."""

    case: str
    converged: bool
    reason: str
    load_fraction: float
    wall_s: float
    cpu_s: float
    assembly_s: float
    linear_solve_s: float
    linear_system_s: float
    factorization_equivalents: float
    load_steps: int
    rejected_steps: int
    newton_iterations: list[int]
    total_newton_iterations: int
    linear_iterations: int
    jacobian_evaluations: int
    preconditioner_builds: int
    residual_evaluations: int
    first_failure: str
    # what a caller adds to the timing record
    wall_s_repeats: list[float] | None = None
    max_disp_mm: float | None = None
    mean_disp_mm: float | None = None
    accuracy: Accuracy | None = None
    self_overlap: SelfOverlap | None = None
    max_difference_from_adaptive_mm: float | None = None
    baseline: TimedSolve | None = None
    baseline_over_adaptive_wall: float | None = None
    baseline_over_adaptive_cpu: float | None = None
    # a reference solve's record
    dofs: int | None = None
    setup_s: float | None = None
    settings: dict[str, Any] | None = None
    mesh: str | None = None


def timed_solve(runner: Any, case: Case, loading: Loading | None = None) -> dict[str, Any]:
    """Solve ``case`` from rest with ``runner`` and return its timing record.

    Args:
        runner: a :class:`fem.case.CaseRunner`.
        case: the case.
        loading: load stepping for this solve (default: the runner's).

    Returns:
        Wall and CPU seconds of the solve, the cost unit (one Jacobian assembly +
        factorisation + solve) and their ratio ``factorization_equivalents``, the load
        path and iteration counts.
    """
    saved = runner.settings
    if loading is not None:
        runner.settings = replace(saved, loading=loading)
    try:
        result, timings = runner.solve(case)
    finally:
        runner.settings = saved
    unit = runner.solver.time_linear_system() if result.converged else float("nan")
    return {
        "case": case.id,
        "converged": bool(result.converged),
        "reason": result.reason,
        "load_fraction": result.fraction,
        "wall_s": timings["solve"],
        "cpu_s": timings["solve_cpu"],
        "assembly_s": timings["assembly"],
        "linear_solve_s": timings["linear_solve"],
        "linear_system_s": unit,
        "factorization_equivalents": timings["solve"] / unit if unit > 0 else float("nan"),
        "load_steps": len(result.accepted),
        "rejected_steps": len(result.attempts) - len(result.accepted),
        "newton_iterations": result.newton_iterations,
        "total_newton_iterations": result.total_iterations,
        "linear_iterations": result.linear_iterations,
        "jacobian_evaluations": timings["jacobian_evaluations"],
        "preconditioner_builds": timings["preconditioner_builds"],
        "residual_evaluations": timings["residual_evaluations"],
        "first_failure": result.first_failure,
    }


def vertex_displacement(runner: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A serial runner's displacement at its mesh's vertices (the material points).

    Returns:
        ``(node_index, X, u)`` ordered by the vertices' index in the mesh file; the values
        are read from the coefficients, not interpolated.
    """
    from fem.io import gather_vertex_coordinates, gather_vertex_values

    index, u = gather_vertex_values(runner.mesh, runner.problem.displacement())
    index_x, X = gather_vertex_coordinates(runner.mesh)
    assert np.array_equal(index, index_x)
    return index, X, u
