"""The interactive view in a real browser: headless Chromium, driven by Playwright.

The page is the one the small workflow wrote (``results/viewer/index.html``), opened from the
file system. Its predictions are compared with Python's, its controls are moved, and the
screenshots are kept beside it (``screenshot-*.png``) to look at.
"""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from studies.surrogate_study.browser import open_page
from surrogate.exceptions import ExtrapolationWarning
from surrogate.export import decode_array, encode_array
from surrogate.predict import Surrogate

pytestmark = pytest.mark.workflow

READY = "window.viewer && window.viewer.ready"


@pytest.fixture(scope="module")
def viewer(small_run: Path) -> Path:
    return small_run / "results" / "viewer" / "index.html"


@pytest.fixture(scope="module")
def model(small_run: Path) -> Surrogate:
    return Surrogate.load(small_run / "results" / "surrogate" / "model")


def test_arrays_travel_exactly() -> None:
    rng = np.random.default_rng(0)
    for values, dtype in ((rng.normal(size=(5, 3)), "float32"), (np.arange(7), "int32"),
                          (np.array([True, False, True]), "uint8")):
        back = decode_array(encode_array(values, dtype))
        assert back.shape == values.shape and np.array_equal(back, values.astype(dtype))


def test_the_page_predicts_what_python_predicts(viewer: Path, model: Surrogate) -> None:
    """20 random setups in the training range: every material point within 1e-4 mm."""
    lo, hi = model.trained.range_checks()["c1_kPa"]
    rng = np.random.default_rng(24)
    setups = np.column_stack([rng.uniform(lo, hi, 20), rng.uniform(-150, 180, 20),
                              rng.uniform(-180, 180, 20)])
    with open_page(viewer, ready=READY) as (page, errors, _):
        for C1, phi, theta in setups:
            in_page = np.asarray(page.evaluate(
                f"window.viewer.predictAll({C1}, {phi}, {theta})")).reshape(-1, 3)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", ExtrapolationWarning)  # θ ≠ 0: the test's own
                expected = model.predict(C1, phi, theta)
            assert in_page.shape == expected.shape
            assert np.abs(in_page - expected).max() <= 1e-4, (C1, phi, theta)
        assert not errors


@pytest.mark.parametrize("structure", ["pointwise", "fourier", "pod"])
def test_the_page_predicts_other_models_as_python_does(
    small_run: Path, tmp_path: Path, structure: str
) -> None:
    """The page of a pointwise, a Fourier-featured separable or a pod model predicts as Python.

    The small run's model, whose page the other tests read, is separable on the coordinates
    alone; these have the paper's pointwise networks in gravity_linear form (the last layer
    contracted with ĝ), point networks that see the point's Fourier features, or no point
    networks but the data's own modes (carried by the page).
    """
    from fem.dataset import read_dataset
    from report.viewer import build_viewer
    from surrogate.checkpoint import save_model
    from surrogate.config import SurrogateConfig
    from surrogate.train import train_and_evaluate

    results = small_run / "results"
    config = SurrogateConfig(hidden_layers=2, width=8, activation="silu", max_epochs=2,
                             structure="pointwise", output_form="gravity_linear",
                             output_scaling="compliance")
    if structure == "fourier":
        config = config.replace(structure="separable", modes=6, point_features=5,
                                point_frequency=2.0)
    if structure == "pod":
        config = config.replace(structure="pod", modes=2)  # the small run trains on 2 cases
    ds = read_dataset(results / "dataset" / "dataset.h5")
    save_model(tmp_path / "model", train_and_evaluate(ds, config, progress=False), ds)
    page_path = tmp_path / "index.html"
    build_viewer(tmp_path / "model", results / "mesh" / "mesh.xdmf",
                 results / "dataset" / "dataset.h5", page_path)
    model = Surrogate.load(tmp_path / "model")
    with open_page(page_path, ready=READY) as (page, errors, _):
        for C1, phi, theta in ((1.0, 180.0, 0.0), (1.7, -40.0, 0.0), (2.3, 95.0, 30.0)):
            in_page = np.asarray(page.evaluate(
                f"window.viewer.predictAll({C1}, {phi}, {theta})")).reshape(-1, 3)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", ExtrapolationWarning)
                expected = model.predict(C1, phi, theta)
            assert np.abs(expected).max() > 0
            assert np.abs(in_page - expected).max() <= 1e-4, (C1, phi, theta)
        assert not errors


