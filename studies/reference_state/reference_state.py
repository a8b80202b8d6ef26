"""The reference state of the workflow's imaged mesh, with its cost in forward solves.

The rule ``reference_state`` (with ``reference_state.imaged`` set) calls
:func:`reference_of_imaged`: one cold forward solve of the imaged case on the imaged shape (the
unit of cost), then :func:`fem.reference.estimate_reference`, then the reference mesh (the
imaged file's cells, tags and numbering) and ``reference.json``. An estimate that does not
converge writes neither: the job fails with the reason.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from studies.results import Result
from studies.timing_hygiene import machine_state


class NoReferenceError(RuntimeError):
    """No reference state reproduces the imaged shape within the iteration budget."""


@dataclass(frozen=True)
class ReferenceRecord(Result):
    """``results/mesh/reference.json``: how the reference of the imaged mesh was found.

    The keys of ``python -m fem.reference``'s ``reference.json`` (``imaged``, ``case``,
    :meth:`fem.reference.ReferenceEstimate.record`), with the cost beside
    them; one reader serves both (the command's file lacks the cost and the machine).

    Attributes:
        imaged: the imaged mesh.
        case: the imaged case (the stiffness assumed and the posture).
        converged: the estimate converged.
        reason: why it stopped.
        forward_solves: forward solves of the estimate.
        misfit_mm: the largest node misfit after each.
        newton_iterations: Newton iterations of each.
        warm_starts: solves that converged from the previous iterate's state.
        relaxation: Aitken's ω at each update (the ``aitken`` method).
        method: how the reference was found (:data:`fem.reference.METHODS`).
        restarts: Anderson histories dropped after a mixed iterate's solve failed.
        wall_s: the estimate's wall time.
        cold_forward_s: one cold forward solve of the imaged case on the imaged shape.
        cost: ``wall_s`` over ``cold_forward_s``.
        largest_shift_mm: the largest node distance between the imaged shape and the reference.
        machine: where it ran.
        inverse_newton_iterations: Newton iterations of the inverse-motion solve that started the
            estimate (None without one).
        inverse_s: its wall time, within ``wall_s``.
    """

    imaged: str
    case: str
    converged: bool
    reason: str
    forward_solves: int
    misfit_mm: list[float]
    newton_iterations: list[int]
    warm_starts: int
    relaxation: list[float]
    method: str
    restarts: int
    wall_s: float
    cold_forward_s: float
    cost: float
    largest_shift_mm: float
    machine: dict[str, Any]
    inverse_newton_iterations: int | None = None
    inverse_s: float | None = None


def reference_of_imaged(imaged: str | Path, settings: Any, c1: float, phi: float, theta: float,
                        tolerance: float, xdmf_out: str | Path, record_out: str | Path
                        ) -> ReferenceRecord:
    """Estimate the imaged mesh's reference; write the mesh and the record.

    Raises:
        NoReferenceError: with the estimate's reason, before anything is written.
    """
    from fem.case import CaseRunner
    from fem.reference import estimate_reference, write_reference_mesh
    from fem.sweep import Case

    case = Case(c1, phi, theta)
    with CaseRunner(imaged, settings) as runner:
        start = time.perf_counter()
        runner.solve(case)  # the unit of cost: a cold forward solve on the imaged shape
        cold = time.perf_counter() - start
        estimate = estimate_reference(runner, case.material(settings.density),
                                      case.gravity(settings.gravity), tolerance=tolerance)
        if not estimate.converged:
            raise NoReferenceError(f"no reference state for {imaged} as {case.id}: "
                                   f"{estimate.reason}")
        # the keys of python -m fem.reference's reference.json, and the cost beside them
        record = ReferenceRecord(
            imaged=str(imaged), case=case.id, **estimate.record(),
            cold_forward_s=cold, cost=estimate.wall_s / cold, machine=machine_state().to_json(),
        )
        write_reference_mesh(runner, estimate.X, xdmf_out)
        record.write(record_out)
    return record


__all__ = ["NoReferenceError", "ReferenceRecord", "reference_of_imaged"]
