"""Penalty contact of the skin with a rigid obstacle (fem.contact).

* a block resting on a plane under its own weight: the contact force equals the weight
  (global equilibrium, exact to solver tolerance) and the penetration is the penalty's;
* where nothing touches, contact changes nothing; configured through the workflow's
  mapping, a case records its contact state;
* bad contact settings are refused by name.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import ufl
from dolfinx import fem
from dolfinx import mesh as dmesh
from mpi4py import MPI

from fem.contact import (
    Contact,
    EllipticCylinder,
    Plane,
    chest_obstacle,
    contact_from_mapping,
    resolve_obstacle,
)
from fem.exceptions import InvalidParameterError
from fem.loading import solve_incrementally
from fem.parameters import (
    TISSUE_DENSITY,
    Discretisation,
    FixedBoundaries,
    Gravity,
    Loading,
    Material,
    SolverSettings,
)
from fem.problem import GravityProblem
from fem.solver import NewtonSolver
from meshes.parametric import BreastGeometry
from meshes.tags import Boundary

pytestmark = pytest.mark.solve

TIGHT = {"snes_rtol": 1e-12, "snes_atol": 1e-11, "load_atol": 0.0}


def standing_block(side: float, n: int):
    """A cube [-side, 0] x [0, side]^2 with its top (x = -side) tagged rib, its base skin."""
    mesh = dmesh.create_box(
        MPI.COMM_WORLD,
        [np.array([-side, 0, 0]), np.array([0, side, side])],
        [n, n, n],
        dmesh.CellType.tetrahedron,
    )
    fdim = 2
    mesh.topology.create_connectivity(fdim, 3)
    top = dmesh.locate_entities_boundary(mesh, fdim, lambda p: np.isclose(p[0], -side))
    base = dmesh.locate_entities_boundary(mesh, fdim, lambda p: np.isclose(p[0], 0.0))
    facets = np.concatenate([top, base])
    values = np.concatenate(
        [np.full(len(top), int(Boundary.RIB)), np.full(len(base), int(Boundary.SKIN))]
    ).astype(np.int32)
    order = np.argsort(facets)
    return mesh, dmesh.meshtags(mesh, fdim, facets[order], values[order])


def test_a_block_resting_on_a_plane_carries_its_weight_by_contact() -> None:
    side, C1 = 0.05, 1000.0
    mesh, tags = standing_block(side, 3)
    contact = Contact(Plane((0.0, 0.0, 0.0), (-1.0, 0.0, 0.0)), stiffness=1.0e4, clearance=0.0)
    # the top slides freely along x: only the contact can hold the block up
    problem = GravityProblem(
        mesh, tags, Discretisation(), FixedBoundaries({"rib": (1, 2)}), contact
    )
    solver = NewtonSolver(problem, TIGHT)
    problem.set_case(Material(C1=C1), Gravity(phi=0.0))  # g along +x, into the plane
    result = solve_incrementally(problem, solver, Loading())
    assert result.converged, result.reason

    u = problem.displacement()
    x = ufl.SpatialCoordinate(mesh)
    ds = ufl.Measure(
        "ds",
        domain=mesh,
        subdomain_data=tags,
        metadata={"quadrature_degree": problem.discretisation.quadrature},
    )
    force = fem.assemble_scalar(
        fem.form(contact.pressure(x, u, problem.C1) * ds(int(Boundary.SKIN)))
    )
    weight = TISSUE_DENSITY * 9.81 * side**3
    assert force == pytest.approx(weight, rel=1e-8)

    status = problem.contact_status()
    assert status["force_N"] == pytest.approx(weight, rel=1e-8)
    mean_penetration = TISSUE_DENSITY * 9.81 * side / (contact.stiffness * C1)  # weight / (κ A)
    assert status["vertices_in_contact"] == status["vertices"] == 16  # the whole base
    assert mean_penetration < 1e-3 * status["max_penetration_mm"] < 2 * mean_penetration
    # the block sinks by its own compression plus the penalty's slack, no more
    assert np.abs(u.x.array.reshape(-1, 3)[:, 0]).max() < 0.2 * side
    solver.destroy()


def test_contact_changes_nothing_where_nothing_touches(coarse_mesh: Path, tmp_path: Path) -> None:
    """Prone, the breast hangs away from the chest: with or without contact, the same solution."""
    import json

    from fem.case import run_case
    from fem.sweep import Case

    fe = {"contact": {"clearance": 0.002}, "petsc_options": TIGHT}
    with_contact = SolverSettings.from_config({"fe": fe, "mesh": {"geometry": {}}})
    assert with_contact.contact == Contact(chest_obstacle(BreastGeometry()), clearance=0.002)
    without = SolverSettings(petsc_options=TIGHT)
    case = Case(2.0, 180.0)
    summaries = [
        run_case(coarse_mesh, case, tmp_path / name, settings)
        for name, settings in (("contact", with_contact), ("free", without))
    ]
    assert summaries[0]["status"] == summaries[1]["status"] == "converged"
    status = summaries[0]["contact"]
    assert (
        status["vertices"] > 100 and status["vertices_in_contact"] == 0 and status["force_N"] == 0
    )
    assert summaries[1]["contact"] is None
    recorded = json.loads((tmp_path / "contact" / "summary.json").read_text())["settings"][
        "contact"
    ]
    assert recorded["obstacle"]["elliptic_cylinder"]["semi_axes"] == pytest.approx([0.12, 0.17])
    import h5py

    u = [h5py.File(tmp_path / name / "points.h5")["u"][...] for name in ("contact", "free")]
    assert np.abs(u[0]).max() > 5e-3
    assert np.max(np.abs(u[0] - u[1])) <= 1e-9 * np.abs(u[1]).max()


def test_the_chest_obstacle_is_the_outer_surface_of_the_tissue_layer() -> None:
    geometry = BreastGeometry()
    obstacle = chest_obstacle(geometry)
    for psi in (0.0, 30.0, 46.0, 80.0):
        on = geometry.ellipse_point(psi, offset=geometry.layer_thickness)
        normal = geometry.ellipse_normal(psi, offset=geometry.layer_thickness)
        points = np.array(
            [[*on, 0.0], [*(on + 0.003 * normal), 0.01], [*(on - 0.003 * normal), 0.0]]
        )
        # first-order signed distance: exact on the surface, within 2 % of the distance near it
        assert obstacle.gap_values(points) == pytest.approx([0.0, 0.003, -0.003], abs=6e-5)
    rib = geometry.ellipse_point(20.0)
    assert obstacle.gap_values(np.array([[*rib, 0.0]]))[0] < -0.015  # the rib is 2 cm inside


def test_a_chest_obstacle_is_written_out_for_the_solve_jobs_and_absent_contact_is_left_alone() -> (
    None
):
    fe = {"solver": "direct", "loading": {}}
    assert (
        resolve_obstacle(fe, {"geometry": {}}) is fe
    )  # no contact: the jobs' params are unchanged
    resolved = resolve_obstacle({**fe, "contact": {}}, {"geometry": {"layer_thickness": 0.03}})
    obstacle = resolved["contact"]["obstacle"]["elliptic_cylinder"]
    assert obstacle["semi_axes"] == pytest.approx([0.13, 0.18])
    assert contact_from_mapping(resolved["contact"]) == Contact(
        EllipticCylinder((0.1, 0.0), (0.13, 0.18))
    )


@pytest.mark.parametrize(
    "values, geometry, message",
    [
        ({"stiffnes": 1e4}, {}, "unknown fe.contact parameter(s): stiffnes"),
        ({}, None, "an imported mesh (mesh.source: file) needs an explicit obstacle"),
        ({"obstacle": {"plane": {"point": [0, 0, 0], "normal": [0, 0, 0]}}}, None, "non-zero"),
        ({"obstacle": {"plane": {"point": [0, 0, 0]}}}, None, "plane is incomplete"),
        ({"obstacle": "floor"}, {}, "must be 'chest'"),
        ({"stiffness": -1.0}, {}, "contact stiffness must be positive"),
        ({"clearance": float("nan")}, {}, "contact clearance must be >= 0"),
        (
            {"obstacle": {"elliptic_cylinder": {"centre": [0, 0], "semi_axes": [0.1, 0]}}},
            None,
            "semi-axes",
        ),
    ],
)
def test_bad_contact_settings_are_refused_by_name(values, geometry, message) -> None:
    with pytest.raises(
        InvalidParameterError, match=message.replace("(", r"\(").replace(")", r"\)")
    ):
        contact_from_mapping(values, geometry)


def test_the_default_contact_is_off_on_an_imported_mesh() -> None:
    """`contact: {}` names no obstacle: on an import it is off; `chest` by name is refused."""
    settings = SolverSettings.from_config({"fe": {"contact": {}}, "mesh": {"source": "file"}})
    assert settings.contact is None
    with pytest.raises(InvalidParameterError, match="explicit obstacle"):
        SolverSettings.from_config(
            {"fe": {"contact": {"obstacle": "chest"}}, "mesh": {"source": "file"}}
        )


def test_contact_keeps_the_skin_out_of_the_chest(coarse_mesh: Path, tmp_path: Path) -> None:
    """Soft and tilted supine, the mound rolls onto the chest: it passes 2 mm into it freely.

    With a vanishing penalty the contact zone measures how far the free body passes into
    the chest; with the default the penetration is the penalty's slack, and a stiffer
    penalty leaves less of it while the contact force settles.
    """
    from fem.case import run_case
    from fem.sweep import Case

    status = {}
    for stiffness in (1e-3, 1e4, 1e5):
        fe = {"contact": {"stiffness": stiffness}}
        settings = SolverSettings.from_config({"fe": fe, "mesh": {"geometry": {}}})
        summary = run_case(coarse_mesh, Case(0.6, 15.0), tmp_path / f"{stiffness:g}", settings)
        assert summary["status"] == "converged", summary["reason"]
        status[stiffness] = summary["contact"]
    free, default, stiff = status[1e-3], status[1e4], status[1e5]
    assert free["max_penetration_mm"] > 1.5 and free["force_N"] < 1e-5
    assert default["vertices_in_contact"] > 0
    assert default["max_penetration_mm"] < 0.3 * free["max_penetration_mm"]
    assert stiff["max_penetration_mm"] < 0.5 * default["max_penetration_mm"]
    assert stiff["force_N"] == pytest.approx(default["force_N"], rel=0.3)
