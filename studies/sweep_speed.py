"""Benchmark: the sweep's chains beside the old path, in one run.

The old path is one process per case (``python -m fem.cli``): interpreter, imports, form
compilation and mesh read for every case, each case from rest, and the unit of cost measured
in every summary. The new path is one process per gravity direction (``python -m fem.chain``):
the direction's cases stiffest first, each from its neighbours' solutions, the unit measured
once. Both run at the same time, each pinned to its own core (BLAS on one thread), as two
jobs of ``snakemake -j2`` would; CPU seconds come from each child's own resource usage, so
the other path's load does not enter them.

The chains solve every C1 of each direction (a chain is only as good as its neighbours);
the old path, which gains nothing from neighbours, solves every ``old_every``-th of them,
soft and stiff alike, so that its mean per case estimates the mean over all. The cases both
paths solved are compared point by point.

``python -m studies.sweep_speed MESH --config config.yaml [--phi -90 0 90 180] [--old-every 3]
[--out DIR]`` prints the table and writes ``DIR/sweep_speed.json``.
"""

from __future__ import annotations

import argparse
import logging
import os
import statistics
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fem.dataset import read_points
from fem.sweep import Case
from studies.machine import MachineState, machine_state
from studies.results import Record, Result

log = logging.getLogger(__name__)

#: The directions of the default run: the soft side-lying one, supine, the other side, prone.
DEFAULT_PHI = (-90.0, 0.0, 90.0, 180.0)


@dataclass(frozen=True, slots=True)
class Process(Record):
    """One child process: what it solved and what it cost."""

    cases: tuple[str, ...]
    wall_s: float
    cpu_s: float
    returncode: int


@dataclass(frozen=True, slots=True)
class PathCost(Record):
    """One path over its cases."""

    cases: int
    converged: int
    cpu_s: float
    wall_s: float
    cpu_per_case_s: float
    wall_per_case_s: float
    median_process_cpu_s: float
    newton_iterations_per_case: float


@dataclass(frozen=True, slots=True)
class SweepSpeed(Result):
    """The two paths side by side, and how far their answers are apart."""

    mesh: str
    directions: tuple[float, ...]
    c1_kpa: tuple[float, ...]
    old: PathCost
    new: PathCost
    cpu_ratio: float
    wall_ratio: float
    compared_cases: int
    max_difference_mm: float
    max_relative_difference: float
    machine_before: MachineState
    machine_after: MachineState


