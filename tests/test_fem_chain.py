"""Chains of cases (fem.chain): each case from its neighbours' solutions, the same answers."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from fem.exceptions import InvalidParameterError
from fem.sweep import Case

pytestmark = pytest.mark.solve


def test_chains_group_directions_stiffest_first() -> None:
    from fem.chain import direction_chains

    cases = [Case(1.0, 0.0), Case(5.0, 90.0), Case(3.0, 0.0), Case(1.0, 90.0), Case(2.0, 0.0, 30.0)]
    chains = direction_chains(cases)
    assert chains == [
        [Case(3.0, 0.0), Case(1.0, 0.0)],
        [Case(2.0, 0.0, 30.0)],
        [Case(5.0, 90.0), Case(1.0, 90.0)],
    ]
    with pytest.raises(InvalidParameterError, match="twice"):
        direction_chains([Case(1.0, 0.0), Case(1.0, 0.0)])


def test_neighbours_are_states_of_the_softer_case_at_lower_load() -> None:
    """Case C1 at load fraction C1/C1k is case C1k at the full load, the pressure scaled."""
    from fem.chain import Neighbours

    neighbours = Neighbours(np.array([2]))  # entries 0 and 1 displacement, entry 2 pressure
    assert neighbours.path(Case(4.0, 0.0)) == ([], neighbours.path(Case(4.0, 0.0))[1])
    assert neighbours.path(Case(4.0, 0.0))[1].kind == "rest"
    neighbours.add(Case(4.0, 0.0), np.array([1.0, 2.0, 8.0]))
    neighbours.add(Case(2.0, 0.0), np.array([2.0, 4.0, 8.0]))
    path, start = neighbours.path(Case(1.0, 0.0))
    assert start.kind == "neighbours" and start.fraction == 0.5
    assert start.neighbours == ("c1=4.00_phi=0.0_theta=0.0", "c1=2.00_phi=0.0_theta=0.0")
    assert [f for f, _ in path] == [0.25, 0.5]
    np.testing.assert_allclose(path[0][1], [1.0, 2.0, 2.0])
    np.testing.assert_allclose(path[1][1], [2.0, 4.0, 4.0])
    # only stiffer cases of the same direction lie on a case's path; three are kept
    assert neighbours.path(Case(5.0, 0.0))[1].kind == "rest"
    assert neighbours.path(Case(1.0, 90.0))[1].kind == "rest"
    neighbours.add(Case(5.0, 90.0), np.zeros(3))
    neighbours.add(Case(1.5, 0.0), np.zeros(3))
    neighbours.add(Case(1.2, 0.0), np.zeros(3))
    assert neighbours.path(Case(1.0, 0.0))[1].neighbours == (
        "c1=2.00_phi=0.0_theta=0.0", "c1=1.50_phi=0.0_theta=0.0", "c1=1.20_phi=0.0_theta=0.0")


def test_the_prediction_is_the_polynomial_through_the_known_states(coarse_mesh: Path) -> None:
    """Three known states: the quadratic through them.

    Where it inverts an element, the line through the last two; where that does too, the last
    state.
    """
    from dolfinx import fem

    from fem.case import CaseRunner
    from fem.loading import _predict

    with CaseRunner(coarse_mesh) as runner:
        problem = runner.problem
        rng = np.random.default_rng(1)
        a, b, c = (1e-6 * rng.standard_normal(problem.w.x.array.size) for _ in range(3))

        def state(lam: float, c: np.ndarray = c) -> np.ndarray:
            return a + lam * b + lam**2 * c

        history = [(lam, state(lam)) for lam in (0.5, 0.6, 0.75)]
        _predict(problem, history, 0.25, extrapolate=True)
        np.testing.assert_allclose(problem.w.x.array, state(1.0), rtol=0, atol=1e-15)
        _predict(problem, history[1:], 0.25, extrapolate=True)  # two states: the line
        line = history[2][1] + (0.25 / 0.15) * (history[2][1] - history[1][1])
        np.testing.assert_allclose(problem.w.x.array, line, rtol=0, atol=1e-15)
        # u = -1.05 λ² X: det F = (1 - 1.05 λ²)³, positive at the known states and on the line
        # (λ² extrapolated linearly to 0.9 at λ = 1), negative for the quadratic
        shrink = fem.Function(problem.V)
        shrink.interpolate(lambda x: -1.05 * x)
        fold = np.zeros_like(c)
        fold[problem.W.sub(0).collapse()[1]] = shrink.x.array
        a[:] = b[:] = 0.0
        history = [(lam, state(lam, fold)) for lam in (0.5, 0.6, 0.75)]
        assert all(_detF_positive(problem, w) for _, w in history)
        _predict(problem, history, 0.25, extrapolate=True)
        line = history[2][1] + (0.25 / 0.15) * (history[2][1] - history[1][1])
        assert _detF_positive(problem, line)
        np.testing.assert_allclose(problem.w.x.array, line, rtol=0, atol=1e-15)
        history = [(lam, state(lam, fold * 1.5 / 1.05)) for lam in (0.5, 0.6, 0.75)]
        _predict(problem, history, 0.25, extrapolate=True)  # the line inverts too
        np.testing.assert_array_equal(problem.w.x.array, history[2][1])


def _detF_positive(problem, w: np.ndarray) -> bool:
    saved = problem.w.x.array.copy()
    problem.w.x.array[:] = w
    positive = problem.min_detF() > 0
    problem.w.x.array[:] = saved
    return positive


def test_the_answer_does_not_depend_on_where_the_path_starts(coarse_mesh: Path) -> None:
    """A path from the stiffer neighbour gives the answer from rest.

    Both meet the same stopping test, so they agree to far below the FE error.
    """
    from fem.case import CaseRunner
    from fem.chain import Neighbours

    with CaseRunner(coarse_mesh) as runner:
        problem = runner.problem
        cold, _ = runner.solve(Case(1.2, 0.0))
        from_rest = problem.w.x.array.copy()
        runner.solve(Case(1.5, 0.0))
        neighbours = Neighbours(problem.pressure_dofs)
        neighbours.add(Case(1.5, 0.0), problem.w.x.array)
        path, start = neighbours.path(Case(1.2, 0.0))
        # the neighbour is an equilibrium of this case at λ = 0.8: its residual vanishes there
        problem.set_case(Case(1.2, 0.0).material(), Case(1.2, 0.0).gravity())
        problem.set_load_fraction(start.fraction)
        problem.w.x.array[:] = path[-1][1]
        runner.solver._residual(runner.solver.snes, problem.w.vector, runner.solver.b)
        at_rest = runner.solver.b.duplicate()
        problem.w.x.array[:] = 0.0
        runner.solver._residual(runner.solver.snes, problem.w.vector, at_rest)
        assert runner.solver.b.norm() < 1e-6 * at_rest.norm()
        warm, _ = runner.solve(Case(1.2, 0.0), path=path)
        assert cold.converged and warm.converged and warm.start_fraction == start.fraction
        scale = np.abs(from_rest).max()
        assert np.abs(problem.w.x.array - from_rest).max() < 1e-6 * scale
        with pytest.raises(InvalidParameterError, match="increase within"):
            runner.solve(Case(1.2, 0.0), path=[(0.9, path[0][1]), (0.8, path[0][1])])


def test_a_chain_writes_every_case_as_run_case_does(coarse_mesh: Path, tmp_path: Path) -> None:
    from fem.case_files import read_points
    from fem.chain import solve_chain

    cases = [Case(1.0, 180.0), Case(5.0, 180.0), Case(2.0, 180.0), Case(5.0, 0.0)]
    solved = solve_chain(coarse_mesh, cases, lambda case: tmp_path / case.id)
    assert [s.case for s in solved] == [Case(5.0, 0.0), Case(5.0, 180.0), Case(2.0, 180.0),
                                        Case(1.0, 180.0)]
    assert all(s.converged for s in solved)
    starts = [len(s.summary["start"]["neighbours"]) for s in solved]
    assert starts == [0, 0, 1, 2]
    assert solved[-1].summary["start"]["fraction"] == pytest.approx(0.5)
    # the unit of cost is measured once per process, the set-up counted once
    measured = [s.summary["factorization_equivalents"] is not None for s in solved]
    assert measured == [True, False, False, False]
    assert [s.summary["wall_s"]["setup"] > 0 for s in solved] == measured
    for s in solved:
        folder = tmp_path / s.case.id
        assert sorted(p.name for p in folder.iterdir()) == [
            "fields.h5", "fields.xdmf", "points.h5", "summary.json"]
        on_disk = json.loads((folder / "summary.json").read_text())
        assert on_disk["case"] == s.case.id and on_disk["status"] == "converged"
        assert on_disk["chain"]["first"] == ("c1=5.00_phi=180.0_theta=0.0"
                                             if s.case.phi == 180 else s.case.id)
    points = read_points(tmp_path / Case(1.0, 180.0).id / "points.h5")
    assert points["case"] == Case(1.0, 180.0).id and np.abs(points["u"]).max() > 0


def test_the_rescue_benchmark_solves_the_chains_both_ways(coarse_mesh: Path,
                                                          tmp_path: Path) -> None:
    """``benchmarks.rescue_settings``: each way's chains in fresh processes, compared by case."""
    import yaml

    from benchmarks.rescue_settings import RescueCost, parse_against, run

    config = {"fe": {"loading": {"stall_window": 6}}}
    result = run(coarse_mesh, config, [(-90.0, 0.0)], [1.5, 1.0], tmp_path)
    assert result.loading["stall_window"] == 6
    assert result.against == {"rescue_after_neighbours": True}
    assert [r.case for r in result.cases] == [Case(1.5, -90.0).id, Case(1.0, -90.0).id]
    for row in result.cases:  # no last resort is needed here: the same answer both ways
        assert row.status_config == row.status_against == "converged"
        assert row.difference_mm == 0.0 and row.newton_config == row.newton_against
    assert result.cpu_config_s > 0 and result.cpu_against_s > 0
    other = yaml.safe_load((tmp_path / "against" / "config.yaml").read_text())
    assert other["fe"]["loading"]["rescue_after_neighbours"] is True
    summary = json.loads((tmp_path / "config" / "cases" / Case(1.0, -90.0).id / "summary.json")
                         .read_text())
    assert summary["settings"]["loading"]["stall_window"] == 6
    result.write(tmp_path / "rescue_settings.json")
    assert RescueCost.read(tmp_path / "rescue_settings.json") == result
    assert parse_against(["rescue_min_step=0.015625", "stall_window=0"]) == {
        "rescue_min_step": 0.015625, "stall_window": 0}
    for against, message in (({"stall_window": 6}, "is the config's own"),
                             ({"stall_windw": 0}, "unknown loading parameter"),
                             ({"rescue_min_step": 0}, "rescue_min_step must lie")):
        with pytest.raises(InvalidParameterError, match=message):
            run(coarse_mesh, config, [(-90.0, 0.0)], [1.0], tmp_path / "none", against)
    with pytest.raises(InvalidParameterError, match="KEY=VALUE"):
        parse_against(["rescue_min_step"])
