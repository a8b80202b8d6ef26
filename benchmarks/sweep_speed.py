"""Benchmark: the sweep's chains beside the old path, both through the workflow, in one run.

The same cases (every C1 of the config's sweep at a few gravity directions) are solved twice,
each in its own working directory by ``snakemake -j1 results/dataset/dataset.h5`` pinned to its
own core (BLAS on one thread), at the same time, as two jobs of ``snakemake -j2`` would run:

* the old path, ``sweep.chains: false``: one job per case (Snakemake's script wrapper,
  interpreter, imports, form compilation and mesh read for every case), each from rest, the
  unit of cost measured in every summary;
* the chains, ``sweep.chains: true``: one job per direction, each case's load path from its
  stiffer neighbours, the unit measured once (:mod:`fem.chain`).

The cost of a path is the CPU time of its whole ``snakemake`` process tree (from the kernel's
accounting of the finished child, so the other path's load does not enter it): jobs, wrappers,
the DAG, the mesh and the dataset alike, divided by the number of cases. The answers of the two
are compared case by case at every material point.

``python -m benchmarks.sweep_speed --config config.yaml [--phi -120 0 90 180] [--out DIR]``
prints the table and writes ``DIR/sweep_speed.json``.
"""

from __future__ import annotations

import argparse
import json
import logging
import statistics
import sys
import threading
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from fem.case_files import read_points
from fem.sweep import Case
from studies.results import Record, Result
from studies.timing_hygiene import MachineState, machine_state, run_pinned

REPO = Path(__file__).resolve().parent.parent

log = logging.getLogger(__name__)

#: The directions of the default run: four of the paper's sixteen, soft and stiff alike
#: (−90°, whose softest case fails either way after a quarter of an hour, is left out).
DEFAULT_PHI = (-120.0, 0.0, 90.0, 180.0)

#: What each path builds: the dataset (so every case, the mesh and the aggregation).
TARGET = "results/dataset/dataset.h5"


@dataclass(frozen=True, slots=True)
class PathCost(Record):
    """One path over the cases: its whole run's cost, and its cases' records."""

    chains: bool
    cases: int
    converged: int
    cpu_s: float
    wall_s: float
    cpu_per_case_s: float
    wall_per_case_s: float
    solve_cpu_per_case_s: float
    newton_iterations_per_case: float
    returncode: int


@dataclass(frozen=True, slots=True)
class SweepSpeed(Result):
    """The two paths side by side, and how far their answers are apart."""

    directions: tuple[float, ...]
    c1_kpa: tuple[float, ...]
    old: PathCost
    new: PathCost
    cpu_ratio: float
    wall_ratio: float
    compared_cases: int
    max_difference_mm: float
    max_relative_difference: float
    failed: tuple[str, ...]
    machine_before: MachineState
    machine_after: MachineState


def case_summaries(workdir: Path, cases: list[Case]) -> dict[Case, dict]:
    """The ``summary.json`` of each of ``cases`` a run in ``workdir`` wrote, by case."""
    out = {}
    for case in cases:
        path = workdir / "results" / "cases" / case.id / "summary.json"
        if path.exists():
            out[case] = json.loads(path.read_text())
    return out


def _cost(chains: bool, run: tuple[float, float, int], summaries: dict[Case, dict],
          n: int) -> PathCost:
    wall, cpu, code = run
    done = list(summaries.values())
    return PathCost(
        chains=chains,
        cases=n,
        converged=sum(s["status"] == "converged" for s in done),
        cpu_s=cpu,
        wall_s=wall,
        cpu_per_case_s=cpu / n,
        wall_per_case_s=wall / n,
        solve_cpu_per_case_s=sum(s["cpu_s"]["solve"] for s in done) / n,
        newton_iterations_per_case=(
            statistics.fmean(s["total_newton_iterations"] for s in done) if done else 0.0),
        returncode=code,
    )


