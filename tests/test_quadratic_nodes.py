"""The fields at every node of a quadratic mesh: in the dataset, a pod model's modes, its answers.

The FE field is quadratic in each cell; a ``pod`` model whose modes are known at every node
answers between the points by the same shape functions, so that a field quadratic in space
comes back exactly where the vertices' linear interpolation misses its curvature.
"""

from __future__ import annotations

import json
import warnings
from dataclasses import replace
from pathlib import Path

import h5py
import numpy as np
import pytest

from fem.aggregate import build_dataset
from fem.case_files import FIELD_DATASET, write_points
from fem.dataset import read_dataset
from fem.directions import gravity_direction
from fem.exceptions import DatasetError
from fem.sweep import Case
from meshes.quadratic import EDGES, edge_order, quadratic_weights
from surrogate.config import SurrogateConfig
from surrogate.exceptions import ExtrapolationWarning, ModelFileError
from surrogate.interpolation import at_centroids, interpolate, locate_quadratic

pytestmark = pytest.mark.unit

CONFIG = SurrogateConfig(structure="pod", modes=6, hidden_layers=2, width=32, activation="silu",
                         c1_encoding="inverse", output_scaling="compliance",
                         output_form="gravity_linear", learning_rate=0.003, beta1=0.9,
                         beta2=0.999, lr_schedule="cosine", max_epochs=60, patience=60)
SIZE = 0.1
"""The cube's edge (m): a breast's scale, so that the 1 mm outside tolerance means the same."""


def quadratic_cube(n: int = 4, order: tuple[tuple[int, int], ...] = EDGES[::-1]
                   ) -> tuple[np.ndarray, np.ndarray, int]:
    """A cube's 10-node tetrahedra, its edge nodes at midpoints in ``order``.

    Returns the nodes, the cells and the number of vertices (the first rows of the nodes).
    """
    from scipy.spatial import Delaunay

    axis = np.linspace(0.0, SIZE, n)
    V = np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), axis=-1).reshape(-1, 3)
    tets = Delaunay(V).simplices
    tets = tets[np.abs(np.linalg.det(V[tets[:, 1:]] - V[tets[:, :1]])) > 1e-12 * SIZE**3]
    nodes, edges, cells = list(V), {}, []
    for tet in tets:
        row = list(tet)
        for a, b in order:
            key = (min(tet[a], tet[b]), max(tet[a], tet[b]))
            if key not in edges:
                edges[key] = len(nodes)
                nodes.append((V[key[0]] + V[key[1]]) / 2)
            row.append(edges[key])
        cells.append(row)
    return np.asarray(nodes), np.asarray(cells, dtype=np.int64), len(V)


def _field(X: np.ndarray, C1: float, phi: float, theta: float) -> np.ndarray:
    """A displacement (m) quadratic in X, linear in ĝ, scaled as 1/C1, zero on the rib x = 0."""
    g = gravity_direction(np.asarray(phi), np.asarray(theta))
    M = np.array([[1.0, 0.2, 0.0], [0.0, 1.0, 0.3], [0.1, 0.0, 1.0]])
    x, y = X[:, 0] / SIZE, X[:, 1] / SIZE
    A = (x * (1.0 + 3.0 * x + 3.0 * y))[:, None, None] * M
    return 0.001 / C1 * (A @ g)


def test_quadratic_shape_functions_give_a_quadratic_field_exactly() -> None:
    X, cells, _ = quadratic_cube()
    assert np.array_equal(edge_order(X, cells), np.asarray(EDGES[::-1]))
    rng = np.random.default_rng(0)
    points = rng.uniform(0.0, SIZE, (300, 3))
    f = _field(X, 1.0, 60.0, 30.0)
    np.testing.assert_allclose(interpolate(f, *locate_quadratic(X, cells, points)),
                               _field(points, 1.0, 60.0, 30.0), rtol=0, atol=1e-15)
    shuffled = cells.copy()
    shuffled[1, 4:] = shuffled[1, [5, 4, 6, 7, 8, 9]]  # one cell's edge nodes in another order
    with pytest.raises(ValueError, match="not in one order"):
        edge_order(X, shuffled)


