"""Per-case outputs: ParaView XDMF, displacement at the material points, summary JSON.

Material points are the mesh vertices, identified by their index in the mesh
file (dolfinx's ``input_global_indices``), so that every case of a sweep, run
serially or under MPI, lists the same points in the same order.

Files of one case (all written atomically: a temporary folder, then renames,
``summary.json`` last so that its presence means the case is complete):

``fields.xdmf`` / ``fields.h5``
    mesh with point data ``displacement`` (m), ``pressure`` (Pa), ``displacement_magnitude``
    (m) and cell data ``J`` (det F at the cell midpoint).
``points.h5``
    ``/node_index`` (N,) int64, ``/X`` (N, 3) reference coordinates (m), ``/u`` (N, 3)
    displacement (m), ``/fixed`` (N,) bool: on a fully clamped surface.
``summary.json``
    status, parameters, load path, Newton iterations, timings (see :mod:`fem.case`).
"""

from __future__ import annotations

import json
import logging
import os
import shutil
from pathlib import Path
from typing import Any

import numpy as np
import ufl
from dolfinx import fem
from mpi4py import MPI

from fem.exceptions import InvalidParameterError
from meshes.io import boundary_facets, geometry_nodes
from meshes.tags import Boundary

log = logging.getLogger(__name__)

FIELDS_NAME = "fields.xdmf"
POINTS_NAME = "points.h5"
SUMMARY_NAME = "summary.json"
CASE_FILES = (FIELDS_NAME, "fields.h5", POINTS_NAME, SUMMARY_NAME)


def vertex_nodes(mesh: Any) -> np.ndarray:
    """Local geometry-node indices of the owned mesh vertices (sorted)."""
    nodes = np.unique(geometry_nodes(mesh)[:, :4])
    return nodes[nodes < mesh.geometry.index_map().size_local]


def node_to_vertex_dof(mesh: Any, V: fem.FunctionSpace) -> np.ndarray:
    """Map geometry-node index -> (block) dof at that vertex of a Lagrange space.

    Lagrange elements list their vertex dofs first, so the value at a vertex is read
    straight from the coefficient vector: no interpolation, hence exact zeros where a
    Dirichlet condition holds.
    """
    geo_nodes = geometry_nodes(mesh)[:, :4]
    dofs = V.dofmap.list.array.reshape(geo_nodes.shape[0], -1)[:, :4]
    node_to_dof = np.full(mesh.geometry.x.shape[0], -1, dtype=np.int64)
    node_to_dof[geo_nodes.ravel()] = dofs.ravel()
    return node_to_dof


def _gather_by_node(
    mesh: Any, nodes: np.ndarray, values: np.ndarray
) -> tuple[np.ndarray, np.ndarray] | None:
    """Gather per-vertex values to rank 0, ordered by mesh-file node index."""
    index = np.asarray(mesh.geometry.input_global_indices, dtype=np.int64)[nodes]
    gathered = mesh.comm.gather((index, values), root=0)
    if mesh.comm.rank != 0:
        return None
    index = np.concatenate([g[0] for g in gathered])
    values = np.concatenate([g[1] for g in gathered])
    index, first = np.unique(index, return_index=True)
    return index, values[first]


def gather_vertex_values(mesh: Any, f: fem.Function) -> tuple[np.ndarray, np.ndarray] | None:
    """Values of a Lagrange function at the mesh vertices, ordered by mesh-file node index.

    Returns:
        ``(node_index, values)`` on rank 0 (values (N,) or (N, bs)), ``None`` elsewhere.
    """
    nodes = vertex_nodes(mesh)
    V = f.function_space
    bs = V.dofmap.index_map_bs
    values = f.x.array.reshape(-1, bs)[node_to_vertex_dof(mesh, V)[nodes]]
    return _gather_by_node(mesh, nodes, values if bs > 1 else values.ravel())


def gather_vertex_coordinates(mesh: Any) -> tuple[np.ndarray, np.ndarray] | None:
    """Reference coordinates of the vertices, ordered by mesh-file node index (rank 0)."""
    nodes = vertex_nodes(mesh)
    return _gather_by_node(mesh, nodes, mesh.geometry.x[nodes])


def _on_boundaries(mesh: Any, facet_tags: Any, boundaries: list[Boundary]) -> np.ndarray:
    """Per-geometry-node flag: a vertex of a local facet tagged with any of ``boundaries``."""
    from dolfinx.cpp.mesh import entities_to_geometry

    facets = boundary_facets(facet_tags, boundaries)
    flags = np.zeros(mesh.geometry.x.shape[0], dtype=bool)
    if facets.size:
        vertices = entities_to_geometry(mesh._mesh, mesh.topology.dim - 1, facets, False)[:, :3]
        flags[vertices.ravel()] = True
    return flags


def boundary_vertex_nodes(mesh: Any, facet_tags: Any, boundaries: list[Boundary]) -> np.ndarray:
    """Local geometry-node indices of the owned vertices on ``boundaries`` (sorted)."""
    nodes = vertex_nodes(mesh)
    return nodes[_on_boundaries(mesh, facet_tags, boundaries)[nodes]]


