"""A clinic's label volumes as they are found: headers checked, axes corrected, one breast.

Each bad file is :mod:`meshes.phantom`'s label volume (a small one: header checks read no
mesh) spoiled as files are found: a NIfTI ``pixdim`` of 0, NaN or negative beside a sform that
says the voxel size, a MetaImage direction matrix scaled or sheared, a voxel size in other
units, a file cut short, two breasts in one image, a breast cut by the field of view, and a
research phantom's header whose axes are wrong (corrected by ``mesh.image.orientation``). Each
is refused before any meshing, naming the header field or the config key, or (the cut breast)
warned of in the quality report and the preview.
"""

from __future__ import annotations

import json
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from meshes.config import MeshConfig, make_mesh
from meshes.exceptions import GeometryError, ImageHeaderError, MeshInputError, UnitsError
from meshes.image import ImageSpec, working_spacing
from meshes.image_header import Grid, read_header
from meshes.label_volume import border_cuts, check_before_meshing, read_labels
from meshes.orientation import axes_directions
from meshes.phantom import BREAST_LABELS, PECTORAL, write_phantom
from meshes.sizing import MeshSize
from tests.conftest import REPO

pytestmark = pytest.mark.unit

#: A small phantom (a header test reads no mesh): 160 x 165 x 150 mm.
SHAPE, SPACING = (40, 44, 30), (4.0, 3.75, 5.0)
#: NIfTI-1's pixdim, a float32 each: pixdim[1] (the voxel size along i) is at 80.
PIXDIM_1 = 80


def small(folder: Path, suffix: str = ".nii", **kwargs: object) -> Path:
    return write_phantom(folder / f"labels{suffix}", SHAPE, SPACING, **kwargs)


def section(path: Path, **extra: object) -> dict:
    """The ``mesh`` section of an image import of ``path`` (the phantom's labels)."""
    return {"source": "image", "size": {"global_size": 0.025},
            "image": {"path": str(path), "breast_labels": list(BREAST_LABELS),
                      "chest_label": PECTORAL, "side": "left", **extra}}


def spoil_nifti(path: Path, offset: int, value: float, name: str) -> Path:
    """A copy of the NIfTI ``path`` with the float32 at ``offset`` set to ``value``."""
    data = bytearray(path.read_bytes())
    struct.pack_into("<f", data, offset, value)
    out = path.with_name(name)
    out.write_bytes(bytes(data))
    return out


def edit_text(path: Path, old: str, new: str, name: str) -> Path:
    """A copy of a text header with ``old`` replaced (it must occur)."""
    text = path.read_text()
    assert old in text, text
    out = path.with_name(name)
    out.write_text(text.replace(old, new))
    return out


def mesh(folder: Path, **image: object) -> dict:
    """Mesh ``image`` (a section's ``image`` keys) into ``folder``; the quality report."""
    config = MeshConfig.from_mapping(section(**image))
    return make_mesh(config, folder / "mesh.xdmf", folder / "q.json", folder / "m.png")


def preview(folder: Path, mesh_section: dict) -> subprocess.CompletedProcess:
    config = folder / "config.yaml"
    config.write_text(yaml.safe_dump({"mesh": mesh_section}))
    return subprocess.run([sys.executable, "-m", "meshes.preview", str(config)], cwd=REPO,
                          capture_output=True, text=True)


# -- the voxel size -----------------------------------------------------------------------------


@pytest.mark.parametrize("value", [0.0, float("nan"), -4.0])
def test_a_nifti_pixdim_that_is_not_finite_and_positive_is_refused(tmp_path: Path,
                                                                  value: float) -> None:
    """A pixdim of 0 or NaN (ITK: 1 mm, a console warning) or negative (ITK: a mirror image)."""
    bad = spoil_nifti(small(tmp_path), PIXDIM_1, value, "bad.nii")
    with pytest.raises(ImageHeaderError, match=r"pixdim\[1:4\] = \((0|nan|-4), 3\.75, 5\) mm is "
                       r"not a finite, positive voxel size \(axis i\)"):
        read_header(bad)
    with pytest.raises(ImageHeaderError, match="pixdim"):
        mesh(tmp_path, path=bad)
    assert not (tmp_path / "mesh.xdmf").exists()


