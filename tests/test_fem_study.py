"""The FE study's pieces: variant names, Pareto front, lowest converging C1, references.

Also the reference storage and the convergence rate; its workflow rules run end to end in
``tests/test_workflow.py``.
"""

from __future__ import annotations

import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from fem.exceptions import InvalidParameterError
from report.common import variant_label
from studies.fe_study.convergence_map import lowest_converging, sweep_records
from studies.fe_study.fe_speed_accuracy import (
    FEVariantRecord,
    SpeedAccuracy,
    pareto_front,
    summarise_fe_variants,
)
from studies.fe_study.fe_variants import (
    FE_VARIANT_ID_PATTERN,
    FEVariant,
    MeshSpec,
    expand_fe_variants,
)

pytestmark = pytest.mark.solve


def test_variant_ids_round_trip_and_expand() -> None:
    v = FEVariant(MeshSpec(0.015, 0.01, 2), "p3p2", "iterative", 3)
    assert v.id == "g=0.0150_m=0.0100_o=2_el=p3p2_solver=iterative_q=3"
    assert FEVariant.from_id(v.id) == v
    variants = expand_fe_variants(
        [{"element": "p2p1", "mesh": [{"global_size": 0.03, "mound_size": 0.02},
                                      {"global_size": 0.02, "mound_size": 0.01}],
          "solver": ["direct", "iterative"]},
         {"element": "p2p1", "mesh": [{"global_size": 0.03, "mound_size": 0.02}]}]
    )
    assert len(variants) == 4  # the second entry repeats one of the first's
    graded = FEVariant(
        MeshSpec.from_mapping({"global_size": 0.015, "mound_size": 0.01, "fold_size": 0.004})
    )
    assert graded.id == "g=0.0150_m=0.0100_f=0.0040_o=1_el=p2p1_solver=direct_q=0"
    assert FEVariant.from_id(graded.id) == graded
    assert re.fullmatch(FE_VARIANT_ID_PATTERN, graded.id)
    assert re.fullmatch(FE_VARIANT_ID_PATTERN, v.id)
    assert graded.mesh.size_mapping()["fold_size"] == 0.004
    assert MeshSpec(0.015, 0.01).size_mapping()["fold_size"] is None  # overrides the workflow's
    assert variant_label(graded.id) == "P2/P1, h 15/10/4 mm, direct"
    with pytest.raises(InvalidParameterError, match="fold_size"):
        MeshSpec(0.015, 0.01, 1, 0.0)
    settings = variants[0].settings(__import__("fem.parameters").parameters.SolverSettings())
    assert settings.discretisation.element == "taylor-hood" and settings.discretisation.degree == 2


def test_pareto_front_and_cheapest_meeting_target() -> None:
    costs = [1.0, 2.0, 3.0, 2.5, 4.0]
    errors = [0.10, 0.02, 0.005, 0.03, 0.005]
    assert pareto_front(costs, errors) == [True, True, True, False, False]
    records = [
        FEVariantRecord(
            variant=f"v{i}",
            mesh={},
            element="p2p1",
            solver="direct",
            quadrature_degree=0,
            dofs=1,
            cells=1,
            material_points=1,
            setup_s=0.0,
            machine={},
            median_cpu_s=c,
            max_relative_error=e,
        )
        for i, (c, e) in enumerate(zip(costs, errors, strict=True))
    ]
    skipped = replace(
        records[0],
        variant="big",
        skipped="too many dofs",
        median_cpu_s=None,
        max_relative_error=None,
    )
    summary = summarise_fe_variants([*records, skipped], target=0.01, default_variant="v1")
    assert summary.cheapest_meeting_target == "v2"
    assert summary.pareto_front == ["v0", "v1", "v2"]
    assert [v.pareto for v in summary.variants] == [True, True, True, False, False, None]
    # the summary is a result file: it round-trips, the skipped variant without a Pareto flag
    written = summary.to_json()
    assert "pareto" not in written["variants"][-1] and written["default_variant"] == "v1"
    assert SpeedAccuracy.from_json(written) == summary


