"""FE benchmarks: clinical-case timings, accuracy against a reference, speed against accuracy.

Everything here is measured, nothing is assumed:

* :func:`solve_reference` solves the clinical cases on a refined discretisation and
  evaluates its displacement at the material points (the default mesh's vertices);
* :func:`fe_clinical` times the clinical cases at the default settings on one
  core, each followed by the same case with a fixed 10-step Newton baseline in the same
  process (so their ratio is free of machine speed), and compares the displacement
  with the reference;
* :func:`run_variant` does the same for one point of the speed-accuracy study (a mesh
  size × element × solver preset); :func:`summarise_fe_variants` marks the Pareto front
  and the cheapest variant meeting the accuracy target.

Timings are wall-clock seconds of the nonlinear solve (set-up, i.e. mesh reading and
form compilation, is reported separately), next to CPU seconds and the load average so
that a reader can tell a busy machine from a slow solver.
"""

from __future__ import annotations

import logging
import statistics
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from fem.overlap import self_overlap
from fem.parameters import SolverSettings
from fem.sweep import Case
from studies.fe_study.fe_timing import TimedSolve, timed_solve, vertex_displacement
from studies.results import Record, Result
from studies.timing_hygiene import machine_state, timed_on_one_core

log = logging.getLogger(__name__)

#: Issue 4's targets for the default discretisation on the clinical cases.
TARGETS = {
    "median_wall_s": 8.0,  # per case, one core
    "factorization_equivalents": 6.0,  # each case
    "relative_max_error": 0.01,  # max |u - u_ref| / max |u_ref|, each case
}


@dataclass(frozen=True, slots=True)
class Target(Record):
    """A measure against its target."""

    target: float
    value: float | None
    met: bool


@dataclass(frozen=True, slots=True)
class ClinicalSummary(Record):
    """The clinical benchmark over its cases, and its targets."""

    median_wall_s: float
    median_cpu_s: float
    max_factorization_equivalents: float
    median_baseline_over_adaptive_wall: float
    max_relative_error: float | None
    all_converged: bool
    targets: dict[str, Target]


@dataclass(frozen=True, slots=True)
class FEClinical(Result):
    """``results/fe_study/fe_clinical.json``: the default discretisation on the clinical cases."""

    mesh: str
    dofs: int
    material_points: int
    setup_s: float
    settings: dict[str, Any]
    baseline_steps: int
    repeats: int
    cases: list[TimedSolve]
    summary: ClinicalSummary
    machine: dict[str, Any]
    reference: dict[str, dict[str, Any]]
    labels: dict[str, str] = field(default_factory=dict)


# -- the clinical benchmark ------------------------------------------------------------------------
def accuracy_at_vertices(runner: Any, reference: Any | None) -> dict[str, Any] | None:
    """Errors of a solved runner at its own vertices against a reference field.

    Args:
        runner: a solved serial :class:`fem.case.CaseRunner`.
        reference: the reference displacement (a dolfinx Function on its own mesh), or None.

    Returns:
        :func:`studies.fe_study.accuracy.displacement_errors` plus how far the farthest vertex lay
        outside the reference mesh (``max_outside_m``), or None without a reference.
    """
    from fem.interpolation import evaluate
    from studies.fe_study.accuracy import displacement_errors

    if reference is None:
        return None
    _, X, u = vertex_displacement(runner)
    u_ref, distance = evaluate(reference, X)
    return {**displacement_errors(u, u_ref), "max_outside_m": float(distance.max())}


