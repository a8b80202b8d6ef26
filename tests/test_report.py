"""Typed result files and the report that reads them.

The report reads every result through its type (:mod:`studies.results`): a key that is
missing, renamed or of the wrong type is an error naming it, not "n/a" on the page.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest

from studies.fe_study.fe_clinical import FEClinical
from studies.fe_study.fe_speed_accuracy import SpeedAccuracy
from studies.results import Record, Result, ResultFormatError
from studies.surrogate_study.surrogate_benchmark import Goal
from studies.timing_hygiene import MachineState, machine_state

pytestmark = pytest.mark.unit


@dataclass(frozen=True, slots=True)
class _Row(Record):
    case: str
    wall_s: float
    steps: list[int]
    note: str | None = None


@dataclass(frozen=True, slots=True)
class _File(Result):
    rows: list[_Row]
    by_id: dict[str, _Row]
    machine: MachineState
    settings: dict[str, Any]
    best: _Row | None = None


@dataclass(frozen=True, slots=True)
class _Open(Result):
    cells: int
    extras: dict[str, Any] = field(default_factory=dict)


def _example() -> _File:
    row = _Row("c1=1.00_phi=180.0_theta=0.0", 0.5, [4, 3])
    return _File(rows=[row, _Row("b", 1.5, [], note="slow")], by_id={"a": row},
                 machine=machine_state(pinned_core=0), settings={"solver": "direct"})


def test_a_result_round_trips_through_its_file(tmp_path: Path) -> None:
    result = _example()
    result.write(tmp_path / "r.json")
    assert _File.read(tmp_path / "r.json") == result
    written = json.loads((tmp_path / "r.json").read_text())
    # optional fields that are None are left out, as the writers leave out such keys
    assert "note" not in written["rows"][0] and "best" not in written
    assert written["rows"][1]["note"] == "slow"
    assert not list(tmp_path.glob(".*.tmp"))  # written through a temporary file


@pytest.mark.parametrize(
    "edit, message",
    [
        (lambda d: d["rows"][1].pop("wall_s"), "rows[1]: missing key 'wall_s'"),
        (lambda d: d["rows"][0].update(wall_seconds=d["rows"][0].pop("wall_s")),
         "rows[0]: missing key 'wall_s'; unknown key(s) wall_seconds"),
        (lambda d: d["by_id"]["a"].update(steps=["four"]), "by_id.a.steps[0]: expected an integer"),
        (lambda d: d["machine"].update(cores="two"), "machine.cores"),
        (lambda d: d.update(rows={}), "rows: expected a list"),
        (lambda d: d["rows"][0].update(wall_s=True), "rows[0].wall_s: expected a number"),
    ],
)
def test_a_missing_renamed_or_mistyped_key_is_named(
    tmp_path: Path, edit: Any, message: str
) -> None:
    data = _example().to_json()
    edit(data)
    (tmp_path / "r.json").write_text(json.dumps(data))
    with pytest.raises(ResultFormatError, match=re.escape(message)):
        _File.read(tmp_path / "r.json")


def test_an_open_record_keeps_the_keys_it_does_not_declare() -> None:
    data = {"cells": 10, "cad": {"volume_m3": 1e-3}, "source": "parametric"}
    quality = _Open.from_json(data)
    assert quality.cells == 10 and quality.extras == {"cad": {"volume_m3": 1e-3},
                                                      "source": "parametric"}
    assert quality.to_json() == data
    with pytest.raises(ResultFormatError, match="missing key 'cells'"):
        _Open.from_json({"cad": {}})


def test_numbers_from_numpy_become_plain_numbers() -> None:
    import numpy as np

    goal = Goal.from_json({"value": np.float64(0.25), "goal": np.int64(1), "met": np.bool_(True)})
    assert goal == Goal(0.25, 1.0, True) and type(goal.met) is bool
    assert json.dumps(goal.to_json())


def _clinical_benchmark() -> dict[str, Any]:
    row = {
        "case": "c1=1.00_phi=180.0_theta=0.0", "converged": True, "reason": "converged",
        "load_fraction": 1.0, "wall_s": 0.5, "cpu_s": 0.5, "assembly_s": 0.3,
        "linear_solve_s": 0.2, "linear_system_s": 0.1, "factorization_equivalents": 5.0,
        "load_steps": 1, "rejected_steps": 0, "newton_iterations": [4],
        "total_newton_iterations": 4, "linear_iterations": 28, "jacobian_evaluations": 4,
        "preconditioner_builds": 1, "residual_evaluations": 5, "first_failure": "",
        "accuracy": {"max_error_mm": 0.5, "rms_error_mm": 0.1, "mean_error_mm": 0.08,
                     "max_disp_mm": 30.0, "relative_max_error": 0.017, "max_outside_m": 0.0},
    }
    target = {"target": 8.0, "value": 0.5, "met": True}
    return {
        "mesh": "results/mesh/mesh.xdmf", "dofs": 7765, "material_points": 406, "setup_s": 0.1,
        "settings": {}, "baseline_steps": 3, "repeats": 1, "cases": [row],
        "summary": {"median_wall_s": 0.5, "median_cpu_s": 0.5, "max_factorization_equivalents": 5.0,
                    "median_baseline_over_adaptive_wall": 2.0, "max_relative_error": 0.017,
                    "all_converged": True, "targets": {"median_wall_s": target}},
        "machine": {"pinned_core": 0}, "reference": {},
    }


def test_the_fe_clinical_benchmark_names_a_renamed_accuracy_key(tmp_path: Path) -> None:
    data = _clinical_benchmark()
    bench = FEClinical.from_json(data)
    assert bench.cases[0].accuracy.relative_max_error == 0.017
    assert FEClinical.from_json(bench.to_json()) == bench
    accuracy = data["cases"][0]["accuracy"]
    accuracy["relative_error"] = accuracy.pop("relative_max_error")
    (tmp_path / "clinical.json").write_text(json.dumps(data))
    with pytest.raises(ResultFormatError, match=r"clinical.json.cases\[0\].accuracy"):
        FEClinical.read(tmp_path / "clinical.json")


def test_the_report_refuses_a_result_whose_key_was_renamed(tmp_path: Path) -> None:
    """A renamed key stops the report with the key's name; it does not print n/a."""
    from report.build import build_report

    data = {"target_relative_max_error": 0.01, "cost": "median_cpu_s", "variants": [],
            "pareto_front": [], "cheapest_meeting_target": None}
    assert SpeedAccuracy.from_json(data).variants == []
    data["cheapest"] = data.pop("cheapest_meeting_target")
    path = tmp_path / "speed_accuracy.json"
    path.write_text(json.dumps(data))
    renamed = "missing key 'cheapest_meeting_target'; unknown key.s. cheapest"
    with pytest.raises(ResultFormatError, match=renamed):
        build_report({"fe_speed_accuracy": path}, tmp_path / "report" / "index.html", [])


