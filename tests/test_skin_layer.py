"""The breast with its skin resolved as cells (meshes.skin_layer), and the membrane against it.

* the layer's mesh: conforming (every exterior face named, none inside), its cells tagged skin
  and t thick along the skin's normal, its outer surface the ``skin`` boundary, the rib and cut
  planes named as on the plain mesh, the body's volume and areas those of the plain mesh, the
  same on every run;
* the push through the layer at a rim node stays in the cut plane;
* on the default anatomy (coarse), the clinical cases at 5 kPa prone and supine: the membrane
  that resists compression carries what the resolved layer does, to 5 % of max |u|; the
  wrinkling membrane (the chosen one) is softer than the resolved layer by more than that;
  without skin the breast sags far more (docs/tissues.md).
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from meshes.parametric import BreastGeometry
from meshes.sizing import MeshSize
from tests.conftest import COARSE, REPO, built_once

THICKNESS = 0.0015


@pytest.fixture(scope="module")
def layered(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The default geometry at the coarse sizes with a 1.5 mm skin layer, one cell across.

    ``mesh.xdmf`` (the layer's cells skin), ``fat.xdmf`` (the same cells all fat),
    ``quality.json``, and ``across_2.xdmf`` (the layer two cells across) in one folder, built
    once.
    """
    from meshes.skin_layer import SkinLayerSpec, write_skin_layer_mesh

    def build(folder: Path) -> None:
        report = write_skin_layer_mesh(BreastGeometry(), MeshSize(**COARSE),
                                       SkinLayerSpec(THICKNESS), folder / "mesh.xdmf",
                                       folder / "fat.xdmf")
        (folder / "quality.json").write_text(json.dumps(report))
        write_skin_layer_mesh(BreastGeometry(), MeshSize(**COARSE), SkinLayerSpec(THICKNESS, 2),
                              folder / "across_2.xdmf")

    return built_once(tmp_path_factory, "skin_layer", build)


@pytest.mark.unit
def test_the_skin_layer_is_a_conforming_shell_of_skin_cells_over_the_same_breast(
    layered: Path, coarse_mesh: Path,
) -> None:
    from meshes.build import gmsh_session
    from meshes.exceptions import GeometryError
    from meshes.skin_layer import SkinLayerSpec, mesh_skin_layer
    from meshes.tags import Boundary, Tissue

    report = json.loads((layered / "quality.json").read_text())
    plain = json.loads((coarse_mesh.parent / "quality.json").read_text())
    # conforming: a face cut one way in one prism and the other in its neighbour would leave
    # two exterior faces inside the body, untagged
    assert report["untagged_exterior_facets"] == 0
    assert report["tagged_interior_facets"] == 0
    assert report["inverted_cells"] == report["degenerate_cells"] == 0
    # the same breast: its volume and every named surface's area
    assert report["volume_m3"] == pytest.approx(plain["volume_m3"], rel=5e-3)
    for name, area in plain["area_m2"].items():
        assert report["area_m2"][name] == pytest.approx(area, rel=0.01), name
    layer = report["skin_layer"]
    assert layer["thickness_along_normal_m"] == pytest.approx([THICKNESS] * 2, rel=1e-9)
    assert layer["skin_volume_ml"] == pytest.approx(
        1e6 * THICKNESS * report["area_m2"]["skin"], rel=0.05)
    assert report["tissue_cells"] == {"fat": report["cells"] - layer["skin_cells"],
                                      "skin": layer["skin_cells"]}
    assert layer["skin_cells"] > 0

    size = MeshSize(**COARSE)
    runs = []
    for across in (1, 1, 2):
        with gmsh_session() as model:
            x, tets, tissues, facets, _ = mesh_skin_layer(
                model, BreastGeometry(), size, SkinLayerSpec(THICKNESS, across))
        runs.append((x, tets, tissues, facets))
    (x, tets, tissues, facets), again, two = runs
    # the same on every run
    assert np.array_equal(x, again[0]) and np.array_equal(tets, again[1])
    # two cells across: twice the skin's cells over the same body cells, the same skin area
    assert np.sum(two[2] == int(Tissue.SKIN)) == 2 * np.sum(tissues == int(Tissue.SKIN))
    assert np.sum(two[2] == int(Tissue.FAT)) == np.sum(tissues == int(Tissue.FAT))
    assert len(two[3][Boundary.SKIN]) == len(facets[Boundary.SKIN])
    # the skin's vertices are the layer's, none the body's under it
    body = np.unique(tets[tissues == int(Tissue.FAT)])
    assert not np.isin(facets[Boundary.SKIN], body).any()
    with pytest.raises(GeometryError, match="straight-sided"):
        with gmsh_session() as model:
            mesh_skin_layer(model, BreastGeometry(), replace(size, order=2),
                            SkinLayerSpec(THICKNESS))


