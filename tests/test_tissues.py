"""The breast's tissues as their own materials (fem.materials, meshes.tags.Tissue).

* the ratios are parsed by name and refused by name when bad; a tumour needs its own;
* a column of two tissues hanging under its own weight (fat at the clamp, a tissue four times
  stiffer below it) stretches as the one-dimensional solution of incompressible neo-Hookean
  uniaxial tension says, section by section: P(X) = ρ g (L − X) = 2 C1(X) (λ − λ⁻²);
* a mesh whose cells all have the ratio 1 keeps the homogeneous forms;
* a label volume's fat, gland, skin and tumour labels tag the cells, to the labelled volumes,
  and count in the solve.
"""

from __future__ import annotations

import re
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from scipy.optimize import brentq

from fem.exceptions import InvalidParameterError
from fem.materials import DEFAULT_RATIOS, Tissues, tissues_from_mapping
from fem.parameters import TISSUE_DENSITY, SolverSettings
from meshes.tags import Tissue

TIGHT = {"snes_rtol": 1e-12, "snes_atol": 1e-11, "load_atol": 0.0}


@pytest.mark.unit
def test_the_ratios_are_read_by_name_with_the_defaults_beneath() -> None:
    tissues = tissues_from_mapping({"gland": 3.0, "tumour": 6.0})
    assert tissues.ratio(Tissue.GLAND) == 3.0 and tissues.ratio(Tissue.TUMOUR) == 6.0
    assert tissues.ratio(Tissue.SKIN) == DEFAULT_RATIOS[Tissue.SKIN]
    assert tissues.ratio(Tissue.FAT) == 1.0
    assert tissues.describe() == {"fat": 1.0, "gland": 3.0, "skin": DEFAULT_RATIOS[Tissue.SKIN],
                                  "tumour": 6.0}
    assert np.array_equal(tissues.cell_ratios(np.array([1, 2, 4, 2])), [1.0, 3.0, 6.0, 3.0])
    settings = SolverSettings.from_config({"material": {"tissues": {"gland": 1.5}}})
    assert settings.tissues.ratio(Tissue.GLAND) == 1.5
    assert settings.describe()["tissues"]["gland"] == 1.5


@pytest.mark.unit
@pytest.mark.parametrize(
    ("values", "words"),
    [
        ({"glandular": 2.0}, "material.tissues: unknown tissue 'glandular'; expected one of: fat, "
                             "gland, skin, tumour"),
        ({"gland": -1.0}, "material.tissues.gland must be a positive number"),
        ({"gland": float("nan")}, "material.tissues.gland must be a positive number"),
        ({"gland": "2"}, "material.tissues.gland must be a positive number, got '2'"),
        ({"fat": 2.0}, "material.tissues.fat is 1 by definition"),
        ([2.0], "material.tissues must be a mapping"),
    ],
)
def test_bad_ratios_are_refused_by_name(values: object, words: str) -> None:
    with pytest.raises(InvalidParameterError, match=re.escape(words)):
        tissues_from_mapping(values)  # type: ignore[arg-type]


@pytest.mark.unit
def test_a_tumour_without_a_ratio_and_an_unknown_tag_are_named() -> None:
    with pytest.raises(InvalidParameterError, match=r"the mesh has tumour cells: give "
                                                    r"material.tissues.tumour"):
        Tissues().cell_ratios(np.array([1, 4]))
    with pytest.raises(InvalidParameterError, match=r"2 cells carry the tag 7, which names no "
                                                    r"tissue; the tissues are 1 \(fat\)"):
        Tissues().cell_ratios(np.array([1, 7, 7]))


def _tag_column(mesh: Any, length: float, end: int | None) -> Any:
    """A column's facet tags: x = 0 the rib, y = 0 and z = 0 symmetry rollers, the rest skin.

    ``end``: the boundary of the far end x = length instead of skin (None: skin).
    """
    from dolfinx import mesh as dmesh

    from meshes.tags import Boundary

    mesh.topology.create_connectivity(2, 3)
    exterior = dmesh.exterior_facet_indices(mesh.topology)
    values = np.full(len(exterior), int(Boundary.SKIN), dtype=np.int32)
    planes = [(int(Boundary.RIB), 0, 0.0), (int(Boundary.STERNAL), 1, 0.0),
              (int(Boundary.CAUDAL), 2, 0.0)] + ([] if end is None else [(end, 0, length)])
    for value, axis, at in planes:
        on = dmesh.locate_entities_boundary(mesh, 2, lambda p, a=axis, c=at: np.isclose(p[a], c))
        values[np.isin(exterior, on)] = value
    return dmesh.meshtags(mesh, 2, exterior, values)


