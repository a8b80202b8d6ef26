"""The surrogate asked about cases outside its training data, against FE solutions of them."""

from __future__ import annotations

from report.common import PAPER_C1_RANGE
from report.context import Context
from report.html import fmt, missing, para, table
from studies.figures import surrogate as surrogate_plots


def extrapolation_section(ctx: Context) -> str:
    """The surrogate outside its training data, against FE solutions of those cases."""
    extra = ctx.results.get("extrapolation")
    if extra is None:
        return missing("results/surrogate/extrapolation.json")
    blocks = {s: getattr(extra, s) for s in ("by_sample", "by_case") if getattr(extra, s)}
    splits = [s for s, block in blocks.items() if block.rows]
    # each model's block lists the same FE solves that failed: each once
    failed = list({f.get("case"): f for b in blocks.values() for f in b.failed_fe}.values())
    if not splits:
        return para(f"No extrapolation case was compared ({len(failed)} FE solves outside the "
                    "sweep failed).", "note")
    ids = list(dict.fromkeys(r.case for s in splits for r in blocks[s].rows))
    rows_of = {s: {r.case: r for r in blocks[s].rows} for s in splits}
    first = {cid: next(rows_of[s][cid] for s in splits if cid in rows_of[s]) for cid in ids}
    labels = [f"C1 {first[c].C1:g} kPa, Φ {first[c].phi:g}°, θ {first[c].theta:g}°\n"
              f"({first[c].kind or 'n/a'})" for c in ids]

    def rmse(split: str, cid: str, nearest: bool = False) -> float | None:
        row = rows_of[split].get(cid)
        if row is not None and nearest:
            row = row.nearest_sweep_case
        return row.rmse_mm if row is not None else None

    series: dict[str, list[float | None]] = {}
    for s in splits:
        name = s.replace("_", "-")
        series[f"{name} model at the case"] = [rmse(s, c) for c in ids]
        series[f"{name} model at the nearest sweep case"] = [rmse(s, c, True) for c in ids]
    out = [para(
        "The surrogate asked about cases outside its training data — C1 below "
        f"{PAPER_C1_RANGE[0]:g} or above {PAPER_C1_RANGE[1]:g} kPa (or the sweep's range), "
        "gravity angles Φ it never saw, gravity out of the plane (θ ≠ 0) — against FE "
        "solutions of those cases. Each bar is the mean point error |u − û| (the paper's Eq. "
        "3); beside it, the same model's error at the nearest case of the sweep, so that the "
        "growth of error outside the data can be read off. The label under each case says "
        f"how it lies outside the {splits[0].replace('_', '-')} model's training data; the "
        "by-case model never saw the clinical cases, so its training range can be narrower "
        "(the table gives both).", "caption")]
    out.append(ctx.figure(
        "extrapolation.png",
        lambda p: surrogate_plots.plot_extrapolation(labels, series, p),
        "surrogate error outside the training data",
        "Mean error per extrapolation case (log), next to the nearest sweep case's error."))
    rows = []
    for cid, label in zip(ids, labels, strict=True):
        row = [label.split("\n")[0], fmt(first[cid].fe_range_mm[-1], ".3g")]
        for s in splits:
            r = rows_of[s].get(cid)
            row += [(r.kind if r else None) or "n/a", fmt(r.rmse_mm if r else None, ".3g"),
                    fmt(r.max_error_mm if r else None, ".3g"), fmt(rmse(s, cid, True), ".3g"),
                    fmt(r.error_ratio_to_nearest if r else None, ".3g")]
        rows.append(row)
    header = ["case", "FE max |u| (mm)"]
    for s in splits:
        name = s.replace("_", "-")
        header += [f"{name}: outside its training by", f"{name}: mean error (mm)",
                   f"{name}: max error (mm)", f"{name}: at nearest sweep case (mm)",
                   f"{name}: ratio"]
    out.append(table(header, rows, table_id="extrapolation"))
    if failed:
        out.append(para("FE solves outside the sweep that failed (no comparison): " + "; ".join(
            f"{f.get('case')}: {f.get('reason', '')}" for f in failed), "note"))
    return "".join(out)
