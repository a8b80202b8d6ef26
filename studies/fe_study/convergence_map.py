"""Where the nonlinear solve fails: load steps, Newton iterations and failures over (C1, Φ).

For every loading scheme (adaptive, and fixed-step baselines) and every (C1, Φ) of a
grid reaching below the paper's C1 range, one solve from rest is recorded: whether
it converged, the load fraction reached, accepted and rejected increments, Newton
iterations, the first failure and the classes of all failures (Newton, line search,
inverted element, NaN residual, linear solver), time, and the largest displacement.

:func:`lowest_converging` reads off, per scheme and Φ, the lowest C1 from which every
grid value upwards converged, and what failed first at the next C1 below it;
:func:`sweep_records` makes the same records of a sweep's dataset.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from fem.parameters import Loading, SolverSettings
from fem.sweep import Case
from studies.results import Record, Result

log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True)
class ConvergenceRecord(Record):
    """One solve of the convergence map's grid (or one case of the sweep, ``scheme`` "sweep")."""

    scheme: str
    C1: float
    phi: float
    converged: bool
    load_fraction: float
    reason: str
    first_failure: str
    failure_kinds: dict[str, int]
    load_steps: int | None = None
    rejected_steps: int | None = None
    newton_iterations: int | None = None
    newton_iterations_accepted: int | None = None
    wall_s: float | None = None
    cpu_s: float | None = None
    max_disp_mm: float | None = None
    min_detF: float | None = None
    theta: float | None = None


@dataclass(frozen=True, slots=True)
class ConvergenceMap(Result):
    """``results/fe_study/convergence_map.json``: every (scheme, C1, Φ) solved once from rest.

    ``lowest_converging`` is :func:`lowest_converging` of the records: per scheme, per Φ (keys
    "%.1f") the lowest converging C1 and the first failure below it, and ``all_phi``.
    """

    mesh: str
    dofs: int
    settings: dict[str, Any]
    schemes: dict[str, dict[str, Any]]
    C1_kPa: list[float]
    phi_deg: list[float]
    records: list[ConvergenceRecord]
    lowest_converging: dict[str, dict[str, Any]]


def loading_schemes(adaptive: Loading, fixed_steps: list[int]) -> dict[str, Loading]:
    """The adaptive scheme and one fixed-step baseline per entry of ``fixed_steps``."""
    schemes = {"adaptive": adaptive}
    for n in fixed_steps:
        schemes[f"fixed-{n}"] = replace(adaptive, fixed_steps=int(n))
    return schemes


def convergence_map(
    mesh_path: str | Path,
    settings: SolverSettings,
    C1_kPa: list[float],
    phi_deg: list[float],
    schemes: dict[str, Loading],
) -> ConvergenceMap:
    """Solve every (scheme, C1, Φ) once from rest and record how it went."""
    from fem.case import CaseRunner

    runner = CaseRunner(mesh_path, settings)
    records = []
    for name, loading in schemes.items():
        runner.settings = replace(settings, loading=loading)
        for c1 in sorted(C1_kPa, reverse=True):
            for phi in phi_deg:
                case = Case(c1, phi)
                start = time.perf_counter()
                result, timings = runner.solve(case)
                u = runner.problem.displacement().x.array.reshape(-1, 3)
                records.append(
                    {
                        "scheme": name,
                        "C1": case.C1,
                        "phi": case.phi,
                        "converged": bool(result.converged),
                        "load_fraction": result.fraction,
                        "reason": result.reason,
                        "load_steps": len(result.accepted),
                        "rejected_steps": len(result.attempts) - len(result.accepted),
                        "newton_iterations": result.total_iterations,
                        "newton_iterations_accepted": int(sum(result.newton_iterations)),
                        "first_failure": result.first_failure,
                        "failure_kinds": result.failure_kinds,
                        "wall_s": time.perf_counter() - start,
                        "cpu_s": timings["solve_cpu"],
                        "max_disp_mm": 1e3 * float(np.linalg.norm(u, axis=1).max(initial=0.0)),
                        "min_detF": runner.problem.min_detF(),
                    }
                )
                log.info(
                    "%s C1=%.2f phi=%.1f: %s at %.3f in %d steps (%d rejected), %d its",
                    name, c1, phi, "converged" if result.converged else "FAILED", result.fraction,
                    len(result.accepted), len(result.attempts) - len(result.accepted),
                    result.total_iterations,
                )
    out = {
        "mesh": str(mesh_path),
        "dofs": runner.problem.num_dofs(),
        "settings": settings.describe(runner.solver.options),
        "schemes": {
            name: {
                "fixed_steps": s.fixed_steps,
                "initial_step": s.initial_step,
                "max_steps": s.max_steps,
                "min_step": s.min_step,
                "rescue": s.rescue and not s.fixed_steps,
                "rescue_min_step": s.rescue_min_step,
            }
            for name, s in schemes.items()
        },
        "C1_kPa": sorted(C1_kPa),
        "phi_deg": list(phi_deg),
        "records": records,
        "lowest_converging": lowest_converging(records),
    }
    runner.solver.destroy()
    return ConvergenceMap.from_json(out)


