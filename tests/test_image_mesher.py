"""The image mesher: CGAL's labelled-image mesher, a tissue tag per label, the same file every run.

The label volume is :mod:`meshes.phantom`'s with a skin label, at a quick test's voxel size
(:func:`tests.test_clinic_data.phantom`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from meshes.config import MeshConfig, make_mesh
from meshes.exceptions import GeometryError
from meshes.image import ImageSpec
from meshes.tags import Tissue
from tests.test_clinic_data import image_section, labelled_tissue_ml, phantom, tissue_section

pytestmark = pytest.mark.unit


def cgal_section(image: Path, **extra: object) -> dict:
    return tissue_section(image, mesher="cgal", **extra)


def test_cgal_meshes_a_tissue_per_label_and_two_runs_write_the_same_file(tmp_path: Path) -> None:
    """Fat, gland, skin and tumour labels tag their cells; two runs give byte-identical files.

    Each tissue's meshed volume is near its labelled one, and the mesh file (cells, tags and
    points) is the same, byte for byte, on a second run.
    """
    from meshes.io import read_mesh

    image = phantom(tmp_path, skin_mm=3.0)
    config = MeshConfig.from_mapping(cgal_section(image))
    assert config.image.mesher == "cgal"
    reports = [make_mesh(config, tmp_path / run / "mesh.xdmf", tmp_path / run / "q.json",
                         tmp_path / run / "m.png")
               for run in ("a", "b")]
    report = reports[0]
    info = report["input"]
    assert info["mesher"] == "cgal"
    labelled = labelled_tissue_ml(image)
    meshed = report["tissue_volume_ml"]
    assert set(meshed) == {"fat", "gland", "skin", "tumour"}
    for name in ("gland", "skin"):
        assert meshed[name] == pytest.approx(labelled[name], rel=0.05), name
    assert meshed["tumour"] == pytest.approx(labelled["tumour"], rel=0.15)
    assert info["volume_kept"] == pytest.approx(1.0, abs=0.02)
    # the floor: the few slivers the flips and moves leave are counted and reported
    assert info["quality_floor"]["cells_below_floor"] <= 0.001 * report["cells"]
    _, cell_tags, facet_tags = read_mesh(tmp_path / "a" / "mesh.xdmf")
    counts = dict(zip(*np.unique(cell_tags.values, return_counts=True), strict=True))
    assert counts == {int(Tissue.from_label(name)): n for name, n in info["tissue_cells"].items()}
    assert len(facet_tags.values) > 0
    for suffix in (".h5", ".xdmf"):
        first = (tmp_path / "a" / f"mesh{suffix}").read_bytes()
        assert first == (tmp_path / "b" / f"mesh{suffix}").read_bytes(), suffix


def test_the_cgal_rib_is_where_the_chest_label_meets_the_breast(tmp_path: Path) -> None:
    """Without tissues, CGAL's mesh is one tissue and its rib the base's ellipse."""
    import math

    config = MeshConfig.from_mapping(image_section(phantom(tmp_path), side="left", mesher="cgal"))
    report = make_mesh(config, tmp_path / "mesh.xdmf", tmp_path / "q.json", tmp_path / "m.png")
    assert report["input"]["mesher"] == "cgal"
    assert "tissue_volume_ml" not in report
    assert 1e4 * report["area_m2"]["rib"] == pytest.approx(math.pi * 70 * 65 / 100, rel=0.08)


def test_an_unknown_mesher_is_refused_by_name(tmp_path: Path) -> None:
    """``mesh.image.mesher`` is cgal or ftetwild; another value is refused, naming both."""
    section = image_section(tmp_path / "labels.nii.gz", side="left")["image"]
    with pytest.raises(GeometryError, match=r"mesh\.image\.mesher must be one of cgal, ftetwild"):
        ImageSpec.from_mapping({**section, "mesher": "tetgen"})
    assert ImageSpec.from_mapping(section).mesher == "cgal"  # the default
    assert ImageSpec.from_mapping({**section, "mesher": "cgal"}).mesher == "cgal"
