"""The Siamese MLP: data checks, loss, one short training, save/load, bad input."""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np
import pytest

from fem.aggregate import build_dataset
from fem.case_files import write_points
from fem.sweep import Case
from surrogate.config import SurrogateConfig, SurrogateConfigError

pytestmark = pytest.mark.unit

N = 200


def _field(X: np.ndarray, C1: float, phi: float) -> np.ndarray:
    """A smooth displacement (m) that vanishes on x = 0 and scales with 1/C1, like gravity sag."""
    g = np.array([np.cos(np.radians(phi)), np.sin(np.radians(phi)), 0.0])
    return 0.01 / C1 * X[:, :1] ** 2 * (g + 0.3 * np.roll(g, 1) * X[:, 1:2])


@pytest.fixture(scope="module")
def dataset_path(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("ds")
    rng = np.random.default_rng(0)
    X = rng.uniform(0, 1, size=(N, 3))
    X[:20, 0] = 0.0  # a clamped 'rib' at x = 0
    fixed = X[:, 0] == 0.0
    summaries, points = [], []
    for C1 in (1.0, 2.0, 3.0, 4.0, 5.0):
        for phi in (0.0, 90.0, 180.0, -90.0):
            case = folder / Case(C1, phi).id
            case.mkdir()
            write_points(case / "points.h5", np.arange(N), X, _field(X, C1, phi), fixed, case.name)
            (case / "summary.json").write_text(json.dumps({
                "status": "converged", "case": case.name, "C1": C1, "phi": phi, "theta": 0.0,
                "gravity_vector": [0, 0, 0], "load_fraction": 1.0}))
            summaries.append(case / "summary.json")
            points.append(case / "points.h5")
    build_dataset(summaries, points, folder / "dataset.h5")
    return folder / "dataset.h5"


def test_config_validation_names_the_key() -> None:
    with pytest.raises(SurrogateConfigError, match="surrogate.width"):
        SurrogateConfig(width=0)
    with pytest.raises(SurrogateConfigError, match="unknown surrogate parameter"):
        SurrogateConfig.from_mapping({"widht": 3})
    with pytest.raises(SurrogateConfigError, match="point_features needs structure: separable"):
        SurrogateConfig(point_features=4)
    for bad in ({"point_features": -1}, {"point_features": True}, {"point_frequency": 0.0},
                {"point_frequency": True}):
        with pytest.raises(SurrogateConfigError, match=f"surrogate.{next(iter(bad))}"):
            SurrogateConfig(structure="separable", **bad)


def test_fourier_features_are_the_points_sines_and_cosines() -> None:
    """``point_inputs``: X, then sin and cos of 2π X·b, with b drawn from the seed alone."""
    from surrogate.structures import structure_for

    config = SurrogateConfig(structure="separable", point_features=5, point_frequency=3.0)
    structure = structure_for(config)
    b = structure.point_frequencies()
    assert b.shape == (3, 5) and np.array_equal(b, structure.point_frequencies())
    assert not np.array_equal(b, structure_for(config.replace(seed=1)).point_frequencies())
    x = np.array([[0.1, -0.2, 0.3], [1.0, 0.0, -1.0]], np.float32)
    z = 2 * np.pi * x @ b
    expected = np.concatenate([x, np.sin(z), np.cos(z)], axis=1)
    assert np.allclose(np.asarray(structure.point_inputs(x)), expected, atol=1e-5)
    assert structure.layer_sizes()[0] == 13 and structure.layer_sizes("branch")[0] == 4
    plain = structure_for(config.replace(point_features=0))
    assert plain.point_frequencies() is None and plain.point_inputs(x) is x


def test_loss_is_eq2() -> None:
    import jax.numpy as jnp

    from surrogate.structures import structure_for

    config = SurrogateConfig(hidden_layers=1, width=4, alpha=10.0, activation="tanh")
    structure = structure_for(config)
    params = structure.init_params(__import__("jax").random.PRNGKey(0))
    # zero the output layers: predictions are 0, so the loss is the weighted mean target norm
    for net in params:
        W, b = params[net][-1]
        params[net][-1] = (W * 0, b * 0)
    x = jnp.zeros((3, 7))
    y = jnp.array([[3.0, 4.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])
    b = jnp.array([False, False, True])
    value = structure.loss(params, x, y, b, jnp.ones(3))
    assert float(value) == pytest.approx((5.0 + 1.0 + 10.0 * 1.0) / 3, rel=1e-5)


def test_a_gravity_linear_network_is_a_matrix_times_the_gravity_direction() -> None:
    """With M blind to ĝ (its direction weights zeroed), u(ĝ) = Σ_j ĝ_j u(e_j) exactly.

    A ``vector`` network blind to ĝ predicts one displacement for every direction, so the
    superposition fails there: the test tells the forms apart.
    """
    import jax
    import jax.numpy as jnp

    from surrogate.data import DIRECTION
    from surrogate.structures import structure_for

    rng = np.random.default_rng(3)
    points = rng.normal(size=(5, 3))
    g = np.array([0.48, -0.6, 0.64])  # a unit direction
    for form, superposes in (("gravity_linear", True), ("vector", False)):
        config = SurrogateConfig(hidden_layers=2, width=8, activation="silu", output_form=form)
        structure = structure_for(config)
        assert structure.layer_sizes()[-1] == (9 if form == "gravity_linear" else 3)
        params = structure.init_params(jax.random.PRNGKey(1))
        W, b = params["domain"][0]
        params["domain"][0] = (W.at[DIRECTION].set(0.0), b + 0.1)
        params["domain"][-1] = tuple(a + 0.05 for a in params["domain"][-1])  # nonzero bias

        def u(direction: np.ndarray, params=params, structure=structure) -> np.ndarray:
            x = np.concatenate([points, np.full((5, 1), 0.3), np.tile(direction, (5, 1))], 1)
            return np.asarray(structure.apply(params, jnp.asarray(x, jnp.float32),
                                              jnp.zeros(5, bool), jnp.ones(5)))

        superposed = sum(g[j] * u(np.eye(3)[j]) for j in range(3))
        assert np.allclose(u(g), superposed, atol=1e-6) == superposes, form


@pytest.mark.parametrize("boundary", ["network", "shared", "exact"])
def test_a_separable_model_trains_on_whole_cases_with_the_loss_of_eq2(
    dataset_path: Path, boundary: str
) -> None:
    """The whole-case loss of a separable model is Eq. 2 over the same samples.

    ``grid_loss`` (point networks once per point, branch once per case) equals ``split_loss``
    on the samples one by one (both networks at every sample, α on the rib), for the by-sample
    split's training samples of three cases; and the gathered evaluation equals the direct one.
    """
    import jax
    import jax.numpy as jnp

    from fem.dataset import read_dataset
    from studies.surrogate_study.architecture import count_parameters
    from surrogate.data import tables
    from surrogate.structures import structure_for
    from surrogate.structures.pointwise import PART_FIELDS
    from surrogate.structures.separable import case_grid, grid_loss, point_order
    from surrogate.train import prepare

    ds = read_dataset(dataset_path)
    config = SurrogateConfig(hidden_layers=2, width=8, activation="silu", alpha=3.0, modes=4,
                             structure="separable", output_form="gravity_linear",
                             output_scaling="compliance", boundary=boundary)
    structure = structure_for(config)
    params = structure.init_params(jax.random.PRNGKey(2))
    assert count_parameters(config.as_dict()) == sum(
        W.size + b.size for layers in params.values() for W, b in layers)
    norm, _, train, _, _ = prepare(ds, config)
    train = train.subset(np.isin(train.case, np.unique(train.case)[:3]))
    use_rib = boundary != "exact"
    inputs = tables(ds, norm)
    grid = case_grid(train, ds.n_points, use_rib)
    assert len(grid[0]) == 3 and grid[3].sum() == (len(train) if use_rib else
                                                   np.sum(~train.boundary))
    whole = grid_loss(params, tuple(jnp.asarray(a) for a in grid), inputs,
                      point_order(ds.boundary), structure)

    def part(mask: np.ndarray) -> tuple:
        return tuple(jnp.asarray(getattr(train.subset(mask), f)) for f in PART_FIELDS)

    one_by_one = structure.split_loss(params, part(~train.boundary),
                                      part(train.boundary) if use_rib else None)
    assert float(whole) == pytest.approx(float(one_by_one), rel=1e-5)
    domain = part(~train.boundary)
    np.testing.assert_allclose(structure.samples_network(params, "domain", domain, inputs),
                               structure.network(params, "domain", domain[0]), atol=1e-5)


def test_training_reduces_the_loss_and_round_trips(dataset_path: Path, tmp_path: Path) -> None:
    from fem.dataset import read_dataset
    from surrogate.checkpoint import save_model
    from surrogate.predict import Surrogate
    from surrogate.train import train_and_evaluate

    ds = read_dataset(dataset_path)
    config = SurrogateConfig(hidden_layers=2, width=16, batch_size=256, max_epochs=40, patience=40)
    result = train_and_evaluate(ds, config, progress=False)
    losses = [h["validation_loss"] for h in result.history]
    assert losses[-1] < 0.5 * losses[0]
    assert result.best_validation_loss == min(losses)
    save_model(tmp_path / "model", result, ds)
    model = Surrogate.load(tmp_path / "model")
    u = model.predict(3.0, 90.0)
    assert u.shape == (N, 3)
    case = ds.case_index(3.0, 90.0)
    assert np.mean(np.linalg.norm(u - ds.displacement[case], axis=1)) < 0.5 * np.mean(
        np.linalg.norm(ds.displacement[case], axis=1)
    )
    # the same weights give the same prediction after reloading
    np.testing.assert_allclose(Surrogate.load(tmp_path / "model").predict(3.0, 90.0), u, rtol=1e-6)


def test_bad_inputs_are_named(dataset_path: Path, tmp_path: Path) -> None:
    from fem.dataset import read_dataset
    from fem.exceptions import DatasetError
    from surrogate.checkpoint import save_model
    from surrogate.exceptions import ExtrapolationWarning, ModelFileError
    from surrogate.predict import Surrogate
    from surrogate.train import train_and_evaluate

    ds = read_dataset(dataset_path)
    result = train_and_evaluate(
        ds, SurrogateConfig(hidden_layers=1, width=4, max_epochs=1), progress=False
    )
    save_model(tmp_path / "m", result, ds)
    model = Surrogate.load(tmp_path / "m")
    with pytest.raises(ValueError, match="C1 must be a finite number"):
        model.predict(float("nan"), 0.0)
    with pytest.raises(ValueError, match="phi must be a finite number"):
        model.predict(1.0, float("inf"))
    with pytest.warns(ExtrapolationWarning, match="outside the training range"):
        model.predict(9.0, 0.0)
    # a model file from another architecture
    meta = json.loads((tmp_path / "m" / "model.json").read_text())
    meta["config"]["width"] = 8
    (tmp_path / "m" / "model.json").write_text(json.dumps(meta))
    with pytest.raises(ModelFileError, match="1x8"):
        Surrogate.load(tmp_path / "m")
    # a dataset with NaN in a converged case, and one without a split
    broken = tmp_path / "broken.h5"
    broken.write_bytes(dataset_path.read_bytes())
    with h5py.File(broken, "a") as h5:
        h5["displacement"][0, 0, 0] = np.nan
    with pytest.raises(DatasetError, match="NaN"):
        read_dataset(broken)
    broken.write_bytes(dataset_path.read_bytes())
    with h5py.File(broken, "a") as h5:
        del h5["splits/by_case/validation"]
    with pytest.raises(DatasetError, match="by_case/validation"):
        read_dataset(broken)


def test_prediction_warns_where_the_sweep_did_not_converge(
    dataset_path: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A model knows the sweep's failed cases and warns at or below their C1 beside their Φ.

    save_model records them; copy_model (the workflow's selection) records them from the
    dataset in the copy of a run saved without them.
    """
    import dataclasses
    import warnings

    from fem.dataset import read_dataset
    from studies.surrogate_study.architecture import copy_model
    from surrogate.checkpoint import save_model
    from surrogate.exceptions import ExtrapolationWarning
    from surrogate.predict import Surrogate
    from surrogate.train import train_and_evaluate

    ds = read_dataset(dataset_path)
    result = train_and_evaluate(
        ds, SurrogateConfig(hidden_layers=1, width=4, max_epochs=1), progress=False
    )
    converged = ds.converged.copy()
    converged[[ds.case_index(1.0, -90.0), ds.case_index(2.0, -90.0)]] = False
    failed = dataclasses.replace(ds, converged=converged)
    save_model(tmp_path / "saved", result, failed)
    save_model(tmp_path / "run", result, ds)
    assert Surrogate.load(tmp_path / "run").training_range["unconverged"] == []
    copy_model(tmp_path / "run", tmp_path / "copied", dataset=failed)
    for folder in ("saved", "copied"):
        model = Surrogate.load(tmp_path / folder)
        assert sorted(model.training_range["unconverged"]) == [[1.0, -90.0, 0.0], [2.0, -90.0, 0.0]]
    with pytest.raises(ValueError, match="not trained on this dataset"):
        copy_model(
            tmp_path / "run", tmp_path / "other", dataset=dataclasses.replace(ds, X=ds.X[:10])
        )
    # at the failed angle, and between it and its neighbours (0° and 180°), up to 2 kPa
    for C1, phi in ((2.0, -90.0), (1.5, 270.0), (1.2, -45.0), (2.0, -135.0)):
        with pytest.warns(ExtrapolationWarning, match="did not converge at C1 = 2 kPa, Φ = -90°"):
            model.predict(C1, phi)
    # the same directions under other names: (90°, θ = 180°) is (-90°, 0°), θ = 360° is θ = 0°;
    # the plane judges them by its own name, and the θ of a direction in it is no extrapolation
    assert model.trained.plane_name(90.0, 180.0) == (-90.0, 0.0)
    assert model.trained.plane_name(45.0, 360.0) == (45.0, 0.0)
    assert model.trained.plane_name(90.0, 20.0) == (90.0, 20.0)
    with pytest.warns(ExtrapolationWarning) as caught:
        model.predict(2.0, 90.0, 180.0)
    assert [str(w.message) for w in caught] == [
        "the sweep's FE solve did not converge at C1 = 2 kPa, Φ = -90° (beside C1 = 2.0 kPa, "
        "Φ = 90.0°, θ = 180.0°), so no FE solution backs C1 ≤ 2 kPa there; the prediction is "
        "an extrapolation"]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for C1, phi, theta in ((2.5, 90.0, 180.0), (1.0, -90.0, 180.0), (1.0, 45.0, 360.0),
                               (1.0, 180.0, 180.0)):
            model.predict(C1, phi, theta)
    with pytest.warns(ExtrapolationWarning, match="trained at θ = 0.0° only"):
        model.predict(2.5, 90.0, 20.0)
    # the copy keeps the run's record of each angle's softest trained C1 (1 kPa at -90°, from
    # the dataset it was saved with): stiffer than every failure, or beside angles without
    # failures, it does not warn
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for C1, phi in ((2.5, -90.0), (1.0, 90.0), (1.0, 45.0), (1.0, 0.0)):
            model.predict(C1, phi)
    # saved with the failures, the model knows that -90° was solved from 3 kPa only
    saved = Surrogate.load(tmp_path / "saved")
    for C1, phi in ((2.5, -90.0), (2.5, -45.0)):
        with pytest.warns(ExtrapolationWarning, match=r"softest FE solution at Φ = -90° \(beside "
                          rf"C1 = {C1} kPa, Φ = {phi}°, θ = 0.0°\) is at C1 = 3 kPa"):
            saved.predict(C1, phi)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for C1, phi in ((3.0, -90.0), (1.0, 90.0), (1.0, 45.0)):
            saved.predict(C1, phi)
    # studies.surrogate_study.warning_coverage on the plane: Φ drawn evenly, half of it beside
    # -90°; there
    # the failures warn up to 2 kPa and the softest solution (3 kPa) above it
    from studies.surrogate_study.warning_coverage import KINDS, warning_coverage

    coverage = warning_coverage(saved, draws=4000, seed=2, edges=(2.0, 3.0))
    assert coverage.queries == coverage.drawn == 4000 and coverage.kinds[KINDS[2]] == 0
    below_failure, below_softest, stiffer = coverage.bands
    assert (below_failure.c1_low, below_softest.c1_low, stiffer.c1_high) == (1.0, 2.0, 5.0)
    assert below_failure.warned == coverage.kinds[KINDS[0]]
    assert below_softest.warned == coverage.kinds[KINDS[1]]
    assert stiffer.warned == 0
    assert 0.4 < below_failure.share < 0.6 and 0.4 < below_softest.share < 0.6
    from studies.surrogate_study.warning_coverage import WarningCoverage, main

    assert main([str(tmp_path / "saved"), "--draws", "4000", "--seed", "2", "--bands", "2",
                 "3", "--json", str(tmp_path / "coverage.json")]) == 0
    out = capsys.readouterr().out
    assert f"warned: {coverage.warned} ({100 * coverage.share:.2f} %)" in out
    assert f"beside a failed FE solve: {coverage.kinds[KINDS[0]]}" in out
    # the workflow's file (rule warning_coverage) reads back as the same result, and the
    # report's table gives each band's count and share, the last band closed at 5 kPa
    assert WarningCoverage.read(tmp_path / "coverage.json") == coverage
    from report.context import Context
    from report.sections.generalisation import warning_coverage_part

    page = warning_coverage_part(Context(out_dir=tmp_path, clinical=[], paths={},
                                         clinical_fields=[],
                                         results={"warning_coverage": coverage}))
    assert (f"<td>[1, 2)</td><td>{below_failure.queries}</td><td>{below_failure.warned}</td>"
            f"<td>{100 * below_failure.share:.2f}</td>") in page
    assert f"<td>[3, 5]</td><td>{stiffer.queries}</td><td>0</td><td>0.00</td>" in page
    assert f"<td>all</td><td>4000</td><td>{coverage.warned}</td>" in page
    assert main([str(tmp_path / "missing")]) == 2
    assert "error:" in capsys.readouterr().err


def test_a_model_of_the_caudal_half_warns_by_direction(tmp_path: Path) -> None:
    """Trained off the plane, a model judges a query by its direction.

    Between the sweep's directions it answers quietly whatever Φ's sign; head-down is outside;
    near a failed case, at or below its C1, it warns.
    """
    import dataclasses
    import warnings

    from fem.dataset import read_dataset
    from fem.sweep import sphere_directions
    from studies.surrogate_study.held_out import warns
    from studies.surrogate_study.surrogate_evaluation import extrapolation_kind
    from surrogate.checkpoint import save_model
    from surrogate.exceptions import ExtrapolationWarning
    from surrogate.predict import Surrogate
    from surrogate.train import train_and_evaluate
    from surrogate.training_range import _unit_directions

    rng = np.random.default_rng(0)
    X = rng.uniform(0, 1, size=(N, 3))
    X[:20, 0] = 0.0
    summaries, points = [], []
    for C1 in (1.0, 3.0):
        for phi, theta in sphere_directions(32, "caudal"):
            case = tmp_path / "cases" / Case(C1, phi, theta).id
            case.mkdir(parents=True)
            write_points(case / "points.h5", np.arange(N), X, _field(X, C1, phi), X[:, 0] == 0,
                         case.name)
            (case / "summary.json").write_text(json.dumps({
                "status": "converged", "case": case.name, "C1": C1, "phi": phi, "theta": theta,
                "gravity_vector": [0, 0, 0], "load_fraction": 1.0}))
            summaries.append(case / "summary.json")
            points.append(case / "points.h5")
    build_dataset(summaries, points, tmp_path / "ds.h5")
    ds = read_dataset(tmp_path / "ds.h5")
    result = train_and_evaluate(
        ds, SurrogateConfig(hidden_layers=1, width=4, max_epochs=1), progress=False
    )
    save_model(tmp_path / "model", result, ds)
    model = Surrogate.load(tmp_path / "model")
    checks = model.trained.range_checks()
    assert checks["phi_gap"] is None and len(checks["directions"]) == 32
    assert 20 < checks["direction_spacing_deg"] < 30  # 32 directions over a half sphere
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        # supine, prone, tilted either way, standing, reclined: all in the caudal half
        for phi, theta in ((0.0, 0.0), (180.0, 0.0), (-30.0, 0.0), (30.0, 0.0),
                           (90.0, -90.0), (45.0, -90.0)):
            model.predict(2.0, phi, theta)
    with pytest.warns(ExtrapolationWarning, match=r"gravity at Φ = 90.0°, θ = 90.0° is \d+° from "
                      r"the nearest training direction \(they are \d+° apart\)"):
        model.predict(2.0, 90.0, 90.0)  # head down
    # a failed case warns the queries within the directions' typical spacing of it, at or
    # below its C1 (here the direction nearest standing, at C1 = 1 kPa)
    nearest = max(sphere_directions(32, "caudal"),
                  key=lambda d: float(_unit_directions([d])[0] @ [0.0, 0.0, -1.0]))
    converged = ds.converged.copy()
    converged[ds.case_index(1.0, *nearest)] = False
    save_model(tmp_path / "failed", result, dataclasses.replace(ds, converged=converged))
    failed = Surrogate.load(tmp_path / "failed")
    with pytest.warns(ExtrapolationWarning, match=rf"did not converge at C1 = 1 kPa, Φ = "
                      rf"{nearest[0]:g}°, θ = {nearest[1]:g}° \(beside C1 = 1.0 kPa, Φ = 90.0°"):
        failed.predict(1.0, 90.0, -90.0)  # standing
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        failed.predict(3.0, 90.0, -90.0)  # the softest solved C1 there
        failed.predict(1.0, 0.0, 0.0)  # supine: far from it
    # stiffer than the failure but softer than the softest solution there: still unbacked
    with pytest.warns(ExtrapolationWarning, match=rf"softest FE solution at Φ = {nearest[0]:g}°, "
                      rf"θ = {nearest[1]:g}° \(beside C1 = 1.5 kPa, Φ = 90.0°, θ = -90.0°\) is at "
                      r"C1 = 3 kPa, so no FE solution backs C1 < 3 kPa there"):
        failed.predict(1.5, 90.0, -90.0)
    # a direction the model was never trained on at 1 kPa (as a by-C1 held-out model's
    # training cases leave it) warns below its softest trained C1 alone, though 1 kPa is inside
    # the model's C1 range
    band = dataclasses.replace(result, train_cases=np.setdiff1d(
        result.train_cases, [ds.case_index(1.0, *nearest)]))
    save_model(tmp_path / "band", band, ds)
    banded = Surrogate.load(tmp_path / "band")
    assert banded.trained.range_checks()["c1_kPa"] == [1.0, 3.0]
    assert banded.trained.softest_beside(1.0, 90.0, -90.0) == (3.0, *nearest)
    assert banded.trained.softest_beside(3.0, 90.0, -90.0) is None
    assert extrapolation_kind(banded, 1.0, *nearest) == "C1 below its direction's range"
    assert extrapolation_kind(banded, 1.0, 0.0, 0.0) == "in range"
    assert warns(banded, ds, ds.case_index(1.0, *nearest))  # what the held-out study records
    assert not warns(banded, ds, ds.case_index(3.0, *nearest))
    with pytest.warns(ExtrapolationWarning, match=r"is at C1 = 3 kPa") as caught:
        banded.predict(1.0, *nearest)
    assert len(caught) == 1
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        banded.predict(3.0, *nearest)
        banded.predict(1.0, 0.0, 0.0)

    # studies.surrogate_study.warning_coverage: the share of the trained range each model warns at,
    # by drawing
    # queries over it. The model without a failure warns nowhere inside its directions; both
    # others warn below 3 kPa beside the one direction whose softest solution is 3 kPa (the
    # failed model's 1 kPa failure itself backs no query: C1 = 1 kPa exactly has no measure)
    from studies.surrogate_study.warning_coverage import KINDS, warning_coverage

    clear = warning_coverage(model, draws=3000, seed=1)
    assert clear.warned == 0 and 0.3 < clear.queries / clear.drawn < 0.8  # the caudal half
    with_failure = warning_coverage(failed, draws=3000, seed=1)
    without_solve = warning_coverage(banded, draws=3000, seed=1)
    assert with_failure.queries == without_solve.queries == clear.queries
    assert with_failure.warned == without_solve.warned == with_failure.kinds[KINDS[1]]
    # beside: within one spacing (about 25°) of one of 32 directions over the caudal half
    assert 0.01 < with_failure.share < 0.2
    assert sum(b.queries for b in with_failure.bands) == with_failure.queries
    assert sum(b.warned for b in with_failure.bands) == with_failure.warned
    assert [(b.c1_low, b.c1_high) for b in with_failure.bands] == [(1.0, 1.2), (1.2, 2.0),
                                                                    (2.0, 3.0)]


def test_selection_takes_the_most_accurate_architecture_within_the_prediction_budget() -> None:
    from studies.surrogate_study.architecture import (
        StudyError,
        architecture_table,
        select_architecture,
    )

    runs = [
        {
            "folder": f"{arch}/r{r}",
            "architecture": arch,
            "seed": r,
            "boundary": "network",
            "split": "by_sample",
            "validation_error_mm": err + 0.01 * r,
            "validation_error_domain_mm": err,
            "train_s": 1.0,
            "compile_s": 0.1,
            "epochs": 10,
            "best_epoch": 9,
            "parameters": 1,
        }
        for arch, err in (("2x32", 0.3), ("3x32", 0.2), ("3x128", 0.1))
        for r in (0, 1)
    ]
    table = architecture_table(runs)
    assert table["selected_architecture"] == "3x128" and table["prediction_budget_ms"] is None
    for arch, ms in (("2x32", 0.2), ("3x32", 0.4), ("3x128", 2.0)):
        table["rows"][arch]["predict_one_core"] = {"api": {"median_ms": ms}}
    select_architecture(table, 0.5)
    assert table["selected_architecture"] == "3x32" and table["selected_run"] == "3x32/r0"
    assert table["most_accurate_architecture"] == "3x128"
    assert not table["rows"]["3x128"]["within_prediction_budget"]
    select_architecture(table, 0.1)  # nothing fits: the fastest, and the rule says so
    assert table["selected_architecture"] == "2x32" and "no architecture" in table["rule"]
    del table["rows"]["2x32"]["predict_one_core"]
    with pytest.raises(StudyError, match="2x32"):
        select_architecture(table, 0.5)


def test_the_repeats_train_only_where_the_first_runs_are_close(tmp_path: Path) -> None:
    """surrogate_study.repeat_within: repeats for the architectures near the best first run."""
    from studies.surrogate_study.architecture import RepeatPlan, StudyError, plan_repeats

    first = [{"folder": f"{a}/r0", "architecture": a, "validation_error_mm": e}
             for a, e in (("2x32", 0.0045), ("3x128", 0.00274), ("4x64", 0.00276),
                          ("4x128", 0.0025))]
    plan = plan_repeats(first, 3, 0.1)  # the bound is 0.00275 mm
    assert plan.runs == {"2x32": 1, "3x128": 3, "4x64": 1, "4x128": 3}
    assert plan.folders("S", "model.json") == [
        "S/2x32/r0/model.json", "S/3x128/r0/model.json", "S/3x128/r1/model.json",
        "S/3x128/r2/model.json", "S/4x64/r0/model.json", "S/4x128/r0/model.json",
        "S/4x128/r1/model.json", "S/4x128/r2/model.json"]
    assert set(plan_repeats(first, 3, None).runs.values()) == {3}  # the paper's protocol
    assert plan_repeats(first, 3, 0.0).runs == {"2x32": 1, "3x128": 1, "4x64": 1, "4x128": 3}
    plan.write(tmp_path / "repeats.json")
    assert RepeatPlan.read(tmp_path / "repeats.json") == plan
    with pytest.raises(StudyError, match="non-finite"):
        plan_repeats([*first, {"folder": "x", "architecture": "5x5",
                               "validation_error_mm": float("nan")}], 2, 0.1)
    with pytest.raises(StudyError, match="two first runs of 2x32"):
        plan_repeats([*first, first[0]], 2, 0.1)
    with pytest.raises(StudyError, match="no runs"):
        plan_repeats([], 2, 0.1)


def test_train_command_line_trains_saves_and_names_bad_settings(
    dataset_path: Path,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture,
) -> None:
    from surrogate.cli import main
    from surrogate.predict import Surrogate

    monkeypatch.setenv("XLA_FLAGS", "")  # main() sets its one-core flags; keep them to this test
    config = tmp_path / "config.yaml"
    config.write_text("surrogate: {hidden_layers: 1, width: 4, batch_size: 64}\n")
    args = [
        "train",
        str(dataset_path),
        "--config",
        str(config),
        "--set",
        "max_epochs=2",
        "--set",
        "activation=silu",
    ]
    assert main([*args, "--out", str(tmp_path / "m")]) == 0
    printed = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert printed["architecture"] == "1x4" and printed["epochs"] == 2
    assert printed["overrides"] == {"max_epochs": 2, "activation": "silu"}
    assert np.isfinite(printed["validation_error_mm"])
    assert Surrogate.load(tmp_path / "m").predict(2.0, 90.0).shape == (N, 3)
    # ... and the model answers from the command line, as the API does
    capsys.readouterr()
    assert (
        main(
            [
                "predict",
                str(tmp_path / "m"),
                "--c1",
                "2",
                "--phi",
                "90",
                "-o",
                str(tmp_path / "u.npy"),
            ]
        )
        == 0
    )
    np.testing.assert_array_equal(
        np.load(tmp_path / "u.npy"), Surrogate.load(tmp_path / "m").predict(2.0, 90.0)
    )
    said = capsys.readouterr().out
    assert "max |u|" in said and f"wrote {tmp_path / 'u.npy'}" in said
    with pytest.raises(SystemExit) as stop:  # the command line's own check, before any work
        main(["predict", str(tmp_path / "m"), "--c1", "-1", "--phi", "90"])
    assert stop.value.code == 2
    assert "argument --c1: C1 = -1 kPa is not above 0" in capsys.readouterr().err
    assert main(["predict", str(tmp_path / "nowhere"), "--c1", "1", "--phi", "90"]) == 2
    assert "cannot read a surrogate model" in capsys.readouterr().err
    # an output folder that does not exist is named, not a traceback after the prediction
    assert main(["predict", str(tmp_path / "m"), "--c1", "2", "--phi", "90",
                 "-o", str(tmp_path / "no" / "such" / "u.npy")]) == 2
    assert "does not exist" in capsys.readouterr().err
    # an extrapolation is answered with one line saying so; --strict refuses it, writing nothing
    outside = ["predict", str(tmp_path / "m"), "--c1", "50", "--phi", "90", "-o",
               str(tmp_path / "far.npy")]
    assert main(outside) == 0 and (tmp_path / "far.npy").is_file()
    err = capsys.readouterr().err
    assert err.startswith("warning: C1 = 50.0 kPa is outside the training range")
    assert len(err.strip().splitlines()) == 1  # not Python's file, line and source line
    (tmp_path / "far.npy").unlink()
    assert main([*outside, "--strict"]) == 3 and not (tmp_path / "far.npy").exists()
    assert capsys.readouterr().err.startswith("error: C1 = 50.0 kPa is outside")
    assert main(["predict", str(tmp_path / "m"), "--c1", "2", "--phi", "90", "--strict"]) == 0
    assert main([*args, "--set", "activation=sigmoid"]) == 2
    assert "surrogate.activation must be one of" in capsys.readouterr().err
    assert main([*args, "--set", "widthx"]) == 2
    assert "not KEY=VALUE" in capsys.readouterr().err


@pytest.mark.parametrize(("boundary", "output_form", "structure", "point_features"), [
    ("network", "vector", "pointwise", 0), ("shared", "vector", "pointwise", 0),
    ("exact", "vector", "pointwise", 0), ("network", "gravity_linear", "pointwise", 0),
    ("exact", "gravity_linear", "pointwise", 0), ("network", "gravity_linear", "separable", 0),
    ("shared", "vector", "separable", 0), ("exact", "gravity_linear", "separable", 0),
    ("network", "gravity_linear", "separable", 6)])
def test_fast_prediction_is_the_plain_network(
    dataset_path: Path, tmp_path: Path, boundary: str, output_form: str, structure: str,
    point_features: int,
) -> None:
    """``Surrogate.predict`` gives the plain forward pass of the saved networks at every point.

    The fast path precomputes the first layer's point part (a separable model's fields), runs
    in float32 and gathers the points per network (and contracts a ``gravity_linear`` model's
    last layer with ĝ before the points pass it); the structure's ``apply`` is the plain
    forward pass, every network evaluated at every sample.
    """
    import warnings
    from dataclasses import replace

    import jax.numpy as jnp
    from scipy.spatial import Delaunay

    from fem.dataset import read_dataset
    from fem.directions import gravity_direction
    from surrogate.checkpoint import save_model
    from surrogate.exceptions import ExtrapolationWarning
    from surrogate.predict import Surrogate
    from surrogate.structures import structure_for
    from surrogate.train import train_and_evaluate

    ds = read_dataset(dataset_path)
    config = SurrogateConfig(
        hidden_layers=2,
        width=16,
        batch_size=256,
        max_epochs=3,
        patience=3,
        boundary=boundary,
        c1_encoding="log",
        output_scaling="compliance",
        output_form=output_form,
        structure=structure,
        modes=5,
        point_features=point_features,
        point_frequency=2.0,
    )
    save_model(tmp_path / "m", train_and_evaluate(ds, config, progress=False), ds)
    model = Surrogate.load(tmp_path / "m")
    # the same model over a mesh of its points, whose x = 0 face is the clamped chest wall
    meshed = Surrogate(replace(model._checkpoint, cells=Delaunay(model.X).simplices))
    norm = model.normalisation
    factor = np.ones(N) if model.point_factor is None else model.point_factor
    for C1, phi, theta in ((1.3, 20.0, 0.0), (4.2, -100.0, 25.0), (2.5, 180.0, -40.0)):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ExtrapolationWarning)  # theta != 0 is outside
            fast = model.predict(C1, phi, theta)
        direction = gravity_direction(np.full(N, phi), np.full(N, theta))
        x = np.concatenate([norm.points(model.X), norm.case(np.full(N, C1), direction)], axis=1)
        gain = norm.gain(np.full(N, C1)) * factor
        plain = norm.u_scale * np.asarray(
            structure_for(model.config).apply(
                model.params,
                jnp.asarray(x, jnp.float32),
                jnp.asarray(model.boundary),
                jnp.asarray(gain, jnp.float32),
            )
        )
        assert np.abs(plain).max() > 0
        np.testing.assert_allclose(fast, plain, rtol=0, atol=1e-5 * np.abs(plain).max())
        if boundary == "exact":
            assert np.all(fast[model.boundary] == 0.0)
        # between the material points: the same network, queried at the domain points alone
        inside = ~model.boundary
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ExtrapolationWarning)
            at_points = model.at(model.X[inside]).predict(C1, phi, theta)
        np.testing.assert_allclose(at_points, fast[inside], rtol=0,
                                   atol=1e-5 * np.abs(plain).max())
        # where the mesh tells the chest wall's face, a point on it answers zero, as FE has it
        # (not the domain network's answer there, whatever the boundary mode)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ExtrapolationWarning)
            everywhere = meshed.at(model.X).predict(C1, phi, theta)
        assert np.all(everywhere[model.boundary] == 0.0)
        np.testing.assert_allclose(everywhere[inside], fast[inside], rtol=0,
                                   atol=1e-5 * np.abs(plain).max())


def test_a_refit_trains_on_the_validation_part_for_the_epochs_given(dataset_path: Path) -> None:
    """``refit_epochs``: the split's validation part trains too, for that many epochs.

    The last weights are kept: no early stopping on data it trains on.
    """
    from fem.dataset import read_dataset
    from surrogate.train import train_and_evaluate

    ds = read_dataset(dataset_path)
    config = SurrogateConfig(hidden_layers=1, width=4, max_epochs=5, patience=1, split="by_case")
    parts = ds.splits["by_case"]
    plain = train_and_evaluate(ds, config, progress=False)
    assert np.array_equal(plain.train_cases, parts["train"]) and not plain.refit
    again = train_and_evaluate(ds, config, progress=False, refit_epochs=3)
    assert np.array_equal(again.train_cases, np.union1d(parts["train"], parts["validation"]))
    assert again.refit and again.summary()["refit"]
    assert len(again.history) == again.best_epoch == 3
    for bad in (0, 2.5, True):
        with pytest.raises(ValueError, match="refit_epochs must be a positive integer"):
            train_and_evaluate(ds, config, progress=False, refit_epochs=bad)


def _scripted_run(figures: list[tuple[float, float, float]], select: str,
                  refit_epochs: int | None = None, max_epochs: int = 20, patience: int = 3):
    """:func:`surrogate.epochs.run_epochs` over epochs whose figures are given; weights = epoch."""
    from surrogate.epochs import EpochFigures, TrainResult, run_epochs

    config = SurrogateConfig(max_epochs=max_epochs, patience=patience)
    result = TrainResult(params=0, config=config, normalisation=None)  # the loop never reads it
    epochs = iter(range(1, len(figures) + 1))

    def one_epoch():
        epoch = next(epochs)
        return epoch, EpochFigures(*figures[epoch - 1])

    run_epochs(one_epoch, 0, config, result, schedule=lambda step: 0.01, steps=10,
               refit_epochs=refit_epochs, progress=False, select=select)
    return result


def test_the_epoch_loop_keeps_the_best_epoch_by_its_figure_and_stops_on_patience() -> None:
    """One loop trains every structure (:func:`surrogate.epochs.run_epochs`).

    The best epoch is the one of the figure named, patience counts from it, the history holds
    every epoch run, a refit keeps its last epoch and a diverged loss ends the run.
    """
    # (train loss, validation loss, validation error mm): the loss is lowest at epoch 4, the
    # error at epoch 2; both rise after epoch 4
    figures = [(1.0, 0.9, 0.50), (0.8, 0.7, 0.20), (0.6, 0.5, 0.30), (0.5, 0.4, 0.25),
               (0.4, 0.6, 0.40), (0.3, 0.8, 0.60), (0.2, 0.9, 0.70), (0.1, 1.0, 0.80)]
    by_loss = _scripted_run(figures, "validation_loss")
    assert (by_loss.best_epoch, by_loss.params, by_loss.best_validation_loss) == (4, 4, 0.4)
    assert len(by_loss.history) == 7  # three epochs past the best
    assert [h["validation_error_mm"] for h in by_loss.history] == [f[2] for f in figures[:7]]
    assert not by_loss.refit

    by_error = _scripted_run(figures, "validation_error_mm")
    assert (by_error.best_epoch, by_error.params, by_error.best_validation_loss) == (2, 2, 0.7)
    assert len(by_error.history) == 5

    refit = _scripted_run(figures, "validation_error_mm", refit_epochs=6)
    assert (refit.best_epoch, refit.params, len(refit.history), refit.refit) == (6, 6, 6, True)

    diverged = _scripted_run([(1.0, 0.9, 0.5), (float("nan"), 0.8, 0.4)], "validation_loss")
    assert (diverged.best_epoch, len(diverged.history)) == (1, 2)

    with pytest.raises(ValueError, match="select"):
        _scripted_run(figures, "train_loss")


def test_the_patience_benchmark_replays_the_epoch_loops_rule() -> None:
    """``benchmarks.patience`` on a whole run's figures stops where the loop itself would."""
    from benchmarks.patience import replay

    rng = np.random.default_rng(0)
    errors = list(np.exp(-np.linspace(0, 3, 60)) * (1 + 0.3 * rng.random(60)))
    figures = [(1.0, 1.0, e) for e in errors]
    for patience in (1, 3, 5, 8, 100):
        run = _scripted_run(figures, "validation_error_mm", max_epochs=60, patience=patience)
        assert replay(errors, patience) == (len(run.history), run.best_epoch)