def test_preview_refuses_a_zero_pixdim_with_exit_status_2(tmp_path: Path) -> None:
    bad = spoil_nifti(small(tmp_path), PIXDIM_1, 0.0, "bad.nii")
    done = preview(tmp_path, section(bad))
    assert done.returncode == 2, done.stdout + done.stderr
    assert "pixdim[1:4] = (0, 3.75, 5) mm is not a finite, positive voxel size" in done.stderr


def test_a_nifti_pixdim_that_disagrees_with_its_sform_is_refused(tmp_path: Path) -> None:
    """A pixdim of 1 mm where the sform's columns are 4 mm long: ITK would take the qform's 1 mm."""
    bad = spoil_nifti(small(tmp_path), PIXDIM_1, 1.0, "bad.nii")
    with pytest.raises(ImageHeaderError, match=r"pixdim\[1:4\] = \(1, 3\.75, 5\) mm disagrees "
                       r"with its sform .* voxels of 4 x 3\.75 x 5 mm"):
        read_header(bad)


def test_a_negative_metaimage_element_spacing_is_refused(tmp_path: Path) -> None:
    """ITK takes ``ElementSpacing = -4`` as 4 mm along a flipped axis: a mirror image."""
    header = small(tmp_path, ".mhd")
    bad = edit_text(header, "ElementSpacing = 4 3.75 5", "ElementSpacing = -4 3.75 5", "bad.mhd")
    with pytest.raises(ImageHeaderError, match=r"ElementSpacing = \(-4, 3\.75, 5\) mm is not a "
                       "finite, positive voxel size"):
        read_header(bad)


def test_a_voxel_size_in_other_units_is_refused_by_its_size(tmp_path: Path) -> None:
    """1e-6 mm voxels (a unit slip): the surface import's size check, before any voxel is read.

    Before, the meshing stopped on ``ValueError: array is too big`` (a traceback).
    """
    header = small(tmp_path, ".mhd")
    bad = edit_text(header, "ElementSpacing = 4 3.75 5", "ElementSpacing = 4e-06 3.75e-06 5e-06",
                    "bad.mhd")
    with pytest.raises(UnitsError, match=r"ElementSpacing: 4e-06 x 3\.75e-06 x 5e-06 mm\) the "
                       r"image is 0\.000\d+ mm across .* probably in other units"):
        mesh(tmp_path, path=bad)


# -- the direction cosines ----------------------------------------------------------------------


@pytest.mark.parametrize(("matrix", "said"), [
    ("2 0 0 0 2 0 0 0 2", r"columns are 2, 2, 2 long, at 90, 90, 90 degrees"),
    ("1 0.3 0 0 1 0 0 0 1", r"columns are 1\.044, 1, 1 long, at 73\.3, 90, 90 degrees"),
])
def test_a_metaimage_direction_that_is_not_orthonormal_is_refused(tmp_path: Path, matrix: str,
                                                                  said: str) -> None:
    """Scaled by 2 it meshed 8 times the labelled volume; sheared it stopped on the rib rule."""
    header = small(tmp_path, ".mhd")
    bad = edit_text(header, "TransformMatrix = 1 0 0 0 1 0 0 0 1", f"TransformMatrix = {matrix}",
                    "bad.mhd")
    with pytest.raises(ImageHeaderError, match=r"direction cosines \(TransformMatrix\) are not "
                       r"orthonormal \(beyond 0\.001\): its " + said):
        mesh(tmp_path, path=bad)
    # the config's axes set the header's direction aside
    grid = read_header(bad, "LPS")
    assert np.array_equal(grid.direction, np.eye(3)) and grid.axes_from == "mesh.image.orientation"


def test_a_sheared_nrrd_direction_is_refused(tmp_path: Path) -> None:
    header = small(tmp_path, ".nhdr")
    bad = edit_text(header, "space directions: (4,0,0)", "space directions: (4,1,0)", "bad.nhdr")
    with pytest.raises(ImageHeaderError, match=r"\(space directions\) are not orthonormal"):
        read_header(bad)


# -- truncated files ----------------------------------------------------------------------------


