"""Benchmark: points tracked from prone to supine by FE and by the surrogate.

    .venv/bin/python -m benchmarks.tracking_benchmark MESH --model MODEL [--config config.yaml]
        [--c1 1.0] [--points 100] [--observed 180] [--target 0] [--target-theta 0] [--seed 0]

``MESH`` is the reference the surrogate was trained on (the sweep's mesh). The imaged shape is
its FE solve in the observed posture; ``--points`` material points inside the breast (cell
centroids drawn at random) are seen there, then carried to the target posture by both paths of
:func:`studies.reference_state.tracking.track_both`. Prints the largest and mean FE-to-surrogate
distance, the
FE path's wall time and the surrogate query's median on one core, and where each point was.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark and print its figures."""
    from fem.case import CaseRunner
    from fem.configfile import read_config_file
    from fem.exceptions import InvalidParameterError
    from fem.io import node_displacement
    from fem.parameters import SolverSettings
    from fem.reference import write_reference_mesh
    from fem.sweep import Case
    from meshes.io import from_file_order, geometry_nodes, nodes_in_file_order
    from studies.reference_state.tracking import check_model_on, track_both
    from studies.timing_hygiene import machine_state
    from surrogate.predict import Surrogate

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("mesh", type=Path, help="the reference the model was trained on")
    parser.add_argument("--model", type=Path, required=True)
    parser.add_argument("--config", type=Path, help="solver settings (fe, material, mesh)")
    parser.add_argument("--c1", type=float, default=1.0, help="C1 in kPa")
    parser.add_argument("--points", type=int, default=100)
    parser.add_argument("--observed", type=float, default=180.0, help="imaged posture Φ")
    parser.add_argument("--target", type=float, default=0.0, help="target posture Φ")
    parser.add_argument("--target-theta", type=float, default=0.0,
                        help="target posture θ (e.g. standing: --target 90 --target-theta -90)")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    try:
        settings = SolverSettings.from_config(read_config_file(args.config) if args.config
                                              else {})
    except InvalidParameterError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    model = Surrogate.load(args.model)
    truth = CaseRunner(args.mesh, settings)
    check_model_on(model, truth.mesh)
    X = truth.mesh.geometry.x.copy()
    observed = Case(args.c1, args.observed)
    result, _ = truth.solve(observed)
    if not result.converged:
        print(f"error: the imaged posture did not converge: {result.reason}", file=sys.stderr)
        return 1
    x = X + node_displacement(truth.problem)
    nodes = geometry_nodes(truth.mesh)[:, :4]
    cells = np.random.default_rng(args.seed).choice(len(nodes), args.points, replace=False)
    seen = x[nodes[cells]].mean(axis=1)  # the cells' vertex centroids, as imaged
    names = [f"p{i}" for i in range(args.points)]
    with tempfile.TemporaryDirectory() as tmp:
        imaged = write_reference_mesh(truth, x, Path(tmp) / "imaged.xdmf")
        with CaseRunner(imaged, settings) as runner:
            # the truth's nodes in the imaged runner's order (the files share their numbering)
            X_imaged = from_file_order(runner.mesh, nodes_in_file_order(truth.mesh, X))
            tracked = track_both(runner, X_imaged, model, names, seen,
                                 Case(args.c1, args.target, args.target_theta), settings.density,
                                 settings.gravity)
    truth.close()
    d = np.asarray(tracked.difference_mm)
    moved = 1e3 * np.linalg.norm(np.asarray(tracked.fe) - np.asarray(tracked.observed), axis=1)
    t = tracked.surrogate_ms
    print(f"machine: {machine_state().to_json()}")
    to = f"Φ {args.target:g}°" + (f", θ {args.target_theta:g}°" if args.target_theta else "")
    print(f"{args.points} points, C1 = {args.c1:g} kPa, Φ {args.observed:g}° → {to}: "
          f"moved {moved.mean():.2f} mm on average (max {moved.max():.2f}); FE against "
          f"surrogate max {d.max():.3f} mm, mean {d.mean():.3f} mm, p95 "
          f"{np.percentile(d, 95):.3f} mm")
    print(f"FE path {tracked.fe_s:.2f} s (locate, solve, evaluate); surrogate query of the "
          f"{args.points} points: median {t['median_ms']:.4f} ms, p95 {t['p95_ms']:.4f} ms on "
          f"one core (core {tracked.machine['pinned_core']})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
