"""The fold with and without the skin's self-contact: old and new state, side by side."""

from __future__ import annotations

from typing import Any

from report.context import Context
from report.html import fmt, missing, para, table
from studies.figures import fe as fem_plots


def fold_section_section(ctx: Context) -> str:
    """The chosen cases cut at the fold (a picture and a table), or why there are none."""
    folds = ctx.results.get("fe_fold_section")
    if folds is None:
        return missing("results/fe_study/fold_section.json")
    if not folds.cases:
        return para("No case was cut at the fold (fe_study.fold_section names none and the "
                    "sweep has no self-contact force to choose by).", "note")
    out = [para(
        "What the skin's self-contact (fe.self_contact) changes where the breast folds onto "
        "itself: each case solved with it and without it on the sweep's mesh, and cut through "
        "the skin node that carries the largest self-contact pressure by the plane that holds "
        "the way the mound rolls: sagittal (y fixed) where gravity leans towards the feet or "
        "the head, transverse (z fixed) where it leans to the side. "
        "The cut is material: the same skin, drawn where each state carries it (a failed "
        "solve shows the last load it reached). Without self-contact the mound's underside "
        "can cross the skin below the fold, a state no breast takes; with it the two sides "
        f"rest on each other. {folds.seconds:.0f} s in all.", "caption")]
    out.append(ctx.figure(
        "fold_section.png",
        lambda p: fem_plots.plot_fold_section([c.to_json() for c in folds.cases], p),
        "the fold's cross-section with and without self-contact",
        "Per case: the whole cut (left) and the fold (right); grey the unloaded reference, red "
        "without self-contact, blue with it; the legend gives each state's max |u|, its outcome "
        "and its boundary vertices inside other cells."))
    out.append(table(
        ["case", "setting", "outcome", "load reached", "max |u| (mm)",
         "boundary vertices inside other cells", "self-contact force (N)", "solve (s)"],
        [_row(c.case, s) for c in folds.cases for s in c.states], table_id="fold-section"))
    return "".join(out)


def _row(case: str, state: Any) -> list[str]:
    return [case, state.setting, state.status, fmt(state.load_fraction, ".3f"),
            fmt(state.max_disp_mm, ".2f"),
            "n/a" if state.self_overlap is None else str(state.self_overlap),
            "—" if state.self_contact_force_N is None else fmt(state.self_contact_force_N, ".3g"),
            fmt(state.wall_s, ".1f")]
