"""The surrogate at random cases off its sweep's grid, against FE: what a user meets.

The held-out study (:mod:`studies.surrogate_study.held_out`) retrains the model with whole
directions or C1
values left out, a pessimistic estimate of the error between the sweep's points. This asks
the model actually used, at ``surrogate_study.off_grid``'s cases: C1 and gravity drawn at
random within the sweep's range (:func:`fem.sweep.random_cases`), each solved by FE outside
the sweep. Each case's error is taken at the material points and, on a quadratic mesh, at its
cells' centroids, between them (:func:`studies.surrogate_study.postures.evaluate_postures`); the
set's spread
is set beside the goals of issue 23: a mean point error of 0.05 mm and a largest point error
of 0.5 mm at any case off the grid, the largest taken at the material points and between them
(a tumour lies anywhere).

``python -m studies.surrogate_study.off_grid MODEL CASE_DIR... [--json OUT]`` does the same for any
case
folders solved outside the workflow (``python -m fem.chain`` or ``fem.cli``): each case's
errors, and their spread per C1 value and over all, beside the goals.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from studies.results import Result, write_json
from studies.surrogate_study.errors_against_fe import ErrorSpread
from studies.surrogate_study.postures import PostureRow, evaluate_postures
from surrogate.predict import Surrogate

GOALS_MM = {"mean": 0.05, "max": 0.5}
"""The goals off the grid (issue 23), mm: the mean over the cases of their mean point error,
and the largest error of any case, at its material points or between them."""


@dataclass(frozen=True, slots=True)
class OffGridEvaluation(Result):
    """``results/surrogate/off_grid.json``: the model at the random cases off the grid.

    Attributes:
        architecture: the model's.
        rows: each case (named ``off-grid <k>`` in drawn order), its FE status and errors.
        spread: the errors over the cases whose FE solve converged, at the material points;
            None if none converged.
        between: the same at the cells' centroids; None where not measured.
        goals_mm: the goals it is judged by (:data:`GOALS_MM`).
        goals_met: whether ``spread``'s mean and the largest error of ``spread`` and
            ``between`` meet them (False if nothing was compared).
    """

    architecture: str
    rows: list[PostureRow]
    spread: ErrorSpread | None
    between: ErrorSpread | None
    goals_mm: dict[str, float]
    goals_met: bool

    @property
    def failed(self) -> list[PostureRow]:
        """The cases whose FE solve did not converge (no comparison)."""
        return [row for row in self.rows if row.errors is None]


def evaluate_off_grid(
    model: Surrogate,
    cases: Sequence[tuple[str | Path, str | Path, str | Path | None]],
    goals_mm: dict[str, float] | None = None,
) -> OffGridEvaluation:
    """The model against FE at each off-grid case.

    Args:
        model: the surrogate.
        cases: ``(summary.json, points.h5, fields.h5)`` of each case, in drawn order
            (``fields.h5`` None: not compared between the points).
        goals_mm: ``{"mean": ..., "max": ...}``, default :data:`GOALS_MM`.

    Raises:
        ValueError: if a case's material points are not the model's.
    """
    named = [(f"off-grid {k}", False, summary, points, fields)
             for k, (summary, points, fields) in enumerate(cases, start=1)]
    rows = evaluate_postures(model, named, movement=False).rows
    compared = [row.errors for row in rows if row.errors is not None]
    centroids = [row.between for row in rows if row.between is not None]
    goals = dict(GOALS_MM if goals_mm is None else goals_mm)
    spread = ErrorSpread.over(compared) if compared else None
    between = ErrorSpread.over(centroids) if centroids else None
    worst = max((s.max_mm for s in (spread, between) if s is not None), default=None)
    met = spread is not None and spread.mean_mm <= goals["mean"] and worst <= goals["max"]
    return OffGridEvaluation(
        architecture=model.config.architecture,
        rows=list(rows),
        spread=spread,
        between=between,
        goals_mm=goals,
        goals_met=bool(met),
    )


def main(argv: list[str] | None = None) -> int:
    """Command line: see the module's docstring."""
    parser = argparse.ArgumentParser(prog="python -m studies.surrogate_study.off_grid",
                                     description="A model's errors against FE at case folders "
                                     "(summary.json, points.h5 and, for the errors between "
                                     "the points, fields.h5).")
    parser.add_argument("model", type=Path, help="model folder")
    parser.add_argument("cases", type=Path, nargs="+", help="FE case folders")
    parser.add_argument("--json", type=Path, help="write the evaluation here too")
    args = parser.parse_args(argv)
    missing = [str(c) for c in args.cases if not (c / "summary.json").is_file()]
    if missing:
        print(f"error: no summary.json in {', '.join(missing)}", file=sys.stderr)
        return 2
    try:
        model = Surrogate.load(args.model)
        cases = [(c / "summary.json", c / "points.h5",
                  c / "fields.h5" if (c / "fields.h5").is_file() else None) for c in args.cases]
        evaluation = evaluate_off_grid(model, cases)
    except (OSError, ValueError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    compared = [row for row in evaluation.rows if row.errors is not None]
    for row in evaluation.rows:
        kind = "" if row.kind == "in range" else f" [{row.kind}]"
        if row.errors is None:
            print(f"{row.case}: FE {row.fe_status} ({row.fe_reason}), not compared{kind}")
        else:
            e = row.errors
            between = f", between the points {row.between.max_mm:.3f}" if row.between else ""
            print(f"{row.case}: mean {e.mean_mm:.4f} / p95 {e.p95_mm:.3f} / max {e.max_mm:.3f} "
                  f"mm of {e.fe_max_mm:.1f}{between}{kind}")
    def show(label: str, rows: Sequence[PostureRow]) -> None:
        spread = ErrorSpread.over([r.errors for r in rows])
        over = sum(max(r.errors.max_mm, r.between.max_mm if r.between else 0.0)
                   > evaluation.goals_mm["max"] for r in rows)
        print(f"{label}: {len(rows)} cases, mean {spread.mean_mm:.4f} / p95 {spread.p95_mm:.3f} "
              f"/ max {spread.max_mm:.3f} mm ({spread.worst_case}); {over} over "
              f"{evaluation.goals_mm['max']:g} mm at the points or between them")

    for c1 in sorted({round(r.C1, 6) for r in compared}):
        show(f"C1 = {c1:g} kPa", [r for r in compared if round(r.C1, 6) == c1])
    if compared:
        show("all", compared)
        inside = [r for r in compared if r.kind == "in range"]
        if inside and len(inside) < len(compared):  # the model warns at the others
            show("in range", inside)
            show("extrapolated", [r for r in compared if r.kind != "in range"])
    print(f"goals (mean {evaluation.goals_mm['mean']:g} mm, max {evaluation.goals_mm['max']:g} "
          f"mm): {'met' if evaluation.goals_met else 'not met'}")
    if args.json:
        write_json(args.json, evaluation.to_json())
    return 0


if __name__ == "__main__":
    sys.exit(main())
