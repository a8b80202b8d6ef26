"""The corpus of anatomies: each is what it says (volume, axes, side, chest wall) and imports.

The imported anatomies are written as a user's files would come (STL in millimetres in LPS axes
of a left breast, a gmsh volume mesh in RAS), imported with their declared orientation, and land
in the project's frame with the chest wall posterior. One solve per path checks the study's
record on a coarse import; the full corpus is a benchmark (`snakemake -j2 corpus`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from meshes.build import mound_volume
from meshes.config import MeshConfig, make_mesh
from meshes.corpus import ANATOMIES, PTOTIC, SMALL, write_anatomy
from meshes.exceptions import GeometryError, InvalidElementsError
from meshes.parametric import BreastGeometry

REPO = Path(__file__).resolve().parent.parent
BASE = yaml.safe_load((REPO / "config.yaml").read_text())["mesh"]


def _import(name: str, folder: Path) -> tuple[dict, dict]:
    section = write_anatomy(name, folder / "input", BASE, import_size=0.015)
    report = make_mesh(MeshConfig.from_mapping(section), folder / "mesh.xdmf",
                       folder / "quality.json", folder / "mesh.png")
    return section, report


@pytest.mark.unit
def test_the_corpus_has_six_anatomies_and_refuses_an_unknown_one(tmp_path: Path) -> None:
    assert list(ANATOMIES) == ["default", "small", "ptotic", "hemisphere", "scan", "volume"]
    with pytest.raises(GeometryError, match="unknown anatomy 'tiny'"):
        write_anatomy("tiny", tmp_path, BASE)


@pytest.mark.unit
@pytest.mark.parametrize("shape, low, high", [(SMALL, 280.0, 330.0), (PTOTIC, 1400.0, 1550.0)])
def test_the_parametric_anatomies_have_their_mound_volumes(shape, low, high) -> None:
    geometry = BreastGeometry.from_mapping({**BASE["geometry"], **shape})
    assert low <= 1e6 * mound_volume(geometry) <= high


@pytest.mark.unit
@pytest.mark.parametrize(
    "name, volume_ml, suffix, axes",
    [("hemisphere", 2 / 3 * np.pi * 60.0**3 / 1e3, ".stl", None),
     ("scan", None, ".stl", "LPS"), ("volume", None, ".msh", "RAS")],
)
def test_an_imported_anatomy_lands_posterior_in_the_project_frame(
    tmp_path: Path, name: str, volume_ml: float | None, suffix: str, axes: str | None
) -> None:
    """Its file is in the declared axes and millimetres; imported, its chest wall is posterior."""
    from dolfinx.io import XDMFFile
    from mpi4py import MPI

    from meshes.tags import Boundary

    section, report = _import(name, tmp_path)
    path = Path(section["file"]["path"])
    assert path.suffix == suffix and section["file"]["units"] == "mm"
    assert (section["file"].get("orientation") or {}).get("axes") == axes
    assert 300.0 < report["volume_ml"] < 1500.0
    if volume_ml is not None:  # the faceted hemisphere holds a little less than the sphere's half
        assert 0.97 * volume_ml < report["volume_ml"] <= volume_ml
    assert report["min_dihedral_deg"] >= 10.0
    with XDMFFile(MPI.COMM_SELF, str(tmp_path / "mesh.xdmf"), "r") as f:
        mesh = f.read_mesh(name="mesh")
        mesh.topology.create_connectivity(2, 3)
        facets = f.read_meshtags(mesh, name="facet_tags")
    x = mesh.geometry.x
    rib = np.unique(mesh.topology.connectivity(2, 0).array.reshape(-1, 3)[
        facets.indices[facets.values == Boundary.RIB.value]])
    # x runs anterior to posterior: the chest wall is the body's posterior side
    assert x[rib, 0].mean() > x[:, 0].mean() + 0.02
    assert np.ptp(x[:, 0]) < 0.15  # metres, not millimetres


@pytest.mark.unit
def test_a_remeshed_import_below_the_dihedral_floor_names_its_worst_cells(tmp_path: Path) -> None:
    """Cells below the floor: a remeshed surface names the worst; a kept surface warns."""
    from meshes.remesh import check_dihedral_floor

    x = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0.3, 0.3, 0.01], [0, 0, 1.0]]) * 0.05
    tets = np.array([[0, 1, 2, 3], [0, 1, 2, 4]])
    with pytest.raises(InvalidElementsError, match=r"1 of 2 tetrahedra .* below 10° \(worst "
                                                   r"cell 0: [0-9.]+° at \("):
        check_dihedral_floor(x, tets, "the remeshed surface", strict=True)
    record = check_dihedral_floor(x, tets, "a volume mesh", strict=False)
    assert record["cells_below_floor"] == 1 and record["min_dihedral_deg"] < 10.0


@pytest.mark.solve
def test_the_corpus_study_solves_an_anatomy_with_both_paths_and_resumes_a_stopped_job(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """One case on the coarse scan with both paths: they agree and are recorded.

    Run again on the same progress file (its last line cut short, as by a job killed while
    writing it), the job solves nothing and returns the same solves; with other settings, the
    file's solves do not count.
    """
    from dataclasses import replace

    from fem.case import CaseRunner
    from fem.parameters import SolverSettings
    from fem.sweep import Case
    from studies.fe_study.corpus import (
        EXACT,
        AnatomyRun,
        CorpusTable,
        Progress,
        corpus_rows,
        fingerprint,
        solve_anatomy,
    )
    from studies.fe_study.mesh_quality import MeshQuality

    section, _ = _import("scan", tmp_path)
    config = yaml.safe_load((REPO / "config.yaml").read_text())
    settings = SolverSettings.from_config({**config, "mesh": section})
    assert settings.contact is None  # the default contact is off on an import
    mesh, progress = tmp_path / "mesh.xdmf", tmp_path / "progress.jsonl"

    def anatomy() -> AnatomyRun:
        return solve_anatomy("scan", ANATOMIES["scan"].description, mesh,
                             MeshQuality.read(tmp_path / "quality.json"), settings,
                             [Case(1.0, 180.0)], progress=progress)

    run = anatomy()
    assert run.resumed == 0 and len(progress.read_text().splitlines()) == 2

    def no_solve(self: CaseRunner, case: Case) -> None:
        raise AssertionError(f"{case.id} solved again")

    monkeypatch.setattr(CaseRunner, "solve", no_solve)
    with progress.open("a") as out:
        out.write('{"fingerprint": "')
    resumed = anatomy()
    assert resumed.resumed == 2 and resumed.solves == run.solves
    other = replace(settings, loading=replace(settings.loading, max_steps=59))
    assert fingerprint(mesh, other) != fingerprint(mesh, settings)
    assert Progress(progress).done({fingerprint(mesh, other)}) == {}
    default, exact = run.by_solver("direct"), run.by_solver(EXACT)
    assert [s.converged for s in default + exact] == [True, True] and run.missed == []
    assert default[0].max_disp_mm == pytest.approx(exact[0].max_disp_mm, rel=1e-6)
    assert default[0].preconditioner_builds < exact[0].preconditioner_builds
    table = CorpusTable([run], soft_C1=0.8, soft_phi=[])
    table.write(tmp_path / "corpus.json")
    row = corpus_rows(CorpusTable.read(tmp_path / "corpus.json"))[0]
    assert row[0] == "scan" and row[6] == "1/1" and row[-1] == "none"


@pytest.mark.unit
def test_the_failures_table_lists_each_case_a_path_did_not_converge_with_its_load_fraction(
) -> None:
    """A case both paths converged is left out; one either path failed shows both paths' λ."""
    from studies.fe_study.corpus import (
        EXACT,
        FAILURES_HEADER,
        AnatomyRun,
        CorpusSolve,
        CorpusTable,
        corpus_failures,
    )

    def solve(case: str, solver: str, fraction: float, reason: str) -> CorpusSolve:
        return CorpusSolve(
            case=case, C1=1.0, phi=0.0, theta=0.0, solver=solver, converged=fraction == 1.0,
            load_fraction=fraction, load_steps=3, newton_iterations=40, preconditioner_builds=2,
            exact_retries=0, rescued=False, solve_s=12.0, max_disp_mm=50.0, reason=reason)

    solves = [solve("a", "direct", 1.0, "converged"), solve("a", EXACT, 1.0, "converged"),
              solve("b", "direct", 0.75, "step cut below min_step"),
              solve("b", EXACT, 0.734, "step cut below min_step"),
              solve("c", "direct", 1.0, "converged"), solve("c", EXACT, 0.5, "diverged")]
    run = AnatomyRun(name="ptotic", description="", source="parametric", volume_ml=1.0,
                     breast_volume_ml=1.0, cells=1, dofs=1, min_dihedral_deg=10.0,
                     solver="direct", solves=solves, machine={})
    table = CorpusTable([run], soft_C1=0.8, soft_phi=[])
    rows = corpus_failures(table)
    assert [row[:2] for row in rows] == [["ptotic", "b"], ["ptotic", "c"]]
    assert all(len(row) == len(FAILURES_HEADER) for row in rows)
    assert rows[0][2] == "0.750 (failed)" and rows[0][6] == "0.734 (failed)"
    assert rows[1][2] == "1.000" and rows[1][5] == "" and rows[1][9] == "diverged"
    from report.context import Context
    from report.sections.corpus import corpus_section

    page = corpus_section(Context(out_dir=Path("."), clinical=[], paths={}, clinical_fields=[],
                                  results={"corpus": table}))
    assert 'id="corpus-failures"' in page and "0.734 (failed)" in page
    assert "The default converged every case that exact Newton converged." in page
