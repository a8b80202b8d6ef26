"""Benchmark: a ``pod`` surrogate on the held-out splits and between the mesh's nodes.

    .venv/bin/python -m benchmarks.pod_basis DATASET --model MODEL [--by-direction MODEL]
        [--by-c1 MODEL] [--outside DIR] [--centroids] [--config config.yaml]
        [--set KEY=VALUE ...] [--json OUT]

A ``pod`` surrogate (:mod:`surrogate.structures.pod`) takes the leading POD modes of the
training cases' fields as its basis and trains a branch network of (C1, ĝ) for their weights.
This benchmark fits such models with the ``surrogate`` settings of ``--config`` (structure
forced to ``pod``, ``--set`` overriding any) and measures them beside trained models of any
structure:

* per the dataset's ``by_direction`` and ``by_c1`` splits, one fitted on the split's training
  cases (stopping early on its validation cases) and measured on its test cases, with the model
  trained on that split (``--by-direction``, ``--by-c1``) beside;
* one fitted on every converged case, measured on them all, on the soft caudal ones (C1 ≤ 1 kPa,
  θ < -30°), and on each converged FE case of ``--outside`` (the postures' and extrapolation
  solves' case folders) inside the training range, with ``--model`` beside.

Errors per case: mean, 95th percentile and largest point error (mm); over cases: their mean, the
95th percentile of the 95th percentiles and the largest
(:class:`studies.surrogate_study.held_out.ErrorSpread`).

The pod models are fitted as the workflow fits them: at every node of a quadratic mesh where
the dataset holds the fields there (``/nodes``). With ``--centroids`` (such a dataset), every
error is measured at the mesh's cell centroids, between the nodes: FE by the 10-node
tetrahedra's shape functions (exact: the FE field is quadratic), the models by
``Surrogate.at``. Without it, errors are at the material points (the mesh's vertices) only.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import warnings
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from fem.case_files import read_summary
from fem.dataset import Dataset, read_dataset
from fem.sweep import Case
from studies.surrogate_study.errors_against_fe import CaseErrors, Centroids, ErrorSpread
from studies.surrogate_study.surrogate_evaluation import fe_in_model_order
from surrogate.config import SurrogateConfig
from surrogate.exceptions import ExtrapolationWarning
from surrogate.predict import Surrogate

SOFT_C1_KPA = 1.0
"""The soft caudal cases: C1 at most this (kPa) and θ below ``CAUDAL_THETA_DEG``."""
CAUDAL_THETA_DEG = -30.0


def fit(ds: Dataset, train: Sequence[int], validation: Sequence[int],
        config: SurrogateConfig) -> tuple[Surrogate, float]:
    """A ``pod`` model fitted on ``train`` (early stopping on ``validation``), and its fit time (s).

    Raises:
        ValueError: if a case did not converge, or there are fewer training cases than modes.
    """
    from surrogate.checkpoint import in_memory
    from surrogate.structures.pod import fit as fit_pod

    result = fit_pod(ds, config.replace(structure="pod"), np.asarray(train),
                     np.asarray(validation))
    return Surrogate(in_memory(result, ds)), result.train_s


def spread(predict, ds: Dataset, cases: Sequence[int], truth=None) -> ErrorSpread:
    """``predict(C1, phi, theta)``'s errors on dataset cases.

    Against ``truth(case)``, by default the dataset's displacement.
    """
    rows = []
    for i in cases:
        C1, phi, theta = float(ds.C1[i]), float(ds.phi[i]), float(ds.theta[i])
        fe = ds.displacement[i] if truth is None else truth(i)
        rows.append(CaseErrors.between(predict(C1, phi, theta), fe, str(ds.ids[i]), C1, phi,
                                       theta))
    return ErrorSpread.over(rows)


def outside_cases(
    ds: Dataset, folder: Path, model: Surrogate, cells: np.ndarray | None = None
) -> list[tuple[str, float, float, float, np.ndarray]]:
    """The converged FE cases under ``folder`` inside the dataset's C1 range.

    Each case's field at ``model``'s material points, in its order (the model trained on
    ``ds``); with ``cells`` (the quadratic mesh's), at those cells' centroids instead.

    Raises:
        ValueError: if a case's material points, or its mesh, are not the model's.
    """
    lo, hi = float(ds.C1[ds.converged].min()), float(ds.C1[ds.converged].max())
    found = []
    for summary_path in sorted(folder.glob("*/summary.json")):
        summary = read_summary(summary_path)
        case = Case.from_summary(summary)
        if summary["status"] != "converged" or not lo - 1e-9 <= case.C1 <= hi + 1e-9:
            continue
        if cells is not None:
            read = Centroids.of_fields(summary_path.parent / "fields.h5")
            if read is None or not np.array_equal(read[0].cells, cells):
                raise ValueError(f"{summary_path.parent}: another mesh than the dataset's")
            found.append((str(summary["case"]), case.C1, case.phi, case.theta, read[1]))
            continue
        fe, _ = fe_in_model_order(model, summary_path.parent / "points.h5")
        found.append((str(summary["case"]), case.C1, case.phi, case.theta, fe))
    return found


def _quiet(model: Surrogate):
    """A surrogate's predict with its extrapolation warnings silenced (cases near failures)."""
    def predict(C1: float, phi: float, theta: float) -> np.ndarray:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ExtrapolationWarning)
            return model.predict(C1, phi, theta)
    return predict