def test_the_report_page_notes_what_is_missing(tmp_path: Path) -> None:
    """Without any result the page still has every section, each noting its missing input."""
    from report.build import SECTIONS, build_report

    page = build_report({}, tmp_path / "index.html", []).read_text()
    for section_id, title, _ in SECTIONS:
        assert f'<section id="{section_id}"><h2>{title}</h2>' in page
    assert "Not available: results/fe_study/speed_accuracy.json" in page
    assert "could not be built" not in page


def test_a_sphere_sweep_is_drawn_one_column_per_direction(tmp_path: Path) -> None:
    """Directions off the plane share a Φ: each gets its own column, the plane's first."""
    import numpy as np

    from studies.figures.fe import direction_axis, plot_sweep_map

    phi = np.array([0.0, 90.0, 0.0, 90.0, 45.0, 45.0])
    plane = np.zeros(6)
    x, ticks, label = direction_axis(phi, plane)
    assert ticks is None and np.array_equal(x, phi) and "Φ" in label
    theta = np.array([0.0, 0.0, 0.0, 0.0, -90.0, -60.0])
    x, ticks, _ = direction_axis(phi, theta)
    assert ticks == ["0/0", "90/0", "45/-90", "45/-60"]
    assert list(x) == [0, 1, 0, 1, 2, 3]  # the same direction in the same column
    plot_sweep_map(np.ones(6), phi, np.arange(6.0), tmp_path / "map.png", "s", theta=theta)
    assert (tmp_path / "map.png").stat().st_size > 0


