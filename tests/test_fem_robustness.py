"""A case that cannot converge fails cleanly; bad input is refused before anything is written."""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from fem.exceptions import InvalidParameterError, MeshError
from fem.parameters import Gravity, Loading, Material, SolverSettings
from fem.sweep import Case

pytestmark = pytest.mark.solve


def test_unconvergeable_case_ends_failed_with_fraction_and_reason(
    coarse_mesh: Path, tmp_path: Path
) -> None:
    from fem.case import run_case

    # 0.02 kPa is 40x softer than the paper's softest tissue: the breast would fold over.
    # A small attempt budget keeps the test short; the outcome must still be a clean record.
    settings = SolverSettings(loading=Loading(max_steps=6), petsc_options={"snes_max_it": 8})
    summary = run_case(coarse_mesh, Case(0.02, 0.0), tmp_path / "case", settings)
    on_disk = json.loads((tmp_path / "case" / "summary.json").read_text())
    assert on_disk["status"] == summary["status"] == "failed"
    assert 0.0 <= on_disk["load_fraction"] < 1.0
    assert "budget" in on_disk["reason"] or "min_step" in on_disk["reason"]
    assert on_disk["rejected_steps"] >= 1 and on_disk["first_failure"]
    assert len(on_disk["load_path"]) <= 6
    # the fields hold the last converged state, which is finite and uninverted
    from fem.case_files import read_points

    points = read_points(tmp_path / "case" / "points.h5")
    assert np.all(np.isfinite(points["u"]))
    assert on_disk["min_detF"] > 0


def test_failed_first_step_is_cut_back_and_recovers(coarse_mesh: Path) -> None:
    from fem.case import CaseRunner

    # three Newton iterations are too few for the whole load at once, enough for halves
    runner = CaseRunner(coarse_mesh, SolverSettings(petsc_options={"snes_max_it": 3}))
    result, _ = runner.solve(Case(1.0, 0.0))
    assert result.converged
    assert not result.attempts[0].converged and result.attempts[0].fraction == 1.0
    assert result.attempts[1].fraction == 0.5
    assert result.first_failure.startswith("diverged_max_it")


def test_the_last_resort_goes_on_where_the_steps_fail(coarse_mesh: Path) -> None:
    """Steps cut below min_step: the loader starts again from rest with RESCUE_OPTIONS."""
    from fem.case import CaseRunner
    from fem.options import RESCUE_OPTIONS

    # one Newton iteration reaches no step; the last resort's 60 do
    crippled = {"snes_max_it": 1}
    case = Case(2.0, 180.0)
    without = CaseRunner(
        coarse_mesh, SolverSettings(loading=Loading(rescue=False), petsc_options=crippled)
    )
    failed, _ = without.solve(case)
    assert not failed.converged and not failed.rescued and "min_step" in failed.reason
    runner = CaseRunner(coarse_mesh, SolverSettings(petsc_options=crippled))
    result, _ = runner.solve(case)
    assert result.converged and result.rescued
    first = next(a for a in result.attempts if a.rescue)
    assert first.fraction == 1.0 and first.step == 1.0  # the whole load, from rest
    # the load path held is the last resort's: one step of more than one iteration
    assert result.accepted == [a for a in result.attempts if a.rescue and a.converged]
    assert len(result.newton_iterations) == 1 and result.newton_iterations[0] > 1
    assert all(not a.converged for a in result.attempts if not a.rescue)
    # the solver's own settings are back after each rescued solve
    from petsc4py import PETSc

    assert PETSc.Options().getString(f"{runner.solver.prefix}snes_linesearch_type") == "bt"
    assert runner.solver.snes.getTolerances()[3] == 1
    u = runner.problem.displacement().x.array.copy()
    reference = CaseRunner(coarse_mesh, SolverSettings())
    plain, _ = reference.solve(case)
    assert plain.converged and not plain.rescued
    u_ref = reference.problem.displacement().x.array
    assert np.abs(u - u_ref).max() < 1e-6 * np.abs(u_ref).max()
    with pytest.raises(InvalidParameterError, match="not ksp_type"):
        runner.solver.solve({**RESCUE_OPTIONS, "ksp_type": "cg"})
    with pytest.raises(InvalidParameterError, match="unknown line search 'nleqerr'"):
        runner.solver.solve({"snes_linesearch_type": "nleqerr"})


