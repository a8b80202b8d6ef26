"""Self-contact at rest (fe.self_contact.at_rest): on any mesh, nothing touches unloaded.

* every corpus anatomy, every import test surface and a closed surface with a sharp
  chest-wall rim, remeshed at the config's size: no pair pushes at rest; on the rim surface,
  whose skin faces itself across the thin tissue at the rim, the treatment-free model's pairs
  do (so the check can fail);
* the rim surface's clinical cases converge in as many load steps as without self-contact,
  to the same displacement; the treatment-free model fails them;
* a crease the surface was made with (a C-shaped block whose slot is a cut, its two faces
  touching at rest) closes no further than it is when its pairs are measured from their rest
  gap, and passes through itself when they are left out.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import yaml

from fem.self_contact import SelfContact, SelfContactAssembler
from fem.self_contact_at_rest import rest_pairs_of_mesh
from meshes.config import MeshConfig, make_mesh
from meshes.corpus import ANATOMIES, rim_section, write_anatomy

REPO = Path(__file__).resolve().parent.parent
CONFIG = yaml.safe_load((REPO / "config.yaml").read_text())


def _rim_mesh(folder: Path) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    section = {"source": "file", "file": rim_section(folder / "rim.stl"),
               "size": CONFIG["mesh"]["size"], "fixed": {"rib": "all"}}
    make_mesh(MeshConfig.from_mapping(section), folder / "mesh.xdmf", folder / "quality.json",
              folder / "mesh.png")
    return folder / "mesh.xdmf"


@pytest.fixture(scope="module")
def rim_mesh(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return _rim_mesh(tmp_path_factory.mktemp("rim"))


@pytest.mark.unit
@pytest.mark.parametrize("name", list(ANATOMIES))
def test_no_pair_pushes_at_rest_on_a_corpus_anatomy(tmp_path: Path, name: str) -> None:
    section = write_anatomy(name, tmp_path / "input", CONFIG["mesh"], import_size=0.015)
    make_mesh(MeshConfig.from_mapping(section), tmp_path / "mesh.xdmf",
              tmp_path / "quality.json", tmp_path / "mesh.png")
    record = rest_pairs_of_mesh(tmp_path / "mesh.xdmf", SelfContact()).to_json()
    assert record["pairs_left"] == 0
    untreated = rest_pairs_of_mesh(tmp_path / "mesh.xdmf", SelfContact(at_rest="none")).to_json()
    assert untreated["pairs_left"] == untreated["pairs"] == record["pairs"]


@pytest.mark.unit
def test_a_sharp_chest_wall_rim_faces_itself_at_rest_and_no_pair_pushes(rim_mesh: Path) -> None:
    """Below the rim's wedge the skin faces the skin above it, behind it across the tissue."""
    untreated = rest_pairs_of_mesh(rim_mesh, SelfContact(at_rest="none")).to_json()
    assert untreated["pairs"] > 20 and untreated["behind"] == untreated["pairs"]
    assert untreated["pairs_left"] == untreated["pairs"]  # they push without a treatment
    assert 1.0 < untreated["deepest_mm"] < 10.0
    # the deepest node sits at the rim: far from the midline, near the chest wall
    x, y, z = untreated["deepest_at_m"]
    assert np.hypot(y, z) > 0.05
    for treatment in ("by_side", "exclude", "rest_gap"):
        record = rest_pairs_of_mesh(rim_mesh, SelfContact(at_rest=treatment)).to_json()
        assert record["pairs"] == untreated["pairs"] and record["pairs_left"] == 0, treatment
    off = rest_pairs_of_mesh(rim_mesh, None)
    assert off.self_contact is False and off.found.pairs == untreated["pairs"]
    path = rim_mesh.parent / "self_contact_at_rest.json"
    off.write(path)
    assert type(off).read(path) == off


