"""What the skin changes (fe_study/skin.py, config fe_study.skin): settings, paths, result.

No solve: the settings come from the config, the result is written by hand and read back,
the tumour point is located on the coarse mesh, and the report's section is built from it.
"""

from __future__ import annotations

import copy
import re
from pathlib import Path

import numpy as np
import pytest
import yaml

from fem.materials import SkinLayer
from fem.sweep import Case
from meshes.schema import load_schema
from run.config import ConfigError, WorkflowConfig
from studies.fe_study.skin import (
    SkinCase,
    SkinStudy,
    prone_supine_pairs,
    skin_settings,
    solver_settings,
    tumour_paths,
    tumour_point,
)
from studies.results import ResultFormatError
from tests.conftest import REPO

pytestmark = pytest.mark.unit

CONFIG = yaml.safe_load((REPO / "config.yaml").read_text())
PRONE, SUPINE = Case(1.0, 180.0), Case(1.0, 0.0)


def parsed(raw: dict) -> WorkflowConfig:
    return WorkflowConfig.from_mapping(copy.deepcopy(raw))


def test_the_settings_are_homogeneous_the_default_skin_then_each_other_ratio_and_thickness(
) -> None:
    config = parsed(CONFIG)
    settings = skin_settings(config.fe_study.skin, config.solver)
    assert [s.name for s in settings] == ["homogeneous", "skin", "ratio 7", "ratio 100",
                                          "thickness 1 mm", "thickness 2.5 mm"]
    assert [(s.ratio, s.thickness_m) for s in settings] == [
        (None, None), (18.5, 0.0015), (7.0, 0.0015), (100.0, 0.0015), (18.5, 0.001),
        (18.5, 0.0025)]
    assert all(s.wrinkles for s in settings[1:])
    assert solver_settings(settings[0], config.solver).skin is None
    stiff = solver_settings(settings[3], config.solver)
    assert stiff.skin == SkinLayer(0.0015, True)
    assert stiff.tissues.describe()["skin"] == 100.0 and stiff.tissues.describe()["gland"] == 2.0
    # the material's own skin is the default, and the list's 18.5 and 1.5 mm become variants
    raw = copy.deepcopy(CONFIG)
    raw["material"]["tissues"] = {"skin": 20.0}
    raw["material"]["skin"] = {"thickness": 0.002, "wrinkles": False}
    config = parsed(raw)
    names = [(s.name, s.ratio, s.thickness_m, s.wrinkles)
             for s in skin_settings(config.fe_study.skin, config.solver)]
    assert names[1] == ("skin", 20.0, 0.002, False)
    assert [n[0] for n in names[2:]] == ["ratio 7", "ratio 18.5", "ratio 100", "thickness 1 mm",
                                         "thickness 1.5 mm", "thickness 2.5 mm"]


@pytest.mark.parametrize(("key", "value", "words"), [
    ("ratios", [0.0], r"fe_study\.skin\.ratios\.0: 0\.0 is less than or equal to the minimum"),
    ("thicknesses", [0.02], r"fe_study\.skin\.thicknesses\.0: 0\.02 is greater than the max"),
    ("tumour", [0.0, 0.1], r"fe_study\.skin\.tumour: \[0\.0, 0\.1\] is too short"),
])
def test_a_bad_skin_setting_is_named(key: str, value: list, words: str) -> None:
    raw = copy.deepcopy(CONFIG)
    raw["fe_study"]["skin"][key] = value
    with pytest.raises(ConfigError, match=words):
        parsed(raw)


def test_the_schemas_thickest_skin_is_the_membranes() -> None:
    bound = load_schema()["properties"]["fe_study"]["properties"]["skin"]["properties"][
        "thicknesses"]["items"]["maximum"]
    SkinLayer(bound)
    with pytest.raises(ValueError, match="material.skin.thickness"):
        SkinLayer(bound * 1.01)


def test_the_tumours_path_pairs_prone_and_supine_by_c1() -> None:
    cases = [Case(1.0, 180.0), Case(5.0, 180.0), Case(1.0, 0.0), Case(2.0, 0.0),
             Case(1.0, 0.0, 30.0)]
    assert prone_supine_pairs(cases) == [(PRONE, SUPINE)]
    settings = skin_settings(parsed(CONFIG).fe_study.skin, parsed(CONFIG).solver)[:2]
    rows = [case("homogeneous", PRONE, [0, 0, 0]), case("homogeneous", SUPINE, [3, 4, 0]),
            case("skin", PRONE, [0, 0, 0]), case("skin", SUPINE, [1, 0, 0], "failed")]
    base, skin = tumour_paths(settings, rows, [PRONE, SUPINE])
    assert (base.distance_mm, base.vector_mm) == (5.0, [3.0, 4.0, 0.0])
    assert skin.setting == "skin" and skin.distance_mm is None and skin.vector_mm is None


