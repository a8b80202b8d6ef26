"""FE speed against accuracy: the variants, their Pareto front, the default on clinical cases."""

from __future__ import annotations

from typing import Any

from report.common import COST_LABELS, TARGET_NAMES, meets, variant_label
from report.context import Context
from report.html import finite, fmt, h3, missing, para, pct, seconds, table, yes
from studies.fe_study.fe_speed_accuracy import SpeedAccuracy
from studies.fe_study.fe_timing import SelfOverlap
from studies.figures import fe as fem_plots


def _fe_variant_points(sa: SpeedAccuracy) -> list[dict[str, Any]]:
    """The solved variants of the speed-accuracy study, as points of its chart."""
    front = set(sa.pareto_front)
    points = []
    for v in sa.variants:
        error, cost = v.max_relative_error, v.cost(sa.cost)
        if v.skipped or not (finite(error) and finite(cost)):
            continue
        points.append({
            "variant": v.variant, "cost_s": cost, "relative_error": error,
            "element": v.element, "solver": v.solver,
            "pareto": v.variant in front or bool(v.pareto),
            "default": v.variant == sa.default_variant,
            "cheapest": v.variant == sa.cheapest_meeting_target,
        })
    return points


def _overlap(record: SelfOverlap | None) -> str:
    """``k of n`` boundary vertices inside other cells of the deformed body, or n/a."""
    if record is None:
        return "n/a"
    return f"{record.overlapping_vertices} of {record.boundary_vertices}"


def _cheapest_and_default(sa: SpeedAccuracy) -> str:
    """A sentence naming the cheapest variant meeting the target and placing the default."""
    target = sa.target_relative_max_error
    default_id, cheapest = sa.default_variant, sa.cheapest_meeting_target
    by_id = {v.variant: v for v in sa.variants}

    def described(variant_id: str) -> str:
        v = by_id.get(variant_id)
        cost = v.cost(sa.cost) if v is not None else None
        error = v.max_relative_error if v is not None else None
        return (f"{variant_label(variant_id)}: {seconds(cost)} per case, error "
                f"{pct(error)} %")

    if cheapest is None:
        text = [f"No variant meets the accuracy target of {pct(target)} %."]
    else:
        text = [f"The cheapest variant meeting the target of {pct(target)} % is "
                f"{described(cheapest)}."]
    if default_id is None:
        text.append("The default configuration is not recorded in the study.")
    elif default_id not in by_id:
        text.append(f"The default configuration ({variant_label(default_id)}) is not among the "
                    "variants studied, so it cannot be placed on this chart.")
    elif default_id == cheapest:
        text.append("The default configuration is that cheapest variant.")
    else:
        met = meets(by_id[default_id].max_relative_error, target)
        text.append(f"The default configuration ({described(default_id)}) is not the cheapest "
                    f"variant meeting the target; it {'meets' if met else 'does not meet'} "
                    "the target.")
    return " ".join(text)


def _fe_variant_table(sa: SpeedAccuracy) -> str:
    """Every variant of the speed-accuracy study, cheapest first."""
    target = sa.target_relative_max_error
    default_id, cheapest = sa.default_variant, sa.cheapest_meeting_target
    ordered = sorted(sa.variants, key=lambda v: (not finite(v.cost(sa.cost)),
                                                 v.cost(sa.cost) or 0.0))
    rows, highlight = [], []
    for i, v in enumerate(ordered):
        error = v.max_relative_error
        notes = []
        if v.variant == default_id:
            notes.append("default")
        if v.variant == cheapest:
            notes.append("cheapest meeting the target")
            highlight.append(i)
        if v.skipped:
            notes.append(f"skipped: {v.skipped}")
        elif not finite(error):
            notes.append("not every case converged or was compared")
        rows.append([
            variant_label(v.variant), fmt(v.dofs, "d"), fmt(v.cells, "d"),
            seconds(v.median_cpu_s), seconds(v.median_wall_s), pct(error),
            fmt(v.max_error_mm, ".3g"), fmt(v.max_factorization_equivalents, ".3g"),
            yes(v.pareto), yes(meets(error, target)),
            fmt(v.max_overlapping_vertices, "d"), "; ".join(notes),
        ])
    return table(["variant", "DOFs", "cells", "median CPU / case", "median wall / case",
                   "max rel. error (%)", "max error (mm)", "factorisation equivalents", "Pareto",
                   "meets target", "self-overlapping vertices", "note"], rows, highlight,
                  table_id="fe-variants")