@timed_on_one_core
def fe_clinical(
    mesh_path: str | Path,
    settings: SolverSettings,
    cases: list[Case],
    references: dict[str, tuple[Any, dict[str, Any]]],
    baseline_steps: int = 10,
    repeats: int = 1,
    labels: dict[str, str] | None = None,
) -> FEClinical:
    """Time and check the clinical cases at the default discretisation.

    Args:
        mesh_path: the default mesh (its vertices are the material points).
        settings: the default solver settings.
        cases: the clinical cases.
        references: case id -> ``(field, meta)`` of
            :func:`studies.fe_study.fe_reference.load_displacement`.
        baseline_steps: equal load steps of the fixed-step Newton baseline.
        repeats: solves per case; the median wall time is reported.
        labels: case id -> the config's label of the case.

    Returns:
        Per-case records (timings, baseline, accuracy, :func:`fem.overlap.self_overlap`) and
        a summary against :data:`TARGETS`, all measured on one pinned core
        (:func:`studies.timing_hygiene.one_core`).
    """
    from fem.case import CaseRunner

    state_before = machine_state().to_json()
    runner = CaseRunner(mesh_path, settings)
    baseline_loading = replace(settings.loading, fixed_steps=baseline_steps)
    rows = []
    for case in cases:
        runs = [timed_solve(runner, case) for _ in range(repeats)]
        record = dict(sorted(runs, key=lambda r: r["wall_s"])[len(runs) // 2])
        record["wall_s_repeats"] = [r["wall_s"] for r in runs]
        node_index, _, u = vertex_displacement(runner)
        record["max_disp_mm"] = 1e3 * float(np.linalg.norm(u, axis=1).max())
        record["mean_disp_mm"] = 1e3 * float(np.linalg.norm(u, axis=1).mean())
        reference = references.get(case.id)
        record["accuracy"] = accuracy_at_vertices(runner, reference[0] if reference else None)
        record["self_overlap"] = self_overlap(runner.mesh, runner.problem.displacement())
        baseline = timed_solve(runner, case, baseline_loading)
        _, _, u_base = vertex_displacement(runner)
        baseline["max_difference_from_adaptive_mm"] = 1e3 * float(np.abs(u_base - u).max())
        record["baseline"] = baseline
        record["baseline_over_adaptive_wall"] = baseline["wall_s"] / record["wall_s"]
        record["baseline_over_adaptive_cpu"] = baseline["cpu_s"] / record["cpu_s"]
        rows.append(record)
        log.info(
            "%s: %.2f s (FE %.2f, %s its), baseline %.2f s, error %s",
            case.id,
            record["wall_s"],
            record["factorization_equivalents"],
            record["newton_iterations"],
            baseline["wall_s"],
            f"{100 * record['accuracy']['relative_max_error']:.2f} %"
            if record["accuracy"]
            else "n/a",
        )
    walls = [r["wall_s"] for r in rows]
    fe = [r["factorization_equivalents"] for r in rows]
    errors = [r["accuracy"]["relative_max_error"] for r in rows if r["accuracy"]]
    summary = {
        "median_wall_s": statistics.median(walls),
        "median_cpu_s": statistics.median(r["cpu_s"] for r in rows),
        "max_factorization_equivalents": max(fe),
        "median_baseline_over_adaptive_wall": statistics.median(
            r["baseline_over_adaptive_wall"] for r in rows
        ),
        "max_relative_error": max(errors) if errors else None,
        "all_converged": all(r["converged"] for r in rows),
    }
    summary["targets"] = {
        "median_wall_s": {
            "target": TARGETS["median_wall_s"],
            "value": summary["median_wall_s"],
            "met": summary["median_wall_s"] <= TARGETS["median_wall_s"],
        },
        "factorization_equivalents": {
            "target": TARGETS["factorization_equivalents"],
            "value": summary["max_factorization_equivalents"],
            "met": summary["max_factorization_equivalents"] <= TARGETS["factorization_equivalents"],
        },
        "relative_max_error": {
            "target": TARGETS["relative_max_error"],
            "value": summary["max_relative_error"],
            "met": bool(errors) and max(errors) <= TARGETS["relative_max_error"],
        },
    }
    out = {
        "mesh": str(mesh_path),
        "dofs": runner.problem.num_dofs(),
        "material_points": int(len(node_index)),
        "setup_s": runner.setup_s,
        "settings": settings.describe(runner.solver.options),
        "baseline_steps": baseline_steps,
        "repeats": repeats,
        "cases": rows,
        "summary": summary,
        "machine": {"before": state_before, "after": machine_state().to_json()},
        "reference": {cid: meta for cid, (_, meta) in references.items()},
        "labels": dict(labels or {}),
    }
    runner.solver.destroy()
    return FEClinical.from_json(out)
