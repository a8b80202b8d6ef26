"""Benchmark: the reference state's round trip, beside the naive supine prediction.

``python -m studies.reference_roundtrip MESH [--config config.yaml] [--c1 1 2 5]
[--observed 180 0 60]``

For each C1 and each posture Φ of the observation: solve from the mesh (the true reference)
to get the observed shape; estimate the reference from it
(:func:`fem.reference.estimate_reference`);
report the largest node distance to the truth (mm and % of the observation's max |u|), the
supine (Φ = 0, or prone Φ = 180 for a supine observation) shape predicted from the estimate
against the one from the truth, the same prediction made from the observed shape taken as
stress-free (the naive way), and the estimate's wall time over one cold forward solve of the
observed case measured in the same process just before it.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
import yaml

from fem.parameters import SolverSettings
from fem.sweep import Case
from studies.machine import machine_state


def main(argv: list[str] | None = None) -> int:
    """Run the round trips and print one row each."""
    from fem.case import CaseRunner
    from fem.reference import estimate_reference, node_dofs

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("mesh", type=Path)
    parser.add_argument("--config", type=Path, help="solver settings (fe, material, mesh)")
    parser.add_argument("--c1", type=float, nargs="+", default=[1.0, 2.0, 5.0])
    parser.add_argument("--observed", type=float, nargs="+", default=[180.0, 0.0, 60.0])
    args = parser.parse_args(argv)
    config = yaml.safe_load(args.config.read_text()) if args.config else {}
    runner = CaseRunner(args.mesh, SolverSettings.from_config(config or {}))
    X = runner.mesh.geometry.x.copy()
    dofs = None

    def deformed(case: Case, reference: np.ndarray) -> tuple[np.ndarray, float]:
        nonlocal dofs
        runner.problem.set_geometry(reference)
        start = time.perf_counter()
        result, _ = runner.solve(case)
        elapsed = time.perf_counter() - start
        if not result.converged:
            raise RuntimeError(f"{case.id} from the reference did not converge: {result.reason}")
        u = runner.problem.displacement()
        if dofs is None:
            dofs = node_dofs(runner.mesh, u.function_space)
        return reference + u.x.array.reshape(-1, 3)[dofs], elapsed

    print(f"machine: {machine_state().to_json()}")
    print(f"{'C1':>4} {'obs Φ':>6} {'target Φ':>8} {'max|u| mm':>9} {'ref err mm':>10} {'%':>6} "
          f"{'target err mm':>13} {'%':>6} {'naive err mm':>12} {'solves':>6} {'cost':>5}")
    for c1 in args.c1:
        for phi in args.observed:
            observed_case = Case(c1, phi)
            target = Case(c1, 180.0 if phi == 0.0 else 0.0)
            x, cold = deformed(observed_case, X)
            runner.problem.set_geometry(x)
            estimate = estimate_reference(runner, observed_case.material(),
                                          observed_case.gravity())
            sag = float(np.linalg.norm(x - X, axis=1).max())
            error = float(np.linalg.norm(estimate.X - X, axis=1).max())
            truth, _ = deformed(target, X)
            proper, _ = deformed(target, estimate.X)
            naive, _ = deformed(target, x)
            target_sag = float(np.linalg.norm(truth - X, axis=1).max())
            e_proper = float(np.linalg.norm(proper - truth, axis=1).max())
            e_naive = float(np.linalg.norm(naive - truth, axis=1).max())
            print(f"{c1:>4g} {phi:>6g} {target.phi:>8g} {1e3 * sag:>9.2f} {1e3 * error:>10.4f} "
                  f"{100 * error / sag:>6.3f} {1e3 * e_proper:>13.4f} "
                  f"{100 * e_proper / target_sag:>6.3f} {1e3 * e_naive:>12.2f} "
                  f"{estimate.forward_solves:>6d} {estimate.wall_s / cold:>5.2f}"
                  + ("" if estimate.converged else f"  FAILED: {estimate.reason}"), flush=True)
    runner.problem.set_geometry(X)
    return 0


if __name__ == "__main__":
    sys.exit(main())
