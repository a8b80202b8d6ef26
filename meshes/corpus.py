"""A corpus of anatomies made by the project itself, to prove the pipeline beyond its own breast.

Six geometries, each a ``mesh:`` config section (and, for the imported ones, the file it names,
written here in the form a user's file would come in):

``default``
    the parametric breast of ``config.yaml`` (about 1,000 ml);
``small``
    the parametric breast scaled to a small mound (about 300 ml);
``ptotic``
    a large pendulous parametric breast (about 1,500 ml), its mound lower on the chest;
``hemisphere``
    a hemisphere of radius 60 mm on a flat chest wall (a common cross-code benchmark), as a
    closed STL surface in millimetres in the project's frame, the chest wall chosen by a plane;
``scan``
    an irregular, scan-like closed surface: an ellipsoidal dome on a curved (cylindrical) chest
    wall, with a smooth random relief and small noise on every vertex, written as STL in
    millimetres in DICOM's LPS axes for a left breast; remeshed on import, the chest wall chosen
    by the posterior rule;
``volume``
    a tetrahedral volume mesh (gmsh ``.msh``, physical groups ``chest_wall`` and ``skin``) of an
    elliptic dome leaning caudally, in millimetres in RAS axes for a right breast.

:func:`write_anatomy` writes an anatomy's input into a folder and returns its ``mesh:`` section.
Every random relief is drawn from a fixed seed, so the corpus is the same on every machine.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from meshes.exceptions import GeometryError
from meshes.orientation import Orientation

#: Default largest element size (m) of the imported anatomies: fine enough for a 60 mm
#: hemisphere.
IMPORT_SIZE = 0.008


@dataclass(frozen=True, slots=True)
class Anatomy:
    """One anatomy of the corpus.

    Attributes:
        name: its key (a folder name).
        description: one line for the report's table.
        write: writes the input files into a folder and returns the ``mesh:`` section.
    """

    name: str
    description: str
    write: Callable[[Path], dict[str, Any]]
    """Writes the input into a folder; returns the ``mesh:`` section (sizes filled later)."""


def _parametric(geometry: dict[str, float] | None) -> Callable[[Path], dict[str, Any]]:
    def write(folder: Path) -> dict[str, Any]:
        section: dict[str, Any] = {"source": "parametric"}
        if geometry is not None:
            section["geometry"] = dict(geometry)
        return section

    return write


#: The small breast: the default mound's four lengths scaled by 0.68 (312 ml).
SMALL = {
    "mound_length": 0.051, "mound_radius_lateral": 0.0442, "mound_radius_cranial": 0.0408,
    "mound_offset": 0.0204, "fold_radius": 0.007,
}
#: The large ptotic breast: longer, wider and lower on a longer chest (about 1,480 ml).
PTOTIC = {
    "mound_length": 0.084, "mound_radius_lateral": 0.07, "mound_radius_cranial": 0.068,
    "mound_offset": 0.045, "mound_z": -0.015, "z_caudal": -0.13,
}


def _nodes(model: Any) -> tuple[np.ndarray, Callable[..., np.ndarray]]:
    """A meshed gmsh model's nodes (m), and its elements of a type as rows of node indices."""
    tags, coords, _ = model.mesh.getNodes()
    index = np.full(int(tags.max()) + 1, -1, dtype=np.int64)
    index[tags.astype(np.int64)] = np.arange(len(tags))

    def elements(element_type: int, per_element: int, entity: int = -1) -> np.ndarray:
        _, nodes = model.mesh.getElementsByType(element_type, entity)
        return index[nodes.astype(np.int64)].reshape(-1, per_element)

    return coords.reshape(-1, 3), elements


