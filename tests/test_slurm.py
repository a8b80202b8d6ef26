"""The SLURM profile against a real single-node cluster started by the test.

munged, slurmctld and slurmd (Debian's slurm-wlm 22.05) run as root on localhost with a
private key, socket, ports and spool folder, so nothing outside the temporary folder is
touched. Accounting is off (no slurmdbd), so job status comes from ``squeue``, which is what
``profiles/slurm`` selects.
"""

from __future__ import annotations

import os
import shutil
import socket
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path

import h5py
import numpy as np
import pytest

from tests.conftest import REPO, snakemake

pytestmark = pytest.mark.cluster

DAEMONS = ("munged", "slurmctld", "slurmd")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _mem_mb() -> int:
    with open("/proc/meminfo") as fh:
        total_kb = int(next(line for line in fh if line.startswith("MemTotal")).split()[1])
    return int(total_kb / 1024 * 0.8)


def _slurm_conf(root: Path) -> str:
    return f"""ClusterName=breasttest
SlurmctldHost=localhost
AuthType=auth/munge
AuthInfo=socket={root}/munge/munge.socket
CredType=cred/munge
SlurmUser=root
SlurmdUser=root
SlurmctldPort={_free_port()}
SlurmdPort={_free_port()}
SlurmctldPidFile={root}/slurmctld.pid
SlurmdPidFile={root}/slurmd.pid
SlurmdSpoolDir={root}/spool
StateSaveLocation={root}/state
SlurmctldLogFile={root}/log/slurmctld.log
SlurmdLogFile={root}/log/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core_Memory
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
JobAcctGatherType=jobacct_gather/none
# Open MPI (dolfinx's) needs PMIx from srun, or MPI_Init aborts in every job.
MpiDefault=pmix
MinJobAge=600
ReturnToService=2
NodeName=localhost CPUs={os.cpu_count()} RealMemory={_mem_mb()} State=UNKNOWN
PartitionName=main Nodes=localhost Default=YES MaxTime=INFINITE State=UP
"""


@pytest.fixture(scope="module")
def slurm_cluster(tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict[str, str]]:
    """Start munge + slurmctld + slurmd; yield the environment that points clients at them."""
    missing = [d for d in (*DAEMONS, "sbatch", "squeue") if shutil.which(d) is None
               and not Path(f"/usr/sbin/{d}").exists()]
    if missing or os.geteuid() != 0:
        pytest.skip(f"needs root and slurm-wlm + munge (missing: {missing or 'root'}); "
                    "`make setup` installs them")
    root = tmp_path_factory.mktemp("slurm")
    for sub in ("munge", "spool", "state", "log"):
        (root / sub).mkdir()
    (root / "munge").chmod(0o700)
    subprocess.run(
        ["/usr/sbin/mungekey", "-c", "-f", "-k", str(root / "munge/munge.key")], check=True
    )
    conf = root / "slurm.conf"
    conf.write_text(_slurm_conf(root))
    env = {**os.environ, "SLURM_CONF": str(conf)}
    subprocess.run(
        [
            "/usr/sbin/munged",
            "--force",
            f"--key-file={root}/munge/munge.key",
            f"--socket={root}/munge/munge.socket",
            f"--pid-file={root}/munge/munged.pid",
            f"--log-file={root}/log/munged.log",
            f"--seed-file={root}/munge/munged.seed",
        ],
        check=True,
    )
    subprocess.run(["/usr/sbin/slurmctld", "-f", str(conf)], check=True, env=env)
    subprocess.run(["/usr/sbin/slurmd", "-f", str(conf)], check=True, env=env)
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            state = subprocess.run(
                ["sinfo", "-h", "-o", "%T"], capture_output=True, text=True, env=env
            )
            if state.stdout.strip() == "idle":
                break
            time.sleep(0.5)
        else:
            pytest.fail(
                "the test cluster did not come up: "
                f"{(root / 'log/slurmctld.log').read_text()[-2000:]}"
            )
        yield env
    finally:
        for pidfile in (root / "slurmd.pid", root / "slurmctld.pid", root / "munge/munged.pid"):
            if pidfile.exists():
                try:
                    os.kill(int(pidfile.read_text().strip()), 15)
                except (ProcessLookupError, ValueError):
                    pass


def test_small_sweep_runs_through_slurm(slurm_cluster: dict[str, str], tmp_path: Path) -> None:
    run = snakemake(
        tmp_path,
        "--workflow-profile",
        str(REPO / "profiles/slurm"),
        # poll sooner than a real cluster needs, to keep the test short
        "--slurm-init-seconds-before-status-checks",
        "2",
        "--seconds-between-status-checks",
        "1",
        "results/dataset/dataset.h5",
        env=slurm_cluster,
        timeout=900,
    )
    assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-4000:]
    # every job really went through the scheduler: mesh + 3 chains (6 cases) + aggregate
    states = subprocess.run(
        ["squeue", "--states=all", "-h", "-o", "%T"],
        capture_output=True,
        text=True,
        env=slurm_cluster,
    ).stdout.split()
    assert states.count("COMPLETED") == 5, states
    with h5py.File(tmp_path / "results/dataset/dataset.h5") as h5:
        assert h5["displacement"].shape[0] == 6
        assert np.all(h5["cases/converged"][...])
