"""Figures about the FE model: the sweep, speed against accuracy, convergence maps, C1's effect.

Every function takes plain numbers (arrays, lists of mappings) and writes one PNG with
matplotlib's Agg backend; which numbers go in is decided by the caller
(:mod:`report.build`).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.colors import LogNorm, Normalize  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402
from matplotlib.patches import Rectangle  # noqa: E402
from matplotlib.ticker import FuncFormatter, MaxNLocator  # noqa: E402

log = logging.getLogger(__name__)

DPI = 110
FONT_SIZE = 10

#: Colour of each element of the speed-accuracy study.
ELEMENT_COLOURS = {"p1-penalty": "tab:blue", "p2p1": "tab:orange", "p3p2": "tab:green"}
ELEMENT_NAMES = {"p1-penalty": "P1 (penalty)", "p2p1": "P2/P1", "p3p2": "P3/P2"}
_MARKERS = ("o", "s", "^", "D", "v", "P", "*")
_FAILURE_COLOURS = ("red", "magenta", "black", "darkorange", "cyan", "brown")

plt.rcParams.update({"font.size": FONT_SIZE, "axes.titlesize": FONT_SIZE + 1,
                     "axes.labelsize": FONT_SIZE, "legend.fontsize": FONT_SIZE - 1})


def save_figure(fig: plt.Figure, path: str | Path) -> None:
    """Write ``fig`` as PNG at the report's resolution and close it."""
    fig.savefig(path, dpi=DPI)
    plt.close(fig)
    log.info("wrote %s", path)


def plain_log_ticks(ax: plt.Axes) -> None:
    """Label log axes with plain numbers (0.3, 2, 100) instead of powers of ten.

    Decades are always labelled; on an axis spanning little more than a decade the
    minor ticks at 2, 3 and 5 times a power of ten are labelled too.
    """
    for axis in (ax.xaxis, ax.yaxis):
        if axis.get_scale() != "log":
            continue

        def minor(value: float, _pos: int, axis: Any = axis) -> str:
            lo, hi = sorted(axis.get_view_interval())
            if value <= 0 or lo <= 0 or math.log10(hi / lo) > 1.3:
                return ""
            mantissa = value / 10 ** math.floor(math.log10(value) + 1e-9)
            return f"{value:g}" if round(mantissa) in (2, 3, 5) else ""

        axis.set_major_formatter(FuncFormatter(lambda value, _pos: f"{value:g}"))
        axis.set_minor_formatter(FuncFormatter(minor))


def direction_axis(
    phi: np.ndarray, theta: np.ndarray | None
) -> tuple[np.ndarray, list[str] | None, str]:
    """Where each case's gravity direction goes on a figure's x axis.

    A sweep in the paper's plane (one θ) is drawn against Φ. A sweep with several θ (the
    sphere) has directions that share a Φ, so each direction gets its own column instead:
    the plane's first, by Φ, then the others by θ and Φ, labelled "Φ/θ".

    Returns:
        the x position of every case, the tick labels (None: Φ itself) and the axis label.
    """
    phi = np.asarray(phi, float)
    if theta is None or len(np.unique(np.round(np.asarray(theta, float), 6))) <= 1:
        return phi, None, "gravity angle Φ (deg)"
    theta = np.asarray(theta, float)
    pairs = sorted({(round(float(p), 6), round(float(t), 6)) for p, t in zip(phi, theta,
                                                                            strict=True)},
                   key=lambda d: (d[1] != 0.0, d[1], d[0]))
    index = {d: i for i, d in enumerate(pairs)}
    x = np.array([index[(round(float(p), 6), round(float(t), 6))]
                  for p, t in zip(phi, theta, strict=True)], dtype=float)
    return x, [f"{p:g}/{t:g}" for p, t in pairs], \
        "gravity direction Φ/θ (deg): the plane θ = 0 first, then the others by θ"


def _direction_ticks(ax: Any, labels: list[str] | None) -> None:
    """One labelled tick per direction, where the x axis holds directions."""
    if labels is None:
        return
    ax.set_xticks(np.arange(len(labels)))
    ax.set_xticklabels(labels, rotation=90, fontsize=6)


