"""A trained surrogate on disk: save a model folder, and load and check it.

A model folder holds ``model.json`` (format version, hyperparameters, normalisation,
training range, metrics), ``params.npz`` (weights as named arrays, plus the material
points, their boundary flags, mesh node indices, the mesh's tetrahedra on them where the
dataset has them, a ``pod`` model's modes at them and, in the exact Dirichlet mode, the
factor φ) and ``history.json`` (the training history). Nothing is pickled; loading
rebuilds the network skeleton from the JSON first and checks every array against it.
This module is the format's one owner: the workflow and the studies read model folders
through it.
"""

from __future__ import annotations

import json
import os
import zipfile
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from fem.dataset import Dataset
from surrogate.config import SurrogateConfig
from surrogate.data import Normalisation
from surrogate.exceptions import ModelFileError, SurrogateConfigError
from surrogate.model import Params
from surrogate.structures import structure_for
from surrogate.training_range import check_record

if TYPE_CHECKING:  # training code is not needed to save or load a model
    from surrogate.epochs import TrainResult

FORMAT_VERSION = 2
MODEL_JSON = "model.json"
PARAMS_NPZ = "params.npz"
HISTORY_JSON = "history.json"
MODEL_FILES = (MODEL_JSON, PARAMS_NPZ, HISTORY_JSON)


def write_json(path: str | Path, payload: dict[str, Any]) -> None:
    """Write JSON (indented, trailing newline) atomically: a temporary file renamed into place."""
    target = Path(path)
    tmp = target.with_name(f".{target.name}.{os.getpid()}.tmp")
    tmp.write_text(json.dumps(payload, indent=2) + "\n")
    os.replace(tmp, target)


def training_range(ds: Dataset, cases: np.ndarray) -> dict[str, Any]:
    """The C1, Φ and θ values of the given (training) cases, and their (Φ, θ) directions.

    ``unconverged`` lists the (C1, Φ, θ) of the dataset's cases whose FE solve failed:
    holes in the range, where no FE solution backs a prediction. ``c1_by_direction`` lists each
    direction's [Φ, θ, softest C1, stiffest C1] among the converged training cases: a sweep
    need not solve every direction at every C1 (``sweep.refine``'s bands). ``tissues`` is the
    tissue map the cases were solved with (each tissue's C1 over the fat's, whose C1 is the
    model's input).
    """
    cases = np.asarray(cases, dtype=int)
    converged = cases[ds.converged[cases]]
    by_direction: dict[tuple[float, float], list[float]] = {}
    for i in converged:
        by_direction.setdefault((float(ds.phi[i]), float(ds.theta[i])), []).append(float(ds.C1[i]))
    return {
        "C1_kPa": [float(ds.C1[cases].min()), float(ds.C1[cases].max())],
        "phi_deg": sorted({float(v) for v in ds.phi[cases]}),
        "theta_deg": sorted({float(v) for v in ds.theta[cases]}),
        "directions": sorted({(float(p), float(t)) for p, t in zip(ds.phi[cases], ds.theta[cases],
                                                                    strict=True)}),
        "unconverged": unconverged_cases(ds),
        "c1_by_direction": [[p, t, min(c1), max(c1)]
                            for (p, t), c1 in sorted(by_direction.items())],
        "tissues": dict(ds.tissues),
    }


def unconverged_cases(ds: Dataset) -> list[list[float]]:
    """[C1 (kPa), Φ, θ (degrees)] of every case of ``ds`` whose FE solve failed."""
    return [[float(ds.C1[i]), float(ds.phi[i]), float(ds.theta[i])]
            for i in np.flatnonzero(~ds.converged)]


