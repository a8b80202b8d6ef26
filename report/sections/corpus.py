"""The corpus of anatomies: the import and the default solver beyond the project's own breast."""

from __future__ import annotations

from report.context import Context
from report.html import missing, para, table
from studies.fe_study.corpus import (
    CORPUS_HEADER,
    EXACT,
    FAILURES_HEADER,
    corpus_failures,
    corpus_rows,
)


def corpus_section(ctx: Context) -> str:
    """One row per anatomy: its mesh, and its cases with the default solver and exact Newton."""
    corpus = ctx.results.get("corpus")
    if corpus is None:
        return missing("results/corpus/corpus.json")
    runs = corpus.anatomies
    cases = len(runs[0].by_solver(EXACT)) if runs else 0
    missed = sum(len(run.missed) for run in runs)
    out = [para(
        "Geometries the project makes itself, each imported the way a user's file would be "
        "(the parametric ones built from the config with another shape): of the config's "
        "breast, a small and a large ptotic one, a hemisphere on a flat chest wall, an "
        "irregular scan-like surface in scanner axes (LPS, a left breast, remeshed, its chest "
        "wall chosen by the posterior rule) and a tetrahedral volume mesh in RAS axes, those "
        f"the config's corpus names. On each, {cases} cases: the clinical cases and C1 = "
        f"{corpus.soft_C1:g} kPa at Φ = {', '.join(f'{p:g}' for p in corpus.soft_phi)}°, "
        "solved with the config's solver (the "
        f"default) and with exact Newton ({EXACT}), alternately in one process. Newton "
        "iterations count every attempt, failed ones included; times are one solve's wall "
        "time, in the same job for both paths.", "caption")]
    out.append(table(CORPUS_HEADER, corpus_rows(corpus), table_id="corpus"))
    resumed = [f"{run.name} ({run.resumed})" for run in runs if run.resumed]
    if resumed:
        out.append(para(
            "Solves taken from an earlier, stopped job's progress file, timed in that job: "
            f"{', '.join(resumed)}."))
    out.append(para(
        "The default converged every case that exact Newton converged."
        if not missed else
        f"{missed} case(s) converged with exact Newton but not with the default: see the last "
        "column."))
    failures = corpus_failures(corpus)
    if failures:
        out.append(para(
            "Where the cases stop: each case some path did not converge, with the load fraction "
            "λ of full gravity that each path reached (the state it kept) and why it stopped. "
            "Where both paths stop at nearly the same λ, the model, not the solver, has reached "
            "its limit there (docs/solver.md).", "caption"))
        out.append(table(FAILURES_HEADER, failures, table_id="corpus-failures"))
    return "".join(out)
