"""Benchmark: the sweep's chains with the skin membrane beside the same chains without it.

The same cases (every C1 of the config's sweep at a few gravity directions, each direction one
chain) are solved twice through the workflow, each in its own working directory by
``snakemake -j1 results/dataset/dataset.h5`` pinned to its own core (BLAS on one thread), at the
same time, as two jobs of ``snakemake -j2`` would run:

* homogeneous: the config as it is, ``material.skin`` removed;
* skin: the config with ``material.skin: {thickness: T}`` (the wrinkling membrane, the skin's
  ratio ``material.tissues.skin`` or its default, docs/tissues.md).

The cost of a path is the CPU time of its whole ``snakemake`` process tree (the kernel's count
for the finished child, so the other path's load does not enter it) divided by the number of
cases; beside it, each path's converged cases, Newton iterations and load steps per case, and
per case the ratio of max |u| with the skin to without. Running both at once on one machine
keeps what else ran the same for both: the ratio is the figure to read, the absolute times are
this machine's.

``python -m benchmarks.skin_sweep --config config.yaml [--phi 180 0 90 -90] [--theta 0 ...]
[--thickness 0.0015] [--out DIR]`` prints the table and writes ``DIR/skin_sweep.json``.
"""

from __future__ import annotations

import argparse
import copy
import logging
import statistics
import sys
import threading
from dataclasses import dataclass
from pathlib import Path

import yaml

from benchmarks.sweep_speed import case_summaries
from fem.materials import DEFAULT_SKIN_THICKNESS
from fem.sweep import Case
from studies.results import Record, Result
from studies.timing_hygiene import MachineState, machine_state, run_pinned

REPO = Path(__file__).resolve().parent.parent

log = logging.getLogger(__name__)

#: The directions of the default run: prone, supine, lying on the side and the other side.
DEFAULT_PHI = (180.0, 0.0, 90.0, -90.0)

#: What each path builds: the dataset (so every case, the mesh and the aggregation).
TARGET = "results/dataset/dataset.h5"

#: The two paths, and the core each is pinned to.
PATHS = {"homogeneous": 1, "skin": 0}


@dataclass(frozen=True, slots=True)
class PathCost(Record):
    """One path over the cases: its whole run's cost, and its cases' records."""

    name: str
    cases: int
    converged: int
    cpu_s: float
    wall_s: float
    cpu_per_case_s: float
    solve_cpu_per_case_s: float
    newton_iterations_per_case: float
    load_steps_per_case: float
    returncode: int


@dataclass(frozen=True, slots=True)
class CaseRatio(Record):
    """One case on both paths: its outcome and max |u| with the skin and without."""

    case: str
    homogeneous: str
    skin: str
    max_u_homogeneous_mm: float | None
    max_u_skin_mm: float | None
    newton_homogeneous: int | None
    newton_skin: int | None


@dataclass(frozen=True, slots=True)
class SkinSweep(Result):
    """The two paths side by side, and what the skin changes case by case."""

    directions: tuple[tuple[float, float], ...]
    c1_kpa: tuple[float, ...]
    thickness_m: float
    homogeneous: PathCost
    skin: PathCost
    cpu_ratio: float
    solve_cpu_ratio: float
    cases: tuple[CaseRatio, ...]
    failed: tuple[str, ...]
    machine_before: MachineState
    machine_after: MachineState


def _cost(name: str, run: tuple[float, float, int], summaries: dict[Case, dict],
          n: int) -> PathCost:
    wall, cpu, code = run
    done = list(summaries.values())
    return PathCost(
        name=name,
        cases=n,
        converged=sum(s["status"] == "converged" for s in done),
        cpu_s=cpu,
        wall_s=wall,
        cpu_per_case_s=cpu / n,
        solve_cpu_per_case_s=sum(s["cpu_s"]["solve"] for s in done) / n,
        newton_iterations_per_case=(
            statistics.fmean(s["total_newton_iterations"] for s in done) if done else 0.0),
        load_steps_per_case=(
            statistics.fmean(s["load_steps"] for s in done) if done else 0.0),
        returncode=code,
    )


def _max_u_mm(summary: dict | None) -> float | None:
    if not summary or summary["status"] != "converged":
        return None
    return float(summary["max_disp_mm"])


def _ratio(a: float, b: float) -> float:
    """The quotient a / b, NaN where a path solved nothing (its run stopped: see its run.log)."""
    return a / b if b > 0 else float("nan")


def path_config(config: dict, c1_values: list[float], directions: list[tuple[float, float]],
                skin: float | None) -> dict:
    """The config of one path: a fixed sweep of the cases, with or without the skin."""
    values = copy.deepcopy(config)
    phis = sorted({phi for phi, _ in directions})
    thetas = sorted({theta for _, theta in directions})
    values["sweep"] = {"C1_kPa": c1_values, "phi_deg": phis, "theta_deg": thetas,
                       "chains": True}
    material = values.setdefault("material", {})
    material.pop("skin", None)
    if skin is not None:
        material["skin"] = {"thickness": skin}
    return values