def test_curved_cells_are_inverted_so_that_a_linear_field_is_exact() -> None:
    """Edge nodes moved off their midpoints (a curved skin): the isoparametric map is inverted."""
    X, cells, n_vertices = quadratic_cube()
    curved = X.copy()
    curved[n_vertices:] += 0.004 * SIZE * np.sin(30.0 / SIZE * X[n_vertices:, [1, 2, 0]])
    pairs = edge_order(curved, cells)
    rng = np.random.default_rng(1)
    which = rng.integers(0, len(cells), 400)
    # points given by their reference coordinates in curved cells
    points = np.einsum("mk,mkd->md", quadratic_weights(rng.dirichlet(np.ones(4), 400), pairs),
                       curved[cells[which]])
    linear = np.array([[1.0, 2.0, 0.0], [0.0, 1.0, 3.0], [1.0, 0.0, 1.0]])
    got = interpolate(curved @ linear, *locate_quadratic(curved, cells, points))
    np.testing.assert_allclose(got, points @ linear, rtol=0, atol=1e-12)


def test_a_quadratic_field_is_exact_at_a_cells_centroid_whatever_the_edge_order() -> None:
    """The 10-node tetrahedron's shape functions at its barycentre: -1/8 and 1/4."""
    vertices = np.array([[0.0, 0.0, 0.0], [1.0, 0.1, 0.0], [0.2, 1.0, 0.1], [0.1, 0.3, 1.2]])
    edges = [(2, 3), (0, 1), (1, 3), (0, 2), (1, 2), (0, 3)]  # any order
    nodes = np.vstack([vertices, [(vertices[a] + vertices[b]) / 2 for a, b in edges]])

    def field(x: np.ndarray) -> np.ndarray:
        return np.stack([x[..., 0] ** 2 + x[..., 1] * x[..., 2], 3 * x[..., 1] ** 2 - x[..., 0],
                         x[..., 2] * x[..., 0] + 0.5], axis=-1)

    cells = np.arange(10)[None, :]
    centroid = vertices.mean(axis=0)
    np.testing.assert_allclose(at_centroids(field(nodes), cells)[0], field(centroid),
                               atol=1e-12)
    np.testing.assert_allclose(at_centroids(nodes, cells)[0], centroid, atol=1e-12)
    assert not np.allclose(field(vertices).mean(axis=0), field(centroid))  # linear would miss
    with pytest.raises(ValueError, match="10-node cells"):
        at_centroids(nodes, cells[:, :4])


@pytest.fixture(scope="module")
def sweep(tmp_path_factory: pytest.TempPathFactory):
    """Cases on the quadratic cube: points at the vertices, fields at every node."""
    from meshes.io import GEOMETRY_DATASET, TOPOLOGY_DATASET

    folder = tmp_path_factory.mktemp("quadratic")
    X, cells, n_vertices = quadratic_cube()
    V = X[:n_vertices]
    summaries, points, fields = [], [], []
    for C1 in (1.0, 2.0, 3.0, 4.0, 5.0):
        for phi, theta in ((0.0, 0.0), (60.0, 0.0), (120.0, 0.0), (180.0, 0.0), (-60.0, 0.0),
                           (-120.0, 0.0), (90.0, 90.0), (90.0, -90.0)):
            case = folder / Case(C1, phi, theta).id
            case.mkdir()
            write_points(case / "points.h5", np.arange(n_vertices), V,
                         _field(V, C1, phi, theta), V[:, 0] == 0.0, case.name)
            with h5py.File(case / "fields.h5", "w") as h5:
                h5[GEOMETRY_DATASET] = X
                h5[TOPOLOGY_DATASET] = cells
                h5[FIELD_DATASET] = _field(X, C1, phi, theta)
            (case / "summary.json").write_text(json.dumps({
                "status": "converged", "case": case.name, "C1": C1, "phi": phi, "theta": theta,
                "gravity_vector": [0, 0, 0], "load_fraction": 1.0}))
            summaries.append(case / "summary.json")
            points.append(case / "points.h5")
            fields.append(case / "fields.h5")
    with h5py.File(folder / "mesh.h5", "w") as h5:
        h5[GEOMETRY_DATASET] = X
        h5[TOPOLOGY_DATASET] = cells
    build_dataset(summaries, points, folder / "ds.h5", mesh=folder / "mesh.xdmf",
                  fields_paths=fields)
    return folder, summaries, points, fields


