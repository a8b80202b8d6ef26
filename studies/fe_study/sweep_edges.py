"""The sweep's own failed cases, each traced from its nearest converged direction.

In the workflow (``fe_study.failure_edges``, ``results/fe_study/failure_edges.json``, the
report's stability section), :func:`sweep_edges` traces the first failed cases of the dataset:
each from the nearest direction that converged at the same C1, reached through the two next
stiffer C1 values that converged there (as its chain reached it), by gravity turned at full
load towards it (:func:`studies.fe_study.failure_edge.turn_runner`).
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fem.directions import gravity_direction
from fem.exceptions import InvalidParameterError
from fem.parameters import SolverSettings
from studies.fe_study.failure_edge import FailureEdge, turn_runner
from studies.results import Record, Result

log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True)
class TracedFailure(Record):
    """One failed case of the sweep, traced from its nearest converged direction.

    Attributes:
        case: the failed case's id.
        load_fraction: the load it reached in the sweep.
        start_case: the converged case the turn starts from (same C1).
        start_sweep_max_mm: that case's largest displacement in the sweep: the turn's first
            state is the sweep's own where its ``max_displacement_mm`` agrees (a near fold, the
            start could land on another equilibrium).
        edge: the turn (:class:`FailureEdge`); None where its start did not converge again.
        error: why there is no turn.
    """

    case: str
    load_fraction: float
    start_case: str
    edge: FailureEdge | None
    error: str | None = None
    start_sweep_max_mm: float = math.nan  # absent from records written before it was kept


@dataclass(frozen=True, slots=True)
class SweepEdges(Result):
    """``results/fe_study/failure_edges.json``: the sweep's failed cases, traced.

    Attributes:
        failed: how many cases of the sweep failed.
        traced: the first ``n`` of them (softest first, the paper's plane first), traced; a
            failed case with no converged case at its C1 is left out.
        seconds: the study's wall time.
    """

    failed: int
    traced: list[TracedFailure]
    seconds: float


@dataclass(frozen=True, slots=True)
class Trace:
    """What :func:`choose_traces` picks for one failed case (indices into the columns)."""

    failed: int
    start: int
    via: tuple[float, ...]


def choose_traces(columns: dict[str, np.ndarray], n: int) -> list[Trace]:
    """The first ``n`` failed cases and where each is traced from (see :func:`sweep_edges`).

    Args:
        columns: the dataset's per-case columns (:func:`fem.dataset.read_case_columns`):
            ``C1``, ``phi``, ``theta``, ``converged``.
        n: how many failed cases at most.

    Failed cases are taken softest first, those in the paper's plane (θ = 0) before the others,
    then by Φ and θ. Each starts from the converged case of the same C1 whose gravity is nearest
    (the smallest angle; the opposite direction is no start), reached through the next two
    stiffer C1 values that converged at that direction. A failed case whose C1 has no other
    converged case is skipped.
    """
    c1 = np.asarray(columns["C1"], dtype=float)
    phi, theta = np.asarray(columns["phi"], dtype=float), np.asarray(columns["theta"], dtype=float)
    converged = np.asarray(columns["converged"], dtype=bool)
    g = gravity_direction(phi, theta)
    failed = sorted(np.flatnonzero(~converged),
                    key=lambda i: (round(c1[i], 9), theta[i] != 0.0, phi[i], theta[i]))
    traces = []
    for i in failed:
        if len(traces) == n:
            break
        same = np.flatnonzero(converged & np.isclose(c1, c1[i], rtol=0, atol=1e-9))
        cos = g[same] @ g[i]
        same, cos = same[cos > -1 + 1e-9], cos[cos > -1 + 1e-9]  # no great circle to the opposite
        if same.size == 0:
            continue
        start = int(same[np.argmax(cos)])
        along = np.flatnonzero(converged & (np.abs(g - g[start]).max(axis=1) < 1e-9)
                               & (c1 > c1[i] + 1e-9))
        via = tuple(sorted(float(c1[k]) for k in along)[:2])
        traces.append(Trace(int(i), start, via))
    return traces


#: The dataset's per-case columns :func:`sweep_edges` reads.
SWEEP_COLUMNS = ("id", "C1", "phi", "theta", "converged", "load_fraction", "max_disp_mm")


def sweep_edges(
    mesh: str | Path,
    settings: SolverSettings,
    columns: dict[str, np.ndarray],
    n: int,
    step_deg: float = 1.0,
    resolution_deg: float = 0.05,
) -> SweepEdges:
    """Trace the first ``n`` failed cases of a sweep (:func:`choose_traces`), on one runner.

    A trace whose start case does not converge again is recorded with its error, not turned.

    Raises:
        InvalidParameterError: if ``columns`` lacks one of :data:`SWEEP_COLUMNS`.
    """
    missing = [key for key in SWEEP_COLUMNS if key not in columns]
    if missing:
        raise InvalidParameterError(
            f"the dataset has no column {', '.join(missing)}: rebuild it (snakemake --forcerun "
            "aggregate)")
    from fem.case import CaseRunner

    clock = time.perf_counter()
    traced = []
    ids = np.asarray(columns["id"]).astype(str)
    traces = choose_traces(columns, n)
    if traces:  # one mesh read and form compilation for every trace
        with CaseRunner(mesh, settings) as runner:
            for trace in traces:
                i, k = trace.failed, trace.start
                log.info("%s: from %s through %s", ids[i], ids[k],
                         trace.via or "nothing stiffer")
                edge, error = None, None
                try:
                    edge = turn_runner(runner, float(columns["C1"][i]),
                                       (float(columns["phi"][k]), float(columns["theta"][k])),
                                       (float(columns["phi"][i]), float(columns["theta"][i])),
                                       trace.via, step_deg, resolution_deg)
                except InvalidParameterError as err:  # its start did not converge again
                    log.warning("%s: %s", ids[i], err)
                    error = str(err)
                traced.append(TracedFailure(
                    case=str(ids[i]), load_fraction=float(columns["load_fraction"][i]),
                    start_case=str(ids[k]), edge=edge, error=error,
                    start_sweep_max_mm=float(columns["max_disp_mm"][k])))
    return SweepEdges(failed=int((~np.asarray(columns["converged"], dtype=bool)).sum()),
                      traced=traced, seconds=time.perf_counter() - clock)


__all__ = ["SWEEP_COLUMNS", "SweepEdges", "Trace", "TracedFailure", "choose_traces", "sweep_edges"]
