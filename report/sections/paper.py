"""The paper side by side: its Tables 2-4 and Fig. 5 beside ours."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from report.common import GOAL_NAMES, predict_s
from report.context import Context
from report.html import finite, fmt, h3, missing, para, pm, seconds, span, table, times, yes
from studies import paper
from studies.figures import surrogate as surrogate_plots
from studies.surrogate_study.architecture import ArchitectureTable
from surrogate.config import parse_architecture

STRUCTURE_WORDS = {
    "pod": ("; our architecture is that of the one network that weighs the training cases' own "
            "POD modes (structure: pod), the paper's that of its Siamese pair, and our "
            "validation points are those of whole validation cases"),
    "separable": ("; our architecture is that of the pair's point networks and of the branch "
                  "that weighs their fields (structure: separable)"),
}
"""How the architecture of a model of each structure reads beside the paper's Siamese pair."""


def _table2(ctx: Context) -> str:
    study = ctx.results.get("table2")
    if study is None:
        return missing("results/surrogate/study/table2.json")
    ours = study.rows
    selected = study.selected_architecture
    names = sorted(set(ours) | set(paper.TABLE2), key=parse_architecture)
    rows, highlight = [], []
    for i, name in enumerate(names):
        row = ours.get(name)
        published = paper.TABLE2.get(name) or {}
        p_err, p_train = published.get("validation_error_mm"), published.get("train_s")
        mark = []
        if name == selected:
            mark.append("selected by us")
            highlight.append(i)
        if name == paper.BEST_ARCHITECTURE:
            mark.append("selected by the paper")
        if name == study.most_accurate_architecture and name != selected:
            mark.append("most accurate, over the prediction budget")
        if row is None:  # the paper's architecture that we did not train
            rows.append([name, "n/a", "n/a", "n/a", pm(*p_err, ".2f") if p_err else "n/a",
                         "n/a", pm(*p_train, ".0f") if p_train else "n/a", "n/a", "n/a",
                         "; ".join(mark)])
            continue
        predict = predict_s(row)
        once = row.runs == 1  # one run: no SD to show
        rows.append([name, fmt(row.parameters, "d"), fmt(row.runs, "d"),
                     pm(row.validation_error_mm.mean,
                        None if once else row.validation_error_mm.sd),  # 3 digits
                     pm(*p_err, ".2f") if p_err else "n/a",
                     pm(row.train_s.mean, None if once else row.train_s.sd, ".3g"),
                     pm(*p_train, ".0f") if p_train else "n/a",
                     fmt(row.epochs.mean, ".0f"),
                     fmt(1e3 * predict if predict is not None else None, ".3g"),
                     "; ".join(mark)])
    card = ctx.results.get("model") or {}
    structure = (card.get("config") or {}).get("structure")
    ours_are = STRUCTURE_WORDS.get(structure, "")
    return "".join([
        h3("Table 2: architecture study"),
        para("Validation error (mean |u − û| over the validation points, mean ± SD over the "
           "repeats) and training time per architecture (hidden layers × width), ours beside "
           f"the paper's (trained on an NVIDIA V100){ours_are}. Our prediction time is one "
           "whole-field prediction on one CPU core. The highlighted row is our selection: "
           f"{study.rule}.{_repeat_words(study)}", "caption"),
        table(["architecture", "parameters", "runs", "validation error (mm)",
                "paper: validation error (mm)", "training time (s)", "paper: training time (s)",
                "epochs", "prediction (ms)", "selected"], rows, highlight, table_id="table2"),
    ])


def _repeat_words(study: ArchitectureTable) -> str:
    """The caption's sentence on which architectures trained their repeats, if not all did."""
    if study.repeat_within is None or all(r.runs == study.repeats for r in study.rows.values()):
        return ""
    return (f" Every architecture trained once, and its {study.repeats} runs only where its "
            f"first run's validation error was within {100 * study.repeat_within:g} % of the "
            "best first run's (surrogate_study.repeat_within): where the choice is close.")


