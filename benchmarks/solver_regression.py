"""Benchmark: the default solver against its settings before the robustness changes, one run.

``python -m benchmarks.solver_regression MESH [--config config.yaml] [--repeats 2]``

The clinical cases of the config solved on ``MESH`` with the config's solver settings and with
the same settings put back as they were before issue 21 (:data:`BEFORE`: GMRES tested on the
preconditioned residual, no re-factorisation after a stalled Newton iteration, an absolute
force as Newton's absolute tolerance; the exact retry never triggers on cases that converge),
alternately case by case in one process pinned to one core, so that their ratio is free of the
machine's speed and load. Prints each solve, the total of each and their ratio, and the
largest difference of the displacements.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

from fem.configfile import read_config_file
from fem.exceptions import InvalidParameterError
from fem.parameters import SolverSettings
from fem.sweep import clinical_cases
from studies.timing_hygiene import machine_state, one_core

#: The ``direct`` preset's options before issue 21, as overrides of today's.
BEFORE = {"ksp_pc_side": "left", "refactor_above_ratio": 1.0, "load_atol": 0.0,
          "snes_atol": 1e-10}


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark and print its figures."""
    from fem.case import CaseRunner

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("mesh", type=Path)
    parser.add_argument("--config", type=Path, default=Path("config.yaml"))
    parser.add_argument("--repeats", type=int, default=2)
    args = parser.parse_args(argv)
    try:
        config = read_config_file(args.config)
        settings = SolverSettings.from_config(config)
    except InvalidParameterError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    cases = clinical_cases(config.get("clinical", []))
    print(f"machine before: {machine_state().to_json()}")
    with one_core() as core:
        runners = {
            "now": CaseRunner(args.mesh, settings),
            "before": CaseRunner(args.mesh, replace(
                settings, petsc_options={**settings.petsc_options, **BEFORE})),
        }
        total = {name: 0.0 for name in runners}
        largest = 0.0
        for repeat in range(args.repeats):
            order = list(runners) if repeat % 2 == 0 else list(reversed(runners))
            for case in cases:
                fields = {}
                for name in order:
                    result, timings = runners[name].solve(case)
                    total[name] += timings["solve"]
                    fields[name] = runners[name].problem.displacement().x.array.copy()
                    print(f"{name:<7} {case.id}: {result.reason}, Newton {result.newton_iterations}"
                          f", {timings['preconditioner_builds']} factorisations, "
                          f"{result.linear_iterations} Krylov, {timings['solve']:.2f} s",
                          flush=True)
                largest = max(largest, float(np.abs(fields["now"] - fields["before"]).max()))
    print(f"core {core}; total solve time now {total['now']:.1f} s, before "
          f"{total['before']:.1f} s: ratio now / before {total['now'] / total['before']:.3f}; "
          f"largest difference of the displacements {1e3 * largest:.2e} mm")
    print(f"machine after: {machine_state().to_json()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