def _solve_whole_load(runner, case: Case, newton: dict | None = None):
    """One Newton solve of the whole load from rest (no load path)."""
    problem, solver, settings = runner.problem, runner.solver, runner.settings
    problem.set_case(case.material(settings.density), case.gravity(settings.gravity))
    problem.w.x.array[:] = 0.0
    solver.scale_to_load()
    problem.set_load_fraction(1.0)
    return solver.solve(newton)


def test_the_stall_test_keeps_petscs_own_tests_where_it_does_not_stall(coarse_mesh: Path) -> None:
    """A solve with a stall window that never fires is PETSc's own, residual for residual."""
    from fem.case import CaseRunner

    with CaseRunner(coarse_mesh) as runner:
        for newton in ({}, {"snes_max_it": 2}):  # converged; and stopped by the iteration limit
            plain = _solve_whole_load(runner, Case(1.5, 0.0), newton)
            windowed = _solve_whole_load(runner, Case(1.5, 0.0), {**newton, "stall_window": 1000})
            assert windowed.reason == plain.reason
            assert windowed.iterations == plain.iterations
            assert windowed.residuals == plain.residuals
        assert plain.reason == "diverged_max_it" and not plain.converged


def test_the_stall_test_tells_a_plateau_from_a_noisy_descent() -> None:
    from fem.convergence import stalled

    plateau = [0.36, 0.18, 0.1, *[0.072, 0.071, 0.073, 0.071] * 2]  # traced: 40 such iterations
    assert stalled(plateau, 8) and not stalled(plateau, 9) and not stalled(plateau, 0)
    # Newton on its way over the fold: noisy, then converging (traced, 31 iterations)
    noisy = [0.14, 0.1, 0.065, 0.047, 0.013, 0.0031, 0.0023, 0.0019, 0.002, 0.0016, 0.0029,
             0.0011, 0.0023, 0.0018, 0.0018, 0.0021, 0.0018, 0.0026, 0.0013, 0.0018, 0.0013]
    # creeping for 15 iterations, then over the fold and converged (traced, 41 iterations)
    creeping = [0.18, 0.138, 0.127, 0.117, 0.105, 0.0858, 0.0694, 0.062, 0.0472, 0.0471, 0.0388,
                0.0359, 0.0337, 0.0268, 0.0235, 0.0221, 0.0213, 0.0212, 0.0202, 0.0201, 0.0178,
                0.0185, 0.0158, 0.0169, 0.0164, 0.0156, 0.0164, 0.0163, 0.0126, 0.00881]
    for moving in (noisy, creeping):
        assert not any(stalled(moving[:k], 8) for k in range(len(moving) + 1))
    # flat, but at less than half the best residual before: progress, not a stall
    assert not stalled([1.0, 0.9, *[0.4] * 8], 8) and stalled([1.0, 0.7, *[0.4] * 8], 8)


def test_a_solve_whose_residual_stops_falling_is_given_up_as_stalled(coarse_mesh: Path) -> None:
    from fem.case import CaseRunner
    from fem.convergence import STALL_RATIO

    case = Case(0.8, -90.0)  # soft, rolled medially: the line search damps the first iterations
    with CaseRunner(coarse_mesh, SolverSettings(contact=None)) as runner:
        free = _solve_whole_load(runner, case, {"snes_max_it": 60})
        stalled = _solve_whole_load(runner, case, {"snes_max_it": 60, "stall_window": 1})
        again = _solve_whole_load(runner, case, {"snes_max_it": 60})  # the window is dropped
    assert again.residuals == free.residuals and free.converged
    norms = stalled.residuals
    assert stalled.reason == "diverged_stalled" and not stalled.converged
    assert stalled.iterations < free.iterations
    # it went as the plain solve did up to the iteration that failed to halve the residual
    assert norms == free.residuals[: len(norms)]
    assert norms[-1] > STALL_RATIO * min(norms[:-1])
    assert all(b <= STALL_RATIO * min(norms[: k + 1]) for k, b in enumerate(norms[1:-1]))
    from fem.loading import failure_kind

    assert failure_kind(stalled.reason) == "stalled"


