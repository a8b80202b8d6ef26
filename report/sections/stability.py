"""Stability: where the FE solve fails, on the study's grid and in the sweep itself."""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from report.common import PAPER_C1_RANGE
from report.context import Context
from report.html import fmt, h3, missing, para, pct, table
from report.sections.fold import fold_section_section
from studies.figures import fe as fem_plots


def _scheme(s: Mapping[str, Any]) -> str:
    """One loading scheme of the convergence map, in words."""
    if s.get("fixed_steps"):
        return f"{s.get('fixed_steps')} equal load steps"
    text = (f"adaptive steps from {s.get('initial_step', 'n/a')} of the load, "
            f"cut back on failure down to {fmt(s.get('min_step'), '.3g')}")
    if s.get("rescue"):
        text += f", then a last resort from rest down to {fmt(s.get('rescue_min_step'), '.3g')}"
    return text


def stability_section(ctx: Context) -> str:
    """The stability section: where the FE solve fails, and whether its states are stable.

    The convergence map of the study's grid and of the sweep, where the sweep's failures begin,
    the fold, and the audit of the sweep's converged states.
    """
    out = []
    stab = ctx.results.get("fe_convergence_map")
    if stab is None:
        out.append(missing("results/fe_study/convergence_map.json"))
    else:
        records = stab.records
        described = "; ".join(f"{name}: {_scheme(s)}" for name, s in stab.schemes.items())
        out.append(para(
            "Where the nonlinear FE solve struggles or fails: each cell is one solve from rest "
            "at a tissue stiffness C1 (rows) and gravity angle Φ (columns), extended below the "
            f"paper's range (C1 ≥ {PAPER_C1_RANGE[0]:g} kPa, dashed line). One column of panels "
            "per loading scheme, the same colour scale along each row: accepted load steps, "
            "Newton iterations over all attempts, and rejected load steps (attempts that "
            "failed and were retried with a smaller step). A cross marks a case that did not "
            "reach the full load; its colour names the first failure. "
            f"Schemes — {described}. Mesh: {Path(stab.mesh).parent.name}, "
            f"{fmt(stab.dofs, 'd')} DOFs.", "caption"))
        if records:
            out.append(ctx.figure(
                "convergence_maps.png",
                lambda p: fem_plots.plot_convergence_maps([r.to_json() for r in records], p,
                                                        PAPER_C1_RANGE[0]),
                "convergence maps over C1 and gravity angle",
                "Load steps, Newton iterations and rejected steps over (Φ, C1) per scheme."))
        lowest = stab.lowest_converging
        if lowest:
            out.append(para("The lowest C1 from which every stiffer C1 of the grid converged, per "
                          "scheme and angle, and what went wrong at the next C1 below "
                          "(\"—\": nothing failed down to the grid's lowest C1).", "caption"))
            out.append(lowest_converging_table(lowest, "lowest-converging"))
        failed = [r for r in records if not r.converged]
        if failed:
            out.append(table(
                ["scheme", "C1 (kPa)", "Φ (deg)", "load reached (%)", "first failure",
                 "failure kinds (count)", "reason"],
                [[r.scheme, f"{r.C1:g}", f"{r.phi:g}", pct(r.load_fraction),
                  r.first_failure or "n/a",
                  ", ".join(f"{k} {v}" for k, v in r.failure_kinds.items()) or "n/a",
                  r.reason] for r in failed], table_id="failed-cases"))
        else:
            out.append(para("Every case of the convergence map's grid converged under every "
                            "scheme."))
    out.append(h3("The sweep on its own mesh"))
    out.append(_sweep_convergence(ctx))
    out.append(h3("Where the sweep's failures begin"))
    out.append(failure_edges_section(ctx.results.get("fe_failure_edges")))
    out.append(h3("The fold with and without self-contact"))
    out.append(fold_section_section(ctx))
    out.append(h3("Are the sweep's converged states stable?"))
    out.append(stability_audit_section(ctx.results.get("fe_stability_audit")))
    return "".join(out)


def lowest_converging_table(lowest: Mapping[str, Any], table_id: str) -> str:
    """Per Φ and scheme: the lowest converging C1 and the first failure below it."""
    names = list(lowest)
    phis = sorted({k for s in lowest.values() for k in s if k != "all_phi"}, key=float)
    rows = []
    for phi in phis:
        row = [f"{float(phi):g}"]
        for name in names:
            item = lowest[name].get(phi) or {}
            below = item.get("failed_below")
            row.append(fmt(item.get("lowest_C1"), "g"))
            row.append("—" if not below else
                       f"C1 {fmt(below.get('C1'), 'g')}: "
                       f"{below.get('first_failure') or 'n/a'} at "
                       f"{pct(below.get('load_fraction'))} % of the load")
        rows.append(row)
    rows.append(["every Φ"] + [v for name in names
                               for v in (fmt(lowest[name].get("all_phi"), "g"), "")])
    header = ["Φ (deg)"] + [h for name in names
                            for h in (f"{name}: lowest converging C1 (kPa)",
                                      f"{name}: first failure below it")]
    return table(header, rows, highlight=[len(rows) - 1], table_id=table_id)


