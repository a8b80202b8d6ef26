"""Surrogate speed against accuracy: the architectures beside the FE, and the ablations."""

from __future__ import annotations

from typing import Any

from report.common import predict_s, variant_label, worst_case
from report.context import Context
from report.html import finite, fmt, h3, missing, para, pm, table
from studies.figures import surrogate as surrogate_plots
from studies.surrogate_study.architecture import RunSummary


def fe_points_for_surrogate(ctx: Context) -> list[dict[str, Any]]:
    """FE configurations as (solve time per case, worst clinical-case mean error)."""
    points = []
    fe = ctx.results.get("fe_clinical")
    if fe is not None:
        err = worst_case(fe.cases, "mean_error_mm")
        time_s = fe.summary.median_wall_s
        if err is not None and finite(time_s):
            points.append({"label": "FE default", "time_s": time_s, "error_mm": err,
                           "default": True})
    sa = ctx.results.get("fe_speed_accuracy")
    for v in sa.variants if sa is not None else []:
        if v.skipped:
            continue
        err = worst_case(v.cases, "mean_error_mm")
        if err is not None and finite(v.median_wall_s):
            points.append({"label": variant_label(v.variant), "time_s": v.median_wall_s,
                           "error_mm": err, "default": False})
    return points


def surrogate_speed_accuracy_section(ctx: Context) -> str:
    """The surrogate speed-accuracy section: architectures beside the FE, and the ablations."""
    study = ctx.results.get("table2")
    if study is None:
        return missing("results/surrogate/study/table2.json")
    selected = study.selected_architecture
    archs = []
    for name, row in study.rows.items():
        err, train = row.validation_error_mm, row.train_s
        if not (finite(err.mean) and finite(train.mean)):
            continue
        archs.append({"name": name, "error_mm": err.mean, "error_sd_mm": err.sd or 0.0,
                      "train_s": train.mean, "train_sd_s": train.sd or 0.0,
                      "predict_s": predict_s(row), "selected": name == selected})
    fe_points = fe_points_for_surrogate(ctx)
    out = [para(
        "Left: each network architecture's validation error (mean over the validation "
        "points of |u − û|; dot = mean over the training repeats, bars = ± 1 SD) against its "
        "training time. Right: the same error against the time of one whole-field "
        "prediction on one CPU core. The FE model is drawn on both panels at its solve time "
        "per clinical case and its error against the refined reference (the worst clinical "
        "case's mean |u − u_ref|): the star is the default configuration, grey triangles the "
        "other FE study variants. On the left a surrogate is worth training when its "
        "training time is a small multiple of the FE solve times it replaces; on the right "
        "the horizontal gap is the speed-up per query and the vertical gap the price in "
        "accuracy. The selected architecture has a black ring.", "caption")]
    if archs:
        out.append(ctx.figure(
            "surrogate_speed_accuracy.png",
            lambda p: surrogate_plots.plot_speed_accuracy(archs, fe_points, p),
            "surrogate error against training and prediction time",
            "Surrogate speed against accuracy, with the FE on the same axes."))
    else:
        out.append(para("The architecture study holds no complete row.", "note"))
    out.append(para(f"Selected architecture: {selected} (rule: {study.rule}); the "
                    f"paper selected {study.paper_selected_architecture}."))
    ablations = ctx.results.get("ablations")
    out.append(h3("Ablations: the training settings changed at the selected architecture"))
    if ablations is None:
        out.append(missing("results/surrogate/ablations.json"))
        return "".join(out)
    out.append(para(
        "Each ablation changes the listed settings of the selected model and is trained with "
        "the same seeds; a ratio below 1 means smaller error (or shorter training) than the "
        "baseline.", "caption"))

    def stats(v: RunSummary, key: str) -> str:
        item = getattr(v, key)
        return pm(item.mean, item.sd)

    base = ablations.baseline
    rows = [["baseline", "none", stats(base, "validation_error_mm"),
             stats(base, "train_s"), fmt(base.parameters, "d"), "1", "1"]]
    for name, v in ablations.ablations.items():
        changed = (", ".join(f"{k} = {val}" for k, val in v.changed.items())
                   if v.changed is not None else f"boundary = {v.boundary or 'n/a'}")
        rows.append([name, changed or "none", stats(v, "validation_error_mm"),
                     stats(v, "train_s"), fmt(v.parameters, "d"),
                     fmt(v.error_ratio_to_baseline, ".3g"),
                     fmt(v.time_ratio_to_baseline, ".3g")])
    out.append(table(["ablation", "settings changed", "validation error (mm)",
                       "training time (s)", "parameters", "error ratio", "time ratio"], rows))
    return "".join(out)