def test_the_dataset_holds_the_fields_at_every_node(sweep) -> None:
    folder = sweep[0]
    ds = read_dataset(folder / "ds.h5", nodes=True)
    nodes = ds.nodes
    assert nodes is not None and nodes.cells.shape[1] == 10
    assert len(nodes.X) > ds.n_points
    np.testing.assert_array_equal(nodes.X[nodes.vertex], ds.X)
    np.testing.assert_allclose(nodes.displacement[:, nodes.vertex], ds.displacement,
                               rtol=1e-6, atol=1e-9)
    assert read_dataset(folder / "ds.h5").nodes is None  # read only when asked for


def test_a_cases_field_at_named_points_is_the_quadratic_field_there(sweep) -> None:
    """A case's field between the nodes, exactly where it is quadratic.

    The function is ``studies.reference_state.fe_at_points``'s.
    """
    from studies.reference_state.fe_at_points import fe_at_points

    folder, summaries, _, _ = sweep
    case = Path(summaries[7]).parent
    C1, phi, theta = (json.loads(Path(summaries[7]).read_text())[k] for k in ("C1", "phi", "theta"))
    points = np.random.default_rng(3).uniform(0.1 * SIZE, 0.9 * SIZE, size=(20, 3))
    np.testing.assert_allclose(fe_at_points(case, points), 1e3 * _field(points, C1, phi, theta),
                               rtol=0, atol=1e-9)


def test_a_case_on_another_mesh_is_named_and_nothing_is_written(sweep, tmp_path: Path) -> None:
    from meshes.io import GEOMETRY_DATASET

    folder, summaries, points, fields = sweep
    other = tmp_path / "fields.h5"
    with h5py.File(fields[3]) as src, h5py.File(other, "w") as dst:
        for key in src:
            src.copy(key, dst)
        del dst[GEOMETRY_DATASET]
        dst[GEOMETRY_DATASET] = src[GEOMETRY_DATASET][...] * 1.01
    with pytest.raises(DatasetError, match="another mesh than"):
        build_dataset(summaries, points, tmp_path / "ds.h5", mesh=folder / "mesh.xdmf",
                      fields_paths=[*fields[:3], other, *fields[4:]])
    assert not (tmp_path / "ds.h5").exists()


@pytest.fixture(scope="module")
def models(sweep, tmp_path_factory: pytest.TempPathFactory):
    """Pod models fitted on the cube's sweep at every node (quadratic) and at the vertices."""
    from surrogate.checkpoint import save_model
    from surrogate.predict import Surrogate
    from surrogate.train import train_and_evaluate

    folder, out = sweep[0], tmp_path_factory.mktemp("models")
    found = {}
    for name, nodes in (("quadratic", True), ("linear", False)):
        ds = read_dataset(folder / "ds.h5", nodes=nodes)
        save_model(out / name, train_and_evaluate(ds, CONFIG, progress=False), ds)
        found[name] = Surrogate.load(out / name)
    return found, out


def test_a_pod_model_with_the_nodes_answers_between_the_points_quadratically(
        models, tmp_path: Path) -> None:
    """At the edge nodes, a model fitted at the nodes is as right as at its points.

    The edge nodes are no material points; a model fitted at the vertices only misses the
    field's curvature there.
    """
    import shutil

    models, saved = models
    assert models["quadratic"]._checkpoint.nodes is not None
    assert models["linear"]._checkpoint.nodes is None
    X, cells, n_vertices = quadratic_cube()
    between = X[n_vertices:]
    query = (2.0, 60.0, 0.0)  # a training case: the branch's weights are near exact there
    truth = 1e3 * _field(between, *query)
    errors = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ExtrapolationWarning)
        at_points = models["quadratic"].predict(*query)
        for name, model in models.items():
            errors[name] = np.abs(model.at(between).predict(*query) - truth).max()
    at_points_error = np.abs(at_points - 1e3 * _field(X[:n_vertices], *query)).max()
    assert errors["quadratic"] <= 2.0 * at_points_error + 1e-6
    assert errors["linear"] >= 10.0 * errors["quadratic"]
    # a folder whose modes at the nodes do not fit its nodes is refused, by name
    from surrogate.checkpoint import PARAMS_NPZ, load_checkpoint

    folder = tmp_path / "quadratic"
    shutil.copytree(saved / "quadratic", folder)
    with np.load(folder / PARAMS_NPZ) as npz:
        arrays = {k: npz[k] for k in npz.files}
    arrays["mesh_nodes_basis"] = arrays["mesh_nodes_basis"][:-1]
    np.savez(folder / PARAMS_NPZ, **arrays)
    with pytest.raises(ModelFileError, match="the modes at the nodes are not finite"):
        load_checkpoint(folder)