def test_the_solves_span_from_the_first_process_start_to_the_last_end() -> None:
    """The sweep's wall time from its cases' clocks; none where a case has no clock."""
    import numpy as np

    from report.sections.sweep_cost import solve_span

    start = np.array([100.0, 100.0, 130.0])  # two cases of one chain's process, then another
    end = np.array([110.0, 125.0, 160.0])
    assert solve_span(start, end) == 60.0
    assert solve_span(np.array([100.0, np.nan, 130.0]), end) is None  # an older summary
    assert solve_span(None, end) is None and solve_span(start[:0], end[:0]) is None


def test_the_by_c1_cases_are_told_apart_by_whether_their_c1_is_interpolated() -> None:
    """A held-out C1 between trained ones at its direction, or beyond them; the report's table."""
    from types import SimpleNamespace

    import numpy as np

    from report.context import Context
    from report.sections.generalisation import held_out_part
    from studies.surrogate_study.errors_against_fe import CaseErrors, ErrorSpread
    from studies.surrogate_study.held_out import (
        HeldOutBlock,
        HeldOutEvaluation,
        by_bracket,
        c1_bracketed,
    )

    # two directions: the plane's -90 at 0.8, 1.0 and 1.2; a band's direction at 1.0 and 1.2
    ds = SimpleNamespace(C1=np.array([0.8, 1.0, 1.2, 1.0, 1.2, 0.8]),
                         phi=np.array([-90.0, -90.0, -90.0, 60.0, 60.0, 60.0]),
                         theta=np.array([0.0, 0.0, 0.0, -120.0, -120.0, -120.0]))
    assert c1_bracketed(ds, [0, 2, 4], [1, 3]) == [True, False]
    # the same direction under another name (-90 at theta 0 is 90 at theta 180) counts
    ds.phi[0], ds.theta[0] = 90.0, 180.0
    assert c1_bracketed(ds, [0, 2, 4], [1]) == [True]
    assert c1_bracketed(ds, [2, 4], [1]) == [False]  # the softer case failed: not trained
    assert c1_bracketed(ds, [0, 2, 4, 5], [3]) == [True]
    fe = np.ones((4, 3))
    rows = [CaseErrors.between(fe + e, fe, f"case{k}", 1.0, 0.0, 0.0)
            for k, e in enumerate((0.01, 2.0, 0.02))]
    bands = by_bracket(rows, [True, False, True])
    assert [(label.split(":")[0], s.cases) for label, s in bands] == [
        ("between trained C1 values at its direction", 2), ("beyond them", 1)]
    assert bands[1][1].max_mm == pytest.approx(2.0 * np.sqrt(3))
    with pytest.raises(ValueError, match="2 flags for 3 cases"):
        by_bracket(rows, [True, False])
    block = HeldOutBlock(split="by_c1", held_out="whole C1 values", groups=["1"],
                         held_out_model=ErrorSpread.over(rows), inside_model=None, rows=rows,
                         inside_rows=[], bracketed=[True, False, True],
                         warned=[False, True, True])
    context = Context(out_dir=Path("."), clinical=[], paths={}, clinical_fields=[],
                      results={"held_out": HeldOutEvaluation(
                          blocks=[block], inside_all=ErrorSpread.over(rows))})
    page = held_out_part(context)
    assert 'id="held-out-c1-bracketed"' in page and "beyond them" in page
    # warned, per group: one of the two bracketed cases, the one beyond them
    assert re.search(r"<td>between trained C1 values at its direction</td><td>2</td><td>1</td>",
                     page)
    assert re.search(r"<td>beyond them[^<]*</td><td>1</td><td>1</td>", page)
    # the one case over 0.5 mm (2 √3 mm), warned at: split, cases, warned, over, of which
    # warned, not warned
    assert re.search(r'id="held-out-warned".*<td>by-c1</td><td>3</td><td>2</td><td>1</td>'
                     r"<td>1</td><td>0</td>", page, re.S)
    older = HeldOutBlock(**{**{f: getattr(block, f) for f in block.__dataclass_fields__},
                            "bracketed": [], "warned": []})
    context.results["held_out"] = HeldOutEvaluation(blocks=[older],
                                                    inside_all=ErrorSpread.over(rows))
    page = held_out_part(context)
    assert "c1-bracketed" not in page and "held-out-warned" not in page


