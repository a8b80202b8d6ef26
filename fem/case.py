"""Run one gravity-loading case end to end: mesh in, XDMF + points + summary out."""

from __future__ import annotations

import logging
import time
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from mpi4py import MPI

from fem.case_files import write_points
from fem.exceptions import InvalidParameterError
from fem.io import (
    CaseWriter,
    gather_boundary_vertices,
    gather_vertex_coordinates,
    gather_vertex_values,
    write_fields,
)
from fem.loading import LoadingResult, solve_incrementally
from fem.overlap import self_overlap
from fem.parameters import Material, SolverSettings
from fem.problem import GravityProblem
from fem.provenance import clock
from fem.solver import NewtonSolver
from fem.sweep import Case
from meshes.io import read_mesh

log = logging.getLogger(__name__)

#: Above this many unknowns a case's summary does not measure the factorisation unit
#: (``linear_system_s``, ``factorization_equivalents``: None); the FE study measures it.
MEASURE_UNIT_MAX_DOFS = 150_000


#: How a case's load path started: from rest, or from its stiffer neighbours' solutions
#: (:mod:`fem.chain`).
START_KINDS = ("rest", "neighbours")


@dataclass(frozen=True, slots=True)
class Start:
    """Where a case's load path started.

    Attributes:
        kind: one of :data:`START_KINDS`.
        neighbours: the cases whose solutions started it, nearest last (none from rest).
        fraction: the load fraction of the nearest one in this case (C1 / its C1).
    """

    kind: str = "rest"
    neighbours: tuple[str, ...] = ()
    fraction: float = 0.0

    def __post_init__(self) -> None:
        if self.kind not in START_KINDS:
            raise InvalidParameterError(
                f"unknown start {self.kind!r}; one of {', '.join(START_KINDS)}"
            )
        if (self.kind == "rest") != (not self.neighbours):
            raise InvalidParameterError("a start from neighbours names them, from rest none")

    def as_dict(self) -> dict[str, Any]:
        """The summary's ``start`` record."""
        return {"from": self.kind, "neighbours": list(self.neighbours), "fraction": self.fraction}



