"""Shared fixtures: one coarse parametric mesh per test session."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
os.environ.setdefault("JAX_PLATFORMS", "cpu")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

COARSE = {"global_size": 0.03, "mound_size": 0.02, "order": 1}


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


@pytest.fixture(scope="session")
def coarse_mesh(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The default geometry on a coarse mesh (about 1,000 vertices), as XDMF."""
    from meshes.build import MeshSize, write_parametric_mesh
    from meshes.parametric import BreastGeometry

    folder = tmp_path_factory.mktemp("mesh")
    path = folder / "mesh.xdmf"
    report = write_parametric_mesh(BreastGeometry(), MeshSize(**COARSE), path)
    (folder / "quality.json").write_text(json.dumps(report))
    return path


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

    The target is ``all``: sweep, dataset, FE study, surrogate study, report.
    """
    workdir = tmp_path_factory.mktemp("workflow")
    run = snakemake(workdir, "-j2")
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-3000:]
    return workdir
