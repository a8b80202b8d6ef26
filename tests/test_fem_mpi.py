"""The same case under ``mpirun -n 2`` gives the serial displacement to solver tolerance."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import REPO

pytestmark = pytest.mark.solve

MPIRUN = shutil.which("mpirun")


def _mpirun(nprocs: int, *args: str) -> subprocess.CompletedProcess:
    cmd = [MPIRUN, "-n", str(nprocs), "--allow-run-as-root", "--oversubscribe",
           sys.executable, "-m", "fem.cli", *args]
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
    return subprocess.run(cmd, capture_output=True, text=True, cwd=REPO, env=env, timeout=600)


@pytest.mark.skipif(MPIRUN is None, reason="mpirun is not installed")
@pytest.mark.parametrize("solver", ["direct", "iterative"])
def test_two_processes_give_the_serial_displacement(
    coarse_mesh: Path, tmp_path: Path, solver: str
) -> None:
    from fem.case import run_case
    from fem.case_files import read_points
    from fem.parameters import SolverSettings
    from fem.sweep import Case

    serial = run_case(
        coarse_mesh, Case(1.0, 180.0), tmp_path / "serial", SolverSettings(solver=solver)
    )
    run = _mpirun(
        2,
        str(coarse_mesh),
        "--c1",
        "1.0",
        "--phi",
        "180",
        "--solver",
        solver,
        "--out",
        str(tmp_path / "mpi"),
    )
    assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-2000:]
    summary = json.loads((tmp_path / "mpi" / "summary.json").read_text())
    assert summary["status"] == "converged" and summary["mpi_size"] == 2
    assert summary["self_overlap"] is None and serial["self_overlap"]["overlapping_vertices"] == 0
    a = read_points(tmp_path / "serial" / "points.h5")
    b = read_points(tmp_path / "mpi" / "points.h5")
    assert np.array_equal(a["node_index"], b["node_index"])
    assert np.array_equal(a["fixed"], b["fixed"])
    assert np.allclose(a["X"], b["X"], rtol=0, atol=1e-15)
    scale = np.abs(a["u"]).max()
    # Newton stops at a relative residual of 1e-7 after the same iterations: the two runs
    # differ only in round-off and in where each stops, far below that
    assert np.max(np.abs(a["u"] - b["u"])) <= 1e-7 * scale
    assert summary["max_disp_mm"] == pytest.approx(serial["max_disp_mm"], rel=1e-7)
    assert summary["volume_change"] == pytest.approx(0.0, abs=1e-10)


@pytest.mark.skipif(MPIRUN is None, reason="mpirun is not installed")
def test_two_processes_give_the_serial_contact(coarse_mesh: Path, tmp_path: Path) -> None:
    """With contact on and the mound resting on the chest, MPI changes nothing either."""
    from fem.case import run_case
    from fem.case_files import read_points
    from fem.parameters import SolverSettings
    from fem.sweep import Case

    config = {"fe": {"contact": {}}, "mesh": {"geometry": {}}}
    (tmp_path / "config.yaml").write_text(json.dumps(config))  # JSON is YAML
    settings = SolverSettings.from_config(config)
    serial = run_case(coarse_mesh, Case(0.6, 15.0), tmp_path / "serial", settings)
    run = _mpirun(
        2,
        str(coarse_mesh),
        "--c1",
        "0.6",
        "--phi",
        "15",
        "--config",
        str(tmp_path / "config.yaml"),
        "--out",
        str(tmp_path / "mpi"),
    )
    assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-2000:]
    summary = json.loads((tmp_path / "mpi" / "summary.json").read_text())
    assert summary["status"] == serial["status"] == "converged"
    a, b = serial["contact"], summary["contact"]
    assert a["vertices_in_contact"] > 0
    assert (b["vertices"], b["vertices_in_contact"]) == (a["vertices"], a["vertices_in_contact"])
    assert b["force_N"] == pytest.approx(a["force_N"], rel=1e-6)
    u_serial = read_points(tmp_path / "serial" / "points.h5")["u"]
    u_mpi = read_points(tmp_path / "mpi" / "points.h5")["u"]
    assert np.max(np.abs(u_serial - u_mpi)) <= 1e-7 * np.abs(u_serial).max()


@pytest.mark.skipif(MPIRUN is None, reason="mpirun is not installed")
def test_self_contact_under_mpi_is_refused_by_name(coarse_mesh: Path, tmp_path: Path) -> None:
    """Self-contact is serial: under mpirun the solve stops before any work, saying so."""
    (tmp_path / "config.yaml").write_text(json.dumps({"fe": {"self_contact": {}}}))
    run = _mpirun(2, str(coarse_mesh), "--c1", "1.0", "--phi", "180", "--config",
                  str(tmp_path / "config.yaml"), "--out", str(tmp_path / "mpi"))
    assert run.returncode == 2, run.stdout[-2000:] + run.stderr[-2000:]
    assert "fe.self_contact is serial" in run.stderr
    assert not (tmp_path / "mpi").exists()