def main(argv: list[str] | None = None) -> int:
    """Command line: see the module's docstring."""
    parser = argparse.ArgumentParser(prog="python -m benchmarks.pod_basis",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("dataset", type=Path)
    parser.add_argument("--model", type=Path, required=True, help="the by-sample model")
    parser.add_argument("--by-direction", type=Path, help="the model of the by_direction split")
    parser.add_argument("--by-c1", type=Path, help="the model of the by_c1 split")
    parser.add_argument("--outside", type=Path, help="folder of extra FE case folders")
    parser.add_argument("--config", type=Path, default=Path("config.yaml"),
                        help="config whose `surrogate` section the pod models take")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help="override one surrogate setting (YAML value), e.g. modes=32")
    parser.add_argument("--centroids", action="store_true",
                        help="measure every error at the quadratic mesh's cell centroids, "
                             "between the nodes (the models by Surrogate.at); needs a dataset "
                             "with the fields at every node (/nodes)")
    parser.add_argument("--json", type=Path, help="write the figures here too")
    args = parser.parse_args(argv)
    for path in (args.model, args.by_direction, args.by_c1, args.outside):
        if path is not None and not path.is_dir():
            print(f"error: {path} is not a folder", file=sys.stderr)
            return 2
    from surrogate.cli import settings
    from surrogate.exceptions import SurrogateError

    try:
        config = settings(args.config, args.set)[0].replace(structure="pod")
    except (OSError, SurrogateError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    ds = read_dataset(args.dataset, nodes=True)
    if ds.node_index is None:
        print(f"error: {args.dataset} has no node_index", file=sys.stderr)
        return 2
    converged = np.flatnonzero(ds.converged)
    figures: dict[str, dict] = {}
    cells, truth = None, None
    if args.centroids:
        if ds.nodes is None:
            print(f"error: {args.dataset} has no fields at a quadratic mesh's nodes (/nodes, "
                  "written for a mesh of 10-node tetrahedra): no centroids to measure at",
                  file=sys.stderr)
            return 2
        centroids = Centroids.of(ds)
        cells = centroids.cells

        def truth(i: int) -> np.ndarray:
            return centroids.fe(ds, i)

    def where(model: Surrogate):  # the model's predict at the points the errors are taken
        return _quiet(model if cells is None else centroids.model(model))

    def row(name: str, pod: ErrorSpread, model: ErrorSpread | None) -> None:
        figures[name] = {"pod": pod.to_json(), "model": model.to_json() if model else None}
        text = f"{name:<34} {pod.cases:>4}  POD {_fmt(pod)}"
        print(text + (f"  | model {_fmt(model)}" if model else ""), flush=True)

    for split, path in (("by_direction", args.by_direction), ("by_c1", args.by_c1)):
        parts = ds.splits[split]
        test = np.intersect1d(parts["test"], converged)
        pod, seconds = fit(ds, parts["train"], parts["validation"], config)
        other = spread(where(Surrogate.load(path)), ds, test, truth) if path else None
        row(f"{split} held out ({seconds:.0f} s)",
            spread(where(pod), ds, test, truth), other)
    pod, seconds = fit(ds, converged, converged, config)
    surrogate = Surrogate.load(args.model)
    model = where(surrogate)
    soft = [i for i in converged
            if ds.C1[i] <= SOFT_C1_KPA + 1e-9 and ds.theta[i] < CAUDAL_THETA_DEG]
    row(f"every case, inside ({seconds:.0f} s)",
        spread(where(pod), ds, converged, truth), spread(model, ds, converged, truth))
    if soft:
        row("soft caudal, inside", spread(where(pod), ds, soft, truth),
            spread(model, ds, soft, truth))
    outside = outside_cases(ds, args.outside, surrogate, cells) if args.outside else []
    for case, C1, phi, theta, fe in outside:
        errors = [ErrorSpread.over([CaseErrors.between(f(C1, phi, theta), fe, case, C1, phi,
                                                       theta)])
                  for f in (where(pod), model)]
        row(case, *errors)
    queries = [(float(ds.C1[i]), float(ds.phi[i]), float(ds.theta[i])) for i in converged[:50]]
    timing = {name: _median_ms(f, queries) for name, f in (("pod", where(pod)), ("model", model))}
    figures["prediction_median_ms"] = timing
    at = "the material points" if cells is None else f"the {len(cells)} centroids"
    print(f"prediction, median of {len(queries) * 4} cases in this process: POD "
          f"{timing['pod']:.3f} ms, model {timing['model']:.3f} ms, at {at}")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({"settings": config.as_dict(), "figures": figures},
                                        indent=1))
    return 0


def _median_ms(predict, queries: Sequence[tuple[float, float, float]]) -> float:
    """Median wall time of one whole-field prediction (ms), each query 4 times, warmed up."""
    for q in queries[:5]:
        predict(*q)
    times = []
    for q in queries * 4:
        start = time.perf_counter()
        predict(*q)
        times.append(time.perf_counter() - start)
    return 1e3 * float(np.median(times))


def _fmt(s: ErrorSpread) -> str:
    return f"{s.mean_mm:.3f} / {s.p95_mm:.3f} / {s.max_mm:.2f} mm"


if __name__ == "__main__":
    sys.exit(main())
