"""Importing a person's geometry: surfaces and volume meshes, boundary rules, broken input.

Inputs are generated in the test (gmsh boxes, the parametric breast's own surface),
so every file is small and its exact volume and areas are known.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import meshio
import numpy as np
import pytest
import yaml

from meshes.build import MeshSize, gmsh_session, write_parametric_mesh, write_parametric_surface
from meshes.exceptions import (
    GeometryError,
    InvalidElementsError,
    MeshInputError,
    NoRibFacetsError,
    SelfIntersectionError,
    SurfaceNotClosedError,
    SurfaceRuleError,
    UnitsError,
)
from meshes.importing import ImportSpec, write_imported_mesh
from meshes.parametric import BreastGeometry, rib_cage_surface
from meshes.tags import Boundary
from tests.conftest import REPO

pytestmark = pytest.mark.unit

BOX = (0.05, 0.2, 0.15)  # a slab of tissue: 5 cm deep (x), 20 cm wide (y), 15 cm tall (z)
SIZE = MeshSize(global_size=0.03, mound_size=0.02)
RIB_PLANE = {"plane": {"point": [0.0, 0.0, 0.0], "normal": [1.0, 0.0, 0.0]}, "distance": 0.001}


def box_mesh(dim: int) -> tuple[np.ndarray, np.ndarray]:
    """The BOX meshed by gmsh: its surface triangles (dim 2) or its tetrahedra (dim 3)."""
    from meshes.build import mesh_arrays

    with gmsh_session("box") as model:
        model.occ.addBox(0, 0, 0, *BOX)
        model.occ.synchronize()
        import gmsh

        gmsh.option.setNumber("Mesh.MeshSizeMax", 0.025)
        model.mesh.generate(dim)
        if dim == 3:
            x, tets, _ = mesh_arrays(model, {})
            return x, tets
        node_tags, coords, _ = model.mesh.getNodes()
        _, nodes = model.mesh.getElementsByType(2)
        index = np.zeros(int(node_tags.max()) + 1, dtype=np.int64)
        index[node_tags.astype(np.int64)] = np.arange(len(node_tags))
        return coords.reshape(-1, 3), index[nodes.reshape(-1, 3).astype(np.int64)]


def write_surface(path: Path, x: np.ndarray, tris: np.ndarray) -> Path:
    meshio.write(str(path), meshio.Mesh(x, [("triangle", tris)]))
    return path


def write_volume(path: Path, x: np.ndarray, tets: np.ndarray) -> Path:
    meshio.write(str(path), meshio.Mesh(x, [("tetra", tets)]))
    return path


#: The boxes below stand on their chest wall at the file's x = 0, +x pointing out of the chest
#: (anterior): the file's axes are A, L, S of a left breast. Without it the import takes the
#: file to be in the project's frame (+x posterior), and refuses a chest wall anterior.
OUT_OF_THE_CHEST = {"axes": "ALS", "side": "left"}


def spec(path: Path, units: str = "m", orientation: dict | None = None,
         **surfaces: dict) -> ImportSpec:
    values = {"path": str(path), "units": units, "surfaces": surfaces or {"rib": RIB_PLANE}}
    if orientation is not None:
        values["orientation"] = orientation
    return ImportSpec.from_mapping(values)


# -- the acceptance test of the issue ------------------------------------------------------


@pytest.mark.parametrize("remesh", [False, True])
def test_stl_of_default_geometry_gives_same_volume_and_rib_area(
    tmp_path: Path, remesh: bool
) -> None:
    """An STL of the default breast's outer surface reproduces the parametric mesh.

    With the rib rule, the volume agrees within 1 % and the rib area within 2 %.
    """
    geometry = BreastGeometry()
    reference = write_parametric_mesh(geometry, MeshSize(), tmp_path / "parametric.xdmf")
    # a scan of the same breast, triangulated differently from the reference mesh
    stl = tmp_path / "breast.stl"
    write_parametric_surface(geometry, MeshSize(global_size=0.012, mound_size=0.008), stl)
    ribcage = write_surface(tmp_path / "ribcage.stl", *rib_cage_surface(geometry))
    rules = {"rib": {"surface": str(ribcage), "distance": 0.0005}}
    imported = write_imported_mesh(
        ImportSpec.from_mapping({"path": str(stl), "surfaces": rules, "remesh": remesh}),
        MeshSize(),
        tmp_path / "imported.xdmf",
    )
    assert imported["volume_m3"] == pytest.approx(reference["volume_m3"], rel=0.01)
    assert imported["area_m2"]["rib"] == pytest.approx(reference["area_m2"]["rib"], rel=0.02)
    assert imported["inverted_cells"] == 0 and imported["untagged_exterior_facets"] == 0
    # only rib and skin are named: the four cuts are skin unless a rule names them
    assert imported["area_m2"]["rib"] + imported["area_m2"]["skin"] == pytest.approx(
        imported["exterior_area_m2"]
    )
    # and the solver accepts it: rib facets present, every rib node on the rib cage
    from dolfinx.cpp.mesh import entities_to_geometry

    from meshes.io import read_mesh

    mesh, _, facet_tags = read_mesh(tmp_path / "imported.xdmf")
    rib = facet_tags.indices[facet_tags.values == int(Boundary.RIB)]
    x = mesh.geometry.x[np.unique(entities_to_geometry(mesh._mesh, 2, rib, False))]
    assert np.max(np.abs(geometry.rib_level_set(x))) < 0.0005


# -- rules ---------------------------------------------------------------------------------


def test_plane_rules_name_the_box_faces(tmp_path: Path) -> None:
    stl = write_surface(tmp_path / "box.stl", *box_mesh(2))
    top = {"plane": {"point": [0, 0, BOX[2]], "normal": [0, 0, 1]}, "distance": 0.001}
    report = write_imported_mesh(
        spec(stl, orientation=OUT_OF_THE_CHEST, rib=RIB_PLANE, cranial=top), SIZE,
        tmp_path / "m.xdmf", tmp_path / "m.png"
    )
    areas = report["area_m2"]
    assert areas["rib"] == pytest.approx(BOX[1] * BOX[2], rel=1e-9)
    assert areas["cranial"] == pytest.approx(BOX[0] * BOX[1], rel=1e-9)
    total = 2 * (BOX[0] * BOX[1] + BOX[1] * BOX[2] + BOX[0] * BOX[2])
    assert areas["skin"] == pytest.approx(total - areas["rib"] - areas["cranial"], rel=1e-9)
    assert report["volume_m3"] == pytest.approx(np.prod(BOX), rel=1e-9)
    # the projection from the chest wall is the slab's depth (the rib is the x = 0 face)
    assert report["anatomy"]["projection_from_chest_wall_m"] == pytest.approx(BOX[0], rel=0.05)
    assert (tmp_path / "m.png").stat().st_size > 20_000


def test_units_are_converted(tmp_path: Path) -> None:
    x, tris = box_mesh(2)
    stl = write_surface(tmp_path / "box_mm.stl", 1000.0 * x, tris)
    rib = {"plane": {"point": [0, 0, 0], "normal": [1, 0, 0]}, "distance": 1.0}  # 1 mm
    report = write_imported_mesh(spec(stl, "mm", OUT_OF_THE_CHEST, rib=rib), SIZE,
                                 tmp_path / "m.xdmf")
    assert report["volume_m3"] == pytest.approx(np.prod(BOX), rel=1e-9)


def test_group_rule_on_a_gmsh_volume_mesh(tmp_path: Path) -> None:
    import gmsh

    path = tmp_path / "box.msh"
    with gmsh_session("box") as model:
        box = model.occ.addBox(0, 0, 0, *BOX)
        model.occ.synchronize()
        faces = {tag: model.occ.getCenterOfMass(2, tag) for _, tag in model.getEntities(2)}
        back = next(t for t, c in faces.items() if abs(c[0]) < 1e-9)
        top = next(t for t, c in faces.items() if abs(c[2] - BOX[2]) < 1e-9)
        model.addPhysicalGroup(3, [box], 1, name="tissue")
        model.addPhysicalGroup(2, [back], 7, name="chest_wall")
        model.addPhysicalGroup(2, [top], 8, name="top")
        gmsh.option.setNumber("Mesh.MeshSizeMax", 0.025)
        model.mesh.generate(3)
        gmsh.write(str(path))
    report = write_imported_mesh(
        spec(path, orientation=OUT_OF_THE_CHEST, rib={"group": "chest_wall"}, cranial={"group": 8}),
        SIZE, tmp_path / "m.xdmf"
    )
    assert report["area_m2"]["rib"] == pytest.approx(BOX[1] * BOX[2], rel=1e-9)
    assert report["area_m2"]["cranial"] == pytest.approx(BOX[0] * BOX[1], rel=1e-9)
    assert report["input"]["kind"] == "volume mesh"
    with pytest.raises(SurfaceRuleError, match="groups are: chest_wall, .*top"):
        write_imported_mesh(spec(path, rib={"group": "ribs"}), SIZE, tmp_path / "bad.xdmf")


@pytest.mark.parametrize("suffix", [".vtu", ".xdmf"])
def test_volume_mesh_formats(tmp_path: Path, suffix: str) -> None:
    path = write_volume(tmp_path / f"box{suffix}", *box_mesh(3))
    report = write_imported_mesh(spec(path, orientation=OUT_OF_THE_CHEST), SIZE,
                                 tmp_path / "m.xdmf")
    assert report["volume_m3"] == pytest.approx(np.prod(BOX), rel=1e-9)
    assert report["area_m2"]["rib"] == pytest.approx(BOX[1] * BOX[2], rel=1e-9)


def test_rules_that_overlap_are_refused(tmp_path: Path) -> None:
    stl = write_surface(tmp_path / "box.stl", *box_mesh(2))
    wide = {"plane": {"point": [0.01, 0, 0], "normal": [1, 0, 0]}, "distance": 0.02}
    with pytest.raises(SurfaceRuleError, match="match both the rib and the sternal rules"):
        write_imported_mesh(spec(stl, rib=RIB_PLANE, sternal=wide), SIZE, tmp_path / "m.xdmf")


# -- broken input: one test per kind ---------------------------------------------------------


def test_surface_not_closed(tmp_path: Path) -> None:
    """A hole too large to fill (a whole face of the box) is refused with its size and place."""
    x, tris = box_mesh(2)
    on_face = np.abs(x[tris][:, :, 0]).max(axis=1) < 1e-9  # the face x = 0: 300 cm²
    stl = write_surface(tmp_path / "open.stl", x, tris[~on_face])
    with pytest.raises(
        SurfaceNotClosedError,
        match=r"not a closed surface: 1 hole\(s\), the largest 300 cm² \(46 % of the surface; "
              r"rim 700 mm in \d+ edges\) centred at \(0\.0, 100\.0, 75\.0\) mm",
    ):
        write_imported_mesh(spec(stl), SIZE, tmp_path / "m.xdmf")
    assert not (tmp_path / "m.xdmf").exists()


def test_surface_not_manifold(tmp_path: Path) -> None:
    x, tris = box_mesh(2)
    # a fin glued to one edge of the box: that edge now has three triangles
    a, b = tris[0][:2]
    fin = np.vstack([x, [[-0.05, 0.1, 0.07]]])
    stl = write_surface(tmp_path / "fin.stl", fin, np.vstack([tris, [[a, b, len(x)]]]))
    with pytest.raises(SurfaceNotClosedError, match="three or more triangles"):
        write_imported_mesh(spec(stl), SIZE, tmp_path / "m.xdmf")


def test_surface_self_intersecting(tmp_path: Path) -> None:
    x, tris = box_mesh(2)
    # one body whose surface crosses itself: the node nearest the middle of the back (x = 0)
    # pulled through the front (x = 5 cm), its triangles a spike through the front's
    # (two bodies crossing are refused as two bodies: tests/test_bodies.py)
    middle = np.argmin(np.linalg.norm(x - [0.0, 0.1, 0.075], axis=1))
    x = x.copy()
    x[middle] = [0.08, 0.1, 0.075]
    spiked = write_surface(tmp_path / "spiked.stl", x, tris)
    with pytest.raises(
        SelfIntersectionError, match=r"intersects itself: \d+ pair\(s\) of triangles cross"
    ):
        write_imported_mesh(spec(spiked), SIZE, tmp_path / "m.xdmf")


def test_wrong_units_millimetres_read_as_metres(tmp_path: Path) -> None:
    x, tris = box_mesh(2)
    stl = write_surface(tmp_path / "box_mm.stl", 1000.0 * x, tris)
    with pytest.raises(
        UnitsError,
        match=r"is 255 m across .* probably in other units.*0.255 m across: "
        r"set mesh.file.units: mm",
    ):
        write_imported_mesh(spec(stl, "m"), SIZE, tmp_path / "m.xdmf")


def test_wrong_units_metres_read_as_centimetres(tmp_path: Path) -> None:
    stl = write_surface(tmp_path / "box.stl", *box_mesh(2))
    with pytest.raises(UnitsError, match="units: m"):
        write_imported_mesh(
            spec(stl, "cm", rib={"plane": RIB_PLANE["plane"]}), SIZE, tmp_path / "m.xdmf"
        )


def test_no_rib_facets_found(tmp_path: Path) -> None:
    stl = write_surface(tmp_path / "box.stl", *box_mesh(2))
    far = {"plane": {"point": [-0.1, 0, 0], "normal": [1, 0, 0]}, "distance": 0.001}
    with pytest.raises(
        NoRibFacetsError,
        match="no boundary facets found for the rib surface.*closest facet lies 100 mm",
    ):
        write_imported_mesh(spec(stl, rib=far), SIZE, tmp_path / "m.xdmf")
    # a surface rule far from the model cannot even measure how far: it says so
    points, triangles = rib_cage_surface(BreastGeometry())
    rib_far = write_surface(tmp_path / "far.stl", points + [0.5, 0.0, 0.0], triangles)
    with pytest.raises(NoRibFacetsError, match="no facet comes within 10 mm"):
        write_imported_mesh(
            spec(stl, rib={"surface": str(rib_far), "distance": 0.001}), SIZE, tmp_path / "m.xdmf"
        )
    # a group rule on a file without groups
    with pytest.raises(SurfaceRuleError, match="has no boundary groups"):
        write_imported_mesh(spec(stl, rib={"group": "rib"}), SIZE, tmp_path / "m.xdmf")


def test_inverted_elements(tmp_path: Path) -> None:
    x, tets = box_mesh(3)
    tets = tets.copy()
    tets[[3, 17]] = tets[[3, 17]][:, [1, 0, 2, 3]]  # two cells turned inside out
    path = write_volume(tmp_path / "inverted.vtu", x, tets)
    with pytest.raises(InvalidElementsError, match=r"2 inverted tetrahedra .* the first \(#3\)"):
        write_imported_mesh(spec(path), SIZE, tmp_path / "m.xdmf")


def test_degenerate_elements(tmp_path: Path) -> None:
    x, tets = box_mesh(3)
    tets = tets.copy()
    tets[5, 3] = tets[5, 2]  # a cell with a repeated vertex: zero volume
    path = write_volume(tmp_path / "flat.vtu", x, tets)
    with pytest.raises(InvalidElementsError, match=r"1 degenerate \(zero-volume\) tetrahedra"):
        write_imported_mesh(spec(path), SIZE, tmp_path / "m.xdmf")


def test_degenerate_surface_triangles() -> None:
    from meshes.checks import check_triangles

    x = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [2, 0, 0.0]])
    check_triangles(x, np.array([[0, 1, 2]]), "ok")
    with pytest.raises(InvalidElementsError, match="1 degenerate \\(zero-area\\) triangle"):
        check_triangles(x, np.array([[0, 1, 2], [0, 1, 3]]), "collinear")


def test_unreadable_or_unsupported_input(tmp_path: Path) -> None:
    with pytest.raises(MeshInputError, match="unsupported file type '.step'"):
        spec(tmp_path / "breast.step")
    with pytest.raises(MeshInputError, match="does not exist"):
        write_imported_mesh(spec(tmp_path / "missing.stl"), SIZE, tmp_path / "m.xdmf")
    garbage = tmp_path / "garbage.stl"
    garbage.write_bytes(b"solid nothing\n  facet normal oops\n")
    # trimesh reads past the broken facet and finds nothing
    with pytest.raises(MeshInputError, match="garbage.stl is empty: it holds no points"):
        write_imported_mesh(spec(garbage), SIZE, tmp_path / "m.xdmf")
    with pytest.raises(GeometryError, match="rule for the rib"):
        ImportSpec.from_mapping({"path": "a.stl", "surfaces": {"cranial": RIB_PLANE}})


def test_the_parametric_sizes_are_left_aside_on_import(caplog) -> None:
    """Curved cells and the fold grading need the parametric CAD: an import says so once."""
    from meshes.importing import import_size

    with caplog.at_level("INFO", logger="meshes.importing"):
        size = import_size(MeshSize(order=2, fold_size=0.004))
    assert (size.order, size.fold_size) == (1, None)
    assert "order: 2, fold_size: 0.004: parametric only" in caplog.text


def test_an_import_finer_than_the_default_mound_size_needs_only_its_global_size() -> None:
    """`size: {global_size: 0.008}` (the README's import) is no error about the mound's size.

    The mound is the parametric breast's: for an import its size is capped at global_size,
    whether the schema filled in its default (0.010) or the key is absent; the parametric
    breast still refuses a mound coarser than the rest.
    """
    from meshes.config import MeshConfig

    config = file_config()["mesh"]
    for size in ({"global_size": 0.008}, {"global_size": 0.008, "mound_size": 0.010}):
        parsed = MeshConfig.from_mapping({**config, "size": size}).size
        assert (parsed.global_size, parsed.mound_size) == (0.008, 0.008)
    kept = MeshConfig.from_mapping({**config, "size": {"global_size": 0.02, "mound_size": 0.01}})
    assert kept.size.mound_size == 0.01
    with pytest.raises(GeometryError, match="mound_size"):
        MeshConfig.from_mapping({"source": "parametric", "size": {"global_size": 0.008}})
    with pytest.raises(GeometryError, match="global_size must be positive"):
        MeshConfig.from_mapping({**config, "size": {"global_size": "fine"}})
    # the whole config, its defaults filled by the schema (the FE study's default variant
    # reads mesh.size too)
    from run.config import WorkflowConfig, validated

    whole = file_config()
    whole["mesh"]["size"] = {"global_size": 0.008}
    assert WorkflowConfig.from_mapping(validated(whole)).mesh.size.mound_size == 0.008


# -- the checks as functions -----------------------------------------------------------------


def test_self_intersections_finds_exactly_the_crossing_pair() -> None:
    from meshes.checks import self_intersections

    x = np.array(
        [
            [0, 0, 0],
            [1, 0, 0],
            [0, 1, 0],  # triangle 0 in z = 0
            [0.2, 0.2, -0.5],
            [0.3, 0.2, 0.5],
            [0.2, 0.3, 0.5],  # triangle 1 pierces it
            [5, 5, 5],
            [6, 5, 5],
            [5, 6, 5],  # triangle 2 far away
            [1, 0, 0],
            [2, 0, 0],
            [1, 1, 0.0],  # triangle 3 touches 0 at a shared corner only
        ],
        dtype=float,
    )
    tris = np.arange(12).reshape(4, 3)
    tris[3, 0] = 1  # shares vertex 1 with triangle 0
    assert self_intersections(x, tris).tolist() == [[0, 1]]


def test_closed_surfaces_pass_every_check(tmp_path: Path) -> None:
    from meshes.checks import check_closed, check_no_self_intersections

    stl = tmp_path / "breast.stl"
    write_parametric_surface(BreastGeometry(), SIZE, stl)
    surface = meshio.read(str(stl))
    from meshes.checks import merge_duplicate_points

    x, tris = merge_duplicate_points(surface.points, surface.cells_dict["triangle"], 1e-10)
    check_closed(x, tris, "the breast")
    check_no_self_intersections(x, tris, "the breast")


# -- the workflow's mesh rule with an imported file -----------------------------------------


def file_config(**file_section: object) -> dict:
    config = yaml.safe_load((REPO / "tests" / "config.yaml").read_text())
    config["mesh"]["source"] = "file"
    config["mesh"]["file"] = {
        "path": "box.stl",
        "units": "m",
        "surfaces": {"rib": RIB_PLANE},
        **file_section,
    }
    # the parametric breast's `chest` obstacle does not exist here: the rib plane is the chest
    config["fe"]["contact"] = {"obstacle": {"plane": RIB_PLANE["plane"]}}
    return config


def _plan(tmp_path: Path, config: dict, target: str) -> subprocess.CompletedProcess:
    """``snakemake -n target`` in tmp_path on this config."""
    path = tmp_path / "file.yaml"
    path.write_text(yaml.safe_dump(config))
    cmd = [sys.executable, "-m", "snakemake", "-s", str(REPO / "Snakefile"), "-d", str(tmp_path),
           "--configfile", str(path), "-j1", "-n", target]
    return subprocess.run(cmd, capture_output=True, text=True, cwd=tmp_path)


def test_schema_accepts_a_file_source_and_rejects_a_missing_rib_rule() -> None:
    import jsonschema

    schema = yaml.safe_load((REPO / "workflow/schemas/config.schema.yaml").read_text())
    validator = jsonschema.Draft7Validator(schema)
    assert list(validator.iter_errors(file_config())) == []
    no_rib = file_config(surfaces={"cranial": {"group": "top"}})
    assert any("'rib' is a required property" in e.message for e in validator.iter_errors(no_rib))
    bad_units = file_config(units="inch")
    assert any(list(e.absolute_path)[-1] == "units" for e in validator.iter_errors(bad_units))


def test_mesh_rule_depends_on_the_imported_file(tmp_path: Path) -> None:
    write_surface(tmp_path / "box.stl", *box_mesh(2))
    run = _plan(tmp_path, file_config(), "results/mesh/mesh.xdmf")
    assert run.returncode == 0, run.stderr[-3000:]
    plan = run.stdout + run.stderr
    # the file is the rule's input (editing it rebuilds the mesh); the PNG is an output
    assert "input: box.stl" in plan and "results/mesh/mesh.png" in plan


def test_an_import_changes_only_the_mesh_section(tmp_path: Path) -> None:
    """config.yaml with only `mesh.source` and `mesh.file` changed plans the import.

    Its `contact: {}` rests the skin on the parametric breast's chest, which an imported mesh
    does not have: contact is off, said in one line; its curved cells and fold grading are left
    aside. An obstacle named `chest` explicitly is still refused before any job.
    """
    write_surface(tmp_path / "box.stl", *box_mesh(2))
    config = file_config()
    config["fe"]["contact"] = {}
    config["mesh"]["size"] = {**config["mesh"]["size"], "order": 2, "fold_size": 0.006}
    run = _plan(tmp_path, config, "results/mesh/mesh.xdmf")
    said = run.stdout + run.stderr
    assert run.returncode == 0, said[-3000:]
    assert said.count("fe.contact: off for the imported mesh") == 1
    config["fe"]["contact"] = {"obstacle": "chest"}
    run = _plan(tmp_path, config, "results/mesh/mesh.xdmf")
    said = run.stdout + run.stderr
    assert run.returncode != 0 and "invalid configuration: fe.contact.obstacle 'chest'" in said
    assert "an imported mesh (mesh.source: file) needs an explicit obstacle" in said
    assert not (tmp_path / "results").exists()


def test_clamping_a_surface_no_rule_names_is_refused() -> None:
    from meshes.config import MeshConfig

    config = file_config()["mesh"]
    config["fixed"] = {"rib": "all", "cranial": ["z"]}
    with pytest.raises(GeometryError, match="mesh.fixed clamps cranial, but mesh.file.surfaces"):
        MeshConfig.from_mapping(config)
    config["file"]["surfaces"]["cranial"] = {"group": "top"}
    assert MeshConfig.from_mapping(config).input_files() == ["box.stl"]


def test_a_dolfinx_xdmf_mesh_round_trips_with_its_tags(coarse_mesh: Path, tmp_path: Path) -> None:
    """This project's own mesh.xdmf imports with its facet tags as groups: every area is kept.

    It holds several grids, which meshio cannot read.
    """
    original = json.loads((coarse_mesh.parent / "quality.json").read_text())
    rules = {b.label: {"group": b.label} for b in Boundary if b != Boundary.SKIN}
    report = write_imported_mesh(
        ImportSpec.from_mapping({"path": str(coarse_mesh), "surfaces": rules}),
        SIZE,
        tmp_path / "m.xdmf",
    )
    assert report["cells"] == original["cells"]
    for name, area in original["area_m2"].items():
        assert report["area_m2"][name] == pytest.approx(area, rel=1e-12), name


# -- inputs that used to pass or fail without naming the problem ----------------------------


@pytest.mark.parametrize("content", [b"", b"solid empty\nendsolid empty\n"])
def test_an_empty_file_is_named_as_empty(tmp_path: Path, content: bytes) -> None:
    stl = tmp_path / "empty.stl"
    stl.write_bytes(content)
    with pytest.raises(MeshInputError, match="empty.stl is empty: it holds no points or no cells"):
        write_imported_mesh(spec(stl, "mm"), SIZE, tmp_path / "m.xdmf")
    assert not (tmp_path / "m.xdmf").exists()


def test_a_nan_vertex_is_named_not_taken_for_wrong_units(tmp_path: Path) -> None:
    x, tris = box_mesh(2)
    x[7, 1] = np.nan
    stl = write_surface(tmp_path / "nan.stl", x, tris)
    with pytest.raises(MeshInputError, match="point.* have a NaN or infinite coordinate") as err:
        write_imported_mesh(spec(stl), SIZE, tmp_path / "m.xdmf")
    assert not isinstance(err.value, UnitsError)


def test_a_small_model_declared_in_centimetres_is_refused_by_its_volume(tmp_path: Path) -> None:
    """A 5 cm model in mm, declared in cm, is 0.5 m across (a plausible extent) but holds 12 l.

    Its volume names the units.
    """
    x, tris = box_mesh(2)
    stl = write_surface(tmp_path / "small_mm.stl", 200.0 * x, tris)  # 1 x 4 x 3 cm, in mm
    rib = {"plane": {"point": [0, 0, 0], "normal": [1, 0, 0]}, "distance": 0.1}
    with pytest.raises(
        UnitsError, match=r"holds 12 l of tissue with units 'cm'.*read in mm it would hold 12 ml"
    ):
        write_imported_mesh(spec(stl, "cm", rib=rib), SIZE, tmp_path / "m.xdmf")
    report = write_imported_mesh(spec(stl, "mm", OUT_OF_THE_CHEST, rib=rib), SIZE,
                                 tmp_path / "m.xdmf")
    assert report["input"]["volume_ml"] == pytest.approx(12.0, rel=1e-9)


def test_a_rib_rule_that_clamps_the_whole_boundary_is_refused(tmp_path: Path) -> None:
    stl = write_surface(tmp_path / "box.stl", *box_mesh(2))
    everything = {"plane": RIB_PLANE["plane"], "distance": 1.0}
    with pytest.raises(SurfaceRuleError, match=r"selects 100 % of the boundary's area.*narrow"):
        write_imported_mesh(spec(stl, rib=everything), SIZE, tmp_path / "m.xdmf")
    assert not (tmp_path / "m.xdmf").exists()


def test_a_rib_rule_that_clamps_a_sliver_is_refused(tmp_path: Path) -> None:
    """A slab 1 cm deep and 45 cm tall clamped by its 1 x 20 cm base: 1 % of its surface."""
    x, tris = box_mesh(2)
    stl = write_surface(tmp_path / "slab.stl", x * [0.2, 1.0, 3.0], tris)
    base = {"plane": {"point": [0, 0, 0], "normal": [0, 0, 1]}, "distance": 0.001}
    with pytest.raises(SurfaceRuleError, match=r"selects 1.0\d* % of the boundary's area.*widen"):
        write_imported_mesh(spec(stl, rib=base), SIZE, tmp_path / "m.xdmf")


def test_a_file_that_is_not_a_project_mesh_is_named_when_read(tmp_path: Path) -> None:
    """An STL, a case's fields.xdmf and a mesh with a NaN node: each refused by what it is."""
    import h5py
    from dolfinx import mesh as dmesh
    from dolfinx.io import XDMFFile
    from mpi4py import MPI

    from meshes.io import read_mesh, write_tagged_mesh

    box = dmesh.create_unit_cube(MPI.COMM_WORLD, 2, 2, 2)
    n = box.topology.index_map(3).size_local
    box.topology.create_connectivity(2, 3)
    facets = dmesh.exterior_facet_indices(box.topology)
    write_tagged_mesh(box, dmesh.meshtags(box, 3, np.arange(n, dtype=np.int32),
                                          np.ones(n, dtype=np.int32)),
                      dmesh.meshtags(box, 2, facets, np.full(len(facets), 2, dtype=np.int32)),
                      tmp_path / "mesh.xdmf")
    assert read_mesh(tmp_path / "mesh.xdmf")[0].topology.index_map(3).size_local == n
    stl = tmp_path / "breast.stl"
    stl.write_text("solid s\nendsolid s\n")
    with pytest.raises(MeshInputError, match="breast.stl is not a mesh of this project .* "
                       "imported by the mesh rule"):
        read_mesh(stl)
    with XDMFFile(MPI.COMM_WORLD, str(tmp_path / "fields.xdmf"), "w") as xdmf:
        xdmf.write_mesh(box)  # a mesh under dolfinx's own name, no tags: a case's fields file
    with pytest.raises(MeshInputError, match="fields.xdmf holds no mesh named 'mesh' .*a "
                       "case's fields.xdmf is not a mesh"):
        read_mesh(tmp_path / "fields.xdmf")
    with h5py.File(tmp_path / "mesh.h5", "a") as h5:
        h5["Mesh/mesh/geometry"][4, 1] = np.nan
    with pytest.raises(MeshInputError, match="mesh.xdmf: node 4 .* not finite numbers"):
        read_mesh(tmp_path / "mesh.xdmf")