def test_the_last_resort_gives_a_stalled_attempt_up(coarse_mesh: Path) -> None:
    """The loader hands ``Loading.stall_window`` to the last resort's attempts."""
    from fem.case import CaseRunner

    case = Case(0.8, -90.0)
    results = {}
    for window in (0, 1):
        # one Newton iteration fails the whole load, and a half step is below min_step: the
        # last resort follows at once, with the whole load from rest, and only that
        settings = SolverSettings(contact=None, petsc_options={"snes_max_it": 1},
                                  loading=Loading(min_step=1.0, stall_window=window,
                                                  rescue_min_step=1.0))
        with CaseRunner(coarse_mesh, settings) as runner:
            results[window], _ = runner.solve(case)
    assert results[0].converged and results[0].rescued
    stalled = results[1].attempts[-1]
    assert not results[1].converged and stalled.rescue
    assert stalled.reason == "diverged_stalled" and stalled.iterations == 1
    assert results[1].failure_kinds.get("stalled") == 1


def test_the_last_resort_stops_at_its_own_floor(coarse_mesh: Path) -> None:
    """``Loading.rescue_min_step``: the last resort's steps are not cut below it."""
    from fem.case import CaseRunner

    case = Case(0.8, -90.0)
    results = {}
    for floor in (1.0, 0.25):
        # as above: the last resort follows at once, and its whole load from rest stalls
        settings = SolverSettings(contact=None, petsc_options={"snes_max_it": 1},
                                  loading=Loading(min_step=1.0, stall_window=1,
                                                  rescue_min_step=floor))
        with CaseRunner(coarse_mesh, settings) as runner:
            results[floor], _ = runner.solve(case)
    rescue = {floor: [a for a in r.attempts if a.rescue] for floor, r in results.items()}
    assert [a.step for a in rescue[1.0]] == [1.0] and not rescue[1.0][0].converged
    assert not results[1.0].converged
    assert "and the last resort's below rescue_min_step=1 at λ=0.0000" in results[1.0].reason
    assert len(rescue[0.25]) > 1 and min(a.step for a in rescue[0.25]) >= 0.25
    assert results[0.25].fraction > results[1.0].fraction
    with pytest.raises(InvalidParameterError, match="rescue_min_step"):
        Loading(rescue_min_step=0.0)


def test_a_path_from_a_neighbour_tries_the_floor_itself(coarse_mesh: Path) -> None:
    """From λ = 0.8 the halvings 0.2, 0.1, 0.05 pass ``min_step`` = 0.0625: it is tried anyway.

    A path from rest halves onto the floor (1, 1/2, ... 1/16); one from a neighbour's state
    would otherwise be given up a cut sooner, as the default sweep's last three failures were
    (0.025, then 0.0125 below 1/64).
    """
    from fem.case import CaseRunner
    from fem.chain import Neighbours

    case, stiffer = Case(1.0, 180.0), Case(1.25, 180.0)
    with CaseRunner(coarse_mesh) as runner:
        assert runner.solve(stiffer)[0].converged
        neighbours = Neighbours(runner.problem.pressure_dofs)
        neighbours.add(stiffer, runner.problem.w.x.array)
        (fraction, state), = neighbours.path(case)[0]
    assert fraction == pytest.approx(0.8)
    # one Newton iteration converges no step: every cut is tried, down to the floor, and fails
    settings = SolverSettings(petsc_options={"snes_max_it": 1},
                              loading=Loading(min_step=0.0625, rescue=False))
    with CaseRunner(coarse_mesh, settings) as runner:
        result, _ = runner.solve(case, path=[(fraction, state)])
    assert [a.step for a in result.attempts] == pytest.approx([0.2, 0.1, 0.0625])
    assert not result.converged and "min_step=0.0625 at λ=0.8000" in result.reason


