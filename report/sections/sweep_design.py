"""How the sweep chose its cases: the adaptive sweep's rounds, and whether its estimate ranks.

The rounds come from ``results/sweep/rounds.json``
(:class:`studies.sweep.sweep_rounds.SweepRounds`),
the directions and their failures from the dataset, and the check of the estimate against the
surrogate's true error from ``results/sweep/estimate.json``
(:class:`studies.sweep.sweep_estimate.SweepEstimateCheck`, the full report only).
"""

from __future__ import annotations

import numpy as np

from fem.directions import direction_keys
from report.context import Context
from report.html import finite, fmt, h3, missing, para, table
from studies.figures import sweep_design as design_plots
from studies.sweep.sweep_estimate import SweepEstimateCheck
from studies.sweep.sweep_rounds import SweepRounds

ROUNDS_FILE = "results/sweep/rounds.json"
ESTIMATE_FILE = "results/sweep/estimate.json"
#: The sets of held-out cases of the estimate check, in the table's order.
ESTIMATE_SETS = ("all", "off_grid", "by_direction", "by_case")

CAPTION = (
    "The adaptive sweep (sweep.adaptive, fem.adaptive) starts from a small design: a few C1 "
    "values, each at a spread of gravity directions over the plane and the caudal half. Then, "
    "round by round, it estimates from the solved cases alone where the worst-point error "
    "between them is largest (the committee estimate: two interpolants of the fields in the "
    "load space x = ĝ/C1, a cubic and a linear one, part where the field bends faster than "
    "the cases are spaced) and adds the "
    "directions of largest estimate, each solved at every C1 value as one chain, until the "
    "estimate over the whole range is under the target or the case budget (or the rounds) is "
    "spent. The table gives each round: the cases tried before it and how many converged, the "
    "estimate's largest value and where, the solved cases' leave-one-out errors, and what the "
    "round added or why the sweep ended there.")


def sweep_design_section(ctx: Context) -> str:
    """The rounds of the adaptive sweep (table and figure), then the check of its estimate."""
    out = []
    rounds = ctx.results.get("sweep_rounds")
    if ctx.paths.get("sweep_rounds") is None:
        out.append(para("The sweep is a fixed design (sweep.adaptive absent or null): its "
                        "cases were listed, not chosen round by round.", "note"))
    elif rounds is None:
        out.append(missing(ROUNDS_FILE))
    else:
        out.append(para(CAPTION, "caption"))
        out.append(rounds_table(rounds))
        out.append(_figure(ctx, rounds))
    if ctx.paths.get("sweep_estimate") is not None:
        check = ctx.results.get("sweep_estimate")
        out.append(missing(ESTIMATE_FILE) if check is None else estimate_check(check))
    return "".join(out)


def rounds_table(rounds: SweepRounds) -> str:
    """One row per round, and a sentence on where the sweep stands."""
    rows = []
    for r in rounds.rounds:
        c1, phi, theta = r.worst
        rows.append([
            f"{r.round}", f"{r.cases_before}", f"{r.converged_before}", fmt(r.estimate_mm),
            f"{c1:g} kPa, {phi:g}/{theta:g}°", f"{fmt(r.median_loo_mm)} / {fmt(r.max_loo_mm)}",
            f"{len(r.directions)}", f"{len(r.cases)}", r.reason,
        ])
    state = ("ended: " + rounds.reason) if rounds.done else "not ended yet"
    summary = para(
        f"{_count(len(rounds.rounds), 'round')}, {_count(rounds.added_directions, 'direction')} "
        f"added to the start design; {rounds.cases} cases in all (budget {rounds.max_cases}); "
        f"the last estimate {fmt(rounds.estimate_mm)} mm against a target of "
        f"{rounds.target_mm:g} mm; the sweep has {state}.")
    return table(["round", "cases before", "converged", "estimated worst-point error (mm)",
                  "where: C1, Φ/θ", "leave-one-out median / largest (mm)", "directions added",
                  "cases added", "ending"], rows, table_id="sweep-rounds") + summary


