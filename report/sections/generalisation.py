"""The surrogate between its sweep's cases (whole groups held out) and in every posture."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from report.context import Context
from report.html import fmt, h3, missing, para, pct, table
from studies.surrogate_study.errors_against_fe import CaseErrors, ErrorSpread
from studies.surrogate_study.held_out import (
    BRACKET_LABELS,
    HeldOutBlock,
    by_bracket,
    by_failure_distance,
)
from studies.surrogate_study.off_grid import GOALS_MM
from studies.surrogate_study.postures import PostureRow


def held_out_part(ctx: Context) -> str:
    """Each held-out model on its test cases, the by-sample model on the same cases beside."""
    result = ctx.results.get("held_out")
    if result is None:
        return missing("results/surrogate/held_out.json")
    out = [para(
        "The paper's split draws material points at random, so each of its test cases has "
        "most of its points in the training data. The models here were trained with whole "
        "groups of the sweep held out: whole gravity directions, whole C1 values, whole "
        "setups. Each is judged on its held-out cases; the by-sample model (the one used "
        "downstream) beside it on those of the same cases it trained on (refitted, as by "
        "default, every case it does not hold out; a pod model not refitted leaves its "
        "validation cases out). A held-out group's neighbours in the "
        "training data are twice the sweep's spacing apart, so the held-out error is a "
        "pessimistic estimate of the error midway between the full sweep's cases: where it is "
        "close to the "
        "by-sample model's, the sweep is dense enough. Errors per case are the mean, the "
        "95th percentile and the maximum over the material points; the table gives the "
        "mean of the cases' means, the 95th percentile of their 95th percentiles, and the "
        "largest point error of any case, in mm and relative to that case's largest FE "
        "displacement." + BETWEEN, "caption")]
    rows = []
    for block in result.blocks:
        for who, spread, between in (
                ("held out", block.held_out_model, block.held_out_between),
                ("by sample", block.inside_model, block.inside_between)):
            if spread is None:  # the by-sample model trained on none of these cases
                continue
            rows.append([
                block.split.replace("_", "-") if who == "held out" else "",
                block.held_out if who == "held out" else "",
                ", ".join(block.groups) if who == "held out" and len(block.groups) <= 8
                else (f"{len(block.groups)} groups" if who == "held out" else ""),
                f"{who} model", spread.cases, fmt(spread.mean_mm, ".3g"),
                fmt(spread.p95_mm, ".3g"), fmt(spread.max_mm, ".3g"),
                pct(spread.relative_max), _between(between), spread.worst_case,
            ])
    inside = result.inside_all
    rows.append(["every case it trained on", "nothing (the by-sample model's own data)", "",
                 "by sample model", inside.cases, fmt(inside.mean_mm, ".3g"),
                 fmt(inside.p95_mm, ".3g"), fmt(inside.max_mm, ".3g"),
                 pct(inside.relative_max), _between(result.inside_all_between),
                 inside.worst_case])
    out.append(table(
        ["split", "holds out", "held-out groups", "model", "cases", "mean (mm)",
         "p95 (mm)", "max (mm)", "max / case max |u| (%)",
         "between the points: mean / p95 / max (mm)", "worst case"],
        rows, table_id="held-out"))
    out.append(_near_failures(result.blocks))
    out.append(_c1_bracketed(result.blocks))
    out.append(_misses_warned(result.blocks))
    out.append(_unstable_set_aside(ctx.results.get("fe_stability_audit")))
    return "".join(out)


def _unstable_set_aside(audit: Any) -> str:
    """The cases whose FE state the stability audit found unstable: set aside as failed."""
    if audit is None or not audit.unstable:
        return ""
    cases = [c.case for c in audit.unstable]
    return para(
        f"{len(cases)} converged case{'s' if len(cases) > 1 else ''} of the sweep "
        f"({', '.join(cases)}) end{'' if len(cases) > 1 else 's'} on an unstable equilibrium "
        "(the stability section's audit): no state a body rests in, so no answer. They are "
        "set aside as the failed cases are: no model trains or is tested on them, and the "
        "models warn beside them.", "caption")


def _near_failures(blocks: Sequence[HeldOutBlock]) -> str:
    """The held-out errors by the cases' angle to the nearest failed direction of their C1."""
    rows = []
    for block in blocks:
        distances = block.failure_distance_deg
        if len(distances) != len(block.rows) or all(math.isnan(d) for d in distances):
            continue
        for band, spread in by_failure_distance(block.rows, distances):
            rows.append([block.split.replace("_", "-"), band, spread.cases,
                         fmt(spread.mean_mm, ".3g"), fmt(spread.p95_mm, ".3g"),
                         fmt(spread.max_mm, ".3g"), spread.worst_case])
    if not rows:
        return ""
    return "".join([
        para("The held-out models' errors by how near each held-out case lies to a direction "
             "where the sweep failed at the same C1 (the angle between the gravity "
             "directions). Beside a failure the sweep has no data beyond it, and there the FE "
             "answer can itself depend on the history: the stability section's 'Where the "
             "sweep's failures begin'.", "caption"),
        table(["split", "angle to the nearest failure at its C1", "cases", "mean (mm)",
               "p95 (mm)", "max (mm)", "worst case"], rows, table_id="held-out-near-failures"),
    ])