@pytest.mark.unit
def test_the_push_through_the_layer_is_t_along_the_normal_and_stays_in_a_cut_plane() -> None:
    from meshes.skin_layer import layer_directions

    n = np.array([0.6, 0.0, 0.8])
    m = np.array([0.0, 0.0, 1.0])  # a cut plane z = const the skin meets at an angle
    smooth, rim = layer_directions([[n], [n]], [[], [m]], 0.002)
    assert smooth == pytest.approx(0.002 * n)
    assert rim @ n == pytest.approx(0.002) and rim @ m == pytest.approx(0.0, abs=1e-15)
    # where two faces meet at an angle, the mitred corner: t along each normal
    a, b = np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])
    corner = layer_directions([[a, b]], [[]], 0.002)[0]
    assert corner == pytest.approx([0.002, 0.002, 0.0])


@pytest.mark.solve
def test_the_plain_membrane_matches_a_resolved_skin_on_the_breast_the_wrinkling_one_is_softer(
    layered: Path,
) -> None:
    """The skin membrane against a resolved skin layer on the default anatomy (coarse).

    Prone and supine at 5 kPa with the config's solver settings: the layer's cells skin
    (18.5 × the fat, one cell 1.5 mm across: two across move max |u| by under 1 %, so the
    layer is resolved; ``python -m benchmarks.skin_reference`` shows the same at the default
    size), against the same cells all fat with the membrane on the skin facets. The membrane
    that resists compression carries what the layer does, to 5 %; the wrinkling membrane,
    which carries nothing where the skin is pressed narrower than it would contract of itself
    (most of the skin, by a few per cent: a layer of cells resists that), lets the breast sag
    more than 5 % further; without skin it sags 30 % further or more.
    """
    from fem.case import CaseRunner
    from fem.configfile import read_config_file
    from fem.materials import SkinLayer
    from fem.parameters import SolverSettings
    from fem.sweep import Case

    base = SolverSettings.from_config(read_config_file(REPO / "config.yaml"))
    cases = (Case(5.0, 180.0), Case(5.0, 0.0))
    settings = {"resolved": ("mesh.xdmf", None), "two across": ("across_2.xdmf", None),
                "plain membrane": ("fat.xdmf", False),
                "wrinkling membrane": ("fat.xdmf", True), "no skin": ("fat.xdmf", None)}
    sag: dict[str, list[float]] = {}
    for name, (mesh, wrinkles) in settings.items():
        skin = None if wrinkles is None else SkinLayer(THICKNESS, wrinkles)
        with CaseRunner(layered / mesh, replace(base, skin=skin)) as runner:
            assert (runner.problem.material.skin is None) == (wrinkles is None), name
            assert (runner.problem.material.stiffness_ratio is None) == (wrinkles is not None
                                                                          or name == "no skin")
            sag[name] = []
            for case in cases:
                result, _ = runner.solve(case)
                assert result.converged, (name, case.id, result.reason)
                u = runner.problem.displacement().x.array.reshape(-1, 3)
                sag[name].append(float(np.linalg.norm(u, axis=1).max()))
    ratio = {name: np.array(values) / np.array(sag["resolved"]) for name, values in sag.items()}
    assert np.all(np.abs(ratio["two across"] - 1.0) < 0.01), ratio
    assert np.all(ratio["no skin"] > 1.3), ratio
    assert np.all(np.abs(ratio["plain membrane"] - 1.0) < 0.05), ratio
    assert np.all((ratio["wrinkling membrane"] > 1.05) & (ratio["wrinkling membrane"] < 1.3)), \
        ratio
