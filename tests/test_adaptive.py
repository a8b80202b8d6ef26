"""The adaptive sweep's planner (fem.adaptive) on synthetic fields: no FE, no workflow."""

from __future__ import annotations

import json
from itertools import combinations
from pathlib import Path

import numpy as np
import pytest
from scipy.interpolate import RBFInterpolator

from fem.adaptive import (
    SEPARATION_DEG,
    AdaptiveDesign,
    AdaptiveSettings,
    Domain,
    LoadSpaceInterpolant,
    RoundPlan,
    load_points,
    plan_round,
    read_cases,
)
from fem.case_files import read_points
from fem.directions import gravity_direction
from fem.exceptions import DatasetError, InvalidParameterError
from fem.sweep import Case, sweep_cases
from tests.test_dataset import _write_case

pytestmark = pytest.mark.unit

SMALL = {"C1_kPa": [1.0, 2.0, 5.0], "phi_deg": [0.0, 60.0, 120.0, 180.0],
         "sphere": {"n": 8, "part": "caudal"}}
"""A small sweep of 36 cases: the plane and the caudal half, three C1 values."""

# The planner's design: the plane every 45 degrees and 10 caudal directions at 5 C1 values
# (90 cases), a fine candidate lattice (spacing about 4.5 degrees, under SEPARATION_DEG)
DESIGN = {"C1_kPa": [5.0, 2.0, 1.2, 1.0, 0.8],
          "phi_deg": [-135.0, -90.0, -45.0, 0.0, 45.0, 90.0, 135.0, 180.0],
          "sphere": {"n": 10, "part": "caudal"},
          "adaptive": {"target_mm": 0.5, "max_cases": 600, "per_round": 12, "candidates": 1000}}
BUMP = (101.4, -41.5)
"""The caudal start direction the bump sits on, at the softest C1."""


def points_of(cases: list[Case] | tuple[Case, ...]) -> np.ndarray:
    return load_points(np.array([c.C1 for c in cases]), np.array([c.phi for c in cases]),
                       np.array([c.theta for c in cases]))


def unit(pairs: list[tuple[float, float]]) -> np.ndarray:
    return gravity_direction(np.array([p for p, _ in pairs], dtype=float),
                             np.array([t for _, t in pairs], dtype=float))