def test_each_need_names_the_cheapest_model_and_the_cheapest_fe_model() -> None:
    """The cheapest model per need, and the cheapest FE model apart.

    A need met by a surrogate and by two FE variants: the surrogate is the cheapest, the
    cheaper FE variant the FE answer; a need no FE meets says none, and the counts add up.
    """
    from report.sections.scene_needs import NEEDS_HEADER, Candidate, needs_rows

    cands = [Candidate("surrogate", 0.02, 0.001, 1e-4, "FE default solution"),
             Candidate("FE coarse", 2.0, 0.3, 0.5, "refined FE reference", fe=True),
             Candidate("FE fine", 0.4, 0.04, 9.8, "refined FE reference", fe=True),
             Candidate("FE untimed", 0.1, 0.01, None, "refined FE reference", fe=True)]
    rows = {row[0]: dict(zip(NEEDS_HEADER, row, strict=True)) for row in needs_rows(cands)}
    assert set(rows) == {"0.5 mm", "1 mm", "5 mm"}
    half, five = rows["0.5 mm"], rows["5 mm"]
    assert half["cheapest at every point"] == "surrogate (100 µs)"
    assert half["cheapest FE at every point"] == "FE fine (9.8 s)"
    assert half["cheapest FE on average"] == "FE coarse (500 ms)"
    assert five["cheapest FE at every point"] == "FE coarse (500 ms)"
    assert half["models meeting it (every point / on average)"] == "3 / 4 of 4"
    only_coarse = needs_rows([cands[0], cands[1]])
    assert only_coarse[0][2] == "none" and only_coarse[0][4] == "FE coarse (500 ms)"
    # the selected model over cases beyond the clinical ones: its worst point error at the
    # points or between them (a tumour's), its worst case mean; the failed FE solves left out
    from types import SimpleNamespace

    from report.sections.scene_needs import over_cases

    def case(max_mm, mean_mm, between_mm=None):
        return SimpleNamespace(errors=SimpleNamespace(max_mm=max_mm, mean_mm=mean_mm),
                               between=between_mm and SimpleNamespace(max_mm=between_mm))

    rows = [case(0.1, 0.002, 0.3), case(0.2, 0.004), SimpleNamespace(errors=None, between=None)]
    beyond = over_cases("surrogate, selected, off the grid", rows, 1e-4)
    assert (beyond.name, beyond.max_error_mm, beyond.mean_error_mm, beyond.fe) == (
        "surrogate, selected, off the grid (2 cases)", 0.3, 0.004, False)
    assert over_cases("none compared", rows[2:], 1e-4) is None


def test_c1s_effect_is_judged_only_where_the_whole_c1_range_was_solved(tmp_path: Path) -> None:
    """A band's direction, solved at 1.0 and 1.2 kPa only, barely changes with C1 there.

    Its small spread must not make it a direction that "can use a single C1" over the sweep's
    0.8–5 kPa: it is drawn and listed apart, with the C1 values it was solved at.
    """
    from types import SimpleNamespace

    import numpy as np

    from report.context import Context
    from report.sections.scene_needs import scene_needs_section

    n = 4
    X = np.linspace(0.0, 1.0, n)[:, None] * np.ones((1, 3))

    def u(C1: float) -> np.ndarray:
        return 10.0 / C1 * X  # mm: the largest point moves 10 / C1 mm along each axis

    cases = [(C1, 0.0, 0.0) for C1 in (0.8, 1.0, 5.0)]  # the plane's supine, the whole range
    cases += [(C1, 60.0, -120.0) for C1 in (1.0, 1.2)]  # a band's direction
    cases += [(C1, 90.0, 0.0) for C1 in (0.8, 1.0, 5.0)]  # the softest case failed
    ds = SimpleNamespace(
        C1=np.array([c[0] for c in cases]), phi=np.array([c[1] for c in cases]),
        theta=np.array([c[2] for c in cases]),
        displacement=np.stack([u(c[0]) for c in cases]),
        converged=np.array([True] * 5 + [False, True, True]))
    context = Context(out_dir=tmp_path, clinical=[], paths={}, clinical_fields=[],
                      _dataset=ds)
    page = scene_needs_section(context)
    assert (tmp_path / "c1_effect.png").stat().st_size > 0
    verdicts = re.search(r"Over C1 = 0\.8–5 kPa, at the one direction solved over all of it: "
                         r"(.*?)</p>", page, re.S)
    assert verdicts, page
    # supine: 10/0.8 − 10/5 = 10.5 mm per axis at the last point; the best single C1 (1.0)
    # leaves 8 mm per axis: no need up to 5 mm is met there, and the band's direction
    # (0.8 mm per axis between 1.0 and 1.2 kPa) is not judged
    assert "no direction can use a single C1" in verdicts.group(1)
    assert "60°/-120°" not in verdicts.group(1) and "Left out: 2 directions" in verdicts.group(1)
    assert re.search(r"<td>60</td><td>-120</td><td>1–1.2</td>", page)
    assert re.search(r"<td>90</td><td>0</td><td>1–5</td>", page)


