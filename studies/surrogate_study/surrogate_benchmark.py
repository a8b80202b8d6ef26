"""The surrogate's benchmark: its goals measured in one job, FE and surrogate on the same core.

Goals (issue 6): best validation error ≤ 0.10 mm; worst clinical-case error (Eq. 3,
by-sample split) ≤ 0.5 mm and ≤ 1.5 % of the case's largest displacement; a
whole-field prediction ≤ 0.5 ms after warm-up on one CPU core; 3x32 trained on the
full dataset in ≤ 5 min. The FE/surrogate speed ratio is measured in the same run:
this process pins itself to one core, solves the clinical cases there with the
project's FE solver (:class:`fem.case.CaseRunner`, setup excluded as the
surrogate's loading is), and times the surrogate in a subprocess pinned to the
same core.
"""

from __future__ import annotations

import logging
import os
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from studies import paper
from studies.results import Record, Result
from studies.surrogate_study.architecture import ArchitectureTable
from studies.surrogate_study.surrogate_evaluation import ClinicalEvaluation
from studies.surrogate_study.timing import time_on_one_core
from studies.timing_hygiene import MachineState, machine_state

log = logging.getLogger(__name__)

GOALS = {
    "validation_error_mm": 0.10,
    "worst_clinical_rmse_mm": 0.5,
    "worst_clinical_relative_rmse": 0.015,
    "predict_one_core_ms": 0.5,
    "train_3x32_s": 300.0,
}


@dataclass(frozen=True, slots=True)
class Goal(Record):
    """A benchmark figure against its goal."""

    value: float | None
    goal: float
    met: bool


@dataclass(frozen=True, slots=True)
class SpeedRow(Record):
    """One clinical case: FE solve and surrogate prediction on the same core (Table 4)."""

    case: str
    fe_solve_s: float
    surrogate_ms: float
    speedup: float
    paper: dict[str, float] | None


@dataclass(frozen=True, slots=True)
class SurrogateBenchmark(Result):
    """``results/surrogate/surrogate_benchmark.json``: the surrogate's goals measured in one job."""

    machine: MachineState
    selected_architecture: str
    validation_error_mm: dict[str, Any]
    clinical_worst: dict[str, Any]
    predict_one_core: dict[str, Any]
    predict_one_core_eigen_single_thread: dict[str, Any]
    timing_process: dict[str, Any]
    fe: dict[str, dict[str, Any]]
    speed: list[SpeedRow]
    train_3x32_s: dict[str, Any] | None
    goals: dict[str, Goal]
    paper: dict[str, Any]
    ablations: dict[str, Any] | None = None


def fe_timings(mesh: str | Path, cases: Sequence[Any], settings: Any) -> dict[str, dict[str, Any]]:
    """Solve each case once with the project's FE solver in this process; wall times in s."""
    from fem.case import CaseRunner

    runner = CaseRunner(mesh, settings)
    out = {}
    for case in cases:
        start = time.perf_counter()
        result, timings = runner.solve(case)
        out[case.id] = {
            "solve_s": timings["solve"],
            "wall_s": time.perf_counter() - start,
            "setup_s": runner.setup_s,
            "converged": bool(result.converged),
            "load_steps": len(result.accepted),
            "newton_iterations": int(sum(result.newton_iterations)),
        }
        log.info("FE %s: %.2f s (%s)", case.id, timings["solve"], result.reason)
    return out


def _goal(value: float | None, goal: float) -> dict[str, Any]:
    ok = value is not None and np.isfinite(value) and value <= goal
    return {"value": value, "goal": goal, "met": bool(ok)}