def case(setting: str, c: Case, tumour: list[float], status: str = "converged",
         max_disp: float = 10.0) -> SkinCase:
    return SkinCase(setting, c.id, c.C1, c.phi, c.theta, status,
                    1.0 if status == "converged" else 0.25, 1, 5, 2.0, max_disp,
                    [float(x) for x in tumour])


def small_study() -> SkinStudy:
    config = parsed(CONFIG)
    settings = skin_settings(config.fe_study.skin, config.solver)
    rows = []
    for i, s in enumerate(settings):  # a stiffer or thicker skin moves the breast less
        less = 0.0 if s.ratio is None else 0.05 * s.ratio + 2e3 * s.thickness_m
        rows.append(case(s.name, PRONE, [0, 0, -i], max_disp=30.0 - less))
        rows.append(case(s.name, SUPINE, [0, 0, 10 + i], "failed" if s.name == "ratio 7"
                         else "converged", 40.0 - less))
    return SkinStudy("mesh.xdmf", [1.0, 2.0, 3.0], "volume centroid", settings, rows,
                     tumour_paths(settings, rows, [PRONE, SUPINE]), 12.0)


def test_the_result_round_trips_and_names_a_renamed_key(tmp_path: Path) -> None:
    study = small_study()
    study.write(tmp_path / "skin.json")
    assert SkinStudy.read(tmp_path / "skin.json") == study
    text = (tmp_path / "skin.json").read_text().replace('"max_disp_mm"', '"max_u_mm"', 1)
    (tmp_path / "renamed.json").write_text(text)
    with pytest.raises(ResultFormatError, match=r"cases\[0\]: missing key 'max_disp_mm'"):
        SkinStudy.read(tmp_path / "renamed.json")


def test_the_section_shows_every_setting_and_an_unconverged_case_as_such(tmp_path: Path) -> None:
    from report.context import Context
    from report.sections.skin import skin_section

    ctx = Context(out_dir=tmp_path, clinical=[], paths={}, clinical_fields=[],
                  results={"fe_skin": small_study()})
    page = skin_section(ctx)
    assert (tmp_path / "skin.png").is_file()
    supine = re.search(rf'<table id="skin-{SUPINE.id}">(.*?)</table>', page, re.S)[1]
    assert "<td>ratio 7</td><td>7</td><td>1.5</td><td>not converged (stopped at λ = 0.250)" \
        in supine
    assert "<td>homogeneous</td><td>none</td><td>none</td><td>converged</td>" in supine
    tumour = re.search(r'<table id="skin-tumour">(.*?)</table>', page, re.S)[1]
    assert "<td>ratio 7</td><td>not converged (supine)</td>" in tumour
    assert "<td>homogeneous</td><td>10.00</td>" in tumour
    assert "<td></td>" not in page and "n/a" not in page
    # the words come from the data: the default skin's ratios, the trend with the ratio
    assert "1 of 12 solves did not converge: ratio 7 at c1=1.00_phi=0.0_theta=0.0." in page
    assert ("The default skin moves the breast less than the homogeneous model: max |u| "
            "87–90 % of the homogeneous value in the 2 case(s) where both converged.") in page
    assert "A stiffer skin moves the breast less, in each of the 1 case(s)" in page
    assert "A thicker skin moves the breast less, in each of the 2 case(s)" in page
    assert "the tumour moves 12.0 mm from prone to supine with the default skin, against " \
        "10.0 mm homogeneous" in page


def test_the_tumour_point_lies_in_the_mesh_or_is_refused_by_its_key(coarse_mesh: Path) -> None:
    from dolfinx import fem

    from meshes.io import read_mesh

    mesh, _, _ = read_mesh(coarse_mesh)
    u = fem.Function(fem.VectorFunctionSpace(mesh, ("Lagrange", 1)))
    point, source = tumour_point(u, None)
    assert source == "volume centroid"
    x = mesh.geometry.x
    assert np.all(point > x.min(axis=0)) and np.all(point < x.max(axis=0))
    inside = tuple(float(v) for v in point)
    assert tumour_point(u, inside)[1] == "fe_study.skin.tumour"
    with pytest.raises(ConfigError, match=r"fe_study\.skin\.tumour: the point \[1\.0, 0\.0, "
                                          r"0\.0\] m lies .* mm outside m\.xdmf"):
        tumour_point(u, (1.0, 0.0, 0.0), "m.xdmf")
