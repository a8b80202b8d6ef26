"""The reference state of an imaged shape: the estimate beside the naive prediction."""

from __future__ import annotations

from report.context import Context
from report.html import missing, para, table
from studies.reference_roundtrip import HEADER, table_rows


def reference_section(ctx: Context) -> str:
    """One row per round trip: the estimate's error and cost, the naive prediction's error."""
    trips = ctx.results.get("reference_roundtrip")
    if trips is None:
        return missing("results/reference/roundtrip.json")
    out = [para(
        "An imaged breast is already loaded: its mesh is not stress-free. Each row solves the "
        "config's mesh (the true reference) in the observed posture, takes that shape as the "
        "image, estimates its reference (fem.reference: Sellier's fixed point with Aitken's "
        "relaxation, warm-started forward solves, tolerance "
        f"{trips.tolerance_mm:g} mm), and predicts the other posture from the estimate. "
        "Beside it, the naive prediction that takes the imaged shape as stress-free. Errors "
        "are the largest over the mesh's nodes, against the prediction from the true "
        "reference (in brackets, as a share of that posture's max |u|); the cost is the "
        "estimate's wall time over one cold forward solve of the observed case, measured in "
        "the same job.", "caption")]
    out.append(table(HEADER, table_rows(trips), table_id="reference-roundtrip"))
    worst = max(trips.rows, key=lambda r: r.target_error_mm / r.target_sag_mm)
    naive = min(trips.rows, key=lambda r: r.naive_error_mm / r.target_sag_mm)
    out.append(para(
        f"The largest error of a prediction from the estimate is {worst.target_error_mm:.3f} "
        f"mm ({100 * worst.target_error_mm / worst.target_sag_mm:.2f} % of its max |u|); the "
        f"smallest error of the naive prediction is {naive.naive_error_mm:.1f} mm "
        f"({100 * naive.naive_error_mm / naive.target_sag_mm:.0f} %)."))
    return "".join(out)
