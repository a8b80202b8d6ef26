"""The reference state of an imaged shape: the estimate beside the naive prediction."""

from __future__ import annotations

import numpy as np

from report.context import Context
from report.html import missing, para, table
from studies.figures.surrogate import plot_stiffness_misfit
from studies.reference_state.reference_roundtrip import HEADER, table_rows


def reference_section(ctx: Context) -> str:
    """One row per round trip: the estimate's error and cost, the naive prediction's error."""
    trips = ctx.results.get("reference_roundtrip")
    if trips is None:
        return missing("results/reference/roundtrip.json")
    out = [para(
        "An imaged breast is already loaded: its mesh is not stress-free. Each row solves the "
        "config's mesh (the true reference) in the observed posture, takes that shape as the "
        "image, estimates its reference (fem.reference: the inverse-motion problem, equilibrium "
        "written on the imaged shape with the reference as unknown, solved once and checked by "
        "forward solves that start from its answer, finished by Sellier's fixed point with "
        "Anderson's mixing where the check misses; tolerance "
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
        f"The largest error of a prediction from the estimate is {worst.target_error_mm:.2g} "
        f"mm ({100 * worst.target_error_mm / worst.target_sag_mm:.2g} % of its max |u|); the "
        f"smallest error of the naive prediction is {naive.naive_error_mm:.1f} mm "
        f"({100 * naive.naive_error_mm / naive.target_sag_mm:.0f} %)."))
    out.extend(_imaged(ctx))
    return "".join(out)


def _imaged(ctx: Context) -> list[str]:
    """The imaged mesh's own chain, where the config sets reference_state.imaged."""
    out = []
    record = ctx.results.get("reference_record")
    if record is not None:
        out.append(para(
            f"The imaged mesh, taken as {record.case}: its reference was found in "
            + ("" if record.inverse_newton_iterations is None else
               f"one inverse-motion solve ({record.inverse_newton_iterations} Newton iterations, "
               f"{record.inverse_s:.1f} s) and ")
            + f"{record.forward_solves} forward solves ({record.warm_starts} warm-started), "
            f"{record.wall_s:.1f} s, {record.cost:.1f} times one cold forward solve "
            f"({record.cold_forward_s:.1f} s); the largest node misfit fell to "
            f"{record.misfit_mm[-1]:.4f} mm. The reference lies up to "
            f"{record.largest_shift_mm:.2f} mm from the imaged shape; the sweep, the surrogate "
            "and the studies above ran on it."))
    for name, tracked in ctx.tracking:
        rows = [[n, f"{1e3 * np.linalg.norm(np.subtract(fe, seen)):.2f}", f"{d:.3f}"]
                for n, seen, fe, d in zip(tracked.names, tracked.observed, tracked.fe,
                                          tracked.difference_mm, strict=True)]
        out.append(para(
            f"Points of {name} tracked from the imaged shape to Φ = {tracked.target_phi:g}°, "
            f"θ = {tracked.target_theta:g}° at C1 = {tracked.C1_kPa:g} kPa, by FE "
            f"({tracked.fe_s:.1f} s) and by the surrogate (median "
            f"{tracked.surrogate_ms['median_ms']:.3f} ms for the {len(tracked.names)} points on "
            f"one core): results/tracking/{name}.csv.", "caption"))
        out.append(table(["point", "moved by FE (mm)", "FE to surrogate (mm)"], rows,
                         table_id=f"tracking-{name}"))
    stiffness = ctx.results.get("stiffness")
    if stiffness is not None:
        lo, hi = stiffness.interval_kPa
        out.append(ctx.figure(
            "stiffness_misfit.png",
            lambda path: plot_stiffness_misfit(
                stiffness.curve_C1_kPa, stiffness.curve_rms_mm, stiffness.fe_C1_kPa,
                stiffness.fe_rms_mm, stiffness.C1_kPa, stiffness.interval_kPa,
                stiffness.truth_C1_kPa, path),
            "misfit over C1",
            f"C1 from the second observation ({stiffness.points} points at Φ = "
            f"{stiffness.phi:g}°): {stiffness.C1_kPa:.3g} kPa, {100 * stiffness.confidence:g} % "
            f"interval [{lo:.3g}, {hi:.3g}] kPa, RMS misfit {stiffness.rms_mm:.2f} mm; the "
            f"surrogate's search found {stiffness.surrogate_C1_kPa:.3g} kPa, "
            f"{len(stiffness.fe_C1_kPa)} FE solves confirmed it; {stiffness.wall_s:.1f} s in all."))
    return out