def test_the_held_out_and_posture_errors_are_taken_between_the_points_too(
        sweep, models) -> None:
    """At the cell centroids the FE field is exact, and a linear model's miss shows there.

    The cube's field is quadratic in space: the centroids' FE values equal the field there;
    the model fitted at every node answers them as well as its material points, the one fitted
    at the vertices misses the curvature, and the evaluations report both at the centroids.
    """
    from studies.surrogate_study.errors_against_fe import Centroids
    from studies.surrogate_study.held_out import evaluate_held_out, trained_cases
    from studies.surrogate_study.postures import evaluate_postures

    folder, summaries, points, fields = sweep
    models = models[0]
    ds = read_dataset(folder / "ds.h5", nodes=True)
    centroids = Centroids.of(ds)
    assert centroids is not None and centroids.X.shape == (len(ds.nodes.cells), 3)
    case = 11
    np.testing.assert_allclose(centroids.fe(ds, case), 1e3 * _field(
        centroids.X, float(ds.C1[case]), float(ds.phi[case]), float(ds.theta[case])),
        rtol=1e-5, atol=1e-6)
    assert Centroids.of(read_dataset(folder / "ds.h5")) is None

    quadratic = evaluate_held_out({}, models["quadratic"], ds)
    linear = evaluate_held_out({}, models["linear"], ds)
    # inside the data: the cases the pod model trained on, not its validation cases
    validation = ds.splits["by_case"]["validation"]
    trained = trained_cases(models["quadratic"], ds)
    assert validation.size and not np.isin(validation, trained).any()
    assert trained.size + validation.size == int(ds.converged.sum())
    assert quadratic.inside_all.cases == quadratic.inside_all_between.cases == trained.size
    assert quadratic.inside_all_between.max_mm <= 2.0 * quadratic.inside_all.max_mm + 1e-6
    assert linear.inside_all_between.max_mm >= 10.0 * quadratic.inside_all_between.max_mm
    assert evaluate_held_out({}, models["quadratic"], read_dataset(folder / "ds.h5")
                             ).inside_all_between is None

    postures = evaluate_postures(models["linear"], [
        ("supine", True, summaries[case], points[case], fields[case]),
        ("supine, no fields", True, summaries[case], points[case], None)])
    with_fields, without = postures.rows
    assert with_fields.between.case == with_fields.errors.case == ds.ids[case]
    assert with_fields.between.max_mm >= 10.0 * quadratic.inside_all_between.max_mm
    assert without.between is None and without.errors == with_fields.errors
    # from the first posture at the same C1: the model's movement against FE's
    other = int(np.flatnonzero((ds.C1 == ds.C1[case]) & (ds.phi != ds.phi[case]))[0])
    stiffer = int(np.flatnonzero(ds.C1 != ds.C1[case])[0])  # no first posture at its C1
    moved = evaluate_postures(models["linear"], [
        ("prone", True, summaries[case], points[case], None),
        ("other", True, summaries[other], points[other], None),
        ("other C1", True, summaries[stiffer], points[stiffer], None)]).rows
    model = models["linear"]
    way = ((model.predict(ds.C1[other], ds.phi[other], ds.theta[other])
            - model.predict(ds.C1[case], ds.phi[case], ds.theta[case]))
           - (ds.displacement[other] - ds.displacement[case]))
    assert moved[0].movement is None
    assert moved[1].movement.max_mm == pytest.approx(np.linalg.norm(way, axis=1).max(), rel=1e-5)
    assert moved[1].movement.fe_max_mm == pytest.approx(np.linalg.norm(
        ds.displacement[other] - ds.displacement[case], axis=1).max(), rel=1e-5)
    assert moved[2].movement is None and moved[2].errors is not None

    from report.context import Context
    from report.sections.generalisation import held_out_part, postures_part

    ctx = Context(out_dir=folder, clinical=[], paths={}, clinical_fields=[],
                  results={"held_out": linear, "postures": postures})
    spread = linear.inside_all_between
    assert (f"{spread.mean_mm:.3g} / {spread.p95_mm:.3g} / {spread.max_mm:.3g}"
            in held_out_part(ctx))
    page = postures_part(ctx)
    assert f"{with_fields.between.max_mm:.3g}</td>" in page and "between the points" in page
    page = postures_part(Context(out_dir=folder, clinical=[], paths={}, clinical_fields=[],
                                 results={"postures": replace(postures, rows=moved)}))
    assert "FE&#x27;s largest movement from prone (mm)" in page
    assert f"<td>other</td><td>{ds.C1[other]:g}</td><td>{moved[1].movement.fe_max_mm:.3g}" in page


