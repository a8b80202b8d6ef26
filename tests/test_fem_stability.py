"""Stability where the solves end: the tangent's inertia, and gravity turned to the patch's edge.

The inertia from MUMPS's LDLᵀ is checked against the eigenvalues of the dense tangent on a
very coarse mesh (about 1,600 unknowns), at a stable equilibrium and at a state whose pressure
makes the body unstable; the turn of gravity against a case solved alone.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fem.exceptions import InvalidParameterError
from fem.parameters import Gravity, Loading, SolverSettings
from fem.sweep import Case


@pytest.fixture(scope="module")
def tiny_mesh(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The default geometry with elements of 5–6 cm: a tangent small enough to diagonalise."""
    from meshes.build import MeshSize, write_parametric_mesh
    from meshes.parametric import BreastGeometry

    path = tmp_path_factory.mktemp("tiny") / "mesh.xdmf"
    write_parametric_mesh(BreastGeometry(), MeshSize(global_size=0.06, mound_size=0.05, order=1),
                          path)
    return path


def _dense_signs(problem) -> tuple[int, int]:
    """Negative and positive eigenvalues of the assembled tangent, by LAPACK."""
    import dolfinx.fem.petsc as fem_petsc

    A = fem_petsc.assemble_matrix(problem.tangent, bcs=problem.bcs)
    A.assemble()
    values = np.linalg.eigvalsh(A.convert("dense").getDenseArray())
    A.destroy()
    return int((values < 0).sum()), int((values > 0).sum())


@pytest.mark.solve
def test_the_inertia_counts_the_dense_tangents_eigenvalues(tiny_mesh: Path) -> None:
    """Stable at equilibrium; a state under a large pressure has unstable modes, counted right."""
    from fem.case import CaseRunner
    from fem.stability import tangent_inertia

    with CaseRunner(tiny_mesh) as runner:
        result, _ = runner.solve(Case(1.0, 180.0))
        assert result.converged
        problem = runner.problem
        inertia = tangent_inertia(problem)
        assert inertia.pressure_dofs == len(problem.pressure_dofs) > 0
        assert (inertia.negative, inertia.positive) == _dense_signs(problem)
        assert inertia.zero == 0 and inertia.unstable_modes == 0 and inertia.stable
        # −p δ²J: a large pressure makes the displacement block indefinite
        problem.w.x.array[problem.pressure_dofs] = 2e4
        loaded = tangent_inertia(problem)
        assert (loaded.negative, loaded.positive) == _dense_signs(problem)
        assert loaded.unstable_modes > 0 and not loaded.stable
        assert loaded.as_dict()["unstable_modes"] == loaded.unstable_modes


@pytest.mark.unit
def test_directions_on_the_great_circle() -> None:
    from studies.failure_edge import direction_angles, great_circle

    for phi, theta in ((-75.0, 0.0), (75.0, 0.0), (120.0, -30.0), (90.0, 90.0), (180.0, 0.0)):
        g = Gravity(phi, theta, magnitude=1.0).vector
        assert np.allclose(Gravity(*direction_angles(g), magnitude=1.0).vector, g, atol=1e-12)
    assert direction_angles(Gravity(-75.0, 0.0, magnitude=1.0).vector) == pytest.approx((-75, 0))
    start, target = (Gravity(a, 0.0, magnitude=1.0).vector for a in (-75.0, -90.0))
    span, at = great_circle(start, target)
    assert span == pytest.approx(15.0)
    assert direction_angles(at(5.0)) == pytest.approx((-80.0, 0.0))
    assert np.allclose(at(span), target)
    for other in (start, -start):
        with pytest.raises(InvalidParameterError, match="neither the same nor opposite"):
            great_circle(start, other)


@pytest.mark.solve
def test_turning_gravity_reaches_the_case_solved_alone(tiny_mesh: Path) -> None:
    """Where nothing fails, the turn ends on the target case's equilibrium, every state stable."""
    from fem.case import CaseRunner
    from studies.failure_edge import turn

    edge = turn(tiny_mesh, SolverSettings(), 1.0, (180.0, 0.0), (150.0, 20.0), via=(2.0,),
                step_deg=10.0, resolution_deg=1.0)
    assert edge.reached_target and edge.first_failure_deg is None and edge.all_stable
    assert all(0 < s.min_detF < 1.5 for s in edge.states)
    assert edge.edge_deg == pytest.approx(edge.span_deg) and len(edge.states) >= 3
    assert [s.angle_deg for s in edge.states] == sorted(s.angle_deg for s in edge.states)
    last = edge.states[-1]
    assert (last.phi, last.theta) == pytest.approx((150.0, 20.0))
    with CaseRunner(tiny_mesh) as runner:
        runner.solve(Case(1.0, 150.0, 20.0))
        u = runner.problem.displacement().x.array.reshape(-1, 3)
        alone = 1e3 * np.linalg.norm(u, axis=1).max()
    assert last.max_displacement_mm == pytest.approx(alone, rel=1e-6)


@pytest.mark.solve
def test_a_turn_whose_steps_fail_stops_at_the_resolution(tiny_mesh: Path) -> None:
    """Steps that cannot converge are halved down to the resolution; the edge is the start."""
    from studies.failure_edge import turn

    edge = turn(tiny_mesh, SolverSettings(), 1.0, (180.0, 0.0), (120.0, 0.0), step_deg=8.0,
                resolution_deg=1.0, newton={"snes_max_it": 1, "snes_linesearch_type": "basic"})
    assert not edge.reached_target and edge.edge_deg == 0.0 and len(edge.states) == 1
    assert [f.angle_deg for f in edge.failures] == [8.0, 4.0, 2.0, 1.0]
    assert edge.first_failure_deg == 1.0
    with pytest.raises(InvalidParameterError, match="did not converge"):
        turn(tiny_mesh, SolverSettings(loading=Loading(rescue=False, max_steps=4),
                                       petsc_options={"snes_max_it": 1}), 1.0, (180.0, 0.0),
             (150.0, 0.0), step_deg=8.0, resolution_deg=1.0)
    with pytest.raises(InvalidParameterError, match="stiffer than 1.0 kPa"):
        turn(tiny_mesh, SolverSettings(), 1.0, (180.0, 0.0), (150.0, 0.0), via=(0.8,))
