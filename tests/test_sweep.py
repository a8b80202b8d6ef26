"""Case identifiers, the sweep definition and parameter validation (no FE)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import yaml

from fem.exceptions import InvalidParameterError
from fem.parameters import Gravity, Loading, Material, SolverSettings
from fem.sweep import PAPER_PHI_DEG, Case, sweep_cases
from tests.conftest import REPO

pytestmark = pytest.mark.unit


def test_case_id_round_trips() -> None:
    case = Case(1.0, -150.0, 0.0)
    assert case.id == "c1=1.00_phi=-150.0_theta=0.0"
    assert Case.from_id(case.id) == case


def test_the_rules_patterns_name_a_case_folder_as_its_id() -> None:
    """One spelling of a case folder: the rules' patterns, filled, are Case.id.

    The solve rules' (fem.sweep.CASE_WILDCARDS) and a chain's (one C1, {direction} left open).
    """
    from fem.sweep import CASE_WILDCARDS, DIRECTION_WILDCARDS, case_folder, case_id

    case = Case(1.0, -150.0, 90.0)
    assert CASE_WILDCARDS.format(c1="1.00", phi="-150.0", theta="90.0") == case.id
    assert case_id("1.00", "{direction}").format(direction=case.direction_id) == case.id
    assert DIRECTION_WILDCARDS.format(phi="-150.0", theta="90.0") == case.direction_id
    assert case_folder("results/cases", case) == f"results/cases/{case.id}"
    assert case_folder("results/outside") == f"results/outside/{CASE_WILDCARDS}"


def test_a_summary_gives_its_case_by_its_numbers() -> None:
    from fem.sweep import case_id

    summary = {"case": "c1=0.50_phi=0.0_theta=0.0", "C1": 5.0, "phi": 180.0, "theta": -90.0}
    assert Case.from_summary(summary) == Case(5.0, 180.0, -90.0)  # not its folder's text
    assert case_id("5.00", "phi=180.0_theta=-90.0") == Case.from_summary(summary).id


def test_the_clinical_cases_are_parsed_once_with_their_labels() -> None:
    from fem.sweep import ClinicalCase, clinical_cases, clinical_list

    section = [{"C1": 1.0, "phi": 180.0, "label": "prone"}, {"C1": 5.0, "phi": 0.0, "theta": 45.0}]
    assert clinical_list(section) == [
        ClinicalCase(Case(1.0, 180.0, 0.0), "prone"),
        ClinicalCase(Case(5.0, 0.0, 45.0), "c1=5.00_phi=0.0_theta=45.0"),
    ]
    assert clinical_cases(section) == [Case(1.0, 180.0), Case(5.0, 0.0, 45.0)]


def test_case_id_rejects_garbage() -> None:
    with pytest.raises(InvalidParameterError, match="not a case identifier"):
        Case.from_id("c1=1_phi=0")


def test_default_config_starts_over_the_plane_and_the_caudal_half_at_every_c1() -> None:
    """The default sweep is adaptive: a start design that rounds add to (fem.adaptive)."""
    from fem.adaptive import AdaptiveDesign
    from fem.sweep import sphere_directions

    config = yaml.safe_load((REPO / "config.yaml").read_text())
    sweep = config["sweep"]
    assert "refine" not in sweep  # no hand-listed directions
    cases = sweep_cases(sweep)
    c1s = sorted({c.C1 for c in cases})
    assert c1s == sorted(sweep["C1_kPa"]) and c1s[0] == 0.8 and c1s[-1] == 5.0
    directions = {(c.phi, c.theta) for c in cases}
    assert len(cases) == len(c1s) * len(directions)  # every direction at every C1
    phis = {phi for phi, theta in directions if theta == 0.0}
    assert {0.0, 180.0} <= phis  # the clinical cases (supine, prone) are sweep cases
    n = sweep["sphere"]["n"]
    lattice = (Case(1.0, phi, theta) for phi, theta in sphere_directions(n, "caudal"))
    caudal = {(case.phi, case.theta) for case in lattice}  # as the case folders round them
    assert caudal <= directions and len(caudal) == n and len(directions) == len(phis) + n
    design = AdaptiveDesign.from_sweep(sweep)
    assert design is not None and design.start == tuple(cases)
    assert design.levels == tuple(sorted(c1s, reverse=True))
    assert design.domain.part == "caudal" and design.domain.plane == (min(phis), max(phis))
    assert len(cases) + len(c1s) <= design.settings.max_cases  # room for a round


@pytest.mark.parametrize(
    "phi, expected", [(0.0, [9.81, 0, 0]), (180.0, [-9.81, 0, 0]), (90.0, [0, 9.81, 0])]
)
def test_gravity_follows_eq1(phi: float, expected: list[float]) -> None:
    np.testing.assert_allclose(Gravity(phi).vector, expected, atol=1e-12)


def test_gravity_theta_rotates_about_x() -> None:
    g = Gravity(90.0, 90.0).vector
    np.testing.assert_allclose(g, [0, 0, 9.81], atol=1e-12)
    np.testing.assert_allclose(Gravity(math.pi, 0.0, unit="rad").vector, [-9.81, 0, 0], atol=1e-12)


@pytest.mark.parametrize("C1", [0.0, -1.0, float("nan"), float("inf")])
def test_bad_c1_is_rejected_by_name(C1: float) -> None:
    with pytest.raises(InvalidParameterError, match="C1"):
        Material(C1=C1)


def test_unknown_angle_unit_is_rejected() -> None:
    with pytest.raises(InvalidParameterError, match="angle unit 'grad'"):
        Gravity(90.0, unit="grad")


def test_unknown_loading_key_is_named() -> None:
    with pytest.raises(InvalidParameterError, match="initial_stepp"):
        Loading.from_mapping({"initial_stepp": 0.5})


def test_solver_settings_from_config() -> None:
    settings = SolverSettings.from_config(
        {
            "fe": {"discretisation": {"degree": 3}},
            "mesh": {"fixed": {"rib": "all", "cranial": ["z"]}},
        }
    )
    assert settings.discretisation.degree == 3
    assert dict((b.label, c) for b, c in settings.fixed.items()) == {
        "rib": (0, 1, 2),
        "cranial": (2,),
    }


def test_paper_angles_cluster_about_the_poles() -> None:
    from fem.sweep import sample_phi

    phis = np.array(sample_phi({"sampling": "paper"}))
    assert len(phis) == 16 and phis.min() == -150.0 and phis.max() == 180.0
    assert {0.0, 180.0} <= set(phis)
    steps = np.diff(np.sort(phis))
    mid = 0.5 * (np.sort(phis)[1:] + np.sort(phis)[:-1])
    near_pole = steps[np.minimum(np.abs(mid), 180 - np.abs(mid)) < 30]
    near_equator = steps[np.abs(np.abs(mid) - 90) < 30]
    assert near_pole.max() < near_equator.min()


def test_equal_area_angles_follow_sin_phi() -> None:
    from fem.sweep import sample_phi

    phis = np.array(sample_phi({"sampling": "equal_area", "n": 400, "min": 0.0, "max": 180.0}))
    # density proportional to sin: the fraction within 30 degrees of a pole is 1 - cos 30
    near_poles = np.mean((phis < 30) | (phis > 150))
    assert near_poles == pytest.approx(1 - np.cos(np.radians(30)), abs=0.01)
    uniform = sample_phi({"sampling": "uniform", "n": 16})
    assert np.allclose(np.diff(uniform), 22.0)


def test_sphere_directions_are_unit_and_cover_the_sphere() -> None:
    from fem.sweep import sphere_directions

    dirs = np.array([Gravity(p, t).vector for p, t in sphere_directions(500)]) / 9.81
    np.testing.assert_allclose(np.linalg.norm(dirs, axis=1), 1.0)
    assert np.linalg.norm(dirs.mean(axis=0)) < 0.01  # no side favoured
    assert dirs[:, 2].min() < -0.9 and dirs[:, 2].max() > 0.9  # theta != 0 reached


def test_the_caudal_half_covers_every_posture_short_of_head_down_evenly() -> None:
    from fem.sweep import sphere_directions

    dirs = np.array([Gravity(p, t).vector for p, t in sphere_directions(400, "caudal")]) / 9.81
    np.testing.assert_allclose(np.linalg.norm(dirs, axis=1), 1.0)
    assert dirs[:, 2].max() <= 0.0 and dirs[:, 2].min() < -0.99  # standing is reached
    # equal area: the band within 30 degrees of the paper's plane holds sin 30 of the points
    assert np.mean(dirs[:, 2] > -0.5) == pytest.approx(0.5, abs=0.01)
    # every caudal direction is near a lattice point; the rim is the paper's plane
    rng = np.random.default_rng(0)
    probe = rng.normal(size=(2000, 3))
    probe /= np.linalg.norm(probe, axis=1, keepdims=True)
    probe[:, 2] = -np.abs(probe[:, 2])
    nearest = np.degrees(np.arccos(np.clip(probe @ dirs.T, -1, 1))).min(axis=1)
    assert nearest.max() < 8.0
    with pytest.raises(InvalidParameterError, match="sweep.sphere.part must be one of"):
        sphere_directions(10, "cranial")
    cases = sweep_cases({"C1_kPa": [1.0], "sphere": {"n": 64, "part": "caudal"}})
    assert len(cases) == 64  # distinct folder names at the ids' 0.1 degree
    # with the plane's angles too: both sets of directions
    both = sweep_cases({"C1_kPa": [1.0, 2.0], "phi_deg": {"sampling": "paper"},
                        "theta_deg": [0.0], "sphere": {"n": 64, "part": "caudal"}})
    assert len(both) == 2 * (16 + 64) and set(cases) < set(both)
    assert {c.phi for c in both if c.theta == 0.0} >= set(PAPER_PHI_DEG)


def test_a_direction_named_twice_is_solved_once(caplog: pytest.LogCaptureFixture) -> None:
    """A Φ × θ grid names each pole once per θ; Φ = 360 is Φ = 0; (90, 0) is (-90, 180).

    Each direction is kept under its first name, the others dropped with a warning that names
    both: the same field is not solved twice into two folders.
    """
    with caplog.at_level("WARNING", logger="fem.sweep"):
        cases = sweep_cases({"C1_kPa": [1.0, 2.0], "phi_deg": [0.0, 90.0, 180.0, 360.0],
                             "theta_deg": [0.0, 90.0, 180.0]})
    # the poles once each, and (90, 0), (90, 90), (90, 180): 5 directions
    assert {(c.phi, c.theta) for c in cases} == {(0.0, 0.0), (90.0, 0.0), (90.0, 90.0),
                                                 (90.0, 180.0), (180.0, 0.0)}
    assert len(cases) == 2 * 5
    said = caplog.text
    assert "(360, 0) is (0, 0), already listed" in said
    assert "(180, 90) is (180, 0), already listed" in said
    caplog.clear()
    with caplog.at_level("WARNING", logger="fem.sweep"):
        assert sweep_cases({"C1_kPa": [1.0], "phi_deg": [-90.0, 90.0],
                            "theta_deg": [0.0, 180.0]}) == [Case(1.0, -90.0, 0.0),
                                                           Case(1.0, -90.0, 180.0)]
    assert "(90, 0) is (-90, 180)" in caplog.text
    caplog.clear()
    with caplog.at_level("WARNING", logger="fem.sweep"):
        sweep_cases({"C1_kPa": [1.0], "phi_deg": [0.0, 0.0, 90.0]})  # the same name twice
    assert not caplog.text


def test_random_cases_are_seeded_within_the_range_and_uniform_in_compliance() -> None:
    from fem.sweep import random_cases

    cases = random_cases(4000, 3, (0.8, 5.0), "caudal")
    assert cases == random_cases(4000, 3, (0.8, 5.0), "caudal")
    assert cases[:10] != random_cases(10, 4, (0.8, 5.0), "caudal")
    assert all(Case.from_id(c.id) == c for c in cases[:50])  # the case solved is the one drawn
    c1 = np.array([c.C1 for c in cases])
    assert c1.min() >= 0.8 and c1.max() <= 5.0
    # uniform in 1/C1 from 0.2 to 1.25: its mean is the midpoint, and C1 <= 1.25 kPa
    # (compliance >= 0.8) holds 0.45 / 1.05 of the draws
    assert np.mean(1.0 / c1) == pytest.approx(0.725, abs=0.01)
    assert np.mean(c1 <= 1.25) == pytest.approx(0.45 / 1.05, abs=0.02)
    dirs = np.array([Gravity(c.phi, c.theta).vector for c in cases]) / 9.81
    np.testing.assert_allclose(np.linalg.norm(dirs, axis=1), 1.0, atol=2e-3)  # 0.1 deg rounding
    assert dirs[:, 2].max() <= 2e-3 and dirs[:, 2].min() < -0.99
    assert np.mean(dirs[:, 2] > -0.5) == pytest.approx(0.5, abs=0.02)  # equal area, as above
    assert np.abs(dirs[:, :2].mean(axis=0)).max() < 0.03  # no side of the plane favoured
    whole = np.array([Gravity(c.phi, c.theta).vector
                      for c in random_cases(4000, 3, (1.0, 2.0), "whole")]) / 9.81
    assert np.abs(whole.mean(axis=0)).max() < 0.03 and whole[:, 2].max() > 0.99
    assert random_cases(0, 1, (1.0, 2.0)) == []
    assert {c.C1 for c in random_cases(5, 1, (1.0, 1.0))} == {1.0}  # a sweep of one C1
    with pytest.raises(InvalidParameterError, match="C1 range 0 < low <= high"):
        random_cases(3, 1, (2.0, 1.0))
    with pytest.raises(InvalidParameterError, match="part must be one of"):
        random_cases(3, 1, (1.0, 2.0), "cranial")


def test_the_paper_preset_replaces_every_key_that_chooses_cases() -> None:
    from fem.sweep import resolve_sweep

    paper = sweep_cases({"preset": "paper"})
    assert len(paper) == 688 and {c.theta for c in paper} == {0.0}
    merged = {"C1_kPa": [1.0], "sphere": {"n": 64, "part": "caudal"}, "chains": False,
              "adaptive": {"target_mm": 0.5}, "preset": "paper"}  # as `--config sweep={preset:
    # paper}` merges into a file's: the paper's fixed grid, no rounds added to it
    assert sweep_cases(merged) == paper
    resolved = resolve_sweep(merged)
    assert resolved["chains"] is False and "sphere" not in resolved and "adaptive" not in resolved
    with pytest.raises(InvalidParameterError, match="sweep.preset must be one of"):
        sweep_cases({"preset": "mammogram"})


def test_sphere_sweep_replaces_the_angle_grid() -> None:
    cases = sweep_cases({"C1_kPa": [1.0, 2.0], "sphere": {"n": 10}})
    assert len(cases) == 20 and len({c.theta for c in cases}) > 5