def test_lowest_converging_reads_down_each_column() -> None:
    def rec(c1, phi, ok, failure=""):
        return {
            "scheme": "adaptive",
            "C1": c1,
            "phi": phi,
            "converged": ok,
            "first_failure": failure,
            "failure_kinds": {"newton": 1} if failure else {},
            "load_fraction": 1.0 if ok else 0.4,
            "reason": failure,
        }

    records = [
        rec(2.0, 0.0, True),
        rec(1.0, 0.0, True),
        rec(0.5, 0.0, False, "diverged_max_it"),
        rec(0.3, 0.0, True),  # converging again below a failure does not count
        rec(2.0, 90.0, True),
        rec(1.0, 90.0, True),
        rec(0.5, 90.0, True),
        rec(0.3, 90.0, True),
    ]
    out = lowest_converging(records)["adaptive"]
    assert out["0.0"]["lowest_C1"] == 1.0
    assert out["0.0"]["failed_below"]["C1"] == 0.5
    assert out["90.0"]["lowest_C1"] == 0.3 and out["90.0"]["failed_below"] is None
    assert out["all_phi"] == 1.0
    # a direction solved at 2.0 and 1.0 kPa only, failing nowhere: it does not make the whole
    # sweep's limit 1.0 kPa
    band = [{**rec(c1, 45.0, True)} for c1 in (2.0, 1.0)]
    assert lowest_converging(records[4:] + band)["adaptive"]["all_phi"] == 0.3
    assert lowest_converging(records + band)["adaptive"]["all_phi"] == 1.0
    stiffest_failed = [rec(2.0, 30.0, False, "diverged_max_it"), rec(1.0, 30.0, True)]
    assert lowest_converging(records + stiffest_failed)["adaptive"]["all_phi"] is None


def test_sweep_records_map_the_sweep_at_theta_zero() -> None:
    cases = {
        "C1": np.array([2.0, 1.0, 0.8, 1.0]),
        "phi": np.array([0.0, 0.0, 0.0, 0.0]),
        "theta": np.array([0.0, 0.0, 0.0, 30.0]),
        "converged": np.array([True, True, False, False]),
        "load_fraction": np.array([1.0, 1.0, 0.7, 0.5]),
        "first_failure": np.array(
            ["", "diverged_max_it", "diverged_line_search", "x"], dtype=object
        ),
        "reason": np.array(
            ["converged", "converged", "step cut below min_step", "y"], dtype=object
        ),
    }
    records = sweep_records(cases)
    assert [r["C1"] for r in records] == [2.0, 1.0, 0.8]  # theta = 30 left out
    out = lowest_converging(records)["sweep"]
    assert out["0.0"]["lowest_C1"] == 1.0
    assert out["0.0"]["failed_below"] == {
        "C1": 0.8,
        "first_failure": "diverged_line_search",
        "failure_kinds": {},
        "load_fraction": 0.7,
        "reason": "step cut below min_step",
    }


def test_stored_reference_is_rebuilt_exactly(coarse_mesh: Path, tmp_path: Path) -> None:
    from fem.case import CaseRunner
    from fem.interpolation import evaluate
    from fem.sweep import Case
    from studies.fe_study.fe_reference import load_displacement, save_displacement
    from studies.fe_study.fe_timing import vertex_displacement

    runner = CaseRunner(coarse_mesh)
    runner.solve(Case(1.0, 180.0))
    save_displacement(tmp_path / "ref.h5", runner.problem, {"note": "test"})
    u, meta = load_displacement(tmp_path / "ref.h5", coarse_mesh)
    assert meta == {"note": "test"}
    _, X, at_vertices = vertex_displacement(runner)
    values, distance = evaluate(u, X)
    assert np.all(distance == 0.0)
    assert np.allclose(values, at_vertices, rtol=0, atol=1e-12)


def test_point_location_fallback_finds_the_containing_cell(coarse_mesh: Path) -> None:
    # the fallback for points dolfinx's GJK test fails on must agree with it where it works
    from dolfinx import geometry
    from mpi4py import MPI

    from fem.interpolation import _colliding_cells, _most_inside_cell
    from meshes.io import read_mesh

    mesh, _, _ = read_mesh(coarse_mesh, MPI.COMM_SELF)
    tree = geometry.BoundingBoxTree(mesh, 3)
    cells = np.arange(0, mesh.topology.index_map(3).size_local, 7)
    nodes = mesh.geometry.x
    centroids = np.array([nodes[mesh.geometry.dofmap.links(c)[:4]].mean(axis=0) for c in cells])
    assert np.array_equal(_colliding_cells(mesh, tree, centroids), cells)
    assert [_most_inside_cell(mesh, tree, x) for x in centroids] == cells.tolist()