def run_benchmark(
    model_dir: str | Path,
    mesh: str | Path,
    clinical_cases: Sequence[Any],
    settings: Any,
    table: ArchitectureTable,
    clinical: ClinicalEvaluation,
    repeats: int = 2000,
    core: int | None = None,
) -> dict[str, Any]:
    """Measure everything the goals need; returns the benchmark record.

    Args:
        model_dir: the selected model.
        mesh: the FE mesh.
        clinical_cases: :class:`fem.sweep.Case` objects of the clinical cases.
        settings: FE solver settings (:class:`fem.parameters.SolverSettings`).
        table: the architecture study (its file, ``results/surrogate/study/table2.json``).
        clinical: the clinical evaluation (``results/surrogate/clinical.json``).
        repeats: timed surrogate predictions.
        core: CPU to pin to (default: the lowest this process may use).
    """
    core = min(os.sched_getaffinity(0)) if core is None else core
    allowed = os.sched_getaffinity(0)
    os.sched_setaffinity(0, {core})
    try:
        queries = [(c.C1, c.phi, c.theta) for c in clinical_cases]
        surrogate = time_on_one_core([model_dir], queries, repeats=repeats, core=core)
        surrogate_single = time_on_one_core([model_dir], queries, repeats=repeats, core=core,
                                            single_thread=True)
        fe = fe_timings(mesh, clinical_cases, settings)
    finally:
        os.sched_setaffinity(0, allowed)
    timing = surrogate["models"][str(model_dir)]
    predict_ms = timing["api"]["median_ms"]
    ratios = {cid: v["solve_s"] / (predict_ms * 1e-3) for cid, v in fe.items()}

    selected = table.rows[table.selected_architecture]
    by_sample = (clinical.by_sample.worst if clinical.by_sample else None) or {}
    by_case = (clinical.by_case.worst if clinical.by_case else None) or {}
    row_3x32 = table.rows.get("3x32")
    rows = []
    for c in clinical_cases:
        published = paper.table4_row(c.C1, c.phi)
        rows.append({
            "case": c.id, "fe_solve_s": fe[c.id]["solve_s"], "surrogate_ms": predict_ms,
            "speedup": ratios[c.id],
            "paper": None if published is None else {
                "fe_s": published["fe_s"][0], "surrogate_s": published["surrogate_s"][0],
                "speedup": published["fe_s"][0] / published["surrogate_s"][0]},
        })
    return {
        "machine": machine_state(pinned_core=core).to_json(),
        "selected_architecture": table.selected_architecture,
        "validation_error_mm": {
            "selected_mean": selected.validation_error_mm.mean,
            "selected_sd": selected.validation_error_mm.sd,
            "selected_run": selected.best_validation_error_mm,
        },
        "clinical_worst": {"by_sample": by_sample, "by_case": by_case},
        "predict_one_core": timing,
        "predict_one_core_eigen_single_thread": surrogate_single["models"][str(model_dir)],
        "timing_process": {k: v for k, v in surrogate.items() if k != "models"},
        "fe": fe,
        "speed": rows,
        "train_3x32_s": None if row_3x32 is None else row_3x32.train_s.to_json(),
        "goals": {
            "validation_error_mm": _goal(
                selected.best_validation_error_mm, GOALS["validation_error_mm"]
            ),
            "worst_clinical_rmse_mm": _goal(
                by_sample.get("rmse_mm"), GOALS["worst_clinical_rmse_mm"]
            ),
            "worst_clinical_relative_rmse": _goal(
                by_sample.get("relative_rmse"), GOALS["worst_clinical_relative_rmse"]
            ),
            "predict_one_core_ms": _goal(predict_ms, GOALS["predict_one_core_ms"]),
            "train_3x32_s": _goal(None if row_3x32 is None else row_3x32.train_s.mean,
                                  GOALS["train_3x32_s"]),
        },
        "paper": {
            "validation_error_mm": paper.TABLE2["3x32"]["validation_error_mm"],
            "worst_clinical_rmse_mm": 1.04,
            "worst_clinical_relative_rmse": 1.04 / 38.4,
            "predict_s": (2.0, 2.4),
            "speedup": paper.SPEEDUP_RANGE,
            "train_3x32_s": 3155.0,
        },
    }


def format_benchmark(bench: dict[str, Any]) -> str:
    """Human-readable summary of :func:`run_benchmark`'s record."""
    g = bench["goals"]
    t = bench["predict_one_core"]
    lines = [
        f"surrogate benchmark ({bench['selected_architecture']}, "
        f"core {bench['machine']['pinned_core']}, "
        f"load {bench['machine']['load_average_1_5_15min'][0]:.2f})",
    ]
    for name, item in g.items():
        value = item["value"]
        shown = "n/a" if value is None else f"{value:.4g}"
        lines.append(
            f"  {name:30s} {shown:>10s}  goal <= {item['goal']:g}  "
            f"{'met' if item['met'] else 'NOT met'}"
        )
    lines.append(
        f"  prediction ({t['points']} points): median {t['api']['median_ms']:.3f} ms "
        f"(network alone {t['network']['median_ms']:.3f} ms, p95 {t['api']['p95_ms']:.3f} ms)"
    )
    for row in bench["speed"]:
        lines.append(
            f"  {row['case']}: FE {row['fe_solve_s']:.2f} s, "
            f"surrogate {row['surrogate_ms']:.3f} ms, "
            f"FE/surrogate = {row['speedup']:.3g}x"
        )
    return "\n".join(lines)