def degrees_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angles (degrees) between the unit directions of ``a`` (P, 3) and ``b`` (Q, 3): (P, Q)."""
    return np.degrees(np.arccos(np.clip(a @ b.T, -1.0, 1.0)))


def nonlinear(x: np.ndarray) -> np.ndarray:
    """A smooth field of 4 material points that is far from linear in x: (M, 4, 3), mm."""
    return np.stack([np.stack([np.sin(2.0 * x[:, 0] + k) + x[:, 1] ** 2,
                               np.exp(0.5 * x[:, 2]) * x[:, 0] * (k + 1),
                               np.cos(x[:, 0] * x[:, 1] - k)], axis=1) for k in range(4)], axis=1)


def linear(x: np.ndarray) -> np.ndarray:
    """A field of 3 material points linear in x (the small-deformation limit): (M, 3, 3), mm."""
    a = np.arange(9.0).reshape(3, 3) + 1.0
    return np.stack([x @ a + k for k in range(3)], axis=1)


def bumped(x: np.ndarray, width: float = 0.25, height_mm: float = 5.0) -> np.ndarray:
    """:func:`linear`, plus a sharp bump at direction :data:`BUMP` at 0.8 kPa."""
    centre = unit([BUMP])[0] / 0.8
    bump = height_mm * np.exp(-np.sum((x - centre) ** 2, axis=1) / width**2)
    return linear(x) + bump[:, None, None] * np.array([0.0, 0.6, 0.8])


@pytest.fixture(scope="module")
def design() -> AdaptiveDesign:
    design = AdaptiveDesign.from_sweep(DESIGN)
    assert design is not None and len(design.start) == 5 * 18
    assert BUMP in {(c.phi, c.theta) for c in design.start}
    return design


def start_directions(design: AdaptiveDesign) -> list[tuple[float, float]]:
    return sorted({(c.phi, c.theta) for c in design.start})


# -- the estimate ----------------------------------------------------------------------------


def test_rippas_leave_one_out_is_the_refit_without_each_case() -> None:
    """e_k = c_k / (A⁻¹)ₖₖ equals refitting the interpolant without case k and predicting at x_k.

    The refit is scipy's cubic RBF with a linear tail, an independent implementation of the
    same interpolant.
    """
    x = points_of(sweep_cases(SMALL))
    fields = nonlinear(x)
    interpolant = LoadSpaceInterpolant(x, fields)
    brute = np.empty(len(x))
    for k in range(len(x)):
        others = np.arange(len(x)) != k
        refit = RBFInterpolator(x[others], fields[others].reshape(others.sum(), -1),
                                kernel="cubic", degree=1)
        miss = refit(x[k:k + 1]).reshape(-1, 3) - fields[k]
        brute[k] = np.linalg.norm(miss, axis=1).max()
    assert len(x) == 36 and brute.min() > 1e-4  # a field the interpolant does not reproduce
    np.testing.assert_allclose(interpolant.loo_mm, brute, rtol=1e-6)
    # and the interpolant itself: it passes through every case, as scipy's does between them
    np.testing.assert_allclose(interpolant.predict(x), fields, atol=1e-9)
    between = 0.5 * (x[:-1] + x[1:])
    whole = RBFInterpolator(x, fields.reshape(len(x), -1), kernel="cubic", degree=1)
    np.testing.assert_allclose(interpolant.predict(between).reshape(len(between), -1),
                               whole(between), atol=1e-8)


def test_the_jackknife_at_a_case_is_its_leave_one_out_error() -> None:
    x = points_of(sweep_cases(SMALL))
    interpolant = LoadSpaceInterpolant(x, nonlinear(x))
    np.testing.assert_allclose(interpolant.cardinal(x), np.eye(len(x)), atol=1e-9)
    np.testing.assert_allclose(interpolant.jackknife(x), interpolant.loo_mm, rtol=1e-9)
    # between the cases it is the largest of the neighbours' errors, each weighted by |L_k|
    y = 0.5 * (x[0] + x[1])
    expected = np.max(np.abs(interpolant.cardinal(y)) * interpolant.loo_mm)
    assert interpolant.jackknife(y)[0] == pytest.approx(expected)
    assert interpolant.jackknife(y)[0] != pytest.approx(interpolant.loo_mm.max())


def test_a_field_linear_in_the_load_is_reproduced_exactly() -> None:
    x = points_of(sweep_cases(SMALL))
    interpolant = LoadSpaceInterpolant(x, linear(x))
    scale = np.abs(linear(x)).max()
    assert interpolant.loo_mm.max() < 1e-9 * scale
    y = np.random.default_rng(1).uniform(-1.0, 1.0, size=(50, 3))
    np.testing.assert_allclose(interpolant.predict(y), linear(y), atol=1e-9 * scale)
    assert interpolant.jackknife(y).max() < 1e-9 * scale


def test_a_design_in_the_plane_alone_has_a_tail_in_the_plane() -> None:
    """The paper's plane: every load point has z = 0, and a tail in z would be singular."""
    plane = {"C1_kPa": [1.0, 2.0, 5.0], "phi_deg": [0.0, 45.0, 90.0, 135.0, 180.0]}
    x = points_of(sweep_cases(plane))
    assert np.all(x[:, 2] == 0.0)
    fields = 3.0 * nonlinear(x)
    interpolant = LoadSpaceInterpolant(x, fields)
    others = np.arange(len(x)) != 3
    refit = RBFInterpolator(x[others][:, :2], fields[others].reshape(others.sum(), -1),
                            kernel="cubic", degree=1)
    miss = refit(x[3:4, :2]).reshape(-1, 3) - fields[3]
    assert interpolant.loo_mm[3] == pytest.approx(np.linalg.norm(miss, axis=1).max(), rel=1e-6)
    design = AdaptiveDesign.from_sweep({**plane, "adaptive": {"candidates": 50}})
    assert design is not None and design.domain == Domain((0.0, 180.0), None)
    plan = design.plan(list(design.start), np.ones(len(x), bool), fields, 1)
    assert plan.directions and all(theta == 0.0 for _, theta in plan.directions)


# -- a round -----------------------------------------------------------------------------------


def test_a_round_adds_directions_where_the_field_has_a_bump(design: AdaptiveDesign) -> None:
    start = list(design.start)
    plan = design.plan(start, np.ones(len(start), bool), bumped(points_of(start)), 1)
    assert not plan.done and plan.reason == "adding" and 1 <= len(plan.directions) <= 12
    assert plan.estimate_mm > design.settings.target_mm
    assert plan.worst[0] == 0.8  # the soft end, where the bump is
    bump = unit([BUMP])
    added = degrees_between(unit(plan.directions), bump)[:, 0]
    tried = degrees_between(unit(start_directions(design)), bump)[:, 0]
    assert added.mean() < 0.5 * tried.mean()
    assert np.sort(added)[:3].max() < 20.0  # the first around the bump, not merely nearer
    # every added direction at every C1 value, as one chain each
    assert plan.new_cases() == sorted(Case(c1, *d) for c1 in design.levels
                                      for d in plan.directions)
    assert not set(plan.new_cases()) & set(start)