def _half_load_state(runner, case: Case) -> np.ndarray:
    """``case`` at half its load: the case of twice its C1 at the full load (fem.chain)."""
    from fem.chain import Neighbours

    stiffer = Case(2 * case.C1, case.phi, case.theta)
    result, _ = runner.solve(stiffer)
    assert result.converged
    neighbours = Neighbours(runner.problem.pressure_dofs)
    neighbours.add(stiffer, runner.problem.w.x.array)
    (fraction, state), = neighbours.path(case)[0]
    assert fraction == 0.5
    return state


def test_the_last_resorts_answer_is_checked_against_the_load_path(coarse_mesh: Path) -> None:
    """Walked back to where the first pass stopped, an answer meets that pass's state or not."""
    from fem.case import CaseRunner
    from fem.loading import BRANCH_TOLERANCE, LoadingResult, _continues

    case, other = Case(1.0, 0.0), Case(1.0, 180.0)
    with CaseRunner(coarse_mesh) as runner:
        on_path = _half_load_state(runner, case)
        elsewhere = _half_load_state(runner, other)  # prone's half-load state: not supine's
        assert runner.solve(case)[0].converged
        answer = runner.problem.w.x.array.copy()
        sag = np.linalg.norm(runner.problem.displacement().x.array.reshape(-1, 3), axis=1).max()
        checks = {}
        for name, state in (("on_path", on_path), ("elsewhere", elsewhere)):
            record = LoadingResult(converged=True, fraction=1.0, reason="")
            checks[name] = (_continues(runner.problem, runner.solver, Loading(), (0.5, state),
                                       record), record)
            assert np.array_equal(runner.problem.w.x.array, answer)  # the answer is kept
    (same, record), (different, apart) = checks["on_path"], checks["elsewhere"]
    assert same and record.branch_check["fraction"] == 0.5
    # one equilibrium, solved two ways to Newton's tolerance: far inside the tolerance
    assert record.branch_check["distance_m"] < 1e-2 * BRANCH_TOLERANCE * sag
    assert record.attempts and all(a.walk_back for a in record.attempts)
    assert record.path_end == 0  # the walk back is not part of the load path held
    assert not different and apart.branch_check["distance_m"] > 0.1 * sag


def test_a_last_resorts_answer_off_the_load_path_fails_the_case(coarse_mesh: Path) -> None:
    """A case whose last resort cannot be walked back to the first pass fails where that stopped.

    And a chain's case, started from its neighbours, takes no last resort unless asked to.

    One Newton iteration passes no half of the load: the first pass, started from the half-load
    state, fails at once; the last resort's 60 converge the whole load from rest, and the walk
    back fails as the first pass did.
    """
    from fem.case import CaseRunner

    case = Case(1.0, 0.0)
    crippled = SolverSettings(petsc_options={"snes_max_it": 1},
                              loading=Loading(min_step=0.5, rescue_min_step=1.0,
                                              rescue_after_neighbours=True))
    with CaseRunner(coarse_mesh) as runner:
        half = _half_load_state(runner, case)
    results = {}
    for check in (True, False):
        settings = replace(crippled, loading=replace(crippled.loading, check_branch=check))
        with CaseRunner(coarse_mesh, settings) as runner:
            results[check], _ = runner.solve(case, path=[(0.5, half)])
            state = runner.problem.w.x.array.copy()
        if check:
            assert np.array_equal(state, half)  # the first pass's furthest state is kept
    unchecked, checked = results[False], results[True]
    assert unchecked.converged and unchecked.rescued and unchecked.branch_check is None
    assert not checked.converged and checked.rescued and checked.fraction == 0.5
    assert "could not be walked back to λ=0.5000, where the first pass stopped" in checked.reason
    assert checked.branch_check == {"fraction": 0.5, "distance_m": None}
    assert any(a.walk_back for a in checked.attempts)
    assert all(not a.rescue and not a.walk_back for a in checked.accepted)
    # by default a case started from its neighbours (a chain's) has no last resort
    settings = replace(crippled, loading=replace(crippled.loading, rescue_after_neighbours=False))
    with CaseRunner(coarse_mesh, settings) as runner:
        chained, _ = runner.solve(case, path=[(0.5, half)])
    assert not chained.converged and not chained.rescued and chained.fraction == 0.5
    assert "no last resort after a start from the neighbours' solutions" in chained.reason


