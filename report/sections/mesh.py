"""The mesh: its size and quality, and its picture."""

from __future__ import annotations

import shutil

from report.context import Context
from report.html import figure, finite, fmt, missing, para, seconds, table


def mesh_section(ctx: Context) -> str:
    """The mesh section: size and quality table, and the picture of the named surfaces."""
    quality = ctx.results.get("quality")
    if quality is None:
        return missing("results/mesh/quality.json")
    anatomy = quality.anatomy
    rows = [
        ["tetrahedra", fmt(quality.cells, "d")],
        ["vertices (material points)", fmt(quality.vertices, "d")],
        ["P2/P1 unknowns", fmt(quality.dofs.get("P2/P1"), "d")],
        ["volume (ml)", fmt(quality.volume_ml, ".0f")],
        ["breast (mound) volume (ml)", fmt(anatomy.get("breast_volume_ml"), ".0f")],
        ["projection from the chest wall (mm)",
         fmt(1e3 * anatomy["projection_from_chest_wall_m"], ".0f")
         if finite(anatomy.get("projection_from_chest_wall_m")) else "n/a"],
        ["min / mean SICN", f"{fmt(quality.min_minSICN, '.3f')} / "
                            f"{fmt(quality.mean_minSICN, '.3f')}"],
        ["min / max dihedral angle (deg)", f"{fmt(quality.min_dihedral_deg, '.1f')} / "
                                           f"{fmt(quality.max_dihedral_deg, '.1f')}"],
        ["inverted / degenerate cells", f"{fmt(quality.inverted_cells, 'd')} / "
                                        f"{fmt(quality.degenerate_cells, 'd')}"],
        ["meshing time", seconds(quality.mesh_wall_s)],
    ]
    out = [para("The tetrahedral mesh of the breast on which the FE sweep was solved; its "
              "vertices are the material points the surrogate learns. SICN is the "
              "signed inverse condition number of a cell (1 for a regular tetrahedron, "
              "≤ 0 for an inverted one).", "caption"),
           table(["quantity", "value"], rows)]
    png = ctx.paths.get("mesh_png")
    if png is not None and png.is_file():
        shutil.copyfile(png, ctx.out_dir / "mesh.png")
        out.append(figure("mesh.png", "the mesh",
                           "The mesh with its named surfaces coloured (rib/chest wall clamped)."))
    return "".join(out)
