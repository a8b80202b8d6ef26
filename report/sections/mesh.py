"""The mesh: its size and quality, and its picture."""

from __future__ import annotations

import shutil

from fem.self_contact_at_rest import MeshRestPairs
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
        ["skin facing itself at rest", _rest_pairs(ctx.results.get("rest_pairs"))],
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


def _rest_pairs(record: MeshRestPairs | None) -> str:
    """The skin's self-contact pairs at rest, and what became of them (docs/contact.md)."""
    if record is None:
        return "n/a"
    found = record.found
    if not found.pairs:
        return "no pair (nothing touches at rest)"
    text = f"{found.pairs} node–triangle pairs ({found.nodes} skin nodes)"
    parts = []
    if found.behind:
        parts.append(f"{found.behind} across the tissue, deepest {found.deepest_mm:.1f} mm"
                     + ("" if found.deepest_at_m is None else
                        " at ({:.0f}, {:.0f}, {:.0f}) mm".format(
                            *(1e3 * v for v in found.deepest_at_m))))
    if found.in_front:
        parts.append(f"{found.in_front} in front, nearest {found.closest_gap_mm:.2f} mm")
    text += ": " + "; ".join(parts)
    if not record.self_contact:
        return text + " (self-contact is off)"
    return text + (f"; at_rest {found.treatment}: {found.pairs_left} push at rest")
