"""The parametric geometry: validation, tags, areas, the rib surface, sizes, order, outputs."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import yaml

from meshes.parametric import BreastGeometry, GeometryError
from meshes.sizing import MeshSize
from meshes.tags import Boundary
from tests.conftest import REPO

pytestmark = pytest.mark.unit


def test_geometry_rejects_bad_values_by_name() -> None:
    with pytest.raises(GeometryError, match="layer_thickness"):
        BreastGeometry(layer_thickness=-0.01)
    with pytest.raises(GeometryError, match="mound_offset"):
        BreastGeometry(mound_offset=0.2)
    with pytest.raises(GeometryError, match="unknown geometry parameter"):
        BreastGeometry.from_mapping({"mound_lenght": 0.1})


def test_fold_radius_is_validated_by_name() -> None:
    with pytest.raises(GeometryError, match="fold_radius"):
        BreastGeometry(fold_radius=-0.001)
    with pytest.raises(GeometryError, match="fold_radius"):
        BreastGeometry(fold_radius=0.05)  # more than half the mound's base radius


def test_the_fold_between_mound_and_layer_is_rounded() -> None:
    from meshes.build import gmsh_session, mound_volume
    from meshes.parametric import build_occ_model, fold_curves

    sharp = replace(BreastGeometry(), fold_radius=0.0)
    rounded = replace(sharp, fold_radius=0.025)
    # sharp: a crease curve lies on both the ellipsoid and the layer's outer cylinder;
    # rounded: the fillet's faces meet each of them along its own curve, none on both
    for geometry, crease in ((sharp, True), (rounded, False)):
        with gmsh_session() as model:
            volume = build_occ_model(model, geometry)
            assert bool(fold_curves(model, geometry, volume)) is crease
    # the fillet fills the fold: less than an R x R square swept around the base
    added = mound_volume(rounded) - mound_volume(sharp)
    R = rounded.fold_radius
    assert 0 < added < R**2 * 2 * np.pi * (max(rounded.mound_base_radii()) + R)


def test_mound_may_not_reach_a_cut_plane() -> None:
    with pytest.raises(GeometryError, match="cranial or caudal"):
        BreastGeometry(mound_radius_cranial=0.11)


def test_mesh_size_rejects_bad_values_by_name() -> None:
    with pytest.raises(GeometryError, match="grading"):
        MeshSize(grading=0.0)
    with pytest.raises(GeometryError, match="mound_size"):
        MeshSize(global_size=0.01, mound_size=0.02)
    with pytest.raises(GeometryError, match="order"):
        MeshSize(order=3)
    with pytest.raises(GeometryError, match="unknown mesh.size"):
        MeshSize.from_mapping({"globl_size": 0.01})
    with pytest.raises(GeometryError, match="fold_size"):
        MeshSize(fold_size=0.0)
    with pytest.raises(GeometryError, match="fold_size"):
        MeshSize(fold_size=float("nan"))


def test_config_geometry_is_the_code_default() -> None:
    # the workflow's default breast and BreastGeometry() (used by tests and tools) must agree;
    # MeshSize() is the plain law any geometry accepts, the config grades it to the fold
    config = yaml.safe_load((REPO / "config.yaml").read_text())["mesh"]
    assert BreastGeometry.from_mapping(config["geometry"]) == BreastGeometry()
    MeshSize.from_mapping(config["size"])  # valid (raises by name otherwise)


def test_default_breast_is_anatomically_plausible() -> None:
    from meshes.build import mound_volume

    g = BreastGeometry()
    assert 300.0 <= 1e6 * mound_volume(g) <= 1500.0
    assert g.projection_from_chest_wall <= 0.15
    # the projection counts the layer: tip to rib = layer + offset + length along the normal
    assert g.projection_from_chest_wall == pytest.approx(
        g.layer_thickness + g.mound_projection, rel=0.05
    )


def test_rib_distance_is_exact() -> None:
    g = BreastGeometry()
    psi = np.radians(np.linspace(-180, 180, 200001))
    ring = np.stack([g.rib_depth * (1 - np.cos(psi)), g.rib_half_width * np.sin(psi)], 1)
    x = np.random.default_rng(0).uniform(-0.15, 0.3, (50, 3))
    brute = np.sqrt(((x[:, None, :2] - ring[None]) ** 2).sum(axis=2)).min(axis=1)
    assert np.allclose(g.rib_distance(x), brute, atol=1e-6)


def test_all_six_surfaces_are_tagged_and_areas_add_up(coarse_mesh: Path) -> None:
    report = json.loads((coarse_mesh.parent / "quality.json").read_text())
    areas = report["area_m2"]
    assert set(areas) == {b.label for b in Boundary}
    assert all(a > 0 for a in areas.values())
    assert report["inverted_cells"] == 0 and report["degenerate_cells"] == 0
    # the six named surfaces cover the boundary exactly: no facet left out, none inside
    assert report["untagged_exterior_facets"] == 0 and report["tagged_interior_facets"] == 0
    assert sum(areas.values()) == pytest.approx(report["exterior_area_m2"], rel=1e-12)
    # and they are the CAD's surfaces: each meshed area within 2 % of the exact one
    for name, exact in report["cad"]["area_m2"].items():
        assert areas[name] == pytest.approx(exact, rel=0.02), name
    from meshes.io import read_mesh

    mesh, _, facet_tags = read_mesh(coarse_mesh)
    assert set(np.unique(facet_tags.values)) == {int(b) for b in Boundary}
    # every exterior facet carries exactly one tag
    from dolfinx.cpp.mesh import exterior_facet_indices

    mesh.topology.create_connectivity(2, 3)
    exterior = exterior_facet_indices(mesh.topology)
    assert np.array_equal(np.sort(facet_tags.indices), np.sort(exterior))


def test_quality_report_has_every_field(coarse_mesh: Path) -> None:
    report = json.loads((coarse_mesh.parent / "quality.json").read_text())
    for key in (
        "cells",
        "vertices",
        "nodes",
        "volume_ml",
        "area_m2",
        "boundary_area_m2",
        "min_minSICN",
        "mean_minSICN",
        "min_gamma",
        "mean_gamma",
        "min_dihedral_deg",
        "dofs",
        "mesh_wall_s",
        "anatomy",
        "cad",
        "volume_error_vs_cad",
    ):
        assert key in report, key
    assert 0 < report["min_minSICN"] <= report["mean_minSICN"] <= 1
    assert 0 < report["min_dihedral_deg"] < 70.53  # the regular tetrahedron's angle bounds the min
    assert abs(report["volume_error_vs_cad"]) < 0.02
    # Taylor-Hood P2/P1: 3 (V + E) + V unknowns
    v, e = report["vertices"], report["edges"]
    assert report["dofs"]["P2/P1"] == 3 * (v + e) + v


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


def test_second_order_mesh_is_curved_onto_the_cad(tmp_path: Path) -> None:
    from dolfinx.cpp.mesh import entities_to_geometry

    from meshes.build import write_parametric_mesh
    from meshes.io import read_mesh

    size = MeshSize(global_size=0.03, mound_size=0.02, order=2)
    report = write_parametric_mesh(BreastGeometry(), size, tmp_path / "mesh.xdmf")
    assert report["nodes"] > report["vertices"]
    # curved cells hold the CAD's volume and rib area far better than straight ones
    assert abs(report["volume_error_vs_cad"]) < 1e-3
    assert report["curved"]["area_m2"]["rib"] == pytest.approx(
        report["cad"]["area_m2"]["rib"], rel=1e-4
    )
    assert abs(report["volume_m3"] / report["cad"]["volume_m3"] - 1) > abs(
        report["volume_error_vs_cad"]
    )
    mesh, _, facet_tags = read_mesh(tmp_path / "mesh.xdmf")
    assert mesh.geometry.dofmap.links(0).size == 10
    rib = facet_tags.indices[facet_tags.values == int(Boundary.RIB)]
    rib_vertices = np.unique(entities_to_geometry(mesh._mesh, 2, rib, False))
    on_rib = np.abs(BreastGeometry().rib_level_set(mesh.geometry.x)) < 1e-6
    assert np.all(on_rib[rib_vertices])
    # mid-edge nodes sit on the curved rib cage too (not on chords, ~1 mm inside it): a
    # triangulated surface has about three edges per vertex, so about 4x the nodes
    assert on_rib.sum() > 3 * rib_vertices.size


def test_size_field_refines_the_mound_and_optionally_the_rib(tmp_path: Path) -> None:
    from meshes.build import gmsh_session, mesh_arrays, mesh_parametric
    from meshes.quality import tet_volumes

    g = BreastGeometry()
    tip = g.mound_tip

    def edge_lengths(size: MeshSize) -> tuple[float, float, float]:
        with gmsh_session() as model:
            groups = mesh_parametric(model, g, size)
            x, tets, facets = mesh_arrays(model, groups)
        h = np.cbrt(
            6 * np.sqrt(2) * np.abs(tet_volumes(x, tets))
        )  # edge of the equal-volume regular tet
        centre = x[tets].mean(axis=1)
        near_tip = np.linalg.norm(centre - tip, axis=1) < 0.03
        far = np.abs(centre[:, 2] - g.z_cranial) < 0.03
        rib_nodes = np.unique(facets[Boundary.RIB])
        on_rib = np.isin(tets, rib_nodes).sum(axis=1) >= 3
        return (
            float(np.median(h[near_tip])),
            float(np.median(h[far])),
            float(np.median(h[on_rib & far])),
        )

    uniform = edge_lengths(MeshSize(global_size=0.03, mound_size=0.03))
    mound = edge_lengths(MeshSize(global_size=0.03, mound_size=0.012))
    rib = edge_lengths(MeshSize(global_size=0.03, mound_size=0.012, rib_size=0.008))
    assert mound[0] < 0.6 * uniform[0]  # finer at the tip ...
    assert mound[1] == pytest.approx(uniform[1], rel=0.15)  # ... not far from it
    assert rib[2] < 0.6 * mound[2]  # rib_size refines the chest wall far from the mound too


def _eval_math(expression: str, x: np.ndarray) -> np.ndarray:
    """Evaluate a gmsh MathEval expression at points ``x`` (n, 3)."""
    code = expression.replace("^", "**").replace("Sqrt", "np.sqrt").replace("Fabs", "np.abs")
    return eval(code, {"np": np, "x": x[:, 0], "y": x[:, 1], "z": x[:, 2]})  # noqa: S307


@pytest.mark.parametrize("fold_radius", [0.0, 0.01])
def test_fold_size_refines_the_fold(fold_radius: float) -> None:
    from meshes.build import gmsh_session, mesh_arrays, mesh_parametric
    from meshes.parametric import build_occ_model, curve_points, fold_curves
    from meshes.quality import tet_volumes
    from meshes.sizing import fold_distance_expression

    sharp = replace(BreastGeometry(), fold_radius=0.0)
    with gmsh_session() as model:
        volume = build_occ_model(model, sharp)
        crease = np.vstack([curve_points(model, c, 200) for c in fold_curves(model, sharp, volume)])
    # The analytic distance vanishes on the crease and grows like the true one off it.
    assert np.abs(_eval_math(fold_distance_expression(sharp), crease)).max() < 1e-4
    skin_normal = np.c_[crease[:, 0] - sharp.rib_depth, crease[:, 1], 0 * crease[:, 2]]
    skin_normal /= np.linalg.norm(skin_normal, axis=1)[:, None]
    off = _eval_math(fold_distance_expression(sharp), crease - 0.005 * skin_normal)
    assert np.all((off > 0.003) & (off < 0.008))

    g = replace(sharp, fold_radius=fold_radius)

    def sizes(size: MeshSize) -> tuple[int, float, float]:
        with gmsh_session() as model:
            x, tets, _ = mesh_arrays(model, mesh_parametric(model, g, size))
        h = np.cbrt(6 * np.sqrt(2) * np.abs(tet_volumes(x, tets)))
        d = np.min(np.linalg.norm(x[tets].mean(axis=1)[:, None] - crease[None], axis=2), axis=1)
        near, far = d < fold_radius + 0.008, d > fold_radius + 0.06
        return len(tets), float(np.median(h[near])), float(np.median(h[far]))

    plain = sizes(MeshSize(global_size=0.03, mound_size=0.02))
    fold = sizes(MeshSize(global_size=0.03, mound_size=0.02, fold_size=0.005))
    assert fold[1] < 0.5 * plain[1]  # much finer at the fold, sharp or rounded ...
    assert fold[2] == pytest.approx(plain[2], rel=0.15)  # ... not far from it
    assert fold[0] > plain[0]


def test_png_shows_the_named_surfaces(tmp_path: Path) -> None:
    from meshes.config import MeshConfig, make_mesh

    config = MeshConfig.from_mapping(
        {"source": "parametric", "size": {"global_size": 0.03, "mound_size": 0.02}}
    )
    paths = [tmp_path / n for n in ("mesh.xdmf", "quality.json", "mesh.png")]
    report = make_mesh(config, *paths)
    png = paths[2].read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 50_000
    assert json.loads(paths[1].read_text())["cells"] == report["cells"]
    # every surface is drawn: pixels of its hue and saturation (shading changes only the
    # brightness) cover far more than its legend patch (about 250 pixels)
    import matplotlib.image
    from matplotlib.colors import rgb_to_hsv, to_rgb

    from meshes.plot import COLOURS

    hsv = rgb_to_hsv(matplotlib.image.imread(paths[2])[..., :3].reshape(-1, 3))
    for boundary, colour in COLOURS.items():
        h, s, _ = rgb_to_hsv(np.array(to_rgb(colour)))
        dh = np.abs(hsv[:, 0] - h)
        same = (np.minimum(dh, 1 - dh) < 0.02) & (np.abs(hsv[:, 1] - s) < 0.1) & (hsv[:, 2] > 0.15)
        assert same.sum() > 1000, boundary


def test_mesh_config_rejects_unknown_keys_and_missing_file() -> None:
    from meshes.config import MeshConfig

    with pytest.raises(GeometryError, match="unknown mesh key"):
        MeshConfig.from_mapping({"source": "parametric", "sizes": {}})
    with pytest.raises(GeometryError, match="mesh.file is missing"):
        MeshConfig.from_mapping({"source": "file"})
    assert (
        MeshConfig.from_mapping({"source": "parametric", "fixed": {"rib": "all"}}).input_files()
        == []
    )


def test_a_points_file_reads_the_same_by_either_reader(tmp_path: Path) -> None:
    """The C parser's names and numbers are the row-by-row reader's, to the last bit.

    A regular file takes the fast reader; one it does not read as regular (a short row) falls
    to the row-by-row one, which names the row. Names that look like numbers or "NA" stay text.
    """
    from meshes import points as pts
    from meshes.exceptions import MeshInputError

    rng = np.random.default_rng(0)
    X = rng.normal(size=(5, 3)) * 0.05
    names = ["007", "NA", "tumour, centre", " margin", ""]
    path = tmp_path / "p.csv"
    pts.write_points(path, names, X)
    assert pts._read_regular(path) is not None
    read_names, read_X = pts.read_points(path)
    assert read_names == names and np.array_equal(read_X, X)
    path.write_bytes(b"\xef\xbb\xbf" + path.read_bytes().replace(b"\r\n", b"\n") + b"\n\n")
    assert pts.read_points(path)[0] == names  # a byte-order mark, blank lines at the end
    path.write_text(path.read_text(encoding="utf-8-sig") + "short,1,2\n")
    assert pts._read_regular(path) is None
    with pytest.raises(MeshInputError, match=r"row 9: expected name,x,y,z, got \['short'"):
        pts.read_points(path)