def save_model(folder: str | Path, result: TrainResult, ds: Dataset) -> Path:
    """Write a trained surrogate (and its training history) to ``folder``.

    Returns:
        The path of ``model.json``.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    checkpoint = in_memory(result, ds)
    nodes = checkpoint.nodes
    extra = {name: value for name, value in (("points_factor", checkpoint.point_factor),
                                             ("points_basis", checkpoint.basis),
                                             ("mesh_cells", checkpoint.cells),
                                             ("mesh_nodes_X", nodes and nodes.X),
                                             ("mesh_nodes_cells", nodes and nodes.cells),
                                             ("mesh_nodes_basis", nodes and nodes.basis))
             if value is not None}
    node_index = ds.node_index if ds.node_index is not None else np.arange(ds.n_points)
    np.savez(
        folder / PARAMS_NPZ,
        points_X=ds.X,
        points_boundary=ds.boundary,
        points_node_index=node_index,
        **extra,
        **structure_for(result.config).to_arrays(result.params),
    )
    meta = {
        "format_version": FORMAT_VERSION,
        "config": result.config.as_dict(),
        "normalisation": result.normalisation.as_dict(),
        "n_points": int(ds.n_points),
        "training_range": checkpoint.training_range,
        "held_out_cases": checkpoint.held_out,
        "metrics": checkpoint.metrics,
        "inputs": ["x", "y", "z", "C1 (encoded, scaled)", "g_x/|g|", "g_y/|g|", "g_z/|g|"],
        "outputs": ["u_x", "u_y", "u_z (mm)"],
    }
    path = folder / MODEL_JSON
    write_json(folder / HISTORY_JSON, {"summary": result.summary(), "history": result.history})
    write_json(path, meta)  # model.json last: it marks the folder complete
    return path


@dataclass(frozen=True)
class NodeModes:
    """A ``pod`` model's modes at every node of a quadratic mesh: its answers between the points.

    Attributes:
        X: the nodes (K, 3), m.
        cells: the 10-node tetrahedra as rows of ``X`` (C, 10), corners first.
        basis: the modes there (K, 3, modes), float32.
    """

    X: np.ndarray
    cells: np.ndarray
    basis: np.ndarray

    def __post_init__(self) -> None:
        X, cells, basis = self.X, self.cells, self.basis
        if X.ndim != 2 or X.shape[1] != 3 or cells.ndim != 2 or cells.shape[1] != 10:
            raise ValueError(f"quadratic nodes need (K, 3) nodes and (C, 10) cells, got "
                             f"{X.shape} and {cells.shape}")
        if cells.size and (cells.min() < 0 or cells.max() >= len(X)):
            raise ValueError("the quadratic cells are not cells of the nodes")
        if basis.ndim != 3 or basis.shape[:2] != (len(X), 3) or not np.all(np.isfinite(basis)):
            raise ValueError(f"the modes at the nodes are not finite (K, 3, modes) with K = "
                             f"{len(X)}, got shape {basis.shape}")


@dataclass(frozen=True)
class Checkpoint:
    """What a model folder holds, checked against its architecture.

    Attributes:
        config: hyperparameters.
        params: network weights.
        normalisation: input/output scaling.
        X: material points (N, 3), m.
        boundary: boundary flags (N,).
        training_range: the C1 / Φ / θ values it was trained on, and the failed cases.
        point_factor: per-point output factor φ (exact Dirichlet mode), else None.
        node_index: index of each point in the mesh file (N,), or None.
        metrics: training metrics as saved.
        held_out: ids of cases kept out of its training and validation.
        basis: a ``pod`` model's modes at the points (N, 3, modes), else None.
        cells: the mesh's tetrahedra as rows of ``X`` (C, 4), where its dataset had them.
        nodes: a ``pod`` model's modes at every node of a quadratic mesh, where its dataset had
            the fields there; else None.
    """

    config: SurrogateConfig
    params: Params
    normalisation: Normalisation
    X: np.ndarray
    boundary: np.ndarray
    training_range: dict[str, Any]
    point_factor: np.ndarray | None = None
    node_index: np.ndarray | None = None
    metrics: dict[str, Any] = field(default_factory=dict)
    held_out: list[str] = field(default_factory=list)
    basis: np.ndarray | None = None
    cells: np.ndarray | None = None
    nodes: NodeModes | None = None


def in_memory(result: TrainResult, ds: Dataset) -> Checkpoint:
    """A trained surrogate's checkpoint in memory: what :func:`save_model` writes.

    A study that fits models it does not keep (:mod:`benchmarks.pod_basis`) queries it directly.
    """
    cases = result.train_cases if result.train_cases is not None else np.flatnonzero(ds.converged)
    held_out = result.held_out_cases if result.held_out_cases is not None else []
    nodes = None
    if result.node_basis is not None:
        if ds.nodes is None:
            raise ValueError("a model fitted at a quadratic mesh's nodes is saved with the "
                             "dataset it was fitted on, read with its nodes")
        nodes = NodeModes(ds.nodes.X, ds.nodes.cells, result.node_basis)
    return Checkpoint(
        result.config, result.params, result.normalisation, ds.X, ds.boundary,
        training_range(ds, cases), point_factor=result.point_factor, node_index=ds.node_index,
        metrics=result.summary(), held_out=[str(ds.ids[c]) for c in held_out],
        basis=result.basis, cells=ds.cells, nodes=nodes,
    )


def load_checkpoint(folder: str | Path) -> Checkpoint:
    """Load a model folder written by :func:`save_model` (or the path of its ``model.json``).

    Raises:
        ModelFileError: if files are missing or the weights do not fit the architecture.
    """
    folder = Path(folder)
    if folder.suffix == ".json":
        folder = folder.parent
    try:
        meta = json.loads((folder / MODEL_JSON).read_text())
    except (OSError, json.JSONDecodeError, ValueError) as err:
        raise ModelFileError(f"cannot read a surrogate model from {folder}: {err}") from None
    version = meta.get("format_version") if isinstance(meta, dict) else None
    if not isinstance(version, int) or isinstance(version, bool) \
            or not 1 <= version <= FORMAT_VERSION:
        raise ModelFileError(f"{folder / MODEL_JSON}: format_version {version!r} is not one this "
                             f"code reads (1 to {FORMAT_VERSION}): a model of other code")
    try:
        with np.load(folder / PARAMS_NPZ, allow_pickle=False) as npz:
            arrays = {k: npz[k] for k in npz.files}
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, zlib.error) as err:
        raise ModelFileError(f"{folder / PARAMS_NPZ} is not a whole NumPy archive of the "
                             f"model's weights ({type(err).__name__}: {err}): truncated or "
                             "damaged; save the model again") from None
    damaged = sorted(k for k, a in arrays.items()
                     if np.issubdtype(a.dtype, np.floating) and not np.all(np.isfinite(a)))
    if damaged:
        raise ModelFileError(f"{folder / PARAMS_NPZ}: {', '.join(damaged)} hold values that are "
                             "not finite numbers")
    try:
        config = SurrogateConfig.from_mapping(meta["config"])
        points = {k: arrays.pop(k) for k in list(arrays) if k.startswith(("points_", "mesh_"))}
        structure = structure_for(config)
        params = structure.from_arrays(arrays)
        norm = Normalisation.from_dict(meta["normalisation"])
        trained = check_record(meta.get("training_range", {}))
        X, boundary = points["points_X"], points["points_boundary"]
    except (KeyError, TypeError, ValueError, SurrogateConfigError) as err:
        raise ModelFileError(f"{folder}: {err}") from None
    if X.shape != (meta.get("n_points", X.shape[0]), 3) or boundary.shape != (X.shape[0],):
        raise ModelFileError(f"{folder}: material points do not match n_points")
    basis, cells = points.get("points_basis"), points.get("mesh_cells")
    wrong = structure.check_saved(basis, len(X))
    if wrong:
        raise ModelFileError(f"{folder}: {wrong}")
    if cells is not None and (cells.ndim != 2 or cells.shape[1] != 4 or cells.min() < 0
                              or cells.max() >= len(X)):
        raise ModelFileError(f"{folder}: mesh_cells are not tetrahedra of its points")
    nodes = None
    if "mesh_nodes_basis" in points:
        try:
            nodes = NodeModes(points["mesh_nodes_X"], points["mesh_nodes_cells"],
                              points["mesh_nodes_basis"])
        except (KeyError, ValueError) as err:
            raise ModelFileError(f"{folder}: {err}") from None
        if basis is not None and nodes.basis.shape[2] != basis.shape[2]:
            raise ModelFileError(f"{folder}: the modes at the nodes are not the points' modes")
    return Checkpoint(
        config,
        params,
        norm,
        X,
        boundary,
        trained,
        point_factor=points.get("points_factor"),
        node_index=points.get("points_node_index"),
        metrics=meta.get("metrics") or {},
        held_out=list(meta.get("held_out_cases") or []),
        basis=basis,
        cells=cells,
        nodes=nodes,
    )


def read_model_card(folder: str | Path) -> dict[str, Any]:
    """The ``model.json`` of a model folder (hyperparameters, training range, metrics).

    Raises:
        ModelFileError: if it is missing, not JSON, or its training range is damaged
            (:func:`surrogate.training_range.check_record`).
    """
    path = Path(folder) / MODEL_JSON
    card = _read(path)
    try:
        check_record(card.get("training_range", {}) if isinstance(card, dict) else {})
    except ValueError as err:
        raise ModelFileError(f"{path}: {err}") from None
    return card


def read_history(folder: str | Path) -> dict[str, Any]:
    """The ``history.json`` of a model folder: ``{"summary": ..., "history": [...]}``.

    Raises:
        ModelFileError: if it is missing, not JSON or lacks either part.
    """
    history = _read(Path(folder) / HISTORY_JSON)
    missing = [k for k in ("summary", "history") if k not in history]
    if missing:
        raise ModelFileError(f"{Path(folder) / HISTORY_JSON} lacks {', '.join(missing)}")
    return history


def _read(path: Path) -> dict[str, Any]:
    try:
        return json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as err:
        raise ModelFileError(f"cannot read {path}: {err}") from None
