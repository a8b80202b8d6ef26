"""Predicted and compared displacement fields on the mesh, as XDMF for ParaView.

The material points are the mesh's vertices; the fields are written on its tetrahedra
(higher-order nodes dropped) with meshio.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from surrogate.exceptions import ModelFileError
from surrogate.predict import Surrogate


def read_mesh_vertices(
    mesh_xdmf: str | Path, node_index: np.ndarray, X: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Tetrahedra of the mesh on the material points: ``(points (N, 3), cells (C, 4))``.

    The material points are the mesh vertices, listed by ``node_index`` into the mesh
    file's geometry; higher-order nodes are dropped.

    Raises:
        ModelFileError: if the mesh is not the one the points come from.
    """
    import h5py

    from meshes.tags import MESH_NAME

    mesh_h5 = Path(mesh_xdmf).with_suffix(".h5")
    try:
        with h5py.File(mesh_h5, "r") as h5:
            geometry = h5[f"Mesh/{MESH_NAME}/geometry"][...]
            topology = h5[f"Mesh/{MESH_NAME}/topology"][...]
    except (OSError, KeyError) as err:
        raise ModelFileError(f"cannot read the mesh {mesh_h5}: {err}") from None
    if node_index.max() >= geometry.shape[0] or not np.allclose(geometry[node_index], X, atol=1e-9):
        raise ModelFileError(f"{mesh_xdmf} is not the mesh the surrogate was trained on")
    lookup = np.full(geometry.shape[0], -1, np.int64)
    lookup[node_index] = np.arange(node_index.size)
    cells = lookup[topology[:, :4]]
    if np.any(cells < 0):
        raise ModelFileError(f"{mesh_xdmf}: a tetrahedron vertex is not a material point")
    return X, cells


def write_point_fields_xdmf(
    path: str | Path,
    mesh_xdmf: str | Path,
    node_index: np.ndarray,
    X: np.ndarray,
    fields: dict[str, np.ndarray],
) -> None:
    """Write per-point fields on the mesh's tetrahedra as XDMF + HDF5 (meshio), for ParaView."""
    import meshio

    points, cells = read_mesh_vertices(mesh_xdmf, node_index, X)
    mesh = meshio.Mesh(
        points, [("tetra", cells)], point_data={k: np.asarray(v) for k, v in fields.items()}
    )
    meshio.write(str(path), mesh)


def write_prediction_xdmf(
    path: str | Path, mesh_xdmf: str | Path, model: Surrogate, u_mm: np.ndarray
) -> None:
    """Write a predicted displacement (mm) and its magnitude on the mesh as XDMF."""
    write_point_fields_xdmf(
        path,
        mesh_xdmf,
        model.node_index,
        model.X,
        {"displacement_mm": u_mm, "displacement_magnitude_mm": np.linalg.norm(u_mm, axis=1)},
    )
