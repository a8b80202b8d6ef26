"""Runs that cannot hurt each other or lose work: the run lock, killed reruns, config files, logs.

Each test runs the real Snakefile on a three-case sweep of tests/config.yaml in its own
working directory.
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

from fem.sweep import Case
from tests.conftest import REPO, job_counts, snakemake, snakemake_command

pytestmark = pytest.mark.workflow

DATASET = "results/dataset/dataset.h5"
CASE_FILES = ("summary.json", "points.h5", "fields.xdmf", "fields.h5")


def three_cases(folder: Path) -> Path:
    """tests/config.yaml with a sweep of three cases (C1 = 1 kPa at three angles).

    No clinical case: the by-case split would hold it out as test besides, and three cases
    are the fewest that fill the split's parts (the config check refuses fewer).
    """
    config = yaml.safe_load((REPO / "tests" / "config.yaml").read_text())
    config["sweep"] = {"C1_kPa": [1.0], "phi_deg": [0.0, 90.0, 180.0], "theta_deg": [0.0]}
    config["clinical"] = []
    path = folder / "three.yaml"
    path.write_text(yaml.safe_dump(config))
    return path


def case_folders(workdir: Path) -> list[Path]:
    return sorted((workdir / "results" / "cases").iterdir())


def solving(session: int) -> bool:
    """Whether a solve job runs in the process session ``session`` (a run started alone)."""
    found = subprocess.run(["pgrep", "-s", str(session), "-f", "solve_c(ase|hain)"],
                           capture_output=True, text=True)
    return found.returncode == 0


def wait_for(condition, timeout: float, what: str) -> None:
    end = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > end:
            raise AssertionError(f"timed out after {timeout} s waiting for {what}")
        time.sleep(0.05)


@pytest.fixture
def solved(tmp_path: Path) -> tuple[Path, Path]:
    """A working directory whose three-case dataset is built, and its config."""
    workdir = tmp_path / "run"
    workdir.mkdir()
    config = three_cases(tmp_path)
    run = snakemake(workdir, "-j2", DATASET, config=config)
    assert run.returncode == 0, run.stderr[-3000:]
    return workdir, config


def test_runs_in_one_directory_cannot_overlap_and_a_killed_rerun_loses_nothing(
    solved: tuple[Path, Path],
) -> None:
    """A second run is refused while one solves; a killed rerun leaves every case whole.

    The second run would delete the mesh; a dry run may look. The first is then killed
    mid-solve: every case folder is still whole (a rerun keeps a case's files until its new ones
    are in place), the next run needs no --unlock, and it solves the interrupted cases again and
    rebuilds the dataset.
    """
    workdir, config = solved
    before = [folder.name for folder in case_folders(workdir)]
    mesh = workdir / "results/mesh/mesh.xdmf"
    mesh_time = mesh.stat().st_mtime_ns
    # the first run solves with 40 fixed load steps: slow enough that the checks below fall
    # within its solves on any machine
    slow = config.with_name("slow.yaml")
    values = yaml.safe_load(config.read_text())
    values["fe"]["loading"] = {"fixed_steps": 40}
    slow.write_text(yaml.safe_dump(values))
    first = subprocess.Popen(
        snakemake_command(workdir, "-j1", "--forcerun", "solve_chain", "--", DATASET,
                          config=slow),
        cwd=workdir, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
        start_new_session=True,
    )
    try:
        incomplete = workdir / ".snakemake" / "incomplete"
        wait_for(lambda: incomplete.is_dir() and any(incomplete.iterdir()), 60,
                 "the first run's first solve job")
        # the second run and the dry run side by side
        second, look = (
            subprocess.Popen(snakemake_command(workdir, *args, config=slow), cwd=workdir,
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
            for args in (("-j1", "--forcerun", "mesh", "--", "results/mesh/mesh.xdmf"),
                         ("-n", DATASET))
        )
        second_err, look_err = second.communicate()[1], look.communicate()[1]
        assert first.poll() is None, "the first run ended before the test could kill it"
        assert second.returncode != 0
        assert "another run of the workflow is working in" in second_err
        assert f"pid {first.pid}" in second_err
        assert mesh.stat().st_mtime_ns == mesh_time
        assert look.returncode == 0, look_err[-3000:]
        # kill it mid-solve, not between two jobs
        wait_for(lambda: solving(first.pid) or first.poll() is not None, 60,
                 "a solve job of the first run")
        assert first.poll() is None, "the first run ended before the test could kill it"
    finally:
        os.killpg(first.pid, signal.SIGKILL)
        first.wait()
    for folder in case_folders(workdir):
        assert all((folder / name).is_file() for name in CASE_FILES), folder.name
        assert json.loads((folder / "summary.json").read_text())["status"] == "converged"
    assert (workdir / ".snakemake" / "locks").is_dir()  # the killed run's Snakemake locks
    plan = snakemake(workdir, "-n", DATASET, config=config)
    assert plan.returncode == 0, plan.stderr[-3000:]
    counts = job_counts(plan.stdout + plan.stderr)
    assert counts.get("aggregate") == 1 and counts.get("solve_chain", 0) >= 1
    again = snakemake(workdir, "-j2", DATASET, config=config)
    assert again.returncode == 0, again.stderr[-3000:]
    assert "cannot be locked" not in again.stderr
    assert [folder.name for folder in case_folders(workdir)] == before
    done = snakemake(workdir, "-n", DATASET, config=config)
    assert "Nothing to be done" in done.stdout + done.stderr


def test_a_failed_rerun_of_a_case_restores_its_files(solved: tuple[Path, Path]) -> None:
    """A case whose rerun fails (here its mesh is unreadable) keeps the files it had."""
    workdir, config = solved
    folder = case_folders(workdir)[0]
    before = {name: (folder / name).read_bytes() for name in CASE_FILES}
    mesh_h5 = workdir / "results/mesh/mesh.h5"
    mesh_h5.write_bytes(b"not an HDF5 file")
    target = f"results/cases/{folder.name}/summary.json"
    run = snakemake(workdir, "-j1", "--forcerun", "solve_chain", "--", target, config=config)
    assert run.returncode != 0 and "Restored previous version" in run.stdout + run.stderr
    assert {name: (folder / name).read_bytes() for name in CASE_FILES} == before
    case = Case.from_id(folder.name)
    log = workdir / "results/logs/solve_chain" / f"phi={case.phi:.1f}_theta={case.theta:.1f}.log"
    log = log.read_text()
    assert "the job failed" in log and "Traceback" in log


def test_a_failed_job_has_its_error_in_its_log(tmp_path: Path) -> None:
    """Snakemake points at the job's log: the error that ended the job is there."""
    config = yaml.safe_load((REPO / "tests" / "config.yaml").read_text())
    config["mesh"].update(
        source="file",
        file={"path": "empty.stl", "units": "mm",
              "surfaces": {"rib": {"plane": {"point": [0, 0, 0], "normal": [1, 0, 0]},
                                   "distance": 1.0}}},
    )
    config["mesh"]["size"]["fold_size"] = None
    del config["fe"]["contact"]
    (tmp_path / "empty.stl").write_text("solid empty\nendsolid empty\n")
    path = tmp_path / "import.yaml"
    path.write_text(yaml.safe_dump(config))
    run = snakemake(tmp_path, "-j1", "results/mesh/mesh.xdmf", config=path)
    assert run.returncode != 0
    log = (tmp_path / "results/logs/mesh.log").read_text()
    assert "the job failed: MeshInputError: empty.stl is empty" in log