def _surface_triangles(model: Any) -> tuple[np.ndarray, np.ndarray]:
    """Nodes (m) and triangles of a gmsh model meshed in 2D."""
    x, elements = _nodes(model)
    tris = elements(2, 3)
    used = np.unique(tris)
    remap = np.full(len(x), -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    return x[used], remap[tris]


def _meshed_surface(model: Any, size: float) -> tuple[np.ndarray, np.ndarray]:
    """Mesh the model's OCC surfaces at ``size`` (m); nodes and outward-facing triangles."""
    model.occ.synchronize()
    _set_size(size)
    model.mesh.generate(2)
    x, tris = _surface_triangles(model)
    return x, _outward(x, tris)


def _set_size(size: float) -> None:
    import gmsh

    gmsh.option.setNumber("Mesh.MeshSizeMax", size)
    gmsh.option.setNumber("Mesh.MeshSizeMin", 0.5 * size)


def _outward(x: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """The triangles, reordered so that the enclosed volume is positive (normals outwards)."""
    a, b, c = x[tris[:, 0]], x[tris[:, 1]], x[tris[:, 2]]
    volume = np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0
    return tris if volume > 0 else tris[:, [0, 2, 1]]


def _write_stl(path: Path, x_mm: np.ndarray, tris: np.ndarray) -> None:
    import meshio

    meshio.write(path, meshio.Mesh(x_mm, [("triangle", tris)]), binary=True)


def hemisphere_surface(radius: float = 0.06, size: float = 0.006) -> tuple[np.ndarray, np.ndarray]:
    """A closed hemisphere standing anterior (−x) of a flat chest wall at x = 0, metres."""
    from meshes.build import gmsh_session

    with gmsh_session("hemisphere") as model:
        ball = model.occ.addSphere(0, 0, 0, radius)
        box = model.occ.addBox(-2 * radius, -2 * radius, -2 * radius, 2 * radius, 4 * radius,
                               4 * radius)
        model.occ.intersect([(3, ball)], [(3, box)])
        return _meshed_surface(model, size)


def scan_surface(
    size: float = 0.005, relief: float = 0.0015, noise: float = 0.0002, seed: int = 7
) -> tuple[np.ndarray, np.ndarray]:
    """An irregular dome on a curved chest wall, project's frame, metres.

    An ellipsoid (semi-axes 60 / 72 / 66 mm along x / y / z, its centre on the chest) cut by a
    cylinder of radius 160 mm along z (the chest wall, curving posteriorly away from the
    midline), its nodes then moved along their normals by a smooth random relief (a few long
    waves, ``relief`` metres) and by independent noise (``noise`` metres), as a surface scan or a
    segmentation gives.
    """
    from meshes.build import gmsh_session

    rng = np.random.default_rng(seed)
    chest = 0.16
    with gmsh_session("scan") as model:
        dome = model.occ.addSphere(0, 0, 0, 1.0)
        model.occ.dilate([(3, dome)], 0, 0, 0, 0.060, 0.072, 0.066)
        body = model.occ.addCylinder(chest, 0, -0.2, 0, 0, 0.4, chest)
        model.occ.cut([(3, dome)], [(3, body)])
        x, tris = _meshed_surface(model, size)
    normals = np.zeros_like(x)
    a, b, c = x[tris[:, 0]], x[tris[:, 1]], x[tris[:, 2]]
    face_normals = np.cross(b - a, c - a)
    for k in range(3):
        np.add.at(normals, tris[:, k], face_normals)
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    waves = np.zeros(len(x))
    for _ in range(6):
        k = rng.normal(size=3) * 40.0  # wavelengths of ~0.1 m
        waves += np.sin(x @ k + rng.uniform(0, 2 * math.pi))
    waves *= relief / np.abs(waves).max()
    # no relief on the chest wall (a segmentation's cut), so the rule selects a clean patch
    on_chest = np.abs(np.hypot(x[:, 0] - chest, x[:, 1]) - chest) < 1e-6
    shift = waves + rng.normal(scale=noise, size=len(x))
    shift[on_chest] = rng.normal(scale=noise, size=int(on_chest.sum()))
    return x + shift[:, None] * normals, tris


def rim_surface(
    size: float = 0.004, chest: float = 0.14, semi_axes: tuple[float, float, float] = (
        0.05, 0.085, 0.08), depth: float = 0.02,
) -> tuple[np.ndarray, np.ndarray]:
    """A breast cut from a torso: a closed surface whose skin meets the chest wall in a sharp rim.

    A flat ellipsoid (``semi_axes`` along x / y / z), its centre ``depth`` posterior of a
    chest wall that curves posteriorly away from the midline (a cylinder of radius ``chest``
    along z), cut by it, as a surface exported from a torso model is: the skin meets the chest
    wall at a shallow angle, so near the rim the tissue is a wedge a few millimetres thick. A
    posterior rule that takes the chest wall's flatter middle leaves the wedge's underside as
    skin, which then faces the skin above it across the tissue.
    """
    from meshes.build import gmsh_session

    with gmsh_session("rim") as model:
        dome = model.occ.addSphere(0, 0, 0, 1.0)
        model.occ.dilate([(3, dome)], 0, 0, 0, *semi_axes)
        model.occ.translate([(3, dome)], depth, 0, 0)
        body = model.occ.addCylinder(chest, 0, -0.3, 0, 0, 0.6, chest)
        model.occ.cut([(3, dome)], [(3, body)])
        return _meshed_surface(model, size)


def rim_section(path: str | Path, angle_deg: float = 30.0) -> dict[str, Any]:
    """Write :func:`rim_surface` as an STL (mm) at ``path``; its ``mesh:`` section's ``file``.

    Remeshed, its chest wall found by the posterior rule (``angle_deg``, a 50 mm band).
    """
    x, tris = rim_surface()
    _write_stl(Path(path), 1e3 * x, tris)
    return {
        "path": str(path),
        "units": "mm",
        "remesh": True,
        "orientation": {"axes": "project", "side": "left"},
        "surfaces": {"rib": {"posterior": {"angle": angle_deg, "band": 50.0}}},
    }


def dome_volume_mesh(size: float = 0.007) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """An elliptic dome leaning caudally on a flat chest wall at x = 0, meshed with tetrahedra.

    Returns:
        ``(x (m), tets, chest-wall triangles, skin triangles)``.
    """
    from meshes.build import gmsh_session

    with gmsh_session("dome") as model:
        dome = model.occ.addSphere(0, 0, 0, 1.0)
        model.occ.dilate([(3, dome)], 0, 0, 0, 0.075, 0.065, 0.06)
        # lean the dome's tip caudally (−z) by shearing it: rotate then cut flat
        model.occ.rotate([(3, dome)], 0, 0, 0, 0, 1, 0, math.radians(-20.0))
        box = model.occ.addBox(-0.3, -0.3, -0.3, 0.3, 0.6, 0.6)
        out, _ = model.occ.intersect([(3, dome)], [(3, box)])
        model.occ.synchronize()
        volume = out[0][1]
        faces = [tag for _, tag in model.getBoundary([(3, volume)], oriented=False)]
        flat = [f for f in faces if abs(model.occ.getCenterOfMass(2, f)[0]) < 1e-9]
        if len(flat) != 1:
            raise GeometryError(f"the dome has {len(flat)} flat faces, expected one")
        model.addPhysicalGroup(3, [volume], 1, "tissue")
        model.addPhysicalGroup(2, flat, 2, "chest_wall")
        model.addPhysicalGroup(2, [f for f in faces if f not in flat], 3, "skin")
        _set_size(size)
        model.mesh.generate(3)
        x, elements = _nodes(model)
        tets = elements(4, 4)
        chest = np.concatenate([elements(2, 3, f) for f in flat])
        skin = np.concatenate([elements(2, 3, f) for f in faces if f not in flat])
    return x, tets, chest, skin


def _write_hemisphere(folder: Path) -> dict[str, Any]:
    x, tris = hemisphere_surface()
    _write_stl(folder / "hemisphere.stl", 1e3 * x, tris)
    return {
        "source": "file",
        "file": {
            "path": str(folder / "hemisphere.stl"),
            "units": "mm",
            "surfaces": {"rib": {"plane": {"point": [0, 0, 0], "normal": [1, 0, 0]},
                                 "distance": 0.5}},
        },
    }


#: Where the scan sits in the scanner's coordinates (mm): images are rarely centred on a breast.
SCAN_ORIGIN_MM = np.array([92.0, -31.0, 1184.0])


def _write_scan(folder: Path) -> dict[str, Any]:
    x, tris = scan_surface()
    orientation = Orientation("LPS", "left")
    file_x = 1e3 * orientation.to_file(x) + SCAN_ORIGIN_MM
    if orientation.mirrors:  # the reflection turns the normals inwards: keep them outwards
        tris = tris[:, [0, 2, 1]]
    _write_stl(folder / "scan_lps.stl", file_x, tris)
    return {
        "source": "file",
        "file": {
            "path": str(folder / "scan_lps.stl"),
            "units": "mm",
            "remesh": True,
            "orientation": {"axes": "LPS", "side": "left"},
            "surfaces": {"rib": {"posterior": {"angle": 60.0, "band": 25.0}}},
        },
    }


def _write_volume(folder: Path) -> dict[str, Any]:
    import meshio

    x, tets, chest, skin = dome_volume_mesh()
    orientation = Orientation("RAS", "right")
    file_x = 1e3 * orientation.to_file(x)
    cells = [("tetra", tets), ("triangle", np.concatenate([chest, skin]))]
    physical = [np.full(len(tets), 1), np.concatenate([np.full(len(chest), 2),
                                                       np.full(len(skin), 3)])]
    mesh = meshio.Mesh(
        file_x, cells,
        cell_data={"gmsh:physical": physical, "gmsh:geometrical": physical},
        field_data={"tissue": np.array([1, 3]), "chest_wall": np.array([2, 2]),
                    "skin": np.array([3, 2])},
    )
    path = folder / "dome_ras.msh"
    meshio.write(path, mesh, file_format="gmsh22", binary=False)
    return {
        "source": "file",
        "file": {
            "path": str(path),
            "units": "mm",
            "orientation": {"axes": "RAS", "side": "right"},
            "surfaces": {"rib": {"group": "chest_wall"}},
        },
    }


ANATOMIES: dict[str, Anatomy] = {
    a.name: a
    for a in (
        Anatomy("default", "the parametric breast of config.yaml", _parametric(None)),
        Anatomy("small", "parametric, a small mound", _parametric(SMALL)),
        Anatomy("ptotic", "parametric, a large pendulous mound", _parametric(PTOTIC)),
        Anatomy("hemisphere", "hemisphere r = 60 mm on a flat chest wall (STL, mm)",
                _write_hemisphere),
        Anatomy("scan", "irregular scan-like surface on a curved chest wall (STL, mm, LPS, "
                "left, remeshed)", _write_scan),
        Anatomy("volume", "tetrahedral volume mesh of a leaning dome (msh, mm, RAS, right)",
                _write_volume),
    )
}


def write_anatomy(
    name: str, folder: str | Path, base: dict[str, Any], import_size: float = IMPORT_SIZE
) -> dict[str, Any]:
    """Write anatomy ``name``'s input into ``folder``; return its complete ``mesh:`` section.

    Args:
        name: a key of :data:`ANATOMIES`.
        folder: where its input file goes (created).
        base: the config's ``mesh:`` section, whose size and fixed surfaces the parametric
            anatomies keep (and whose geometry they change).
        import_size: the largest element size (m) of an imported anatomy.

    Raises:
        GeometryError: for an unknown name.
    """
    if name not in ANATOMIES:
        raise GeometryError(f"unknown anatomy {name!r}; the corpus has {', '.join(ANATOMIES)}")
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    section = ANATOMIES[name].write(folder)
    if section["source"] == "parametric":
        geometry = {**(base.get("geometry") or {}), **section.get("geometry", {})}
        kept = {key: value for key, value in base.items() if key in ("size", "fixed")}
        return {**kept, "source": "parametric", "geometry": geometry}
    size = {"global_size": import_size, "mound_size": import_size, "order": 1}
    return {**section, "size": size, "fixed": {"rib": "all"}}


__all__ = ["ANATOMIES", "Anatomy", "dome_volume_mesh", "hemisphere_surface", "rim_section",
           "rim_surface", "scan_surface", "write_anatomy"]