def _picture(page, path: Path) -> np.ndarray:
    page.locator("#view").screenshot(path=str(path))
    return np.asarray(Image.open(path).convert("RGB"), dtype=float)


def test_moving_a_slider_changes_the_picture(viewer: Path) -> None:
    """A slider moved as a user moves it (input events) redraws the breast under new gravity.

    The screenshots are kept beside the page.
    """
    with open_page(viewer, ready=READY) as (page, errors, requests):
        page.evaluate("window.viewer.setQuery(1.0, 180, 0)")
        page.screenshot(path=str(viewer.parent / "screenshot-prone.png"))
        before = _picture(page, viewer.parent / "view-prone.png")
        page.locator("#phi").fill("0")  # a range input takes fill(); it fires input events
        state = page.evaluate("window.viewer.state()")
        assert state["phi"] == 0 and state["C1"] == 1.0
        page.screenshot(path=str(viewer.parent / "screenshot-supine.png"))
        after = _picture(page, viewer.parent / "view-supine.png")
        changed = np.mean(np.abs(after - before).sum(axis=2) > 30)
        assert changed > 0.01, f"only {changed:.2%} of the picture changed"
        assert "Φ (gravity elevation)" in page.inner_text("#panel")
        assert re.search(r"\|u\|, surrogate \(mm\)", page.inner_text("#scale"))
        assert not errors
        assert all(url.startswith("file://") for url in requests), requests


def test_the_colour_scale_reads_from_zero_to_its_top(viewer: Path) -> None:
    """The ticks are numbers from 0 to a round top at least the largest value (e.g. 100, not 1).

    Over the slider's C1 range, from rest and from prone: the toy breast's way from prone to
    supine or lateral, about twice its displacement from rest, lies between 50 and 100 mm at
    the soft end, so that the top is 100 there.
    """
    tops = set()
    with open_page(viewer, ready=READY) as (page, errors, _):
        for start in ("rest", "0"):  # the menu's values: rest, then the first posture, prone
            page.evaluate(f"window.viewer.setStart('{start}')")
            for C1 in np.linspace(float(page.get_attribute("#c1", "min")), 5.0, 12):
                for phi in (0, 45):
                    page.evaluate(f"window.viewer.setQuery({C1:.2f}, {phi}, 0)")
                    largest = float(re.search(r"largest ([\d.]+) mm",
                                              page.inner_text("#max-value"))[1])
                    ticks = [float(page.inner_text(f"#tick-{i}")) for i in range(5)]
                    assert ticks[0] == 0 and ticks == sorted(ticks), ticks
                    assert largest <= ticks[-1] <= 2.5 * largest, (C1, largest, ticks)
                    tops.add(ticks[-1])
        assert 100 in tops, tops  # the top the old ticks printed as "1"
        assert not errors


def test_outside_the_training_range_the_page_says_what_predict_warns(
    viewer: Path, model: Surrogate
) -> None:
    lo, hi = model.trained.range_checks()["c1_kPa"]
    with open_page(viewer, ready=READY) as (page, _, _):
        # the last two: directions of the trained plane under other names, judged as Python
        # judges them (no θ warning)
        for C1, phi, theta in ((hi * 1.4, 180.0, 0.0), (lo, 120.0, 30.0), (lo, 180.0, 0.0),
                               (hi * 1.4, 90.0, 180.0), (lo, -45.0, -180.0)):
            shown = _warnings_as_python(page, model, C1, phi, theta)
            assert page.locator("#warnings").is_visible() == bool(shown)


