"""Benchmark: how many gravity directions a sweep needs, by the surrogate's error between them.

A sweep over the sphere of directions costs its number of directions times its C1 values, so
the number is chosen by what it buys: the surrogate's error at directions it never saw, beside
its error inside its own data. Each *design* (the paper's plane of 16 directions, and Fibonacci
lattices of n directions over the caudal half of the sphere, :func:`fem.sweep.sphere_directions`)
is solved at a few C1 values, a surrogate is trained on it with the config's settings (by-sample
split, as the workflow's model), and every design's model is asked about the same *test*
directions: seeded random directions over the caudal half, solved by FE at the same C1 values.

Per design the table gives the error inside its data and between its directions (mean, the
95th percentile of the cases' 95th percentiles, the largest point error; mm and relative to the
case's largest displacement, :class:`studies.surrogate_study.held_out.ErrorSpread`), the FE cost of
its cases,
and its training. The design is dense enough where the error between its directions is as
small as inside them.

Every case is solved by :func:`fem.chain.solve_chain` (a direction's C1 values in one chain) in
``--jobs`` processes, each on one BLAS thread, into ``OUT/cases/<case id>``; a case whose summary
is already there is not solved again, so an interrupted run resumes. Trainings run in the same
number of processes, one JAX thread each.

``python -m benchmarks.directions_needed --config config.yaml [--n 16 32 64] [--test 24]
[--c1 1 2 5] [--out DIR] [--jobs 2]`` prints the table and writes ``DIR/directions_needed.json``.
"""

from __future__ import annotations

import argparse
import json
import logging
import multiprocessing
import os
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from fem.sweep import PAPER_PHI_DEG, Case, sphere_directions
from studies.results import Record, Result
from studies.surrogate_study.errors_against_fe import CaseErrors, ErrorSpread
from studies.timing_hygiene import MachineState, machine_state

REPO = Path(__file__).resolve().parent.parent

log = logging.getLogger(__name__)

DEFAULT_N = (16, 32, 64)
DEFAULT_C1 = (1.0, 2.0, 5.0)
DEFAULT_TEST = 24


@dataclass(frozen=True, slots=True)
class Design(Record):
    """One sweep design: its FE cost, its model, and the model's errors.

    Attributes:
        name: ``plane`` (the paper's 16 angles) or ``caudal <n>``.
        directions: its number of gravity directions.
        cases: its FE cases (directions × C1 values).
        failed: its cases whose FE solve failed (left out of training).
        fe_cpu_s: the CPU time of its cases' solves, summed.
        validation_error_mm: the model's validation error (by-sample split).
        train_s: the model's training time.
        inside: the model over its own converged cases.
        between: the model at the test directions.
        between_rows: per test case.
    """

    name: str
    directions: int
    cases: int
    failed: list[str]
    fe_cpu_s: float
    validation_error_mm: float
    train_s: float
    inside: ErrorSpread
    between: ErrorSpread
    between_rows: list[CaseErrors]


@dataclass(frozen=True, slots=True)
class DirectionDensity(Result):
    """``directions_needed.json``: every design against the same test directions."""

    C1_kPa: list[float]
    test_directions: list[list[float]]
    test_failed: list[str]
    designs: list[Design]
    surrogate: dict[str, Any]
    wall_s: float
    machine: MachineState


def random_caudal_directions(n: int, seed: int = 0) -> list[tuple[float, float]]:
    """``n`` seeded random gravity directions, uniform over the caudal half of the sphere."""
    rng = np.random.default_rng(seed)
    g = rng.normal(size=(n, 3))
    g /= np.linalg.norm(g, axis=1, keepdims=True)
    g[:, 2] = -np.abs(g[:, 2])
    phi = np.degrees(np.arccos(np.clip(g[:, 0], -1.0, 1.0)))
    theta = np.degrees(np.arctan2(g[:, 2], g[:, 1]))
    return [(float(p), float(t)) for p, t in zip(phi, theta, strict=True)]