def _sweep_convergence(ctx: Context) -> str:
    """The sweep's convergence over (C1, Φ), on the mesh the dataset was solved on."""
    from studies.fe_study.convergence_map import lowest_converging, sweep_records

    columns = ctx.case_columns()
    if not columns:
        return missing("results/dataset/dataset.h5")
    keys = ("C1", "phi", "theta", "converged", "load_fraction", "first_failure", "reason",
            "min_detF")
    if any(k not in columns for k in keys):
        return para("The dataset predates the first-failure record; rebuild it "
                  "(snakemake --forcerun aggregate) to map the sweep's failures.", "note")
    cases = {k: columns[k] for k in keys}
    records = sweep_records(cases)
    if not records:
        return para("The sweep has no case at θ = 0, so there is no (C1, Φ) map of it.", "note")
    failed = ~cases["converged"].astype(bool)
    out = [para(
        f"The sweep itself is a convergence map at the paper's resolution, solved on the mesh "
        f"of the dataset: {int(failed.sum())} of {len(failed)} cases did not reach the full "
        "load. Per Φ: the lowest C1 from which every stiffer C1 of the sweep converged, and "
        "what failed first at the next C1 below it (\"—\": every C1 solved at that Φ "
        "converged; a refinement band's directions start at its own C1_min). The last row: "
        "the lowest C1 from which every case converged.",
        "caption")]
    out.append(lowest_converging_table(lowest_converging(records), "sweep-lowest-converging"))
    if failed.any():
        rows = [[f"{cases['C1'][i]:g}", f"{cases['phi'][i]:g}", f"{cases['theta'][i]:g}",
                 pct(cases["load_fraction"][i]), cases["first_failure"][i] or "n/a",
                 fmt(cases["min_detF"][i], ".2g"), cases["reason"][i]]
                for i in np.flatnonzero(failed)]
        out.append(table(["C1 (kPa)", "Φ (deg)", "θ (deg)", "load reached (%)",
                           "first failure", "min det F of the last converged state", "reason"],
                          rows, table_id="sweep-failed-cases"))
    out.append(sweep_contact_and_overlap(columns, failed))
    return "".join(out)


def _cases_end(n: int) -> str:
    """'1 case ends' or 'n cases end'."""
    return f"{n} case ends" if n == 1 else f"{n} cases end"


def sweep_contact_and_overlap(columns: dict[str, np.ndarray], failed: np.ndarray) -> str:
    """Which cases end in contact with the chest or with themselves, which pass through."""
    def case(i: int) -> str:
        return f"C1 = {columns['C1'][i]:g} kPa at Φ = {columns['phi'][i]:g}°"

    out = []
    # (column, the sentence without it, what the sweep was solved with, how a case ends)
    kinds = (
        ("contact_force_N", "The sweep was solved without contact (fe.contact): nothing keeps "
         "the skin out of the chest below the fold.",
         "contact of the skin with the chest", "in contact"),
        ("self_contact_force_N", "The sweep was solved without self-contact "
         "(fe.self_contact): nothing keeps the skin from passing through itself at the fold.",
         "self-contact of the skin", "with the skin resting on itself"),
    )
    for column, without, solved_with, ending in kinds:
        if column not in columns:
            continue  # an older dataset
        force = np.asarray(columns[column], dtype=float)
        if np.isnan(force).all():
            out.append(without)
            continue
        touching = np.flatnonzero(np.nan_to_num(force) > 0)
        largest = (f", the largest force {force[touching].max():.2g} N "
                   f"({case(touching[np.argmax(force[touching])])})" if len(touching) else "")
        out.append(f"Solved with {solved_with}: {_cases_end(len(touching))} {ending}{largest}.")
    if "self_overlap" in columns:
        overlap = np.asarray(columns["self_overlap"])
        through = np.flatnonzero(overlap > 0)
        if len(through):
            itself = "itself" if len(through) == 1 else "themselves"
            out.append(f"{_cases_end(len(through))} passing through {itself} (boundary vertices "
                       "inside another cell: the fold's skin creasing into itself), "
                       + ", ".join(f"{case(i)} ({overlap[i]}{', failed' if failed[i] else ''})"
                                   for i in through) + ".")
            converged = int(np.sum(~np.asarray(failed, dtype=bool)[through]))
            if converged:
                which = ("the one that converged is" if converged == 1
                         else f"the {converged} that converged are")
                out.append(f"The data the surrogate learns from and is judged on holds none of "
                           f"them: {which} in no split.")
        else:
            out.append("No case ends passing through itself.")
    return para(" ".join(out), "caption") if out else ""


