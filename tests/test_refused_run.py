"""A run refused by the working directory's run lock leaves the running run alone (issue 70).

A second ``make reproduce`` where one works is refused; it used to leave its own Snakemake log
behind (the running run's ``first_report`` then took it for its own and failed: "no job in this
Snakemake log") and, stopped inside Snakemake's own lock, to remove the lock folder and the
running run's locks with it. Here this process holds the lock, as a running run does.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from run.run_log import newest_log, run_time
from run.workdir import RunLock
from tests.conftest import snakemake
from tests.test_run_log import LOG

pytestmark = pytest.mark.workflow

MESH = "results/mesh/mesh.xdmf"


def files(folder: Path) -> dict[str, tuple[bytes, int]]:
    """Every file under ``folder``: its bytes and modification time."""
    return {str(p.relative_to(folder)): (p.read_bytes(), p.stat().st_mtime_ns)
            for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.fixture
def running(tmp_path: Path) -> Path:
    """A working directory where a run works: its lock held, its run log, its Snakemake locks."""
    workdir = tmp_path / "run"
    log = workdir / ".snakemake" / "log" / "2026-11-29T012950.000000.snakemake.log"
    log.parent.mkdir(parents=True)
    log.write_text(LOG)
    locks = workdir / ".snakemake" / "locks"
    locks.mkdir()
    # files apart from the refused run's: Snakemake's own lock check lets that run go on
    (locks / "0.input.lock").write_text(f"{workdir}/results/cases/c1=1.00_phi=0.0_theta=0.0/"
                                        "summary.json\n")
    (locks / "0.output.lock").write_text(f"{workdir}/results/dataset/dataset.h5\n")
    return workdir


def test_a_refused_run_writes_nothing_in_the_working_directory(running: Path) -> None:
    lock = RunLock(running)
    assert lock.acquire()
    before = files(running)
    refused = snakemake(running, "-j1", "--forcerun", "mesh", "--", MESH)
    assert refused.returncode != 0
    assert "another run of the workflow is working in" in refused.stderr
    after = files(running)
    assert [k for k in after if "/log/" in k] == [k for k in before if "/log/" in k]
    assert [k for k in after if "/locks/" in k] == [k for k in before if "/locks/" in k]
    assert after == before
    assert run_time(newest_log(running)).finished == 4  # the running run's log is still newest


def test_a_dry_run_beside_a_running_one_looks_without_a_log(running: Path) -> None:
    lock = RunLock(running)
    assert lock.acquire()
    logs_and_locks = {k: v for k, v in files(running).items() if "/iocache/" not in k}
    look = snakemake(running, "-n", MESH)
    assert look.returncode == 0, look.stderr[-2000:]
    assert "another run of the workflow is working in" in look.stdout + look.stderr
    # (a dry run keeps Snakemake's I/O cache, read only with --trust-io-cache)
    assert {k: v for k, v in files(running).items() if "/iocache/" not in k} == logs_and_locks
