"""Figures about the tissues: what the skin's ratio and thickness change.

Every function takes plain numbers (a result as its JSON mapping) and writes one PNG with
matplotlib's Agg backend, as :mod:`studies.figures.fe` does.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from studies.figures.fe import plain_log_ticks, save_figure  # noqa: E402

__all__ = ["plot_skin"]


def _series(study: Mapping[str, Any], varied: str) -> list[Mapping[str, Any]]:
    """The default skin and the settings that vary ``varied``, by the varied value."""
    key = "ratio" if varied == "ratio" else "thickness_m"
    chosen = [s for s in study["settings"] if s["varied"] in ("default", varied)]
    return sorted(chosen, key=lambda s: s[key])


def plot_skin(study: Mapping[str, Any], path: str | Path,
              labels: Mapping[str, str] | None = None) -> None:
    """Max |u| and the tumour's way against the skin's ratio and thickness, in one PNG.

    Top: max |u|; bottom: the tumour's prone-to-supine distance; left: against the skin's
    ratio, right: against its thickness. ``study`` is a :class:`studies.fe_study.skin.SkinStudy` as
    a
    mapping; ``labels`` names the clinical cases by id. One line per clinical case (per C1 for
    the tumour's path), the homogeneous model's value dotted in the same colour; a case that
    did not converge is a hollow marker at the load it reached, a path that lacks a converged
    case is left out.
    """
    labels = labels or {}
    cases = {(c["setting"], c["case"]): c for c in study["cases"]}
    paths = {(p["setting"], p["C1"]): p for p in study["paths"]}
    case_ids = list(dict.fromkeys(c["case"] for c in study["cases"]))
    c1s = sorted({p["C1"] for p in study["paths"]})
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    fig, axes = plt.subplots(2, 2, figsize=(11, 8), layout="constrained", sharey="row")
    for col, varied in enumerate(("ratio", "thickness")):
        series = _series(study, varied)
        xs = [s["ratio"] if varied == "ratio" else 1e3 * s["thickness_m"] for s in series]
        top, bottom = axes[0, col], axes[1, col]
        for i, cid in enumerate(case_ids):
            colour = colours[i % len(colours)]
            rows = [cases.get((s["name"], cid)) for s in series]
            top.plot(xs, [r["max_disp_mm"] if r else float("nan") for r in rows], "-",
                     color=colour, label=labels.get(cid, cid))
            for x, r in zip(xs, rows, strict=True):
                if r is not None:
                    top.plot(x, r["max_disp_mm"], "o", color=colour,
                             fillstyle="full" if r["status"] == "converged" else "none")
            homogeneous = cases.get(("homogeneous", cid))
            if homogeneous is not None:
                top.axhline(homogeneous["max_disp_mm"], color=colour, linestyle=":")
        for i, c1 in enumerate(c1s):
            colour = colours[i % len(colours)]
            ds = [(paths.get((s["name"], c1)) or {}).get("distance_mm") for s in series]
            bottom.plot(xs, [float("nan") if d is None else d for d in ds], "o-", color=colour,
                        label=f"C1 = {c1:g} kPa")
            homogeneous = (paths.get(("homogeneous", c1)) or {}).get("distance_mm")
            if homogeneous is not None:
                bottom.axhline(homogeneous, color=colour, linestyle=":")
        if not c1s:
            bottom.text(0.5, 0.5, "no prone and supine clinical case of one C1",
                        ha="center", va="center", transform=bottom.transAxes)
        name = "the skin's C1 over the fat's" if varied == "ratio" else "the skin's thickness (mm)"
        for ax in (top, bottom):
            ax.set_xlabel(name)
            ax.grid(True, alpha=0.3)
            if varied == "ratio":
                ax.set_xscale("log")
                plain_log_ticks(ax)
        top.set_title(f"max |u| against {name.split(' (')[0]}")
        bottom.set_title(f"the tumour's prone-to-supine way against {name.split(' (')[0]}")
    axes[0, 0].set_ylabel("max |u| (mm)")
    axes[1, 0].set_ylabel("tumour moves, prone to supine (mm)")
    axes[0, 0].legend(title="dotted: homogeneous; hollow: not converged")
    if c1s:
        axes[1, 0].legend(title="dotted: homogeneous")
    save_figure(fig, path)