class CaseRunner:
    """Holds one mesh, its compiled forms and a solver; runs any number of cases on it.

    The Snakemake workflow runs one case per process; benchmarks and tests reuse a
    runner so that the form compilation and the mesh read are paid once.
    """

    def __init__(
        self, mesh_path: str | Path, settings: SolverSettings = SolverSettings(), comm: Any = None
    ) -> None:
        start = time.perf_counter()
        self.comm = MPI.COMM_WORLD if comm is None else comm
        self.mesh_path = Path(mesh_path)
        self.settings = settings
        self.mesh, self.cell_tags, self.facet_tags = read_mesh(mesh_path, self.comm)
        self.problem = GravityProblem(
            self.mesh, self.facet_tags, settings.discretisation, settings.fixed, settings.contact,
            settings.self_contact, self.cell_tags, settings.tissues, settings.skin,
        )
        self.solver = NewtonSolver(self.problem, settings.petsc_options, settings.solver)
        self.setup_s = time.perf_counter() - start

    def close(self) -> None:
        """Free the solver's PETSc objects and its entries in PETSc's options database.

        The database holds a few hundred entries in all, so a process that builds many
        runners (a test session, a study) closes each when done; ``with CaseRunner(...) as
        runner:`` does it.
        """
        self.solver.destroy()

    def __enter__(self) -> CaseRunner:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def solve(
        self,
        case: Case,
        guess: np.ndarray | None = None,
        path: Sequence[tuple[float, np.ndarray]] = (),
    ) -> tuple[LoadingResult, dict[str, float]]:
        """Solve ``case`` (see :meth:`solve_material`)."""
        s = self.settings
        return self.solve_material(case.material(s.density), case.gravity(s.gravity), guess,
                                   path)

    def solve_material(
        self,
        material: Material,
        gravity: Any,
        guess: np.ndarray | None = None,
        path: Sequence[tuple[float, np.ndarray]] = (),
    ) -> tuple[LoadingResult, dict[str, float]]:
        """Solve for explicit :class:`Material` and :class:`Gravity` objects.

        ``guess`` (mixed-field values near the answer, such as the previous iterate of a
        reference estimate) is tried first at the whole load; where it fails, the adaptive
        load path runs from rest. ``path`` (states of this case at load fractions below 1,
        such as a stiffer neighbour's solution: :mod:`fem.chain`) starts the load path there
        instead of at rest (:func:`fem.loading.solve_incrementally`).
        """
        problem, solver = self.problem, self.solver
        problem.set_case(material, gravity)
        problem.w.x.array[:] = 0.0
        t = solver.timings
        before = replace(t)  # a snapshot: the counters accumulate over the runner's cases
        cpu_start = time.process_time()
        start = time.perf_counter()
        result = solve_incrementally(problem, solver, self.settings.loading, guess, path)
        solve_s = time.perf_counter() - start
        assembly = t.assembly - before.assembly
        timings = {
            "solve": solve_s,
            "assembly": assembly,
            "linear_solve": max(t.snes - before.snes - assembly, 0.0),
            # CPU seconds of this process: robust to other jobs sharing the cores
            "solve_cpu": time.process_time() - cpu_start,
            "residual_evaluations": t.residual_evaluations - before.residual_evaluations,
            "jacobian_evaluations": t.jacobian_evaluations - before.jacobian_evaluations,
            # factorisations with the direct presets, AMG set-ups with the iterative one
            "preconditioner_builds": t.preconditioner_builds - before.preconditioner_builds,
        }
        return result, timings

    def solve_from(
        self, material: Material, gravity: Any, guess: np.ndarray | None
    ) -> tuple[bool, int, bool]:
        """:meth:`solve_material` for a loop that needs only the outcome.

        Returns ``(converged, Newton iterations, whether the guess gave the answer)``.
        """
        result, _ = self.solve_material(material, gravity, guess)
        return result.converged, result.total_iterations, result.warm_started

    def summary(
        self,
        case: Case,
        result: LoadingResult,
        timings: dict[str, float],
        measure_unit: bool = True,
        start: Start = Start(),
    ) -> dict[str, Any]:
        """Summary record of a solved case (call right after :meth:`solve`).

        ``measure_unit`` adds the unit of cost (one more assembly, factorisation and solve,
        ``linear_system_s``) and the solve's ``factorization_equivalents``: it costs as much as a
        solve from a neighbour (:mod:`fem.chain`), so a chain measures it on its first case only.
        ``start`` says where the load path started.
        """
        problem = self.problem
        # at image resolution the unit costs as much memory and time as the solve: never there
        dofs = problem.num_dofs()
        measure = measure_unit and dofs <= MEASURE_UNIT_MAX_DOFS
        linear_s = self.solver.time_linear_system() if measure else None
        u = problem.displacement()
        norms = np.linalg.norm(u.x.array.reshape(-1, 3), axis=1)
        max_local = float(norms.max(initial=0.0))
        max_disp = self.comm.allreduce(max_local, op=MPI.MAX)
        accepted = result.accepted
        return {
            "status": "converged" if result.converged else "failed",
            "reason": result.reason,
            "case": case.id,
            "C1": case.C1,
            "C1_units": "kPa",
            "phi": case.phi,
            "theta": case.theta,
            "angle_units": "deg",
            "gravity_vector": case.gravity(self.settings.gravity).vector.tolist(),
            "load_fraction": result.fraction,
            "load_steps": len(accepted),
            "rejected_steps": len(result.attempts) - len(accepted),
            "first_failure": result.first_failure,
            "failure_kinds": result.failure_kinds,
            "rescued": result.rescued,
            "branch_check": result.branch_check,
            "start": start.as_dict(),
            "exact_retries": result.exact_retries,
            "newton_iterations": result.newton_iterations,
            "total_newton_iterations": result.total_iterations,
            "final_residual": accepted[-1].final_residual if accepted else None,
            "load_path": result.as_dict()["attempts"],
            "max_disp_mm": 1e3 * max_disp,
            "mean_disp_mm": None,  # filled from the material points by run_case
            "volume_change": problem.volume_change(),
            "min_detF": problem.min_detF(),
            # flag a body that passes through itself (serial only): contact, where it is on,
            # keeps the skin off the chest below the fold, not the body off itself
            "self_overlap": self_overlap(self.mesh, u) if self.comm.size == 1 else None,
            "contact": problem.contact_status(),
            "self_contact": problem.self_contact_status(),
            "dofs": dofs,
            "linear_path": self.solver.linear_path,
            "wall_s": {
                "setup": self.setup_s,
                **{k: timings[k] for k in ("solve", "assembly", "linear_solve")},
            },
            "cpu_s": {"solve": timings["solve_cpu"]},
            "residual_evaluations": timings["residual_evaluations"],
            "jacobian_evaluations": timings["jacobian_evaluations"],
            "preconditioner_builds": timings["preconditioner_builds"],
            "linear_iterations": result.linear_iterations,
            "linear_system_s": linear_s,
            "factorization_equivalents": timings["solve"] / linear_s if linear_s else None,
            "mpi_size": self.comm.size,
            "mesh": str(self.mesh_path),
            "settings": self.settings.describe(self.solver.options),
        }

    def write(self, outdir: str | Path, summary: dict[str, Any]) -> dict[str, Any]:
        """Write the case's files atomically; returns the completed summary."""
        start = time.perf_counter()
        problem = self.problem
        writer = CaseWriter(outdir, self.comm)
        u = problem.displacement()
        write_fields(writer.path("fields.xdmf"), self.mesh, u, problem.pressure(), problem.J)
        points = gather_vertex_values(self.mesh, u)
        fixed = gather_boundary_vertices(
            self.mesh, self.facet_tags, self.settings.fixed.fully_fixed()
        )
        X = gather_vertex_coordinates(self.mesh)
        if self.comm.rank == 0:
            index, values = points
            write_points(
                writer.path("points.h5"), index, X[1], values, fixed[1], case=summary["case"]
            )
            summary["mean_disp_mm"] = float(1e3 * np.mean(np.linalg.norm(values, axis=1)))
            summary["num_points"] = int(index.size)
        summary["wall_s"]["output"] = time.perf_counter() - start
        summary["wall_s"]["total"] = sum(summary["wall_s"][k] for k in ("setup", "solve", "output"))
        # Unix times: the solving process's start (one per job) and this case's end
        summary["clock"] = clock()
        writer.commit(summary)
        return summary


def run_case(
    mesh_path: str | Path,
    case: Case,
    outdir: str | Path,
    settings: SolverSettings = SolverSettings(),
) -> dict[str, Any]:
    """Solve one case and write its outputs; the public entry point of the solver.

    Inputs are validated before anything is written: a bad parameter or mesh raises
    with a message naming the problem and leaves ``outdir`` untouched. A case whose
    load path cannot be completed is *not* an error: its summary says
    ``status: failed``, with the load fraction reached and why, and its fields hold
    the last converged state.
    """
    runner = CaseRunner(mesh_path, settings)
    result, timings = runner.solve(case)
    summary = runner.summary(case, result, timings)
    log.info(
        "%s: %s in %d steps (%s Newton its), max |u| = %.2f mm, %.2f s",
        case.id,
        summary["status"],
        summary["load_steps"],
        summary["newton_iterations"],
        summary["max_disp_mm"],
        timings["solve"],
    )
    return runner.write(outdir, summary)
