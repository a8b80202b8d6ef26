"""The reference state's round trip, beside the naive prediction: a benchmark and a report table.

``python -m studies.reference_state.reference_roundtrip MESH [--config config.yaml] [--c1 1 2 5]
[--observed 180 0 60] [--out roundtrip.json]``

For each C1 and each posture Φ of the observation: solve from the mesh (the true reference)
to get the observed shape; estimate the reference from it
(:func:`fem.reference.estimate_reference`);
report the largest node distance to the truth (mm and % of the observation's max |u|), the
supine (Φ = 0, or prone Φ = 180 for a supine observation) shape predicted from the estimate
against the one from the truth, the same prediction made from the observed shape taken as
stress-free (the naive way), and the estimate's wall time over one cold forward solve of the
observed case measured in the same process just before it. The workflow's rule
``reference_roundtrip`` writes the table for the report.
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from fem.configfile import read_config_file
from fem.exceptions import FEError
from fem.parameters import SolverSettings
from fem.sweep import Case
from studies.results import Record, Result
from studies.timing_hygiene import machine_state


@dataclass(frozen=True)
class RoundTrip(Record):
    """One round trip.

    Attributes:
        C1_kPa: the stiffness.
        observed_phi: the observation's Φ.
        target_phi: the predicted posture's Φ.
        sag_mm: the observation's max |u| from the true reference.
        reference_error_mm: the estimate's largest node distance to the true reference.
        target_sag_mm: the target posture's max |u| from the true reference.
        target_error_mm: the target shape from the estimate against the one from the truth.
        naive_error_mm: the target shape from the observed shape taken as stress-free, against
            the truth.
        forward_solves: forward solves of the estimate (the inverse-motion solve not counted).
        newton_iterations: their Newton iterations in all.
        cost: the estimate's wall time over one cold forward solve of the observed case.
        estimate_s: the estimate's wall time.
        converged: whether the estimate converged.
        reason: why it stopped.
        method: how the reference was found (:data:`fem.reference.METHODS`).
        inverse_newton_iterations: Newton iterations of the inverse-motion solve (None without
            one).
    """

    C1_kPa: float
    observed_phi: float
    target_phi: float
    sag_mm: float
    reference_error_mm: float
    target_sag_mm: float
    target_error_mm: float
    naive_error_mm: float
    forward_solves: int
    newton_iterations: int
    cost: float
    estimate_s: float
    converged: bool
    reason: str
    method: str = "anderson"
    inverse_newton_iterations: int | None = None


@dataclass(frozen=True)
class RoundTripTable(Result):
    """``roundtrip.json``: the round trips and where they were measured."""

    rows: list[RoundTrip]
    tolerance_mm: float
    machine: dict[str, Any]


HEADER = ["C1 (kPa)", "observed Φ", "predicted Φ", "observed max |u| (mm)",
          "reference error (mm)", "predicted error (mm)", "naive error (mm)", "solves",
          "cost (cold solves)"]


def table_rows(table: RoundTripTable) -> list[list[str]]:
    """The report's rows: errors in mm and as % of the posture's max |u|."""
    rows = []
    for r in table.rows:
        rows.append([
            f"{r.C1_kPa:g}", f"{r.observed_phi:g}°", f"{r.target_phi:g}°", f"{r.sag_mm:.2f}",
            f"{r.reference_error_mm:.3g} ({100 * r.reference_error_mm / r.sag_mm:.2g} %)",
            f"{r.target_error_mm:.3g} ({100 * r.target_error_mm / r.target_sag_mm:.2g} %)",
            f"{r.naive_error_mm:.2f} ({100 * r.naive_error_mm / r.target_sag_mm:.0f} %)",
            _solves(r) + ("" if r.converged else f" (failed: {r.reason})"),
            f"{r.cost:.2f}",
        ])
    return rows


def _solves(r: RoundTrip) -> str:
    """The estimate's solves: the inverse-motion solve (Newton iterations) and forward ones."""
    forward = f"{r.forward_solves} forward"
    if r.inverse_newton_iterations is None:
        return forward
    return f"1 inverse ({r.inverse_newton_iterations} Newton its) + {forward}"


def round_trips(mesh: Path, settings: SolverSettings, c1s: list[float],
                observed_phis: list[float], tolerance: float = 1e-5) -> RoundTripTable:
    """Run every round trip on one runner (its geometry is moved and put back)."""
    from fem.case import CaseRunner
    from fem.io import node_displacement
    from fem.reference import estimate_reference

    runner = CaseRunner(mesh, settings)
    X = runner.mesh.geometry.x.copy()

    def deformed(case: Case, reference: np.ndarray) -> tuple[np.ndarray, float]:
        runner.problem.set_geometry(reference)
        start = time.perf_counter()
        result, _ = runner.solve(case)
        elapsed = time.perf_counter() - start
        if not result.converged:
            raise RuntimeError(f"{case.id} from the reference did not converge: {result.reason}")
        return reference + node_displacement(runner.problem), elapsed

    rows = []
    try:
        for c1 in c1s:
            for phi in observed_phis:
                observed_case = Case(c1, phi)
                target = Case(c1, 180.0 if phi == 0.0 else 0.0)
                x, cold = deformed(observed_case, X)
                runner.problem.set_geometry(x)
                estimate = estimate_reference(
                    runner, observed_case.material(settings.density),
                    observed_case.gravity(settings.gravity), tolerance=tolerance)
                truth, _ = deformed(target, X)
                proper, _ = deformed(target, estimate.X)
                naive, _ = deformed(target, x)

                def largest(a: np.ndarray, b: np.ndarray) -> float:
                    return 1e3 * float(np.linalg.norm(a - b, axis=1).max())

                rows.append(RoundTrip(
                    C1_kPa=c1, observed_phi=phi, target_phi=target.phi, sag_mm=largest(x, X),
                    reference_error_mm=largest(estimate.X, X),
                    target_sag_mm=largest(truth, X), target_error_mm=largest(proper, truth),
                    naive_error_mm=largest(naive, truth),
                    forward_solves=estimate.forward_solves,
                    newton_iterations=int(sum(estimate.newton_iterations)),
                    cost=estimate.wall_s / cold, estimate_s=estimate.wall_s,
                    converged=estimate.converged, reason=estimate.reason,
                    method=estimate.method,
                    inverse_newton_iterations=estimate.record()["inverse_newton_iterations"],
                ))
    finally:
        runner.problem.set_geometry(X)
        runner.close()
    return RoundTripTable(rows=rows, tolerance_mm=1e3 * tolerance,
                          machine=machine_state().to_json())


def main(argv: list[str] | None = None) -> int:
    """Run the round trips, print one row each and write the table with ``--out``."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("mesh", type=Path)
    parser.add_argument("--config", type=Path, help="solver settings (fe, material, mesh)")
    parser.add_argument("--c1", type=float, nargs="+", default=[1.0, 2.0, 5.0])
    parser.add_argument("--observed", type=float, nargs="+", default=[180.0, 0.0, 60.0])
    parser.add_argument("--tolerance-mm", type=float, default=0.01)
    parser.add_argument("--out", type=Path, help="roundtrip.json to write")
    args = parser.parse_args(argv)
    try:
        config = read_config_file(args.config) if args.config else {}
        table = round_trips(args.mesh, SolverSettings.from_config(config), args.c1,
                            args.observed, 1e-3 * args.tolerance_mm)
    except (FEError, OSError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    print(f"machine: {table.machine}")
    print(" | ".join(HEADER))
    for row in table_rows(table):
        print(" | ".join(row))
    if args.out is not None:
        table.write(args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
