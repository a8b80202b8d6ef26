"""Speed against accuracy: one study variant timed on the clinical cases, and the Pareto front.

:func:`run_variant` times one variant (a mesh size x element x solver preset) on the
clinical cases on one pinned core and measures its error at its own material points
against the reference; :func:`summarise_fe_variants` marks the Pareto front (cost against
the worst relative error) and the cheapest variant meeting the accuracy target.
"""

from __future__ import annotations

import logging
import statistics
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from fem.overlap import self_overlap
from fem.parameters import SolverSettings
from fem.sweep import Case
from studies.fe_study.fe_clinical import TARGETS, accuracy_at_vertices
from studies.fe_study.fe_timing import TimedSolve, timed_solve
from studies.fe_study.fe_variants import FEVariant
from studies.results import Result
from studies.timing_hygiene import machine_state, timed_on_one_core

log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True)
class FEVariantRecord(Result):
    """``results/fe_study/speed_accuracy/<variant>.json``: one variant on the clinical cases.

    A variant above the study's DOF limit is recorded with ``skipped`` and no cases.
    """

    variant: str
    mesh: dict[str, Any]
    element: str
    solver: str
    quadrature_degree: int
    dofs: int
    cells: int
    material_points: int
    setup_s: float
    machine: dict[str, Any]
    skipped: str | None = None
    cases: list[TimedSolve] = field(default_factory=list)
    median_wall_s: float | None = None
    median_cpu_s: float | None = None
    max_factorization_equivalents: float | None = None
    max_relative_error: float | None = None
    max_error_mm: float | None = None
    max_overlapping_vertices: int | None = None
    pareto: bool | None = None

    def cost(self, name: str) -> float | None:
        """The cost measure ``name`` (``median_cpu_s`` or ``median_wall_s``)."""
        if name not in ("median_cpu_s", "median_wall_s"):
            raise ValueError(f"unknown cost measure {name!r}")
        return getattr(self, name)


@dataclass(frozen=True, slots=True)
class SpeedAccuracy(Result):
    """``results/fe_study/speed_accuracy.json``: every variant, the Pareto front, the verdict."""

    target_relative_max_error: float
    cost: str
    variants: list[FEVariantRecord]
    pareto_front: list[str]
    cheapest_meeting_target: str | None
    default_variant: str | None = None


@timed_on_one_core
def run_variant(
    mesh_path: str | Path,
    variant: FEVariant,
    base: SolverSettings,
    cases: list[Case],
    references: dict[str, tuple[Any, dict[str, Any]]],
    max_dofs: int | None = None,
) -> FEVariantRecord:
    """Time one study variant on the clinical cases and measure its error at its material points.

    The material points of a variant are its own mesh's vertices (as the dataset's are
    the default mesh's); the reference is evaluated there. A variant above ``max_dofs``
    is recorded as skipped (with its DOF count), not solved. Timed on one pinned core.
    """
    from fem.case import CaseRunner

    settings = variant.settings(base)
    runner = CaseRunner(mesh_path, settings)
    dofs = runner.problem.num_dofs()
    record: dict[str, Any] = {
        "variant": variant.id,
        "mesh": variant.mesh.size_mapping(),
        "element": variant.element,
        "solver": variant.solver,
        "quadrature_degree": settings.discretisation.quadrature,
        "dofs": dofs,
        "cells": runner.mesh.topology.index_map(3).size_global,
        "material_points": runner.mesh.topology.index_map(0).size_global,
        "setup_s": runner.setup_s,
        "machine": machine_state().to_json(),
    }
    if max_dofs is not None and dofs > max_dofs:
        record["skipped"] = f"{dofs} dofs exceed fe_study.speed_accuracy.max_dofs = {max_dofs}"
        runner.solver.destroy()
        return FEVariantRecord.from_json(record)
    rows = []
    for case in cases:
        row = timed_solve(runner, case)
        reference = references.get(case.id)
        if row["converged"]:
            row["self_overlap"] = self_overlap(runner.mesh, runner.problem.displacement())
            if reference is not None:
                row["accuracy"] = accuracy_at_vertices(runner, reference[0])
        rows.append(row)
        log.info("%s %s: %.2f s, error %s", variant.id, case.id, row["wall_s"],
                 row["accuracy"]["relative_max_error"] if row.get("accuracy") else "n/a")
    record["cases"] = rows
    ok = [r for r in rows if r.get("accuracy")]
    record["median_wall_s"] = statistics.median(r["wall_s"] for r in rows)
    record["median_cpu_s"] = statistics.median(r["cpu_s"] for r in rows)
    record["max_factorization_equivalents"] = max(r["factorization_equivalents"] for r in rows)
    record["max_relative_error"] = (
        max(r["accuracy"]["relative_max_error"] for r in ok) if len(ok) == len(rows) else None
    )
    record["max_error_mm"] = (
        max(r["accuracy"]["max_error_mm"] for r in ok) if len(ok) == len(rows) else None
    )
    record["max_overlapping_vertices"] = max(
        (r["self_overlap"]["overlapping_vertices"] for r in rows if "self_overlap" in r),
        default=None,
    )
    runner.solver.destroy()
    return FEVariantRecord.from_json(record)


def pareto_front(costs: list[float], errors: list[float]) -> list[bool]:
    """Points no other point beats in both cost and error.

    A point is beaten by one at most as costly and at most as wrong, and better in one of the two.
    """
    flags = []
    for i, (c, e) in enumerate(zip(costs, errors, strict=True)):
        dominated = any(
            (c2 <= c and e2 <= e) and (c2 < c or e2 < e)
            for j, (c2, e2) in enumerate(zip(costs, errors, strict=True))
            if j != i
        )
        flags.append(not dominated)
    return flags


def summarise_fe_variants(
    records: list[FEVariantRecord],
    target: float = TARGETS["relative_max_error"],
    cost: str = "median_cpu_s",
    default_variant: str | None = None,
) -> SpeedAccuracy:
    """Mark the Pareto front and the cheapest variant that meets ``target``.

    The front is of cost against the worst-case relative error.

    Args:
        records: :func:`run_variant` records.
        target: accuracy target on the max relative error over the clinical cases.
        cost: the cost measure (CPU seconds are robust to a shared machine; wall
            seconds are what a user waits).
        default_variant: the id of the variant the workflow's own settings amount to.
    """
    solved = [r for r in records if not r.skipped and r.max_relative_error is not None]
    flags = pareto_front([r.cost(cost) for r in solved], [r.max_relative_error for r in solved])
    pareto = {r.variant: flag for r, flag in zip(solved, flags, strict=True)}
    records = [replace(r, pareto=pareto[r.variant]) if r.variant in pareto else r for r in records]
    meeting = sorted(
        (r for r in records if r.variant in pareto and r.max_relative_error <= target),
        key=lambda r: r.cost(cost),
    )
    return SpeedAccuracy(
        target_relative_max_error=target,
        cost=cost,
        variants=records,
        pareto_front=[r.variant for r in records if r.pareto],
        cheapest_meeting_target=meeting[0].variant if meeting else None,
        default_variant=default_variant,
    )