def _table3(ctx: Context) -> str:
    clinical = ctx.results.get("clinical")
    out = [h3("Table 3: clinical cases")]
    if clinical is None:
        return "".join(out) + missing("results/surrogate/clinical.json")
    out.append(para(
        "Mean displacement and displacement range of the FE and the surrogate, and the "
        "surrogate's error as the paper's Eq. 3 (mean over the points of |u − û|, ± SD), "
        "ours beside the paper's, for each clinical case. The by-sample model trained on "
        "points of every case (the paper's split; a pod model, on every case but its "
        "validation cases); the by-case model never saw the clinical cases.", "caption"))
    for split in ("by_sample", "by_case"):
        block = getattr(clinical, split)
        if block is None or not block.rows:
            continue
        cases = block.rows
        published = [paper.table3_row(r.C1, r.phi) or {} for r in cases]
        metrics = [
            ("FE mean displacement (mm)", lambda r: fmt(r.fe_mean_mm, ".3g"),
             lambda p: fmt(p.get("fe_mean_mm"), ".3g")),
            ("FE displacement range (mm)", lambda r: span(r.fe_range_mm),
             lambda p: span(p.get("fe_range_mm"))),
            ("surrogate mean displacement (mm)", lambda r: fmt(r.surrogate_mean_mm, ".3g"),
             lambda p: fmt(p.get("surrogate_mean_mm"), ".3g")),
            ("RMSE ± SD (mm, Eq. 3)", lambda r: pm(r.rmse_mm, r.sd_mm),
             lambda p: pm(p.get("rmse_mm"), p.get("sd_mm"))),
            ("surrogate displacement range (mm)", lambda r: span(r.surrogate_range_mm),
             lambda p: span(p.get("surrogate_range_mm"))),
        ]
        rows = []
        for name, ours, theirs in metrics:
            rows.append([f"{name}: ours"] + [ours(r) for r in cases])
            rows.append([f"{name}: paper"] + [theirs(p) for p in published])
        rows.append(["max error (mm): ours"] + [fmt(r.max_error_mm, ".3g") for r in cases])
        rows.append(["max error (mm): paper (Fig. 5 caption)"] + [
            fmt(paper.fig5_max_error_mm(r.C1, r.phi), ".3g") for r in cases])
        out.append(para(f"{split.replace('_', '-')} model ({block.architecture}, "
                        f"boundary: {block.boundary}):"))
        out.append(table(["metric"] + [r.label or r.case for r in cases], rows,
                          highlight=range(0, len(rows), 2), table_id=f"table3-{split}"))
    return "".join(out)


def _table4(ctx: Context) -> str:
    bench = ctx.results.get("surrogate_benchmark")
    out = [h3("Table 4: wall time per case")]
    if bench is None:
        return "".join(out) + missing("results/surrogate/surrogate_benchmark.json")
    speed = bench.speed
    if not speed:
        return "".join(out) + para("The benchmark holds no timed case.", "note")
    cases = {item.case.id: item.case for item in ctx.clinical}
    published = []
    for row in speed:
        case = cases.get(row.case)
        published.append(paper.table4_row(case.C1, case.phi) if case else None)
    out.append(para(
        "Wall time of one FE solve (set-up excluded) and one surrogate prediction, both on the "
        "same pinned CPU core in one job, ours beside the paper's (an Intel Core i7 at 2.3 GHz, "
        "mean ± SD), and the speed-up FE / surrogate.", "caption"))
    rows = [
        ["FE: ours"] + [seconds(r.fe_solve_s) for r in speed],
        ["FE: paper"] + [pm(*p["fe_s"], ".3g") + " s" if p else "n/a" for p in published],
        ["surrogate: ours"] + [seconds(1e-3 * r.surrogate_ms) if finite(r.surrogate_ms)
                               else "n/a" for r in speed],
        ["surrogate: paper"] + [pm(*p["surrogate_s"], ".3g") + " s" if p else "n/a"
                                for p in published],
        ["speed-up: ours"] + [times(r.speedup) for r in speed],
        ["speed-up: paper"] + [times(p["fe_s"][0] / p["surrogate_s"][0]) if p else "n/a"
                               for p in published],
    ]
    out.append(table(["model"] + [ctx.case_label(r.case) for r in speed], rows,
                      highlight=(0, 2, 4), table_id="table4"))
    machine = bench.machine
    out.append(para(f"Machine: {machine.cpu}, {fmt(machine.cores, 'd')} CPUs, pinned core "
                    f"{fmt(machine.pinned_core, 'd')}, load average "
                    f"{fmt(machine.load_average_1_5_15min[0], '.2f')}.", "note"))
    goals = bench.goals
    if goals:
        out.append(table(["benchmark goal", "value", "goal", "met"],
                         [[GOAL_NAMES.get(k, k.replace("_", " ")), fmt(g.value, ".4g"),
                           fmt(g.goal, "g"), yes(g.met)] for k, g in goals.items()],
                         table_id="goals"))
    return "".join(out)


