"""Read and write tagged meshes as XDMF (mesh + cell tags + facet tags) for dolfinx 0.5."""

from __future__ import annotations

import logging
import shutil
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from meshes.exceptions import MeshInputError
from meshes.tags import CELL_TAGS_NAME, FACET_TAGS_NAME, MESH_NAME, TISSUE, Boundary, Tissue

__all__ = [
    "MeshInputError",
    "add_tagged_mesh",
    "boundary_facets",
    "geometry_nodes",
    "from_file_order",
    "moved_mesh",
    "nodes_in_file_order",
    "read_mesh",
    "same_cells",
    "write_gmsh_model",
    "write_tagged_mesh",
]

log = logging.getLogger(__name__)


def add_tagged_mesh(
    model: Any, x: np.ndarray, tets: np.ndarray, facets: dict[Boundary, np.ndarray],
    tissues: np.ndarray | None = None,
) -> dict[Boundary, list[int]]:
    """Put a tagged tetrahedral mesh given as arrays into an empty gmsh model.

    One discrete volume per tissue holds its cells (one, ``tissue``, for a homogeneous
    mesh: ``tissues`` None) and one discrete surface per named boundary its triangles, each
    with its physical group, so that the model converts to dolfinx exactly like a meshed CAD
    model: the cell tags are the tissues' :class:`meshes.tags.Tissue` values.

    Returns:
        The gmsh surface tag of each boundary that has facets.
    """
    tets = np.asarray(tets, dtype=np.int64)
    values = np.full(len(tets), TISSUE) if tissues is None else np.asarray(tissues)
    present = [int(v) for v in np.unique(values)]
    node_holder = None
    for value in present:
        volume = model.addDiscreteEntity(3)
        if node_holder is None:  # dolfinx's gmshio expects node tags 1..N in order
            model.mesh.addNodes(3, volume, np.arange(1, len(x) + 1),
                                np.asarray(x, dtype=float).ravel())
            node_holder = volume
        model.mesh.addElementsByType(volume, 4, [], (tets[values == value] + 1).ravel())
        name = "tissue" if tissues is None else Tissue(value).label
        model.addPhysicalGroup(3, [volume], value, name=name)
    groups: dict[Boundary, list[int]] = {}
    for boundary, tris in facets.items():
        if len(tris) == 0:
            continue
        surface = model.addDiscreteEntity(2)
        model.mesh.addElementsByType(surface, 2, [], (np.asarray(tris, dtype=np.int64) + 1).ravel())
        model.addPhysicalGroup(2, [surface], int(boundary), name=boundary.label)
        groups[boundary] = [surface]
    return groups


def write_gmsh_model(model: Any, xdmf_path: str | Path) -> None:
    """Convert a meshed gmsh model (with physical groups) to dolfinx and write XDMF.

    The pair ``<name>.xdmf`` / ``<name>.h5`` is written in a temporary folder
    beside the target and moved into place, so a crash never leaves half a mesh.
    """
    from dolfinx.io import gmshio
    from mpi4py import MPI

    mesh, cell_tags, facet_tags = gmshio.model_to_mesh(model, MPI.COMM_SELF, 0, gdim=3)
    write_tagged_mesh(mesh, cell_tags, facet_tags, xdmf_path)


def write_tagged_mesh(mesh: Any, cell_tags: Any, facet_tags: Any, xdmf_path: str | Path) -> None:
    """Write a dolfinx mesh with its cell and facet tags as XDMF, under the names it is read by.

    The pair ``<name>.xdmf`` / ``<name>.h5`` is written in a temporary folder beside the
    target and moved into place, so a crash never leaves half a mesh (serial meshes).
    """
    from dolfinx.io import XDMFFile

    comm = mesh.comm
    mesh.name = MESH_NAME
    cell_tags.name = CELL_TAGS_NAME
    facet_tags.name = FACET_TAGS_NAME
    target = Path(xdmf_path)
    target.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=target.parent, prefix=f".{target.stem}.") as tmp:
        tmp_xdmf = Path(tmp) / target.name
        with XDMFFile(comm, str(tmp_xdmf), "w") as xdmf:
            xdmf.write_mesh(mesh)
            mesh.topology.create_connectivity(2, 3)
            xdmf.write_meshtags(cell_tags)
            xdmf.write_meshtags(facet_tags)
        if comm.size == 1:
            without_timestamps(tmp_xdmf.with_suffix(".h5"))
        for suffix in (".h5", ".xdmf"):  # the .xdmf last: it is what marks completion
            shutil.move(str(tmp_xdmf.with_suffix(suffix)), str(target.with_suffix(suffix)))
    log.info("wrote %s (%d cells)", target, mesh.topology.index_map(3).size_global)