def _column(length: float, width: float, n: int) -> tuple:
    """A column along x, clamped in x at x = 0, on symmetry rollers y = 0 and z = 0."""
    from dolfinx import mesh as dmesh
    from mpi4py import MPI


    mesh = dmesh.create_box(MPI.COMM_WORLD, [np.zeros(3), np.array([length, width, width])],
                            [n, 2, 2], dmesh.CellType.tetrahedron)
    facets = _tag_column(mesh, length, None)
    cells = np.arange(mesh.topology.index_map(3).size_local, dtype=np.int32)
    centre = dmesh.compute_midpoints(mesh, 3, cells)[:, 0]
    tissue = np.where(centre < length / 2, int(Tissue.FAT), int(Tissue.GLAND)).astype(np.int32)
    return mesh, facets, dmesh.meshtags(mesh, 3, cells, tissue)


def _stretch(P: float, C1: float) -> float:
    """λ of incompressible neo-Hookean uniaxial tension at nominal stress P."""
    return brentq(lambda lam: 2 * C1 * (lam - lam**-2) - P, 1.0, 3.0, xtol=1e-14)


@pytest.mark.solve
def test_a_two_tissue_column_hangs_as_the_uniaxial_solution_says() -> None:
    from fem.loading import solve_incrementally
    from fem.parameters import Discretisation, FixedBoundaries, Gravity, Loading, Material
    from fem.problem import GravityProblem
    from fem.solver import NewtonSolver

    length, width, C1, ratio = 0.1, 0.01, 1000.0, 4.0
    fixed = FixedBoundaries({"rib": (0,), "sternal": (1,), "caudal": (2,)})
    tip = {}
    for name, tissues in (("two tissues", Tissues({Tissue.GLAND: ratio})),
                          ("one ratio", Tissues({Tissue.GLAND: 1.0}))):
        mesh, facets, cells = _column(length, width, 16)
        problem = GravityProblem(mesh, facets, Discretisation(), fixed, None, None, cells,
                                 tissues)
        assert (problem.material.stiffness_ratio is None) == (name == "one ratio")
        solver = NewtonSolver(problem, TIGHT)
        problem.set_case(Material(C1=C1), Gravity(phi=0.0))  # gravity along +x: hanging
        result = solve_incrementally(problem, solver, Loading())
        assert result.converged, result.reason
        # the mean axial displacement over a section, from the displacement's nodes on it
        u_nodes = problem.displacement().x.array.reshape(-1, 3)
        coords = problem.V.tabulate_dof_coordinates()
        at = {key: np.isclose(coords[:, 0], where) for key, where in
              (("middle", length / 2), ("tip", length))}
        tip[name] = {key: float(u_nodes[mask, 0].mean()) for key, mask in at.items()}
        solver.destroy()

    # 1D: u(X) = ∫₀^X (λ(s) − 1) ds, λ from P(s) = ρ g (L − s) and the local C1
    weight = TISSUE_DENSITY * 9.81

    def u_1d(X: float, ratios: tuple[float, float]) -> float:
        s = np.linspace(0.0, X, 4001)
        lam = [_stretch(weight * (length - t), C1 * (ratios[0] if t < length / 2 else ratios[1]))
               for t in s]
        return float(np.trapz(np.array(lam) - 1.0, s))

    for name, ratios in (("two tissues", (1.0, ratio)), ("one ratio", (1.0, 1.0))):
        for key, X in (("middle", length / 2), ("tip", length)):
            assert tip[name][key] == pytest.approx(u_1d(X, ratios), rel=0.01), (name, key)
    # the stiffer lower half stretches four times less than the same half of fat
    lower = {name: tip[name]["tip"] - tip[name]["middle"] for name in tip}
    assert lower["two tissues"] < 0.3 * lower["one ratio"]