@pytest.mark.solve
def test_the_rim_surface_solves_its_clinical_cases_as_without_self_contact(
    rim_mesh: Path,
) -> None:
    from fem.case import CaseRunner
    from fem.io import gather_vertex_values
    from fem.parameters import SolverSettings
    from fem.sweep import Case

    cases = [Case(1.0, 180.0), Case(1.0, 0.0)]
    base = SolverSettings.from_config(CONFIG)
    outcome = {}
    for name, sc in (("off", None), ("by_side", SelfContact()),
                     ("none", SelfContact(at_rest="none"))):
        with CaseRunner(rim_mesh, replace(base, self_contact=sc)) as runner:
            for case in cases:
                result, timings = runner.solve(case)
                summary = runner.summary(case, result, timings, measure_unit=False)
                _, u = gather_vertex_values(runner.mesh, runner.problem.displacement())
                outcome[(name, case.id)] = (summary, u)
                if name == "none":
                    break  # one case shows it: each takes its load steps down to the floor
    for case in cases:
        off, u_off = outcome[("off", case.id)]
        on, u_on = outcome[("by_side", case.id)]
        assert off["status"] == on["status"] == "converged"
        assert on["load_steps"] == off["load_steps"]
        assert np.abs(u_on - u_off).max() <= 1e-9 * np.abs(u_off).max()
        assert on["self_contact"]["rest_pairs"] > 20 and on["self_contact"]["pairs"] == 0
    assert outcome[("none", cases[0].id)][0]["status"] != "converged"


def _cracked_block(side: float, n: int) -> tuple:
    """A cube of n cells a side cut along x = 2h above z = 2h: a slot of no width.

    The cut's two faces touch at rest (the nodes on it doubled), as the sides of a crease a
    surface was made with; the far face x = side is the rib. Gravity along −x opens the cut,
    along +x presses its faces together.
    """
    from meshes.tags import Boundary
    from tests.test_self_contact import _box, _mesh_of

    cells, x = _box(side, n)
    h = side / n
    on_cut = np.isclose(x[:, 0], 2 * h) & (x[:, 2] > 2 * h + 1e-9 * h)
    twin = np.full(len(x), -1)
    twin[on_cut] = len(x) + np.arange(on_cut.sum())
    far = x[cells].mean(axis=1)[:, 0] > 2 * h
    cells = cells.copy()
    moved = far[:, None] & on_cut[cells]
    cells[moved] = twin[cells[moved]]
    x = np.vstack([x, x[on_cut]])
    return _mesh_of(cells, x, {int(Boundary.RIB): lambda p: np.isclose(p[0], side)})


@pytest.mark.solve
def test_a_crease_made_with_the_surface_closes_no_further_than_it_is() -> None:
    from fem.loading import solve_incrementally
    from fem.overlap import self_overlap
    from fem.parameters import Discretisation, FixedBoundaries, Gravity, Loading, Material
    from fem.problem import GravityProblem
    from fem.solver import NewtonSolver

    side, C1 = 0.05, 500.0
    outcome = {}
    for treatment in ("by_side", "exclude"):
        mesh, tags = _cracked_block(side, 4)
        problem = GravityProblem(mesh, tags, Discretisation(), FixedBoundaries(), None,
                                 SelfContact(at_rest=treatment))
        rest = problem.self_contact.rest
        assert rest.pairs > 0 and rest.in_front == rest.pairs and rest.pairs_left == 0
        assert rest.closest_gap_mm == pytest.approx(0.0, abs=1e-9)
        solver = NewtonSolver(problem)
        problem.set_case(Material(C1=C1), Gravity(phi=0.0))  # gravity along +x
        result = solve_incrementally(problem, solver, Loading())
        # how far the cut's faces crossed, judged by the pairs measured from their rest gap
        judge = SelfContactAssembler(SelfContact(), problem.self_contact.surface)
        u = problem.displacement()
        outcome[treatment] = (result.converged, self_overlap(mesh, u)["overlapping_vertices"],
                              problem.self_contact_status(),
                              judge.status(problem.w.x.array, C1)["max_penetration_mm"],
                              np.abs(u.x.array).max())
        solver.destroy()
    converged, overlapping, status, crossed_mm, sag = outcome["by_side"]
    kappa = SelfContact().stiffness * C1
    assert converged and status["force_N"] > 0
    # touching at rest, the faces push back from touching: they cross by the penalty's
    # (contact pressure)/κ, a few hundredths of a millimetre
    assert crossed_mm == pytest.approx(status["max_penetration_mm"])
    assert crossed_mm <= 1.001e3 * status["max_pressure_Pa"] / kappa < 0.1
    # left out, nothing holds them: the arm swings deep into the other side (past the band
    # within which a node behind the skin is seen at all)
    converged, overlapping_left_out, status, _, sag_left_out = outcome["exclude"]
    assert status["force_N"] == 0.0
    assert overlapping_left_out > 2 * overlapping and sag_left_out > 2 * sag
