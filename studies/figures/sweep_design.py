"""Figures about the adaptive sweep's design: how its estimate fell, where its directions landed.

Every function takes plain numbers and writes one PNG with matplotlib's Agg backend, as
:mod:`studies.figures.fe` does.
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
from matplotlib.ticker import MaxNLocator  # noqa: E402

from fem.directions import gravity_direction  # noqa: E402
from studies.figures.fe import plain_log_ticks, save_figure  # noqa: E402

__all__ = ["below_projection", "plot_sweep_design"]

#: Where the paper's plane (the rim) is labelled: (Φ, what that gravity direction is).
RIM_LABELS = ((0.0, "Φ 0°\nsupine"), (90.0, "Φ 90°"), (180.0, "Φ 180°\nprone"),
              (-90.0, "Φ −90°"))


def below_projection(phi: Any, theta: Any) -> tuple[np.ndarray, np.ndarray]:
    """Plot coordinates of gravity directions (Φ, θ) seen from below (the feet).

    The azimuthal equal-area (Lambert) projection of the unit vector g
    (:func:`fem.directions.gravity_direction`) about the −z axis: g = −z (gravity to the feet,
    upright) at the centre, the paper's plane (g_z = 0) on the rim at radius √2, equal areas
    of the sphere equal areas of the plot. Seen from below, +x (Φ = 0°, supine) is up and +y
    (Φ = 90°, θ = 0°) is right.
    """
    g = gravity_direction(np.asarray(phi, dtype=float), np.asarray(theta, dtype=float))
    radius = np.sqrt(np.clip(2.0 * (1.0 + g[..., 2]), 0.0, None))
    rho = np.hypot(g[..., 0], g[..., 1])
    scale = np.divide(radius, rho, out=np.zeros_like(rho), where=rho > 1e-12)
    return scale * g[..., 1], scale * g[..., 0]


def plot_sweep_design(rounds: Sequence[Mapping[str, Any]], target_mm: float,
                      phi: Any, theta: Any, added_in: Any, all_failed: Any,
                      path: str | Path) -> None:
    """The estimate round by round (left) and every direction of the sweep by its round (right).

    Args:
        rounds: per round, ``round``, ``cases_before`` and ``estimate_mm`` (the estimated
            worst-point error from the cases before the round).
        target_mm: the target the rounds stop under (a dashed line).
        phi: the sweep's directions' Φ (degrees), one each.
        theta: their θ (degrees).
        added_in: the round that added each direction (0: the start design).
        all_failed: True where every case of the direction failed (drawn hollow).
        path: PNG to write.
    """
    added_in = np.asarray(added_in, dtype=int)
    all_failed = np.asarray(all_failed, dtype=bool)
    fig, (left, right) = plt.subplots(1, 2, figsize=(12, 5.5), layout="constrained",
                                      gridspec_kw={"width_ratios": [1, 1.1]})
    numbers = [int(r["round"]) for r in rounds]
    estimates = [float(r["estimate_mm"]) for r in rounds]
    left.plot(numbers, estimates, "o-", color="tab:blue",
              label="estimated worst-point error before the round")
    for n, e, r in zip(numbers, estimates, rounds, strict=True):
        left.annotate(f"{int(r['cases_before'])} cases", (n, e), textcoords="offset points",
                      xytext=(4, 6), fontsize=8)
    left.axhline(target_mm, color="tab:red", linestyle="--", label=f"target ({target_mm:g} mm)")
    positive = [e for e in estimates if e > 0]
    if positive and max(positive + [target_mm]) / min(positive + [target_mm]) > 20:
        left.set_yscale("log")
        plain_log_ticks(left)
    else:
        left.set_ylim(bottom=0)
    left.margins(x=0.15)  # room for the last round's count of cases
    left.xaxis.set_major_locator(MaxNLocator(integer=True))
    left.set_xlabel("round")
    left.set_ylabel("estimated worst-point error (mm)")
    left.grid(True, which="both", alpha=0.3)
    left.legend(loc="best")
    left.set_title("The estimate, round by round")

    x, y = below_projection(phi, theta)
    rim = np.sqrt(2.0)
    angle = np.linspace(0.0, 2 * np.pi, 361)
    right.plot(rim * np.cos(angle), rim * np.sin(angle), color="black", linewidth=1.0)
    right.plot([0.0], [0.0], "+", color="grey", markersize=10)
    right.annotate("upright\n(Φ/θ 90/−90)", (0.0, 0.0), textcoords="offset points",
                   xytext=(6, -22), fontsize=8, color="grey")
    for p, text in RIM_LABELS:
        lx, ly = below_projection(p, 0.0)
        right.annotate(text, (float(lx), float(ly)), textcoords="offset points",
                       xytext=(14 * np.sign(lx), 14 * np.sign(ly)), fontsize=8,
                       ha="center", va="center")
    last = max(int(added_in.max(initial=0)), 1)
    cmap = plt.get_cmap("viridis", last)  # the start design grey, the rounds in order
    handles = []
    for k in range(last + 1):
        mine = added_in == k
        if not mine.any():
            continue
        colour = "0.6" if k == 0 else cmap(k - 1)
        for hollow in (False, True):
            sel = mine & (all_failed == hollow)
            right.scatter(x[sel], y[sel], s=40, facecolors="none" if hollow else [colour],
                          edgecolors=[colour], linewidths=1.4 if hollow else 0.5, zorder=3)
        handles.append(Line2D([], [], linestyle="", marker="o", color=colour,
                              label="start design" if k == 0 else f"round {k}"))
    if all_failed.any():
        handles.append(Line2D([], [], linestyle="", marker="o", markerfacecolor="none",
                              markeredgecolor="grey", label="every case failed"))
    reach = max(rim, float(np.hypot(x, y).max(initial=0.0))) + 0.35
    right.set_xlim(-reach, reach)
    right.set_ylim(-reach, reach)
    right.set_aspect("equal")
    right.set_axis_off()
    right.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.0, 1.0), fontsize=8)
    right.set_title("Directions seen from below (equal-area; rim: the paper's plane)")
    save_figure(fig, path)