def plot_sweep_map(
    C1: np.ndarray,
    phi: np.ndarray,
    values: np.ndarray,
    path: str | Path,
    label: str,
    failed: np.ndarray | None = None,
    title: str = "",
    theta: np.ndarray | None = None,
) -> None:
    """A per-case quantity over C1 and the gravity direction; failed cases marked with crosses.

    Args:
        C1: per case, kPa.
        phi: per case, degrees.
        values: the quantity per case (colour).
        path: PNG to write.
        label: colour-bar label, with units.
        failed: True where the case failed (drawn as a red cross).
        title: figure title.
        theta: per case, degrees; with several values, one column per direction
            (:func:`direction_axis`).
    """
    C1, values = np.asarray(C1, float), np.asarray(values, float)
    x, ticks, xlabel = direction_axis(phi, theta)
    fig, ax = plt.subplots(figsize=(8 if ticks is None else 11, 5), constrained_layout=True)
    # square markers about as tall as the C1 spacing of the grid, so that a dense sweep
    # (43 C1 values) does not overlap into a smear
    rows = max(len(np.unique(np.round(C1, 6))), 1)
    size = float(np.clip((260.0 / rows) ** 2, 12.0, 80.0))
    sc = ax.scatter(x, C1, c=values, cmap="viridis", s=size, marker="s")
    if failed is not None and np.any(failed):
        failed = np.asarray(failed, bool)
        ax.scatter(x[failed], C1[failed], marker="x", color="red", s=size, label="failed")
        fig.legend(loc="outside lower center")
    fig.colorbar(sc, ax=ax, label=label)
    _direction_ticks(ax, ticks)
    ax.set_xlabel(xlabel)
    ax.set_ylabel("C1 (kPa)")
    if title:
        ax.set_title(title)
    save_figure(fig, path)


def plot_speed_accuracy(
    variants: Sequence[Mapping[str, Any]],
    path: str | Path,
    cost_label: str,
    target: float | None = None,
) -> None:
    """FE variants' cost per case against their error relative to the refined reference.

    Args:
        variants: one mapping per solved variant with ``cost_s`` (seconds per case),
            ``relative_error`` (max |u − u_ref| / max |u_ref| over the clinical cases, a
            fraction), ``element`` (a key of :data:`ELEMENT_COLOURS`), ``solver``, and the
            flags ``pareto``, ``default`` and ``cheapest`` (meeting the target).
        path: PNG to write.
        cost_label: x-axis label (what the cost is), with units.
        target: the accuracy target (a fraction), drawn as a horizontal line.
    """
    fig, ax = plt.subplots(figsize=(9, 5.5), constrained_layout=True)
    solvers = sorted({str(v["solver"]) for v in variants})
    marker = {s: _MARKERS[i % len(_MARKERS)] for i, s in enumerate(solvers)}
    for v in variants:
        ax.scatter(v["cost_s"], 100 * v["relative_error"], s=70, marker=marker[str(v["solver"])],
                   color=ELEMENT_COLOURS.get(v["element"], "grey"), edgecolor="black",
                   linewidth=0.5, zorder=3)
    front = sorted((v for v in variants if v.get("pareto")), key=lambda v: v["cost_s"])
    if front:
        ax.step([v["cost_s"] for v in front], [100 * v["relative_error"] for v in front],
                where="post", color="black", linewidth=1.2, zorder=2)
    for v in variants:
        if v.get("default"):
            ax.scatter(v["cost_s"], 100 * v["relative_error"], s=260, facecolor="none",
                       edgecolor="crimson", linewidth=2.0, zorder=4)
        if v.get("cheapest"):
            ax.scatter(v["cost_s"], 100 * v["relative_error"], s=420, marker="D",
                       facecolor="none", edgecolor="tab:green", linewidth=2.0, zorder=4)
    if target is not None:
        ax.axhline(100 * target, color="tab:red", linestyle="--", linewidth=1.2)
    ax.set_xscale("log")
    ax.set_yscale("log")
    plain_log_ticks(ax)
    ax.set_xlabel(cost_label)
    ax.set_ylabel("discretisation error: max |u − u_ref| / max |u_ref| (%)")
    ax.grid(True, which="both", alpha=0.3)
    handles = [Line2D([], [], linestyle="", marker="s", markersize=9, color=ELEMENT_COLOURS[e],
                      label=f"element {ELEMENT_NAMES[e]}")
               for e in ELEMENT_COLOURS if any(v["element"] == e for v in variants)]
    handles += [Line2D([], [], linestyle="", marker=marker[s], markersize=8, color="grey",
                       markeredgecolor="black", label=f"solver {s}") for s in solvers]
    if front:
        handles.append(Line2D([], [], color="black", label="Pareto front"))
    if target is not None:
        handles.append(Line2D([], [], color="tab:red", linestyle="--",
                              label=f"accuracy target ({100 * target:g} %)"))
    if any(v.get("cheapest") for v in variants):
        handles.append(Line2D([], [], linestyle="", marker="D", markersize=14,
                              markerfacecolor="none", markeredgecolor="tab:green",
                              markeredgewidth=2, label="cheapest meeting the target"))
    if any(v.get("default") for v in variants):
        handles.append(Line2D([], [], linestyle="", marker="o", markersize=13,
                              markerfacecolor="none", markeredgecolor="crimson",
                              markeredgewidth=2, label="default configuration"))
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.02, 1.0))
    ax.set_title("FE speed against accuracy (clinical cases)")
    save_figure(fig, path)