@pytest.mark.solve
def test_a_label_volumes_tissues_become_the_cells_tags_and_count_in_the_solve(
    tmp_path: Path,
) -> None:
    """A label volume's tissues tag the cells, and the stiffer ones hold the breast up.

    Fat, gland, skin and tumour labels each tag their cells, to the labelled volumes; prone
    at C1 = 1 kPa the breast sags less than the same mesh as one tissue.
    """
    from fem.case import CaseRunner
    from fem.sweep import Case
    from meshes.config import MeshConfig, make_mesh
    from meshes.io import read_mesh
    from tests.test_clinic_data import labelled_tissue_ml, phantom, tissue_section

    image = phantom(tmp_path, skin_mm=3.0)
    report = make_mesh(MeshConfig.from_mapping(tissue_section(image, mesher="ftetwild")),
                       tmp_path / "mesh.xdmf", tmp_path / "quality.json", tmp_path / "mesh.png")
    labelled = labelled_tissue_ml(image)
    meshed = report["tissue_volume_ml"]
    assert set(meshed) == {"fat", "gland", "skin", "tumour"}
    for name in ("gland", "skin"):
        assert meshed[name] == pytest.approx(labelled[name], rel=0.15), name
    assert 0.3 * labelled["tumour"] < meshed["tumour"] < 1.5 * labelled["tumour"]
    _, cell_tags, _ = read_mesh(tmp_path / "mesh.xdmf")
    counts = dict(zip(*np.unique(cell_tags.values, return_counts=True), strict=True))
    assert counts == {int(Tissue.from_label(name)): n
                      for name, n in report["input"]["tissue_cells"].items()}

    base = SolverSettings(petsc_options=TIGHT)
    case = Case(1.0, 180.0)
    sag = {}
    for name, tissues in (("tissues", Tissues({Tissue.TUMOUR: 5.0})),
                          ("one tissue", Tissues(dict.fromkeys(
                              (Tissue.GLAND, Tissue.SKIN, Tissue.TUMOUR), 1.0)))):
        with CaseRunner(tmp_path / "mesh.xdmf", replace(base, tissues=tissues)) as runner:
            result, timings = runner.solve(case)
            summary = runner.summary(case, result, timings, measure_unit=False)
        assert summary["status"] == "converged", name
        assert summary["settings"]["tissues"] == tissues.describe()
        sag[name] = summary["max_disp_mm"]
    assert sag["tissues"] < 0.8 * sag["one tissue"]


def _skinned_column(length: float, width: float, skin: float, resolved: bool) -> tuple:
    """The column of :func:`_column` whose free sides (y = width, z = width) are skin.

    ``resolved``: the outermost layer of cells under those sides is ``skin`` thick and tagged
    skin (a mesh graded to it); else every cell is fat, for a membrane on the sides. Both
    columns have one shape and one weight.
    """
    from dolfinx import mesh as dmesh
    from mpi4py import MPI

    from meshes.tags import Boundary

    n = 8  # 6.25 mm across, the skin's layer 1 mm: converged to about 2 % (n = 10 moves 1 %)
    mesh = dmesh.create_box(MPI.COMM_WORLD, [np.zeros(3), np.array([length, width, width])],
                            [16, n, n], dmesh.CellType.tetrahedron)
    if resolved:  # the last layer of cells is the skin
        x = mesh.geometry.x
        inner = width * (n - 1) / n
        for axis in (1, 2):
            s = x[:, axis].copy()
            x[:, axis] = np.where(s <= inner + 1e-12, s * (width - skin) / inner,
                                  width - skin + (s - inner) * skin / (width - inner))
    # the far end is a free cut, no skin: only the column's sides are
    facets = _tag_column(mesh, length, int(Boundary.AXILLA))
    cells = np.arange(mesh.topology.index_map(3).size_local, dtype=np.int32)
    centre = dmesh.compute_midpoints(mesh, 3, cells)
    in_skin = resolved & ((centre[:, 1] > width - skin) | (centre[:, 2] > width - skin))
    tissue = np.where(in_skin, int(Tissue.SKIN), int(Tissue.FAT)).astype(np.int32)
    return mesh, facets, dmesh.meshtags(mesh, 3, cells, tissue)


