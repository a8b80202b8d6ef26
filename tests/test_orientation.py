"""A person's geometry in her own orientation: scanner axes (LPS, RAS), the breast's side, units.

The same body is written in the project's frame (metres) and in DICOM's LPS axes in
millimetres as a left breast (a mirror image): imported with its orientation declared, it is
the same mesh, and the same case solved on it gives the same displacement, mapped back into
the file's axes.
"""

from __future__ import annotations

import re
from pathlib import Path

import meshio
import numpy as np
import pytest
from scipy.spatial import cKDTree

from meshes.exceptions import GeometryError
from meshes.importing import ImportSpec, write_imported_mesh
from meshes.orientation import Orientation
from meshes.quality import tet_volumes
from tests.conftest import REPO
from tests.test_mesh_import import BOX, SIZE, box_mesh

# In the project's frame the chest wall is posterior: the box's face at x = BOX[0].
RIB = {"plane": {"point": [BOX[0], 0.0, 0.0], "normal": [1.0, 0.0, 0.0]}, "distance": 0.001}
LEFT_LPS = Orientation("LPS", "left")


def _spec(path: Path, units: str, rib: dict, orientation: dict | None = None) -> ImportSpec:
    values = {"path": str(path), "units": units, "surfaces": {"rib": rib}}
    if orientation is not None:
        values["orientation"] = orientation
    return ImportSpec.from_mapping(values)


def _in_lps_mm(folder: Path) -> tuple[Path, dict, Path]:
    """The box as tetrahedra in the project's frame (m) and in LPS mm of a left breast."""
    x, tets = box_mesh(3)
    project = folder / "box_project.vtu"
    meshio.write(str(project), meshio.Mesh(x, [("tetra", tets)]))
    lps = folder / "box_lps_mm.vtu"
    # a mirror image: its tetrahedra are written inside out, as a left-breast file holds them
    meshio.write(str(lps), meshio.Mesh(1000.0 * LEFT_LPS.to_file(x), [("tetra", tets)]))
    point, normal = (np.asarray(RIB["plane"][k]) for k in ("point", "normal"))
    rib = {"plane": {"point": (1000.0 * LEFT_LPS.to_file(point)).tolist(),
                     "normal": LEFT_LPS.to_file(normal).tolist()}, "distance": 1.0}
    return project, rib, lps


@pytest.mark.unit
def test_codes_map_scanner_axes_to_the_body() -> None:
    # LPS, right breast: posterior is +y of the file, lateral (the right) is -x, superior +z
    right = Orientation("lps", "right")
    assert right.axes == "LPS" and not right.mirrors
    assert np.allclose(right.to_project([[0, 1, 0], [-1, 0, 0], [0, 0, 1]]), np.eye(3))
    # a left breast is a mirror image of the project's frame
    assert LEFT_LPS.mirrors and np.allclose(LEFT_LPS.to_project([1, 0, 0]), [0, 1, 0])
    # RAS is LPS with x and y reversed
    assert np.allclose(Orientation("RAS", "left").matrix,
                       LEFT_LPS.matrix @ np.diag([-1.0, -1.0, 1.0]))
    for orientation in (right, LEFT_LPS, Orientation("RAS", "right"), Orientation()):
        x = np.random.default_rng(0).normal(size=(5, 3))
        assert np.allclose(orientation.to_file(orientation.to_project(x)), x)


@pytest.mark.unit
@pytest.mark.parametrize(
    "values, message",
    [
        ({"axes": "LPQ", "side": "left"}, "not an anatomical code"),
        ({"axes": "LRS", "side": "left"}, "one of each pair"),
        ({"axes": "LPS"}, "side must be left or right with axes LPS"),
        ({"axes": "LPS", "side": "middle"}, "side must be left or right"),
        ({"axes": "LPS", "side": "left", "flip": True}, "unknown mesh.file.orientation key"),
    ],
)
def test_a_bad_orientation_is_named(values: dict, message: str) -> None:
    with pytest.raises(GeometryError, match=message):
        Orientation.from_mapping(values)


