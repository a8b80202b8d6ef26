"""Outputs that never overwrite an input, and voxel indices within their image (issue 70).

``meshes.frame`` with its output equal to its points overwrote the user's picks; an output in a
missing folder, or a folder, was a traceback; voxel indices outside the image came back as
points metres away. ``report.viewer MODEL -o MODEL/model.json`` replaced the model's card with
the page (tests/probe_inputs.py runs that one on a trained model).
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

import numpy as np
import pytest
import yaml

from meshes.arguments import output_file, overwritten
from meshes.frame import main as frame

pytestmark = pytest.mark.unit

PICKS = "name,x,y,z\ntumour,30,-40,10\nmargin,32.5,-40,10\n"


@pytest.fixture
def imported(tmp_path: Path) -> tuple[Path, Path]:
    """A config importing a file in LPS mm (a left breast), and a CSV of picks in it."""
    config = tmp_path / "c.yaml"
    config.write_text(yaml.safe_dump({"mesh": {"source": "file", "file": {
        "path": str(tmp_path / "b.stl"), "units": "mm",
        "orientation": {"axes": "LPS", "side": "left"},
        "surfaces": {"rib": {"group": "chest"}}}}}))
    (tmp_path / "b.stl").write_text("solid b\nendsolid b\n")
    picks = tmp_path / "picks.csv"
    picks.write_text(PICKS)
    return config, picks


def refused(argv: list[str], capsys: pytest.CaptureFixture[str]) -> str:
    """``meshes.frame`` on ``argv`` stops with status 2; its one error line."""
    try:
        status = frame(argv)
    except SystemExit as stop:  # argparse's refusal
        status = stop.code
    assert status == 2
    errors = [line for line in capsys.readouterr().err.splitlines() if "error:" in line]
    assert len(errors) == 1, errors
    return errors[0]


@pytest.mark.parametrize("target", ["picks.csv", "c.yaml", "b.stl"])
def test_frame_refuses_an_output_that_is_one_of_its_inputs(
        tmp_path: Path, imported: tuple[Path, Path], capsys: pytest.CaptureFixture[str],
        target: str) -> None:
    config, picks = imported
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    line = refused([str(config), str(picks), str(tmp_path / target), "--to", "project"], capsys)
    assert f"{target} is an input" in line
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before


def test_frame_refuses_the_picks_by_another_name(
        tmp_path: Path, imported: tuple[Path, Path], capsys: pytest.CaptureFixture[str]) -> None:
    config, picks = imported
    (tmp_path / "sub").mkdir()
    os.symlink(picks, tmp_path / "sub" / "link.csv")
    line = refused([str(config), str(tmp_path / "sub" / ".." / "picks.csv"),
                    str(tmp_path / "sub" / "link.csv"), "--to", "project"], capsys)
    assert "is an input (points:" in line
    assert picks.read_text() == PICKS


def test_frame_refuses_a_folder_and_a_file_as_the_output_folder(
        tmp_path: Path, imported: tuple[Path, Path], capsys: pytest.CaptureFixture[str]) -> None:
    config, picks = imported
    line = refused([str(config), str(picks), str(tmp_path), "--to", "project"], capsys)
    assert "is a folder, not a file to write" in line
    line = refused([str(config), str(picks), str(picks / "deeper" / "out.csv"), "--to",
                    "project"], capsys)
    assert "the folder of" in line and "is a file" in line


def test_frame_makes_a_missing_output_folder(tmp_path: Path,
                                             imported: tuple[Path, Path]) -> None:
    config, picks = imported
    out = tmp_path / "new" / "folder" / "out.csv"
    assert frame([str(config), str(picks), str(out), "--to", "project"]) == 0
    assert out.read_text().splitlines()[0] == "name,x,y,z"


def image_config(tmp_path: Path, shape: tuple[int, int, int] = (50, 56, 36)) -> Path:
    """A config meshing a phantom label volume of ``shape`` voxels."""
    from meshes.phantom import BREAST_LABELS, PECTORAL, write_phantom

    image = write_phantom(tmp_path / "labels.nii.gz", shape=shape, spacing_mm=(3.2, 3.0, 4.0))
    config = tmp_path / "image.yaml"
    config.write_text(yaml.safe_dump({"mesh": {"source": "image", "image": {
        "path": str(image), "breast_labels": list(BREAST_LABELS), "chest_label": PECTORAL,
        "side": "left"}}}))
    return config


@pytest.mark.parametrize("index", ["1000,1000,1000", "-3,10,10", "10,56,10"])
def test_frame_refuses_voxel_indices_outside_the_image(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], index: str) -> None:
    config = image_config(tmp_path)
    picks = tmp_path / "voxels.csv"
    picks.write_text(f"name,x,y,z\ninside,10,10,10\nstray,{index}\n")
    out = tmp_path / "out.csv"
    line = refused([str(config), str(picks), str(out), "--to", "project", "--voxels"], capsys)
    assert "point 2 ('stray') at voxel indices" in line
    assert "outside the image" in line and "50 x 56 x 36 voxels" in line
    assert not out.exists()


def test_frame_takes_voxel_indices_to_the_image_s_edges(tmp_path: Path) -> None:
    config = image_config(tmp_path)
    picks = tmp_path / "voxels.csv"
    picks.write_text("name,x,y,z\nfirst,-0.5,-0.5,-0.5\nlast,49.5,55.5,35.5\n")
    out = tmp_path / "out.csv"
    assert frame([str(config), str(picks), str(out), "--to", "project", "--voxels"]) == 0
    xyz = np.loadtxt(out, delimiter=",", skiprows=1, usecols=(1, 2, 3))
    # the image's diagonal: 50 x 3.2, 56 x 3.0, 36 x 4.0 mm
    assert np.linalg.norm(xyz[1] - xyz[0]) == pytest.approx(
        1e-3 * np.linalg.norm([160.0, 168.0, 144.0]), rel=1e-6)  # NIfTI: float32


def test_an_output_is_checked_against_every_kind_of_input(tmp_path: Path) -> None:
    model = tmp_path / "model"
    model.mkdir()
    (model / "model.json").write_text("{}")
    mesh = tmp_path / "mesh.xdmf"
    mesh.write_text("")
    (tmp_path / "mesh.h5").write_bytes(b"")
    inputs = [("MODEL", model), ("--mesh", mesh), ("--points", None)]
    assert "lies in an input folder (MODEL" in overwritten(model / "model.json", inputs)
    assert "lies in an input folder (MODEL" in overwritten(model / "new.html", inputs)
    assert "is the HDF5 data of an input (--mesh" in overwritten(tmp_path / "mesh.h5", inputs)
    assert "is an input (--mesh" in overwritten(tmp_path / "." / "mesh.xdmf", inputs)
    os.link(mesh, tmp_path / "hard.xdmf")
    assert "is an input (--mesh" in overwritten(tmp_path / "hard.xdmf", inputs)
    assert overwritten(tmp_path / "page.html", inputs) is None
    assert overwritten(tmp_path / "model.html", inputs) is None


def test_output_file_names_a_file_in_the_way_of_its_folder(tmp_path: Path) -> None:
    (tmp_path / "a").write_text("")
    with pytest.raises(argparse.ArgumentTypeError, match=r"the folder of .* is a file \(.*a\)"):
        output_file(str(tmp_path / "a" / "b" / "c.csv"))
    assert output_file(str(tmp_path / "x" / "y" / "c.csv")) == tmp_path / "x" / "y" / "c.csv"


@pytest.mark.parametrize("out", ["picks.csv", "tracked.csv"])
def test_tracking_refuses_to_write_over_its_inputs(tmp_path: Path, out: str,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    """``tracking --out`` and the JSON it writes beside it are checked the same way.

    The command is ``studies.reference_state.tracking``.
    """
    from studies.reference_state.tracking import main as tracking

    picks = tmp_path / "picks.csv"
    picks.write_text(PICKS)
    config = tmp_path / "tracked.json"  # where --out tracked.csv writes its JSON
    config.write_text("{}")
    with pytest.raises(SystemExit) as stop:
        tracking([str(picks), "--imaged", "m.xdmf", "--reference", "r.xdmf", "--model", "model",
                  "--c1", "1", "--phi", "0", "--out", str(tmp_path / out),
                  "--config", str(config)])
    assert stop.value.code == 2
    assert "it would be overwritten" in capsys.readouterr().err
    assert picks.read_text() == PICKS and config.read_text() == "{}"