def designs(ns: tuple[int, ...]) -> dict[str, list[tuple[float, float]]]:
    """The paper's plane and a caudal lattice of each ``n``, as (Φ, θ) lists."""
    out = {"plane": [(float(p), 0.0) for p in PAPER_PHI_DEG]}
    out.update({f"caudal {n}": sphere_directions(n, "caudal") for n in ns})
    return out


def _solve_batch(mesh: str, cases: list[Case], root: str, fe: dict, material: dict,
                 fixed: Any) -> None:
    """One worker's chains (imports dolfinx here, after the parent set one BLAS thread)."""
    from fem.chain import solve_chain
    from fem.parameters import SolverSettings

    logging.basicConfig(level=logging.WARNING)
    settings = SolverSettings.from_config({"fe": fe, "material": material,
                                           "mesh": {"fixed": fixed}})
    solve_chain(mesh, cases, lambda case: Path(root) / case.id, settings)


def _train(dataset: str, folder: str, settings: dict) -> None:
    """One worker's training, on one JAX thread, saved into ``folder``."""
    from surrogate.runtime import configure_cpu

    configure_cpu(single_thread=True)
    from fem.dataset import read_dataset
    from surrogate.checkpoint import save_model
    from surrogate.config import SurrogateConfig
    from surrogate.train import train_and_evaluate

    ds = read_dataset(dataset)
    result = train_and_evaluate(ds, SurrogateConfig.from_mapping(settings), progress=False)
    save_model(folder, result, ds)


def _batches(cases: list[Case], jobs: int) -> list[list[Case]]:
    """Whole directions dealt round-robin to ``jobs`` batches."""
    by_direction: dict[tuple[float, float], list[Case]] = {}
    for case in cases:
        by_direction.setdefault((case.phi, case.theta), []).append(case)
    batches: list[list[Case]] = [[] for _ in range(jobs)]
    for i, key in enumerate(sorted(by_direction)):
        batches[i % jobs].extend(by_direction[key])
    return [b for b in batches if b]


