"""Predicted and compared displacement fields on the mesh, as XDMF for ParaView.

The material points are the mesh's vertices; the fields are written on its tetrahedra
(higher-order nodes dropped) with meshio.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from fem.aggregate import mesh_cells
from fem.exceptions import DatasetError
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
    try:
        cells = mesh_cells(mesh_xdmf, node_index, X)
    except DatasetError as err:
        raise ModelFileError(f"{err} (the surrogate's training points)") from None
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
    path: str | Path, mesh_xdmf: str | Path, model: Surrogate, u_mm: np.ndarray,
    movement_mm: np.ndarray | None = None,
) -> None:
    """Write a predicted displacement (mm) and its magnitude on the mesh as XDMF.

    With ``movement_mm`` (each point's movement from another posture, mm) that field and its
    magnitude too, as ``movement_mm`` and ``movement_magnitude_mm``.
    """
    fields = {"displacement_mm": u_mm, "displacement_magnitude_mm": np.linalg.norm(u_mm, axis=1)}
    if movement_mm is not None:
        fields |= {"movement_mm": movement_mm,
                   "movement_magnitude_mm": np.linalg.norm(movement_mm, axis=1)}
    write_point_fields_xdmf(path, mesh_xdmf, model.node_index, model.X, fields)