def _read_point_fields(path: Path) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    import meshio

    mesh = meshio.read(str(path))
    return np.asarray(mesh.points), {k: np.asarray(v) for k, v in mesh.point_data.items()}


def _figure5(ctx: Context) -> str:
    out = [h3("Figure 5: displacement and surrogate error on the material points")]
    by_key = {(p.parent.name, p.stem): p for p in ctx.clinical_fields if p.suffix == ".xdmf"}
    clinical = ctx.results.get("clinical")
    blocks = {s: getattr(clinical, s) if clinical is not None else None
              for s in ("by_sample", "by_case")}
    rows = {s: {r.case: r for r in (block.rows if block is not None else [])}
            for s, block in blocks.items()}
    out.append(para(
        "For each clinical case, the material points seen from the front (projected on the "
        "y–z plane, the front-most point of each line of sight drawn on top): the FE "
        "displacement magnitude |u|, and the magnitude of the surrogate's error |u − û| for "
        "the by-sample and the by-case model. Each panel has its own colour bar in mm; the "
        "table below gives the largest error beside the paper's Fig. 5 caption.", "caption"))
    figures, table_rows = [], []
    for item in ctx.clinical:
        cid, label = item.case.id, item.label
        panels: list[tuple[np.ndarray, str]] = []
        X = None
        for split in ("by_sample", "by_case"):
            path = by_key.get((split, cid))
            if path is None or not path.is_file():
                continue
            points, data = _read_point_fields(path)
            if X is None:
                X = points
                panels.append((data["fe_displacement_norm_mm"], "FE displacement |u|"))
            panels.append((data["error_norm_mm"], f"{split.replace('_', '-')} error |u − û|"))
        if X is None:
            figures.append(para(f"{label}: no error field among the inputs.", "note"))
            continue
        name = f"fig5_{re.sub(r'[^A-Za-z0-9.-]+', '_', cid)}.png"
        figures.append(ctx.figure(name, lambda p, X=X, panels=panels, label=label:
                                  surrogate_plots.plot_point_fields(X, panels, p, label),
                                  f"FE displacement and surrogate error, {label}",
                                  f"{label}: FE |u| and surrogate error, seen from the front."))
        paper_max = paper.fig5_max_error_mm(item.case.C1, item.case.phi)
        table_rows.append([label] + [
            fmt(rows[s][cid].max_error_mm if cid in rows[s] else None, ".3g")
            for s in ("by_sample", "by_case")
        ] + [fmt(paper_max, ".3g")])
    out += figures
    if table_rows:
        out.append(table(["case", "by-sample: max error (mm)", "by-case: max error (mm)",
                           "paper (Fig. 5 caption): max error (mm)"], table_rows,
                          table_id="fig5"))
    return "".join(out)


def paper_section(ctx: Context) -> str:
    """The paper side by side: Tables 2-4 and Fig. 5 beside ours."""
    return "".join([
        para("The paper's Tables 2–4 and Fig. 5 with our figures beside theirs. Our mesh, "
           "training data and hardware differ from the paper's, so agreement is expected in "
           "magnitude and trend, not digit by digit.", "caption"),
        _table2(ctx), _table3(ctx), _table4(ctx), _figure5(ctx),
    ])