def test_a_configfile_stands_alone(tmp_path: Path) -> None:
    """A config.yaml in the working directory is not merged under --configfile."""
    (tmp_path / "config.yaml").write_text(
        (REPO / "config.yaml").read_text() + "\nnot_a_key_of_the_schema: 1\n"
    )
    run = snakemake(tmp_path, "-n", "results/mesh/mesh.xdmf")
    assert run.returncode == 0, run.stderr[-3000:]
    alone = snakemake(tmp_path, "-n", "results/mesh/mesh.xdmf", config=None)
    assert alone.returncode != 0 and "not_a_key_of_the_schema" in alone.stdout + alone.stderr


def test_a_yaml_syntax_error_names_its_line(tmp_path: Path) -> None:
    """In config.yaml read by the Snakefile, and by the check that make reproduce runs first.

    Snakemake reads a --configfile itself, and reports a syntax error without its line.
    """
    text = (REPO / "tests" / "config.yaml").read_text().replace(
        "C1_kPa: [1.0, 5.0]", "C1_kPa: [1.0, 5.0"
    )
    line = 1 + text.splitlines().index("  C1_kPa: [1.0, 5.0")
    (tmp_path / "config.yaml").write_text(text)
    run = snakemake(tmp_path, "-n", config=None)
    assert run.returncode != 0
    assert f"config.yaml: YAML syntax error at line {line + 1}" in run.stdout + run.stderr
    check = subprocess.run(
        [str(REPO / ".venv/bin/python"), "-m", "run.config", "config.yaml"],
        cwd=tmp_path, capture_output=True, text=True,
    )
    assert check.returncode == 2 and f"YAML syntax error at line {line + 1}" in check.stderr
    assert not (tmp_path / "results").exists()


def test_the_default_profile_applies_to_a_plain_run(tmp_path: Path) -> None:
    run = snakemake(tmp_path, "-n", "results/mesh/mesh.xdmf")
    assert run.returncode == 0, run.stderr[-3000:]
    assert f"Using workflow specific profile {REPO / 'profiles' / 'default'}" in run.stderr