def _failure_kind(record: Mapping[str, Any]) -> str:
    kind = record.get("first_failure") or ""
    if not kind:
        kinds = record.get("failure_kinds") or {}
        kind = ", ".join(sorted(kinds)) or "unclassified"
    return str(kind)


def plot_convergence_maps(
    records: Sequence[Mapping[str, Any]],
    path: str | Path,
    paper_C1_min: float | None = None,
) -> None:
    """Load steps, Newton iterations and rejected steps over (Φ, C1), one column per scheme.

    Each row shares one colour scale across the schemes; a failed case (load not reached)
    is outlined and marked with a cross whose colour names its first failure.

    Args:
        records: :func:`studies.fe_study.convergence_map.convergence_map`'s records
            (``scheme``, ``C1``, ``phi``, ``converged``, ``load_steps``, ``newton_iterations``,
            ``rejected_steps``, ``first_failure``, ``failure_kinds``).
        path: PNG to write.
        paper_C1_min: the lower end of the paper's C1 range, marked by a line.
    """
    schemes = list(dict.fromkeys(str(r["scheme"]) for r in records))
    C1s = sorted({float(r["C1"]) for r in records})
    phis = sorted({float(r["phi"]) for r in records})
    quantities = [("load_steps", "accepted load steps"),
                  ("newton_iterations", "Newton iterations\n(all attempts)"),
                  ("rejected_steps", "rejected load steps\n(failed attempts)")]
    failure_kinds = sorted({_failure_kind(r) for r in records if not r["converged"]})
    kind_colour = {k: _FAILURE_COLOURS[i % len(_FAILURE_COLOURS)]
                   for i, k in enumerate(failure_kinds)}
    annotate = len(phis) <= 20 and len(C1s) <= 16
    width = max(4.0, 0.42 * len(phis) + 1.2)
    height = max(2.6, 0.3 * len(C1s) + 1.2)
    fig, axes = plt.subplots(len(quantities), len(schemes), squeeze=False, sharex=True, sharey=True,
                             figsize=(width * len(schemes) + 1.6, height * len(quantities) + 0.8),
                             constrained_layout=True)
    for row, (key, label) in enumerate(quantities):
        grids = {}
        for scheme in schemes:
            grid = np.full((len(C1s), len(phis)), np.nan)
            for r in records:
                if r["scheme"] == scheme and r.get(key) is not None:
                    grid[C1s.index(float(r["C1"])), phis.index(float(r["phi"]))] = r[key]
            grids[scheme] = grid
        values = np.concatenate([g[np.isfinite(g)] for g in grids.values()])
        vmin = float(values.min()) if values.size else 0.0
        vmax = float(values.max()) if values.size else 1.0
        if vmax <= vmin:
            vmax = vmin + 1.0
        norm = (LogNorm(max(vmin, 1.0), vmax) if vmin >= 1.0 and vmax / vmin > 20
                else Normalize(vmin, vmax))
        cmap = plt.get_cmap("viridis").copy()
        cmap.set_bad("lightgrey")
        for col, scheme in enumerate(schemes):
            ax = axes[row, col]
            grid = grids[scheme]
            shown = np.ma.masked_invalid(grid)
            if isinstance(norm, LogNorm):
                shown = np.ma.masked_less(shown, 1.0)
            im = ax.imshow(shown, origin="lower", aspect="auto", cmap=cmap, norm=norm,
                           interpolation="nearest")
            failed = {(C1s.index(float(r["C1"])), phis.index(float(r["phi"]))): _failure_kind(r)
                      for r in records if r["scheme"] == scheme and not r["converged"]}
            if annotate:
                for i in range(len(C1s)):
                    for j in range(len(phis)):
                        if np.isfinite(grid[i, j]):
                            rgba = cmap(norm(max(grid[i, j], 1.0) if isinstance(norm, LogNorm)
                                             else grid[i, j]))
                            light = 0.299 * rgba[0] + 0.587 * rgba[1] + 0.114 * rgba[2] > 0.5
                            # a failed cell's number moves left to make room for its cross
                            ax.text(j - 0.17 if (i, j) in failed else j, i, f"{grid[i, j]:.0f}",
                                    ha="center", va="center", fontsize=7,
                                    color="black" if light else "white")
            for (i, j), kind in failed.items():
                ax.add_patch(Rectangle((j - 0.5, i - 0.5), 1, 1, fill=False,
                                       edgecolor=kind_colour[kind], linewidth=1.8, zorder=3))
                ax.scatter(j + 0.25 if annotate else j, i, marker="x", s=45, linewidth=2.0,
                           color=kind_colour[kind], zorder=4)
            if paper_C1_min is not None and C1s[0] < paper_C1_min - 1e-9:
                below = sum(c < paper_C1_min - 1e-9 for c in C1s)
                ax.axhline(below - 0.5, color="white", linewidth=2.0)
                ax.axhline(below - 0.5, color="crimson", linewidth=1.2, linestyle="--")
            if row == 0:
                ax.set_title(f"scheme: {scheme}")
            if row == len(quantities) - 1:
                ax.set_xlabel("gravity angle Φ (deg)")
            if col == 0:
                ax.set_ylabel("C1 (kPa)")
        bar = fig.colorbar(im, ax=list(axes[row, :]), label=label, pad=0.01, fraction=0.03)
        if not isinstance(norm, LogNorm):
            bar.locator = MaxNLocator(integer=True)
            bar.update_ticks()
    for ax in axes[-1, :]:
        ax.set_xticks(range(len(phis)))
        ax.set_xticklabels([f"{p:g}" for p in phis], rotation=60, fontsize=8)
    for ax in axes[:, 0]:
        ax.set_yticks(range(len(C1s)))
        ax.set_yticklabels([f"{c:g}" for c in C1s], fontsize=8)
    handles = [Line2D([], [], linestyle="", marker="x", markersize=9, markeredgewidth=2.2,
                      color=kind_colour[k], label=f"failed: {k}") for k in failure_kinds]
    if paper_C1_min is not None and C1s and C1s[0] < paper_C1_min - 1e-9:
        handles.append(Line2D([], [], color="crimson", linestyle="--",
                              label=f"paper's range starts at C1 = {paper_C1_min:g} kPa"))
    handles.append(Line2D([], [], linestyle="", marker="s", markersize=9, color="lightgrey",
                          label="not run"))
    fig.legend(handles=handles, loc="outside lower center", ncol=min(len(handles), 4))
    save_figure(fig, path)


