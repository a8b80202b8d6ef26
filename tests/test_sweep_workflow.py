"""The sweep as a user drives it: resume after SIGKILL, and rerun only what a change touches."""

from __future__ import annotations

import os
import signal
import subprocess
import tempfile
import time
from base64 import urlsafe_b64decode
from pathlib import Path

import h5py
import numpy as np
import pytest
import yaml

from tests.conftest import REPO, job_counts, snakemake

pytestmark = pytest.mark.workflow

# Twelve quick cases on the coarse test mesh.
KILL_CONFIG = {
    "mesh": {"source": "parametric", "size": {"global_size": 0.03, "mound_size": 0.02}},
    "sweep": {"C1_kPa": [1.0, 2.0, 3.0, 4.0], "phi_deg": [0.0, 90.0, 180.0]},
    "clinical": [],
}


def make_reproduce(workdir: Path, config: Path, *targets: str, **popen) -> subprocess.Popen:
    """Start the README's reproduce command on ``workdir``."""
    cmd = ["make", "-s", "-C", str(REPO), "reproduce", f"WORKDIR={workdir}", f"CONFIG={config}",
           f"SNAKEMAKE_ARGS={' '.join(targets)}"]
    popen.setdefault("stdout", subprocess.PIPE)
    return subprocess.Popen(cmd, stderr=subprocess.STDOUT, text=True, **popen)


def finished_cases(workdir: Path) -> dict[Path, tuple[int, int]]:
    """Summary files present now, with (inode, mtime) to detect rewrites."""
    return {p: (p.stat().st_ino, p.stat().st_mtime_ns)
            for p in (workdir / "results/cases").glob("*/summary.json")}


def incomplete_outputs(workdir: Path) -> set[str]:
    """Outputs Snakemake has marked incomplete: jobs started and not yet recorded as finished.

    Snakemake marks every output of a job when it starts it and unmarks them only after it has
    written their metadata, so an output without a marker is one a resumed run keeps. The marker
    files are named by the urlsafe base64 of the output path (long names split into '@' chunks).
    """
    root = workdir / ".snakemake" / "incomplete"
    marked = set()
    for path in root.rglob("*"):
        if path.is_file() and path.name != "migration_underway":
            b64 = "".join(part.lstrip("@") for part in path.relative_to(root).parts)
            marked.add(urlsafe_b64decode(b64).decode())
    return marked


def recorded_cases(workdir: Path) -> tuple[dict[Path, tuple[int, int]], set[str]]:
    """Finished cases Snakemake has recorded as complete, and the outputs still marked incomplete.

    A case whose script has written its summary but whose job Snakemake had not yet recorded
    when it was killed is, rightly, redone on resume; only recorded cases must be kept.
    """
    marked = incomplete_outputs(workdir)
    running = {Path(m).parent.name for m in marked}
    recorded = {p: stamp for p, stamp in finished_cases(workdir).items()
                if p.parent.name not in running}
    return recorded, marked


def test_sigkill_mid_sweep_resumes_without_recomputing(tmp_path: Path) -> None:
    config = tmp_path / "config.yaml"
    config.write_text(yaml.safe_dump(KILL_CONFIG))
    target = "results/dataset/dataset.h5"
    log = (tmp_path / "killed_run.log").open("w")
    run = make_reproduce(tmp_path, config, target, start_new_session=True, stdout=log)
    deadline = time.monotonic() + 300
    seen_running = set()  # the markers must be read right, or every case would count as recorded
    while time.monotonic() < deadline and run.poll() is None:
        recorded, marked = recorded_cases(tmp_path)
        seen_running |= {m for m in marked if m.endswith("/summary.json")}
        if len(recorded) >= 3:
            break
        time.sleep(0.2)
    os.killpg(run.pid, signal.SIGKILL)
    run.wait()
    log.close()
    done_early, _ = recorded_cases(tmp_path)
    assert seen_running, "Snakemake marks a running case's outputs incomplete; none was seen"
    assert 3 <= len(done_early) < 12, "the kill must land mid-sweep"
    assert not (tmp_path / target).exists()

    resumed = make_reproduce(tmp_path, config, target)
    output, _ = resumed.communicate(timeout=600)
    assert resumed.returncode == 0, output[-3000:]
    after = finished_cases(tmp_path)
    assert len(after) == 12
    for path, stamp in done_early.items():
        assert after[path] == stamp, f"{path.parent.name} was recomputed"
    assert list((tmp_path / "results/cases").glob("*/.partial")) == []
    with h5py.File(tmp_path / target) as h5:
        assert h5["displacement"].shape[0] == 12
        assert np.all(h5["cases/converged"][...])
        assert np.all(np.isfinite(h5["displacement"][...]))


def _planned(workdir: Path, change: dict) -> dict[str, int]:
    config = yaml.safe_load((REPO / "tests" / "config.yaml").read_text())
    for dotted, value in change.items():
        node = config
        *parents, key = dotted.split(".")
        for p in parents:
            node = node.setdefault(p, {})
        node[key] = value
    with tempfile.TemporaryDirectory() as folder:  # the run is shared: nothing written there
        path = Path(folder) / "changed.yaml"
        path.write_text(yaml.safe_dump(config))
        run = snakemake(workdir, "-n", "-j2", config=path)
    assert run.returncode == 0, run.stderr[-3000:]
    text = run.stdout + run.stderr
    return job_counts(text) if "Job stats:" in text else {}


def test_nothing_to_do_when_nothing_changed(small_run: Path) -> None:
    assert _planned(small_run, {}) == {}


def test_surrogate_change_reruns_training_only(small_run: Path) -> None:
    planned = _planned(small_run, {"surrogate.width": 16})
    trainings = {"train_study_run", "train_ablation_run", "train_held_out", "select_model"}
    assert trainings <= set(planned)
    assert {"mesh", "solve", "solve_chain", "aggregate"}.isdisjoint(planned)


def test_new_stiffness_solves_the_chains_it_joins(small_run: Path) -> None:
    """A new C1 joins every direction's chain, and those chains re-solve."""
    planned = _planned(small_run, {"sweep.C1_kPa": [1.0, 5.0, 2.5]})
    assert planned["solve_chain"] == 3 and "solve" not in planned  # 3 directions
    assert "mesh" not in planned and planned["aggregate"] == 1


def test_solver_change_resolves_every_case_but_keeps_the_mesh(small_run: Path) -> None:
    planned = _planned(small_run, {"fe.loading.initial_step": 0.5})
    assert planned["solve_chain"] == 3 and "mesh" not in planned