def test_the_off_grid_set_is_judged_against_its_goals_and_lists_failed_solves(
        sweep, models, tmp_path: Path) -> None:
    """The off-grid evaluation spreads the compared cases' errors and names the failed ones."""
    from report.context import Context
    from report.sections.generalisation import off_grid_part
    from studies.surrogate_study.off_grid import GOALS_MM, OffGridEvaluation, evaluate_off_grid

    folder, summaries, points, fields = sweep
    failed = tmp_path / "failed.json"
    failed.write_text(json.dumps({**json.loads(summaries[3].read_text()), "status": "failed",
                                  "reason": "step cut below min_step at λ=0.5"}))
    cases = [(summaries[5], points[5], fields[5]), (failed, points[3], fields[3]),
             (summaries[11], points[11], None)]
    assert evaluate_off_grid(models[0]["quadratic"], cases).goals_mm == GOALS_MM
    # the cube's field is a few mm: goals at its scale, which the model fitted at every node
    # meets and the one fitted at the vertices misses between them (at the vertices it fits)
    goals = {"mean": 0.05, "max": 0.05}
    good = evaluate_off_grid(models[0]["quadratic"], cases, goals)
    bad = evaluate_off_grid(models[0]["linear"], cases, goals)
    for result in (good, bad):
        assert [r.posture for r in result.rows] == ["off-grid 1", "off-grid 2", "off-grid 3"]
        assert [r.case for r in result.failed] == [result.rows[1].case]
        assert result.spread.cases == 2 and result.between.cases == 1
        assert result.spread.max_mm == max(result.rows[k].errors.max_mm for k in (0, 2))
        assert result.spread.max_mm < goals["max"]
    assert good.goals_met and good.between.max_mm < goals["max"]
    assert not bad.goals_met and bad.between.max_mm > goals["max"]
    path = tmp_path / "off_grid.json"
    bad.write(path)
    assert OffGridEvaluation.read(path) == bad

    ctx = Context(out_dir=folder, clinical=[], paths={}, clinical_fields=[],
                  results={"off_grid": bad})
    page = off_grid_part(ctx)
    assert "1 of 3 FE solves failed" in page and "min_step at λ=0.5" in page
    assert "all 2 compared (a goal missed)" in page
    assert f"{bad.spread.max_mm:.3g}</td>" in page