def run(config: dict, c1_values: list[float], directions: list[tuple[float, float]],
        thickness: float, out: Path) -> SkinSweep:
    """Run both paths at once, each pinned to its core, and compare them."""
    cases = [Case(c1, phi, theta) for phi, theta in directions for c1 in c1_values]
    runs: dict[str, tuple[float, float, int]] = {}
    folders = {name: out / name for name in PATHS}

    def path(name: str) -> None:
        workdir = folders[name]
        workdir.mkdir(parents=True, exist_ok=True)
        values = path_config(config, c1_values, directions,
                             thickness if name == "skin" else None)
        (workdir / "config.yaml").write_text(yaml.safe_dump(values))
        command = [sys.executable, "-m", "snakemake", "-s", str(REPO / "Snakefile"), "-d",
                   str(workdir), "--configfile", str(workdir / "config.yaml"), "-j1", TARGET]
        runs[name] = run_pinned(command, PATHS[name], workdir / "run.log", workdir)

    before = machine_state()
    threads = [threading.Thread(target=path, args=(name,)) for name in PATHS]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    after = machine_state()
    done = {name: case_summaries(folders[name], cases) for name in PATHS}
    costs = {name: _cost(name, runs[name], done[name], len(cases)) for name in PATHS}
    ratios = []
    for case in cases:
        row = {}
        for name in PATHS:
            summary = done[name].get(case)
            row[name] = summary["status"] if summary else "missing"
            row[f"max_u_{name}_mm"] = _max_u_mm(summary)
            row[f"newton_{name}"] = summary["total_newton_iterations"] if summary else None
        ratios.append(CaseRatio(case=case.id, **row))
    failed = sorted(f"{r.case}: {name} {getattr(r, name)}" for r in ratios for name in PATHS
                    if getattr(r, name) != "converged")
    homogeneous, skin = costs["homogeneous"], costs["skin"]
    return SkinSweep(
        directions=tuple(directions),
        c1_kpa=tuple(c1_values),
        thickness_m=thickness,
        homogeneous=homogeneous,
        skin=skin,
        cpu_ratio=_ratio(skin.cpu_per_case_s, homogeneous.cpu_per_case_s),
        solve_cpu_ratio=_ratio(skin.solve_cpu_per_case_s, homogeneous.solve_cpu_per_case_s),
        cases=tuple(ratios),
        failed=tuple(failed),
        machine_before=before,
        machine_after=after,
    )


def main(argv: list[str] | None = None) -> int:
    """Entry point (see the module docstring)."""
    from run.config import ConfigError, WorkflowConfig, read_config_file

    parser = argparse.ArgumentParser(prog="python -m benchmarks.skin_sweep",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("--config", type=Path, default=Path("config.yaml"))
    parser.add_argument("--phi", type=float, nargs="+", default=list(DEFAULT_PHI))
    parser.add_argument("--theta", type=float, nargs="+", default=[0.0],
                        help="θ (deg): every Φ is solved at every θ")
    parser.add_argument("--thickness", type=float, default=DEFAULT_SKIN_THICKNESS,
                        help="the skin membrane's thickness (m)")
    parser.add_argument("--out", type=Path, default=Path("results/benchmarks/skin_sweep"))
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    directions = [(phi, theta) for phi in args.phi for theta in args.theta]
    try:
        config = read_config_file(args.config)
        c1_values = sorted({case.C1 for case in WorkflowConfig.from_mapping(config).cases})
    except ConfigError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    result = run(config, c1_values, directions, args.thickness, args.out.resolve())
    result.write(args.out / "skin_sweep.json")
    print(f"{'path':<12}{'cases':>6}{'converged':>10}{'CPU/case s':>12}{'solve CPU/case':>15}"
          f"{'Newton/case':>12}{'steps/case':>11}")
    for cost in (result.homogeneous, result.skin):
        print(f"{cost.name:<12}{cost.cases:>6}{cost.converged:>10}{cost.cpu_per_case_s:>12.2f}"
              f"{cost.solve_cpu_per_case_s:>15.2f}{cost.newton_iterations_per_case:>12.1f}"
              f"{cost.load_steps_per_case:>11.2f}")
    print(f"CPU per case, skin / homogeneous: {result.cpu_ratio:.3f}; "
          f"solve CPU: {result.solve_cpu_ratio:.3f}")
    print(f"{'case':<34}{'max|u| homog.':>14}{'with skin':>11}{'ratio':>7}{'Newton':>9}")
    for row in result.cases:
        a, b = row.max_u_homogeneous_mm, row.max_u_skin_mm
        ratio = f"{b / a:7.3f}" if a and b else "      -"
        print(f"{row.case:<34}{a if a is not None else float('nan'):>14.2f}"
              f"{b if b is not None else float('nan'):>11.2f}{ratio}"
              f"{str(row.newton_homogeneous):>5}/{row.newton_skin}")
    print(f"failed: {', '.join(result.failed) or 'none'}")
    return 0 if result.homogeneous.returncode == result.skin.returncode == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