@pytest.mark.solve
def test_the_skin_membrane_carries_what_a_resolved_skin_layer_does() -> None:
    """A hanging column with skin on its free sides: membrane against resolved layer.

    The skin (1 mm, 18.5 times the fat) carries about half the column's weight; the membrane
    on the all-fat column's sides stretches it as the layer of skin cells does, to 5 %.
    """
    from fem.loading import solve_incrementally
    from fem.materials import SkinLayer
    from fem.parameters import Discretisation, FixedBoundaries, Gravity, Loading, Material
    from fem.problem import GravityProblem
    from fem.solver import NewtonSolver

    # the skin as thin against the column as against a breast (1 mm on 50 mm): the fat that
    # the membrane's column holds in the layer's place then counts as little as in a breast
    length, width, skin, C1 = 0.1, 0.05, 0.001, 300.0
    fixed = FixedBoundaries({"rib": (0,), "sternal": (1,), "caudal": (2,)})
    tip = {}
    for name, resolved, layer in (("resolved", True, None), ("membrane", False, SkinLayer(skin)),
                                  ("no skin", False, None)):
        mesh, facets, cells = _skinned_column(length, width, skin, resolved)
        problem = GravityProblem(mesh, facets, Discretisation(), fixed, None, None, cells,
                                 Tissues(), layer)
        assert (problem.material.skin is not None) == (name == "membrane")
        solver = NewtonSolver(problem, TIGHT)
        problem.set_case(Material(C1=C1), Gravity(phi=0.0))
        result = solve_incrementally(problem, solver, Loading())
        assert result.converged, (name, result.reason)
        u = problem.displacement().x.array.reshape(-1, 3)
        coords = problem.V.tabulate_dof_coordinates()
        tip[name] = float(u[np.isclose(coords[:, 0], length), 0].mean())
        solver.destroy()
    # the skin carries much of the load: without it the column stretches far more
    assert tip["no skin"] > 1.5 * tip["resolved"]
    assert tip["membrane"] == pytest.approx(tip["resolved"], rel=0.05)
    # a mesh whose cells carry the skin gets no membrane on top
    mesh, facets, cells = _skinned_column(length, width, skin, True)
    problem = GravityProblem(mesh, facets, Discretisation(), fixed, None, None, cells,
                             Tissues(), SkinLayer(skin))
    assert problem.material.skin is None



def _plain_membrane(a: float, b: float) -> float:
    """The plain membrane's energy over C1 t at principal squared in-plane stretches a, b."""
    return a + b + 1.0 / (a * b) - 3.0


@pytest.mark.solve
@pytest.mark.parametrize("stretches", [(1.3, 1.1), (1.4, 0.7), (1.2, 0.95), (0.9, 0.8),
                                       (1.05, 0.5), (1.0, 1.0)])
def test_the_wrinkling_membrane_is_the_least_energy_of_any_fine_wrinkling(
        stretches: tuple[float, float]) -> None:
    """The relaxed membrane energy equals min W over every wrinkled state of the same mean.

    A sheet's mean stretches (λ1, λ2) can be taken by any finer wrinkling whose true stretches
    are at least as long; the relaxed energy is the least of the plain energy over them,
    found here by brute force, independent of the closed form of fem.materials.Membrane
    (taut, wrinkled, slack). The plain membrane keeps its compressive energy.
    """
    import ufl
    from dolfinx import fem
    from dolfinx import mesh as dmesh
    from mpi4py import MPI
    from scipy.optimize import minimize

    from fem.materials import Membrane

    l1, l2 = stretches
    cube = dmesh.create_unit_cube(MPI.COMM_WORLD, 1, 1, 1, dmesh.CellType.tetrahedron)
    top = dmesh.locate_entities_boundary(cube, 2, lambda x: np.isclose(x[2], 1.0))
    tags = dmesh.meshtags(cube, 2, top, np.ones_like(top))
    ds = ufl.Measure("ds", domain=cube, subdomain_data=tags)(1)
    # a sheared, rotated F whose in-plane principal stretches on the top face are (l1, l2)
    c, s = np.cos(0.4), np.sin(0.4)
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    U = np.diag([l1, l2, 1.3]) + np.array([[0, 0, 0.2], [0, 0, -0.1], [0, 0, 0]])
    F = ufl.as_matrix((R @ U).tolist())
    energy = {wrinkles: fem.assemble_scalar(fem.form(
        Membrane(2.0, 0.5, wrinkles).strain_energy(F, ufl.FacetNormal(cube)) * ds))
        for wrinkles in (True, False)}
    a, b = l1**2, l2**2
    assert energy[False] == pytest.approx(_plain_membrane(a, b), rel=1e-9)

    def wrinkled(t: np.ndarray) -> float:  # true squared stretches a + t0², b + t1² ≥ (a, b)
        return _plain_membrane(a + t[0] ** 2, b + t[1] ** 2)

    least = min(minimize(wrinkled, start, method="Nelder-Mead",
                         options={"xatol": 1e-10, "fatol": 1e-14, "maxiter": 4000}).fun
                for start in ([0.0, 0.0], [0.5, 0.5], [0.0, 0.8], [0.8, 0.0]))
    assert energy[True] == pytest.approx(least, abs=1e-7)
    assert energy[True] <= energy[False] + 1e-12