def sweep_records(cases: Mapping[str, Sequence[Any]]) -> list[dict[str, Any]]:
    """The θ = 0 cases of a sweep as records of :func:`lowest_converging` (scheme ``"sweep"``).

    The sweep is a convergence map at the paper's own resolution, on the mesh the
    dataset was solved on, which the FE study's coarse grid is not.

    Args:
        cases: per-case columns ``C1``, ``phi``, ``theta``, ``converged``,
            ``load_fraction``, ``first_failure`` and ``reason`` (the dataset's ``/cases``).
    """
    records = []
    for i in range(len(cases["C1"])):
        if float(cases["theta"][i]) != 0.0:
            continue
        first = str(cases["first_failure"][i])
        records.append(
            {
                "scheme": "sweep",
                "C1": float(cases["C1"][i]),
                "phi": float(cases["phi"][i]),
                "converged": bool(cases["converged"][i]),
                "load_fraction": float(cases["load_fraction"][i]),
                "first_failure": first,
                "failure_kinds": {},  # the dataset keeps the first failure only
                "reason": str(cases["reason"][i]),
            }
        )
    return records


def lowest_converging(records: list[dict[str, Any]]) -> dict[str, dict[str, Any]]:
    """Per scheme and Φ: the lowest C1 from which every C1 upwards converged.

    Returns:
        ``{scheme: {phi: {"lowest_C1": float | None, "failed_below": {C1, first_failure,
        failure_kinds, load_fraction} | None}}}`` plus, per scheme, ``"all_phi"``: the
        lowest C1 from which every case of every Φ converged (the highest ``lowest_C1``
        among the Φ where a case failed; where none failed, the lowest C1 solved). A Φ
        solved only from a stiffer C1 (a refinement band's) does not raise it: nothing
        failed there.
    """
    out: dict[str, dict[str, Any]] = {}
    schemes = sorted({r["scheme"] for r in records})
    for scheme in schemes:
        rows = [r for r in records if r["scheme"] == scheme]
        per_phi: dict[str, Any] = {}
        for phi in sorted({r["phi"] for r in rows}):
            column = sorted((r for r in rows if r["phi"] == phi), key=lambda r: -r["C1"])
            lowest, below = None, None
            for r in column:  # from stiff to soft
                if not r["converged"]:
                    below = {
                        k: r[k]
                        for k in ("C1", "first_failure", "failure_kinds", "load_fraction", "reason")
                    }
                    break
                lowest = r["C1"]
            per_phi[f"{phi:.1f}"] = {"lowest_C1": lowest, "failed_below": below}
        failed = [v["lowest_C1"] for v in per_phi.values() if v["failed_below"] is not None]
        if any(v is None for v in failed):
            per_phi["all_phi"] = None  # a Φ failed at its stiffest C1
        elif failed:
            per_phi["all_phi"] = max(failed)
        else:
            per_phi["all_phi"] = min(v["lowest_C1"] for v in per_phi.values())
        out[scheme] = per_phi
    return out


__all__ = ["loading_schemes", "lowest_converging", "convergence_map", "sweep_records"]