@pytest.mark.parametrize("suffix", [".nii.gz", ".nii"])
def test_a_nifti_cut_short_is_refused_as_truncated(tmp_path: Path, suffix: str) -> None:
    """ITK reads a NIfTI cut to half its bytes as whole, the missing voxels as background."""
    whole = small(tmp_path, suffix)
    data = whole.read_bytes()
    cut = tmp_path / f"cut{suffix}"
    cut.write_bytes(data[: len(data) // 2])
    with pytest.raises(ImageHeaderError, match=r"cut\.nii(\.gz)? is truncated"):
        mesh(tmp_path, path=cut)
    read_header(whole)  # the whole file passes


def test_a_metaimage_cut_short_is_named_truncated(tmp_path: Path) -> None:
    """ITK refuses it too, but as ``No such file or directory``."""
    header = small(tmp_path, ".mhd")
    raw = tmp_path / "labels.raw"
    raw.write_bytes(raw.read_bytes()[:1000])
    with pytest.raises(ImageHeaderError, match=r"labels\.mhd is truncated: its data "
                       r"\(labels\.raw\) holds 1000 bytes where its header .* needs 52800"):
        read_header(header)


def test_a_nifti2_header_is_checked_as_nifti1(tmp_path: Path) -> None:
    """The same fields at NIfTI-2's offsets (doubles, 64-bit dims): a zero pixdim is refused."""
    data = bytearray(small(tmp_path).read_bytes())
    one = {k: struct.unpack_from("<" + f, data, o) for k, (o, f) in (
        ("dim", (40, "8h")), ("pixdim", (76, "8f")), ("srow", (280, "12f")),
        ("codes", (252, "2h")), ("datatype", (70, "2h")))}
    two = bytearray(544)
    struct.pack_into("<i", two, 0, 540)
    two[4:12] = b"n+2\0\r\n\x1a\n"
    struct.pack_into("<2h", two, 12, *one["datatype"])
    struct.pack_into("<8q", two, 16, *one["dim"])
    struct.pack_into("<8d", two, 104, *(0.0 if i == 1 else v for i, v in enumerate(one["pixdim"])))
    struct.pack_into("<q", two, 168, 544)
    struct.pack_into("<d", two, 176, 1.0)  # scl_slope
    struct.pack_into("<2i", two, 344, *one["codes"])
    struct.pack_into("<12d", two, 400, *one["srow"])
    struct.pack_into("<i", two, 500, 10)  # mm and s
    path = tmp_path / "two.nii"
    path.write_bytes(bytes(two) + bytes(data[352:]))
    with pytest.raises(ImageHeaderError, match=r"pixdim\[1:4\] = \(0, 3\.75, 5\) mm"):
        read_header(path)


# -- one breast, the whole breast -----------------------------------------------------------------


def two_breasts(folder: Path) -> Path:
    """The phantom twice, side by side along i: two equal breasts, each on its pectoral."""
    import SimpleITK as sitk

    one = sitk.ReadImage(str(small(folder)))
    both = sitk.GetImageFromArray(np.concatenate([sitk.GetArrayFromImage(one)] * 2, axis=2))
    both.SetSpacing(one.GetSpacing())
    both.SetOrigin(one.GetOrigin())
    both.SetDirection(one.GetDirection())
    path = folder / "two.nii.gz"
    sitk.WriteImage(both, str(path), True)
    return path


def test_two_equal_breasts_are_refused_naming_their_sizes(tmp_path: Path) -> None:
    """Before, the larger (by a voxel, or the first) was meshed and the other dropped unsaid."""
    with pytest.raises(MeshInputError, match=r"the breast's labels form 2 separate pieces: the "
                       r"largest (\d+\.\d) ml .*, the next \1 ml \(at .* 100 % of the largest\)"):
        mesh(tmp_path, path=two_breasts(tmp_path))


def test_a_speck_is_dropped_and_recorded(tmp_path: Path) -> None:
    """A few voxels apart from the breast (a segmentation's speck) are no refusal."""
    labels, grid = read_labels(small(tmp_path))
    labels[1:3, 1:3, 1:3] = BREAST_LABELS[0]
    spec = ImageSpec.from_mapping(section(tmp_path / "labels.nii")["image"])
    checked = check_before_meshing(labels, grid, spec, working_spacing(MeshSize(0.025)))
    assert len(checked["pieces_ml"]) == 2 and checked["pieces_ml"][1] == pytest.approx(0.6)


def cut_anteriorly(folder: Path, slices: int) -> Path:
    """The phantom with its ``slices`` most anterior j-planes (identity direction) cut off."""
    import SimpleITK as sitk

    image = sitk.ReadImage(str(small(folder, ".nrrd")))
    cut = image[:, slices:, :]  # SimpleITK keeps the origin of what is kept
    path = folder / "cut.nrrd"
    sitk.WriteImage(cut, str(path), True)
    return path


def test_a_breast_cut_by_the_field_of_view_is_warned_of(tmp_path: Path) -> None:
    """The anterior cut face would be skin: a warning with its area, in the report and preview."""
    path = cut_anteriorly(tmp_path, 16)
    spec = ImageSpec.from_mapping(section(path)["image"])
    labels, grid = read_labels(path)
    checked = check_before_meshing(labels, grid, spec, working_spacing(MeshSize(0.025)))
    breast = np.isin(labels[:, 0, :], BREAST_LABELS)  # the cut face: 4 x 5 mm a voxel
    assert checked["field_of_view_cut_cm2"] == {"A": pytest.approx(0.2 * breast.sum())}
    said = "the breast's labels reach the edge of the image on its anterior (A)"
    assert said in checked["warnings"][0]
    report = mesh(tmp_path, path=path)
    assert said in json.loads((tmp_path / "q.json").read_text())["input"]["warnings"][0]
    assert report["input"]["field_of_view_cut_cm2"] == checked["field_of_view_cut_cm2"]
    done = preview(tmp_path, section(path))
    assert done.returncode == 0, done.stderr
    assert f"warning: {said}" in done.stdout


def test_the_whole_phantom_has_no_cut(tmp_path: Path) -> None:
    labels, grid = read_labels(small(tmp_path))
    assert border_cuts(np.isin(labels, BREAST_LABELS), grid) == {}


def test_the_chest_side_of_the_image_may_cut_the_breast() -> None:
    """A breast image cut at the chest wall: its posterior face holds breast, no warning."""
    breast = np.zeros((10, 10, 10), dtype=bool)
    breast[3:7, 5:, 3:7] = True  # reaching j = 9, posterior in LPS with the identity
    grid = Grid(np.zeros(3), np.ones(3), np.eye(3), breast.shape)
    assert border_cuts(breast, grid) == {}
    breast[3:7, 0:, 3:7] = True
    assert border_cuts(breast, grid) == {"A": pytest.approx(0.16)}


# -- the axes: mesh.image.orientation -----------------------------------------------------------


def research_phantom(folder: Path) -> Path:
    """A breast image written LPS with the identity direction, its breast pointing along +k.

    Its voxel axes really point i superior, j left, k anterior (SLA), as research phantoms
    are often written.
    """
    import SimpleITK as sitk

    true = write_phantom(folder / "true.nrrd", (70, 80, 60), (2.0, 2.0, 2.0),
                         direction=axes_directions("SLA"))
    image = sitk.ReadImage(str(true))
    image.SetDirection(tuple(np.eye(3).ravel()))
    path = folder / "research.nrrd"
    sitk.WriteImage(image, str(path), True)
    true.unlink()
    return path


def test_a_wrong_header_is_refused_before_meshing_naming_the_image_key(tmp_path: Path) -> None:
    """The message names mesh.image.orientation, not mesh.file.orientation (an image has none)."""
    with pytest.raises(GeometryError) as refused:
        mesh(tmp_path, path=research_phantom(tmp_path))
    said = str(refused.value)
    assert "towards the patient's inferior (I), 90° from posterior, where it belongs posterior" in (
        said) and "give them as mesh.image.orientation" in said
    assert "mesh.file" not in said


def test_mesh_image_orientation_corrects_a_wrong_header(tmp_path: Path) -> None:
    """With ``orientation: SLA`` it meshes to the floor, keeping the labelled volume."""
    report = mesh(tmp_path, path=research_phantom(tmp_path), orientation="SLA")
    info = report["input"]
    assert info["axes"]["code"] == "SLA" and info["axes"]["from"] == "mesh.image.orientation"
    assert info["volume_kept"] == pytest.approx(1.0, abs=0.03)
    assert info["quality_floor"]["cells_below_floor"] == 0
    assert info["warnings"] == []


def test_preview_says_which_axes_were_used(tmp_path: Path) -> None:
    image = research_phantom(tmp_path)
    done = preview(tmp_path, section(image, orientation="sla"))
    assert done.returncode == 0, done.stderr
    assert "voxel axes i, j, k point SLA, by mesh.image.orientation (the header's" in (
        done.stdout)
    done = preview(tmp_path, section(small(tmp_path)))
    assert "voxel axes i, j, k point LPS, by the header's direction cosines;" in done.stdout


def test_the_orientation_key_is_checked(tmp_path: Path) -> None:
    from meshes.schema import load_schema, schema_errors

    config = yaml.safe_load((REPO / "config.yaml").read_text())
    config["mesh"] = section(Path("labels.nii.gz"), orientation="SLA")
    assert schema_errors(config, load_schema()) == []
    config["mesh"]["image"]["orientation"] = "XYZ"
    assert any(e.startswith("mesh.image.orientation") for e in schema_errors(config,
                                                                              load_schema()))
    with pytest.raises(GeometryError, match=r"mesh\.image\.orientation 'LLS' is not an "
                       "anatomical code"):
        ImageSpec.from_mapping(section(Path("labels.nii.gz"), orientation="LLS")["image"])


def test_voxels_map_by_the_configured_axes(tmp_path: Path) -> None:
    """``meshes.frame --voxels`` places voxels by mesh.image.orientation, not the header."""
    image = research_phantom(tmp_path)
    spec = ImageSpec.from_mapping(section(image, orientation="SLA")["image"])
    header = read_header(image)
    moved = spec.voxels_to_file_frame(np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]))
    assert np.allclose(moved - header.origin, [[0, 0, 2.0], [0, -2.0, 0]])
    assert np.allclose(spec.file_frame_to_voxels(moved), [[1, 0, 0], [0, 0, 1]])


