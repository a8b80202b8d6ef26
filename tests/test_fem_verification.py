"""Verification of the FE solver against analytic solutions and exact symmetries.

* homogeneous uniaxial stretch of a block: P11 = 2 C1 (λ - λ⁻²), all else zero;
* a mirror-symmetric body under gravity in its symmetry plane deforms mirror-symmetrically;
* the solution depends on ρg/C1 only, and a tiny load scales linearly with 1/C1;
* zero gravity gives exactly zero; total volume is conserved to the solver's tolerance.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import ufl
from dolfinx import fem
from dolfinx import mesh as dmesh
from mpi4py import MPI
from petsc4py import PETSc

from fem.kinematics import deformation_gradient
from fem.materials import first_piola_kirchhoff, strain_energy
from fem.parameters import Discretisation, FixedBoundaries, Gravity, Loading, Material
from fem.problem import GravityProblem
from fem.solver import NewtonSolver
from meshes.tags import Boundary

pytestmark = pytest.mark.solve

TIGHT = {"snes_rtol": 1e-12, "snes_atol": 1e-11, "load_atol": 0.0}


# -- homogeneous uniaxial stretch ---------------------------------------------------------------
class UniaxialStretch:
    """A unit cube stretched to λ along x, free laterally (symmetry planes x, y, z = 0).

    Uses the project's strain energy (:func:`fem.materials.strain_energy`) and Newton
    solver on a mixed Taylor–Hood space. The exact solution (u linear, p constant)
    lies in the discrete space, so the FE solution is exact to solver tolerance.
    """

    mixed = True
    symmetric = True  # the second variation of a potential, as the solver's problems declare

    def __init__(self, stretch: float, C1: float, degree: int) -> None:
        self.mesh = dmesh.create_box(
            MPI.COMM_WORLD, [np.zeros(3), np.ones(3)], [2, 2, 2], dmesh.CellType.tetrahedron
        )
        cell = self.mesh.ufl_cell()
        element = ufl.MixedElement(
            [
                ufl.VectorElement("Lagrange", cell, degree),
                ufl.FiniteElement("Lagrange", cell, degree - 1),
            ]
        )
        self.W = fem.FunctionSpace(self.mesh, element)
        self.V, _ = self.W.sub(0).collapse()
        self.w = fem.Function(self.W)
        u, p = ufl.split(self.w)
        self.F = deformation_gradient(u)
        self.C1 = fem.Constant(self.mesh, PETSc.ScalarType(C1))
        self.psi = strain_energy(self.F, p, self.C1, Discretisation(degree=degree))
        dx = ufl.dx(metadata={"quadrature_degree": 2 * degree})  # exact: the state is homogeneous
        residual = ufl.derivative(self.psi * dx, self.w, ufl.TestFunction(self.W))
        tangent = ufl.derivative(residual, self.w, ufl.TrialFunction(self.W))
        self.residual, self.tangent = fem.form(residual), fem.form(tangent)
        self.bcs = []
        fdim = self.mesh.topology.dim - 1
        for comp, plane, value in (
            (0, 0.0, 0.0),
            (0, 1.0, stretch - 1.0),
            (1, 0.0, 0.0),
            (2, 0.0, 0.0),
        ):
            facets = dmesh.locate_entities_boundary(
                self.mesh, fdim, lambda x, c=comp, v=plane: np.isclose(x[c], v)
            )
            sub = self.W.sub(0).sub(comp)
            collapsed, _ = sub.collapse()
            g = fem.Function(collapsed)
            g.x.array[:] = value
            dofs = fem.locate_dofs_topological((sub, collapsed), fdim, facets)
            self.bcs.append(fem.dirichletbc(g, dofs, sub))

    def stress_at_quadrature_points(self) -> np.ndarray:
        """First Piola–Kirchhoff stress (cells, points, 3, 3) from the solved state."""
        P = first_piola_kirchhoff(self.psi, self.F)
        points = np.array([[0.25, 0.25, 0.25], [0.1, 0.2, 0.6], [0.7, 0.1, 0.1]])
        n_cells = self.mesh.topology.index_map(3).size_local
        values = fem.Expression(P, points).eval(np.arange(n_cells, dtype=np.int32))
        return values.reshape(n_cells, len(points), 3, 3)


@pytest.mark.parametrize("degree", [2, 3])
@pytest.mark.parametrize("stretch", [1.5, 0.7])
def test_uniaxial_stretch_matches_analytic_stress(degree: int, stretch: float) -> None:
    C1 = 1000.0
    problem = UniaxialStretch(stretch, C1, degree)
    solver = NewtonSolver(problem, TIGHT)
    result = solver.solve()
    assert result.converged, result.reason
    P = problem.stress_at_quadrature_points()
    analytic = 2 * C1 * (stretch - stretch**-2)
    assert np.max(np.abs(P[..., 0, 0] - analytic)) <= 1e-8 * abs(analytic)
    others = P.copy()
    others[..., 0, 0] = 0.0
    assert np.max(np.abs(others)) <= 1e-8 * abs(analytic)
    # and the deformation is the homogeneous isochoric one: lateral stretch λ^(-1/2)
    u = problem.w.sub(0).collapse()
    x = problem.V.tabulate_dof_coordinates()
    expected = x * np.array([stretch - 1.0, stretch**-0.5 - 1.0, stretch**-0.5 - 1.0])
    assert np.allclose(u.x.array.reshape(-1, 3), expected, rtol=0, atol=1e-10)
    solver.destroy()


# -- mirror symmetry ------------------------------------------------------------------------------
def mirrored_block(length: float = 0.1, half_width: float = 0.05, height: float = 0.06, n: int = 3):
    """A block x ∈ [0, L], y ∈ [-W, W], z ∈ [0, H] whose tetrahedra are mirror images in y = 0.

    The half y ≥ 0 is meshed and reflected, so that the *discrete* problem is symmetric
    and a symmetric solution is expected to solver tolerance, not just to
    discretisation error. Facets on x = 0 are tagged as the rib (clamped).
    """
    half = dmesh.create_box(
        MPI.COMM_SELF,
        [np.zeros(3), np.array([length, half_width, height])],
        [n, n, n],
        dmesh.CellType.tetrahedron,
    )
    x = half.geometry.x
    cells = half.geometry.dofmap.array.reshape(-1, 4).astype(np.int64)
    mirror = x * np.array([1.0, -1.0, 1.0])
    on_plane = np.isclose(x[:, 1], 0.0)
    index = np.arange(len(x)) + len(x)
    index[on_plane] = np.flatnonzero(on_plane)  # nodes on y = 0 are shared
    mirrored_cells = index[cells][:, [1, 0, 2, 3]]  # swap two vertices: keep orientation
    points = np.vstack([x, mirror])
    cells_all = np.vstack([cells, mirrored_cells])
    # drop unused duplicate nodes and renumber
    used, inverse = np.unique(cells_all, return_inverse=True)
    domain = ufl.Mesh(ufl.VectorElement("Lagrange", "tetrahedron", 1))
    if MPI.COMM_WORLD.rank == 0:
        mesh = dmesh.create_mesh(MPI.COMM_WORLD, inverse.reshape(-1, 4), points[used], domain)
    else:
        mesh = dmesh.create_mesh(
            MPI.COMM_WORLD, np.empty((0, 4), np.int64), np.empty((0, 3)), domain
        )
    fdim = 2
    mesh.topology.create_connectivity(fdim, 3)
    facets = dmesh.locate_entities_boundary(mesh, fdim, lambda p: np.isclose(p[0], 0.0))
    tags = dmesh.meshtags(
        mesh, fdim, np.sort(facets), np.full(len(facets), int(Boundary.RIB), np.int32)
    )
    return mesh, tags


def test_mirror_symmetric_body_deforms_symmetrically() -> None:
    from fem.loading import solve_incrementally

    mesh, tags = mirrored_block()
    problem = GravityProblem(mesh, tags, Discretisation(), FixedBoundaries())
    solver = NewtonSolver(problem, TIGHT)
    # gravity in the symmetry plane y = 0: θ = 90° puts g in the x-z plane
    problem.set_case(Material(C1=400.0), Gravity(phi=120.0, theta=90.0))
    result = solve_incrementally(problem, solver, Loading())
    assert result.converged, result.reason
    u = problem.displacement()
    values = u.x.array.reshape(-1, 3)
    x = problem.V.tabulate_dof_coordinates()
    scale = np.abs(values).max()
    assert scale > 5e-3  # a large deformation, not a trivially small one
    # pair every dof node with its mirror image (x, -y, z)
    from scipy.spatial import cKDTree

    distance, mirror = cKDTree(x).query(x * np.array([1.0, -1.0, 1.0]))
    assert np.all(distance < 1e-12)
    reflected = values[mirror] * np.array([1.0, -1.0, 1.0])
    assert np.max(np.abs(values - reflected)) <= 1e-9 * scale
    # and the symmetry is not imposed trivially: the body moves out of plane nowhere
    # but it does move along y off the plane (Poisson-like bulging)
    assert np.abs(values[:, 1]).max() > 1e-3 * scale
    solver.destroy()


# -- scaling, zero load, volume ------------------------------------------------------------------
@pytest.fixture(scope="module")
def coarse_problem(coarse_mesh: Path):
    from meshes.io import read_mesh

    msh, _, facet_tags = read_mesh(coarse_mesh)
    problem = GravityProblem(msh, facet_tags)
    solver = NewtonSolver(problem, TIGHT)
    yield problem, solver
    solver.destroy()


def _solve(problem: GravityProblem, solver: NewtonSolver, material: Material, gravity: Gravity):
    from fem.loading import solve_incrementally

    problem.set_case(material, gravity)
    problem.w.x.array[:] = 0.0
    result = solve_incrementally(problem, solver, Loading())
    assert result.converged, result.reason
    return problem.displacement().x.array.reshape(-1, 3).copy(), result


def test_solution_depends_on_density_times_gravity_over_C1_only(coarse_problem) -> None:
    problem, solver = coarse_problem
    u1, _ = _solve(problem, solver, Material(C1=1000.0), Gravity(phi=150.0))
    u2, _ = _solve(problem, solver, Material(C1=2500.0), Gravity(phi=150.0, magnitude=2.5 * 9.81))
    assert np.abs(u1).max() > 5e-3
    assert np.max(np.abs(u1 - u2)) <= 1e-9 * np.abs(u1).max()


def test_tiny_load_scales_linearly_with_compliance(coarse_problem) -> None:
    problem, solver = coarse_problem
    tiny = 1e-4 * 9.81
    soft, _ = _solve(problem, solver, Material(C1=1000.0), Gravity(phi=30.0, magnitude=tiny))
    stiff, _ = _solve(problem, solver, Material(C1=2000.0), Gravity(phi=30.0, magnitude=tiny))
    # u ∝ 1/C1 to first order; the nonlinearity enters at relative order |∇u| ~ 1e-4
    assert np.max(np.abs(soft - 2.0 * stiff)) <= 1e-3 * np.abs(soft).max()
    # while at full gravity the response is visibly nonlinear
    soft_full, _ = _solve(problem, solver, Material(C1=1000.0), Gravity(phi=30.0))
    stiff_full, _ = _solve(problem, solver, Material(C1=2000.0), Gravity(phi=30.0))
    assert np.max(np.abs(soft_full - 2.0 * stiff_full)) > 1e-2 * np.abs(soft_full).max()


def test_zero_gravity_gives_exactly_zero(coarse_problem) -> None:
    problem, solver = coarse_problem
    u, result = _solve(problem, solver, Material(C1=1000.0), Gravity(phi=0.0, magnitude=0.0))
    assert np.all(u == 0.0)
    assert result.newton_iterations == [0]


def test_volume_is_conserved_to_solver_tolerance(coarse_problem) -> None:
    problem, solver = coarse_problem
    _, result = _solve(problem, solver, Material(C1=1000.0), Gravity(phi=0.0))
    # Σ_i of the pressure rows of the residual is -∫(J - 1) dX (P1 is a partition of
    # unity), so |∫(J - 1) dX| <= sqrt(#pressure dofs) * ||residual||.
    n_p = problem.W.sub(1).collapse()[0].dofmap.index_map.size_global
    bound = np.sqrt(n_p) * result.accepted[-1].final_residual
    change = abs(problem.volume_change()) * problem.volume
    assert change <= bound + 1e-16
    assert abs(problem.volume_change()) < 1e-10
    # the deformation is large, so this is not trivially satisfied
    assert problem.min_detF() < 0.99


# -- self-overlap of the deformed body -------------------------------------------------------------
def test_self_overlap_finds_a_fold_not_a_rigid_motion_or_a_solution(coarse_problem) -> None:
    from fem.overlap import self_overlap

    problem, solver = coarse_problem
    msh = problem.mesh
    x0 = msh.geometry.x.copy()
    V = fem.VectorFunctionSpace(msh, ("Lagrange", 2))
    u = fem.Function(V)
    untouched = self_overlap(msh, u)
    assert untouched["overlapping_vertices"] == 0 and untouched["boundary_vertices"] > 100
    u.interpolate(lambda x: np.vstack([0.05 + 0 * x[0], 0.02 + 0 * x[1], -0.01 + 0 * x[2]]))
    assert self_overlap(msh, u)["overlapping_vertices"] == 0  # a translation
    # fold the body about a plane: the part x < c is mirrored onto the part x > c
    c = 0.5 * (x0[:, 0].min() + x0[:, 0].max())
    u.interpolate(lambda x: np.vstack([2 * np.maximum(c - x[0], 0.0), 0 * x[1], 0 * x[2]]))
    folded = self_overlap(msh, u)
    assert folded["overlapping_vertices"] > 0.1 * folded["boundary_vertices"]
    # reported where they start from: points of the undeformed mesh
    assert all(np.linalg.norm(x0 - p, axis=1).min() < 1e-12 for p in folded["examples_m"])
    assert np.array_equal(msh.geometry.x, x0)  # the mesh is restored
    # a converged prone case on this coarse mesh does not overlap itself
    _solve(problem, solver, Material(C1=1000.0), Gravity(phi=180.0))
    assert self_overlap(msh, problem.displacement())["overlapping_vertices"] == 0


@pytest.mark.parametrize("bulge", [0.2, -0.2], ids=["bulging", "hollow"])
def test_self_overlap_tests_a_curved_cell_by_its_own_map(bulge: float) -> None:
    """A vertex near a curved cell's face: inside the cell exactly when its map bulges there.

    Cell A, curved: its edge node between corners 1 and 2 moved off the face x + y + z = 1 by
    ``bulge`` along (1, 1, 0). Cell B, apart, has a vertex just outside that face (bulging: the
    cell holds it, its straight tetrahedron does not) or just inside (hollow: the reverse).
    """
    from fem.overlap import self_overlap

    corners = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]])
    # dolfinx's order of a 10-node tetrahedron: the corners, then the edges (2,3), (1,3),
    # (1,2), (0,3), (0,2), (0,1)
    edges = [(2, 3), (1, 3), (1, 2), (0, 3), (0, 2), (0, 1)]
    mid = [(corners[a] + corners[b]) / 2 for a, b in edges]
    mid[2] = mid[2] + bulge * np.array([1.0, 1.0, 0.0]) / np.sqrt(2)
    side = 0.04 if bulge > 0 else -0.04  # the vertex beyond (or before) the straight face
    p = np.array([0.5, 0.5, 0.02]) + side * np.array([1.0, 1.0, 0.0])
    other = np.array([p, p + [0.3, 0.0, 0.0], p + [0.0, 0.3, 0.0], p + [0.0, 0.0, 0.3]])
    other_mid = [(other[a] + other[b]) / 2 for a, b in edges]
    x = np.vstack([corners, mid, other, other_mid])
    cells = np.array([np.arange(10), 10 + np.arange(10)], dtype=np.int64)
    domain = ufl.Mesh(ufl.VectorElement("Lagrange", "tetrahedron", 2))
    msh = dmesh.create_mesh(MPI.COMM_WORLD, cells, x, domain)
    u = fem.Function(fem.VectorFunctionSpace(msh, ("Lagrange", 2)))
    straight = np.linalg.solve((corners[1:] - corners[0]).T, p - corners[0])
    assert (straight.min() > 0 and straight.sum() < 1) == (bulge < 0)  # the straight test's say
    assert self_overlap(msh, u)["overlapping_vertices"] == (1 if bulge > 0 else 0)
