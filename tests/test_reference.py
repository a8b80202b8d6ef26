"""The reference state of an imaged (loaded) shape: a round trip on the coarse default breast.

Solve from the true reference in one posture; take the loaded shape as the observation;
estimate the reference with the same C1; compare with the truth, then predict supine from the
estimate and from the loaded shape taken as stress-free (the naive way). One runner holds the
mesh throughout (its geometry is moved), so every field is in the same node order.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from fem.case import CaseRunner
from fem.io import node_displacement
from fem.parameters import SolverSettings
from fem.reference import estimate_reference, write_reference_mesh
from fem.sweep import Case
from meshes.io import nodes_in_file_order, read_mesh, same_cells

pytestmark = pytest.mark.solve


def _deformed(runner: CaseRunner, case: Case, X: np.ndarray) -> np.ndarray:
    """Geometry-node positions after solving ``case`` from the reference ``X``."""
    runner.problem.set_geometry(X)
    result, _ = runner.solve(case)
    assert result.converged, result.reason
    return X + node_displacement(runner.problem)


@pytest.fixture(scope="module")
def runner(coarse_mesh: Path) -> Iterator[CaseRunner]:
    with CaseRunner(coarse_mesh) as runner:
        yield runner


@pytest.mark.parametrize("observed_in", [Case(2.0, 180.0), Case(2.0, 60.0)],
                         ids=["prone", "tilted"])
def test_the_reference_of_a_loaded_shape_is_found_and_predicts_supine(
    runner: CaseRunner, observed_in: Case, tmp_path: Path
) -> None:
    X_true = runner.mesh.geometry.x.copy()
    try:
        x_observed = _deformed(runner, observed_in, X_true)
        runner.problem.set_geometry(x_observed)
        estimate = estimate_reference(runner, observed_in.material(), observed_in.gravity())
        assert estimate.converged, estimate.reason
        assert np.array_equal(runner.mesh.geometry.x, x_observed)  # put back as observed
        sag = np.linalg.norm(x_observed - X_true, axis=1).max()
        error = np.linalg.norm(estimate.X - X_true, axis=1).max()
        assert error <= min(0.01 * sag, 2e-4), (error, sag)
        # the later solves start from the previous iterate's state (the first steps, large,
        # from rest)
        assert estimate.warm_starts >= estimate.forward_solves - 3 and estimate.warm_starts

        supine = Case(2.0, 0.0)
        from_truth = _deformed(runner, supine, X_true)
        from_estimate = _deformed(runner, supine, estimate.X)
        naive = _deformed(runner, supine, x_observed)  # the imaged shape taken as stress-free
        sag_supine = np.linalg.norm(from_truth - X_true, axis=1).max()
        proper = np.linalg.norm(from_estimate - from_truth, axis=1).max()
        wrong = np.linalg.norm(naive - from_truth, axis=1).max()
        assert proper <= 0.01 * sag_supine, (proper, sag_supine)
        assert wrong > 20 * proper and wrong > 1e-3, (wrong, proper)

        # the estimate as a mesh with the same tags, read back as any mesh is
        path = write_reference_mesh(runner, estimate.X, tmp_path / "reference.xdmf")
        # ... on the observed file's node numbering: node k of each is the same material point
        mesh, _, facets = read_mesh(path)
        expected = np.empty_like(estimate.X)
        expected[np.asarray(runner.mesh.geometry.input_global_indices)] = estimate.X
        assert np.allclose(nodes_in_file_order(mesh), expected, atol=1e-12)
        assert same_cells(path, runner.mesh_path)
        assert np.array_equal(np.sort(facets.values), np.sort(runner.facet_tags.values))
    finally:
        runner.problem.set_geometry(X_true)


@pytest.fixture(scope="module")
def curved_runner(curved_coarse_mesh: Path) -> Iterator[CaseRunner]:
    """The coarse default breast with curved (order-2) cells, with contact with the chest."""
    from dataclasses import replace

    from fem.contact import Contact, chest_obstacle
    from meshes.parametric import BreastGeometry

    settings = replace(SolverSettings(), contact=Contact(chest_obstacle(BreastGeometry())))
    with CaseRunner(curved_coarse_mesh, settings) as runner:
        yield runner


@pytest.mark.parametrize("observed_in", [Case(1.0, 0.0), Case(1.0, -100.0)],
                         ids=["supine", "rolled-onto-the-chest"])
def test_on_a_curved_mesh_the_inverse_motion_solve_is_the_forward_problem_exactly(
    curved_runner: CaseRunner, observed_in: Case
) -> None:
    """With the displacement's nodes as geometry nodes, the two discrete problems are one.

    So the reference found in one inverse-motion solve reproduces the observed nodes in a
    forward solve that starts from it, within the solvers' tolerances: at Φ = −100° with the
    skin pressed on the chest (the contact term pulled to the loaded shape) as well.
    """
    runner = curved_runner
    X_true = runner.mesh.geometry.x.copy()
    try:
        x_observed = _deformed(runner, observed_in, X_true)
        force = runner.problem.contact_status()["force_N"]
        assert (force > 0) == (observed_in.phi == -100.0), force
        runner.problem.set_geometry(x_observed)
        estimate = estimate_reference(runner, observed_in.material(), observed_in.gravity())
        assert estimate.converged and estimate.inverse is not None
        assert estimate.inverse.converged, estimate.inverse.loading.reason
        # the check starts at the answer: at most one iteration to the forward stopping test
        assert estimate.forward_solves == 1 and estimate.newton_iterations[0] <= 1
        sag = np.linalg.norm(x_observed - X_true, axis=1).max()
        assert np.linalg.norm(estimate.X - X_true, axis=1).max() <= 1e-8 * sag
        assert estimate.record()["inverse_newton_iterations"] > 0
    finally:
        runner.problem.set_geometry(X_true)


def test_anderson_and_aitken_find_the_same_reference_of_a_soft_supine_shape(
    runner: CaseRunner,
) -> None:
    """The two accelerations check each other; Anderson needs fewer forward solves here."""
    X_true = runner.mesh.geometry.x.copy()
    supine = Case(1.0, 0.0)
    try:
        x_observed = _deformed(runner, supine, X_true)
        found = {}
        for method in ("anderson", "aitken"):
            runner.problem.set_geometry(x_observed)
            found[method] = estimate_reference(runner, supine.material(), supine.gravity(),
                                               tolerance=1e-6, method=method)
            assert found[method].converged and found[method].method == method
        a, b = found["anderson"], found["aitken"]
        sag = np.linalg.norm(x_observed - X_true, axis=1).max()
        assert np.linalg.norm(a.X - b.X, axis=1).max() <= 1e-4 * sag
        assert a.forward_solves < b.forward_solves and a.relaxation == []
    finally:
        runner.problem.set_geometry(X_true)


def test_a_shape_without_a_reference_in_the_budget_fails_with_its_reason(
    runner: CaseRunner,
) -> None:
    X_true = runner.mesh.geometry.x.copy()
    prone = Case(2.0, 180.0)
    try:
        x_observed = _deformed(runner, prone, X_true)
        runner.problem.set_geometry(x_observed)
        estimate = estimate_reference(runner, prone.material(), prone.gravity(),
                                      max_iterations=2, method="anderson")
        assert not estimate.converged and estimate.forward_solves == 2
        assert estimate.reason == "no reference within 2 forward solves"
        assert np.array_equal(runner.mesh.geometry.x, x_observed)
        assert estimate.misfit_m[1] < estimate.misfit_m[0]  # the best iterate is returned
    finally:
        runner.problem.set_geometry(X_true)


def test_the_command_line_writes_the_reference_mesh_and_its_record(
    runner: CaseRunner, tmp_path: Path
) -> None:
    import json

    from fem.reference import main

    X_true = runner.mesh.geometry.x.copy()
    prone = Case(2.0, 180.0)
    try:
        observed = write_reference_mesh(runner, _deformed(runner, prone, X_true),
                                        tmp_path / "prone.xdmf")
    finally:
        runner.problem.set_geometry(X_true)
    assert main([str(observed), "--c1", "2", "--phi", "180", "--out", str(tmp_path / "ref")]) == 0
    record = json.loads((tmp_path / "ref" / "reference.json").read_text())
    assert record["converged"] and record["misfit_mm"][-1] <= 1e-2
    assert record["method"] == "inverse" and record["inverse_newton_iterations"] > 0
    assert main([str(observed), "--c1", "2", "--phi", "180", "--out", str(tmp_path / "fixed"),
                 "--method", "anderson"]) == 0
    fixed = json.loads((tmp_path / "fixed" / "reference.json").read_text())
    assert fixed["method"] == "anderson" and fixed["inverse_newton_iterations"] is None
    assert fixed["forward_solves"] > record["forward_solves"]
    # one format with the workflow's record, which adds the cost and the machine
    from studies.reference_state.reference_state import ReferenceRecord

    fields = set(ReferenceRecord.__dataclass_fields__)
    assert set(record) <= fields and fields - set(record) == {"cold_forward_s", "cost", "machine"}
    mesh, _, _ = read_mesh(tmp_path / "ref" / "reference.xdmf")
    assert mesh.geometry.x.shape == X_true.shape
    assert main([str(tmp_path / "missing.xdmf"), "--c1", "2", "--phi", "180", "--out",
                 str(tmp_path / "none")]) == 2 and not (tmp_path / "none").exists()


def test_points_seen_prone_are_tracked_to_supine_through_the_reference(runner: CaseRunner) -> None:
    """Interior points seen prone, tracked to supine, land where the truth puts them.

    A point outside the body is refused by name.
    """
    from fem.exceptions import InvalidParameterError
    from fem.interpolation import evaluate
    from fem.tracking import track

    X_true = runner.mesh.geometry.x.copy()
    prone, supine = Case(2.0, 180.0), Case(2.0, 0.0)
    rng = np.random.default_rng(0)
    # material points: centroids of random cells, inside the body
    cells = rng.choice(runner.mesh.topology.index_map(3).size_local, 20, replace=False)
    nodes = runner.mesh.geometry.dofmap.array.reshape(-1, runner.mesh.geometry.dofmap.links(0).size)
    material = X_true[nodes[cells, :4]].mean(axis=1)
    try:
        runner.problem.set_geometry(X_true)
        assert runner.solve(supine)[0].converged
        truth_supine = material + evaluate(runner.problem.displacement(), material)[0]
        x_prone = _deformed(runner, prone, X_true)
        # seen in the image as the imaged mesh shows them: the same cells' centroids, prone
        seen = x_prone[nodes[cells, :4]].mean(axis=1)
        runner.problem.set_geometry(x_prone)
        estimate = estimate_reference(runner, prone.material(), prone.gravity())
        names = [f"p{i}" for i in range(len(seen))]
        tracked = track(runner, estimate.X, names, seen, supine.material(), supine.gravity())
        assert tracked.converged
        assert np.array_equal(runner.mesh.geometry.x, x_prone)
        sag = np.linalg.norm(truth_supine - material, axis=1).max()
        assert np.abs(tracked.reference - material).max() <= 0.01 * sag
        assert np.linalg.norm(tracked.target - truth_supine, axis=1).max() <= 0.01 * sag
        far = np.array([[1.0, 1.0, 1.0]])
        with pytest.raises(InvalidParameterError, match=r"1 point\(s\) lie outside .*: far \("):
            track(runner, estimate.X, ["far"], far, supine.material(), supine.gravity())
    finally:
        runner.problem.set_geometry(X_true)


def test_the_stiffness_confirmation_solves_the_c1_it_is_asked(runner: CaseRunner) -> None:
    """``fe_shape`` solves C1 as given, not rounded to a case folder's 0.01 kPa.

    The confirmation steps by less than that near its answer; two solves rounded to one C1
    gave one field twice, and its secant between them was flat.
    """
    from surrogate.stiffness import fe_shape

    shape = fe_shape(runner, 0.0)
    a, b = shape(2.4854), shape(2.4945)
    rest = shape(1000.0)  # about the unloaded shape: the sag scales as 1/C1
    sag = np.linalg.norm(a - rest, axis=1).max()
    moved = np.linalg.norm(a - b, axis=1).max()
    assert 0.002 * sag < moved < 0.01 * sag  # 1 - 2.4854 / 2.4945 = 0.0036 of the sag


@pytest.mark.workflow
def test_the_tracking_command_carries_points_by_fe_and_by_the_surrogate(
    small_run: Path, tmp_path: Path
) -> None:
    """Points seen prone go supine by both paths, from the imaged mesh and its reference.

    The small run's mesh is the true reference (its surrogate was trained on the sweep from
    it); the imaged shape is its prone solve. The FE path lands where the truth puts the
    points; the toy surrogate (two C1 values, three angles) lands near them; a model of
    another mesh and a point outside the body are refused by name.
    """
    import csv

    from fem.interpolation import evaluate
    from studies.reference_state.tracking import TrackingResult, main

    reference = small_run / "results/mesh/mesh.xdmf"
    model = small_run / "results/surrogate/model"
    runner = CaseRunner(reference)
    X_true = runner.mesh.geometry.x.copy()
    prone, supine = Case(1.0, 180.0), Case(1.0, 0.0)
    nodes = runner.mesh.geometry.dofmap.array.reshape(-1, 4)
    cells = np.random.default_rng(1).choice(len(nodes), 12, replace=False)
    material = X_true[nodes[cells]].mean(axis=1)
    assert runner.solve(supine)[0].converged
    truth = material + evaluate(runner.problem.displacement(), material)[0]
    x_prone = _deformed(runner, prone, X_true)
    imaged = write_reference_mesh(runner, x_prone, tmp_path / "imaged.xdmf")
    runner.close()
    points = tmp_path / "points.csv"
    seen = x_prone[nodes[cells]].mean(axis=1)
    points.write_text("name,x,y,z\n" + "".join(
        f"p{i},{x!r},{y!r},{z!r}\n" for i, (x, y, z) in enumerate(seen)))

    out = tmp_path / "tracking" / "points.csv"
    args = [str(points), "--imaged", str(imaged), "--reference", str(reference), "--model",
            str(model), "--c1", "1", "--phi", "0", "--out", str(out)]
    assert main(args) == 0
    rows = list(csv.DictReader(out.open()))
    assert [r["name"] for r in rows] == [f"p{i}" for i in range(len(seen))]
    fe = np.array([[float(r[f"fe_{a}_m"]) for a in "xyz"] for r in rows])
    by_surrogate = np.array([[float(r[f"surrogate_{a}_m"]) for a in "xyz"] for r in rows])
    sag = np.linalg.norm(truth - material, axis=1).max()
    assert np.linalg.norm(fe - truth, axis=1).max() <= 1e-3 * sag + 1e-6
    assert np.linalg.norm(by_surrogate - truth, axis=1).max() <= 0.25 * sag
    result = TrackingResult.read(out.with_suffix(".json"))
    assert result.surrogate_ms["points"] == len(seen) and result.surrogate_ms["median_ms"] > 0
    gaps = np.array([float(r["difference_mm"]) for r in rows])
    assert np.allclose(gaps, 1e3 * np.linalg.norm(fe - by_surrogate, axis=1), atol=1e-3)

    # the imaged mesh is not the surrogate's mesh: refused, nothing written
    other = tmp_path / "other.csv"
    assert main([*args[:4], str(imaged), *args[5:-1], str(other)]) == 2 and not other.exists()
    points.write_text("name,x,y,z\nfar,1.0,1.0,1.0\n")
    assert main([*args[:-1], str(other)]) == 2 and not other.exists()


@pytest.mark.workflow
def test_the_stiffness_is_found_from_a_noisy_second_observation(
    small_run: Path, tmp_path: Path
) -> None:
    """C1 from the skin of a supine FE solve with 0.5 mm noise: within 5 %, in its interval.

    The small run's toy surrogate (two C1 values) searches; FE confirms, so the estimate does
    not rest on the surrogate's accuracy. A 95 % interval misses the truth in one draw of the
    noise in twenty, so six draws are taken: every estimate within 5 %, and at least five of
    the six intervals holding the truth (a 97 % event for a true 95 % interval; one draw, the
    first, has the truth 0.5 % above its interval). An observation in other units, or in other
    axes, is refused by name.
    """
    from studies.reference_state.stiffness import Estimator, main
    from studies.reference_state.tracking import TrackingInputError
    from surrogate.stiffness import StiffnessError

    reference = small_run / "results/mesh/mesh.xdmf"
    model = small_run / "results/surrogate/model"
    estimator = Estimator(reference, model, SolverSettings())
    skin = estimator.skin_of_solve(2.5, 0.0, 0.0)
    held = 0
    for seed in range(3, 9):
        observed = skin + np.random.default_rng(seed).normal(scale=5e-4, size=skin.shape)
        result = estimator.estimate(observed, 0.0, 0.0, "test", truth=2.5)
        assert abs(result.C1_kPa / 2.5 - 1) <= 0.05 and result.converged
        lo, hi = result.interval_kPa
        held += lo <= 2.5 <= hi
        assert hi / lo < 1.2
        assert 0.3 < result.rms_mm < 0.7  # the noise's normal component, 0.5 mm
    assert held >= 5

    points = tmp_path / "scan.csv"
    points.write_text("name,x,y,z\n" + "".join(
        f"s{i},{x!r},{y!r},{z!r}\n" for i, (x, y, z) in enumerate(observed)))
    out = tmp_path / "stiffness"
    args = [str(points), "--reference", str(reference), "--model", str(model), "--phi", "0",
            "--out", str(out)]
    assert main(args) == 0
    assert (out / "misfit.png").stat().st_size > 0 and (out / "stiffness.json").is_file()

    with pytest.raises(StiffnessError, match="units"):
        estimator.estimate(1e3 * observed, 0.0, 0.0, "in mm, read as m", fe=False)
    with pytest.raises(StiffnessError, match="axes"):
        estimator.estimate(observed[:, [1, 0, 2]], 0.0, 0.0, "x and y swapped", fe=False)
    with pytest.raises(TrackingInputError, match="another mesh"):
        Estimator(small_run / "results/fe_study/meshes/g=0.0400_m=0.0300_o=1/mesh.xdmf", model,
                  SolverSettings())
    estimator.close()


@pytest.mark.workflow
def test_the_workflow_runs_from_an_imaged_mesh_to_tracked_points_and_the_stiffness(
    tmp_path: Path,
) -> None:
    """With reference_state.imaged the chain runs from the imaged shape to points and C1.

    The mesh rule writes the imaged shape, rule reference_state its reference (the sweep's
    mesh), then tracking and the stiffness run on the surrogate trained on that sweep.

    The coarse test breast is taken as imaged prone at C1 = 1 kPa (a C1 of the toy sweep, so
    that its surrogate answers within its validation error). Points are cell centroids of the
    imaged mesh; the second observation is the skin of an FE solve on the reference at
    C1 = 2.5 kPa, supine, with 0.5 mm of noise.
    """
    import json
    import re

    import yaml

    from studies.reference_state.reference_state import ReferenceRecord
    from studies.reference_state.stiffness import Estimator, StiffnessResult
    from studies.reference_state.tracking import TrackingResult
    from surrogate.export import decode_array
    from tests.conftest import REPO, snakemake

    config = yaml.safe_load((REPO / "tests" / "config.yaml").read_text())
    config["reference_state"].update({
        "imaged": {"C1_kPa": 1.0, "phi": 180.0},
        "points": {"tumour": {"file": "tumour.csv", "phi": 0.0}},
        "observation": {"file": "scan.csv", "phi": 0.0},
    })
    path = tmp_path / "imaged.yaml"
    path.write_text(yaml.safe_dump(config))

    run = snakemake(tmp_path, "-j2", "results/mesh/imaged.xdmf", config=path)
    assert run.returncode == 0, run.stderr[-3000:]
    mesh, _, _ = read_mesh(tmp_path / "results/mesh/imaged.xdmf")
    nodes = mesh.geometry.x[mesh.geometry.dofmap.array.reshape(-1, 4)]
    centroids = nodes[::max(1, len(nodes) // 5)].mean(axis=1)[:5]
    (tmp_path / "tumour.csv").write_text("name,x,y,z\n" + "".join(
        f"t{i},{x!r},{y!r},{z!r}\n" for i, (x, y, z) in enumerate(centroids)))
    run = snakemake(tmp_path, "-j2", "results/tracking/tumour.csv", "results/viewer/index.html",
                    config=path)
    assert run.returncode == 0, run.stderr[-3000:]

    record = ReferenceRecord.read(tmp_path / "results/mesh/reference.json")
    assert record.converged and record.misfit_mm[-1] <= 0.01 and record.cost > 1
    assert same_cells(tmp_path / "results/mesh/imaged.xdmf", tmp_path / "results/mesh/mesh.xdmf")
    tracked = TrackingResult.read(tmp_path / "results/tracking/tumour.json")
    moved = np.linalg.norm(np.subtract(tracked.fe, tracked.observed), axis=1)
    assert tracked.names == [f"t{i}" for i in range(5)] and moved.max() > 1e-3
    # the toy surrogate answers within a few times its validation error off the rib, where the
    # points lie (a unit or pairing error would be tens of millimetres off). Its error over all
    # points, the rib's fixed ones among them, is lower: on one machine of this kind the same
    # test's training put a point at 3.1 times that, on another under 3
    from surrogate.predict import Surrogate

    model = Surrogate.load(tmp_path / "results/surrogate/model")
    assert max(tracked.difference_mm) <= 3 * model.metrics["validation_error_domain_mm"]
    # the 3D view carries the tracked points at their material positions, named by their set
    page = (tmp_path / "results/viewer/index.html").read_text()
    data = json.loads(re.search(r'id="viewer-data"[^>]*>(.*?)</script>', page, re.S).group(1))
    assert data["inner"]["names"] == [f"tumour: t{i}" for i in range(5)]
    np.testing.assert_allclose(decode_array(data["inner"]["model"]["X_m"]), tracked.reference,
                               atol=1e-6)
    # and it measures movement from the posture the breast was imaged in: at the tracked
    # posture, the table gives each point's way from where the image saw it (the surrogate's)
    assert data["starts"][-1] == {"name": "as imaged", "phi": 180.0, "theta": 0.0,
                                  "selected": True}
    from studies.surrogate_study.browser import open_page

    moved = (model.at(tracked.reference).predict(1.0, 0.0)
             - model.at(tracked.reference).predict(1.0, 180.0))
    with open_page(tmp_path / "results/viewer/index.html",
                   ready="window.viewer && window.viewer.ready") as (page, errors, _):
        state = page.evaluate("window.viewer.state()")  # opened at the tracked posture
        assert (state["start"], state["C1"], state["phi"]) == ("as imaged", 1.0, 0.0)
        sizes = [float(r[1]) for r in page.evaluate("window.viewer.pointRows()")]
        np.testing.assert_allclose(sizes, np.linalg.norm(moved, axis=1), atol=0.006)
        assert not errors

    with Estimator(tmp_path / "results/mesh/mesh.xdmf", tmp_path / "results/surrogate/model",
                   SolverSettings()) as estimator:
        skin = estimator.skin_of_solve(2.5, 0.0, 0.0)
    skin += np.random.default_rng(0).normal(scale=5e-4, size=skin.shape)
    (tmp_path / "scan.csv").write_text("name,x,y,z\n" + "".join(
        f"s{i},{x!r},{y!r},{z!r}\n" for i, (x, y, z) in enumerate(skin)))
    run = snakemake(tmp_path, "-j2", "results/stiffness/stiffness.json", config=path)
    assert run.returncode == 0, run.stderr[-3000:]
    found = StiffnessResult.read(tmp_path / "results/stiffness/stiffness.json")
    assert abs(found.C1_kPa / 2.5 - 1) <= 0.05
    assert (tmp_path / "results/stiffness/misfit.png").stat().st_size > 0

    # the report's section shows the chain's results
    from report.context import Context
    from report.sections.reference import _imaged

    ctx = Context.load({
        "reference_record": str(tmp_path / "results/mesh/reference.json"),
        "tracking": [str(tmp_path / "results/tracking/tumour.json")],
        "stiffness": str(tmp_path / "results/stiffness/stiffness.json"),
    }, tmp_path / "report", [])
    (tmp_path / "report").mkdir()
    html = "".join(_imaged(ctx))
    assert f"{record.forward_solves} forward solves" in html
    assert f"one inverse-motion solve ({record.inverse_newton_iterations} Newton iterations" in html
    assert 'id="tracking-tumour"' in html and "stiffness_misfit.png" in html
