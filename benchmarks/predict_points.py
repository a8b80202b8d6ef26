"""Benchmark: a surrogate asked at many named points from the command line, timed and weighed.

    .venv/bin/python -m benchmarks.predict_points MODEL [--points 1000000] [--c1 1] [--phi 0]

Draws ``--points`` material points inside the model's mesh (a random point of a random cell,
drawn towards its centroid so that it lies inside), writes them as a ``name,x,y,z`` CSV, and
runs ``python -m surrogate.cli predict MODEL --points CSV -o OUT`` in a fresh process as a user
would: reading the CSV, locating every point in its cell, one prediction, writing the moved
positions. Prints the command's wall time and peak resident memory (the child's maximum RSS,
which the kernel accounts), the points' largest displacement, and the machine.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from meshes.points import read_points, write_points
from studies.timing_hygiene import machine_state
from surrogate.checkpoint import load_checkpoint


def draw_points(model: str | Path, count: int, seed: int = 0) -> np.ndarray:
    """``count`` points (m) inside the model's mesh: random cells, random points in them."""
    c = load_checkpoint(model)
    if c.nodes is not None:
        X, cells = c.nodes.X, c.nodes.cells[:, :4]
    elif c.cells is not None:
        X, cells = c.X, c.cells
    else:
        raise ValueError(f"{model}: the model's dataset has no mesh cells to draw points in")
    rng = np.random.default_rng(seed)
    corners = X[cells[rng.integers(0, len(cells), count)]]
    centroids = corners.mean(axis=1)
    inside = np.einsum("mj,mjd->md", rng.dirichlet(np.ones(4), count), corners)
    return centroids + 0.9 * (inside - centroids)


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point; prints one JSON line of figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("model", help="the surrogate's model folder")
    parser.add_argument("--points", type=int, default=1_000_000, help="how many points")
    parser.add_argument("--c1", type=float, default=1.0, help="C1, kPa")
    parser.add_argument("--phi", type=float, default=0.0, help="gravity elevation Φ, degrees")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as folder:
        points, out = Path(folder) / "points.csv", Path(folder) / "moved.csv"
        X = draw_points(args.model, args.points)
        write_points(points, [f"p{i}" for i in range(len(X))], X)
        command = [sys.executable, "-m", "surrogate.cli", "predict", str(args.model),
                   "--c1", str(args.c1), "--phi", str(args.phi), "--points", str(points),
                   "-o", str(out)]
        start = time.perf_counter()
        run = subprocess.run(command, capture_output=True, text=True)
        wall = time.perf_counter() - start
        if run.returncode:
            print(run.stderr, file=sys.stderr)
            return run.returncode
        peak_gb = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss * 1024 / 1e9
        moved = read_points(out)[1]
    print(json.dumps({
        "points": len(X), "wall_s": round(wall, 2), "peak_rss_gb": round(peak_gb, 3),
        "max_displacement_mm": round(1e3 * float(np.linalg.norm(moved - X, axis=1).max()), 3),
        "said": run.stdout.strip().splitlines()[0], "machine": dataclasses.asdict(machine_state()),
    }))
    return 0


if __name__ == "__main__":
    sys.exit(main())
