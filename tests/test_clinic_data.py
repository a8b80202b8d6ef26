"""A clinic's own data: surface files as tools write them, small repairs, a sharp rim, an image.

Surface files as real tools write them, small repairs, a remesh that holds on a sharp rim, and
a segmentation's label volume meshed straight from its header. The surfaces are a low-poly
breast as a modelling tool exports it (:func:`low_poly_cap`: UV-sphere rings down to the chest
cut, the cut disc filled by a zig-zag of long thin triangles, the skin meeting the cut at a
sharp rim), on which gmsh's reparametrisation stops with a traceback. The label volumes are
:mod:`meshes.phantom`'s, at a coarse voxel size so that each test takes seconds.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from meshes.config import MeshConfig, make_mesh
from meshes.exceptions import GeometryError, MeshInputError, SurfaceNotClosedError
from meshes.image import Grid, ImageSpec, read_header
from meshes.importing import ImportSpec, read_volume
from meshes.orientation import Orientation
from meshes.phantom import BREAST_LABELS, PECTORAL, rotation, write_phantom
from meshes.remesh import MIN_DIHEDRAL_DEG, _gmsh_fill
from meshes.sizing import MeshSize
from meshes.tags import Boundary
from tests.conftest import REPO

pytestmark = pytest.mark.unit

RIB_PLANE = {"plane": {"point": [0, 0, 0], "normal": [1, 0, 0]}, "distance": 0.5}
SCANNER_MM = np.array([92.0, -31.0, 1184.0])


def low_poly_cap(depth: float = 0.06, segments: int = 32, rings: int = 12,
                 noise: float = 0.0005) -> tuple[np.ndarray, np.ndarray]:
    """A low-poly breast on a flat chest cut at x = 0 (project's frame, m), outward triangles."""
    a, b, c = 0.055 + depth, 0.075, 0.07
    cut = math.acos(depth / a)  # the latitude at which the ellipsoid meets x = 0
    points = [[depth - a, 0.0, 0.0]]
    for i in range(1, rings + 1):
        t = cut * i / rings
        for j in range(segments):
            p = 2 * math.pi * j / segments
            points.append([depth - a * math.cos(t), b * math.sin(t) * math.cos(p),
                           c * math.sin(t) * math.sin(p)])
    x = np.array(points)
    x[-segments:, 0] = 0.0
    ring = [1 + i * segments + np.arange(segments) for i in range(rings)]
    tris = [[0, ring[0][(j + 1) % segments], ring[0][j]] for j in range(segments)]
    for r, s in zip(ring[:-1], ring[1:], strict=True):
        for j in range(segments):
            k = (j + 1) % segments
            tris += [[r[j], r[k], s[k]], [r[j], s[k], s[j]]]
    lo, hi, order = 0, segments - 1, []
    while lo <= hi:  # an n-gon fill: a zig-zag of long thin triangles across the cut
        order.append(lo)
        lo += 1
        if lo <= hi:
            order.append(hi)
            hi -= 1
    tris += [[ring[-1][order[k]], ring[-1][order[k + 1]], ring[-1][order[k + 2]]]
             for k in range(len(order) - 2)]
    tris = np.array(tris)
    a_, b_, c_ = (x[tris[:, i]] for i in range(3))
    inward = np.einsum("ij,ij->i", np.cross(b_ - a_, c_ - a_), a_ + b_ + c_ - 3 * x.mean(0)) < 0
    tris[inward] = tris[inward][:, [0, 2, 1]]
    x[:-segments] += np.random.default_rng(1).normal(scale=noise, size=x[:-segments].shape)
    return x, tris


def write_obj_as_blender(path: Path, x_mm: np.ndarray, tris: np.ndarray) -> Path:
    """An OBJ as Blender writes it: texture coordinates, normals, objects, groups, materials."""
    uv = np.random.default_rng(0).uniform(size=(len(tris) + 7, 2))
    lines = ["# Blender 4.2.0", "mtllib breast.mtl", "o Breast"]
    lines += [f"v {p[0]:.6f} {p[1]:.6f} {p[2]:.6f}" for p in x_mm]
    lines += [f"vt {u:.6f} {v:.6f}" for u, v in uv]
    lines += ["vn 0.0000 0.0000 1.0000", "vn 1.0000 0.0000 0.0000", "g skin", "usemtl Skin",
              "s 1"]
    for k, (p, q, r) in enumerate(tris + 1):
        if k == len(tris) // 2:
            lines += ["g chest", "usemtl Chest"]
        lines.append(f"f {p}/{k + 1}/1 {q}/{k + 2}/1 {r}/{k + 3}/2")
    path.write_text("\n".join(lines) + "\n")
    return path


def surface_spec(path: Path, **extra: object) -> ImportSpec:
    return ImportSpec.from_mapping({"path": str(path), "units": "mm",
                                    "surfaces": {"rib": RIB_PLANE}, **extra})


# -- surface and volume files as tools write them ---------------------------------------------


def write_every_kind(folder: Path, x_mm: np.ndarray, tris: np.ndarray) -> list[Path]:
    """The same surface in every format the import reads, as each tool writes it."""
    import meshio
    import trimesh
    from vtkmodules.util.numpy_support import numpy_to_vtk, numpy_to_vtkIdTypeArray
    from vtkmodules.vtkCommonCore import vtkPoints
    from vtkmodules.vtkCommonDataModel import vtkCellArray, vtkPolyData
    from vtkmodules.vtkIOXML import vtkXMLPolyDataWriter

    mesh = trimesh.Trimesh(x_mm, tris, process=False)
    mesh.visual.vertex_colors = np.tile([230, 180, 160, 255], (len(x_mm), 1))
    mesh.export(folder / "scanner.ply")  # binary PLY with colours
    mesh.export(folder / "ascii.stl", file_type="stl_ascii")
    mesh.export(folder / "binary.stl")
    mesh.export(folder / "mesh.off")
    meshio.write(folder / "legacy.vtk", meshio.Mesh(x_mm, [("triangle", tris)]), binary=False)
    polydata = vtkPolyData()
    points = vtkPoints()
    points.SetData(numpy_to_vtk(np.ascontiguousarray(x_mm, dtype=float), deep=True))
    polydata.SetPoints(points)
    polys = vtkCellArray()
    polys.SetData(numpy_to_vtkIdTypeArray(np.arange(0, 3 * len(tris) + 1, 3), deep=True),
                  numpy_to_vtkIdTypeArray(np.ascontiguousarray(tris.ravel(), np.int64), deep=True))
    polydata.SetPolys(polys)
    writer = vtkXMLPolyDataWriter()
    writer.SetFileName(str(folder / "paraview.vtp"))
    writer.SetInputData(polydata)
    writer.Write()
    return [write_obj_as_blender(folder / "blender.obj", x_mm, tris),
            *(folder / name for name in ("scanner.ply", "ascii.stl", "binary.stl", "mesh.off",
                                         "legacy.vtk", "paraview.vtp"))]


def test_every_surface_format_imports_to_the_same_body(tmp_path: Path) -> None:
    """Every surface format imports to the same closed body, its volume the surface's.

    OBJ (texture coordinates, normals, groups), PLY with colours, ASCII and binary STL, OFF,
    legacy VTK and VTP.
    """
    from meshes.checks import enclosed_volume

    x, tris = low_poly_cap(noise=0.0)
    expected_ml = 1e6 * enclosed_volume(x, tris)
    volumes = {}
    for path in write_every_kind(tmp_path, 1e3 * x, tris):
        volume = read_volume(surface_spec(path), MeshSize(global_size=0.025, mound_size=0.01))
        volumes[path.name] = volume.info["volume_ml"]
        assert volume.info["repair"]["triangles_turned"] == 0, path.name
        assert len(volume.select(surface_spec(path))[Boundary.RIB]) > 0, path.name
    assert volumes == pytest.approx(dict.fromkeys(volumes, expected_ml), rel=1e-5), volumes


def test_a_legacy_vtk_volume_mesh_imports(tmp_path: Path) -> None:
    import meshio

    from meshes.corpus import dome_volume_mesh

    x, tets, chest, skin = dome_volume_mesh()
    path = tmp_path / "dome.vtk"
    meshio.write(path, meshio.Mesh(1e3 * x, [("tetra", tets)]), binary=True)
    volume = read_volume(surface_spec(path), MeshSize(global_size=0.025, mound_size=0.01))
    assert volume.info["kind"] == "volume mesh"
    assert len(volume.tets) == len(tets)


def test_inconsistent_winding_is_turned_and_recorded(tmp_path: Path) -> None:
    import trimesh

    x, tris = low_poly_cap(noise=0.0)
    flipped = tris.copy()
    flipped[::5] = flipped[::5, ::-1]
    trimesh.Trimesh(1e3 * x, flipped, process=False).export(tmp_path / "flipped.ply")
    volume = read_volume(surface_spec(tmp_path / "flipped.ply"),
                         MeshSize(global_size=0.025, mound_size=0.01))
    assert volume.info["repair"]["triangles_turned"] == len(tris[::5])


def test_a_small_hole_is_filled_and_its_area_recorded(tmp_path: Path) -> None:
    import trimesh

    from meshes.quality import triangle_areas

    x, tris = low_poly_cap(noise=0.0)
    dropped = tris[40:42]  # two triangles of the skin: a hole of well under 1 % of the area
    trimesh.Trimesh(1e3 * x, np.delete(tris, [40, 41], axis=0), process=False).export(
        tmp_path / "holed.stl")
    volume = read_volume(surface_spec(tmp_path / "holed.stl"),
                         MeshSize(global_size=0.025, mound_size=0.01))
    repair = volume.info["repair"]
    assert repair["holes_filled"] == 1
    assert repair["holes"][0]["edges"] == 4
    hole = triangle_areas(x, dropped).sum()
    assert repair["filled_area_m2"] == pytest.approx(hole, rel=0.25)


def test_a_large_hole_is_refused_with_its_size_and_place(tmp_path: Path) -> None:
    import trimesh

    x, tris = low_poly_cap(noise=0.0)
    disc = np.abs(x[tris][:, :, 0]).max(axis=1) < 1e-9  # the whole chest cut is missing
    trimesh.Trimesh(1e3 * x, tris[~disc], process=False).export(tmp_path / "open.stl")
    with pytest.raises(SurfaceNotClosedError,
                       match=r"1 hole\(s\), the largest \d+ cm² .* centred at \(0\.0, "):
        read_volume(surface_spec(tmp_path / "open.stl"), MeshSize(global_size=0.025))


# -- a remesh that holds on a sharp rim -------------------------------------------------------


def test_gmsh_reparametrisation_alone_fails_on_the_low_poly_surface() -> None:
    """The reason for the fallback: gmsh raises on this surface (a traceback, before)."""
    x, tris = low_poly_cap()
    with pytest.raises(Exception, match="Wrong topology of boundary mesh for parametrization"):
        _gmsh_fill(x, tris, MeshSize(global_size=0.025, mound_size=0.01), reparametrise=True)


@pytest.mark.parametrize("size", [0.025, 0.010, 0.006])
@pytest.mark.parametrize("oriented", [False, True])
def test_a_sharp_rim_remeshes_to_the_floor(tmp_path: Path, size: float, oriented: bool) -> None:
    """The low-poly surface remeshes to the floor at 25, 10 and 6 mm, with or without orientation.

    In the project's frame and in scanner LPS with an orientation; the volume kept within 1 %.
    """
    from meshes.checks import enclosed_volume
    from meshes.corpus import _write_stl
    from meshes.importing import prepare_input

    x, tris = low_poly_cap()
    section: dict = {"units": "mm", "remesh": True}
    if oriented:
        frame = Orientation("LPS", "left")
        _write_stl(tmp_path / "cap.stl", 1e3 * frame.to_file(x) + SCANNER_MM, tris[:, [0, 2, 1]])
        section.update(orientation={"axes": "LPS", "side": "left"},
                       surfaces={"rib": {"posterior": {"angle": 30.0, "band": 5.0}}})
    else:
        _write_stl(tmp_path / "cap.stl", 1e3 * x, tris)
        section.update(surfaces={"rib": RIB_PLANE})
    spec = ImportSpec.from_mapping({"path": str(tmp_path / "cap.stl"), **section})
    points, tets, facets, info, _ = prepare_input(spec, MeshSize(global_size=size, mound_size=size))
    assert info["quality_floor"]["cells_below_floor"] == 0, info["fill"]
    assert info["quality_floor"]["min_dihedral_deg"] >= MIN_DIHEDRAL_DEG
    assert info["fill"]["attempts"][0]["outcome"].startswith("failed: ")
    from meshes.quality import tet_volumes

    assert np.abs(tet_volumes(points, tets)).sum() == pytest.approx(enclosed_volume(x, tris),
                                                                    rel=0.01)
    assert len(facets[Boundary.RIB]) > 0


# -- a segmentation's label volume ------------------------------------------------------------


def phantom(folder: Path, suffix: str = ".nii.gz", **kwargs: object) -> Path:
    """The phantom at 1.6 mm (a quick test's size), rotated, anisotropic, in scanner LPS."""
    defaults = {"shape": (100, 110, 70), "spacing_mm": (1.6, 1.5, 2.1), "side": "left",
                "direction": rotation((8.0, -5.0, 12.0)), "scanner_origin_mm": SCANNER_MM}
    return write_phantom(folder / f"phantom{suffix}", **{**defaults, **kwargs})


def image_section(path: Path, **extra: object) -> dict:
    return {"source": "image", "size": {"global_size": 0.025},
            "image": {"path": str(path), "breast_labels": list(BREAST_LABELS),
                      "chest_label": PECTORAL, **extra}}


def tissue_section(path: Path, **extra: object) -> dict:
    """The phantom's mesh section with its fat, gland, skin and tumour labels as tissues."""
    from meshes.phantom import SKIN, TISSUE_LABELS

    section = image_section(path, side="left", tissues=TISSUE_LABELS, **extra)
    section["image"]["breast_labels"] = [*BREAST_LABELS, SKIN]
    section["size"] = {"global_size": 0.01}
    return section


def labelled_tissue_ml(path: Path) -> dict[str, float]:
    """Each tissue's labelled volume in the phantom's image (ml), fat's aside."""
    import SimpleITK as sitk

    from meshes.phantom import TISSUE_LABELS

    voxels = sitk.ReadImage(str(path))
    labels = sitk.GetArrayViewFromImage(voxels)
    voxel_ml = float(np.prod(voxels.GetSpacing())) / 1e3
    return {name: voxel_ml * float(np.isin(labels, values).sum())
            for name, values in TISSUE_LABELS.items()}


@pytest.mark.parametrize("suffix", [".nii.gz", ".nrrd", ".mha"])
def test_a_label_volume_meshes_with_the_chest_label_as_the_rib(tmp_path: Path,
                                                               suffix: str) -> None:
    """A label volume meshes to the floor, the rib where the chest label meets the breast.

    NIfTI, NRRD and MetaImage with a rotated, anisotropic grid; the volume within 3 % of the
    labelled voxels', the rib of the base's size, the mesh in the project's frame.
    """
    config = MeshConfig.from_mapping(image_section(phantom(tmp_path, suffix), side="left"))
    report = make_mesh(config, tmp_path / "mesh.xdmf", tmp_path / "q.json", tmp_path / "m.png")
    info = report["input"]
    assert report["source"] == "image"
    assert info["quality_floor"]["cells_below_floor"] == 0
    assert info["volume_kept"] == pytest.approx(1.0, abs=0.03)
    # the breast's base: the ellipse of the phantom's lateral and cranial semi-axes, on a chest
    # that curves away from it
    assert 1e4 * report["area_m2"]["rib"] == pytest.approx(math.pi * 70 * 65 / 100, rel=0.08)
    from meshes.io import read_mesh

    mesh, _, _ = read_mesh(tmp_path / "mesh.xdmf")
    # the import does not translate: the phantom's base centre is the scanner's SCANNER_MM
    x = mesh.geometry.x - Orientation("LPS", "left").to_project(1e-3 * SCANNER_MM)
    assert x[:, 0].min() == pytest.approx(-0.055, abs=0.004)  # the breast's anterior tip
    assert abs(x[:, 1].mean()) < 0.01 and abs(x[:, 2].mean()) < 0.01


def test_the_formats_agree_on_where_the_voxels_are(tmp_path: Path) -> None:
    """NIfTI stores RAS, NRRD and MetaImage LPS: read back, every header gives the same map."""
    grids = [read_header(phantom(tmp_path, suffix)) for suffix in (".nii", ".nrrd", ".mha")]
    index = np.array([[0, 0, 0], [99, 109, 69], [10.5, 20.25, 3.0]])
    for grid in grids[1:]:
        assert np.allclose(grid.to_physical(index), grids[0].to_physical(index), atol=1e-4)
    assert np.allclose(grids[0].to_index(grids[0].to_physical(index)), index)


def test_the_side_comes_from_a_torso_image_and_is_asked_of_a_breast_image(tmp_path: Path) -> None:
    centred = ImageSpec.from_mapping(image_section(phantom(tmp_path))["image"])
    with pytest.raises(GeometryError, match="does not tell the breast's side.*mesh.image.side"):
        _ = centred.orientation
    for side in ("left", "right"):
        torso = phantom(tmp_path / side, side=side, shape=(260, 110, 70),
                        spacing_mm=(1.6, 1.5, 2.1), breast_offset_mm=120.0)
        spec = ImageSpec.from_mapping(image_section(torso)["image"])
        assert spec.orientation == Orientation("LPS", side)


def test_absent_labels_are_named_with_the_labels_the_image_has(tmp_path: Path) -> None:
    section = image_section(phantom(tmp_path), side="left")
    section["image"]["breast_labels"] = [1, 9]
    with pytest.raises(MeshInputError, match=r"label\(s\) 9 do not occur.*0 \(\d+\), 1 \(\d+\)"):
        make_mesh(MeshConfig.from_mapping(section), tmp_path / "m.xdmf", tmp_path / "q.json",
                  tmp_path / "m.png")
    assert not (tmp_path / "m.xdmf").exists()


def test_a_label_volume_without_a_chest_label_takes_a_posterior_rule(tmp_path: Path) -> None:
    section = image_section(phantom(tmp_path), side="left")
    del section["image"]["chest_label"]
    with pytest.raises(GeometryError, match="needs the rib"):
        MeshConfig.from_mapping(section)
    section["image"]["surfaces"] = {"rib": {"posterior": {"angle": 60.0, "band": 15.0}}}
    report = make_mesh(MeshConfig.from_mapping(section), tmp_path / "m.xdmf",
                       tmp_path / "q.json", tmp_path / "m.png")
    assert report["area_m2"]["rib"] > 0.01


def test_points_go_from_voxels_to_the_project_frame_and_back(tmp_path: Path) -> None:
    """A tumour's centre picked as a voxel lands where the phantom put it, in metres."""
    from meshes.phantom import TUMOUR_CENTRE_M

    image = phantom(tmp_path)
    config = tmp_path / "config.yaml"
    config.write_text(yaml.safe_dump({"mesh": image_section(image, side="left")}))
    frame = Orientation("LPS", "left")
    grid: Grid = read_header(image)
    voxel = grid.to_index(SCANNER_MM + 1e3 * frame.to_file(np.array(TUMOUR_CENTRE_M)))
    (tmp_path / "voxels.csv").write_text("name,x,y,z\ntumour," + ",".join(map(str, voxel)) + "\n")
    run = [sys.executable, "-m", "meshes.frame", str(config)]
    for args in (["voxels.csv", "project.csv", "--to", "project", "--voxels"],
                 ["project.csv", "back.csv", "--to", "file", "--voxels"]):
        done = subprocess.run(run + [str(tmp_path / a) if a.endswith(".csv") else a
                                     for a in args], cwd=REPO, capture_output=True, text=True)
        assert done.returncode == 0, done.stderr
    project = np.loadtxt(tmp_path / "project.csv", delimiter=",", skiprows=1, usecols=(1, 2, 3))
    back = np.loadtxt(tmp_path / "back.csv", delimiter=",", skiprows=1, usecols=(1, 2, 3))
    # the mesh does not translate: the project's position is the scanner's, carried by the map
    assert np.allclose(project, frame.to_project(1e-3 * SCANNER_MM) + TUMOUR_CENTRE_M, atol=1e-9)
    assert np.allclose(back, voxel, atol=1e-6)


def test_preview_shows_the_labels_and_the_rules(tmp_path: Path) -> None:
    config = tmp_path / "config.yaml"
    config.write_text(yaml.safe_dump({"mesh": image_section(phantom(tmp_path), side="left")}))
    done = subprocess.run([sys.executable, "-m", "meshes.preview", str(config)], cwd=REPO,
                          capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    out = done.stdout
    assert "label volume" in out and "voxels of 1.6 x 1.5 x 2.1 mm" in out
    for row in (r"\n\s+1\s+\d+\s+[\d.]+\s+breast", r"\n\s+3\s+\d+\s+[\d.]+\s+chest wall",
                r"\n\s+5\s+\d+\s+[\d.]+\s+not used", r"\nrib\s+\d+\s+[\d.]+\s+[\d.]+%\s+group "
                "'chest_wall'"):
        assert __import__("re").search(row, out), (row, out)
    assert "the rules would do" in out


def test_the_schema_accepts_an_image_source() -> None:
    from meshes.schema import load_schema, schema_errors

    config = yaml.safe_load((REPO / "config.yaml").read_text())
    config["mesh"] = image_section(Path("labels.nii.gz"), side="left")
    assert schema_errors(config, load_schema()) == []
    config["mesh"]["image"]["breast_labels"] = []
    assert schema_errors(config, load_schema())


@pytest.mark.solve
def test_the_clinical_cases_solve_on_an_image_mesh(tmp_path: Path) -> None:
    """Prone and supine solve on the image's mesh, and its unloaded reference is found."""
    config = MeshConfig.from_mapping(image_section(phantom(tmp_path), side="left"))
    make_mesh(config, tmp_path / "mesh.xdmf", tmp_path / "q.json", tmp_path / "m.png")
    for phi in (180.0, 0.0):
        out = tmp_path / f"case_{phi:g}"
        done = subprocess.run([sys.executable, "-m", "fem.cli", str(tmp_path / "mesh.xdmf"),
                               "--c1", "1.0", "--phi", str(phi), "--out", str(out)], cwd=REPO,
                              capture_output=True, text=True)
        assert done.returncode == 0, done.stderr[-2000:]
        summary = json.loads((out / "summary.json").read_text())
        quality = json.loads((tmp_path / "q.json").read_text())
        assert summary["status"] == "converged", (summary["reason"], quality["input"]["fill"])
        assert summary["max_disp_mm"] > 0.5, quality["input"]["fill"]
    done = subprocess.run([sys.executable, "-m", "fem.reference", str(tmp_path / "mesh.xdmf"),
                           "--c1", "1.0", "--phi", "180", "--out", str(tmp_path / "reference")],
                          cwd=REPO, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-2000:]
    reference = json.loads((tmp_path / "reference" / "reference.json").read_text())
    assert reference["converged"] and reference["misfit_mm"][-1] < 0.01


@pytest.mark.workflow
def test_the_workflow_meshes_a_label_volume(tmp_path: Path) -> None:
    """The mesh rule builds from the image (its input), as for any other source."""
    image = phantom(tmp_path)
    config = yaml.safe_load((REPO / "tests" / "config.yaml").read_text())
    config["mesh"] = {**image_section(image.relative_to(tmp_path), side="left"),
                      "fixed": {"rib": "all"}}
    config["fe"]["contact"] = {"obstacle": {"plane": {"point": [1.0, 0, 0],
                                                      "normal": [-1.0, 0, 0]}}}
    (tmp_path / "image.yaml").write_text(yaml.safe_dump(config))
    cmd = [sys.executable, "-m", "snakemake", "-s", str(REPO / "Snakefile"), "-d", str(tmp_path),
           "--configfile", str(tmp_path / "image.yaml"), "-j1", "results/mesh/mesh.xdmf"]
    done = subprocess.run(cmd, capture_output=True, text=True, cwd=tmp_path)
    assert done.returncode == 0, done.stderr[-3000:]
    quality = json.loads((tmp_path / "results/mesh/quality.json").read_text())
    assert quality["source"] == "image"
    assert quality["input"]["quality_floor"]["cells_below_floor"] == 0
    assert "phantom.nii.gz" in done.stderr  # the image is the rule's input


@pytest.mark.parametrize("suffix", [".nhdr", ".mhd"])
def test_a_detached_header_names_its_data_file_as_an_input(tmp_path: Path, suffix: str) -> None:
    """Editing the voxels of a detached header's data file rebuilds the mesh too."""
    image = write_phantom(tmp_path / f"labels{suffix}", (20, 20, 10), (5.0, 5.0, 5.0))
    spec = ImageSpec.from_mapping({"path": str(image), "breast_labels": [1], "chest_label": 3})
    files = spec.input_files()
    assert files[0] == str(image) and len(files) == 2 and Path(files[1]).is_file()