def without_timestamps(h5_path: str | Path) -> None:
    """Rewrite an HDF5 file without its objects' modification times (same groups, data, attributes).

    HDF5 stamps every dataset with the second it was written (dolfinx leaves the library's
    default on), so two writes of one mesh differ in a few bytes; without the stamps the same
    mesh gives the same file, byte for byte.
    """
    import h5py

    source = Path(h5_path)
    target = source.with_name(source.name + ".tmp")
    untimed = h5py.h5p.create(h5py.h5p.GROUP_CREATE)
    untimed.set_obj_track_times(False)

    def copy(src: Any, dst: Any) -> None:
        dst.attrs.update(dict(src.attrs))
        for name, item in src.items():
            if isinstance(item, h5py.Group):
                h5py.h5g.create(dst.id, name.encode(), gcpl=untimed)
                copy(item, dst[name])
            else:
                data = dst.create_dataset(name, data=item[()], track_times=False)
                data.attrs.update(dict(item.attrs))

    root = h5py.h5p.create(h5py.h5p.FILE_CREATE)
    root.set_obj_track_times(False)
    with h5py.File(source, "r") as src, h5py.File(
            h5py.h5f.create(str(target).encode(), h5py.h5f.ACC_TRUNC, fcpl=root)) as dst:
        copy(src, dst)
    target.replace(source)


GEOMETRY_DATASET = f"/Mesh/{MESH_NAME}/geometry"
TOPOLOGY_DATASET = f"/Mesh/{MESH_NAME}/topology"


def nodes_in_file_order(mesh: Any, values: np.ndarray | None = None) -> np.ndarray:
    """Per-node ``values`` of a serial mesh (its node positions if None), in its file's order."""
    values = mesh.geometry.x if values is None else np.asarray(values)
    out = np.empty_like(values)
    out[np.asarray(mesh.geometry.input_global_indices, dtype=np.int64)] = values
    return out


def from_file_order(mesh: Any, by_file: np.ndarray) -> np.ndarray:
    """Per-node values given in the file's order, in the serial ``mesh``'s node order."""
    return np.asarray(by_file)[np.asarray(mesh.geometry.input_global_indices, dtype=np.int64)]


def moved_mesh(source: str | Path, mesh: Any, x: np.ndarray, xdmf_path: str | Path) -> Path:
    """Write the mesh file ``source`` with its nodes moved to ``x``, its numbering kept.

    The file's cells, tags and node numbering are those of ``source``: node k of the new file
    is node k of the source, the same material point in another configuration (a loaded shape
    and its reference). Re-writing a mesh through dolfinx would renumber it.

    Args:
        source: a mesh file written by :func:`write_tagged_mesh`.
        mesh: that file read (serially), whose node order ``x`` follows.
        x: (nodes, 3) new positions, in ``mesh``'s node order.
        xdmf_path: the file to write (with its ``.h5``); written whole or not at all.
    """
    import h5py

    source, target = Path(source), Path(xdmf_path)
    x = np.asarray(x, dtype=float)
    if x.shape != mesh.geometry.x.shape:
        raise MeshInputError(f"{x.shape[0]} positions for a mesh of {mesh.geometry.x.shape[0]} "
                             "nodes")
    by_file = nodes_in_file_order(mesh, x)
    target.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=target.parent, prefix=f".{target.stem}.") as tmp:
        tmp_xdmf = Path(tmp) / target.name
        shutil.copyfile(source.with_suffix(".h5"), tmp_xdmf.with_suffix(".h5"))
        with h5py.File(tmp_xdmf.with_suffix(".h5"), "r+") as h5:
            geometry = h5[GEOMETRY_DATASET]
            if geometry.shape[0] != len(by_file):
                raise MeshInputError(f"{source} holds {geometry.shape[0]} nodes, not the "
                                     f"{len(by_file)} of the mesh read from it")
            geometry[...] = by_file[:, : geometry.shape[1]]
        text = source.read_text().replace(f"{source.stem}.h5:", f"{target.stem}.h5:")
        tmp_xdmf.write_text(text)
        for suffix in (".h5", ".xdmf"):  # the .xdmf last: it is what marks completion
            shutil.move(str(tmp_xdmf.with_suffix(suffix)), str(target.with_suffix(suffix)))
    return target