def _c1_bracketed(blocks: Sequence[HeldOutBlock]) -> str:
    """The by-C1 model's errors where a held-out C1 lies between trained ones at its direction."""
    rows = []
    for block in blocks:
        if block.split != "by_c1" or len(block.bracketed) != len(block.rows):
            continue
        warned = block.warned if len(block.warned) == len(block.rows) else None
        for label, spread in by_bracket(block.rows, block.bracketed):
            flag = label == BRACKET_LABELS[True]
            told = ("" if warned is None else sum(
                w for b, w in zip(block.bracketed, warned, strict=True) if b == flag))
            rows.append([label, spread.cases, told, fmt(spread.mean_mm, ".3g"),
                         fmt(spread.p95_mm, ".3g"), fmt(spread.max_mm, ".3g"),
                         spread.worst_case])
    if not rows:
        return ""
    return "".join([
        para("The by-C1 model's held-out cases by whether the model trained on a softer and a "
             "stiffer C1 at the same direction. The split always holds out the second softest "
             "C1, where the field changes fastest with C1; at a direction solved at fewer C1 "
             "values (a refined band) or where the softer cases failed, that value lies beyond "
             "the trained ones there, and the model extrapolates. 'Warned' counts the cases "
             "where the model says so itself (an extrapolation warning: below the softest C1 "
             "trained beside the direction, or beside a failed solve).", "caption"),
        table(["held-out C1", "cases", "warned", "mean (mm)", "p95 (mm)", "max (mm)",
               "worst case"], rows, table_id="held-out-c1-bracketed"),
    ])


def _misses_warned(blocks: Sequence[HeldOutBlock]) -> str:
    """Per held-out model: its cases over the largest-error goal, and how many it warned at."""
    rows = []
    for block in blocks:
        if len(block.warned) != len(block.rows):  # a record written before warnings were kept
            continue
        over = [w for r, w in zip(block.rows, block.warned, strict=True)
                if r.max_mm > GOALS_MM["max"]]
        rows.append([block.split.replace("_", "-"), len(block.rows), sum(block.warned),
                     len(over), sum(over), len(over) - sum(over)])
    if not rows:
        return ""
    return "".join([
        para(f"Where a user meets a held-out model's largest errors: its held-out cases, those "
             f"at which it warns that the prediction is an extrapolation, those whose largest "
             f"point error exceeds the goal of {GOALS_MM['max']:g} mm, and how many of these it "
             f"warned at. A miss without a warning is one a user is not told of.", "caption"),
        table(["split", "cases", "warned", f"over {GOALS_MM['max']:g} mm", "of which warned",
               "not warned"], rows, table_id="held-out-warned"),
    ])


