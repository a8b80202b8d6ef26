"""PETSc SNES Newton solver for :class:`fem.problem.GravityProblem`.

All solver options live in :func:`default_parameters`; a config overrides them
key by key (PETSc option names without the leading dash).
"""

from __future__ import annotations

import itertools
import logging
import time
from dataclasses import dataclass, field
from typing import Any

from dolfinx.fem import petsc as fem_petsc
from petsc4py import PETSc

from fem.problem import GravityProblem

log = logging.getLogger(__name__)

_prefix_counter = itertools.count()


def default_parameters() -> dict[str, Any]:
    """Default PETSc options: Newton with backtracking line search and MUMPS LU."""
    return {
        "snes_type": "newtonls",
        "snes_linesearch_type": "bt",
        "snes_rtol": 1e-9,
        "snes_atol": 1e-10,
        "snes_stol": 0.0,
        "snes_max_it": 25,
        "snes_divergence_tolerance": 1e8,
        "ksp_type": "preonly",
        "pc_type": "lu",
        "pc_factor_mat_solver_type": "mumps",
    }


@dataclass
class Timings:
    """Accumulated wall-clock seconds of one solver's phases."""

    residual: float = 0.0
    jacobian: float = 0.0
    snes: float = 0.0

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
    """Outcome of one SNES solve."""

    converged: bool
    reason: str
    iterations: int
    residuals: list[float] = field(default_factory=list)


class NewtonSolver:
    """A SNES solver bound to one problem.

    Args:
        problem: the variational problem.
        options: PETSc options overriding :func:`default_parameters`.
    """

    def __init__(self, problem: GravityProblem, options: dict[str, Any] | None = None) -> None:
        self.problem = problem
        self.options = {**default_parameters(), **(options or {})}
        self.timings = Timings()
        comm = problem.mesh.comm
        self.A = fem_petsc.create_matrix(problem.tangent)
        self.A.setOption(PETSc.Mat.Option.SYMMETRIC, True)
        self.b = fem_petsc.create_vector(problem.residual)
        self.x = problem.w.vector.duplicate()
        self.snes = PETSc.SNES().create(comm)
        self.prefix = f"breast_{next(_prefix_counter)}_"
        self.snes.setOptionsPrefix(self.prefix)
        opts = PETSc.Options()
        for key, value in self.options.items():
            opts[f"{self.prefix}{key}"] = value
        self.snes.setFunction(self._residual, self.b)
        self.snes.setJacobian(self._jacobian, self.A)
        self.snes.setFromOptions()
        for key in self.options:
            del opts[f"{self.prefix}{key}"]
        self.snes.setConvergenceHistory()

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
        fem_petsc.apply_lifting(b, [self.problem.tangent], bcs=[self.problem.bcs], x0=[x], scale=-1.0)
        b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        fem_petsc.set_bc(b, self.problem.bcs, x, -1.0)
        self.timings.residual += time.perf_counter() - start

    def _jacobian(self, snes: PETSc.SNES, x: PETSc.Vec, A: PETSc.Mat, P: PETSc.Mat) -> None:
        start = time.perf_counter()
        A.zeroEntries()
        fem_petsc.assemble_matrix(A, self.problem.tangent, bcs=self.problem.bcs)
        A.assemble()
        self.timings.jacobian += time.perf_counter() - start

    # -- driver ---------------------------------------------------------------------------------
    def solve(self) -> SolveResult:
        """Run Newton from the problem's current state; on success the state holds the solution."""
        self.problem.w.vector.copy(self.x)
        start = time.perf_counter()
        self.snes.solve(None, self.x)
        self.timings.snes += time.perf_counter() - start
        reason = self.snes.getConvergedReason()
        iterations = self.snes.getIterationNumber()
        history = self.snes.getConvergenceHistory()[0]
        residuals = [float(r) for r in history[: iterations + 1]]
        converged = reason > 0
        if converged:
            self._update_state(self.x)
        return SolveResult(converged, _reason_name(reason), iterations, residuals)

    def time_linear_system(self) -> float:
        """Seconds for one Jacobian assembly + factorisation + solve at the current state.

        This is the unit of cost of a Newton solve, measured in the same process so
        that `nonlinear time / this` is a machine-independent ratio.
        """
        A = fem_petsc.create_matrix(self.problem.tangent)
        A.setOption(PETSc.Mat.Option.SYMMETRIC, True)
        ksp = PETSc.KSP().create(self.problem.mesh.comm)
        prefix = f"{self.prefix}lin_"
        ksp.setOptionsPrefix(prefix)
        opts = PETSc.Options()
        ksp_keys = [k for k in self.options if k.startswith(("ksp_", "pc_", "mat_", "fieldsplit_"))]
        for key in ksp_keys:
            opts[f"{prefix}{key}"] = self.options[key]
        ksp.setFromOptions()
        for key in ksp_keys:
            del opts[f"{prefix}{key}"]
        x = self.b.duplicate()
        b = self.b.duplicate()
        self._residual(self.snes, self.problem.w.vector, b)
        saved = (self.timings.residual, self.timings.jacobian)
        start = time.perf_counter()
        A.zeroEntries()
        fem_petsc.assemble_matrix(A, self.problem.tangent, bcs=self.problem.bcs)
        A.assemble()
        ksp.setOperators(A)
        ksp.solve(b, x)
        elapsed = time.perf_counter() - start
        self.timings.residual, self.timings.jacobian = saved
        ksp.destroy()
        A.destroy()
        return elapsed

    def destroy(self) -> None:
        """Free PETSc objects."""
        self.snes.destroy()
        self.A.destroy()
        self.b.destroy()
        self.x.destroy()


_REASONS = {
    getattr(PETSc.SNES.ConvergedReason, name): name
    for name in dir(PETSc.SNES.ConvergedReason)
    if name.isupper() or name.startswith(("CONVERGED", "DIVERGED"))
}


def _reason_name(reason: int) -> str:
    return _REASONS.get(reason, str(reason)).lower()


__all__ = ["NewtonSolver", "SolveResult", "Timings", "default_parameters"]
