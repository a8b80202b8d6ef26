"""The report's section on how the adaptive sweep chose its cases, from its typed results.

The rounds (:class:`studies.sweep.sweep_rounds.SweepRounds`, built from the plans the rounds write)
and the check of the estimate (:class:`studies.sweep.sweep_estimate.SweepEstimateCheck`) are written
to a folder through their classes and read back as the report reads them.
"""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import numpy as np
import pytest

from fem.adaptive import AdaptiveSettings, RoundPlan
from fem.dataset import Dataset
from fem.directions import gravity_direction
from fem.sweep import Case
from report.context import Context
from report.sections.sweep_design import sweep_design_section
from studies.sweep.sweep_estimate import EstimateScore, SweepEstimateCheck
from studies.sweep.sweep_rounds import START_ROUND, SweepRound, SweepRounds

pytestmark = pytest.mark.unit

LEVELS = (3.0, 1.0)
START = ((0.0, 0.0), (90.0, 0.0), (180.0, 0.0), (90.0, -90.0))
ROUND_1 = ((45.0, -30.0), (135.0, -60.0))
ROUND_2 = ((60.0, -75.0),)


def _plans(tmp_path: Path) -> list[RoundPlan]:
    """Three rounds as the workflow writes them: two add directions, the third ends."""
    def cases(directions: tuple[tuple[float, float], ...]) -> list[str]:
        return sorted(Case(c1, *d).id for c1 in LEVELS for d in directions)

    plans = [
        RoundPlan(1, 8, 7, 2.4, (1.0, 45.0, -30.0), 0.30, 1.9, list(ROUND_1), cases(ROUND_1)),
        RoundPlan(2, 12, 11, 0.9, (1.0, 60.0, -75.0), 0.20, 0.8, list(ROUND_2), cases(ROUND_2)),
        RoundPlan(3, 14, 13, 0.41, (3.0, 0.0, 0.0), 0.10, 0.35, done=True, reason="target met"),
    ]
    for plan in plans:
        plan.write(tmp_path / "sweep" / f"round_{plan.round}.json")
    return [RoundPlan.read(tmp_path / "sweep" / f"round_{k}.json") for k in (3, 1, 2)]


def _dataset(failed_direction: tuple[float, float]) -> Dataset:
    """Every direction of the sweep at every C1; one direction's cases all failed.

    One case of another direction failed alone.
    """
    directions = [*START, *ROUND_1, *ROUND_2]
    phi = np.array([d[0] for d in directions for _ in LEVELS])
    theta = np.array([d[1] for d in directions for _ in LEVELS])
    C1 = np.array([c1 for _ in directions for c1 in LEVELS])
    g = gravity_direction(phi, theta)
    converged = ~((phi == failed_direction[0]) & (theta == failed_direction[1]))
    converged[0] = False  # (0, 0) at the stiff C1 only: that direction did not fail whole
    u = np.where(converged[:, None, None], g[:, None, :] / C1[:, None, None], np.nan)
    return Dataset(X=np.zeros((1, 3)), boundary=np.zeros(1, bool), C1=C1, phi=phi, theta=theta,
                   direction=g, displacement=u, converged=converged,
                   splits={}, ids=np.array([Case(*p).id for p in zip(C1, phi, theta,
                                                                     strict=True)]))


def _check(rho: float) -> SweepEstimateCheck:
    scores = [EstimateScore(s, e, n, r, w) for s, n in (("all", 30), ("off_grid", 24),
                                                          ("by_direction", 6))
              for e, r, w in (("committee", 0.9, 1.0), ("jackknife", rho, 0.5),
                              ("nearest", 0.6, 0.25))]
    return SweepEstimateCheck("jackknife", 0.7, [], scores)


def _context(tmp_path: Path, rounds: SweepRounds | None, check: SweepEstimateCheck | None,
             with_rounds: bool = True, with_estimate: bool = True) -> Context:
    """The report's context of these files, written and read back through their types."""
    inputs = {}
    if with_rounds:
        inputs["sweep_rounds"] = [str(tmp_path / "sweep" / "rounds.json")]
        if rounds is not None:
            rounds.write(tmp_path / "sweep" / "rounds.json")
    if with_estimate:
        inputs["sweep_estimate"] = str(tmp_path / "sweep" / "estimate.json")
        if check is not None:
            check.write(tmp_path / "sweep" / "estimate.json")
    (tmp_path / "report").mkdir(exist_ok=True)
    return Context.load(inputs, tmp_path / "report", [])


def _rows(html: str, table_id: str) -> list[list[str]]:
    body = re.search(rf'<table id="{table_id}">.*?<tbody>(.*?)</tbody>', html, re.S)
    assert body, f"no table {table_id}"
    return [re.findall(r"<td>(.*?)</td>", row) for row in re.findall(r"<tr[^>]*>(.*?)</tr>",
                                                                     body[1])]


def test_the_rounds_record_holds_every_plan_in_order(tmp_path: Path) -> None:
    """Built from the plan files in any order; their fields, the settings, the summary."""
    assert [f.name for f in dataclasses.fields(SweepRound)] == [
        f.name for f in dataclasses.fields(RoundPlan)]
    record = SweepRounds.of(_plans(tmp_path), AdaptiveSettings(target_mm=0.5, max_cases=40))
    record.write(tmp_path / "rounds.json")
    back = SweepRounds.read(tmp_path / "rounds.json")
    assert back == record
    assert [r.round for r in back.rounds] == [1, 2, 3]
    assert back.rounds[0].directions == list(ROUND_1) and back.rounds[0].worst == (1.0, 45.0,
                                                                                   -30.0)
    assert (back.target_mm, back.max_cases) == (0.5, 40)
    assert back.cases == 14 and back.added_directions == 3
    assert back.estimate_mm == 0.41 and back.done and back.reason == "target met"