def test_the_extrapolation_and_training_tables_say_each_thing_once(tmp_path: Path) -> None:
    """A failed FE solve is named once, not once per model; a sphere's directions are counted.

    Φ and θ of a sweep over the sphere listed apart read as a grid that was never trained.
    """
    from report.context import Context
    from report.sections.extrapolation import extrapolation_section
    from report.sections.training import _training_range
    from studies.surrogate_study.surrogate_evaluation import Extrapolation, ExtrapolationBlock

    failed = [{"case": "c1=0.50_phi=0.0_theta=0.0", "reason": "step cut below min_step"}]
    block = ExtrapolationBlock(rows=[], failed_fe=failed, by_kind={})
    context = Context(out_dir=tmp_path, clinical=[], paths={}, clinical_fields=[],
                      results={"extrapolation": Extrapolation(by_sample=block, by_case=block)})
    assert "(1 FE solves outside the sweep failed)" in extrapolation_section(context)
    directions = [[phi, 0.0] for phi in range(-150, 180, 10)] + [[45.0, -90.0], [60.0, -30.0]]
    said = _training_range({"C1_kPa": [0.8, 5.0], "directions": directions,
                            "phi_deg": sorted({p for p, _ in directions}),
                            "theta_deg": [-90.0, -30.0, 0.0]})
    assert said == ("C1 [0.8, 5] kPa; 35 gravity directions (33 in the plane θ = 0; each "
                    "(Φ, θ) in model.json's training_range)")
    few = _training_range({"C1_kPa": [1.0, 5.0], "phi_deg": [0.0, 180.0], "theta_deg": [0.0],
                           "directions": [[0.0, 0.0], [180.0, 0.0]]})
    assert few == "C1 [1, 5] kPa; Φ ∈ {0, 180}°; θ ∈ {0}°"


def test_the_report_names_a_clinical_case_by_the_configs_label_else_its_folder(
    tmp_path: Path,
) -> None:
    """The report reads the config's clinical list once (fem.sweep.clinical_list).

    A case is found by its folder's name (C1 and the angles at that precision, theta 0 when
    not given) and named by its label, or by that name where the config gives none.
    """
    from report.context import Context

    ctx = Context.load({}, tmp_path, [{"C1": 1, "phi": 180, "label": "prone, soft"},
                                      {"C1": 5.0, "phi": 0.0, "theta": 0.0}])
    assert [item.case.id for item in ctx.clinical] == [
        "c1=1.00_phi=180.0_theta=0.0", "c1=5.00_phi=0.0_theta=0.0"]
    assert ctx.case_label("c1=1.00_phi=180.0_theta=0.0") == "prone, soft"
    assert ctx.case_label("c1=5.00_phi=0.0_theta=0.0") == "c1=5.00_phi=0.0_theta=0.0"
    assert ctx.case_label("c1=2.00_phi=90.0_theta=0.0") == "c1=2.00_phi=90.0_theta=0.0"