def plot_c1_effect(
    phi: np.ndarray,
    spread_mm: np.ndarray,
    single_mm: np.ndarray,
    relative: np.ndarray,
    path: str | Path,
    needs_mm: Sequence[float] = (),
    C1_range: tuple[float, float] | None = None,
    theta: np.ndarray | None = None,
    full: np.ndarray | None = None,
) -> None:
    """How much C1 changes the displacement, per gravity direction.

    Args:
        phi: gravity angles, degrees.
        spread_mm: max over points of |u(C1_min) − u(C1_max)|, mm, per angle.
        single_mm: the error of the best single C1 (the largest difference to any other
            C1 of the sweep, minimised over the C1 chosen), mm, per angle.
        relative: ``spread_mm`` over the largest |u| at that angle, a fraction.
        path: PNG to write.
        needs_mm: accuracy needs, drawn as horizontal lines.
        C1_range: the sweep's C1 range (kPa), for the title.
        theta: the directions' θ, degrees; with several values, one column per direction
            (:func:`direction_axis`).
        full: per direction, whether its cases span the whole C1 range (default: all do);
            the others are drawn grey, apart from the lines.
    """
    x, ticks, xlabel = direction_axis(phi, theta)
    order = np.argsort(x, kind="stable")
    x, spread_mm = x[order], np.asarray(spread_mm)[order]
    single_mm, relative = np.asarray(single_mm)[order], np.asarray(relative)[order]
    full = np.ones(len(x), bool) if full is None else np.asarray(full, bool)[order]
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11 if ticks is None else 14, 5.0),
                                   constrained_layout=True)
    # lines join neighbouring angles of the plane; the sphere's columns are not neighbours
    line, dashed = ("-", "--") if ticks is None else ("none", "none")
    ax1.plot(x[full], spread_mm[full], marker="o", linestyle=line, linewidth=3.0, markersize=9,
             alpha=0.6, label="|u(C1 min) − u(C1 max)|, max over points")
    ax1.plot(x[full], single_mm[full], marker="s", linestyle=dashed, markerfacecolor="none",
             markersize=7, markeredgewidth=1.5, label="error of the best single C1")
    if not full.all():
        ax1.plot(x[~full], spread_mm[~full], marker="o", linestyle="none", markersize=7,
                 color="0.6", alpha=0.7, label="over part of the C1 range only")
        ax1.plot(x[~full], single_mm[~full], marker="s", linestyle="none",
                 markerfacecolor="none", markersize=6, color="0.6")
    styles = ("--", "-.", ":", (0, (5, 1)))
    for i, need in enumerate(needs_mm):
        ax1.axhline(need, color="grey", linestyle=styles[i % len(styles)], linewidth=1.1,
                    label=f"need {need:g} mm")
    ax1.set_yscale("log")
    plain_log_ticks(ax1)
    _direction_ticks(ax1, ticks)
    ax1.set_xlabel(xlabel)
    ax1.set_ylabel("displacement difference (mm)")
    fig.legend(*ax1.get_legend_handles_labels(), fontsize=8, loc="outside lower center",
               ncol=4)  # below both panels, clear of the direction labels
    ax1.grid(True, which="both", alpha=0.3)
    ax2.plot(x[full], 100 * relative[full], marker="o", linestyle=line, color="tab:purple")
    if not full.all():
        ax2.plot(x[~full], 100 * relative[~full], marker="o", linestyle="none", color="0.6")
    _direction_ticks(ax2, ticks)
    ax2.set_xlabel(xlabel)
    ax2.set_ylabel("spread / max |u| in that direction (%)")
    ax2.set_ylim(bottom=0)
    ax2.grid(True, alpha=0.3)
    if C1_range is not None:
        fig.suptitle(f"Effect of C1 over the sweep's range {C1_range[0]:g}–{C1_range[1]:g} kPa")
    save_figure(fig, path)