def _run(command: list[str], core: int) -> tuple[float, float, int]:
    """Run ``command`` pinned to ``core``; its wall seconds, CPU seconds and exit status."""
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
    start = time.perf_counter()
    proc = subprocess.Popen(["taskset", "-c", str(core), *command], env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - start
    proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode != 0:
        log.warning("%s failed: %s", " ".join(command[:4]),
                    proc.stderr.read().decode(errors="replace")[-2000:] if proc.stderr else "")
    return wall, usage.ru_utime + usage.ru_stime, proc.returncode


def _cost(processes: list[Process], folder: Path) -> PathCost:
    summaries = [_summary(folder / case) for p in processes for case in p.cases]
    done = [s for s in summaries if s is not None]
    n = sum(len(p.cases) for p in processes)
    cpu = sum(p.cpu_s for p in processes)
    wall = sum(p.wall_s for p in processes)
    return PathCost(
        cases=n,
        converged=sum(s["status"] == "converged" for s in done),
        cpu_s=cpu,
        wall_s=wall,
        cpu_per_case_s=cpu / n,
        wall_per_case_s=wall / n,
        median_process_cpu_s=statistics.median(p.cpu_s for p in processes),
        newton_iterations_per_case=(
            statistics.fmean(s["total_newton_iterations"] for s in done) if done else 0.0),
    )


def _summary(folder: Path) -> dict | None:
    import json

    path = folder / "summary.json"
    return json.loads(path.read_text()) if path.exists() else None


def run(
    mesh: Path,
    config: Path,
    c1_values: list[float],
    directions: list[float],
    old_every: int,
    out: Path,
) -> SweepSpeed:
    """Run both paths at once (old on core 1, chains on core 0) and compare them."""
    python = sys.executable
    old_cases = [Case(c1, phi) for phi in directions for c1 in c1_values[::old_every]]
    new_dir, old_dir = out / "chains", out / "old"
    old: list[Process] = []
    new: list[Process] = []

    def old_path() -> None:
        for case in old_cases:
            cmd = [python, "-m", "fem.cli", str(mesh), "--c1", str(case.C1), "--phi",
                   str(case.phi), "--out", str(old_dir / case.id), "--config", str(config)]
            old.append(Process((case.id,), *_run(cmd, 1)))

    def new_path() -> None:
        for phi in directions:
            cmd = [python, "-m", "fem.chain", str(mesh), "--c1", *map(str, c1_values), "--phi",
                   str(phi), "--cases", str(new_dir), "--config", str(config)]
            ids = tuple(Case(c1, phi).id for c1 in c1_values)
            new.append(Process(ids, *_run(cmd, 0)))

    before = machine_state()
    threads = [threading.Thread(target=old_path), threading.Thread(target=new_path)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    after = machine_state()
    old_cost, new_cost = _cost(old, old_dir), _cost(new, new_dir)
    diff, rel, compared = 0.0, 0.0, 0
    for case in old_cases:
        a, b = old_dir / case.id / "points.h5", new_dir / case.id / "points.h5"
        sa, sb = _summary(old_dir / case.id), _summary(new_dir / case.id)
        if not (sa and sb and sa["status"] == sb["status"] == "converged"):
            continue
        ua, ub = read_points(a)["u"], read_points(b)["u"]
        d = float(np.linalg.norm(ua - ub, axis=1).max())
        diff = max(diff, 1e3 * d)
        rel = max(rel, d / float(np.linalg.norm(ua, axis=1).max()))
        compared += 1
    return SweepSpeed(
        mesh=str(mesh),
        directions=tuple(directions),
        c1_kpa=tuple(c1_values),
        old=old_cost,
        new=new_cost,
        cpu_ratio=new_cost.cpu_per_case_s / old_cost.cpu_per_case_s,
        wall_ratio=new_cost.wall_per_case_s / old_cost.wall_per_case_s,
        compared_cases=compared,
        max_difference_mm=diff,
        max_relative_difference=rel,
        machine_before=before,
        machine_after=after,
    )


def main(argv: list[str] | None = None) -> int:
    """Entry point (see the module docstring)."""
    from studies.config import WorkflowConfig, read_config_file

    parser = argparse.ArgumentParser(prog="python -m studies.sweep_speed",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("mesh", type=Path, help="the sweep's mesh (results/mesh/mesh.xdmf)")
    parser.add_argument("--config", type=Path, default=Path("config.yaml"))
    parser.add_argument("--phi", type=float, nargs="+", default=list(DEFAULT_PHI))
    parser.add_argument("--old-every", type=int, default=3,
                        help="the old path solves every k-th C1 of the sweep")
    parser.add_argument("--out", type=Path, default=Path("results/benchmarks/sweep_speed"))
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    cases = WorkflowConfig.from_mapping(read_config_file(args.config)).cases
    c1_values = sorted({case.C1 for case in cases}, reverse=True)
    result = run(args.mesh, args.config, c1_values, args.phi, args.old_every, args.out)
    result.write(args.out / "sweep_speed.json")
    print(f"{'path':<8}{'cases':>6}{'converged':>10}{'CPU/case s':>12}{'wall/case s':>12}"
          f"{'Newton/case':>12}")
    for name, cost in (("old", result.old), ("chains", result.new)):
        print(f"{name:<8}{cost.cases:>6}{cost.converged:>10}{cost.cpu_per_case_s:>12.2f}"
              f"{cost.wall_per_case_s:>12.2f}{cost.newton_iterations_per_case:>12.1f}")
    print(f"CPU per case, chains / old: {result.cpu_ratio:.3f}; wall: {result.wall_ratio:.3f}")
    print(f"{result.compared_cases} cases in both: max difference {result.max_difference_mm:.2e} "
          f"mm ({result.max_relative_difference:.1e} of max |u|)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
