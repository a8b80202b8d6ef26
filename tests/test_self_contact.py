"""Self-contact of the skin (fem.self_contact, fem.point_triangle).

* the point–triangle kernel's gradient and Hessian are those of its signed distance
  (central differences);
* two blocks of one mesh, the upper one held only sideways, stand on each other (P2/P1,
  P1-penalty and P3/P2): the contact carries the upper block's whole weight (its
  equilibrium, to the solver's tolerance) and the skin stays apart by no more than the offset;
* a C-shaped block whose upper arm falls onto the lower one under gravity: without
  self-contact it passes through itself; with it, it converges with no boundary vertex
  inside another cell;
* where nothing touches (the breast prone), self-contact changes nothing;
* a curved (quadratic) skin's facets split into the same triangles as a straight one's;
* bad settings are refused by name.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
import ufl
from dolfinx import mesh as dmesh
from mpi4py import MPI

from fem.exceptions import InvalidParameterError
from fem.loading import solve_incrementally
from fem.overlap import self_overlap
from fem.parameters import (
    TISSUE_DENSITY,
    Discretisation,
    FixedBoundaries,
    Gravity,
    Loading,
    Material,
    SolverSettings,
)
from fem.point_triangle import barycentric, signed_distance, signed_distance_derivatives
from fem.problem import GravityProblem
from fem.self_contact import SelfContact, SelfContactAssembler, self_contact_from_mapping
from fem.solver import NewtonSolver
from meshes.io import geometry_nodes
from meshes.tags import Boundary

TIGHT = {"snes_rtol": 1e-12, "snes_atol": 1e-11, "load_atol": 0.0}


def _split(q: np.ndarray) -> tuple[np.ndarray, ...]:
    return q[:, 0:3], q[:, 3:6], q[:, 6:9], q[:, 9:12]


@pytest.mark.unit
def test_the_kernel_derivatives_are_those_of_the_signed_distance() -> None:
    rng = np.random.default_rng(3)
    q = rng.normal(size=(20, 12))
    g, grad, hess = signed_distance_derivatives(*_split(q))
    assert g == pytest.approx(signed_distance(*_split(q)), abs=1e-14)
    h, eye = 1e-6, np.eye(12)
    numeric = np.stack([
        (signed_distance(*_split(q + h * eye[k])) - signed_distance(*_split(q - h * eye[k])))
        / (2 * h) for k in range(12)
    ], axis=1)
    assert np.abs(grad - numeric).max() < 1e-8
    numeric_hess = np.stack([
        (signed_distance_derivatives(*_split(q + h * eye[k]))[1]
         - signed_distance_derivatives(*_split(q - h * eye[k]))[1]) / (2 * h)
        for k in range(12)
    ], axis=2)
    assert np.abs(hess - numeric_hess).max() < 1e-7 * np.abs(hess).max()
    assert np.array_equal(hess, np.transpose(hess, (0, 2, 1)))


@pytest.mark.unit
def test_the_kernel_on_a_unit_triangle() -> None:
    tri = [np.array([[0.0, 0.0, 0.0]]), np.array([[1.0, 0.0, 0.0]]), np.array([[0.0, 1.0, 0.0]])]
    point = np.array([[0.25, 0.25, -0.1]])
    assert signed_distance(point, *tri) == pytest.approx([-0.1])  # behind the +z normal
    assert barycentric(point, *tri)[0] == pytest.approx([0.5, 0.25, 0.25])


@pytest.mark.unit
@pytest.mark.parametrize(
    ("values", "words"),
    [
        ({"stiffnes": 1.0}, "unknown fe.self_contact parameter(s): stiffnes"),
        ({"stiffness": -1.0}, "fe.self_contact.stiffness"),
        ({"band": float("nan")}, "fe.self_contact.band"),
        ({"facing": 2.0}, "fe.self_contact.facing"),
        ({"offset": "a"}, "must be numbers"),
        ({"offset": -0.001}, "fe.self_contact.offset must be a number in [0, 0.01]"),
        ([1, 2], "must be a mapping"),
        ({"at_rest": "ignore"}, "fe.self_contact.at_rest must be one of by_side, exclude, "
                                "rest_gap, none, got 'ignore'"),
        ({"at_rest": 1}, "fe.self_contact.at_rest must be one of"),
    ],
)
def test_bad_self_contact_settings_are_refused_by_name(values: object, words: str) -> None:
    with pytest.raises(InvalidParameterError, match=re.escape(words)):
        self_contact_from_mapping(values)  # type: ignore[arg-type]


@pytest.mark.unit
def test_the_config_turns_self_contact_on_and_records_it() -> None:
    on = SolverSettings.from_config({"fe": {"self_contact": {"offset": 0.001}}})
    assert on.self_contact == SelfContact(offset=0.001)
    assert on.describe()["self_contact"]["offset"] == 0.001
    assert SolverSettings.from_config({"fe": {"self_contact": {"offset": 0}}}).self_contact \
        == SelfContact(offset=0.0)  # contact at touching
    for fe in ({}, {"self_contact": None}):
        assert SolverSettings.from_config({"fe": fe}).self_contact is None


def _mesh_of(cells: np.ndarray, x: np.ndarray, tag: dict[int, object]) -> tuple:
    """A serial mesh of straight tetrahedra with its exterior facets tagged.

    Skin, except where a ``tag`` value's predicate (of the facet's midpoint) holds.
    """
    used, cells = np.unique(cells, return_inverse=True)
    domain = ufl.Mesh(ufl.VectorElement("Lagrange", "tetrahedron", 1))
    mesh = dmesh.create_mesh(MPI.COMM_WORLD, cells.reshape(-1, 4).astype(np.int64), x[used],
                             domain)
    mesh.topology.create_connectivity(2, 3)
    exterior = dmesh.exterior_facet_indices(mesh.topology)
    values = np.full(len(exterior), int(Boundary.SKIN), dtype=np.int32)
    for value, where in tag.items():
        values[np.isin(exterior, dmesh.locate_entities_boundary(mesh, 2, where))] = value
    return mesh, dmesh.meshtags(mesh, 2, exterior, values)


def _box(side: float, n: int) -> tuple[np.ndarray, np.ndarray]:
    box = dmesh.create_box(MPI.COMM_SELF, [np.zeros(3), np.full(3, side)], [n, n, n],
                           dmesh.CellType.tetrahedron)
    return geometry_nodes(box).astype(np.int64), box.geometry.x.copy()


def stacked_blocks(side: float, n: int = 3) -> tuple:
    """Two cubes of one mesh touching along x = side, not sharing nodes (n and n + 1 cells).

    Gravity along +x presses the upper (x < side) on the lower; the lower's far face is the
    rib, the upper's far face (sternal) is held in y and z only.
    """
    upper, xu = _box(side, n)
    lower, xl = _box(side, n + 1)
    x = np.vstack([xu, xl + [side, 0.0, 0.0]])
    cells = np.vstack([upper, lower + len(xu)])
    return _mesh_of(cells, x, {
        int(Boundary.STERNAL): lambda p: np.isclose(p[0], 0.0),
        int(Boundary.RIB): lambda p: np.isclose(p[0], 2 * side),
    })


def c_block(side: float, n: int) -> tuple:
    """A cube of n cells a side with a slot one cell wide (x from 2h to 3h, above z = 2h).

    An upper arm (x < 2h, one cell shorter than the lower) on a spine (z < 2h) over the
    lower arm, whose far face x = side is the rib. Gravity along +x closes the slot.
    """
    cells, x = _box(side, n)
    h = side / n
    c = x[cells].mean(axis=1)
    slot = (c[:, 0] > 2 * h) & (c[:, 0] < 3 * h) & (c[:, 2] > 2 * h)
    short = (c[:, 0] < 2 * h) & (c[:, 2] > side - h)
    return _mesh_of(cells[~(slot | short)], x,
                    {int(Boundary.RIB): lambda p: np.isclose(p[0], side)})


@pytest.mark.solve
@pytest.mark.parametrize(
    "discretisation",
    [Discretisation(), Discretisation(element="p1-penalty", degree=1), Discretisation(degree=3)],
    ids=["P2-P1", "P1-penalty", "P3-P2"],
)
def test_stacked_blocks_carry_the_upper_weight_by_self_contact(
    discretisation: Discretisation,
) -> None:
    """Every element's skin is triangulated through all its nodes (k² triangles a facet).

    The blocks touch at rest, pressed together from the start (``at_rest: none``): the upper
    one, held only sideways, has nothing else to stand on.
    """
    side, C1 = 0.05, 1000.0
    mesh, tags = stacked_blocks(side, 1 if discretisation.degree == 3 else 3)
    settings = SelfContact(at_rest="none")
    problem = GravityProblem(mesh, tags, discretisation,
                             FixedBoundaries({"rib": (0, 1, 2), "sternal": (1, 2)}), None, settings)
    solver = NewtonSolver(problem, TIGHT)
    problem.set_case(Material(C1=C1), Gravity(phi=0.0))
    result = solve_incrementally(problem, solver, Loading())
    assert result.converged, result.reason

    # The upper block's equilibrium in x: its weight against the contact forces on its nodes
    # (the held face takes no x force), which the residual's contact part holds.
    b = np.zeros_like(problem.w.x.array)
    problem.add_self_contact_residual(b)
    surface = problem.self_contact.surface
    # the upper block's nodes: behind its contact face (x < side), or on it (normal +x)
    tri = surface.triangles
    normal = np.cross(surface.X[tri[:, 1]] - surface.X[tri[:, 0]],
                      surface.X[tri[:, 2]] - surface.X[tri[:, 0]])
    on_face = np.zeros(len(surface.X))
    np.add.at(on_face, tri.ravel(), np.repeat(normal[:, 0], 3))
    upper = (surface.X[:, 0] < side - 1e-9) | (on_face > 0)
    weight = TISSUE_DENSITY * 9.81 * side**3
    contact_force_x = -b[surface.dofs[upper, 0]].sum()  # the residual holds −force
    assert contact_force_x == pytest.approx(-weight, rel=1e-8)

    status = problem.self_contact_status()
    # the pairs press along x: their summed force is the weight, to the tilt of the bulge
    assert status["force_N"] == pytest.approx(weight, rel=2e-3)
    assert status["area_cm2"] > 0.5 * 1e4 * side**2
    # the pressure (about the weight over the area, ~441 Pa) stays below κ · offset: no
    # penetration, and the gap it leaves is at most the offset
    assert status["max_pressure_Pa"] < settings.stiffness * C1 * settings.offset
    assert status["max_penetration_mm"] == 0.0
    u = problem.displacement()
    assert self_overlap(mesh, u)["overlapping_vertices"] == 0
    solver.destroy()


@pytest.mark.solve
def test_a_closing_crease_converges_without_passing_through_itself() -> None:
    side, C1 = 0.05, 500.0
    outcomes = {}
    for name, settings in (("free", None), ("self-contact", SelfContact())):
        mesh, tags = c_block(side, 4)
        problem = GravityProblem(mesh, tags, Discretisation(), FixedBoundaries(), None, settings)
        solver = NewtonSolver(problem)
        problem.set_case(Material(C1=C1), Gravity(phi=0.0))
        result = solve_incrementally(problem, solver, Loading())
        u = problem.displacement()
        outcomes[name] = (result.converged, self_overlap(mesh, u)["overlapping_vertices"],
                          problem.self_contact_status())
        if settings is not None:
            # the kept candidate list missed no pair: a fresh search finds the same ones
            kept = problem.self_contact.pairs(problem.w.x.array)
            fresh = SelfContactAssembler(settings, problem.self_contact.surface)
            found = fresh.pairs(problem.w.x.array)
            assert fresh.searches == 1 and len(kept.slaves) > 0
            pairs = [sorted(zip(p.slaves, p.masters, strict=True)) for p in (kept, found)]
            assert pairs[0] == pairs[1]
        solver.destroy()
    # without self-contact the upper arm swings into the lower one (where its solve stops)
    assert outcomes["free"][1] > 5
    converged, overlapping, status = outcomes["self-contact"]
    assert converged and overlapping == 0
    assert status["force_N"] > 0 and status["max_penetration_mm"] == 0.0


@pytest.mark.solve
def test_self_contact_changes_nothing_where_nothing_touches(coarse_mesh: Path,
                                                             tmp_path: Path) -> None:
    """Prone, the breast hangs away from the chest: the same solution with self-contact."""
    import h5py

    from fem.case import run_case
    from fem.sweep import Case

    case = Case(2.0, 180.0)
    summaries = {
        name: run_case(coarse_mesh, case, tmp_path / name,
                       SolverSettings(petsc_options=TIGHT, self_contact=sc))
        for name, sc in (("on", SelfContact()), ("off", None))
    }
    assert summaries["on"]["status"] == summaries["off"]["status"] == "converged"
    status = summaries["on"]["self_contact"]
    assert status["pairs"] == 0 and status["force_N"] == 0 and status["skin_nodes"] > 500
    assert summaries["off"]["self_contact"] is None
    assert summaries["on"]["settings"]["self_contact"] == SelfContact().as_mapping()
    u = {name: h5py.File(tmp_path / name / "points.h5")["u"][...] for name in summaries}
    assert np.abs(u["off"]).max() > 5e-3
    assert np.max(np.abs(u["on"] - u["off"])) <= 1e-9 * np.abs(u["off"]).max()


def _crossings(segments: np.ndarray) -> int:
    """Pairs of 2D segments that cross at a point inside both (sharing no end)."""
    a, b = segments[:, 0], segments[:, 1]
    d = b - a

    def cross(u: np.ndarray, v: np.ndarray) -> np.ndarray:
        return u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]

    denom = cross(d[:, None], d[None, :])
    ab = a[None, :] - a[:, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        s = cross(ab, d[None, :]) / denom
        t = cross(ab, d[:, None]) / denom
    inside = (s > 1e-6) & (s < 1 - 1e-6) & (t > 1e-6) & (t < 1 - 1e-6) & (np.abs(denom) > 0)
    return int(np.triu(inside, 1).sum())


@pytest.mark.unit
def test_the_fold_section_cuts_the_boundary_where_each_state_moves_it() -> None:
    from studies.fe_study.fold_section import boundary_triangles, section_segments

    box = dmesh.create_box(MPI.COMM_SELF, [np.zeros(3), np.ones(3)], [3, 3, 3],
                           dmesh.CellType.tetrahedron)
    X, tri = box.geometry.x, boundary_triangles(box)
    cut = section_segments(X, np.zeros_like(X), tri, 0.5)
    # the plane y = 0.5 cuts the cube's boundary in the square's perimeter, 4 long
    assert np.allclose(cut[:, :, 1], 0.5)
    assert np.linalg.norm(cut[:, 1] - cut[:, 0], axis=1).sum() == pytest.approx(4.0)
    on_edge = np.isclose(cut[:, :, [0, 2]], 0.0) | np.isclose(cut[:, :, [0, 2]], 1.0)
    assert on_edge.any(axis=2).all()
    # a material cut: the same points, carried by a shear x += z
    shear = np.column_stack([X[:, 2], np.zeros(len(X)), np.zeros(len(X))])
    moved = section_segments(X, shear, tri, 0.5)
    assert np.allclose(moved[..., 0], cut[..., 0] + cut[..., 2])
    assert _crossings(cut[:, :, [0, 2]]) == 0
    # a transverse cut, z = 0.25: the same square's perimeter, at that height
    across = section_segments(X, np.zeros_like(X), tri, 0.25, "z")
    assert np.allclose(across[:, :, 2], 0.25)
    assert np.linalg.norm(across[:, 1] - across[:, 0], axis=1).sum() == pytest.approx(4.0)


@pytest.mark.unit
def test_the_fold_is_cut_in_the_plane_the_mound_rolls_in() -> None:
    """Lying on the side: a transverse cut; gravity towards the feet or supine: sagittal."""
    from fem.sweep import Case
    from studies.fe_study.fold_section import cut_axis

    def axis(phi: float, theta: float = 0.0) -> str:
        return cut_axis(Case(0.8, phi, theta).gravity().vector)

    assert axis(-90.0) == axis(-120.0) == axis(35.0) == "z"  # in the plane θ = 0: sideways
    assert axis(58.4, -97.8) == "y"  # mostly towards the feet
    assert axis(0.0) == axis(180.0) == "y"  # no sideways component: the sagittal cut


@pytest.mark.unit
def test_the_fold_section_takes_the_named_cases_then_the_largest_forces() -> None:
    from fem.sweep import Case
    from studies.fe_study.fold_section import choose_cases

    columns = {"C1": np.array([1.0, 0.8, 0.8, 1.2]), "phi": np.array([0.0, -90.0, -75.0, 0.0]),
               "theta": np.zeros(4), "converged": np.array([True, True, False, True]),
               "self_contact_force_N": np.array([0.0, 0.3, 0.9, 0.1])}
    named = [Case(0.8, -90.0)]
    # the failed case's force does not count; the named one is not taken twice
    assert choose_cases(columns, named, 2) == [Case(0.8, -90.0), Case(1.2, 0.0)]
    assert choose_cases(columns, [], 1) == [Case(0.8, -90.0)]
    assert choose_cases({k: v for k, v in columns.items() if k != "self_contact_force_N"},
                        named, 3) == named


@pytest.mark.solve
def test_the_fold_section_shows_the_crease_crossing_itself_only_without_self_contact(
    tmp_path: Path,
) -> None:
    from fem.sweep import Case
    from meshes.io import write_tagged_mesh
    from studies.fe_study.fold_section import FoldSections, fold_sections
    from studies.figures.fe import plot_fold_section

    mesh, facets = c_block(0.05, 4)
    cells = dmesh.meshtags(mesh, 3, np.arange(mesh.topology.index_map(3).size_local,
                                              dtype=np.int32),
                           np.ones(mesh.topology.index_map(3).size_local, dtype=np.int32))
    write_tagged_mesh(mesh, cells, facets, tmp_path / "c.xdmf")
    result = fold_sections(tmp_path / "c.xdmf", SolverSettings(), [Case(0.5, 0.0)])
    result.write(tmp_path / "fold.json")
    (case,) = FoldSections.read(tmp_path / "fold.json").cases
    states = {s.setting: s for s in case.states}
    assert states["self-contact"].status == "converged"
    assert states["self-contact"].self_overlap == 0 and states["none"].self_overlap > 5
    assert states["self-contact"].self_contact_force_N > 0
    # the slot's faces cross each other in the cut without self-contact, never with it
    assert _crossings(np.asarray(states["none"].segments_mm)) > 0
    assert _crossings(np.asarray(states["self-contact"].segments_mm)) == 0
    assert _crossings(np.asarray(case.reference_mm)) == 0
    plot_fold_section([case.to_json()], tmp_path / "fold.png")
    assert (tmp_path / "fold.png").stat().st_size > 10_000


@pytest.mark.solve
def test_the_inertia_is_counted_when_the_contact_adds_entries_to_the_tangent() -> None:
    """Counted open (no pair), then closed: PETSc factorises the grown pattern anew."""
    from fem.stability import tangent_inertia

    mesh, tags = c_block(0.05, 4)
    problem = GravityProblem(mesh, tags, Discretisation(), FixedBoundaries(), None,
                             SelfContact())
    solver = NewtonSolver(problem)
    problem.set_case(Material(C1=500.0), Gravity(phi=0.0))
    apart = tangent_inertia(problem)
    assert problem.self_contact_status()["pairs"] == 0 and apart.stable
    assert solve_incrementally(problem, solver, Loading()).converged
    assert problem.self_contact_status()["pairs"] > 0
    touching = tangent_inertia(problem)
    assert touching.stable and touching.pressure_dofs == apart.pressure_dofs
    solver.destroy()


def _quadratic_box(shift: float) -> tuple:
    """A cube of 2 cells a side as 10-node (quadratic) tetrahedra, its skin tagged.

    Each edge node sits at the edge's midpoint, moved along the edge by ``shift`` times its
    length where the edge lies on the cube's faces: a strongly curved skin's nodes.
    """
    cells, x = _box(1.0, 2)
    pairs = ((2, 3), (1, 3), (1, 2), (0, 3), (0, 2), (0, 1))  # the reference edges' order
    edges = np.sort(cells[:, pairs].reshape(-1, 2), axis=1)
    unique, which = np.unique(edges, axis=0, return_inverse=True)
    a, b = x[unique[:, 0]], x[unique[:, 1]]
    on_face = np.any(np.isclose(a, 0.0) & np.isclose(b, 0.0)
                     | np.isclose(a, 1.0) & np.isclose(b, 1.0), axis=1)
    mid = 0.5 * (a + b) + shift * on_face[:, None] * (b - a)
    nodes = np.vstack([x, mid])
    cells10 = np.hstack([cells, len(x) + which.reshape(-1, 6)])
    domain = ufl.Mesh(ufl.VectorElement("Lagrange", "tetrahedron", 2))
    mesh = dmesh.create_mesh(MPI.COMM_SELF, cells10, nodes, domain)
    mesh.topology.create_connectivity(2, 3)
    exterior = dmesh.exterior_facet_indices(mesh.topology)
    return mesh, exterior


def test_a_curved_skins_facets_are_split_by_the_elements_numbering() -> None:
    """A tight fold's curved facets split into the straight mesh's four triangles each.

    On a quadratic mesh whose skin nodes lie far from their edges' midpoints, the triangles are
    found by the element's numbering, not by where the nodes sit (which failed: "do not form a
    degree-2 lattice", the corpus's small anatomy).
    """
    from dolfinx import fem as dfem

    from fem.skin_surface import SkinSurface

    surfaces, coords = [], []
    for shift in (0.0, 0.3):
        mesh, facets = _quadratic_box(shift)
        V = dfem.VectorFunctionSpace(mesh, ("Lagrange", 2))
        surfaces.append(SkinSurface.from_problem(V, False, mesh, facets))
        coords.append(V.tabulate_dof_coordinates())
    straight, curved = surfaces
    assert len(straight.triangles) == 4 * 8 * 6  # 8 facets a face, each of 4 triangles
    assert np.array_equal(straight.triangles, curved.triangles)
    assert np.array_equal(straight.dofs, curved.dofs)
    moved = np.linalg.norm(curved.X - straight.X, axis=1) > 1e-9
    assert moved.any() and not moved.all()  # the edge nodes moved, the corners did not
    # on the straight mesh the lattice is the facets' own: total area that of the cube
    tri = straight.X[straight.triangles]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    assert np.isclose(area.sum(), 6.0)
