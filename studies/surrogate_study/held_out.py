"""The surrogate on whole groups of cases it never saw: directions, C1 values, setups.

The paper's split draws points at random, so every case of its test set has most of its
points in the training set: its error says how well the network fits, not how well it
answers between the sweep's cases, which is what a user asks of it. The dataset's group
splits (:data:`fem.splits.SPLIT_KINDS`) hold out whole gravity directions
(``by_direction``), whole C1 values (``by_c1``) or whole setups (``by_case``). Each held-out
model is judged here on its test cases, and the by-sample model beside it on those of the
same cases it trained on (every case, for the paper's split of points; all but its validation
cases, for a ``pod`` model, :func:`trained_cases`): the pair says how much a sweep's spacing
costs, and so whether the sweep is dense enough ("as small an error at held-out directions
as inside the data").

A case's error is given as its mean, 95th percentile and maximum over the material points
(a tumour is one point), in mm and relative to the case's largest FE displacement.

``python -m studies.surrogate_study.held_out DATASET MODEL... [--bands 1.1 1.9]`` prints models
trained outside
the workflow (``python -m surrogate.cli train``) on their held-out and training cases, by
stiffness band.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from fem.dataset import Dataset
from fem.directions import direction_keys, gravity_direction
from studies.results import Record, Result
from studies.surrogate_study.errors_against_fe import CaseErrors, Centroids, ErrorSpread
from surrogate.exceptions import ExtrapolationWarning
from surrogate.structures import structure_for

if TYPE_CHECKING:  # JAX is imported by whoever has a model, not by this module's records
    from surrogate.predict import Surrogate

#: What each split holds out, in words for the report.
HELD_OUT = {
    "by_case": "whole setups (C1, direction); the clinical cases among them",
    "by_direction": "whole gravity directions, every C1 at each",
    "by_c1": "whole C1 values, every direction at each (the softest and stiffest train; the "
             "second softest is always among those held out)",
}


@dataclass(frozen=True, slots=True)
class HeldOutBlock(Record):
    """One held-out model on its test cases, the by-sample model on the same cases beside it.

    Attributes:
        split: the dataset split the model trained on.
        held_out: what the split holds out, in words.
        groups: the held-out groups of its test part (directions as ``phi/theta`` in degrees,
            C1 values in kPa, or case ids).
        held_out_model: the held-out model's errors over its test cases.
        inside_model: the by-sample model's errors over those of the same cases it trained on
            (:func:`trained_cases`); None where it trained on none of them.
        rows: the held-out model's errors per test case.
        inside_rows: the by-sample model's on those cases, in the same order.
        held_out_between: the held-out model's errors at the cell centroids (:class:`Centroids`)
            over the same cases; absent where the dataset has no quadratic mesh's nodes.
        inside_between: the by-sample model's there.
        failure_distance_deg: for each of ``rows``, the angle (degrees) from its gravity to the
            nearest direction where the sweep failed at the same C1 (:func:`failure_distances`;
            NaN where nothing failed at that C1); empty in records written before it was kept.
        bracketed: for each of ``rows`` of a ``by_c1`` block, whether the model trained on a
            softer and a stiffer C1 at the case's direction (:func:`c1_bracketed`): a held-out
            C1 interpolated there, not extrapolated; empty for the other splits.
        warned: for each of ``rows``, whether the held-out model warns that its prediction
            there is an extrapolation (:func:`warns`), as a user querying it would be told;
            empty in records written before it was kept.
    """

    split: str
    held_out: str
    groups: list[str]
    held_out_model: ErrorSpread
    inside_model: ErrorSpread | None
    rows: list[CaseErrors]
    inside_rows: list[CaseErrors]
    held_out_between: ErrorSpread | None = None
    inside_between: ErrorSpread | None = None
    failure_distance_deg: list[float] = field(default_factory=list)
    bracketed: list[bool] = field(default_factory=list)
    warned: list[bool] = field(default_factory=list)


@dataclass(frozen=True, slots=True)
class HeldOutEvaluation(Result):
    """``results/surrogate/held_out.json``: every held-out model, and the by-sample model.

    ``inside_all`` is the by-sample model over every converged case of the sweep it trained on
    (:func:`trained_cases`): its error inside the data; ``inside_all_between`` the same at the
    cell centroids, between the material points (absent without a quadratic mesh's nodes).
    """

    blocks: list[HeldOutBlock]
    inside_all: ErrorSpread
    inside_all_between: ErrorSpread | None = None


def held_out_groups(ds: Dataset, split: str, cases: np.ndarray) -> list[str]:
    """The groups of ``cases`` that ``split`` holds out, as labels."""
    if split == "by_direction":  # one label per direction, as the split groups them
        keys = direction_keys(ds.phi[cases], ds.theta[cases])
        seen = {key: f"phi={ds.phi[i]:g}/theta={ds.theta[i]:g}" for key, i in
                zip(keys[::-1], cases[::-1], strict=True)}  # the first case's angles name it
        return sorted(seen.values())
    if split == "by_c1":
        return [f"{c:g}" for c in sorted({round(float(ds.C1[i]), 9) for i in cases})]
    return [str(ds.ids[i]) for i in cases]


def failure_distances(ds: Dataset, cases: Sequence[int]) -> list[float]:
    """Each case's angle (degrees) to the nearest direction where ``ds`` failed at its C1.

    NaN where no case of that C1 failed. Beside a failure the sweep has no data beyond, and the
    FE answer there can depend on the history (:mod:`studies.fe_study.failure_edge`).
    """
    g = gravity_direction(np.asarray(ds.phi, dtype=float), np.asarray(ds.theta, dtype=float))
    c1 = np.asarray(ds.C1, dtype=float)
    failed = ~np.asarray(ds.converged, dtype=bool)
    out = []
    for i in cases:
        same = np.flatnonzero(failed & np.isclose(c1, c1[i], rtol=0, atol=1e-9))
        if same.size == 0:
            out.append(float("nan"))
            continue
        nearest = float(np.clip(g[same] @ g[i], -1.0, 1.0).max())
        out.append(float(np.degrees(np.arccos(nearest))))
    return out


def c1_bracketed(ds: Dataset, trained: Sequence[int], cases: Sequence[int]) -> list[bool]:
    """For each of ``cases``, whether ``trained`` holds a softer and a stiffer C1 at its direction.

    Where it does, a model that trained on ``trained`` interpolates the case's C1; where not (a
    direction solved at a few C1 values only, or one where the softer cases failed), it
    extrapolates, whatever the held-out value's place in the sweep's range.
    """
    keys = direction_keys(np.asarray(ds.phi, dtype=float), np.asarray(ds.theta, dtype=float))
    c1 = np.asarray(ds.C1, dtype=float)
    trained = np.asarray(trained, dtype=np.int64)
    out = []
    for i in cases:
        there = c1[trained[keys[trained] == keys[i]]]
        out.append(bool(np.any(there < c1[i] - 1e-9) and np.any(there > c1[i] + 1e-9)))
    return out


def by_bracket(rows: Sequence[CaseErrors], bracketed: Sequence[bool]) -> list[
        tuple[str, ErrorSpread]]:
    """The spread of a ``by_c1`` block's ``rows``: interpolated in C1 at their direction or not.

    Raises:
        ValueError: if ``bracketed`` does not pair with ``rows``.
    """
    if len(bracketed) != len(rows):
        raise ValueError(f"{len(bracketed)} flags for {len(rows)} cases")
    return [(label, ErrorSpread.over(inside)) for flag, label in BRACKET_LABELS.items()
            if (inside := [r for r, b in zip(rows, bracketed, strict=True) if b == flag])]


#: The groups of :func:`by_bracket`, by whether a case's C1 is bracketed at its direction.
BRACKET_LABELS = {
    True: "between trained C1 values at its direction",
    False: "beyond them: softer (or stiffer) than any trained at its direction",
}


#: The bands of :func:`by_failure_distance`, in degrees.
FAILURE_DISTANCE_BANDS = (10.0, 25.0)


def by_failure_distance(
    rows: Sequence[CaseErrors], distances: Sequence[float],
    edges: Sequence[float] = FAILURE_DISTANCE_BANDS,
) -> list[tuple[str, ErrorSpread]]:
    """The spread of ``rows`` by their angle to the nearest failed direction of their C1.

    Bands without cases are left out; cases whose C1 has no failure form the last band.

    Raises:
        ValueError: if ``distances`` does not pair with ``rows``.
    """
    if len(distances) != len(rows):
        raise ValueError(f"{len(distances)} distances for {len(rows)} cases")
    d = np.asarray(distances, dtype=float)
    bounds = [0.0, *sorted(edges), float("inf")]
    bands = []
    for lo, hi in zip(bounds[:-1], bounds[1:], strict=False):
        inside = [r for r, x in zip(rows, d, strict=True) if lo <= x < hi]
        label = (f"within {hi:g}° of a failure at its C1" if lo == 0 else
                 f"{lo:g}° or more from one" if hi == float("inf") else f"{lo:g}–{hi:g}°")
        if inside:
            bands.append((label, ErrorSpread.over(inside)))
    none = [r for r, x in zip(rows, d, strict=True) if np.isnan(x)]
    if none:
        bands.append(("no failure at its C1", ErrorSpread.over(none)))
    return bands


def warns(model: Surrogate, ds: Dataset, case: int) -> bool:
    """Whether ``model`` warns that its prediction at case ``case`` of ``ds`` is an extrapolation.

    Any :class:`~surrogate.exceptions.ExtrapolationWarning` of ``Surrogate.predict`` counts:
    outside the trained C1 range or directions, beside a failed FE solve, or below the softest
    C1 trained beside the case's direction. The query's checks alone are run
    (``Surrogate.features``, which ``predict`` calls), not the network: the case's errors have
    predicted it already.
    """
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", ExtrapolationWarning)
        model.features(float(ds.C1[case]), float(ds.phi[case]), float(ds.theta[case]))
    return any(issubclass(w.category, ExtrapolationWarning) for w in caught)


def trained_cases(model: Surrogate, ds: Dataset) -> np.ndarray:
    """The converged cases of ``ds`` whose fields ``model`` trained on (indices, ascending).

    A ``pod`` model trains on whole cases and leaves its validation cases out (with ``split:
    by_sample``, the ``by_case`` split's validation cases:
    :func:`surrogate.structures.pod.case_split`); a
    pointwise or separable model's by-sample split draws points, so that it trains on part of
    every case. A model refitted on its validation data too (``metrics.refit``,
    :func:`surrogate.train.train_and_evaluate`'s ``refit_epochs``) trained on those as well.
    Cases the model held out (``Surrogate.held_out``) are not among them.
    """
    held = np.flatnonzero(np.isin(ds.ids, list(model.held_out)))
    refit = bool(model.metrics.get("refit"))
    cases = structure_for(model.config).trained_cases(ds, held, refit)
    return np.intersect1d(cases, np.flatnonzero(ds.converged))


def evaluate_held_out(
    models: Mapping[str, Surrogate], inside: Surrogate, ds: Dataset
) -> HeldOutEvaluation:
    """Each held-out model on its split's test cases, ``inside`` (the by-sample model) beside.

    Every error is taken at the material points and, where ``ds`` was read with its fields
    at a quadratic mesh's nodes (``read_dataset(..., nodes=True)``), at the cell centroids too.

    Args:
        models: the held-out models by the split each trained on (``by_case``,
            ``by_direction``, ``by_c1``).
        inside: the by-sample model, judged on the cases it trained on only
            (:func:`trained_cases`): its error inside the data.
        ds: the dataset both trained on.

    Raises:
        ValueError: if a model trained on another split than its key, or a split has no
            test cases.
    """
    trained = trained_cases(inside, ds)
    inside_of = {int(i): CaseErrors.of(inside, ds, int(i)) for i in trained}
    centroids = Centroids.of(ds)
    inside_between_of: dict[int, CaseErrors] = {}
    if centroids is not None:
        inside_at = centroids.model(inside)
        inside_between_of = {int(i): CaseErrors.of(inside_at, ds, int(i), centroids)
                             for i in trained}
    blocks = []
    for split, model in models.items():
        if model.config.split != split:
            raise ValueError(f"the {split} model was trained on the {model.config.split} split")
        test = np.asarray(ds.splits[split]["test"], dtype=np.int64)
        test = test[ds.converged[test]]
        if test.size == 0:
            raise ValueError(f"the dataset's {split} split has no test cases")
        rows = [CaseErrors.of(model, ds, int(i)) for i in test]
        inside_rows = [inside_of[int(i)] for i in test if int(i) in inside_of]
        held_out_between = inside_between = None
        if centroids is not None:
            model_at = centroids.model(model)
            held_out_between = ErrorSpread.over(
                [CaseErrors.of(model_at, ds, int(i), centroids) for i in test])
            between = [inside_between_of[int(i)] for i in test if int(i) in inside_between_of]
            inside_between = ErrorSpread.over(between) if between else None
        blocks.append(HeldOutBlock(
            split=split,
            held_out=HELD_OUT.get(split, split),
            groups=held_out_groups(ds, split, test),
            held_out_model=ErrorSpread.over(rows),
            inside_model=ErrorSpread.over(inside_rows) if inside_rows else None,
            rows=rows,
            inside_rows=inside_rows,
            held_out_between=held_out_between,
            inside_between=inside_between,
            failure_distance_deg=failure_distances(ds, [int(i) for i in test]),
            bracketed=(c1_bracketed(ds, trained_cases(model, ds), [int(i) for i in test])
                       if split == "by_c1" else []),
            warned=[warns(model, ds, int(i)) for i in test],
        ))
    return HeldOutEvaluation(
        blocks=blocks, inside_all=ErrorSpread.over(list(inside_of.values())),
        inside_all_between=(ErrorSpread.over(list(inside_between_of.values()))
                            if inside_between_of else None))


def by_stiffness(rows: Sequence[CaseErrors], edges: Sequence[float]) -> list[
        tuple[str, ErrorSpread]]:
    """The spread of ``rows`` in each band of C1 that ``edges`` (kPa, ascending) bound.

    Bands without cases are left out.
    """
    bounds = [0.0, *sorted(edges), float("inf")]
    bands = []
    for lo, hi in zip(bounds[:-1], bounds[1:], strict=False):
        inside = [r for r in rows if lo <= r.C1 < hi]
        if not inside:
            continue
        if lo == 0:
            label = f"C1 < {hi:g}"
        elif hi == float("inf"):
            label = f"C1 >= {lo:g}"
        else:
            label = f"{lo:g} <= C1 < {hi:g}"
        bands.append((label, ErrorSpread.over(inside)))
    return bands


def main(argv: list[str] | None = None) -> int:
    """Each model on the cases its split held out and on those it trained on, by stiffness."""
    import argparse
    import sys

    from fem.dataset import read_dataset
    from fem.exceptions import DatasetError
    from surrogate.exceptions import SurrogateError
    from surrogate.predict import Surrogate

    parser = argparse.ArgumentParser(
        prog="python -m studies.surrogate_study.held_out",
        description="Point errors (mean of the cases' means / 95th percentile of their 95th "
                    "percentiles / largest, mm) of trained models on the dataset's cases that "
                    "each model's split held out, and on the cases it trained on.")
    parser.add_argument("dataset", type=Path, help="the dataset the models trained on")
    parser.add_argument("models", type=Path, nargs="+", help="model folders")
    parser.add_argument("--bands", type=float, nargs="*", default=[1.1, 1.9],
                        help="C1 values (kPa) between the stiffness bands (default 1.1 1.9)")
    args = parser.parse_args(argv)
    try:
        ds = read_dataset(args.dataset)
        models = [(folder, Surrogate.load(folder)) for folder in args.models]
    except (DatasetError, SurrogateError, OSError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2

    def show(label: str, spread: ErrorSpread) -> None:
        print(f"  {label:<22}{spread.cases:>5} cases  {spread.mean_mm:.4f} / "
              f"{spread.p95_mm:.3f} / {spread.max_mm:.3f} mm  (worst {spread.worst_case})")

    for folder, model in models:
        config = model.config
        split = ds.splits.get(config.split)
        if split is None:
            print(f"error: the dataset has no {config.split} split ({folder})", file=sys.stderr)
            return 2
        print(f"{folder}: {config.architecture} {config.structure}, {config.output_form} output, "
              f"split {config.split}, validation error "
              f"{model.metrics.get('validation_error_mm')} mm")
        trained = trained_cases(model, ds)
        if config.split == "by_sample":  # every case but a pod model's validation cases
            parts = {"trained on": trained,
                     "not trained on": np.setdiff1d(np.flatnonzero(ds.converged), trained)}
        else:
            parts = {"held out": np.asarray(split["test"], dtype=np.int64),
                     "trained on": trained}
        for label, cases in parts.items():
            cases = cases[ds.converged[cases]]
            rows = [CaseErrors.of(model, ds, int(i)) for i in cases]
            if rows:
                show(label, ErrorSpread.over(rows))
                for band, spread in by_stiffness(rows, args.bands):
                    show(f"  {band}", spread)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())


__all__ = ["BRACKET_LABELS", "FAILURE_DISTANCE_BANDS", "HELD_OUT", "CaseErrors", "Centroids",
           "ErrorSpread", "HeldOutBlock", "HeldOutEvaluation", "by_bracket", "by_failure_distance",
           "by_stiffness", "c1_bracketed", "evaluate_held_out", "failure_distances",
           "held_out_groups", "warns"]
