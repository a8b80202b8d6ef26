"""FE speed against accuracy: the variants, their Pareto front, the default on clinical cases."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from report.common import COST_LABELS, TARGET_NAMES, meets, variant_label
from report.context import Context
from report.html import finite, fmt, h3, missing, para, pct, seconds, table, yes
from studies.figures import fe as fem_plots


def _fe_variant_points(sa: Mapping[str, Any]) -> list[dict[str, Any]]:
    """The solved variants of the speed-accuracy study, as points of its chart."""
    cost_key = sa.get("cost") or "median_cpu_s"
    front = set(sa.get("pareto_front") or [])
    points = []
    for v in sa.get("variants") or []:
        error, cost = v.get("max_relative_error"), v.get(cost_key)
        if v.get("skipped") or not (finite(error) and finite(cost)):
            continue
        points.append({
            "variant": v["variant"], "cost_s": cost, "relative_error": error,
            "element": v.get("element"), "solver": v.get("solver"),
            "pareto": v["variant"] in front or bool(v.get("pareto")),
            "default": v["variant"] == sa.get("default_variant"),
            "cheapest": v["variant"] == sa.get("cheapest_meeting_target"),
        })
    return points


def _overlap(record: Mapping[str, Any] | None) -> str:
    """``k of n`` boundary vertices inside other cells of the deformed body, or n/a."""
    if not record:
        return "n/a"
    return f"{record['overlapping_vertices']} of {record['boundary_vertices']}"


def _cheapest_and_default(sa: Mapping[str, Any]) -> str:
    """A sentence naming the cheapest variant meeting the target and placing the default."""
    cost_key = sa.get("cost") or "median_cpu_s"
    target = sa.get("target_relative_max_error")
    default_id, cheapest = sa.get("default_variant"), sa.get("cheapest_meeting_target")
    by_id = {v["variant"]: v for v in sa.get("variants") or []}

    def described(variant_id: str) -> str:
        v = by_id.get(variant_id, {})
        return (f"{variant_label(variant_id)}: {seconds(v.get(cost_key))} per case, error "
                f"{pct(v.get('max_relative_error'))} %")

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
        met = meets(by_id[default_id].get("max_relative_error"), target)
        text.append(f"The default configuration ({described(default_id)}) is not the cheapest "
                    f"variant meeting the target; it {'meets' if met else 'does not meet'} "
                    "the target.")
    return " ".join(text)


def _fe_variant_table(sa: Mapping[str, Any]) -> str:
    """Every variant of the speed-accuracy study, cheapest first."""
    cost_key = sa.get("cost") or "median_cpu_s"
    target = sa.get("target_relative_max_error")
    default_id, cheapest = sa.get("default_variant"), sa.get("cheapest_meeting_target")
    ordered = sorted(sa.get("variants") or [],
                     key=lambda v: (not finite(v.get(cost_key)), v.get(cost_key) or 0.0))
    rows, highlight = [], []
    for i, v in enumerate(ordered):
        error = v.get("max_relative_error")
        notes = []
        if v["variant"] == default_id:
            notes.append("default")
        if v["variant"] == cheapest:
            notes.append("cheapest meeting the target")
            highlight.append(i)
        if v.get("skipped"):
            notes.append(f"skipped: {v['skipped']}")
        elif not finite(error):
            notes.append("not every case converged or was compared")
        rows.append([
            variant_label(v["variant"]), fmt(v.get("dofs"), "d"), fmt(v.get("cells"), "d"),
            seconds(v.get("median_cpu_s")), seconds(v.get("median_wall_s")), pct(error),
            fmt(v.get("max_error_mm"), ".3g"), fmt(v.get("max_factorization_equivalents"), ".3g"),
            yes(v.get("pareto")) if "pareto" in v else "n/a", yes(meets(error, target)),
            fmt(v.get("max_overlapping_vertices"), "d"), "; ".join(notes),
        ])
    return table(["variant", "DOFs", "cells", "median CPU / case", "median wall / case",
                   "max rel. error (%)", "max error (mm)", "factorisation equivalents", "Pareto",
                   "meets target", "self-overlapping vertices", "note"], rows, highlight,
                  table_id="fe-variants")


def _fe_clinical_tables(ctx: Context) -> str:
    """The default configuration on the clinical cases: targets, then one row per case."""
    fe = ctx.json.get("fe_clinical")
    if fe is None:
        return missing("results/fe_study/clinical.json")
    out = [para(
        "The clinical cases solved with the sweep's own settings, timed on one core; each is "
        f"solved again with a fixed {fe.get('baseline_steps', 'n/a')}-step Newton baseline in "
        "the same process, and compared with the refined reference. A factorisation "
        "equivalent is the solve time divided by the time of one Jacobian assembly, "
        "factorisation and solve of the same system; factorisations counts those the "
        "solve itself did (the default solver keeps one across Newton iterations while "
        "GMRES converges on it in few Krylov iterations). Self-overlap counts the boundary "
        "vertices of the deformed body that lie inside another of its cells: the model has no "
        "contact, so a fold that closes can pass through itself.", "caption")]
    rows = []
    for name, item in ((fe.get("summary") or {}).get("targets") or {}).items():
        value, goal = item.get("value"), item.get("target")
        shown = ((pct(value), pct(goal)) if name == "relative_max_error"
                 else (fmt(value, ".3g"), fmt(goal, ".3g")))
        rows.append([TARGET_NAMES.get(name, name.replace("_", " ")), *shown,
                     yes(item.get("met"))])
    out.append(table(["measure", "value", "target", "met"], rows, table_id="fe-targets"))
    rows = []
    for c in fe.get("cases") or []:
        acc, base = c.get("accuracy") or {}, c.get("baseline") or {}
        rows.append([
            ctx.case_label(c["case"]), yes(c.get("converged")), seconds(c.get("wall_s")),
            fmt(c.get("load_steps"), "d"), fmt(c.get("total_newton_iterations"), "d"),
            fmt(c.get("linear_iterations"), "d"), fmt(c.get("preconditioner_builds"), "d"),
            fmt(c.get("factorization_equivalents"), ".3g"), pct(acc.get("relative_max_error")),
            fmt(acc.get("max_error_mm"), ".3g"), fmt(acc.get("mean_error_mm"), ".3g"),
            seconds(base.get("wall_s")), fmt(c.get("baseline_over_adaptive_wall"), ".3g"),
            _overlap(c.get("self_overlap")),
        ])
    out.append(table(["case", "converged", "wall time", "load steps", "Newton its",
                       "Krylov its", "factorisations",
                       "factorisation equivalents", "max rel. error (%)", "max error (mm)",
                       "mean error (mm)", "fixed-step baseline", "baseline / adaptive",
                       "self-overlap"], rows, table_id="fe-clinical"))
    return "".join(out)


def fe_speed_accuracy_section(ctx: Context) -> str:
    """The FE speed-accuracy section: chart, verdict, variant table and the clinical tables."""
    sa = ctx.json.get("fe_speed_accuracy")
    out = []
    if sa is None:
        out.append(missing("results/fe_study/speed_accuracy.json"))
    else:
        cost_key = sa.get("cost") or "median_cpu_s"
        cost_label = COST_LABELS.get(cost_key, f"{cost_key} per clinical case (s)")
        target = sa.get("target_relative_max_error")
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