def run(config: dict, c1_values: list[float], directions: list[float], out: Path) -> SweepSpeed:
    """Run both paths at once (old on core 1, chains on core 0) and compare them."""
    cases = [Case(c1, phi) for phi in directions for c1 in c1_values]
    runs: dict[bool, tuple[float, float, int]] = {}
    folders = {chains: out / ("chains" if chains else "old") for chains in (True, False)}

    def path(chains: bool) -> None:
        workdir = folders[chains]
        workdir.mkdir(parents=True, exist_ok=True)
        values = {**config, "sweep": {"C1_kPa": c1_values, "phi_deg": directions,
                                      "theta_deg": [0.0], "chains": chains}}
        (workdir / "config.yaml").write_text(yaml.safe_dump(values))
        command = [sys.executable, "-m", "snakemake", "-s", str(REPO / "Snakefile"), "-d",
                   str(workdir), "--configfile", str(workdir / "config.yaml"), "-j1", TARGET]
        runs[chains] = run_pinned(command, 0 if chains else 1, workdir / "run.log", workdir)

    before = machine_state()
    threads = [threading.Thread(target=path, args=(chains,)) for chains in (False, True)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    after = machine_state()
    old_cases, new_cases = (case_summaries(folders[c], cases) for c in (False, True))
    old_cost = _cost(False, runs[False], old_cases, len(cases))
    new_cost = _cost(True, runs[True], new_cases, len(cases))
    diff, rel, compared = 0.0, 0.0, 0
    for case in cases:
        sa, sb = old_cases.get(case), new_cases.get(case)
        if not (sa and sb and sa["status"] == sb["status"] == "converged"):
            continue
        ua, ub = (read_points(folders[c] / "results/cases" / case.id / "points.h5")["u"]
                  for c in (False, True))
        d = float(np.linalg.norm(ua - ub, axis=1).max())
        diff = max(diff, 1e3 * d)
        rel = max(rel, d / float(np.linalg.norm(ua, axis=1).max()))
        compared += 1
    failed = sorted({f"{'chains' if c else 'old'}: {case.id}"
                     for c, done in ((False, old_cases), (True, new_cases))
                     for case, s in done.items() if s["status"] != "converged"})
    return SweepSpeed(
        directions=tuple(directions),
        c1_kpa=tuple(c1_values),
        old=old_cost,
        new=new_cost,
        cpu_ratio=new_cost.cpu_per_case_s / old_cost.cpu_per_case_s,
        wall_ratio=new_cost.wall_per_case_s / old_cost.wall_per_case_s,
        compared_cases=compared,
        max_difference_mm=diff,
        max_relative_difference=rel,
        failed=tuple(failed),
        machine_before=before,
        machine_after=after,
    )


def main(argv: list[str] | None = None) -> int:
    """Entry point (see the module docstring)."""
    from run.config import ConfigError, WorkflowConfig, read_config_file

    parser = argparse.ArgumentParser(prog="python -m benchmarks.sweep_speed",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("--config", type=Path, default=Path("config.yaml"))
    parser.add_argument("--phi", type=float, nargs="+", default=list(DEFAULT_PHI))
    parser.add_argument("--out", type=Path, default=Path("results/benchmarks/sweep_speed"))
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    try:
        config = read_config_file(args.config)
        cases = WorkflowConfig.from_mapping(config).cases
    except ConfigError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    c1_values = sorted({case.C1 for case in cases})
    result = run(config, c1_values, args.phi, args.out.resolve())
    result.write(args.out / "sweep_speed.json")
    print(f"{'path':<8}{'cases':>6}{'converged':>10}{'CPU/case s':>12}{'wall/case s':>12}"
          f"{'solve CPU/case':>15}{'Newton/case':>12}")
    for name, cost in (("old", result.old), ("chains", result.new)):
        print(f"{name:<8}{cost.cases:>6}{cost.converged:>10}{cost.cpu_per_case_s:>12.2f}"
              f"{cost.wall_per_case_s:>12.2f}{cost.solve_cpu_per_case_s:>15.2f}"
              f"{cost.newton_iterations_per_case:>12.1f}")
    print(f"CPU per case, chains / old: {result.cpu_ratio:.3f}; wall: {result.wall_ratio:.3f}")
    print(f"{result.compared_cases} cases in both: max difference {result.max_difference_mm:.2e} "
          f"mm ({result.max_relative_difference:.1e} of max |u|); failed: "
          f"{', '.join(result.failed) or 'none'}")
    return 0 if result.old.returncode == result.new.returncode == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