def failure_edges_section(edges: Any) -> str:
    """The sweep's failed cases traced from their nearest converged direction (a table)."""
    if edges is None:
        return missing("results/fe_study/failure_edges.json")
    if not edges.traced:
        return para("No failed case of the sweep was traced (none failed, or "
                    "fe_study.failure_edges.n is 0).", "note")
    out = [para(
        f"{len(edges.traced)} of the sweep's {edges.failed} failed cases, each traced from the "
        "converged case of the same C1 whose gravity is nearest: gravity turned at full load "
        "along the great circle towards the failed direction, each step a Newton solve from the "
        "last state, a failed step halved down to the resolution. The edge is the angle from "
        "the start where the solution was last found; stable means that every state up to it "
        "is a strict minimum of the potential (the tangent has one negative eigenvalue per "
        "pressure unknown and no null pivot, fem.stability). A turn of gravity is the history "
        "of a patient rolling over: past the edge, Newton from the last state finds no "
        "equilibrium however short the step (down to the resolution). Near an edge two "
        "histories can end in different stable states at one direction (python -m "
        "studies.fe_study.failure_edge --meet compares them). "
        f"{edges.seconds:.0f} s in all.", "caption")]
    rows = []
    for t in edges.traced:
        e = t.edge
        if e is None:
            rows.append([t.case, pct(t.load_fraction), t.start_case,
                         f"{fmt(t.start_sweep_max_mm, '.2f')} / n/a", "n/a",
                         f"not traced: {t.error or 'n/a'}", "", "", "", "", ""])
            continue
        last = e.states[-1]
        rows.append([
            t.case, pct(t.load_fraction), t.start_case,
            f"{fmt(t.start_sweep_max_mm, '.2f')} / {fmt(e.states[0].max_displacement_mm, '.2f')}",
            fmt(e.span_deg, ".1f"),
            "reached" if e.reached_target else fmt(e.edge_deg, ".2f"),
            "—" if e.first_failure_deg is None else fmt(e.first_failure_deg, ".2f"),
            f"{last.phi:.2f} / {last.theta:.2f}", fmt(last.max_displacement_mm, ".1f"),
            fmt(min(s.min_detF for s in e.states), ".3f"),
            "yes" if e.all_stable else "no",
        ])
    out.append(table(
        ["failed case", "its load reached in the sweep (%)", "turned from",
         "its max |u| in the sweep / at the turn's start (mm)", "angle to it (deg)",
         "edge (deg from the start)", "first step that failed (deg)",
         "last solution Φ / θ (deg)", "its max |u| (mm)", "smallest det F on the way",
         "every state stable"], rows, table_id="failure-edges"))
    return "".join(out)


def stability_audit_section(audit: Any) -> str:
    """The sweep's converged cases at its softest C1 values judged for stability (tables)."""
    if audit is None:
        return missing("results/fe_study/stability_audit.json")
    if not audit.C1:
        return para("No case of the sweep was audited (fe_study.stability_audit.softest is 0).",
                    "note")
    out = [para(
        "Every converged case of the sweep's softest C1 values: its state read from the dataset "
        "and polished by Newton at the full load (moved: the largest change at a point), then "
        "judged by its tangent's inertia (stable: one negative eigenvalue per pressure unknown "
        "and no null pivot, fem.stability). An unstable equilibrium solves the equations but "
        "is no state a body rests in: the slightest disturbance carries it elsewhere. "
        f"{audit.seconds:.0f} s in all.", "caption")]
    rows = []
    for value in audit.C1:
        cases, judged, unstable = audit.tally(value)
        rows.append([f"{value:g}", str(len(cases)), str(judged), str(len(unstable)),
                     fmt(max((c.moved_mm for c in cases), default=math.nan), ".1e")])
    out.append(table(["C1 (kPa)", "converged cases", "judged", "unstable",
                      "largest move by the polish (mm)"], rows, table_id="stability-audit"))
    flagged = [c for c in audit.cases if not c.stable]
    if flagged:
        out.append(table(
            ["case", "verdict", "unstable modes", "null pivots", "max |u| (mm)",
             "smallest det F"],
            [[c.case, "unstable" if c.stable is False else f"not judged: {c.error}",
              str(c.unstable_modes), str(c.zero), fmt(c.max_mm, ".1f"), fmt(c.min_detF, ".3f")]
             for c in flagged], table_id="unstable-cases"))
    return "".join(out)
