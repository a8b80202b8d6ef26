"""The surrogate at random cases off its sweep's grid, against FE: what a user meets.

The held-out study (:mod:`studies.held_out`) retrains the model with whole directions or C1
values left out, a pessimistic estimate of the error between the sweep's points. This asks
the model actually used, at ``surrogate_study.off_grid``'s cases: C1 and gravity drawn at
random within the sweep's range (:func:`fem.sweep.random_cases`), each solved by FE outside
the sweep. Each case's error is taken at the material points and, on a quadratic mesh, at its
cells' centroids, between them (:func:`studies.postures.evaluate_postures`); the set's spread
is set beside the goals of issue 23: a mean point error of 0.05 mm and a largest point error
of 0.5 mm at any case off the grid, the largest taken at the material points and between them
(a tumour lies anywhere).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from studies.held_out import ErrorSpread
from studies.postures import PostureRow, evaluate_postures
from studies.results import Result
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
    rows = evaluate_postures(model, named).rows
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