def warning_coverage_part(ctx: Context) -> str:
    """How much of the selected model's trained range it answers without a warning."""
    result = ctx.results.get("warning_coverage")
    if result is None:
        return missing("results/surrogate/warning_coverage.json")
    low, high = result.c1_kpa
    rows = [[f"[{band.c1_low:g}, {band.c1_high:g}{']' if band.c1_high == high else ')'}",
             band.queries, band.warned, pct(band.share, ".2f")] for band in result.bands]
    rows.append(["all", result.queries, result.warned, pct(result.share, ".2f")])
    kinds = "; ".join(f"{kind}: {count}" for kind, count in result.kinds.items())
    return "".join([
        para(f"The tables above give how large the misses are where the model warns; this gives "
             f"how much of its range a user meets a warning in. {result.drawn:,} gravity "
             f"directions (for a model of the paper's plane, Φ alone) were drawn evenly and "
             f"kept where they lie among the training directions ({result.queries:,} queries), "
             f"each with C1 drawn evenly in the trained range {low:g}–{high:g} kPa (seed "
             f"{result.seed}); each query's checks were run as a prediction runs them. A "
             f"warned query is one where no FE solution of the sweep backs an answer: beside a "
             f"case whose FE solve failed at that C1 or a stiffer one, or below the softest C1 "
             f"solved beside its direction. The share warned is that of the range, not of the "
             f"queries users make.", "caption"),
        table(["C1 (kPa)", "queries", "warned", "warned (%)"], rows, table_id="warning-coverage"),
        para(f"Warned queries by kind (each counted once, under the first that applies): "
             f"{kinds}.", "note"),
    ])


BETWEEN = (
    " A tumour lies between the material points the model trained on: the column 'between "
    "the points' gives the same errors at the FE mesh's cell centroids, where the FE field is "
    "known exactly from its quadratic cells (blank where the mesh is linear). The centroids "
    "lie inside the body; the skin's points are among the material points.")


def _between(spread: CaseErrors | ErrorSpread | None) -> str:
    """Mean / p95 / max (mm) of errors at the cell centroids, or blank where not measured."""
    if spread is None:
        return ""
    return " / ".join(fmt(v, ".3g") for v in (spread.mean_mm, spread.p95_mm, spread.max_mm))


#: The columns of :func:`_fe_row` after its label.
FE_COLUMNS = ["C1 (kPa)", "Φ / θ", "FE max |u| (mm)", "mean error (mm)", "p95 (mm)", "max (mm)",
              "max / FE max (%)", "between the points: mean / p95 / max (mm)",
              "relative to the training data"]


def _fe_row(label: str, row: PostureRow) -> list[str]:
    """A table row of one case against FE: its errors, or "FE failed" where it did not solve."""
    e = row.errors
    head = [label, fmt(row.C1, "g"), f"{row.phi:g}° / {row.theta:g}°"]
    if e is None:
        return [*head, "FE failed", "", "", "", "", "", row.kind]
    return [*head, fmt(e.fe_max_mm, ".3g"), fmt(e.mean_mm, ".3g"), fmt(e.p95_mm, ".3g"),
            fmt(e.max_mm, ".3g"), pct(e.relative_max), _between(row.between), row.kind]