def test_a_round_keeps_its_directions_apart(design: AdaptiveDesign,
                                            monkeypatch: pytest.MonkeyPatch) -> None:
    """None within SEPARATION_DEG of a direction tried or of another added.

    Without the rule (SEPARATION_DEG = 0) and without counting a chosen direction as solved
    before the next is chosen (NEIGHBOURHOOD_DEG = 0) this design's round does crowd: the check
    can fail.
    """
    start = list(design.start)
    fields = bumped(points_of(start))
    tried = unit(start_directions(design))

    def closest(plan: RoundPlan) -> tuple[float, float]:
        added = unit(plan.directions)
        pairs = [degrees_between(added[i:i + 1], added[j:j + 1])[0, 0]
                 for i, j in combinations(range(len(added)), 2)]
        return degrees_between(added, tried).min(), min(pairs)

    to_tried, to_added = closest(design.plan(start, np.ones(len(start), bool), fields, 1))
    # the case folders' 0.1 degree rounding moves a direction by less than 0.1 degree
    assert to_tried >= SEPARATION_DEG - 0.1 and to_added >= SEPARATION_DEG - 0.1
    monkeypatch.setattr("fem.adaptive.SEPARATION_DEG", 0.0)
    monkeypatch.setattr("fem.adaptive.NEIGHBOURHOOD_DEG", 0.0)
    crowded = closest(design.plan(start, np.ones(len(start), bool), fields, 1))
    assert min(crowded) < SEPARATION_DEG - 0.1


def test_a_round_adds_no_reserved_direction(design: AdaptiveDesign) -> None:
    """The extrapolation study's directions stay unseen.

    With the direction the round adds nearest the bump reserved, the same round adds nothing
    within SEPARATION_DEG of it.
    """
    start = list(design.start)
    fields = bumped(points_of(start))
    free = design.plan(start, np.ones(len(start), bool), fields, 1)
    first = free.directions[int(np.argmin(degrees_between(unit(free.directions),
                                                          unit([BUMP]))[:, 0]))]
    kept = design.plan(start, np.ones(len(start), bool), fields, 1, reserved=[first])
    assert kept.directions and first not in kept.directions
    assert degrees_between(unit(kept.directions), unit([first])).min() >= SEPARATION_DEG - 0.1


def test_a_linear_field_meets_the_target_at_once(design: AdaptiveDesign) -> None:
    start = list(design.start)
    plan = design.plan(start, np.ones(len(start), bool), linear(points_of(start)), 1)
    assert plan.done and plan.reason == "target met" and plan.cases == [] == plan.directions
    assert plan.estimate_mm < 1e-6 and plan.max_loo_mm < 1e-6
    assert (plan.cases_before, plan.converged_before) == (90, 90)


def test_the_budget_and_the_rounds_end_the_sweep(design: AdaptiveDesign) -> None:
    start = list(design.start)
    converged, fields = np.ones(len(start), bool), bumped(points_of(start))
    levels = len(design.levels)

    def plan(round_number: int = 1, **settings: int) -> RoundPlan:
        return plan_round(AdaptiveSettings(**{**DESIGN["adaptive"], **settings}), design.levels,
                          design.domain, start, converged, fields, round_number)

    spent = plan(max_cases=len(start) + levels - 1)  # no room for one direction's C1 values
    assert spent.done and spent.reason == "budget spent" and spent.cases == []
    assert spent.estimate_mm > 0.5  # not for want of error
    two = plan(max_cases=len(start) + 2 * levels + levels - 1)
    assert not two.done and len(two.directions) == 2 and len(two.cases) == 2 * levels
    assert plan(max_rounds=1).reason == "adding"
    last = plan(2, max_rounds=1)
    assert last.done and last.reason == "rounds spent" and last.cases == []


