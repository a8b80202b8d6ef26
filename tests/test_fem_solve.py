"""Small solves on the coarse default geometry."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from fem.sweep import Case

pytestmark = pytest.mark.solve


@pytest.fixture(scope="module")
def runner(coarse_mesh: Path):
    from fem.case import CaseRunner

    return CaseRunner(coarse_mesh)


def test_zero_gravity_gives_zero_displacement(runner) -> None:
    from fem.parameters import Gravity

    result, _ = runner.solve_material(Case(1.0, 0.0).material(), Gravity(0.0, magnitude=0.0))
    assert result.converged
    assert np.max(np.abs(runner.problem.w.x.array)) == 0.0


def test_prone_case_converges_conserves_volume_and_sags(runner) -> None:
    result, timings = runner.solve(Case(1.0, 180.0))
    assert result.converged and result.fraction == 1.0
    assert abs(runner.problem.volume_change()) < 1e-8
    u = runner.problem.displacement().x.array.reshape(-1, 3)
    # prone: gravity along -x pulls the breast anteriorly (towards -x)
    assert u[:, 0].min() < -5e-3
    assert timings["solve"] > 0


def test_a_large_case_skips_measuring_the_factorisation_unit(
    runner, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Above MEASURE_UNIT_MAX_DOFS the summary does not pay a second factorisation."""
    import fem.case

    monkeypatch.setattr(fem.case, "MEASURE_UNIT_MAX_DOFS", 10)
    calls = []
    monkeypatch.setattr(runner.solver, "time_linear_system", lambda: calls.append(1) or 1.0)
    case = Case(5.0, 0.0)
    summary = runner.summary(case, *runner.solve(case))
    assert summary["linear_system_s"] is None and summary["factorization_equivalents"] is None
    assert calls == [] and summary["status"] == "converged"


def test_run_case_writes_complete_outputs(coarse_mesh: Path, tmp_path: Path) -> None:
    from fem.case import run_case
    from fem.case_files import read_points

    summary = run_case(coarse_mesh, Case(5.0, 0.0), tmp_path / "case")
    files = sorted(p.name for p in (tmp_path / "case").iterdir())
    assert files == ["fields.h5", "fields.xdmf", "points.h5", "summary.json"]
    on_disk = json.loads((tmp_path / "case" / "summary.json").read_text())
    assert on_disk["status"] == "converged"
    for key in ("C1", "phi", "theta", "load_steps", "newton_iterations", "final_residual",
                "max_disp_mm", "mean_disp_mm", "volume_change", "factorization_equivalents"):
        assert on_disk[key] is not None, key
    assert set(on_disk["wall_s"]) >= {
        "setup",
        "solve",
        "assembly",
        "linear_solve",
        "output",
        "total",
    }
    assert on_disk["self_overlap"]["overlapping_vertices"] == 0
    assert on_disk["self_overlap"]["boundary_vertices"] > 0
    points = read_points(tmp_path / "case" / "points.h5")
    assert points["u"].shape == points["X"].shape
    assert np.all(points["u"][points["fixed"]] == 0.0)
    assert summary["max_disp_mm"] == pytest.approx(
        1e3 * np.linalg.norm(points["u"], axis=1).max(), rel=1e-6
    )


def test_bad_input_writes_nothing(coarse_mesh: Path, tmp_path: Path) -> None:
    from fem.case import run_case
    from fem.exceptions import InvalidParameterError, MeshError
    from fem.parameters import FixedBoundaries

    with pytest.raises(InvalidParameterError, match="C1"):
        run_case(coarse_mesh, Case(-1.0, 0.0), tmp_path / "bad")
    assert not (tmp_path / "bad").exists()
    missing = tmp_path / "nomesh.xdmf"
    with pytest.raises(ValueError, match="does not exist"):
        run_case(missing, Case(1.0, 0.0), tmp_path / "bad")
    assert not (tmp_path / "bad").exists()
    # a mesh whose facet tags lack the fixed (rib) surface
    from dolfinx.mesh import meshtags

    from fem.problem import check_mesh
    from meshes.io import read_mesh

    mesh, _, tags = read_mesh(coarse_mesh)
    no_rib = meshtags(mesh, 2, tags.indices[tags.values != 1], tags.values[tags.values != 1])
    with pytest.raises(MeshError, match="'rib'"):
        check_mesh(mesh, no_rib, FixedBoundaries())
