"""One self-describing HDF5 dataset of all cases of a sweep.

Layout (units in attributes; M cases, N material points)::

    /points/X            (N, 3) float64   reference coordinates, m
    /points/node_index   (N,)   int64     index of the point in the mesh file
    /points/kind         (N,)   int8      0 domain, 1 boundary (on a fully clamped surface)
    /points/cells        (C, 4) int64     the mesh's tetrahedra, as rows of the points (their
                                          corners; written when the dataset is built with its
                                          mesh, e.g. for a surrogate queried between the points)
    /nodes/X             (K, 3) float64   every node of a quadratic mesh (its vertices and edge
                                          nodes), m: where the FE field is known exactly
    /nodes/cells         (C, 10) int64    the mesh's 10-node tetrahedra as rows of /nodes
    /nodes/vertex        (N,)   int64     the row of /nodes of each material point
    /nodes/displacement  (M, K, 3) float32  m; NaN for failed cases (the /nodes group is
                                          written when the cases' fields are quadratic and the
                                          dataset is built with them)
    /cases/id            (M,)   str       case folder name
    /cases/C1            (M,)   float64   kPa
    /cases/phi, theta    (M,)   float64   degrees
    /cases/gravity       (M, 3) float64   m/s^2
    /cases/status        (M,)   str       converged | failed
    /cases/reason        (M,)   str       why (solver's words)
    /cases/converged     (M,)   bool
    /cases/load_fraction (M,)   float64   fraction of gravity reached
    /cases/first_failure (M,)   str       reason of the first rejected load step ("" if none)
    /cases/min_detF      (M,)   float64   smallest det F of the final state
    /cases/self_overlap  (M,)   int64     boundary vertices of the final state inside another
                                          of its cells (the body through itself); -1: not measured
    /cases/contact_force_N (M,) float64   contact force on the skin, N (fe.contact); NaN when
                                          solved without contact
    /cases/self_contact_force_N (M,) float64  the skin's contact force with itself, N
                                          (fe.self_contact); NaN when solved without it
    /cases/load_steps, newton_iterations  (M,) int64
    /cases/wall_s        (M,)   float64   solve wall time
    /cases/cpu_s         (M,)   float64   solve CPU time of the case's process
    /cases/start_fraction (M,)  float64   where the load path started: 0 from rest, λ = C1/C1ₖ
                                          from a stiffer neighbour's solution (fem.chain)
    /cases/process_start_s, finished_s (M,) float64  Unix time (UTC) when the case's solving
                                          process started and when the case ended (its summary's
                                          ``clock``); NaN for a summary without one
    /cases/max_disp_mm   (M,)   float64
    /displacement        (M, N, 3) float64  m; NaN for failed cases
    /splits/by_sample/{train,validation,test}   flat sample indices (case * N + point)
    /splits/by_case/{train,validation,test}     case indices (test includes the clinical cases)
    /splits/by_direction/{train,validation,test} case indices: whole gravity directions held out
    /splits/by_c1/{train,validation,test}       case indices: whole C1 values held out (the
                                                 softest and stiffest always train)

Root attributes hold a description, the creation time, the provenance (config
sections, package versions, git commit) and the tissue map the cases were solved with
(``tissues``: each tissue's C1 over the fat's, :mod:`fem.materials.tissues`) as JSON strings.
This module imports neither dolfinx nor jax, so any tool can read the format:
:func:`fem.aggregate.build_dataset` writes it, :func:`read_dataset` and
:func:`read_case_columns` read it.
"""

from __future__ import annotations

import json
from collections.abc import Iterable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from fem.case_files import Nodes
from fem.directions import gravity_direction
from fem.exceptions import DatasetError
from fem.splits import GROUP_SPLITS, SPLIT_KINDS, SPLITS

FORMAT_VERSION = 1
DOMAIN, BOUNDARY = 0, 1


