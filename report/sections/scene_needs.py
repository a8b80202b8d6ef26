"""Model no more than a scene needs: the cheapest model meeting an accuracy need; C1's effect."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from report.common import NEEDS_MM, meets, predict_s, variant_label, worst_case
from report.context import Context
from report.html import finite, fmt, h3, missing, para, seconds, table
from studies.figures import fe as fem_plots
from studies.surrogate_study.postures import PostureRow


@dataclass(frozen=True, slots=True)
class Candidate:
    """A model that can answer a query, with its worst clinical-case errors and its cost.

    Attributes:
        name: readable name.
        max_error_mm: the largest point error over the cases it is judged on (the clinical
            cases, unless its name says which others).
        mean_error_mm: the largest per-case mean point error over the same cases.
        cost_s: seconds per prediction (surrogate) or per solve (FE), one core.
        against: what the errors are measured against.
        fe: whether it is an FE model (a geometry without a trained surrogate needs one).
    """

    name: str
    max_error_mm: float | None
    mean_error_mm: float | None
    cost_s: float | None
    against: str
    fe: bool = False


def candidates(ctx: Context) -> list[Candidate]:
    """Every model with clinical-case errors and a cost on record."""
    out = []
    clinical = ctx.results.get("clinical")
    bench = ctx.results.get("surrogate_benchmark")
    study = ctx.results.get("table2")
    for split, name in (("by_sample", "surrogate, by-sample split"),
                        ("by_case", "surrogate, by-case split (clinical cases unseen)")):
        block = getattr(clinical, split) if clinical is not None else None
        if block is None or not block.rows:
            continue
        rows = block.rows
        max_err = [r.max_error_mm for r in rows]
        mean_err = [r.rmse_mm for r in rows]
        cost = None
        if (split == "by_sample" and bench is not None
                and bench.selected_architecture == block.architecture):
            cost = predict_s(bench)
        if cost is None and study is not None:  # the same architecture's timing in the study
            cost = predict_s(study.rows.get(block.architecture))
        out.append(Candidate(
            f"{name} ({block.architecture})",
            max(max_err) if all(finite(v) for v in max_err) else None,
            max(mean_err) if all(finite(v) for v in mean_err) else None,
            cost, "FE default solution", fe=False))
    # the selected model beyond the clinical cases: at random cases off the sweep's grid and in
    # every posture, where a tumour lies between the material points too
    selected_cost = predict_s(bench) if bench is not None else None
    for key, where in (("off_grid", "at random cases off the grid"),
                       ("postures", "in every posture")):
        result = ctx.results.get(key)
        if result is not None:
            cost = (selected_cost if bench is not None
                    and bench.selected_architecture == result.architecture else None)
            beyond = over_cases(f"surrogate, selected ({result.architecture}), {where}",
                                result.rows, cost)
            out += [beyond] if beyond is not None else []
    fe = ctx.results.get("fe_clinical")
    if fe is not None:
        out.append(Candidate("FE default configuration", worst_case(fe.cases, "max_error_mm"),
                             worst_case(fe.cases, "mean_error_mm"), fe.summary.median_wall_s,
                             "refined FE reference", fe=True))
    sa = ctx.results.get("fe_speed_accuracy")
    for v in sa.variants if sa is not None else []:
        if v.skipped:
            continue
        default = " (the default's discretisation)" if v.variant == sa.default_variant else ""
        out.append(Candidate(f"FE {variant_label(v.variant)}{default}",
                             worst_case(v.cases, "max_error_mm"),
                             worst_case(v.cases, "mean_error_mm"), v.median_wall_s,
                             "refined FE reference", fe=True))
    return out


def over_cases(name: str, rows: list[PostureRow], cost_s: float | None) -> Candidate | None:
    """A model judged over FE cases, or None where no case was compared.

    Its largest error at the points or between them (the cells' centroids), and its largest
    per-case mean.
    """
    compared = [r for r in rows if r.errors is not None]
    if not compared:
        return None
    worst = max(max(r.errors.max_mm, r.between.max_mm if r.between else 0.0) for r in compared)
    return Candidate(f"{name} ({len(compared)} cases)", worst,
                     max(r.errors.mean_mm for r in compared), cost_s, "FE of each case")


NEEDS_HEADER = ["accuracy need", "cheapest at every point", "cheapest FE at every point",
                "cheapest on average", "cheapest FE on average",
                "models meeting it (every point / on average)"]


def needs_rows(cands: list[Candidate]) -> list[list[str]]:
    """Per accuracy need (:data:`NEEDS_HEADER`): the cheapest model meeting it, and FE's.

    The cheapest FE model is the answer for a geometry without a trained surrogate (a new
    patient's), and says how much FE a need costs; the last column counts the models that meet
    the need, of those with errors on record.
    """
    def cheapest(meeting: list[Candidate]) -> str:
        costed = [c for c in meeting if finite(c.cost_s)]
        if not costed:
            return "none"
        best = min(costed, key=lambda c: c.cost_s)
        return f"{best.name} ({seconds(best.cost_s)})"

    rows = []
    for need in NEEDS_MM:
        row, counts = [f"{need:g} mm"], []
        for attr in ("max_error_mm", "mean_error_mm"):
            meeting = [c for c in cands if meets(getattr(c, attr), need)]
            row += [cheapest(meeting), cheapest([c for c in meeting if c.fe])]
            counts.append(str(len(meeting)))
        rows.append([*row, f"{' / '.join(counts)} of {len(cands)}"])
    return rows


def c1_effect(
    C1: np.ndarray, phi: np.ndarray, theta: np.ndarray, displacement: np.ndarray,
    converged: np.ndarray,
) -> dict[str, np.ndarray]:
    """How much C1 changes the displacement at each gravity direction of a sweep.

    For each (Φ, θ) with at least two converged C1 values: ``spread_mm``, the largest
    point difference between the softest and the stiffest case; ``single_mm``, the
    error of the best single C1 (for each candidate C1, the largest point difference to
    any other C1 at that angle; the smallest over the candidates); ``relative``, the
    spread over the largest |u| at that angle; ``best_C1``, the candidate achieving
    ``single_mm``.

    Args:
        C1: per case, kPa.
        phi: per case, degrees.
        theta: per case, degrees.
        displacement: (cases, points, 3), mm.
        converged: per case.
    """
    keys = sorted(
        {(round(float(p), 6), round(float(t), 6)) for p, t in zip(phi, theta, strict=True)}
    )
    out: dict[str, list[float]] = {k: [] for k in ("phi", "theta", "spread_mm", "single_mm",
                                                   "relative", "best_C1", "C1_min", "C1_max")}
    for p, t in keys:
        cases = np.flatnonzero(np.isclose(phi, p) & np.isclose(theta, t) & converged)
        if len(np.unique(C1[cases])) < 2:
            continue
        cases = cases[np.argsort(C1[cases])]
        u = displacement[cases]
        spread = float(np.linalg.norm(u[-1] - u[0], axis=1).max())
        worst = np.array([np.linalg.norm(u - u[i], axis=2).max() for i in range(len(cases))])
        best = int(np.argmin(worst))
        peak = float(np.linalg.norm(u, axis=2).max())
        for key, value in (("phi", p), ("theta", t), ("spread_mm", spread),
                           ("single_mm", float(worst[best])),
                           ("relative", spread / peak if peak > 0 else np.nan),
                           ("best_C1", float(C1[cases[best]])), ("C1_min", float(C1[cases[0]])),
                           ("C1_max", float(C1[cases[-1]]))):
            out[key].append(value)
    return {k: np.asarray(v, float) for k, v in out.items()}


def c1_verdicts(effect: dict[str, np.ndarray], full: np.ndarray,
                C1_range: tuple[float, float]) -> str:
    """Per accuracy need, the directions that can use a single C1 over the whole C1 range.

    Only the directions whose converged cases span ``C1_range`` (``full``) are judged: a
    spread over part of the range says nothing of the rest. The others are counted apart.
    """
    span = f"{C1_range[0]:g}–{C1_range[1]:g} kPa"
    partial = int((~full).sum())
    tail = (f" Left out: {partial} direction{'s' if partial != 1 else ''} solved over part of "
            "the range (the table gives each one's C1 values).") if partial else ""
    single, phi, theta = (effect[k][full] for k in ("single_mm", "phi", "theta"))
    if not single.size:
        return (f"No direction has converged cases over the whole C1 range {span}, so no "
                f"verdict is given.{tail}")
    sentences = []
    for need in NEEDS_MM:
        ok = single <= need
        if ok.all():
            sentences.append(f"For a {need:g} mm need, every such direction can use a single C1.")
        elif not ok.any():
            sentences.append(f"For a {need:g} mm need, no direction can use a single C1 (the "
                             f"smallest single-C1 error is {single.min():.3g} mm).")
        else:
            angles = ", ".join(f"{p:g}°" if t == 0 else f"{p:g}°/{t:g}°" for p, t in
                               zip(phi[ok], theta[ok], strict=True))
            sentences.append(f"For a {need:g} mm need, a single C1 is enough at Φ = {angles}.")
    judged = (f"the {single.size} directions" if single.size > 1 else "the one direction")
    return f"Over C1 = {span}, at {judged} solved over all of it: " + " ".join(sentences) + tail


def scene_needs_section(ctx: Context) -> str:
    """The scene-needs section: the cheapest model per accuracy need, and C1's effect."""
    cands = candidates(ctx)
    out = [para(
        "Which model is enough for a given accuracy need? For each model: its worst "
        "error over the clinical cases (the largest error at any material point, and the "
        "largest per-case mean error) and its cost per answer on one core. The surrogates' "
        "errors are measured against the default FE solution (so they add to the FE "
        "default's own error against the refined reference, listed in its row); the FE "
        "variants' errors are against the refined reference. A surrogate's cost is one "
        "whole-field prediction on one pinned core (the by-case model's is its "
        "architecture's timing in the architecture study); an FE model's is the median "
        "wall time of a clinical-case solve, set-up excluded. A model meets a need when its "
        "error is at most the need; the cheapest such model is named, and the cheapest FE "
        "model apart: a geometry without a trained surrogate (a new patient's) needs FE. The "
        "selected surrogate is also judged beyond the clinical cases: at the random cases off "
        "the sweep's grid and in every posture, at the material points and between them (the "
        "cells' centroids, where a tumour lies), against each case's FE solution. The paper's "
        "clinically accepted error is 5 mm.", "caption")]
    if not cands:
        out.append(para("No model has clinical-case errors on record.", "note"))
    else:
        rows = [[c.name, fmt(c.max_error_mm, ".3g"), fmt(c.mean_error_mm, ".3g"),
                 seconds(c.cost_s), c.against] for c in sorted(
                     cands, key=lambda c: (c.cost_s is None, c.cost_s or 0.0))]
        out.append(table(["model", "worst max error (mm)", "worst mean error (mm)",
                           "cost per answer", "errors against"], rows, table_id="candidates"))
        out.append(table(NEEDS_HEADER, needs_rows(cands), table_id="needs"))
    out.append(h3("Can C1's effect be skipped?"))
    ds = ctx.dataset()
    if ds is None:
        out.append(missing("results/dataset/dataset.h5"))
        return "".join(out)
    effect = c1_effect(ds.C1, ds.phi, ds.theta, ds.displacement, ds.converged)
    if effect["phi"].size == 0:
        out.append(para("The sweep has fewer than two converged C1 values at every angle, so "
                      "C1's effect cannot be measured.", "note"))
        return "".join(out)
    C1_range = (float(np.min(ds.C1)), float(np.max(ds.C1)))
    full = ((effect["C1_min"] <= C1_range[0] * (1 + 1e-9))
            & (effect["C1_max"] >= C1_range[1] * (1 - 1e-9)))
    out.append(para(
        "For each gravity direction of the sweep: the largest difference, over the material "
        "points, between the displacement of the softest and the stiffest tissue solved there "
        "(circles), and the error left if one modelled that direction with a single, "
        "best-chosen C1 (squares: the largest difference from it to any other C1 solved "
        "there). A scene whose accuracy need (grey lines) lies above the squares can use one "
        "C1 in that direction. Grey markers: directions whose converged cases span part of the "
        "sweep's C1 range only (a refinement band's directions, solved at its own C1 values, "
        "or a direction whose softest cases failed): their spread is C1's effect over that "
        "part, so they are left out of the verdicts below. Right: the spread as a share of "
        "the largest displacement in that direction.", "caption"))
    out.append(ctx.figure(
        "c1_effect.png",
        lambda p: fem_plots.plot_c1_effect(effect["phi"], effect["spread_mm"], effect["single_mm"],
                                           effect["relative"], p, NEEDS_MM, C1_range,
                                           effect["theta"], full=full),
        "C1's effect on the displacement per gravity angle",
        "Displacement spread across the C1 range against the gravity angle Φ."))
    out.append(para(c1_verdicts(effect, full, C1_range)))
    rows = [[f"{p:g}", f"{t:g}", f"{lo:g}–{hi:g}", f"{s:.3g}", f"{100 * r:.3g}", f"{w:.3g}",
             f"{b:g}"]
            for p, t, lo, hi, s, r, w, b in zip(
                effect["phi"], effect["theta"], effect["C1_min"], effect["C1_max"],
                effect["spread_mm"], effect["relative"], effect["single_mm"], effect["best_C1"],
                strict=True)]
    out.append(table(["Φ (deg)", "θ (deg)", "C1 solved (kPa)", "spread (mm)",
                       "spread / max |u| (%)", "best single-C1 error (mm)",
                       "best single C1 (kPa)"], rows, table_id="c1-effect"))
    return "".join(out)
