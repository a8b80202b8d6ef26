"""The selected surrogate's training: loss and validation error per epoch, and its settings."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from report.context import Context
from report.html import finite, fmt, missing, para, seconds, span, table
from studies.figures import surrogate as surrogate_plots


def training_section(ctx: Context) -> str:
    """The selected model's training history and settings."""
    history = ctx.results.get("history")
    if history is None:
        return missing("results/surrogate/model/history.json")
    summary = history.get("summary") or {}
    arch = summary.get("architecture", "n/a")
    refit = bool(summary.get("refit"))
    out = [para(
        "The selected model's training: the loss (the paper's Eq. 2) on the training and "
        "validation samples, and the validation error in mm, per epoch. " + (
            "It is the selected run trained again on its validation data too "
            "(surrogate_study.refit), for the epochs that run's validation chose, keeping the "
            "last weights: its 'validation' error is measured on data it trained on, and the "
            "held-out section judges the selection instead." if refit else
            "Training stops at max_epochs, or earlier when the validation loss (a pod "
            "model's: its validation error in mm) has not improved for the configured "
            "patience; the best epoch's weights are kept."),
        "caption")]
    if history.get("history"):
        out.append(ctx.figure(
            "training_history.png",
            lambda p: surrogate_plots.plot_history(
                history["history"], p, f"training of the selected model ({arch})",
                summary.get("best_epoch") if finite(summary.get("best_epoch")) else None),
            "training history", f"Training history of the selected model ({arch})."))
    out.append(table(["quantity", "value"], [
        ["architecture", arch], ["boundary", summary.get("boundary", "n/a")],
        ["split", summary.get("split", "n/a")], ["seed", summary.get("seed", "n/a")],
        ["epochs (best epoch)",
         f"{fmt(summary.get('epochs'), 'd')} ({fmt(summary.get('best_epoch'), 'd')})"],
        ["validation error, on data it trained on (mm)" if refit else "validation error (mm)",
         fmt(summary.get("validation_error_mm"), ".4g")],
        ["training time", seconds(summary.get("train_s"))],
        ["training cases", fmt(summary.get("n_train_cases"), "d")],
        ["training range", _training_range((ctx.results.get("model") or {}).get("training_range"))],
    ], table_id="training"))
    return "".join(out)


MAX_LISTED = 24
"""More training directions than this are counted, not listed, in the training table."""


def _training_range(rng: Mapping[str, Any] | None) -> str:
    if not rng:
        return "n/a"
    parts = []
    if rng.get("C1_kPa"):
        parts.append(f"C1 {span(rng['C1_kPa'], 'g')} kPa")
    directions = rng.get("directions") or []
    if len(directions) > MAX_LISTED:  # a sphere's directions: Φ and θ are not a grid
        plane = sum(1 for _, theta in directions if theta == 0)
        parts.append(f"{len(directions)} gravity directions ({plane} in the plane θ = 0; "
                     "each (Φ, θ) in model.json's training_range)")
        return "; ".join(parts)
    for key, name in (("phi_deg", "Φ"), ("theta_deg", "θ")):
        if rng.get(key):
            parts.append(f"{name} ∈ {{{', '.join(f'{v:g}' for v in rng[key])}}}°")
    return "; ".join(parts) or "n/a"