def test_each_direction_is_given_the_round_that_added_it(tmp_path: Path) -> None:
    record = SweepRounds.of(_plans(tmp_path), AdaptiveSettings())
    phi = [0.0, 45.0, 135.0, 60.0, 90.0, -90.0]
    theta = [0.0, -30.0, -60.0, -75.0, -90.0, 90.0]  # (-90, 90) is (90, -90) named otherwise
    assert list(record.rounds_of(phi, theta)) == [START_ROUND, 1, 1, 2, START_ROUND,
                                                  START_ROUND]


def test_the_section_tables_every_round_and_draws_the_design(tmp_path: Path) -> None:
    record = SweepRounds.of(_plans(tmp_path), AdaptiveSettings(target_mm=0.5, max_cases=40))
    ctx = _context(tmp_path, record, None, with_estimate=False)
    ctx._dataset = _dataset(failed_direction=ROUND_1[1])
    html = sweep_design_section(ctx)
    assert "start" in html and "until" in html and "case budget" in html  # the caption
    assert _rows(html, "sweep-rounds") == [
        ["1", "8", "7", "2.4", "1 kPa, 45/-30°", "0.3 / 1.9", "2", "4", "adding"],
        ["2", "12", "11", "0.9", "1 kPa, 60/-75°", "0.2 / 0.8", "1", "2", "adding"],
        ["3", "14", "13", "0.41", "3 kPa, 0/0°", "0.1 / 0.35", "0", "0", "target met"],
    ]
    assert "14 cases in all (budget 40)" in html and "3 directions added" in html
    assert "target of 0.5 mm; the sweep has ended: target met." in html
    # only the direction whose every case failed is hollow; (0, 0) lost one case of two
    assert "hollow: the 1 direction whose every case failed." in html
    assert 'src="sweep_design.png"' in html
    assert (tmp_path / "report" / "sweep_design.png").stat().st_size > 5000
    assert "estimate-check" not in html and "Does the estimate" not in html  # not an input


def test_the_estimate_check_puts_the_chosen_first_and_judges_it_by_the_file(
        tmp_path: Path) -> None:
    """A rank correlation of 0.5 does not meet the goal of 0.7; 0.8 does."""
    record = SweepRounds.of(_plans(tmp_path), AdaptiveSettings())
    html = sweep_design_section(_context(tmp_path, record, _check(0.5)))
    assert "results/dataset/dataset.h5 was not found" in html  # the figure, without a dataset
    rows = _rows(html, "sweep-estimate")
    assert [r[:2] for r in rows[:3]] == [["all", "jackknife (chosen)"], ["all", "committee"],
                                         ["all", "nearest"]]
    assert [r[0] for r in rows] == ["all"] * 3 + ["off_grid"] * 3 + ["by_direction"] * 3
    assert rows[0][2:] == ["30", "0.500", "50%"] and rows[4][2:] == ["24", "0.900", "100%"]
    marked = re.findall(r'<tr class="highlight"><td>[^<]*</td><td>([^<]*)</td>', html)
    assert marked == ["jackknife (chosen)"] * 3
    assert "rank correlation of 0.500: it does not meet the goal of 0.7." in html
    html = sweep_design_section(_context(tmp_path, record, _check(0.8)))
    assert "rank correlation of 0.800: it meets the goal of 0.7." in html


def test_a_fixed_design_says_so_in_one_line_and_still_shows_the_check(tmp_path: Path) -> None:
    html = sweep_design_section(_context(tmp_path, None, _check(0.75), with_rounds=False))
    assert html.count("<p") == 3  # the line, the check's caption and its verdict
    assert "The sweep is a fixed design (sweep.adaptive absent or null)" in html
    assert "sweep-rounds" not in html and "it meets the goal of 0.7" in html
    # the first report: no estimate among its inputs, the one line alone
    html = sweep_design_section(_context(tmp_path, None, None, with_rounds=False,
                                         with_estimate=False))
    assert html.count("<p") == 1 and "fixed design" in html


def test_missing_files_are_noted(tmp_path: Path) -> None:
    html = sweep_design_section(_context(tmp_path, None, None))
    assert "Not available: results/sweep/rounds.json" in html
    assert "Not available: results/sweep/estimate.json" in html


def test_the_section_stands_before_the_sweeps_cost_in_both_reports(tmp_path: Path) -> None:
    from report.build import FIRST_SECTIONS, SECTIONS, build_report

    ids = [s[0] for s in SECTIONS]
    assert ids.index("sweep-design") + 1 == ids.index("sweep-cost")
    assert "sweep-design" in FIRST_SECTIONS
    record = SweepRounds.of(_plans(tmp_path), AdaptiveSettings())
    record.write(tmp_path / "rounds.json")
    page = build_report({"sweep_rounds": [tmp_path / "rounds.json"]},
                        tmp_path / "first" / "index.html", [], first=True).read_text()
    found = re.findall(r'<section id="([^"]+)"><h2>([^<]+)</h2>', page)
    assert ("sweep-design", "How the sweep chose its cases") in found
    assert [s for s, _ in found].index("sweep-design") + 1 == [s for s, _ in found].index(
        "sweep-cost")
    assert '<table id="sweep-rounds">' in page and "could not be built" not in page