# -- every check that needs no mesh, before the meshing --------------------------------------------


@pytest.mark.parametrize("mesher", ["ftetwild", "cgal"])
def test_the_side_is_asked_before_any_meshing(tmp_path: Path, mesher: str,
                                              monkeypatch: pytest.MonkeyPatch) -> None:
    """A breast image without mesh.image.side is refused before either mesher starts.

    The meshers' first steps are replaced by a tripwire: reaching one fails the test (before,
    the breast was meshed and only then was the side asked).
    """
    import meshes.cgal_image
    import meshes.image

    def tripwire(*args: object, **kwargs: object) -> None:
        raise AssertionError("the meshing started before the side was asked")

    monkeypatch.setattr(meshes.image, "breast_surface", tripwire)
    monkeypatch.setattr(meshes.cgal_image, "mesh_labels", tripwire)
    values = section(small(tmp_path), mesher=mesher)
    del values["image"]["side"]
    with pytest.raises(GeometryError, match="give mesh.image.side"):
        make_mesh(MeshConfig.from_mapping(values), tmp_path / "m.xdmf", tmp_path / "q.json",
                  tmp_path / "m.png")


@pytest.mark.solve
def test_the_corrected_research_phantom_solves(tmp_path: Path) -> None:
    """Meshed with ``orientation: SLA``, prone gravity solves on it."""
    mesh(tmp_path, path=research_phantom(tmp_path), orientation="SLA")
    out = tmp_path / "prone"
    done = subprocess.run([sys.executable, "-m", "fem.cli", str(tmp_path / "mesh.xdmf"), "--c1",
                           "1.0", "--phi", "180", "--out", str(out)], cwd=REPO,
                          capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-2000:]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "converged" and summary["max_disp_mm"] > 0.5



def test_a_posterior_rule_that_selects_nothing_names_the_image_key(tmp_path: Path) -> None:
    """Its remedy names mesh.image.orientation, which an image has, not mesh.file.orientation."""
    from meshes.exceptions import NoRibFacetsError

    values = section(small(tmp_path))
    del values["image"]["chest_label"]
    values["image"]["surfaces"] = {"rib": {"posterior": {"angle": 0.01, "band": 0.01}}}
    with pytest.raises(NoRibFacetsError, match=r"or check mesh\.image\.orientation$"):
        make_mesh(MeshConfig.from_mapping(values), tmp_path / "m.xdmf", tmp_path / "q.json",
                  tmp_path / "m.png")