def plot_fold_section(cases: Sequence[Mapping[str, Any]], path: str | Path,
                      zoom_mm: float = 35.0) -> None:
    """The fold's cross-section per case: reference, without and with self-contact.

    ``cases`` are :class:`studies.fe_study.fold_section.FoldCase` records as mappings. One row per
    case: the whole cut, and a window of ``zoom_mm`` either side of the focus (the node of the
    largest self-contact pressure where self-contact moves it).
    """
    from matplotlib.collections import LineCollection

    styles = {"reference": ("0.65", 0.8, "reference (unloaded)"),
              "none": ("tab:red", 1.3, "without self-contact"),
              "self-contact": ("tab:blue", 1.3, "with self-contact")}
    fig, axes = plt.subplots(len(cases), 3, figsize=(13, 4.4 * len(cases)), squeeze=False,
                             layout="constrained", width_ratios=[1, 1, 0.62])
    for (*row, key), case in zip(axes, cases, strict=True):
        layers = [("reference", case["reference_mm"], "")]
        for state in sorted(case["states"], key=lambda s: s["setting"] != "none"):
            outcome = "" if state["status"] == "converged" else \
                f", failed at λ = {state['load_fraction']:.3f}"
            overlap = state.get("self_overlap")
            crossing = f",\n{overlap} boundary vertices inside other cells" if overlap else ""
            layers.append((state["setting"], state["segments_mm"],
                           f":\nmax |u| {state['max_disp_mm']:.1f} mm{outcome}{crossing}"))
        focus = np.asarray(case["focus_mm"], dtype=float)
        plane = case["plane_axis"]
        vertical = {"y": "z, inferior → superior (mm)",  # a sagittal view, superior up
                    "z": "y, medial → lateral (mm)"}[plane]  # a transverse view
        for ax in row:
            for name, segments, note in layers:
                colour, width, label = styles[name]
                if len(segments):
                    ax.add_collection(LineCollection(np.asarray(segments),
                                                     colors=colour, linewidths=width,
                                                     label=label + note))
            ax.set_aspect("equal")
            ax.autoscale_view()
            ax.set_xlabel("x, anterior → posterior (mm)")
            ax.set_ylabel(vertical)
            ax.grid(True, alpha=0.3)
        row[1].set_xlim(focus[0] - zoom_mm, focus[0] + zoom_mm)
        row[1].set_ylim(focus[1] - zoom_mm, focus[1] + zoom_mm)
        row[0].set_title(f"the cut at {plane} = {case['plane_at_mm']:.1f} mm (reference)")
        row[1].set_title(f"the fold, ±{zoom_mm:g} mm")
        key.axis("off")  # the row's legend: what each line is, its max |u| and outcome
        key.legend(*row[0].get_legend_handles_labels(), loc="center left", fontsize=8,
                   title=f"C1 = {case['C1']:g} kPa, Φ = {case['phi']:g}°, θ = {case['theta']:g}°")
    save_figure(fig, path)


__all__ = [
    "direction_axis", "plot_c1_effect", "plot_fold_section", "plot_speed_accuracy",
    "plot_convergence_maps", "plot_sweep_map",
]
