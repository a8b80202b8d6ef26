"""The adaptive sweep in the workflow: rounds as checkpoints, a killed run resumed, a case rerun.

Issue 71: killing the workflow mid-round and running again loses nothing and solves nothing
twice; a single case can still be rerun by its path. On the suite's coarse mesh, a start
design of 6 directions at 2 C1 values and rounds of 2 directions until a budget of 20 cases.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import time
from pathlib import Path

import pytest
import yaml

from fem.adaptive import RoundPlan
from fem.dataset import read_dataset
from tests.conftest import REPO, snakemake, snakemake_command

pytestmark = pytest.mark.workflow

DATASET = "results/dataset/dataset.h5"
SWEEP = {"C1_kPa": [1.0, 5.0], "phi_deg": [0.0, 90.0, 180.0], "theta_deg": [0.0],
         "sphere": {"n": 3, "part": "caudal"},
         # a target no estimate meets: the rounds end on the budget, 6 x 2 + 2 x (2 x 2)
         "adaptive": {"target_mm": 1e-6, "max_cases": 20, "per_round": 2}}


@pytest.fixture(scope="module")
def config(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """tests/config.yaml with the adaptive sweep above."""
    config = yaml.safe_load((REPO / "tests" / "config.yaml").read_text())
    config["sweep"] = SWEEP
    path = tmp_path_factory.mktemp("adaptive") / "adaptive.yaml"
    path.write_text(yaml.safe_dump(config))
    return path


def summaries(workdir: Path) -> dict[str, bytes]:
    """Every case's summary.json, by its path relative to the workdir."""
    return {str(p.relative_to(workdir)): p.read_bytes()
            for p in (workdir / "results" / "cases").glob("*/summary.json")}


def test_a_killed_adaptive_run_resumes_and_solves_nothing_finished_again(
        tmp_path: Path, config: Path) -> None:
    workdir = tmp_path / "run"
    workdir.mkdir()
    start = yaml.safe_load(config.read_text())
    first_round = workdir / "results" / "sweep" / "round_1.json"
    run = subprocess.Popen(snakemake_command(workdir, "-j1", "--rerun-incomplete", DATASET,
                                             config=config),
                           cwd=workdir, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                           start_new_session=True)
    try:
        # mid-round: round 1 planned, and one of its chains solved or solving
        deadline = time.monotonic() + 600
        while time.monotonic() < deadline and run.poll() is None:
            if first_round.is_file():
                added = RoundPlan.read(first_round).cases
                if any((workdir / "results" / "cases" / c / "summary.json").is_file()
                       for c in added):
                    break
            time.sleep(0.2)
        assert run.poll() is None, "the run ended before it could be killed mid-round"
        os.killpg(run.pid, signal.SIGKILL)
        run.wait()
    finally:
        if run.poll() is None:
            os.killpg(run.pid, signal.SIGKILL)
    assert start["sweep"]["adaptive"]["max_cases"] == 20
    plan_before = first_round.read_bytes()
    # a direction's chain is one job: finished where every C1 value of it is written (the one
    # that was running when the run was killed is solved again, as any running job is)
    written = summaries(workdir)
    by_direction: dict[str, list[str]] = {}
    for path in written:
        by_direction.setdefault(path.split("_", 1)[1], []).append(path)
    finished = {path: written[path] for paths in by_direction.values()
                if len(paths) == len(SWEEP["C1_kPa"]) for path in paths}
    assert len(finished) >= 12  # the start design, at least

    resumed = snakemake(workdir, "-j2", "--rerun-incomplete", DATASET, "results/sweep/rounds.json",
                        config=config)
    assert resumed.returncode == 0, resumed.stdout[-3000:] + resumed.stderr[-3000:]
    # nothing finished was solved again, the plan was not made again
    assert first_round.read_bytes() == plan_before
    after = summaries(workdir)
    assert {path: after[path] for path in finished} == finished
    rounds = json.loads((workdir / "results" / "sweep" / "rounds.json").read_text())
    assert [r["reason"] for r in rounds["rounds"]] == ["adding", "adding", "budget spent"]
    planned = {c for r in rounds["rounds"] for c in r["cases"]}
    ds = read_dataset(workdir / DATASET)
    assert len(ds.ids) == 20 and planned <= set(ds.ids)
    assert len(after) == 20

    # one case rerun by its path: its direction's chain, nothing else
    case = sorted(planned)[0]
    again = snakemake(workdir, "-j1", "-f", f"results/cases/{case}/summary.json", config=config)
    assert again.returncode == 0, again.stdout[-3000:] + again.stderr[-3000:]
    rerun = summaries(workdir)
    changed = {path for path in rerun if rerun[path] != after[path]}
    assert f"results/cases/{case}/summary.json" in changed
    assert len(changed) == 2  # the two C1 values of its chain
    assert first_round.read_bytes() == plan_before


def test_the_small_run_checks_its_estimate_and_reports_its_fixed_design(small_run: Path) -> None:
    """The suite's shared run (a fixed design) writes the estimate check and the section."""
    from studies.sweep.sweep_estimate import ESTIMATORS, SweepEstimateCheck

    check = SweepEstimateCheck.read(small_run / "results" / "sweep" / "estimate.json")
    assert check.chosen == ESTIMATORS[0]
    assert {row.set for row in check.rows} <= {"off_grid", "by_direction", "by_case"}
    assert all(set(row.estimates) == set(ESTIMATORS) for row in check.rows)
    assert all(row.true_mm >= 0 and row.interpolant_mm >= 0 for row in check.rows)
    html = (small_run / "results" / "report" / "index.html").read_text()
    assert "How the sweep chose its cases" in html
    assert "fixed design" in html
    assert not (small_run / "results" / "sweep" / "rounds.json").exists()
