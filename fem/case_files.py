"""A solved case's files as the dataset reads them: ``summary.json``, ``points.h5``, ``fields.h5``.

:mod:`fem.case` writes a case's material points (:func:`write_points`); aggregation
(:mod:`fem.aggregate`) reads each case's summary and points, checked against its folder's name
(:func:`read_case`), and on a quadratic mesh its field at every node (:func:`gather_nodes`).
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from fem.exceptions import DatasetError

REQUIRED_SUMMARY_KEYS = ("status", "case", "C1", "phi", "theta", "gravity_vector", "load_fraction")
REQUIRED_POINT_FIELDS = ("node_index", "X", "u", "fixed")
STATUSES = ("converged", "failed")
"""The statuses a case's summary may have (:func:`fem.case.run_case` writes one of them)."""
FIELD_DATASET = "Function/displacement/0"
"""Where a case's ``fields.h5`` (:mod:`fem.io`) holds the displacement at the mesh's nodes."""


def read_node_displacement(path: str | Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A case's displacement at every node of its mesh (m), its cells and its nodes (m).

    From the case's ``fields.h5``, where the displacement is given at every node of the mesh's
    geometry: on a quadratic mesh, the FE field's own nodes, so that its shape functions give
    the field anywhere in a cell.

    Raises:
        DatasetError: if the file is missing, unreadable or lacks the displacement or mesh.
    """
    import h5py

    from meshes.io import GEOMETRY_DATASET, TOPOLOGY_DATASET

    try:
        with h5py.File(path, "r") as h5:
            u = np.asarray(h5[FIELD_DATASET], dtype=np.float64)
            cells = np.asarray(h5[TOPOLOGY_DATASET], dtype=np.int64)
            nodes = np.asarray(h5[GEOMETRY_DATASET], dtype=np.float64)
    except (OSError, KeyError) as err:
        raise DatasetError(f"{path}: not a case's fields ({err})") from None
    if u.shape != nodes.shape:
        raise DatasetError(f"{path}: {len(u)} displacement values for {len(nodes)} nodes")
    return u, cells, nodes


@dataclass(frozen=True)
class Nodes:
    """Every node of a quadratic mesh and the cases' displacement there (``/nodes``).

    Attributes:
        X: the nodes (K, 3), m: the vertices and the edge nodes.
        cells: the 10-node tetrahedra as rows of ``X`` (C, 10), corners first.
        vertex: the row of ``X`` of each material point (N,).
        displacement: (M, K, 3) in mm (float32), NaN rows for failed cases; None where the
            dataset was read without it.
    """

    X: np.ndarray
    cells: np.ndarray
    vertex: np.ndarray
    displacement: np.ndarray | None = None


def gather_nodes(
    fields_paths: Sequence[str | Path], converged: np.ndarray, X: np.ndarray
) -> dict[str, np.ndarray] | None:
    """The converged cases' fields at a quadratic mesh's nodes, for ``/nodes``.

    Args:
        fields_paths: each case's ``fields.h5``.
        converged: which cases converged (the others' rows stay NaN).
        X: the material points, which must be nodes of the mesh.

    Returns:
        ``{"X", "cells", "vertex", "displacement" (m)}``, or None where the cells are not
        10-node tetrahedra (a linear mesh: its vertices are all its nodes).

    Raises:
        DatasetError: naming a case whose fields are on another mesh, or a material point that
            is no node.
    """
    from scipy.spatial import cKDTree

    first = int(np.flatnonzero(converged)[0])
    u, cells, nodes = read_node_displacement(fields_paths[first])
    if cells.ndim != 2 or cells.shape[1] != 10:
        return None
    distance, vertex = cKDTree(nodes).query(X)
    if np.any(distance > 1e-9):
        raise DatasetError(f"{fields_paths[first]}: a material point is not a node of its mesh "
                           f"(off by {distance.max():.3g} m)")
    displacement = np.full((len(fields_paths), *nodes.shape), np.nan, dtype=np.float32)
    for i in np.flatnonzero(converged):
        u, c, x = read_node_displacement(fields_paths[i])
        if not (np.array_equal(c, cells) and np.array_equal(x, nodes)):
            raise DatasetError(f"{fields_paths[i]}: another mesh than {fields_paths[first]}'s")
        if not np.all(np.isfinite(u)):
            raise DatasetError(f"{fields_paths[i]}: a converged case's field has NaN/inf")
        displacement[i] = u
    return {"X": nodes, "cells": cells, "vertex": vertex.astype(np.int64),
            "displacement": displacement}


def write_points(
    path: str | Path,
    node_index: np.ndarray,
    X: np.ndarray,
    u: np.ndarray,
    fixed: np.ndarray,
    case: str | None = None,
) -> None:
    """Write a case's material-point file: ``node_index``, ``X`` (m), ``u`` (m), ``fixed``.

    ``case`` (the case folder's name) is kept as an attribute, so that aggregation can tell a
    file copied from another case's folder.
    """
    import h5py

    with h5py.File(path, "w") as h5:
        h5.create_dataset("node_index", data=node_index)
        h5.create_dataset("X", data=X).attrs["units"] = "m"
        h5.create_dataset("u", data=u).attrs["units"] = "m"
        h5.create_dataset("fixed", data=fixed.astype(bool))
        h5.attrs["description"] = "displacement at the mesh vertices (material points)"
        if case is not None:
            h5.attrs["case"] = case


def read_points(path: str | Path) -> dict[str, Any]:
    """Read a case's material-point file (``points.h5``, see :mod:`fem.io`).

    Returns the fields of :data:`REQUIRED_POINT_FIELDS` and ``case``: the case the file was
    written for (None for a file written before the attribute existed).
    """
    import h5py

    try:
        with h5py.File(path, "r") as h5:
            missing = [k for k in REQUIRED_POINT_FIELDS if k not in h5]
            if missing:
                raise DatasetError(f"{path}: missing field(s) {', '.join(missing)}")
            points: dict[str, Any] = {key: h5[key][...] for key in REQUIRED_POINT_FIELDS}
            case = h5.attrs.get("case")
            points["case"] = case.decode() if isinstance(case, bytes) else case
            return points
    except OSError as err:
        raise DatasetError(f"{path}: unreadable or truncated HDF5 file ({err})") from None


def _finite_number(value: Any) -> bool:
    return (
        isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)
    )


def read_summary(path: str | Path) -> dict[str, Any]:
    """Read a case's ``summary.json`` and check the fields the dataset needs.

    Raises:
        DatasetError: naming the file, for a file that is not JSON (or not text), is not a
            JSON object, lacks a field, has an unknown status or a non-numeric parameter.
    """
    try:
        with open(path, encoding="utf-8") as fh:
            summary = json.load(fh)
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        raise DatasetError(f"{path}: unreadable or truncated summary ({err})") from None
    if not isinstance(summary, dict):
        raise DatasetError(
            f"{path}: a summary is a JSON object, this file holds {type(summary).__name__}"
        )
    missing = [k for k in REQUIRED_SUMMARY_KEYS if k not in summary]
    if missing:
        raise DatasetError(f"{path}: summary lacks {', '.join(missing)}")
    if summary["status"] not in STATUSES:
        raise DatasetError(
            f"{path}: unknown status {summary['status']!r}; a case is one of {', '.join(STATUSES)}"
        )
    bad = [k for k in ("C1", "phi", "theta", "load_fraction") if not _finite_number(summary[k])]
    gravity = summary["gravity_vector"]
    if not (isinstance(gravity, list) and len(gravity) == 3 and all(map(_finite_number, gravity))):
        bad.append("gravity_vector")
    if bad:
        raise DatasetError(
            f"{path}: summary field(s) {', '.join(bad)} are not finite numbers "
            f"({', '.join(f'{k}={summary[k]!r}' for k in bad)})"
        )
    return summary


def read_case(summary_path: str | Path, points_path: str | Path) -> tuple[dict, dict]:
    """Read one case folder's summary and points, and check that they are that folder's case.

    The folder's name is the case (:class:`fem.sweep.Case`); its ``summary.json`` must describe
    the same C1, Φ and θ, and its ``points.h5`` (where it says) must have been written for it, so
    that files copied between folders cannot put one case in the dataset twice.

    Raises:
        DatasetError: naming the folder and the disagreement.
    """
    from fem.exceptions import InvalidParameterError
    from fem.sweep import Case

    summary_path, points_path = Path(summary_path), Path(points_path)
    folder = summary_path.parent
    if points_path.parent != folder:
        raise DatasetError(
            f"{summary_path} and {points_path} are in different folders: a case's files are in "
            "its own folder"
        )
    try:
        expected = Case.from_id(folder.name)
    except InvalidParameterError as err:
        raise DatasetError(f"{folder}: not a case folder ({err})") from None
    summary = read_summary(summary_path)
    described = Case.from_summary(summary)
    if described != expected or summary["case"] != expected.id:
        raise DatasetError(
            f"{summary_path}: the summary is of case {summary['case']!r} (C1 = {summary['C1']} "
            f"kPa, phi = {summary['phi']} deg, theta = {summary['theta']} deg), not of its folder "
            f"{expected.id!r}; solve the case again (whichever job solved it, alone or in its "
            f"direction's chain: snakemake {summary_path} --forcerun {summary_path})"
        )
    points = read_points(points_path)
    if points["case"] is not None and points["case"] != expected.id:
        raise DatasetError(
            f"{points_path}: written for case {points['case']!r}, not for its folder "
            f"{expected.id!r}; solve the case again"
        )
    return summary, points