def _fe_clinical_tables(ctx: Context) -> str:
    """The default configuration on the clinical cases: targets, then one row per case."""
    fe = ctx.results.get("fe_clinical")
    if fe is None:
        return missing("results/fe_study/fe_clinical.json")
    out = [para(
        "The clinical cases solved with the sweep's own settings, timed on one core; each is "
        f"solved again with a fixed {fe.baseline_steps}-step Newton baseline in "
        "the same process, and compared with the refined reference. A factorisation "
        "equivalent is the solve time divided by the time of one Jacobian assembly, "
        "factorisation and solve of the same system; factorisations counts those the "
        "solve itself did (the default solver keeps one across Newton iterations while "
        "GMRES converges on it in few Krylov iterations). Self-overlap counts the boundary "
        "vertices of the deformed body that lie inside another of its cells: the model has no "
        "contact, so a fold that closes can pass through itself.", "caption")]
    rows = []
    for name, item in fe.summary.targets.items():
        value, goal = item.value, item.target
        shown = ((pct(value), pct(goal)) if name == "relative_max_error"
                 else (fmt(value, ".3g"), fmt(goal, ".3g")))
        rows.append([TARGET_NAMES.get(name, name.replace("_", " ")), *shown, yes(item.met)])
    out.append(table(["measure", "value", "target", "met"], rows, table_id="fe-targets"))
    rows = []
    for c in fe.cases:
        acc = c.accuracy
        rows.append([
            ctx.case_label(c.case), yes(c.converged), seconds(c.wall_s),
            fmt(c.load_steps, "d"), fmt(c.total_newton_iterations, "d"),
            fmt(c.linear_iterations, "d"), fmt(c.preconditioner_builds, "d"),
            fmt(c.factorization_equivalents, ".3g"),
            pct(acc.relative_max_error if acc else None),
            fmt(acc.max_error_mm if acc else None, ".3g"),
            fmt(acc.mean_error_mm if acc else None, ".3g"),
            seconds(c.baseline.wall_s if c.baseline else None),
            fmt(c.baseline_over_adaptive_wall, ".3g"), _overlap(c.self_overlap),
        ])
    out.append(table(["case", "converged", "wall time", "load steps", "Newton its",
                       "Krylov its", "factorisations",
                       "factorisation equivalents", "max rel. error (%)", "max error (mm)",
                       "mean error (mm)", "fixed-step baseline", "baseline / adaptive",
                       "self-overlap"], rows, table_id="fe-clinical"))
    return "".join(out)


def fe_speed_accuracy_section(ctx: Context) -> str:
    """The FE speed-accuracy section: chart, verdict, variant table and the clinical tables."""
    sa = ctx.results.get("fe_speed_accuracy")
    out = []
    if sa is None:
        out.append(missing("results/fe_study/speed_accuracy.json"))
    else:
        cost_label = COST_LABELS.get(sa.cost, f"{sa.cost} per clinical case (s)")
        target = sa.target_relative_max_error
        points = _fe_variant_points(sa)
        out.append(para(
            "Each point is one FE discretisation of the study (mesh size × element × linear "
            f"solver preset): its cost, the {cost_label.replace(' (s)', '')}, against its "
            "discretisation error, the largest displacement difference from a refined "
            "reference solution over the clinical cases, relative to the largest reference "
            "displacement. Lower left is better. Colour gives the element, marker shape the "
            "solver; the black staircase joins the Pareto front (variants no other variant "
            "beats in both cost and error); the dashed red line is the accuracy target; the "
            "red ring marks the default configuration the sweep uses and the green diamond "
            "the cheapest variant meeting the target.", "caption"))
        if points:
            out.append(ctx.figure(
                "fe_speed_accuracy.png",
                lambda p: fem_plots.plot_speed_accuracy(points, p, cost_label, target),
                "FE cost against discretisation error",
                "FE speed against accuracy: cost per case (log) against relative error (log)."))
        else:
            out.append(para("No variant of the study was solved with an error measured.", "note"))
        out.append(para(_cheapest_and_default(sa)))
        out.append(_fe_variant_table(sa))
    out.append(h3("Default configuration on the clinical cases"))
    out.append(_fe_clinical_tables(ctx))
    return "".join(out)