def same_cells(a: str | Path, b: str | Path) -> bool:
    """Whether two mesh files have the same cells on the same node numbering."""
    import h5py

    with h5py.File(Path(a).with_suffix(".h5"), "r") as fa, \
            h5py.File(Path(b).with_suffix(".h5"), "r") as fb:
        ta, tb = fa.get(TOPOLOGY_DATASET), fb.get(TOPOLOGY_DATASET)
        return ta is not None and tb is not None and ta.shape == tb.shape \
            and bool(np.array_equal(ta[...], tb[...]))


def read_mesh(xdmf_path: str | Path, comm: Any = None) -> tuple[Any, Any, Any]:
    """Read a mesh written by :func:`write_gmsh_model`.

    Returns:
        ``(mesh, cell_tags, facet_tags)``.

    Raises:
        MeshInputError: if the file does not exist, is not such an XDMF mesh (a surface file,
            a case's fields), holds no cell or facet tags, or has a node whose coordinates
            are not finite numbers (named by its index in the file).
    """
    from dolfinx.io import XDMFFile
    from mpi4py import MPI

    path = Path(xdmf_path)
    if not path.is_file():
        raise MeshInputError(f"mesh file {path} does not exist")
    if path.suffix != ".xdmf":
        raise MeshInputError(
            f"{path} is not a mesh of this project (an .xdmf with its .h5, as the workflow's "
            "mesh rule writes it); a surface or volume file of another tool is imported by the "
            "mesh rule (mesh.source: file)")
    if not path.with_suffix(".h5").is_file():
        raise MeshInputError(f"mesh file {path} has no {path.with_suffix('.h5').name} beside it")
    comm = MPI.COMM_WORLD if comm is None else comm
    with XDMFFile(comm, str(path), "r") as xdmf:
        try:
            mesh = xdmf.read_mesh(name=MESH_NAME)
            cell_tags = xdmf.read_meshtags(mesh, name=CELL_TAGS_NAME)
        except RuntimeError as err:
            raise MeshInputError(
                f"{path} holds no mesh named {MESH_NAME!r} with its cell tags, as the workflow's "
                "mesh rule writes it (a case's fields.xdmf is not a mesh: give the mesh it was "
                "solved on)") from err
        mesh.topology.create_connectivity(2, 3)
        try:
            facet_tags = xdmf.read_meshtags(mesh, name=FACET_TAGS_NAME)
        except RuntimeError as err:
            raise MeshInputError(f"{path} has no facet tags named {FACET_TAGS_NAME!r}") from err
    bad = ~np.isfinite(mesh.geometry.x).all(axis=1)
    if comm.allreduce(int(bad.any())):
        index = np.asarray(mesh.geometry.input_global_indices)[bad]
        raise MeshInputError(f"{path}: node {int(index[0]) if len(index) else '?'} (of "
                             f"{comm.allreduce(int(bad.sum()))} with coordinates that are not "
                             "finite numbers) has no place: the mesh file is damaged")
    return mesh, cell_tags, facet_tags


def boundary_facets(facet_tags: Any, boundaries: list[Boundary]) -> np.ndarray:
    """Local indices of the facets tagged with any of ``boundaries``."""
    values = [int(b) for b in boundaries]
    return np.sort(facet_tags.indices[np.isin(facet_tags.values, values)]).astype(np.int32)


def geometry_nodes(mesh: Any) -> np.ndarray:
    """Geometry-node indices of every local cell, shape (cells, nodes per cell).

    The first four columns of a tetrahedral mesh are its vertices, whatever the
    geometric order.
    """
    dofmap = mesh.geometry.dofmap
    return dofmap.array.reshape(-1, len(dofmap.links(0)))