def _warnings_as_python(page, model: Surrogate, C1: float, phi: float, theta: float) -> list[str]:
    """The page's warnings at a query, checked to be ``model.predict``'s, word for word.

    Python is asked at the query the page took (its sliders round C1, Φ and θ to their steps).
    """
    page.evaluate(f"window.viewer.setQuery({C1}, {phi}, {theta})")
    state = page.evaluate("window.viewer.state()")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", ExtrapolationWarning)
        model.predict(float(state["C1"]), float(state["phi"]), float(state["theta"]))
    assert state["warnings"] == [str(w.message) for w in caught], (C1, phi, theta)
    return state["warnings"]


def test_below_a_directions_softest_trained_c1_the_page_says_what_predict_warns(
    small_run: Path, tmp_path: Path
) -> None:
    """A model trained without the softest case at Φ = 90° warns below 5 kPa beside 90°.

    Its C1 range is still [1, 5] kPa (the other angles' soft cases train): only the record of
    each direction's softest trained C1 tells the page and Python that 90° is unbacked there.
    """
    from fem.dataset import read_dataset
    from report.viewer import build_viewer
    from surrogate.checkpoint import save_model
    from surrogate.config import SurrogateConfig
    from surrogate.train import train_and_evaluate

    results = small_run / "results"
    ds = read_dataset(results / "dataset" / "dataset.h5")
    config = SurrogateConfig(hidden_layers=1, width=4, max_epochs=1)
    save_model(tmp_path / "model", train_and_evaluate(
        ds, config, progress=False, holdout=np.array([ds.case_index(1.0, 90.0)])), ds)
    page_path = tmp_path / "index.html"
    build_viewer(tmp_path / "model", results / "mesh" / "mesh.xdmf",
                 results / "dataset" / "dataset.h5", page_path)
    model = Surrogate.load(tmp_path / "model")
    assert model.trained.range_checks()["c1_kPa"] == [1.0, 5.0]
    with open_page(page_path, ready=READY) as (page, errors, _):
        for C1, phi, theta, expected in ((1.0, 90.0, 0.0, 1), (3.0, 45.0, 0.0, 1),
                                         (5.0, 90.0, 0.0, 0), (1.0, 0.0, 0.0, 0),
                                         (1.0, -90.0, 180.0, 1), (5.0, -90.0, 180.0, 0)):
            shown = _warnings_as_python(page, model, C1, phi, theta)
            assert len(shown) == expected, shown
            assert all("softest FE solution at Φ = 90°" in m for m in shown)
        assert not errors


def test_an_fe_case_can_be_shown_and_compared(viewer: Path) -> None:
    with open_page(viewer, ready=READY) as (page, errors, _):
        page.select_option("#fe-case", index=1)
        state = page.evaluate("window.viewer.state()")
        assert state["fe"] is not None and state["mode"] == "surrogate"
        page.check("input[name=mode][value=difference]")
        assert page.evaluate("window.viewer.state()")["mode"] == "difference"
        assert "|u surrogate − u FE| (mm)" in page.inner_text("#scale-title")
        page.evaluate("window.viewer.addPoint(0)")
        assert "P1" in page.inner_text("#points")
        page.locator("#phi").fill("17")  # off the solved case: FE is not offered
        assert page.evaluate("window.viewer.state()")["fe"] is None
        assert page.locator("input[name=mode][value=fe]").is_disabled()
        assert not errors


def test_the_page_and_its_library_stay_small(viewer: Path) -> None:
    assert viewer.stat().st_size <= 5e6
    assert "MIT" in (viewer.parent / "THREE-LICENSE.txt").read_text()


def test_the_report_links_the_view(small_run: Path) -> None:
    report = (small_run / "results" / "report" / "index.html").read_text()
    assert '<a href="../viewer/index.html">' in report