@dataclass
class Dataset:
    """The dataset in memory: points, cases, displacements (mm) and splits.

    Attributes:
        X: reference coordinates of the material points (N, 3), m.
        boundary: True where the point lies on a clamped surface (N,).
        C1: per case, kPa (M,).
        phi: per case, degrees (M,).
        theta: per case, degrees (M,).
        direction: unit gravity direction per case (M, 3).
        displacement: (M, N, 3) in mm; NaN rows for failed cases.
        converged: (M,) bool.
        splits: ``{kind: {"train": ..., "validation": ..., "test": ...}}`` index arrays of
            every kind of :data:`SPLIT_KINDS`.
        ids: case identifiers (M,).
        node_index: index of each point in the mesh file (N,), for writing fields.
        cells: the mesh's tetrahedra as rows of ``X`` (C, 4), or None if not recorded.
        nodes: every node of a quadratic mesh and the fields there (``/nodes``), where the
            dataset has them and was read with them.
        tissues: each tissue's C1 over the fat's that the cases were solved with (the root
            attribute ``tissues``; all fat for a dataset written before it).
    """

    X: np.ndarray
    boundary: np.ndarray
    C1: np.ndarray
    phi: np.ndarray
    theta: np.ndarray
    direction: np.ndarray
    displacement: np.ndarray
    converged: np.ndarray
    splits: dict[str, dict[str, np.ndarray]]
    ids: np.ndarray
    node_index: np.ndarray | None = None
    cells: np.ndarray | None = None
    nodes: Nodes | None = None
    tissues: dict[str, float] = field(default_factory=lambda: {"fat": 1.0})

    @property
    def n_points(self) -> int:
        """Material points per case."""
        return self.X.shape[0]

    def case_index(self, C1: float, phi: float, theta: float = 0.0) -> int:
        """Index of the case with these parameters.

        Raises:
            KeyError: if the dataset has no such case.
        """
        hit = np.flatnonzero(
            np.isclose(self.C1, C1) & np.isclose(self.phi, phi) & np.isclose(self.theta, theta)
        )
        if hit.size == 0:
            raise KeyError(f"no case with C1={C1} kPa, phi={phi} deg, theta={theta} deg")
        return int(hit[0])

    def without(self, ids: Iterable[str]) -> Dataset:
        """The dataset with the cases ``ids`` set aside as if their solve had failed.

        Their displacement becomes NaN (at the points and the nodes), ``converged`` False, and
        they leave every split; every other case keeps its place. A case whose FE state is no
        answer (an unstable equilibrium, :mod:`studies.fe_study.stability_audit`) is no sample.

        Raises:
            DatasetError: naming an id the dataset does not have.
        """
        ids = list(ids)
        index = {str(name): i for i, name in enumerate(self.ids)}
        unknown = [name for name in ids if name not in index]
        if unknown:
            raise DatasetError(f"the dataset has no case {', '.join(unknown)}")
        if not ids:
            return self
        drop = np.array(sorted(index[name] for name in ids))
        displacement = self.displacement.copy()
        displacement[drop] = np.nan
        converged = self.converged.copy()
        converged[drop] = False
        splits = {}
        for kind, parts in self.splits.items():
            splits[kind] = {}
            for part, indices in parts.items():
                splits[kind][part] = indices[~np.isin(self.split_cases(kind, indices), drop)]
        nodes = self.nodes
        if nodes is not None and nodes.displacement is not None:
            fields = nodes.displacement.copy()
            fields[drop] = np.nan
            nodes = replace(nodes, displacement=fields)
        return replace(self, displacement=displacement, converged=converged, splits=splits,
                       nodes=nodes)

    def split_cases(self, kind: str, indices: np.ndarray) -> np.ndarray:
        """The case of each index of a split of ``kind`` (a sample's case in ``by_sample``)."""
        return indices // self.n_points if kind == "by_sample" else indices

    def sample_indices(self, split: str, part: str) -> np.ndarray:
        """Flat sample indices (case * N + point) of a split part."""
        indices = self.splits[split][part]
        if split != "by_sample":
            return (indices[:, None] * self.n_points + np.arange(self.n_points)[None, :]).ravel()
        return indices


