"""A cell with every node on the clamped chest wall leaves its pressure undetermined.

fem.pressure_modes pins it. An image mesher makes such cells where the chest wall meets the skin
at a sharp rim: CGAL's mesh of the test phantom with tissues had one, and its tangent was
singular (MUMPS INFOG(1) = -10, then -3 in the solve phase): no case on it solved. The mesh here
is a box clamped at x = 0 with one "ear", a tetrahedron outside that face, whose three outer
faces are clamped too: all ten of its nodes are fixed, and its apex's pressure meets no free
displacement.
"""

from __future__ import annotations

import numpy as np
import pytest

pytestmark = pytest.mark.solve


def _box_with_ear(ear: bool) -> tuple:
    """A 4 cm cube of fat clamped at x = 0 (rib) and, with ``ear``, a clamped cell outside."""
    import ufl
    from dolfinx import mesh as dmesh
    from mpi4py import MPI

    from meshes.tags import Boundary

    side = 0.04
    box = dmesh.create_box(MPI.COMM_WORLD, [np.zeros(3), np.full(3, side)], [2, 2, 2],
                           dmesh.CellType.tetrahedron)
    x = box.geometry.x.copy()
    cells = box.geometry.dofmap.array.reshape(-1, 4).copy()
    if ear:  # a cell on a face of x = 0, its apex outside
        box.topology.create_connectivity(2, 0)
        face_vertices = box.topology.connectivity(2, 0)
        faces = dmesh.locate_entities_boundary(box, 2, lambda p: np.isclose(p[0], 0.0))
        vertex_to_node = _vertex_to_node(box)
        face = vertex_to_node[face_vertices.links(faces[0])]
        apex = x[face].mean(axis=0) - np.array([0.01, 0.0, 0.0])
        x = np.vstack([x, apex])
        ear_cell = np.append(face, len(x) - 1)
        if _signed_volume(x, ear_cell) * _signed_volume(x, cells[0]) < 0:
            ear_cell[[0, 1]] = ear_cell[[1, 0]]  # oriented as the box's cells are
        cells = np.vstack([cells, ear_cell])
    domain = ufl.Mesh(ufl.VectorElement("Lagrange", ufl.tetrahedron, 1))
    mesh = dmesh.create_mesh(MPI.COMM_WORLD, cells, x, domain)
    mesh.topology.create_connectivity(2, 3)
    exterior = dmesh.exterior_facet_indices(mesh.topology)
    values = np.full(len(exterior), int(Boundary.SKIN), dtype=np.int32)
    on_rib = dmesh.locate_entities_boundary(mesh, 2, lambda p: p[0] <= 1e-12)
    values[np.isin(exterior, on_rib)] = int(Boundary.RIB)
    return mesh, dmesh.meshtags(mesh, 2, exterior, values)


def _signed_volume(x: np.ndarray, cell: np.ndarray) -> float:
    a, b, c, d = x[cell]
    return float(np.dot(np.cross(b - a, c - a), d - a))


def _vertex_to_node(mesh) -> np.ndarray:
    """The geometry node of each vertex (P1 geometry: one node per vertex)."""
    num_vertices = mesh.topology.index_map(0).size_local
    out = np.empty(num_vertices, dtype=np.int64)
    mesh.topology.create_connectivity(3, 0)
    c2v = mesh.topology.connectivity(3, 0)
    nodes = mesh.geometry.dofmap
    for cell in range(mesh.topology.index_map(3).size_local):
        out[c2v.links(cell)] = nodes.links(cell)
    return out


def test_the_ear_apex_is_the_one_undetermined_pressure() -> None:
    from fem.pressure_modes import undetermined_pressure_dofs
    from fem.problem import GravityProblem

    for ear, expected in ((False, 0), (True, 1)):
        mesh, facets = _box_with_ear(ear)
        problem = GravityProblem(mesh, facets)
        dofs = undetermined_pressure_dofs(problem.W, problem.bcs)
        assert len(dofs) == expected, ear
        if ear:  # the apex: the one vertex outside the box
            pressure, to_W = problem.W.sub(1).collapse()
            where = pressure.tabulate_dof_coordinates()[list(to_W).index(dofs[0])]
            assert where[0] == pytest.approx(-0.01)