@pytest.mark.unit
def test_a_left_breast_in_lps_mm_imports_as_the_same_mesh(tmp_path: Path) -> None:
    project, rib_lps, lps = _in_lps_mm(tmp_path)
    direct = write_imported_mesh(_spec(project, "m", RIB), SIZE, tmp_path / "a.xdmf")
    declared = _spec(lps, "mm", rib_lps, {"axes": "LPS", "side": "left"})
    mapped = write_imported_mesh(declared, SIZE, tmp_path / "b.xdmf")
    assert mapped["cells"] == direct["cells"]
    assert mapped["volume_m3"] == pytest.approx(direct["volume_m3"], rel=1e-12)
    for name, area in direct["area_m2"].items():
        assert mapped["area_m2"][name] == pytest.approx(area, rel=1e-12), name
    assert mapped["input"]["orientation"]["mirrored"] is True
    # the cells of the mirrored file are positive again, in the same places
    xa, ca = _written(tmp_path / "a.xdmf")
    xb, cb = _written(tmp_path / "b.xdmf")
    assert (tet_volumes(xa, ca) > 0).all() and (tet_volumes(xb, cb) > 0).all()
    assert np.allclose(np.sort(xa, axis=0), np.sort(xb, axis=0), atol=1e-12)
    # positions go back into the file's axes and units: the chest wall is the file's +y (P) face
    assert declared.to_file_frame(xb)[:, 1].max() == pytest.approx(1000.0 * BOX[0])


def _written(xdmf: Path) -> tuple[np.ndarray, np.ndarray]:
    """The vertices and tetrahedra of a mesh as the import wrote it."""
    import h5py

    with h5py.File(xdmf.with_suffix(".h5")) as h5:
        return h5["Mesh/mesh/geometry"][...], h5["Mesh/mesh/topology"][...][:, :4]


@pytest.mark.unit
def test_an_orientation_that_puts_the_chest_wall_anterior_is_refused(tmp_path: Path) -> None:
    """The LPS file declared as RAS: posterior becomes anterior."""
    _, rib_lps, lps = _in_lps_mm(tmp_path)
    with pytest.raises(GeometryError, match=r"axes RAS, side left, the chest wall .* lies "
                       r"2\d\.\d mm anterior of the breast's centroid, where it belongs posterior"):
        write_imported_mesh(_spec(lps, "mm", rib_lps, {"axes": "RAS", "side": "left"}), SIZE,
                            tmp_path / "m.xdmf")


@pytest.mark.unit
def test_a_file_without_orientation_whose_chest_wall_is_anterior_is_refused(
    tmp_path: Path,
) -> None:
    """Taken to be in the project's frame, the box's x = 0 face as the rib is anterior."""
    project, _, _ = _in_lps_mm(tmp_path)
    front = {"plane": {"point": [0.0, 0.0, 0.0], "normal": [-1.0, 0.0, 0.0]}, "distance": 0.001}
    for orientation in (None, {"axes": "project"}):
        with pytest.raises(GeometryError, match=r"taken to be in the project's frame .* chest "
                           r"wall .* mm anterior of the breast's centroid.*declare the file's "
                           r"axes"):
            write_imported_mesh(_spec(project, "m", front, orientation), SIZE,
                                tmp_path / "m.xdmf")
    assert not (tmp_path / "m.xdmf").exists()


@pytest.mark.solve
def test_the_displacement_is_the_same_in_either_frame(tmp_path: Path) -> None:
    """Prone at C1 = 1 kPa on the box and on its LPS-mm left-breast twin agree at every vertex.

    The twin's field is mapped back into the file's axes and units (mm) for the comparison.
    """
    from fem.case import run_case
    from fem.case_files import read_points
    from fem.sweep import Case

    project, rib_lps, lps = _in_lps_mm(tmp_path)
    declared = _spec(lps, "mm", rib_lps, {"axes": "LPS", "side": "left"})
    fields = {}
    for name, spec in (("project", _spec(project, "m", RIB)), ("lps", declared)):
        write_imported_mesh(spec, SIZE, tmp_path / f"{name}.xdmf")
        summary = run_case(tmp_path / f"{name}.xdmf", Case(1.0, 180.0), tmp_path / name)
        assert summary["status"] == "converged"
        points = read_points(tmp_path / name / "points.h5")
        fields[name] = (points["X"], points["u"])
    (xa, ua), (xb, ub) = fields["project"], fields["lps"]
    _, match = cKDTree(xa).query(xb)
    assert np.allclose(xa[match], xb, atol=1e-12)
    u_file = declared.to_file_frame(ub)  # mm, the file's axes
    expected = declared.to_file_frame(ua[match])
    assert np.abs(expected).max() > 1.0  # the box sags by more than a millimetre
    assert np.abs(u_file - expected).max() < 1e-6 * np.abs(expected).max()