def test_a_level_whose_nearest_case_failed_is_not_scored(design: AdaptiveDesign) -> None:
    """The FE has no solution there to add: the round looks elsewhere."""
    start = list(design.start)
    x = points_of(start)
    fields = bumped(x)

    def nearest_tried_converged(plan: RoundPlan, converged: np.ndarray) -> bool:
        worst = points_of([Case(*plan.worst)])
        return bool(converged[np.argmin(np.linalg.norm(x - worst, axis=1))])

    # the bump's own softest case failed (its 1.0 kPa case still sees the bump): with it
    # scored, the worst candidate would lie beside that failed case
    failed = np.array([(c.phi, c.theta) == BUMP and c.C1 == 0.8 for c in start])
    plan = design.plan(start, ~failed, fields, 1)
    assert plan.directions and nearest_tried_converged(plan, ~failed)
    everything = design.plan(start, np.ones(len(start), bool), fields, 1)
    assert not nearest_tried_converged(everything, ~failed)

    # every case of the two start directions nearest the bump failed: no direction added there,
    # where the round adds some when they converged
    tried = start_directions(design)
    by_distance = np.argsort(degrees_between(unit(tried), unit([BUMP]))[:, 0])
    beside = [tried[i] for i in by_distance[1:3]]
    failed = np.array([(c.phi, c.theta) in beside for c in start])

    def added_beside(plan: RoundPlan) -> int:
        nearest = np.argmin(degrees_between(unit(plan.directions), unit(tried)), axis=1)
        return sum(tried[i] in beside for i in nearest)

    assert added_beside(everything) > 0
    plan = design.plan(start, ~failed, fields, 1)
    assert plan.directions and added_beside(plan) == 0
    assert (plan.cases_before, plan.converged_before) == (90, 90 - 2 * 5)


# -- the plan's file, the design from the config --------------------------------------------


def test_a_round_plan_reads_back_as_written(tmp_path: Path, design: AdaptiveDesign) -> None:
    start = list(design.start)
    plan = design.plan(start, np.ones(len(start), bool), bumped(points_of(start)), 1)
    path = tmp_path / "sweep" / "round_1.json"
    plan.write(path)
    assert RoundPlan.read(path) == plan
    assert [p.name for p in path.parent.iterdir()] == ["round_1.json"]  # no .part left
    assert json.loads(path.read_text())["reason"] == "adding"
    done = RoundPlan(2, 90 + len(plan.cases), 90 + len(plan.cases), 0.1, (0.8, 10.0, -5.0),
                     0.01, 0.2, done=True, reason="target met")
    done.write(tmp_path / "round_2.json")
    again = RoundPlan.read(tmp_path / "round_2.json")
    assert again == done and again.new_cases() == []


def test_the_design_comes_from_the_sweep_section() -> None:
    fixed = {key: value for key, value in DESIGN.items() if key != "adaptive"}
    assert AdaptiveDesign.from_sweep(fixed) is None
    assert AdaptiveDesign.from_sweep({**fixed, "adaptive": None}) is None
    design = AdaptiveDesign.from_sweep({**fixed, "adaptive": {}})  # every default
    assert design is not None and design.settings == AdaptiveSettings()
    assert design.start == tuple(sweep_cases(fixed))
    assert design.levels == (5.0, 2.0, 1.2, 1.0, 0.8)
    assert design.domain == Domain((-135.0, 180.0), "caudal")
    with pytest.raises(InvalidParameterError, match=r"sweep\.adaptive\.max_cases = 89 is fewer "
                       r"than the start design's 90 cases"):
        AdaptiveDesign.from_sweep({**fixed, "adaptive": {"max_cases": 89}})
    with pytest.raises(InvalidParameterError, match=r"sweep\.adaptive\.target_mm"):
        AdaptiveDesign.from_sweep({**fixed, "adaptive": {"target_mm": 0.0}})
    # the paper's preset is the paper's fixed grid: it drops `adaptive` with the other case keys
    paper = {"preset": "paper", "adaptive": {"target_mm": 0.5, "max_cases": 600}}
    assert AdaptiveDesign.from_sweep(paper) is None
    assert len(sweep_cases(paper)) == 688


# -- the cases a round reads -----------------------------------------------------------------


def test_read_cases_gives_each_case_whether_it_converged_and_its_field_in_mm(
    tmp_path: Path,
) -> None:
    """A case that passes through itself is not converged, as the dataset's splits have it."""
    good = _write_case(tmp_path, 1.0, 0.0)
    through = _write_case(tmp_path, 2.0, 90.0, self_overlap={"overlapping_vertices": 3})
    cases, converged, fields = read_cases([good[0], through[0]], [good[1], through[1]])
    assert cases == [Case(1.0, 0.0), Case(2.0, 90.0)]
    assert converged.tolist() == [True, False]
    np.testing.assert_allclose(fields[0], 1e3 * read_points(good[1])["u"])
    assert np.abs(fields[0]).max() > 0.1  # mm: u is of order 1e-3 m
    assert fields.shape == (2, 50, 3)
    failed = _write_case(tmp_path, 3.0, 45.0, status="failed")
    assert read_cases([good[0], failed[0]], [good[1], failed[1]])[1].tolist() == [True, False]
    other_mesh = _write_case(tmp_path, 5.0, 45.0, n=40)
    with pytest.raises(DatasetError, match="40 material points, expected 50"):
        read_cases([good[0], other_mesh[0]], [good[1], other_mesh[1]])

