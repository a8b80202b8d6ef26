"""Shared fixtures: one coarse parametric mesh and one small workflow run per test session."""

from __future__ import annotations

import fcntl
import json
import os
import re
import shutil
import subprocess
import sys
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
os.environ.setdefault("JAX_PLATFORMS", "cpu")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

COARSE = {"global_size": 0.03, "mound_size": 0.02, "order": 1}


#: Modules that take longest, or wait longest (the cluster's scheduler), in the order the
#: parallel suite starts them (``make test``: ``--dist loadscope --no-loadscope-reorder``), so
#: that the workers finish together; the workflow's module first, as it builds the small run
#: that later modules read (:func:`small_run`). The others follow in the order pytest finds them.
LONGEST_FIRST = (
    "test_workflow.py", "test_slurm.py", "test_probe_inputs.py", "test_patient_page.py",
    "test_self_contact.py",
    "test_reference.py", "test_workflow_safety.py", "test_viewer.py", "test_clinic_data.py",
    "test_fem_robustness.py",
    "test_surrogate.py", "test_sweep_workflow.py", "test_fem_mpi.py", "test_fem_solvers.py",
)


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """The longest modules first (:data:`LONGEST_FIRST`), each module's tests kept together."""
    rank = {name: i for i, name in enumerate(LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))


@pytest.fixture(autouse=True, scope="module")
def _free_solver_options() -> Iterator[None]:
    """After each test module, drop its solvers' entries from PETSc's options database.

    Every :class:`fem.solver.NewtonSolver` keeps its options there under its own prefix
    until it is destroyed, and the database holds 512 entries in all: a test session builds
    more solvers than that allows, and not every test closes its runner. No solver outlives
    its module (runner fixtures are module-scoped at most), so the prefix is cleared here.
    """
    yield
    if "petsc4py" not in sys.modules:
        return
    from petsc4py import PETSc

    from fem.solver import SOLVER_PREFIX

    options = PETSc.Options()
    for key in list(options.getAll()):
        if key.startswith(SOLVER_PREFIX):
            options.delValue(key)


def built_once(tmp_path_factory: pytest.TempPathFactory, name: str,
               build: Callable[[Path], None]) -> Path:
    """A folder that one process of the session builds and every other one reads.

    Under pytest-xdist each worker runs its own session fixtures; this gives them one folder
    in the session's shared temporary root, under a file lock: the first worker to take it
    calls ``build(folder)`` (recorded as built when it returns), the others wait for the lock
    and read what it built. A build that failed is retried by the next worker, which then
    fails the same way.
    """
    root = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        root = root.parent  # the session's root, above the workers' own
    folder, done = root / name, root / f"{name}.built"
    with open(root / f"{name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not done.exists():
            shutil.rmtree(folder, ignore_errors=True)
            folder.mkdir()
            build(folder)
            done.touch()
    return folder


@pytest.fixture(scope="session")
def coarse_mesh(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The default geometry on a coarse mesh (about 1,000 vertices), as XDMF (built once)."""
    from meshes.build import MeshSize, write_parametric_mesh
    from meshes.parametric import BreastGeometry

    def build(folder: Path) -> None:
        report = write_parametric_mesh(BreastGeometry(), MeshSize(**COARSE), folder / "mesh.xdmf")
        (folder / "quality.json").write_text(json.dumps(report))

    return built_once(tmp_path_factory, "mesh", build) / "mesh.xdmf"


@pytest.fixture(scope="session")
def curved_coarse_mesh(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The default geometry on the coarse mesh with curved (order-2) cells (built once)."""
    from meshes.build import MeshSize, write_parametric_mesh
    from meshes.parametric import BreastGeometry

    def build(folder: Path) -> None:
        write_parametric_mesh(BreastGeometry(), MeshSize(**{**COARSE, "order": 2}),
                              folder / "mesh.xdmf")

    return built_once(tmp_path_factory, "curved_mesh", build) / "mesh.xdmf"


def snakemake(
    workdir: Path,
    *args: str,
    config: Path | None = REPO / "tests" / "config.yaml",
    env: dict[str, str] | None = None,
    timeout: float | None = None,
) -> subprocess.CompletedProcess:
    """Run the project's Snakefile in ``workdir`` with the venv's Snakemake.

    ``config`` None runs on the working directory's ``config.yaml``, as a plain ``snakemake``
    does; ``env`` replaces the environment (e.g. a test cluster's), ``timeout`` bounds the run (s).
    """
    return subprocess.run(snakemake_command(workdir, *args, config=config), capture_output=True,
                          text=True, cwd=workdir, env=env, timeout=timeout)


def snakemake_command(
    workdir: Path, *args: str, config: Path | None = REPO / "tests" / "config.yaml"
) -> list[str]:
    """The command line :func:`snakemake` runs (for a test that starts it in the background)."""
    configfile = ["--configfile", str(config)] if config is not None else []
    return [sys.executable, "-m", "snakemake", "-s", str(REPO / "Snakefile"), "-d", str(workdir),
            *configfile, *args]


def job_counts(output: str) -> dict[str, int]:
    """Parse Snakemake's 'Job stats' table."""
    table = output.split("Job stats:")[1]
    return {m[1]: int(m[2]) for m in re.finditer(r"^(\w+)\s+(\d+)\s*$", table, re.M)}


@pytest.fixture(scope="session")
def small_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The whole workflow run once on tests/config.yaml; tests only read it.

    The target is ``all``: sweep, dataset, FE study, surrogate study, report. Built once
    for all the session's workers (:func:`built_once`).
    """
    def build(workdir: Path) -> None:
        run = snakemake(workdir, "-j2")
        assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-3000:]

    return built_once(tmp_path_factory, "workflow", build)