def test_a_page_for_any_model_from_the_command_line(
    small_run: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``python -m report.viewer``: a model trained outside the workflow gets its page too.

    Without a dataset the FE controls are hidden; a config's postures become its buttons;
    named points inside the body (``--points``, a tumour) are predicted in the page as
    ``Surrogate.at`` predicts them, listed and drawn through a skin one can see through, and
    with a dataset the FE cases' displacement there is shown and compared too. A
    model that cannot be read, a point outside the body, or a dataset of other material points
    is named and nothing is written.
    """
    import json

    from fem.dataset import read_dataset
    from report.viewer import ViewerError, fe_cases
    from report.viewer.__main__ import main
    from studies.reference_state.fe_at_points import fe_at_points
    from tests.conftest import REPO

    results = small_run / "results"
    model_dir, mesh = results / "surrogate" / "model", results / "mesh" / "mesh.xdmf"
    ds = read_dataset(results / "dataset" / "dataset.h5")
    inside = ds.X[ds.cells[:2]].mean(axis=1)  # two cells' centroids
    points = tmp_path / "tumour.csv"
    points.write_text("name,x,y,z\n" + "".join(
        f"t<{i}>,{x!r},{y!r},{z!r}\n" for i, (x, y, z) in enumerate(inside)))
    page_path = tmp_path / "page.html"
    assert main([str(model_dir), "-o", str(page_path), "--mesh", str(mesh),
                 "--config", str(REPO / "tests" / "config.yaml"), "--points", str(points)]) == 0
    assert capsys.readouterr().out.startswith(f"wrote {page_path}: ")
    model = Surrogate.load(model_dir)
    with open_page(page_path, ready=READY) as (page, errors, _):
        in_page = np.asarray(page.evaluate("window.viewer.predictAll(2.0, 180, 0)"))
        assert np.abs(in_page.reshape(-1, 3) - model.predict(2.0, 180.0)).max() <= 1e-4
        assert page.locator("#fe-controls").is_hidden()
        assert page.locator(".presets button").all_inner_texts() == ["prone", "standing"]
        for C1, phi in ((1.0, 180.0), (4.0, 0.0)):
            at = np.asarray(page.evaluate(f"window.viewer.predictInner({C1}, {phi}, 0)"))
            assert np.abs(at.reshape(-1, 3) - model.at(inside).predict(C1, phi)).max() <= 1e-4
        page.evaluate("window.viewer.setQuery(1.0, 0, 0)")
        rows = page.locator("#points tr").all_inner_texts()
        assert [r.split("\t")[0] for r in rows] == ["● t<0>", "● t<1>"], rows  # as text
        assert page.evaluate("window.viewer.state()")["seeThrough"]
        page.uncheck("#see-through")
        assert not page.evaluate("window.viewer.state()")["seeThrough"]
        assert not errors
    # with the dataset, each FE case carries its field at the points: the FE mode moves them
    # there, the difference mode lists the surrogate's error at them
    with_fe = tmp_path / "with_fe.html"
    assert main([str(model_dir), "-o", str(with_fe), "--mesh", str(mesh), "--points", str(points),
                 "--dataset", str(results / "dataset" / "dataset.h5")]) == 0
    data = json.loads(re.search(r'id="viewer-data"[^>]*>(.*?)</script>', with_fe.read_text(),
                                re.S).group(1))
    fe_case = data["fe_cases"][0]
    fe = decode_array(fe_case["inner_u_mm"])
    np.testing.assert_allclose(fe, fe_at_points(results / "cases" / fe_case["id"], inside),
                               atol=1e-4)  # the dataset's fields and the case's own files
    surrogate = model.at(inside).predict(fe_case["C1"], fe_case["phi"], fe_case["theta"])
    with open_page(with_fe, ready=READY) as (page, errors, _):
        page.select_option("#fe-case", index=1)
        for mode, expected in (("fe", fe), ("difference", surrogate - fe)):
            page.check(f"input[name=mode][value={mode}]")
            sizes = [float(r[1]) for r in page.evaluate("window.viewer.pointRows()")]
            assert np.allclose(sizes, np.linalg.norm(expected, axis=1), atol=0.006), mode
        assert page.inner_text("#points-u") == "u surrogate − u FE (mm)"
        assert not errors
    missing = tmp_path / "missing.html"
    assert main([str(tmp_path / "no_model"), "-o", str(missing), "--mesh", str(mesh)]) == 2
    assert "cannot read a surrogate model" in capsys.readouterr().err
    partial = tmp_path / "partial.yaml"
    partial.write_text("surrogate_study: {postures: {directions: [{name: prone}]}}\n")
    assert main([str(model_dir), "-o", str(missing), "--mesh", str(mesh),
                 "--config", str(partial)]) == 2
    assert f"error: {partial}: invalid configuration: " in capsys.readouterr().err
    points.write_text("name,x,y,z\nfar,1.0,1.0,1.0\n")
    assert main([str(model_dir), "-o", str(missing), "--mesh", str(mesh),
                 "--points", str(points)]) == 2
    assert ("the named points: 1 of 1 points lie outside the mesh by more than 1 mm: far ("
            in capsys.readouterr().err)
    assert not missing.exists()
    # a page named like a folder: refused before any work, nothing left beside it
    folder = tmp_path / "a_folder.html"
    folder.mkdir()
    with pytest.raises(SystemExit) as stop:
        main([str(model_dir), "-o", str(folder), "--mesh", str(mesh)])
    assert stop.value.code == 2
    assert f"{folder} is a folder, not a file to write" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir() if p.name.endswith(".tmp")) == []
    with pytest.raises(ViewerError, match="not the model's"):
        fe_cases(results / "dataset" / "dataset.h5", np.arange(3), material_points=model.X + 0.01)


def test_movement_is_measured_from_a_posture_the_user_chooses(
    small_run: Path, tmp_path: Path, model: Surrogate
) -> None:
    """"Movement from": rest, a config's posture, or the sliders' posture, at the sliders' C1.

    A tumour seen prone and operated on supine: from prone, the table gives each named point's
    way between the two postures, ``Surrogate.at``'s difference of the two predictions, and
    the colours the same for the skin. The FE modes measure from the start's FE case where the
    page carries it (the FE movement, and the surrogate's error in it), else from rest, and
    say which.
    """
    from report.viewer.__main__ import main
    from studies.reference_state.fe_at_points import fe_at_points
    from tests.conftest import REPO

    results = small_run / "results"
    inside = model.X[model.X[:, 0] < np.median(model.X[:, 0])][:3] * 0.98 + 0.02 * model.X.mean(0)
    points = tmp_path / "tumour.csv"
    points.write_text("name,x,y,z\n" + "".join(
        f"t{i},{x!r},{y!r},{z!r}\n" for i, (x, y, z) in enumerate(inside)))
    page_path = tmp_path / "page.html"
    assert main([str(results / "surrogate" / "model"), "-o", str(page_path), "--mesh",
                 str(results / "mesh" / "mesh.xdmf"), "--dataset",
                 str(results / "dataset" / "dataset.h5"), "--config",
                 str(REPO / "tests" / "config.yaml"), "--points", str(points)]) == 0
    at = model.at(inside)

    def rows(page) -> tuple[np.ndarray, np.ndarray]:
        shown = page.evaluate("window.viewer.pointRows()")
        return (np.array([float(r[1]) for r in shown]),
                np.array([[float(x) for x in r[2].split(", ")] for r in shown]))

    with open_page(page_path, ready=READY) as (page, errors, _):
        assert page.locator("#start option").all_inner_texts() == [
            "rest (the unloaded shape)", "prone", "standing",
            "the sliders' posture (choose to fix it)"]
        page.evaluate("window.viewer.setQuery(1.0, 0, 0)")
        assert page.evaluate("window.viewer.state()")["start"] is None
        sizes, _ = rows(page)
        assert np.allclose(sizes, np.linalg.norm(at.predict(1.0, 0.0), axis=1), atol=0.006)
        page.select_option("#start", label="prone")
        moved = at.predict(1.0, 0.0) - at.predict(1.0, 180.0)
        sizes, components = rows(page)
        assert np.allclose(sizes, np.linalg.norm(moved, axis=1), atol=0.006)
        assert np.allclose(components, moved, atol=0.06)
        assert page.inner_text("#scale-title") == "movement, surrogate, from prone (mm)"
        # the skin's colours: the largest movement of a surface vertex between the postures
        largest = float(re.search(r"largest ([\d.]+) mm", page.inner_text("#max-value"))[1])
        whole = model.predict(1.0, 0.0) - model.predict(1.0, 180.0)
        assert 0.5 * np.linalg.norm(whole, axis=1).max() < largest <= (
            np.linalg.norm(whole, axis=1).max() + 0.006)
        # the sliders' posture, fixed when chosen: the way from lying on the side to supine
        page.evaluate("window.viewer.setQuery(2.0, 90, 0)")
        page.select_option("#start", value="here")
        assert page.evaluate("window.viewer.state()")["start"] == "Φ = 90°, θ = 0°"
        assert np.allclose(rows(page)[0], 0, atol=0.006)
        page.evaluate("window.viewer.setQuery(2.0, 0, 0)")
        moved = at.predict(2.0, 0.0) - at.predict(2.0, 90.0)
        assert np.allclose(rows(page)[0], np.linalg.norm(moved, axis=1), atol=0.006)
        # FE: from prone to supine at 1 kPa, both sweep cases: the FE movement, and in the
        # difference mode the surrogate's error in it, to the micrometre
        fe = {phi: fe_at_points(results / "cases" / f"c1=1.00_phi={phi:.1f}_theta=0.0", inside)
              for phi in (0.0, 180.0)}
        page.select_option("#start", label="prone")
        page.evaluate("window.viewer.setQuery(1.0, 0, 0)")
        selected = page.eval_on_selector("#fe-case", "s => s.options[s.selectedIndex].text")
        assert selected.endswith("C1 = 1 kPa, Φ = 0°, θ = 0°"), selected
        page.check("input[name=mode][value=fe]")
        assert page.inner_text("#scale-title") == "movement, FE, from prone (mm)"
        assert "FE from the case c1=1.00_phi=180.0_theta=0.0" in page.inner_text("#start-note")
        sizes, components = rows(page)
        assert np.allclose(sizes, np.linalg.norm(fe[0.0] - fe[180.0], axis=1), atol=0.006)
        page.check("input[name=mode][value=difference]")
        error = (at.predict(1.0, 0.0) - at.predict(1.0, 180.0)) - (fe[0.0] - fe[180.0])
        sizes, components = rows(page)
        assert np.allclose(sizes, np.linalg.norm(error, axis=1), atol=6e-4)
        assert np.allclose(components, error, atol=6e-4)
        assert page.inner_text("#points-u") == "Δx surrogate − Δx FE (mm)"
        # a start without an FE case at that C1: the FE modes from rest, and said so
        page.evaluate("window.viewer.setQuery(1.0, 45, 0)")
        page.select_option("#start", value="here")
        page.evaluate("window.viewer.setQuery(1.0, 0, 0)")
        page.check("input[name=mode][value=fe]")
        assert "no FE case Φ = 45°, θ = 0° at C1 = 1.00 kPa" in page.inner_text("#start-note")
        assert np.allclose(rows(page)[0], np.linalg.norm(fe[0.0], axis=1), atol=0.006)
        assert page.inner_text("#scale-title") == "|u|, FE (mm)"
        # a solved direction under another name is that case
        for phi, theta, case in ((-180, 0, "c1=1.00_phi=180.0_theta=0.0"),
                                 (-90, 180, "c1=1.00_phi=90.0_theta=0.0")):
            page.evaluate(f"window.viewer.setQuery(1.0, {phi}, {theta})")
            assert page.evaluate("window.viewer.state()")["fe"] == case
        assert not errors