def gather_boundary_vertices(
    mesh: Any, facet_tags: Any, boundaries: list[Boundary]
) -> tuple[np.ndarray, np.ndarray] | None:
    """Per-vertex flag: on a facet tagged with any of ``boundaries`` (rank 0)."""
    flags = _on_boundaries(mesh, facet_tags, boundaries)
    nodes = vertex_nodes(mesh)
    gathered = _gather_by_node(mesh, nodes, flags[nodes])
    # A vertex shared between ranks is on the boundary if any rank says so. Every rank
    # must take part in this second gather (returning early on rank > 0 deadlocked).
    index = np.asarray(mesh.geometry.input_global_indices, dtype=np.int64)[nodes]
    on = mesh.comm.gather(index[flags[nodes]], root=0)
    if gathered is None:
        return None
    return gathered[0], np.isin(gathered[0], np.concatenate(on))


def _output_space(mesh: Any, shape: tuple[int, ...]) -> fem.FunctionSpace:
    """Lagrange space matching the geometry degree (what XDMFFile can write)."""
    degree = mesh.geometry.cmap.degree
    if shape:
        return fem.VectorFunctionSpace(mesh, ("Lagrange", degree))
    return fem.FunctionSpace(mesh, ("Lagrange", degree))


def write_fields(
    path: Path, mesh: Any, u: fem.Function, p: fem.Function | None, J: ufl.core.expr.Expr
) -> None:
    """Write displacement, pressure, |u| and J to an XDMF file for ParaView."""
    from dolfinx.io import XDMFFile

    Vout = _output_space(mesh, (3,))
    u_out = fem.Function(Vout, name="displacement")
    u_out.interpolate(u)
    Sout = _output_space(mesh, ())
    magnitude = fem.Function(Sout, name="displacement_magnitude")
    magnitude.interpolate(
        fem.Expression(ufl.sqrt(ufl.dot(u_out, u_out)), Sout.element.interpolation_points())
    )
    DG0 = fem.FunctionSpace(mesh, ("DG", 0))
    J_out = fem.Function(DG0, name="J")
    J_out.interpolate(fem.Expression(J, DG0.element.interpolation_points()))
    with XDMFFile(mesh.comm, str(path), "w") as xdmf:
        xdmf.write_mesh(mesh)
        xdmf.write_function(u_out)
        xdmf.write_function(magnitude)
        if p is not None:
            p_out = fem.Function(Sout, name="pressure")
            p_out.interpolate(p)
            xdmf.write_function(p_out)
        xdmf.write_function(J_out)


class CaseWriter:
    """Stage a case's files in a temporary folder, then move them into place.

    ``summary.json`` is moved last, so a case folder with a summary is complete and a
    crash leaves no partial file under a final name.
    """

    def __init__(self, outdir: str | Path, comm: Any = MPI.COMM_WORLD) -> None:
        self.outdir = Path(outdir)
        self.comm = comm
        self.tmp = self.outdir / ".partial"
        if comm.rank == 0:
            # files staged by a run that was killed before its commit are stale
            shutil.rmtree(self.tmp, ignore_errors=True)
            self.tmp.mkdir(parents=True)
        comm.barrier()

    def path(self, name: str) -> Path:
        """Where to stage ``name``."""
        return self.tmp / name

    def commit(self, summary: dict[str, Any]) -> None:
        """Write the summary and move every staged file into the case folder."""
        self.comm.barrier()
        if self.comm.rank == 0:
            with open(self.tmp / SUMMARY_NAME, "w") as fh:
                json.dump(summary, fh, indent=2, default=_json_default)
                fh.write("\n")
            staged = sorted(self.tmp.iterdir(), key=lambda p: p.name == SUMMARY_NAME)
            for item in staged:
                os.replace(item, self.outdir / item.name)
            shutil.rmtree(self.tmp, ignore_errors=True)
        self.comm.barrier()


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    raise TypeError(f"{type(obj).__name__} is not JSON serialisable")


def node_dofs(mesh: Any, V: Any) -> np.ndarray:
    """The displacement space's (block) dof at every geometry node.

    The geometry nodes of a straight mesh are its vertices, the first four local dofs of any
    Lagrange element; those of a curved (order 2) mesh add the edge midpoints, which are the
    dofs of a P2 displacement with the same local layout.

    Raises:
        InvalidParameterError: for a curved mesh with another displacement degree.
    """
    nodes = geometry_nodes(mesh)
    dofs = V.dofmap.list.array.reshape(nodes.shape[0], -1)
    k = nodes.shape[1]
    if k > 4 and dofs.shape[1] != k:
        raise InvalidParameterError(
            f"the reference state of a curved mesh ({k} nodes per cell) needs a displacement "
            f"with the same nodes (P2), not {dofs.shape[1]} dofs per cell"
        )
    out = np.full(mesh.geometry.x.shape[0], -1, dtype=np.int64)
    out[nodes.ravel()] = dofs[:, :k].ravel()
    return out


def node_displacement(problem: Any) -> np.ndarray:
    """The solved displacement at every geometry node (nodes, 3), in the mesh's node order."""
    u = problem.displacement()
    return u.x.array.reshape(-1, 3)[node_dofs(problem.mesh, u.function_space)]
