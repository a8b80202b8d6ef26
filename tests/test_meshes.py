"""The parametric geometry: validation, tags, areas and the rib surface."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from meshes.parametric import BreastGeometry, GeometryError
from meshes.tags import Boundary


def test_geometry_rejects_bad_values_by_name() -> None:
    with pytest.raises(GeometryError, match="layer_thickness"):
        BreastGeometry(layer_thickness=-0.01)
    with pytest.raises(GeometryError, match="mound_offset"):
        BreastGeometry(mound_offset=0.2)
    with pytest.raises(GeometryError, match="unknown geometry parameter"):
        BreastGeometry.from_mapping({"mound_lenght": 0.1})


def test_mound_may_not_reach_a_cut_plane() -> None:
    with pytest.raises(GeometryError, match="cranial or caudal"):
        BreastGeometry(mound_radius_cranial=0.11)


def test_all_six_surfaces_are_tagged_and_areas_add_up(coarse_mesh: Path) -> None:
    report = json.loads((coarse_mesh.parent / "quality.json").read_text())
    areas = report["area_m2"]
    assert set(areas) == {b.label for b in Boundary}
    assert all(a > 0 for a in areas.values())
    assert report["inverted_cells"] == 0
    from meshes.io import read_mesh

    mesh, _, facet_tags = read_mesh(coarse_mesh)
    assert set(np.unique(facet_tags.values)) == {int(b) for b in Boundary}
    # every exterior facet carries exactly one tag
    from dolfinx.cpp.mesh import exterior_facet_indices

    mesh.topology.create_connectivity(2, 3)
    exterior = exterior_facet_indices(mesh.topology)
    assert np.array_equal(np.sort(facet_tags.indices), np.sort(exterior))


def test_every_rib_node_lies_on_the_rib_cage(coarse_mesh: Path) -> None:
    from dolfinx.cpp.mesh import entities_to_geometry

    from meshes.io import read_mesh

    mesh, _, facet_tags = read_mesh(coarse_mesh)
    rib = facet_tags.indices[facet_tags.values == int(Boundary.RIB)]
    nodes = entities_to_geometry(mesh._mesh, 2, rib, False)
    x = mesh.geometry.x[np.unique(nodes)]
    distance = BreastGeometry().rib_level_set(x)
    assert np.max(np.abs(distance)) < 1e-6
    skin = facet_tags.indices[facet_tags.values == int(Boundary.SKIN)]
    skin_x = mesh.geometry.x[np.unique(entities_to_geometry(mesh._mesh, 2, skin, False))]
    # the skin is not the rib: most skin nodes lie centimetres away from the rib cage
    assert np.median(BreastGeometry().rib_level_set(skin_x)) > 0.01