def run(config_path: Path, ns: tuple[int, ...], n_test: int, c1: tuple[float, ...], out: Path,
        jobs: int = 2) -> DirectionDensity:
    """Solve, train and compare every design (see the module's docstring)."""
    from run.config import WorkflowConfig, read_config_file

    start = time.perf_counter()
    raw = read_config_file(config_path)
    config = WorkflowConfig.from_mapping(raw)
    out.mkdir(parents=True, exist_ok=True)
    (out / "config.yaml").write_text(yaml.safe_dump(raw))
    mesh = out / "results/mesh/mesh.xdmf"
    if not mesh.is_file():  # the config's mesh, built by the workflow's own rule
        subprocess.run([sys.executable, "-m", "snakemake", "-s", str(REPO / "Snakefile"), "-d",
                        str(out), "--configfile", str(out / "config.yaml"), "-j1",
                        "results/mesh/mesh.xdmf"], check=True, capture_output=True)
    plans = designs(ns)
    tests = random_caudal_directions(n_test)
    wanted = sorted({Case(C1, p, t) for dirs in [*plans.values(), tests] for p, t in dirs
                     for C1 in c1})
    root = out / "cases"
    todo = [case for case in wanted if not (root / case.id / "summary.json").is_file()]
    log.info("%d cases, %d to solve", len(wanted), len(todo))
    os.environ.update(OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    ctx = multiprocessing.get_context("spawn")
    with ctx.Pool(jobs) as pool:
        pool.starmap(_solve_batch, [
            (str(mesh), batch, str(root), config.solve_fe, config.section("material"),
             config.section("mesh", "fixed")) for batch in _batches(todo, jobs)])

    from fem.aggregate import build_dataset
    from fem.dataset import read_dataset

    def dataset(name: str, dirs: list[tuple[float, float]]) -> tuple[Path, list[Case]]:
        cases = sorted({Case(C1, p, t) for p, t in dirs for C1 in c1})
        path = out / "datasets" / f"{name.replace(' ', '_')}.h5"
        build_dataset([root / c.id / "summary.json" for c in cases],
                      [root / c.id / "points.h5" for c in cases], path)
        return path, cases

    built = {name: dataset(name, dirs) for name, dirs in plans.items()}
    test_path, _ = dataset("test", tests)
    settings = config.surrogate.as_dict()
    with ctx.Pool(jobs) as pool:
        pool.starmap(_train, [(str(path), str(out / "models" / name.replace(" ", "_")), settings)
                              for name, (path, _) in built.items()])

    from surrogate.runtime import configure_cpu

    configure_cpu()
    from surrogate.predict import Surrogate

    test_ds = read_dataset(test_path)
    test_cases = np.flatnonzero(test_ds.converged)
    results = []
    for name, (path, cases) in built.items():
        ds = read_dataset(path)
        model = Surrogate.load(out / "models" / name.replace(" ", "_"))
        card = json.loads((out / "models" / name.replace(" ", "_") / "model.json").read_text())
        cpu = [json.loads((root / c.id / "summary.json").read_text()).get("cpu_s", {})
               .get("solve", float("nan")) for c in cases]
        results.append(Design(
            name=name,
            directions=len(plans[name]),
            cases=len(cases),
            failed=[str(ds.ids[i]) for i in np.flatnonzero(~ds.converged)],
            fe_cpu_s=float(np.nansum(cpu)),
            validation_error_mm=float(card["metrics"]["validation_error_mm"]),
            train_s=float(card["metrics"]["train_s"]),
            inside=ErrorSpread.over([CaseErrors.of(model, ds, int(i))
                                     for i in np.flatnonzero(ds.converged)]),
            between=ErrorSpread.over(rows := [CaseErrors.of(model, test_ds, int(i))
                                              for i in test_cases]),
            between_rows=rows,
        ))
    return DirectionDensity(
        C1_kPa=[float(v) for v in c1],
        test_directions=[[p, t] for p, t in tests],
        test_failed=[str(test_ds.ids[i]) for i in np.flatnonzero(~test_ds.converged)],
        designs=results,
        surrogate=settings,
        wall_s=time.perf_counter() - start,
        machine=machine_state(),
    )


def table(result: DirectionDensity) -> str:
    """The designs as a plain-text table."""
    lines = [f"{'design':<12} {'dirs':>5} {'cases':>6} {'FE CPU s':>9} {'val mm':>7} "
             f"{'inside mean/p95/max mm':>24} {'between mean/p95/max mm':>25} {'max rel':>8}"]
    for d in result.designs:
        lines.append(
            f"{d.name:<12} {d.directions:>5} {d.cases:>6} {d.fe_cpu_s:>9.0f} "
            f"{d.validation_error_mm:>7.3f} "
            f"{d.inside.mean_mm:>8.3f}/{d.inside.p95_mm:.3f}/{d.inside.max_mm:.2f}   "
            f"{d.between.mean_mm:>8.3f}/{d.between.p95_mm:.3f}/{d.between.max_mm:.2f}   "
            f"{100 * d.between.relative_max:>6.2f} %")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Command line: see the module's docstring."""
    parser = argparse.ArgumentParser(prog="python -m benchmarks.directions_needed",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("--config", type=Path, default=REPO / "config.yaml")
    parser.add_argument("--n", type=int, nargs="+", default=list(DEFAULT_N),
                        help="directions of each caudal lattice")
    parser.add_argument("--test", type=int, default=DEFAULT_TEST, help="test directions")
    parser.add_argument("--c1", type=float, nargs="+", default=list(DEFAULT_C1), help="kPa")
    parser.add_argument("--out", type=Path, default=Path("results/benchmarks/directions_needed"))
    parser.add_argument("--jobs", type=int, default=2)
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    # killed, exit through the pools' context managers, which terminate their workers
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))
    result = run(args.config, tuple(args.n), args.test, tuple(args.c1), args.out, args.jobs)
    result.write(args.out / "directions_needed.json")
    print(table(result))
    print(f"wall {result.wall_s:.0f} s; {args.out / 'directions_needed.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
