"""Whether the adaptive sweep's error estimate finds where the surrogate errs.

The adaptive sweep (:mod:`fem.adaptive`) adds FE cases where an estimate built from the solved
cases alone says the field is least known. This checks that estimate against the truth at FE
cases that no round chose and the model did not train on:

* the workflow's random cases off the grid (``surrogate_study.off_grid``), against the
  selected model, the estimate built from every case of the sweep;
* each held-out split's test cases (whole directions, or single cases, left out), against the
  model trained without them, the estimate built from the cases that model trained on.

At each case it sets the surrogate's true worst-point error beside three estimates (mm), and
the error of the load-space interpolant itself (the data's own limit there):

* ``committee``: the largest point distance between the cubic interpolant and a linear one
  (:func:`fem.adaptive.committee`), what the rounds use;
* ``jackknife``: :meth:`fem.adaptive.LoadSpaceInterpolant.jackknife`;
* ``nearest``: the leave-one-out error of the nearest solved case in the load space (the
  cross-validation Voronoi rule of sequential design).

Per set and estimator: Spearman's rank correlation with the true error, and the share of the
true worst tenth of the cases that the estimate's worst tenth holds. The issue's bar is a rank
correlation of 0.7.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fem.adaptive import LoadSpaceInterpolant, committee, load_points
from fem.case_files import read_case
from fem.dataset import Dataset
from studies.results import Record, Result
from studies.surrogate_study.errors_against_fe import CaseErrors
from studies.surrogate_study.off_grid import OffGridEvaluation
from surrogate.predict import Surrogate

log = logging.getLogger(__name__)

ESTIMATORS = ("committee", "jackknife", "nearest")
"""The estimates compared; the first is the one the rounds use."""
RANK_CORRELATION_GOAL = 0.7
FEWEST_CASES = 5
"""The fewest cases an estimate is built from (the interpolant's linear tail needs four)."""


@dataclass(frozen=True, slots=True)
class EstimateRow(Record):
    """One held-out case: the surrogate's true error and each estimate of it (mm).

    Attributes:
        set: ``off_grid``, ``by_direction`` or ``by_case``.
        case: its case id.
        C1, phi, theta: kPa, degrees.
        true_mm: the model's largest point error against FE.
        interpolant_mm: the load-space interpolant's own largest point error against FE.
        estimates: by estimator (:data:`ESTIMATORS`).
    """

    set: str
    case: str
    C1: float
    phi: float
    theta: float
    true_mm: float
    interpolant_mm: float
    estimates: dict[str, float]


@dataclass(frozen=True, slots=True)
class EstimateScore(Record):
    """One estimator on one set of cases.

    Attributes:
        set: the set (``all`` for every set together).
        estimator: its name.
        cases: how many.
        rank_correlation: Spearman's, with the true error.
        worst_tenth_found: the share of the true worst tenth (at least one case) in the
            estimate's worst tenth.
    """

    set: str
    estimator: str
    cases: int
    rank_correlation: float
    worst_tenth_found: float


@dataclass(frozen=True, slots=True)
class SweepEstimateCheck(Result):
    """``results/sweep/estimate.json``: the estimate against the truth (the module)."""

    chosen: str
    goal: float
    rows: list[EstimateRow]
    scores: list[EstimateScore]

    def score(self, set_name: str = "all", estimator: str | None = None) -> EstimateScore:
        """The score of ``estimator`` (default: the chosen one) on ``set_name``."""
        wanted = estimator or self.chosen
        return next(s for s in self.scores if s.set == set_name and s.estimator == wanted)

    @property
    def goal_met(self) -> bool:
        """Whether the chosen estimate's rank correlation over every case meets the goal."""
        return bool(self.scores) and self.score().rank_correlation >= self.goal


def estimates_at(x: np.ndarray, fields: np.ndarray, y: np.ndarray,
                 fe: np.ndarray) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """Each estimate (:data:`ESTIMATORS`) at load points ``y``, and the interpolant's error.

    The estimates come from solved cases at load points ``x`` with ``fields`` (M, N, 3), mm;
    the error is the cubic interpolant's own worst-point error at ``y`` against the FE fields
    ``fe`` (Q, N, 3).
    """
    cubic = LoadSpaceInterpolant(x, fields)
    guess = cubic.predict(y)
    return ({"committee": committee(guess, LoadSpaceInterpolant(x, fields, power=1), y),
             "jackknife": cubic.jackknife(y), "nearest": cubic.nearest(y)},
            np.linalg.norm(guess - fe, axis=2).max(axis=1))


def _estimates(ds: Dataset, trained: np.ndarray, C1: np.ndarray, phi: np.ndarray,
               theta: np.ndarray, fe: np.ndarray) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """:func:`estimates_at` the cases (C1, Φ, θ), from the dataset's cases ``trained``."""
    x = load_points(ds.C1[trained], ds.phi[trained], ds.theta[trained])
    return estimates_at(x, ds.displacement[trained], load_points(C1, phi, theta), fe)


def _rows(set_name: str, ids: Sequence[str], C1: np.ndarray, phi: np.ndarray, theta: np.ndarray,
          true_mm: Sequence[float], estimates: Mapping[str, np.ndarray],
          interpolant_mm: np.ndarray) -> list[EstimateRow]:
    return [EstimateRow(set_name, str(ids[k]), float(C1[k]), float(phi[k]), float(theta[k]),
                        float(true_mm[k]), float(interpolant_mm[k]),
                        {name: float(v[k]) for name, v in estimates.items()})
            for k in range(len(ids))]


def _good_cases(ds: Dataset) -> np.ndarray:
    """The cases some split holds (converged, not passing through themselves)."""
    parts = ds.splits["by_case"]
    return np.sort(np.concatenate([parts[p] for p in ("train", "validation", "test")]))


def check_estimate(ds: Dataset, off_grid: OffGridEvaluation | None,
                   off_grid_points: Sequence[str | Path],
                   held_out: Mapping[str, Surrogate]) -> SweepEstimateCheck:
    """The estimate against the truth at the off-grid cases and the held-out splits' tests.

    Args:
        ds: the sweep's dataset.
        off_grid: the selected model at the random cases off the grid (None: not checked).
        off_grid_points: those cases' ``points.h5``, in its rows' order.
        held_out: the held-out models by the split they trained on (``by_direction``,
            ``by_case``; others are skipped).

    A set whose estimate would rest on fewer than :data:`FEWEST_CASES` cases is skipped (a
    small test sweep's held-out split); a sweep with no set left gives a check with no rows
    and no scores.
    """
    rows: list[EstimateRow] = []
    if off_grid is not None:
        compared = [(row, path) for row, path in zip(off_grid.rows, off_grid_points, strict=True)
                    if row.errors is not None]
        if compared and len(_good_cases(ds)) >= FEWEST_CASES:
            fe = np.array([1e3 * read_case(Path(p).parent / "summary.json", p)[1]["u"]
                           for _, p in compared])
            C1, phi, theta = (np.array([getattr(r, k) for r, _ in compared], dtype=float)
                              for k in ("C1", "phi", "theta"))
            est, own = _estimates(ds, _good_cases(ds), C1, phi, theta, fe)
            rows += _rows("off_grid", [r.case for r, _ in compared], C1, phi, theta,
                          [r.errors.max_mm for r, _ in compared], est, own)
    for split, model in held_out.items():
        if split not in ("by_direction", "by_case"):
            continue
        parts = ds.splits[split]
        test = np.asarray(parts["test"], dtype=np.int64)
        test = test[ds.converged[test]]
        trained = np.sort(np.concatenate([parts["train"], parts["validation"]]))
        if test.size == 0 or trained.size < FEWEST_CASES:
            log.info("estimate check: the %s split is skipped (%d test cases, %d trained on)",
                     split, test.size, trained.size)
            continue
        est, own = _estimates(ds, trained, ds.C1[test], ds.phi[test], ds.theta[test],
                              ds.displacement[test])
        true = [CaseErrors.of(model, ds, int(i)).max_mm for i in test]
        rows += _rows(split, ds.ids[test], ds.C1[test], ds.phi[test], ds.theta[test], true,
                      est, own)
    sets = ("all", *dict.fromkeys(r.set for r in rows)) if rows else ()
    scores = [rank_score(name, estimator, [r for r in rows if name in ("all", r.set)])
              for name in sets for estimator in ESTIMATORS]
    return SweepEstimateCheck(ESTIMATORS[0], RANK_CORRELATION_GOAL, rows, scores)


def rank_score(set_name: str, estimator: str, rows: Sequence[EstimateRow]) -> EstimateScore:
    """How ``estimator`` ranks the true error over ``rows`` (NaN correlation under 3 rows)."""
    from scipy.stats import spearmanr

    true = np.array([r.true_mm for r in rows])
    guess = np.array([r.estimates[estimator] for r in rows])
    rho = float(spearmanr(true, guess).statistic) if len(rows) > 2 else math.nan
    tenth = max(1, int(math.ceil(0.1 * len(rows))))
    worst = set(np.argsort(-true)[:tenth])
    found = len(worst & set(np.argsort(-guess)[:tenth])) / tenth
    return EstimateScore(set_name, estimator, len(rows), rho, float(found))


def main(argv: list[str] | None = None) -> int:
    """``python -m studies.sweep.sweep_estimate WORKDIR [--json OUT]``: the check on a run's files.

    Reads WORKDIR's dataset, ``results/surrogate/off_grid.json`` with its cases under
    ``results/outside``, and the held-out models ``results/surrogate/model_<split>``; prints
    each estimator's scores.
    """
    import argparse
    import sys

    from fem.dataset import read_dataset
    from surrogate.runtime import configure_cpu

    parser = argparse.ArgumentParser(prog="python -m studies.sweep.sweep_estimate",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("workdir", type=Path)
    parser.add_argument("--json", type=Path, help="write the check here too")
    args = parser.parse_args(argv)
    configure_cpu()
    results = args.workdir / "results"
    off_grid = OffGridEvaluation.read(results / "surrogate" / "off_grid.json")
    points = [results / "outside" / row.case / "points.h5" for row in off_grid.rows]
    models = {split: Surrogate.load(results / "surrogate" / f"model_{split}" / "model.json")
              for split in ("by_direction", "by_case")
              if (results / "surrogate" / f"model_{split}" / "model.json").is_file()}
    check = check_estimate(read_dataset(results / "dataset" / "dataset.h5"), off_grid, points,
                           models)
    if not check.rows:
        print("error: no held-out case to check the estimate at", file=sys.stderr)
        return 2
    print(f"{'set':<14}{'estimator':<11}{'cases':>6}{'rank corr.':>11}{'worst tenth':>12}")
    for s in check.scores:
        print(f"{s.set:<14}{s.estimator:<11}{s.cases:>6}{s.rank_correlation:>11.3f}"
              f"{s.worst_tenth_found:>12.2f}")
    if args.json:
        check.write(args.json)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
