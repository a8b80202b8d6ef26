"""Figures about the surrogate: training, speed against accuracy, extrapolation, error fields.

Every function takes plain numbers and writes one PNG with matplotlib's Agg backend;
which numbers go in is decided by the caller (:mod:`report.build`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402

from studies.figures.fe import FONT_SIZE, plain_log_ticks, save_figure  # noqa: E402


def plot_history(
    history: list[dict[str, Any]], path: str | Path, title: str = "", best_epoch: int | None = None
) -> None:
    """Training and validation loss, and the validation error in mm, per epoch.

    Args:
        history: per-epoch records (``epoch``, ``train_loss``, ``validation_loss``,
            ``validation_error_mm``) of a model's ``history.json``.
        path: PNG to write.
        title: figure title.
        best_epoch: the epoch whose weights were kept, marked by a vertical line.
    """
    epochs = [h["epoch"] for h in history]
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 3.8), constrained_layout=True)
    ax1.semilogy(epochs, [h["train_loss"] for h in history], label="training")
    ax1.semilogy(epochs, [h["validation_loss"] for h in history], label="validation")
    ax1.set_xlabel("epoch")
    ax1.set_ylabel("loss (Eq. 2, per sample, scaled units)")
    ax2.semilogy(epochs, [h["validation_error_mm"] for h in history], color="C2")
    ax2.set_xlabel("epoch")
    ax2.set_ylabel("validation error (mean |u − û|, mm)")
    if best_epoch is not None:
        for ax in (ax1, ax2):
            ax.axvline(best_epoch, color="grey", linestyle=":", label=f"best epoch ({best_epoch})")
        ax2.legend()
    ax1.legend()
    if title:
        fig.suptitle(title)
    save_figure(fig, path)


def plot_speed_accuracy(
    architectures: Sequence[Mapping[str, Any]],
    fe: Sequence[Mapping[str, Any]],
    path: str | Path,
) -> None:
    """Each architecture's validation error against training time and against prediction time.

    Two panels; the FE is drawn on both at its solve time per case and its error against
    the refined reference, so that one reads off what a trained surrogate buys.

    Args:
        architectures: per architecture ``name``, ``error_mm`` and ``error_sd_mm`` (mean and
            SD over the repeats), ``train_s`` and ``train_sd_s``, ``predict_s`` (one
            whole-field prediction, or None) and ``selected`` (bool).
        fe: per FE configuration ``label``, ``time_s`` (per case), ``error_mm`` and
            ``default`` (bool).
        path: PNG to write.
    """
    fig, axes = plt.subplots(1, 2, figsize=(12, 5.2), constrained_layout=True, sharey=True)
    colours = plt.get_cmap("tab10" if len(architectures) <= 10 else "tab20")
    handles = []
    for i, arch in enumerate(architectures):
        colour = colours(i % colours.N)
        kw = {"color": colour, "marker": "o", "markersize": 11 if arch.get("selected") else 7,
              "markeredgecolor": "black" if arch.get("selected") else colour,
              "markeredgewidth": 2.0 if arch.get("selected") else 1.0, "capsize": 3,
              "linestyle": ""}
        axes[0].errorbar(arch["train_s"], arch["error_mm"], yerr=arch["error_sd_mm"],
                         xerr=arch.get("train_sd_s") or None, **kw)
        if arch.get("predict_s") is not None:
            axes[1].errorbar(arch["predict_s"], arch["error_mm"], yerr=arch["error_sd_mm"], **kw)
        label = f"surrogate {arch['name']}" + (" (selected)" if arch.get("selected") else "")
        handles.append(Line2D([], [], linestyle="", marker="o", color=colour,
                              markeredgecolor=kw["markeredgecolor"],
                              markeredgewidth=kw["markeredgewidth"], label=label))
    other = [f for f in fe if not f.get("default")]
    default = [f for f in fe if f.get("default")]
    for ax in axes:
        if other:
            ax.scatter([f["time_s"] for f in other], [f["error_mm"] for f in other], marker="^",
                       s=45, color="lightgrey", edgecolor="dimgrey", zorder=2)
        if default:
            ax.scatter([f["time_s"] for f in default], [f["error_mm"] for f in default],
                       marker="*", s=260, color="black", zorder=4)
        ax.set_xscale("log")
        ax.set_yscale("log")
        plain_log_ticks(ax)
        ax.grid(True, which="both", alpha=0.3)
    if other:
        handles.append(Line2D([], [], linestyle="", marker="^", markersize=8, color="lightgrey",
                              markeredgecolor="dimgrey", label="FE study variants"))
    if default:
        handles.append(Line2D([], [], linestyle="", marker="*", markersize=14, color="black",
                              label="FE default configuration"))
    axes[0].set_xlabel("surrogate: training time (s) · FE: solve time per case (s)")
    axes[1].set_xlabel("surrogate: one whole-field prediction (s) · FE: solve time per case (s)")
    axes[0].set_ylabel("error (mm): surrogate validation mean |u − û|;\n"
                       "FE worst clinical case mean |u − u_ref|")
    axes[0].set_title("error against training time")
    axes[1].set_title("error against prediction time")
    fig.legend(handles=handles, loc="outside lower center", ncol=min(len(handles), 5))
    save_figure(fig, path)


def plot_extrapolation(
    labels: Sequence[str],
    series: Mapping[str, Sequence[float | None]],
    path: str | Path,
    xlabel: str = "mean error |u − û| over the points (mm)",
) -> None:
    """Grouped horizontal bars: one group per case, one bar per series (log scale).

    Series are coloured in pairs (dark, light) of one hue: give them as (value, its
    reference) pairs.

    Args:
        labels: one per case (the y-axis).
        series: name -> one value per case (None: not measured, no bar).
        path: PNG to write.
        xlabel: x-axis label, with units.
    """
    n, m = len(labels), max(len(series), 1)
    fig, ax = plt.subplots(figsize=(10, 1.8 + 0.2 * m * n + 0.25 * n), constrained_layout=True)
    height = 0.8 / m
    y = np.arange(n)
    # consecutive series come in pairs (a model at the case, the same model near it):
    # one hue per pair, dark and light
    colours = plt.get_cmap("tab20")
    for k, (name, values) in enumerate(series.items()):
        shown = [np.nan if v is None else float(v) for v in values]
        ax.barh(y + (k - (m - 1) / 2) * height, shown, height=height, label=name,
                color=colours(k % colours.N))
    ax.set_yticks(y)
    ax.set_yticklabels(labels, fontsize=8)
    ax.invert_yaxis()
    ax.set_xscale("log")
    plain_log_ticks(ax)
    ax.set_xlabel(xlabel)
    ax.grid(True, axis="x", which="both", alpha=0.3)
    fig.legend(loc="outside lower center", ncol=2)
    save_figure(fig, path)


def plot_point_fields(
    X_m: np.ndarray,
    panels: Sequence[tuple[np.ndarray, str]],
    path: str | Path,
    title: str = "",
) -> None:
    """Scalar fields on the material points, seen from the front (projected on the y–z plane).

    Points are drawn from posterior to anterior, so the front-most point of a line of
    sight is the one seen. Each panel has its own colour bar (mm).

    Args:
        X_m: reference coordinates (N, 3), m; x runs anterior to posterior.
        panels: ``(values (N,), panel title)`` pairs, values in mm.
        path: PNG to write.
        title: figure title.
    """
    X_mm = 1e3 * np.asarray(X_m, float)
    order = np.argsort(-X_mm[:, 0])  # posterior first, anterior (smallest x) drawn last
    fig, axes = plt.subplots(1, len(panels), figsize=(4.6 * len(panels), 4.6), squeeze=False,
                             constrained_layout=True, sharex=True, sharey=True)
    size = float(np.clip(9000.0 / max(len(X_mm), 1), 2.0, 30.0))
    for ax, (values, name) in zip(axes[0], panels, strict=True):
        sc = ax.scatter(X_mm[order, 1], X_mm[order, 2], c=np.asarray(values)[order], s=size,
                        cmap="viridis" if "error" not in name else "magma", linewidths=0)
        fig.colorbar(sc, ax=ax, label="mm", shrink=0.85)
        ax.set_title(name, fontsize=FONT_SIZE)
        ax.set_aspect("equal")
        ax.set_xlabel("y, medial → lateral (mm)")
    axes[0, 0].set_ylabel("z, caudal → cranial (mm)")
    if title:
        fig.suptitle(title)
    save_figure(fig, path)


__all__ = ["plot_extrapolation", "plot_history", "plot_point_fields", "plot_speed_accuracy"]


def plot_stiffness_misfit(
    curve_c1: Sequence[float], curve_rms_mm: Sequence[float], fe_c1: Sequence[float],
    fe_rms_mm: Sequence[float], estimate: float, interval: Sequence[float],
    truth: float | None, path: str | Path,
) -> None:
    """The misfit over C1: the surrogate's curve, the FE solves, the estimate and its interval."""
    fig, ax = plt.subplots(figsize=(6.0, 3.8), layout="constrained")
    ax.plot(curve_c1, curve_rms_mm, color="tab:blue", label="surrogate search")
    ax.plot(fe_c1, fe_rms_mm, "o", color="tab:orange", label="FE confirmation")
    ax.axvspan(interval[0], interval[1], color="tab:orange", alpha=0.2,
               label=f"interval [{interval[0]:.3g}, {interval[1]:.3g}] kPa")
    ax.axvline(estimate, color="tab:orange", lw=1.2, label=f"estimate {estimate:.3g} kPa")
    if truth is not None:
        ax.axvline(truth, color="black", ls="--", lw=1.0, label=f"truth {truth:.3g} kPa")
    ax.set_xscale("log")
    plain_log_ticks(ax)
    ax.set_xlabel("C1 (kPa)")
    ax.set_ylabel("RMS distance to the observed skin (mm)")
    ax.legend(fontsize=FONT_SIZE - 2)
    save_figure(fig, path)