def test_blas_and_openmp_threads_are_limited_in_the_loaded_libraries() -> None:
    import ctypes
    import os

    from studies.timing_hygiene import limit_blas_threads

    done = limit_blas_threads(1)  # numpy has loaded OpenBLAS; dolfinx's import loads libgomp
    assert {"libblas.so.3", "libopenblas.so.0"} & set(done)
    for name in {"libblas.so.3", "libopenblas.so.0"} & set(done):
        assert ctypes.CDLL(name, mode=os.RTLD_NOLOAD).openblas_get_num_threads() == 1


def test_one_core_pins_every_thread_and_restores_the_affinity() -> None:
    import os

    from studies.timing_hygiene import one_core

    allowed = os.sched_getaffinity(0)
    with one_core() as core:
        assert core == min(allowed)
        for tid in os.listdir("/proc/self/task"):
            assert os.sched_getaffinity(int(tid)) == {core}
    assert os.sched_getaffinity(0) == allowed


@pytest.fixture(scope="module")
def mesh_ladder(tmp_path_factory: pytest.TempPathFactory) -> dict[float, Path]:
    """The sharp-fold geometry at four element sizes (uniform, curved cells).

    The default breast's 1 cm fillet is not resolved by uniform 2-6 cm elements: on this
    ladder its RMS errors fall at rates of only 0.31 and 0.41 (pre-asymptotic), so the ladder
    keeps the sharp crease, whose singularity is present at every size.
    """
    from meshes.build import write_parametric_mesh
    from meshes.parametric import BreastGeometry
    from meshes.sizing import MeshSize

    folder = tmp_path_factory.mktemp("ladder")
    sharp = replace(BreastGeometry(), fold_radius=0.0)
    paths = {}
    for h in (0.06, 0.045, 0.03, 0.02):
        paths[h] = folder / f"h{h}.xdmf"
        write_parametric_mesh(sharp, MeshSize(global_size=h, mound_size=h, order=2), paths[h])
    return paths


def test_error_falls_with_mesh_size_against_a_finer_reference(
    mesh_ladder: dict[float, Path],
) -> None:
    """P2/P1 errors against a finer reference fall monotonically with the mesh size.

    Stiff prone case (5 kPa); errors at each mesh's own vertices against P3/P2 on the finest
    mesh fall as the mesh is refined, at roughly half to first order.

    A small-scale version of the fe_study speed-accuracy rule (which uses a much finer
    reference). The rate is not P2's smooth-solution rate: the displacement is singular
    along the edge where the clamped rib meets the free skin and at the crease where the
    mound meets the chest-wall layer, and the reference is itself only one size finer.
    Measured here: RMS rates 0.66 (0.06 -> 0.045) and 0.53 (0.045 -> 0.03).
    """
    from fem.case import CaseRunner
    from fem.parameters import Discretisation, SolverSettings
    from fem.sweep import Case
    from studies.fe_study.accuracy import observed_rates
    from studies.fe_study.fe_clinical import accuracy_at_vertices

    case = Case(5.0, 180.0)
    fine = CaseRunner(mesh_ladder[0.02], SolverSettings(discretisation=Discretisation(degree=3)))
    assert fine.solve(case)[0].converged
    reference = fine.problem.displacement()
    sizes, errors = [], []
    for h in (0.06, 0.045, 0.03):
        runner = CaseRunner(mesh_ladder[h])
        assert runner.solve(case)[0].converged
        acc = accuracy_at_vertices(runner, reference)
        sizes.append(h)
        errors.append(acc["rms_error_mm"])
        runner.solver.destroy()
    assert errors[0] > errors[1] > errors[2]
    assert observed_rates(sizes, errors)[0] > 0.5
    fine.solver.destroy()