def test_a_mesh_with_a_clamped_ear_solves_as_the_box_alone() -> None:
    """The pinned pressure changes no displacement: the box hangs as it does without the ear.

    Without the pin, the ear's mesh does not solve at all (its tangent is singular).
    """
    from fem.loading import solve_incrementally
    from fem.parameters import Gravity, Loading, Material
    from fem.problem import GravityProblem
    from fem.solver import NewtonSolver

    tight = {"snes_rtol": 1e-12, "snes_atol": 1e-11, "load_atol": 0.0}
    largest = {}
    for ear in (False, True):
        mesh, facets = _box_with_ear(ear)
        problem = GravityProblem(mesh, facets)
        solver = NewtonSolver(problem, tight)
        problem.set_case(Material(C1=1000.0), Gravity(phi=90.0))
        result = solve_incrementally(problem, solver, Loading())
        assert result.converged, (ear, result.reason)
        u = problem.displacement().x.array.reshape(-1, 3)
        largest[ear] = float(np.linalg.norm(u, axis=1).max())
        solver.destroy()
    # the ear is clamped on all its outer faces: it holds nothing up and moves nowhere
    assert largest[True] == pytest.approx(largest[False], rel=1e-9)
    assert largest[False] > 1e-4


def test_after_a_petsc_error_the_next_attempt_starts_on_a_clean_linear_solver(
    monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    """Without the pin the ear's tangent is singular: every attempt fails, each for that reason.

    A PETSc error inside the Krylov solve used to leave the KSP mid-solve, and from the third
    attempt on every solve failed with "Cannot embed PCPreSolve() more than twice" instead,
    so no cut-back could ever succeed on a state where a fresh solve would.
    """
    import logging

    import fem.problem
    from fem.loading import solve_incrementally
    from fem.parameters import Gravity, Loading, Material
    from fem.problem import GravityProblem
    from fem.solver import NewtonSolver

    monkeypatch.setattr(fem.problem, "pinned_pressure_bcs", lambda W, bcs: [])
    mesh, facets = _box_with_ear(True)
    problem = GravityProblem(mesh, facets)
    solver = NewtonSolver(problem, {})
    problem.set_case(Material(C1=1000.0), Gravity(phi=90.0))
    with caplog.at_level(logging.WARNING, logger="fem.solver"):
        result = solve_incrementally(problem, solver, Loading())
    solver.destroy()
    assert not result.converged
    errors = [r.getMessage() for r in caplog.records if "PETSc error" in r.getMessage()]
    assert len(errors) >= 3, errors
    assert not any("Cannot embed" in e for e in errors), errors
    assert all("MUMPS" in e for e in errors), errors


def test_a_pinned_pressure_is_not_counted_as_one_in_the_stability_audit() -> None:
    """The ear's state at rest is a stable equilibrium: no unstable mode, none missing.

    The pinned pressure's row is a unit diagonal, like a clamped displacement's: it adds a
    positive eigenvalue, not the negative one a pressure unknown adds. Counted as a pressure
    unknown, every state of such a mesh read as unstable (-1 modes), and the stability audit
    set aside every case of a patient's CGAL mesh.
    """
    from fem.parameters import Gravity, Material
    from fem.problem import GravityProblem
    from fem.stability import tangent_inertia

    mesh, facets = _box_with_ear(True)
    problem = GravityProblem(mesh, facets)
    assert problem.pinned_pressure_dofs == 1
    problem.set_case(Material(C1=1000.0), Gravity(phi=90.0))
    problem.set_load_fraction(0.0)
    inertia = tangent_inertia(problem)
    assert inertia.unstable_modes == 0 and inertia.zero == 0 and inertia.stable, inertia