def direction_rounds(ctx: Context, rounds: SweepRounds) -> dict[str, np.ndarray] | None:
    """Every direction of the dataset's sweep, the round that added it, and whether it failed.

    A direction failed where every one of its cases did. None without a dataset.
    """
    ds = ctx.dataset()
    if ds is None:
        return None
    phi, theta = np.asarray(ds.phi, dtype=float), np.asarray(ds.theta, dtype=float)
    keys = direction_keys(phi, theta)
    unique, first, inverse = np.unique(keys, return_index=True, return_inverse=True)
    converged = np.zeros(len(unique), dtype=bool)
    np.logical_or.at(converged, inverse.ravel(), np.asarray(ds.converged, dtype=bool))
    return {"phi": phi[first], "theta": theta[first],
            "round": rounds.rounds_of(phi[first], theta[first]), "all_failed": ~converged}


def _figure(ctx: Context, rounds: SweepRounds) -> str:
    directions = direction_rounds(ctx, rounds)
    if directions is None:
        return missing("results/dataset/dataset.h5")
    hollow = int(directions["all_failed"].sum())
    caption = (
        "Left: the estimated worst-point error before each round (its cases tried beside it) "
        "and the target (dashed). Right: every gravity direction of the sweep seen from below, "
        "an equal-area projection of the caudal half about the feet-ward axis (upright at the "
        "centre, the paper's plane the rim), coloured by the round that added it (the start "
        "design grey)" + (f"; hollow: the {_count(hollow, 'direction')} whose every case "
                             "failed." if hollow else "."))
    return ctx.figure(
        "sweep_design.png",
        lambda p: design_plots.plot_sweep_design(
            [r.to_json() for r in rounds.rounds], rounds.target_mm, directions["phi"],
            directions["theta"], directions["round"], directions["all_failed"], p),
        "The adaptive sweep's estimate by round and its directions by round", caption)


def _count(n: int, noun: str) -> str:
    return f"{n} {noun}" + ("" if n == 1 else "s")


def estimate_check(check: SweepEstimateCheck) -> str:
    """Per set and estimator, how well the estimate ranks the true error; the goal's verdict."""
    order = list(dict.fromkeys([check.chosen, *(s.estimator for s in check.scores)]))
    sets = [s for s in ESTIMATE_SETS if any(x.set == s for x in check.scores)]
    sets += sorted({s.set for s in check.scores} - set(sets))
    rows, highlight = [], []
    for set_name in sets:
        for estimator in order:
            score = next((s for s in check.scores
                          if s.set == set_name and s.estimator == estimator), None)
            if score is None:
                continue
            if estimator == check.chosen:
                highlight.append(len(rows))
            rows.append([set_name, estimator + (" (chosen)" if estimator == check.chosen else ""),
                         f"{score.cases}", fmt(score.rank_correlation, ".3f"),
                         fmt(score.worst_tenth_found, ".0%")])
    out = [h3("Does the estimate find where the surrogate errs?"), para(
        "At FE cases that no round chose and the model did not train on (the random cases off "
        "the grid, against the selected model; the held-out splits' test cases, against the "
        "model trained without them), each estimate of the error beside the surrogate's true "
        "worst-point error: Spearman's rank correlation, and the share of the true worst tenth "
        "of the cases that the estimate's worst tenth holds. The estimate the rounds use is "
        "marked and first.", "caption"),
        table(["set", "estimator", "cases", "rank correlation", "worst tenth found"], rows,
              highlight, table_id="sweep-estimate")]
    overall = next((s for s in check.scores if s.set == "all" and s.estimator == check.chosen),
                   None)
    if not check.scores:
        out.append(para("No held-out case could be compared: the random cases off the grid "
                        "failed and the sweep forms no held-out split.", "note"))
    elif overall is None:
        out.append(para(f"The file has no score of the chosen estimate ({check.chosen}) over "
                        "all cases.", "note"))
    elif not finite(overall.rank_correlation):
        out.append(para(f"The chosen estimate ({check.chosen})'s rank correlation over all "
                        f"{overall.cases} cases could not be measured: the goal of "
                        f"{check.goal:g} is not shown met."))
    else:
        verdict = "meets" if check.goal_met else "does not meet"
        out.append(para(
            f"The chosen estimate ({check.chosen}) ranks the true error over all "
            f"{overall.cases} cases with a rank correlation of "
            f"{fmt(overall.rank_correlation, '.3f')}: it {verdict} the goal of {check.goal:g}."))
    return "".join(out)
