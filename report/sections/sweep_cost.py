"""The sweep's cost: the FE solve time of every case over (C1, Phi), and the totals."""

from __future__ import annotations

import numpy as np

from report.context import Context
from report.html import missing, para, seconds, table
from studies.figures import fe as fem_plots


def sweep_cost_section(ctx: Context) -> str:
    """The sweep's cost: solve time per case over (C1, Phi) and the totals."""
    ds = ctx.dataset()
    if ds is None:
        return missing("results/dataset/dataset.h5")
    columns = ctx.case_columns()
    wall = columns.get("wall_s")
    cpu = columns.get("cpu_s")
    start = columns.get("start_fraction")
    steps = columns.get("load_steps")
    its = columns.get("newton_iterations")
    if wall is None:
        return para("The dataset holds no solve times.", "note")
    out = [para(
        "The FE solve wall time of every case of the sweep over stiffness C1 and gravity "
        "angle Φ (or, for a sweep beyond the paper's plane, the gravity direction Φ/θ): one "
        "square per case, its colour the time in seconds (colour bar); a red "
        "cross marks a case that failed. The table gives the totals.", "caption")]
    out.append(ctx.figure(
        "sweep_cost.png",
        lambda p: fem_plots.plot_sweep_map(ds.C1, ds.phi, wall, p, "FE solve wall time (s)",
                                           failed=~ds.converged, title="FE cost per case",
                                           theta=ds.theta),
        "FE solve time per case over C1 and gravity angle", "FE solve time per case."))
    rows = [
        ["cases", f"{len(wall)}"],
        ["converged", f"{int(ds.converged.sum())}"],
        ["total solve time", seconds(float(np.nansum(wall)))],
        ["median per case", seconds(float(np.nanmedian(wall)))],
        ["slowest case", seconds(float(np.nanmax(wall)))],
    ]
    if cpu is not None and np.isfinite(cpu).any():
        rows.append(["solve CPU time, mean per case", seconds(float(np.nanmean(cpu)))])
        rows.append(["solve CPU time, total", seconds(float(np.nansum(cpu)))])
    span = solve_span(columns.get("process_start_s"), columns.get("finished_s"))
    if span is not None:
        rows.append(["wall time of the solves, from the first solving process starting to the "
                     "last case ending (any pause between runs included)", seconds(span)])
    if start is not None:
        rows.append(["cases started from a stiffer neighbour (chains)",
                     f"{int(np.sum(start > 0))} of {len(start)}"])
    if steps is not None:
        rows.append(["load steps (min–max)", f"{int(steps.min())}–{int(steps.max())}"])
    if its is not None:
        rows.append(["Newton iterations (min–max)", f"{int(its.min())}–{int(its.max())}"])
    out.append(table(["sweep", "value"], rows, table_id="sweep-cost"))
    return "".join(out)


def solve_span(process_start: np.ndarray | None, finished: np.ndarray | None) -> float | None:
    """Seconds from the earliest solving process's start to the latest case's end.

    The sweep's wall time as its jobs saw it, each job's interpreter start, imports and set-up
    included (the mesh before and the aggregation after are not). None unless every case has
    its clock (summaries written before it was recorded have none), since a part of the cases
    would understate it. Cases solved in separate runs count the time between the runs too.
    """
    if process_start is None or finished is None or not len(finished):
        return None
    if not (np.isfinite(process_start).all() and np.isfinite(finished).all()):
        return None
    return float(finished.max() - process_start.min())