def postures_part(ctx: Context) -> str:
    """The surrogate against FE in each posture of ``surrogate_study.postures``."""
    result = ctx.results.get("postures")
    if result is None:
        return missing("results/surrogate/postures.json")
    if not result.rows:
        return para("No posture is configured (surrogate_study.postures).", "note")
    out = [para(
        f"The selected model ({result.architecture}) in the postures a patient takes, each a "
        "direction of gravity relative to the body at a few stiffnesses, against FE: the "
        "sweep's solution where the sweep has the case, else an extra solve outside it. The "
        "last column says whether the posture lies among the directions and stiffnesses the "
        "model was trained on; a posture outside them (standing and reclined are out of the "
        "paper's plane) is an extrapolation, and its error says what a sweep over the whole "
        "sphere of directions would buy." + BETWEEN, "caption")]
    rows = [_fe_row(row.posture, row) for row in result.rows]
    out.append(table(["posture", *FE_COLUMNS], rows, table_id="postures"))
    moved = [r for r in result.rows if r.movement is not None]
    if moved:
        first = result.rows[0].posture
        out.append(para(
            f"From {first} (the first posture; prone is the MRI's) to each other posture at the "
            "same C1: the way the breast takes, which a tumour seen in the image takes too. FE's "
            "largest movement of a material point, and the surrogate's error in the movement "
            "(its movement minus FE's, at the material points).", "caption"))
        out.append(table(
            ["posture", "C1 (kPa)", f"FE's largest movement from {first} (mm)",
             "error in it: mean / p95 / max (mm)", "max / FE's largest movement (%)"],
            [[r.posture, fmt(r.C1, "g"), fmt(r.movement.fe_max_mm, ".3g"),
              f"{r.movement.mean_mm:.3g} / {r.movement.p95_mm:.3g} / {r.movement.max_mm:.3g}",
              pct(r.movement.relative_max)] for r in moved], table_id="postures-movement"))
    failed = [r for r in result.rows if r.errors is None]
    if failed:
        out.append(para("FE solves that failed (no comparison): " + "; ".join(
            f"{r.posture} ({r.case}): {r.fe_reason}" for r in failed), "note"))
    return "".join(out)


def off_grid_part(ctx: Context) -> str:
    """The selected model at the random cases of ``surrogate_study.off_grid``, against FE."""
    result = ctx.results.get("off_grid")
    if result is None:
        return missing("results/surrogate/off_grid.json")
    if not result.rows:
        return para("No test set off the grid is configured (surrogate_study.off_grid).", "note")
    goals = result.goals_mm
    out = [para(
        f"The selected model ({result.architecture}) at cases drawn at random within the "
        "sweep's range, none of them on its grid: C1 uniform in the compliance 1/C1 (soft "
        "cases as often as their share of the displacements), gravity uniform over the part "
        "of the sphere the config names; each solved by FE from rest outside the sweep. Unlike "
        "the held-out models above, this is the model a user queries, between the sweep's "
        "points as a user meets it. Errors per case as in the tables above; the last row "
        "gives the set's spread (mean of the means, 95th percentile of the 95th percentiles, "
        f"largest point error) against the goals of {goals['mean']:g} mm mean and "
        f"{goals['max']:g} mm at any point." + BETWEEN, "caption")]
    rows = [_fe_row(row.case, row)
            for row in sorted(result.rows, key=lambda r: (r.C1, r.phi, r.theta))]
    spread = result.spread
    if spread is not None:
        verdict = "both goals met" if result.goals_met else "a goal missed"
        rows.append([f"all {spread.cases} compared ({verdict})", "", "", "",
                     fmt(spread.mean_mm, ".3g"), fmt(spread.p95_mm, ".3g"),
                     fmt(spread.max_mm, ".3g"), pct(spread.relative_max),
                     _between(result.between), f"worst: {spread.worst_case}"])
    out.append(table(["case", *FE_COLUMNS], rows, table_id="off-grid"))
    if result.failed:
        out.append(para(f"{len(result.failed)} of {len(result.rows)} FE solves failed (no "
                        "comparison): " + "; ".join(f"{r.case}: {r.fe_reason}"
                                                    for r in result.failed), "note"))
    return "".join(out)


def generalisation_section(ctx: Context) -> str:
    """Held-out groups, random cases off the grid, then the clinical postures."""
    return "".join([h3("Between the sweep's cases: whole groups held out"), held_out_part(ctx),
                    h3("Where the model warns over its trained range"),
                    warning_coverage_part(ctx),
                    h3("At random cases off the grid"), off_grid_part(ctx),
                    h3("In every posture"), postures_part(ctx)])


__all__ = ["generalisation_section", "held_out_part", "off_grid_part", "postures_part",
           "warning_coverage_part"]
