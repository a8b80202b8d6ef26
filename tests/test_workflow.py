"""The Snakemake workflow: planning, config validation, and the small sweep end to end."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest
import yaml

from tests.conftest import REPO


def snakemake(workdir: Path, *args: str, config: Path = REPO / "tests" / "config.yaml") -> subprocess.CompletedProcess:
    """Run the project's Snakefile in ``workdir`` with the venv's Snakemake."""
    cmd = [sys.executable, "-m", "snakemake", "-s", str(REPO / "Snakefile"), "-d", str(workdir),
           "--configfile", str(config), *args]
    return subprocess.run(cmd, capture_output=True, text=True, cwd=workdir)


def job_counts(output: str) -> dict[str, int]:
    """Parse Snakemake's 'Job stats' table."""
    table = output.split("Job stats:")[1]
    return {m[1]: int(m[2]) for m in re.finditer(r"^(\w+)\s+(\d+)\s*$", table, re.M)}


def test_full_config_plans_688_solves(tmp_path: Path) -> None:
    run = snakemake(tmp_path, "-n", "-j2", config=REPO / "config.yaml")
    assert run.returncode == 0, run.stderr
    counts = job_counts(run.stdout + run.stderr)
    assert counts["solve"] == 688
    assert counts["mesh"] == counts["aggregate"] == counts["train"] == counts["report"] == 1


def test_one_case_path_runs_only_that_case(tmp_path: Path) -> None:
    target = "results/cases/c1=2.30_phi=-150.0_theta=0.0/summary.json"
    run = snakemake(tmp_path, "-n", "-j2", target, config=REPO / "config.yaml")
    assert run.returncode == 0, run.stderr
    assert job_counts(run.stdout + run.stderr) == {"mesh": 1, "solve": 1, "total": 2}


@pytest.mark.parametrize(
    "section, key, value, message",
    [
        ("sweep", "C1_kPa", [1.0, -2.0], "sweep.C1_kPa"),
        ("material", "density", 0.0, "material.density"),
        ("surrogate", "width", 0, "surrogate.width"),
    ],
)
def test_out_of_bounds_config_stops_before_any_job(
    tmp_path: Path, section: str, key: str, value: object, message: str
) -> None:
    config = yaml.safe_load((REPO / "tests" / "config.yaml").read_text())
    config.setdefault(section, {})[key] = value
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(config))
    run = snakemake(tmp_path, "-j1", config=path)
    assert run.returncode != 0
    assert "invalid configuration" in run.stderr and message in run.stderr
    assert not (tmp_path / "results").exists()


def test_inconsistent_geometry_stops_before_any_job(tmp_path: Path) -> None:
    config = yaml.safe_load((REPO / "tests" / "config.yaml").read_text())
    config["mesh"]["geometry"] = {"mound_radius_cranial": 0.11}
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(config))
    run = snakemake(tmp_path, "-j1", config=path)
    assert run.returncode != 0 and "cranial or caudal" in run.stderr
    assert not (tmp_path / "results").exists()


@pytest.fixture(scope="module")
def small_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    workdir = tmp_path_factory.mktemp("workflow")
    run = snakemake(workdir, "-j2")
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-3000:]
    return workdir


def test_small_sweep_dataset_content(small_run: Path) -> None:
    config = yaml.safe_load((REPO / "tests" / "config.yaml").read_text())
    n_cases = len(config["sweep"]["C1_kPa"]) * len(config["sweep"]["phi_deg"])
    with h5py.File(small_run / "results/dataset/dataset.h5") as h5:
        u = h5["displacement"][...]
        kind = h5["points/kind"][...]
        assert u.shape == (n_cases, h5["points/X"].shape[0], 3)
        assert np.all(h5["cases/converged"][...])
        boundary = kind == 1
        assert 0 < boundary.sum() < len(kind)
        assert np.all(u[:, boundary] == 0.0)  # clamped on the chest wall
        norms = np.linalg.norm(u[:, ~boundary], axis=2)
        assert np.all(norms.max(axis=1) > 1e-3)  # every case sags by more than a millimetre
        C1 = h5["cases/C1"][...]
        phi = h5["cases/phi"][...]
        prone_soft = np.flatnonzero((C1 == 1.0) & (phi == 180.0))[0]
        prone_stiff = np.flatnonzero((C1 == 5.0) & (phi == 180.0))[0]
        # five times stiffer sags about five times less (near-linear regime)
        ratio = np.abs(u[prone_soft]).max() / np.abs(u[prone_stiff]).max()
        assert 3.5 < ratio < 7.0
    for case in (small_run / "results/cases").iterdir():
        assert (case / "fields.xdmf").is_file() and (case / "fields.h5").is_file()


def test_small_sweep_surrogate_predicts_the_fe(small_run: Path) -> None:
    from surrogate.data import load_dataset
    from surrogate.predict import Surrogate

    ds = load_dataset(small_run / "results/dataset/dataset.h5")
    model = Surrogate.load(small_run / "results/surrogate/model")
    total_err = total_norm = 0.0
    for case in range(len(ds.C1)):
        fe = ds.displacement[case]
        pred = model.predict(float(ds.C1[case]), float(ds.phi[case]))
        err = np.linalg.norm(pred - fe, axis=1).mean()
        norm = np.linalg.norm(fe, axis=1).mean()
        # at least twice as good as predicting no displacement, in every case ...
        assert err < 0.5 * norm, ds.ids[case]
        total_err, total_norm = total_err + err, total_norm + norm
    # ... and within 15 % of the typical displacement over the sweep
    assert total_err < 0.15 * total_norm


def test_small_sweep_report(small_run: Path) -> None:
    page = (small_run / "results/report/index.html").read_text()
    assert "<img" in page and "Clinical cases" in page
    for img in re.findall(r'src="([^"]+\.png)"', page):
        assert (small_run / "results/report" / img).stat().st_size > 1000