@pytest.mark.parametrize("window", [-1, 1.5, True])
def test_a_bad_stall_window_is_named(coarse_mesh: Path, window: object) -> None:
    from fem.case import CaseRunner

    with pytest.raises(InvalidParameterError, match="loading.stall_window"):
        Loading(stall_window=window)
    with CaseRunner(coarse_mesh) as runner, pytest.raises(InvalidParameterError,
                                                          match="stall_window"):
        runner.solver.solve({"stall_window": window})


@pytest.mark.parametrize("c1", [0.0, -1.0, math.nan, math.inf])
def test_bad_c1_is_named(c1: float) -> None:
    with pytest.raises(InvalidParameterError, match="C1"):
        Material(C1=c1)
    with pytest.raises(InvalidParameterError, match="C1"):
        Case(c1, 0.0)


def test_unknown_angle_unit_is_named() -> None:
    with pytest.raises(InvalidParameterError, match="unknown angle unit 'grad'"):
        Gravity(phi=90.0, unit="grad")
    assert np.allclose(Gravity(phi=math.pi, unit="rad").vector, [-9.81, 0.0, 0.0])


def _rewrite_mesh(
    source: Path, target: Path, move_vertex: bool = False, drop_tag: int | None = None
) -> None:
    """Copy an XDMF mesh, optionally breaking it.

    Either one interior vertex is pushed through its neighbours (inverting cells), or one
    facet tag is removed.
    """
    from dolfinx.io import XDMFFile
    from dolfinx.mesh import exterior_facet_indices, meshtags
    from mpi4py import MPI

    from meshes.io import read_mesh
    from meshes.tags import CELL_TAGS_NAME, FACET_TAGS_NAME, MESH_NAME

    mesh, cell_tags, facet_tags = read_mesh(source, MPI.COMM_SELF)
    if move_vertex:
        mesh.topology.create_connectivity(2, 0)
        boundary_nodes = np.unique(
            mesh.topology.connectivity(2, 0).array.reshape(-1, 3)[
                exterior_facet_indices(mesh.topology)
            ]
        )
        x = mesh.geometry.x
        interior = np.setdiff1d(np.arange(len(x)), boundary_nodes)
        centre = x.mean(axis=0)
        node = interior[np.argmin(np.linalg.norm(x[interior] - centre, axis=1))]
        x[node] += np.array([0.08, 0.0, 0.0])  # several element sizes: folds cells over
    if drop_tag is not None:
        keep = facet_tags.values != drop_tag
        facet_tags = meshtags(mesh, 2, facet_tags.indices[keep], facet_tags.values[keep])
    mesh.name, cell_tags.name, facet_tags.name = MESH_NAME, CELL_TAGS_NAME, FACET_TAGS_NAME
    with XDMFFile(MPI.COMM_SELF, str(target), "w") as xdmf:
        xdmf.write_mesh(mesh)
        xdmf.write_meshtags(cell_tags)
        xdmf.write_meshtags(facet_tags)


@pytest.mark.parametrize(
    "kind, message",
    [("inverted", "inverted cells"), ("no-rib", "no facets tagged 'rib'")],
)
def test_bad_mesh_is_named_and_nothing_is_written(
    coarse_mesh: Path, tmp_path: Path, kind: str, message: str
) -> None:
    from fem.case import run_case

    bad = tmp_path / "bad.xdmf"
    _rewrite_mesh(
        coarse_mesh, bad, move_vertex=kind == "inverted", drop_tag=1 if kind == "no-rib" else None
    )
    with pytest.raises(MeshError, match=message):
        run_case(bad, Case(1.0, 0.0), tmp_path / "case")
    assert not (tmp_path / "case").exists()


def test_bad_settings_from_config_are_named() -> None:
    with pytest.raises(InvalidParameterError, match="unknown loading parameter"):
        SolverSettings.from_config({"fe": {"loading": {"max_step": 3}}})
    with pytest.raises(InvalidParameterError, match="unknown element"):
        SolverSettings.from_config({"fe": {"discretisation": {"element": "p2-penalty"}}})