# -- a chest wall that is not a plane: the posterior rule, and the preview -------------------

POSTERIOR_RULE = {"posterior": {"angle": 30.0, "band": 1.0}}  # file units: mm below


@pytest.mark.unit
def test_the_posterior_rule_finds_the_chest_wall_in_either_frame(tmp_path: Path) -> None:
    """On the box, the facets facing posterior near the back are its posterior face.

    So in the project's frame and in LPS mm of a left breast (where posterior is +y).
    """
    project, _, lps = _in_lps_mm(tmp_path)
    rule_m = {"posterior": {"angle": 30.0, "band": 0.001}}
    direct = write_imported_mesh(_spec(project, "m", rule_m, {"axes": "project"}), SIZE,
                                 tmp_path / "a.xdmf")
    declared = _spec(lps, "mm", POSTERIOR_RULE, {"axes": "LPS", "side": "left"})
    mapped = write_imported_mesh(declared, SIZE, tmp_path / "b.xdmf")
    for report in (direct, mapped):
        assert report["area_m2"]["rib"] == pytest.approx(BOX[1] * BOX[2], rel=1e-9)
    # without the orientation, posterior would be the file's +x (the box's left face): refused
    with pytest.raises(GeometryError, match=r"mesh.file.surfaces.rib: a posterior rule needs to "
                       r"know where the patient's posterior is in the file: give "
                       r"mesh.file.orientation"):
        _spec(lps, "mm", POSTERIOR_RULE)