def read_dataset(path: str | Path, nodes: bool = False) -> Dataset:
    """Read and check the HDF5 dataset written by :func:`build_dataset`.

    With ``nodes``, the fields at every node of a quadratic mesh too (``/nodes``, where the
    dataset has them: about seven times the material points' size).

    Raises:
        DatasetError: if the file is missing, empty, has NaN in a converged
            case, or lacks a split.
    """
    import h5py

    path = Path(path)
    if not path.is_file():
        raise DatasetError(f"dataset {path} does not exist")
    try:
        with h5py.File(path, "r") as h5:
            for key in ("points/X", "points/kind", "cases/C1", "cases/phi", "displacement"):
                if key not in h5:
                    raise DatasetError(f"dataset {path} lacks /{key}")
            splits: dict[str, dict[str, np.ndarray]] = {}
            for kind in SPLIT_KINDS:
                for part in SPLITS:
                    key = f"splits/{kind}/{part}"
                    if key not in h5:
                        raise DatasetError(
                            f"dataset {path} lacks the split /{key} (written by an older "
                            "version: rebuild it, e.g. snakemake --forcerun aggregate)"
                        )
                    splits.setdefault(kind, {})[part] = h5[key][...]
            ds = Dataset(
                X=h5["points/X"][...],
                boundary=h5["points/kind"][...] == BOUNDARY,
                C1=h5["cases/C1"][...],
                phi=h5["cases/phi"][...],
                theta=h5["cases/theta"][...],
                direction=gravity_direction(h5["cases/phi"][...], h5["cases/theta"][...]),
                displacement=1e3 * h5["displacement"][...],
                converged=h5["cases/converged"][...].astype(bool),
                splits=splits,
                ids=h5["cases/id"].asstr()[...],
                node_index=h5["points/node_index"][...] if "points/node_index" in h5 else None,
                cells=h5["points/cells"][...] if "points/cells" in h5 else None,
                nodes=_read_nodes(h5, path) if nodes and "nodes" in h5 else None,
                tissues=json.loads(h5.attrs["tissues"]) if "tissues" in h5.attrs
                else {"fat": 1.0},
            )
    except OSError as err:
        raise DatasetError(f"dataset {path} is unreadable ({err})") from None
    if ds.X.shape[0] == 0 or ds.C1.shape[0] == 0:
        raise DatasetError(f"dataset {path} is empty")
    if ds.displacement.shape != (ds.C1.shape[0], ds.X.shape[0], 3):
        raise DatasetError(
            f"dataset {path}: /displacement has shape {ds.displacement.shape}, expected "
            f"({ds.C1.shape[0]}, {ds.X.shape[0]}, 3)"
        )
    if ds.cells is not None and (ds.cells.ndim != 2 or ds.cells.shape[1] != 4 or (
            ds.cells.size and (ds.cells.min() < 0 or ds.cells.max() >= ds.X.shape[0]))):
        raise DatasetError(f"dataset {path}: /points/cells are not tetrahedra of its points")
    if not ds.converged.any():
        raise DatasetError(f"dataset {path} has no converged case")
    if not np.all(np.isfinite(ds.displacement[ds.converged])):
        raise DatasetError(f"dataset {path} has NaN or inf displacements in converged cases")
    if ds.nodes is not None and not np.all(np.isfinite(ds.nodes.displacement[ds.converged])):
        raise DatasetError(f"dataset {path} has NaN or inf /nodes displacements in converged "
                           "cases")
    n_samples = {kind: ds.C1.shape[0] for kind in SPLIT_KINDS}
    n_samples["by_sample"] = ds.C1.shape[0] * ds.X.shape[0]
    for kind, parts in splits.items():
        # a sweep with too few directions or C1 values has nothing to hold out by group
        if kind not in GROUP_SPLITS and (parts["train"].size == 0 or parts["validation"].size == 0):
            raise DatasetError(
                f"dataset {path}: split {kind} has an empty train or validation part"
            )
        for part, idx in parts.items():
            if idx.size and (idx.min() < 0 or idx.max() >= n_samples[kind]):
                raise DatasetError(f"dataset {path}: split {kind}/{part} has out-of-range indices")
            if idx.size and not ds.converged[ds.split_cases(kind, idx)].all():
                raise DatasetError(f"dataset {path}: split {kind}/{part} includes failed cases")
    return ds


def _read_nodes(h5: Any, path: Path) -> Nodes:
    """The ``/nodes`` group, checked; the displacement in mm (float32)."""
    group = h5["nodes"]
    X, cells, vertex = (group[k][...] for k in ("X", "cells", "vertex"))
    displacement = group["displacement"][...]
    displacement *= np.float32(1e3)
    n_cases, n_points = h5["cases/C1"].shape[0], h5["points/X"].shape[0]
    if (X.ndim != 2 or X.shape[1] != 3 or cells.ndim != 2 or cells.shape[1] != 10
            or cells.min() < 0 or cells.max() >= len(X) or vertex.shape != (n_points,)
            or vertex.min() < 0 or vertex.max() >= len(X)
            or displacement.shape != (n_cases, len(X), 3)):
        raise DatasetError(f"dataset {path}: /nodes is not a quadratic mesh of its points and "
                           "cases")
    if not np.allclose(X[vertex], h5["points/X"][...], rtol=0, atol=1e-9):
        raise DatasetError(f"dataset {path}: /nodes/vertex does not list the material points")
    return Nodes(X=X, cells=cells, vertex=vertex, displacement=displacement)


def read_case_columns(path: str | Path) -> dict[str, np.ndarray]:
    """Every per-case column under ``/cases``; strings come back as ``str`` arrays.

    A column an older dataset lacks is simply not a key, so a reader checks for the columns
    it needs.

    Raises:
        DatasetError: if the file is missing or unreadable.
    """
    import h5py

    path = Path(path)
    if not path.is_file():
        raise DatasetError(f"dataset {path} does not exist")
    columns = {}
    try:
        with h5py.File(path, "r") as h5:
            group = h5.get("cases")
            for key, column in group.items() if group is not None else ():
                if isinstance(column, h5py.Dataset):
                    columns[key] = column.asstr()[...] if column.dtype.kind == "O" else column[...]
    except OSError as err:
        raise DatasetError(f"dataset {path} is unreadable ({err})") from None
    return columns