def test_the_off_grid_command_compares_a_model_folder_with_case_folders(
        sweep, models, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``python -m studies.surrogate_study.off_grid MODEL CASE...``: per case, C1 and overall."""
    import shutil

    from studies.surrogate_study.off_grid import OffGridEvaluation, main

    folder, summaries, points, fields = sweep
    failed = tmp_path / "failed"
    failed.mkdir()
    shutil.copy(points[3], failed / "points.h5")
    (failed / "summary.json").write_text(json.dumps({
        **json.loads(summaries[3].read_text()), "status": "failed",
        "reason": "step cut below min_step at λ=0.5"}))
    cases = [summaries[5].parent, failed, summaries[11].parent]
    out = tmp_path / "eval.json"
    assert main([str(models[1] / "quadratic"), *map(str, cases), "--json", str(out)]) == 0
    text = capsys.readouterr().out
    evaluation = OffGridEvaluation.read(out)
    assert [row.case for row in evaluation.rows] == [json.loads(
        (c / "summary.json").read_text())["case"] for c in cases]
    first = evaluation.rows[0].errors
    assert f"{first.case}: mean {first.mean_mm:.4f}" in text
    assert f"{evaluation.rows[1].case}: FE failed (step cut below min_step" in text
    c1s = {round(r.C1, 6) for r in evaluation.rows if r.errors is not None}
    assert all(f"C1 = {c1:g} kPa: " in text for c1 in c1s)
    assert f"all: 2 cases, mean {evaluation.spread.mean_mm:.4f}" in text
    assert main([str(models[1] / "quadratic"), str(tmp_path / "none")]) == 2
    assert "no summary.json in" in capsys.readouterr().err


def test_a_held_out_block_without_cases_the_by_sample_model_trained_on(
        sweep, models, tmp_path: Path) -> None:
    """Where the by-sample model trained on none of a split's test cases, no row says it did."""
    from report.context import Context
    from report.sections.generalisation import held_out_part
    from studies.surrogate_study.errors_against_fe import CaseErrors, ErrorSpread
    from studies.surrogate_study.held_out import HeldOutBlock, HeldOutEvaluation

    folder = sweep[0]
    ds = read_dataset(folder / "ds.h5")
    model = models[0]["linear"]
    test = ds.splits["by_case"]["validation"][:2]  # cases the pod model validated on
    rows = [CaseErrors.of(model, ds, int(i)) for i in test]
    block = HeldOutBlock(split="by_case", held_out="whole setups", groups=list(ds.ids[test]),
                         held_out_model=ErrorSpread.over(rows), inside_model=None, rows=rows,
                         inside_rows=[])
    evaluation = HeldOutEvaluation(blocks=[block], inside_all=ErrorSpread.over(rows))
    evaluation.write(tmp_path / "held_out.json")
    back = HeldOutEvaluation.read(tmp_path / "held_out.json")
    assert back.blocks[0].inside_model is None and back == evaluation
    page = held_out_part(Context(out_dir=folder, clinical=[], paths={}, clinical_fields=[],
                                 results={"held_out": back}))
    assert page.count("held out model") == 1 and page.count("by sample model") == 1


def test_a_point_inside_a_cell_is_found_however_far_its_centroid_lies() -> None:
    """Near a big cell's corner, dozens of small cells' centroids are nearer than its own."""
    from scipy.spatial import Delaunay

    from surrogate.interpolation import locate

    axis = np.linspace(0.0, SIZE, 3)
    coarse = np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), axis=-1).reshape(-1, 3)
    fine = np.stack(np.meshgrid(*[np.linspace(0.01, 0.03, 7)] * 3, indexing="ij"),
                    axis=-1).reshape(-1, 3)
    X = np.vstack([coarse, fine])
    cells = Delaunay(X).simplices
    cells = cells[np.abs(np.linalg.det(X[cells[:, 1:]] - X[cells[:, :1]])) > 1e-12 * SIZE**3]
    # four points near each corner of every cell, inside it
    weights = np.full((4, 4), 0.01) + np.eye(4) * 0.96
    points = np.einsum("aj,cjd->cad", weights, X[cells]).reshape(-1, 3)
    own = np.repeat(np.arange(len(cells)), 4)
    centroids = X[cells].mean(axis=1)
    rank = (np.linalg.norm(centroids[None] - points[:, None], axis=2)
            < np.linalg.norm(centroids[own] - points, axis=1)[:, None]).sum(axis=1)
    assert rank.max() > 24  # beyond the fixed candidate count that missed them
    rows, w = locate(X, cells, points)
    assert np.all(w >= 0)
    np.testing.assert_allclose(interpolate(X, rows, w), points, atol=1e-12)
    # blocks of any size give the same cells
    import surrogate.interpolation as interpolation

    block = interpolation.BLOCK
    try:
        interpolation.BLOCK = 7
        np.testing.assert_allclose(interpolate(X, *locate(X, cells, points)), points, atol=1e-12)
    finally:
        interpolation.BLOCK = block