@pytest.mark.unit
def test_the_preview_prints_what_each_rule_selects(tmp_path: Path) -> None:
    import subprocess
    import sys

    import yaml

    _, rib_lps, lps = _in_lps_mm(tmp_path)
    mesh = {"source": "file", "size": {"fold_size": None, "order": 1, "global_size": 0.03},
            "file": {"path": str(lps), "units": "mm",
                     "orientation": {"axes": "LPS", "side": "left"},
                     "surfaces": {"rib": POSTERIOR_RULE, "cranial": {
                         "plane": {"point": [0, 0, 1000 * BOX[2]], "normal": [0, 0, 1]},
                         "distance": 1.0}}}}
    config = tmp_path / "import.yaml"
    config.write_text(yaml.safe_dump({"mesh": mesh}))
    cmd = [sys.executable, "-m", "meshes.preview", str(config), "--png", str(tmp_path / "r.png")]
    run = subprocess.run(cmd, capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    total = 2 * (BOX[0] * BOX[1] + BOX[1] * BOX[2] + BOX[0] * BOX[2])
    rib = next(line for line in run.stdout.splitlines() if line.startswith("rib"))
    assert f"{1e4 * BOX[1] * BOX[2]:.1f}" in rib and f"{100 * BOX[1] * BOX[2] / total:.1f}%" in rib
    assert "facing posterior within 30°" in rib
    assert run.stdout.splitlines()[-1] == "the rules would do"
    assert (tmp_path / "r.png").stat().st_size > 10_000
    # a rule that takes the whole boundary: the preview says the import would stop
    mesh["file"]["surfaces"] = {"rib": {"plane": {"point": [0, 0, 0], "normal": [0, 1, 0]},
                                        "distance": 1000.0}}
    config.write_text(yaml.safe_dump({"mesh": mesh}))
    run = subprocess.run(cmd, capture_output=True, text=True)
    assert run.returncode == 1
    assert "the import would stop: the rib rule" in run.stdout and "narrow the rule" in run.stdout


def _import_config(folder: Path, orientation: dict, rib: dict | None = None) -> tuple[dict, Path]:
    """The box in LPS mm of a left breast, as a config's mesh section (the LPS rib by default).

    Returns the section and the config file written with it alone.
    """
    import yaml

    _, rib_lps, lps = _in_lps_mm(folder)
    mesh = {"source": "file", "file": {"path": str(lps), "units": "mm", "orientation": orientation,
                                       "surfaces": {"rib": rib if rib is not None else rib_lps}}}
    config = folder / "import.yaml"
    config.write_text(yaml.safe_dump({"mesh": mesh}))
    return mesh, config


@pytest.mark.unit
@pytest.mark.parametrize(("orientation", "rib", "words"), [
    ({}, POSTERIOR_RULE, "mesh.file.orientation"),
    ({"axes": "LPS", "side": "left"}, {"posterior": {"angle": 30.0, "band": 1.0},
                                       "distance": 1.0}, "mesh.file.surfaces.rib"),
    ({"axes": "LPS", "side": "left"}, {"posterior": {"angle": "30", "band": 1.0}},
     "mesh.file.surfaces.rib"),
], ids=["empty-orientation", "distance-beside-posterior", "angle-as-text"])
def test_the_preview_refuses_what_the_run_refuses(
    tmp_path: Path, orientation: dict, rib: dict, words: str,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """A preview that said "the rules would do" where the run then stopped is worse than none."""
    import yaml

    from meshes.preview import main
    from run.config import ConfigError, WorkflowConfig

    mesh, config = _import_config(tmp_path, orientation, rib)
    assert main([str(config)]) == 2
    said = capsys.readouterr().err
    assert "invalid mesh section" in said and words in said, said
    full = yaml.safe_load((REPO / "tests" / "config.yaml").read_text())
    full["mesh"] = mesh
    with pytest.raises(ConfigError, match=re.escape(words)):  # the run's own check
        WorkflowConfig.from_mapping(full)


@pytest.mark.unit
@pytest.mark.parametrize("orientation", [{"axes": "RAS", "side": "left"},
                                         {"axes": "LAS", "side": "left"}],
                         ids=["lps-declared-ras", "anterior-code"])
def test_the_preview_says_the_import_would_stop_where_the_chest_wall_lands_anterior(
    tmp_path: Path, orientation: dict, capsys: pytest.CaptureFixture[str],
) -> None:
    """An LPS file declared RAS, or with A for P: the run refuses it, so the preview says so."""
    from meshes.preview import main

    mesh, config = _import_config(tmp_path, orientation)
    assert main([str(config)]) == 1
    said = capsys.readouterr().out
    assert "the import would stop" in said and "anterior of the breast's centroid" in said
    with pytest.raises(GeometryError, match="anterior of the breast's centroid"):
        write_imported_mesh(ImportSpec.from_mapping(mesh["file"]), SIZE, tmp_path / "m.xdmf")


@pytest.mark.unit
def test_named_points_go_to_the_project_frame_and_back(tmp_path: Path) -> None:
    """`python -m meshes.frame`: a tumour picked in LPS mm lands in the project's frame.

    A left breast's point goes where the import puts the same material point, and comes back
    unchanged.
    """
    import yaml

    from meshes.frame import main

    config = tmp_path / "c.yaml"
    config.write_text(yaml.safe_dump({"mesh": {"source": "file", "file": {
        "path": "b.stl", "units": "mm", "orientation": {"axes": "LPS", "side": "left"},
        "surfaces": {"rib": {"group": "chest"}}}}}))
    points = tmp_path / "p.csv"
    # LPS: +x left (lateral for a left breast), +y posterior, +z superior
    points.write_text("name,x,y,z\ntumour,30,-40,10\nmargin,32.5,-40,10\n")
    assert main([str(config), str(points), str(tmp_path / "q.csv"), "--to", "project"]) == 0
    lines = (tmp_path / "q.csv").read_text().splitlines()
    tumour = np.array([float(v) for v in lines[1].split(",")[1:]])
    # project: x posterior, y lateral, z cranial, metres
    assert np.allclose(tumour, [-0.040, 0.030, 0.010])
    assert main([str(config), str(tmp_path / "q.csv"), str(tmp_path / "r.csv"), "--to",
                 "file"]) == 0
    back = (tmp_path / "r.csv").read_text().splitlines()
    assert np.allclose([float(v) for v in back[2].split(",")[1:]], [32.5, -40, 10])
    points.write_text("name,x,y\ntumour,1,2\n")
    assert main([str(config), str(points), str(tmp_path / "q.csv"), "--to", "project"]) == 2
