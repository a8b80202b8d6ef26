"""A picture of the mesh with each named boundary surface in its own colour."""

from __future__ import annotations

import logging
import os
from pathlib import Path

import numpy as np

from meshes.tags import Boundary

log = logging.getLogger(__name__)

COLOURS = {
    Boundary.RIB: "#d62728",
    Boundary.SKIN: "#f2c7a5",
    Boundary.STERNAL: "#1f77b4",
    Boundary.CRANIAL: "#2ca02c",
    Boundary.CAUDAL: "#9467bd",
    Boundary.AXILLA: "#ff7f0e",
}
"""One colour per boundary; the skin is skin-coloured so the cuts stand out."""

VIEWS = (
    ("antero-medial, from cranial: skin, sternal, cranial", 25.0, -135.0, "persp"),
    ("postero-lateral, from caudal: rib, axilla, caudal", -20.0, 30.0, "persp"),
    ("transverse, from cranial", 90.0, -90.0, "ortho"),
)
"""(title, elevation, azimuth, projection) of each panel; matplotlib's azimuth is the
camera's angle from +x in the x-y plane, so -135° looks from anterior-medial. Between
them the first two panels show all six named surfaces."""


def plot_boundaries(
    x: np.ndarray,
    facets: dict[Boundary, np.ndarray],
    png_path: str | Path,
    title: str = "",
) -> None:
    """Render the boundary triangles coloured by surface and write a PNG atomically.

    Args:
        x: vertex coordinates (N, 3), metres (plotted in cm).
        facets: boundary -> triangle vertex indices (M, 3).
        png_path: output file.
        title: figure title.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Patch
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    xc = 100.0 * np.asarray(x)
    lo, hi = xc.min(axis=0), xc.max(axis=0)
    present = [(b, t) for b, t in facets.items() if len(t)]
    tris = np.concatenate([t for _, t in present])
    colours = np.concatenate([[COLOURS[b]] * len(t) for b, t in present])
    fig = plt.figure(figsize=(15, 6.5), dpi=110)
    for i, (view, elev, azim, proj) in enumerate(VIEWS):
        ax = fig.add_subplot(1, len(VIEWS), i + 1, projection="3d")
        # One collection for all surfaces: matplotlib depth-sorts faces within a
        # collection but draws separate collections in one fixed order, which would
        # paint the skin over the rib in the posterior view.
        ax.add_collection3d(
            Poly3DCollection(
                xc[tris],
                facecolors=colours,
                edgecolors="k",
                linewidths=0.08,
                shade=True,  # light-dependent shading gives the curved surfaces depth
            )
        )
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(lo[1], hi[1])
        ax.set_zlim(lo[2], hi[2])
        ax.set_box_aspect(np.maximum(hi - lo, 1e-9))  # true proportions
        ax.view_init(elev=elev, azim=azim)
        ax.set_proj_type(proj)
        ax.set_xlabel("x (cm, ant.→post.)")
        ax.set_ylabel("y (cm, med.→lat.)")
        ax.set_zlabel("z (cm, caud.→cran.)")
        if elev == 90.0:  # looking along z: its ticks would pile up on one spot
            ax.set_zticks([])
            ax.set_zlabel("")
            ax.yaxis.labelpad = 14  # clear of the tick labels
        # below the panel and its axis labels: a camera from caudal puts tick labels
        # where a title would go
        ax.text2D(0.5, -0.1, view, transform=ax.transAxes, ha="center", va="top", fontsize=10)
    handles = [
        Patch(
            facecolor=COLOURS[b],
            edgecolor="k",
            label=f"{b.label} ({len(facets.get(b, []))} facets)",
        )
        for b in Boundary
    ]
    fig.legend(handles=handles, loc="lower center", ncol=len(handles), fontsize=9, frameon=False)
    if title:
        fig.suptitle(title, fontsize=11, y=0.99)
    # room above for the title and the caudal view's tick labels, below for the captions
    fig.subplots_adjust(left=0.02, right=0.98, top=0.84, bottom=0.2, wspace=0.12)
    target = Path(png_path)
    target.parent.mkdir(parents=True, exist_ok=True)
    # a temporary name beside the target (created with the usual permissions, unlike
    # mkstemp's 0600), renamed into place: a crash never leaves half a picture
    tmp = target.with_name(f".{target.name}.{os.getpid()}.tmp")
    try:
        fig.savefig(tmp, format="png")
        os.replace(tmp, target)
    finally:
        plt.close(fig)
        tmp.unlink(missing_ok=True)
    log.info("wrote %s", target)
