"""Read a user's surface or volume mesh file into points, tetrahedra and tagged triangles (metres).

Each kind of file is read by the library made for it, as the tools of the field write it:

* surfaces of modelling and scanning tools (``.obj`` with texture coordinates, normals, groups
  and quads; ``.ply`` with colours; ASCII and binary ``.stl``; ``.off``) with trimesh, which
  splits quads and polygons into triangles;
* VTK's XML polygon data (``.vtp``) with VTK's own reader;
* volume meshes (``.msh``, ``.vtu``, legacy ``.vtk``, single-grid ``.xdmf``) with meshio; an
  XDMF written by dolfinx (several grids: mesh and tags), which meshio cannot read, with
  dolfinx, its facet tags becoming named groups.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from meshes.checks import UNITS, merge_duplicate_points
from meshes.exceptions import MeshInputError
from meshes.tags import Boundary

SURFACE_SUFFIXES = (".stl", ".obj", ".ply", ".off", ".vtp")
VOLUME_SUFFIXES = (".msh", ".vtu", ".vtk", ".xdmf")
"""A legacy ``.vtk`` file may hold a surface as well: the content decides, not the suffix."""

#: Surface files read with trimesh (the others with meshio, ``.vtp`` with VTK).
TRIMESH_SUFFIXES = (".stl", ".obj", ".ply", ".off")


@dataclass(frozen=True)
class InputMesh:
    """A file's content in metres: points, tetrahedra (possibly none), triangles and groups.

    Attributes:
        points: (N, 3) coordinates, metres.
        tets: (n, 4) tetrahedra, or (0, 4) for a surface.
        triangles: (m, 3) triangles of the file.
        triangle_groups: (m,) integer group of each triangle (-1: none).
        group_names: physical name -> group integer.
    """

    points: np.ndarray
    tets: np.ndarray
    triangles: np.ndarray
    triangle_groups: np.ndarray
    group_names: dict[str, int]

    @property
    def is_volume(self) -> bool:
        """Whether the file holds tetrahedra (else it is a surface)."""
        return len(self.tets) > 0


def read_input(path: str | Path, units: str) -> InputMesh:
    """Read a surface or volume mesh with meshio and convert it to metres.

    Raises:
        MeshInputError: if the file is missing, unreadable, or holds neither
            tetrahedra nor triangles.
    """
    import meshio

    path = Path(path)
    if not path.is_file():
        raise MeshInputError(f"mesh file {path} does not exist")
    suffix = path.suffix.lower()
    if suffix in TRIMESH_SUFFIXES:
        return _read_surface(path, units)
    if suffix == ".vtp":
        return _read_vtp(path, units)
    try:
        mesh = meshio.read(str(path))
    # meshio raises many types (and its XDMF reader calls sys.exit): all mean "cannot read"
    except (Exception, SystemExit) as err:
        if path.suffix.lower() == ".xdmf":
            # meshio reads single-grid XDMF only; dolfinx writes mesh and tags as several
            return _read_dolfinx_xdmf(path, units, err)
        raise MeshInputError(f"cannot read {path}: {type(err).__name__}: {err}") from err
    raw = np.asarray(mesh.points, dtype=float)
    if raw.size == 0 or sum(len(block.data) for block in mesh.cells) == 0:
        raise MeshInputError(f"{path} is empty: it holds no points or no cells")
    points = raw.reshape(len(raw), -1)[:, :3] * UNITS[units]
    tets, tris, groups = [], [], []
    physical = mesh.cell_data.get("gmsh:physical")
    int_data = [
        name
        for name, blocks in mesh.cell_data.items()
        if name != "gmsh:geometrical"
        and all(np.issubdtype(np.asarray(b).dtype, np.integer) for b in blocks)
    ]
    tag_name = "gmsh:physical" if physical is not None else (int_data[0] if int_data else None)
    for k, block in enumerate(mesh.cells):
        data = np.asarray(block.data, dtype=np.int64)
        if block.type in ("tetra", "tetra10"):
            tets.append(data[:, :4])  # vertices only: imported meshes are linear
        elif block.type in ("triangle", "triangle6"):
            tris.append(data[:, :3])
            tags = np.asarray(mesh.cell_data[tag_name][k]).reshape(-1) if tag_name else None
            groups.append(tags.astype(np.int64) if tags is not None else np.full(len(data), -1))
        elif block.type == "quad":
            # split quads of a surface scan into two triangles each
            tris.append(np.concatenate([data[:, [0, 1, 2]], data[:, [0, 2, 3]]]))
            groups.append(np.full(2 * len(data), -1))
    if not tets and not tris:
        types = sorted({b.type for b in mesh.cells})
        raise MeshInputError(
            f"{path} holds no tetrahedra or triangles (cell types: {', '.join(types) or 'none'})"
        )
    names = {str(name): int(value[0]) for name, value in (mesh.field_data or {}).items()}
    result = InputMesh(
        points=points,
        tets=np.concatenate(tets) if tets else np.empty((0, 4), dtype=np.int64),
        triangles=np.concatenate(tris) if tris else np.empty((0, 3), dtype=np.int64),
        triangle_groups=np.concatenate(groups) if groups else np.empty(0, dtype=np.int64),
        group_names=names,
    )
    check_finite(result, path)
    return result


def _surface_mesh(points: np.ndarray, triangles: np.ndarray, units: str,
                  path: Path) -> InputMesh:
    if len(points) == 0 or len(triangles) == 0:
        raise MeshInputError(f"{path} is empty: it holds no points or no cells")
    mesh = InputMesh(
        points=np.asarray(points, dtype=float)[:, :3] * UNITS[units],
        tets=np.empty((0, 4), dtype=np.int64),
        triangles=np.asarray(triangles, dtype=np.int64),
        triangle_groups=np.full(len(triangles), -1, dtype=np.int64),
        group_names={},
    )
    check_finite(mesh, path)
    return mesh


def _read_surface(path: Path, units: str) -> InputMesh:
    """A surface file as modelling and scanning tools write it, with trimesh.

    Texture coordinates, normals, colours and materials are read past; every object and group
    of the file is kept (one surface); quads and polygons become triangles. Vertices split at
    texture seams are merged again by the import.
    """
    import trimesh

    try:
        mesh = trimesh.load(str(path), force="mesh", process=False)
    except Exception as err:  # trimesh raises many types for a broken file
        raise MeshInputError(f"cannot read {path}: {type(err).__name__}: {err}") from err
    if not isinstance(mesh, trimesh.Trimesh):
        raise MeshInputError(f"{path} holds no triangles (read as {type(mesh).__name__})")
    return _surface_mesh(np.asarray(mesh.vertices), np.asarray(mesh.faces), units, path)


def _read_vtp(path: Path, units: str) -> InputMesh:
    """VTK's XML polygon data, with VTK's reader; polygons become triangles."""
    from vtkmodules.util.numpy_support import vtk_to_numpy
    from vtkmodules.vtkFiltersCore import vtkTriangleFilter
    from vtkmodules.vtkIOXML import vtkXMLPolyDataReader

    reader = vtkXMLPolyDataReader()
    if not reader.CanReadFile(str(path)):
        raise MeshInputError(f"cannot read {path}: not a VTK XML PolyData file")
    reader.SetFileName(str(path))
    triangles = vtkTriangleFilter()
    triangles.SetInputConnection(reader.GetOutputPort())
    triangles.PassLinesOff()
    triangles.PassVertsOff()
    triangles.Update()
    data = triangles.GetOutput()
    if data.GetNumberOfPoints() == 0 or data.GetNumberOfPolys() == 0:
        raise MeshInputError(f"{path} is empty: it holds no points or no polygons")
    points = vtk_to_numpy(data.GetPoints().GetData())
    cells = vtk_to_numpy(data.GetPolys().GetConnectivityArray()).reshape(-1, 3)
    return _surface_mesh(points, cells, units, path)


def check_finite(mesh: InputMesh, path: str | Path) -> None:
    """Refuse a file whose elements use a point with a NaN or infinite coordinate.

    Raises:
        MeshInputError: with the number of such points and the first one's index.
    """
    used = np.unique(np.concatenate([mesh.tets.ravel(), mesh.triangles.ravel()]))
    if used.size and (used.min() < 0 or used.max() >= len(mesh.points)):
        raise MeshInputError(f"{path}: its cells refer to points it does not have")
    bad = used[~np.isfinite(mesh.points[used]).all(axis=1)]
    if len(bad):
        raise MeshInputError(
            f"{path}: {len(bad)} point(s) of its cells have a NaN or infinite coordinate, the "
            f"first is point #{bad[0]}; repair the file (a broken export or conversion)"
        )


def _read_dolfinx_xdmf(path: Path, units: str, meshio_error: Exception) -> InputMesh:
    """Read an XDMF file as dolfinx writes it (this project's mesh.xdmf, for instance).

    The facet tags become groups, named after :class:`Boundary` (their values).
    """
    from dolfinx.cpp.mesh import entities_to_geometry
    from dolfinx.io import XDMFFile
    from mpi4py import MPI

    from meshes.io import geometry_nodes
    from meshes.tags import FACET_TAGS_NAME, MESH_NAME

    try:
        with XDMFFile(MPI.COMM_SELF, str(path), "r") as xdmf:
            mesh = xdmf.read_mesh(name=MESH_NAME)
            mesh.topology.create_connectivity(2, 3)
            try:
                tags = xdmf.read_meshtags(mesh, name=FACET_TAGS_NAME)
            except RuntimeError:
                tags = None
    except RuntimeError as err:
        raise MeshInputError(
            f"cannot read {path}: meshio reads single-grid XDMF only ({meshio_error}) and dolfinx "
            f"found no mesh named {MESH_NAME!r} in it ({err})"
        ) from err
    if mesh.topology.cell_name() != "tetrahedron":
        raise MeshInputError(f"{path} holds {mesh.topology.cell_name()} cells, not tetrahedra")
    if tags is not None and len(tags.indices):
        triangles = entities_to_geometry(mesh._mesh, 2, tags.indices, False).astype(np.int64)
        groups = tags.values.astype(np.int64)
    else:
        triangles, groups = np.empty((0, 3), dtype=np.int64), np.empty(0, dtype=np.int64)
    return InputMesh(
        points=np.asarray(mesh.geometry.x, dtype=float) * UNITS[units],
        tets=geometry_nodes(mesh)[:, :4].astype(np.int64),  # vertices only
        triangles=triangles,
        triangle_groups=groups,
        group_names={b.label: int(b) for b in Boundary},
    )


def read_surface(path: str | Path, units: str) -> tuple[np.ndarray, np.ndarray]:
    """Points (metres) and triangles of a surface file used by a ``surface`` rule."""
    surface = read_input(path, units)
    if len(surface.triangles) == 0:
        raise MeshInputError(f"{path} holds no triangles to measure distances from")
    extent = float(np.linalg.norm(np.ptp(surface.points, axis=0)))
    return merge_duplicate_points(surface.points, surface.triangles, 1e-9 * max(extent, 1e-12))
