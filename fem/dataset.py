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
sections, package versions, git commit) as JSON strings. This module imports
neither dolfinx nor jax, so any tool can read the format: :func:`build_dataset` writes it,
:func:`read_dataset` and :func:`read_case_columns` read it.
"""

from __future__ import annotations

import json
import logging
import math
import os
import tempfile
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, replace
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from fem.directions import direction_keys, gravity_direction
from fem.provenance import provenance

log = logging.getLogger(__name__)

FORMAT_VERSION = 1
DOMAIN, BOUNDARY = 0, 1
SPLITS = ("train", "validation", "test")
SPLIT_KINDS = ("by_sample", "by_case", "by_direction", "by_c1")
"""The dataset's splits: ``by_sample`` holds flat sample indices, the others case indices."""
GROUP_SPLITS = {"by_direction": 1, "by_c1": 2}
"""Splits that hold out whole groups of cases, with the stream of the seed each draws from
(the by-sample and by-case splits draw from stream 0, as before these were added)."""
REQUIRED_SUMMARY_KEYS = ("status", "case", "C1", "phi", "theta", "gravity_vector", "load_fraction")
REQUIRED_POINT_FIELDS = ("node_index", "X", "u", "fixed")
STATUSES = ("converged", "failed")
"""The statuses a case's summary may have (:func:`fem.case.run_case` writes one of them)."""


class DatasetError(ValueError):
    """A case file or the dataset is missing, truncated or inconsistent (the message names it)."""


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
    described = Case(summary["C1"], summary["phi"], summary["theta"])
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


@dataclass(frozen=True, slots=True)
class SplitFractions:
    """Fractions of the train / validation / test split (the paper's 80/10/10)."""

    train: float = 0.8
    validation: float = 0.1
    test: float = 0.1

    def __post_init__(self) -> None:
        values = (self.train, self.validation, self.test)
        if any(v < 0 for v in values) or self.train <= 0 or self.validation <= 0:
            raise DatasetError(
                "split fractions must be non-negative, train and validation positive"
            )
        if abs(sum(values) - 1.0) > 1e-9:
            raise DatasetError(f"split fractions must add up to 1, got {sum(values):g}")

    def partition(self, n: int, rng: np.random.Generator) -> dict[str, np.ndarray]:
        """Randomly partition ``range(n)`` into sorted index arrays."""
        order = rng.permutation(n)
        n_train = int(round(self.train * n))
        n_val = int(round(self.validation * n))
        if n >= 3:
            n_train = min(max(n_train, 1), n - 2 if self.test > 0 else n - 1)
            n_val = min(max(n_val, 1), n - n_train - (1 if self.test > 0 else 0))
        parts = np.split(order, [n_train, n_train + n_val])
        return {name: np.sort(p).astype(np.int64) for name, p in zip(SPLITS, parts, strict=True)}


def group_partition(
    cases: np.ndarray,
    key: np.ndarray,
    keep_in_training: Sequence[Any],
    split: SplitFractions,
    rng: np.random.Generator,
    always_test: Sequence[Any] = (),
) -> dict[str, np.ndarray]:
    """Partition ``cases`` by whole groups (cases with equal ``key``) into sorted index arrays.

    Groups whose key is in ``keep_in_training`` always train (the ends of a range, so that
    held-out groups are interpolated, not extrapolated); those in ``always_test`` are always
    tested; the others are partitioned by ``split``'s fractions of their number. With fewer
    than three groups free of both there is nothing to hold out: every case trains and the
    other parts are empty.

    Raises:
        ValueError: if a group of ``always_test`` is not among the keys, or must also train.
    """
    unique = np.unique(key)
    kept = np.isin(unique, np.asarray(keep_in_training, dtype=unique.dtype))
    wanted = np.asarray(always_test, dtype=unique.dtype)
    tested = np.isin(unique, wanted)
    if not np.all(np.isin(wanted, unique[~kept])):
        raise ValueError(f"groups {wanted.tolist()} cannot all be tested: the free groups are "
                         f"{unique[~kept].tolist()}")
    free = unique[~kept & ~tested]
    if free.size < 3:
        parts = {"train": unique, "validation": unique[:0], "test": unique[:0]}
    else:
        drawn = split.partition(free.size, rng)
        parts = {name: free[idx] for name, idx in drawn.items()}
        parts["train"] = np.concatenate([parts["train"], unique[kept]])
        parts["test"] = np.concatenate([parts["test"], unique[tested]])
    return {name: np.sort(cases[np.isin(key, groups)]).astype(np.int64)
            for name, groups in parts.items()}


def softest_held_out_c1(c1_values: np.ndarray) -> tuple[float, ...]:
    """The C1 value that the by-C1 split always tests: the softest one it may hold out.

    The softest and the stiffest train (held-out values are interpolated), so it is the second
    softest, where the field changes fastest with C1. None with fewer than six values: the
    split draws from at least three others (:func:`group_partition`), so that it tests more
    than the soft end.
    """
    values = np.unique(np.asarray(c1_values, dtype=float))
    return (float(values[1]),) if values.size >= 6 else ()


def build_dataset(
    summary_paths: Sequence[str | Path],
    point_paths: Sequence[str | Path],
    output: str | Path,
    split: SplitFractions = SplitFractions(),
    seed: int = 0,
    config: dict[str, Any] | None = None,
    test_cases: Sequence[tuple[float, float, float]] = (),
    mesh: str | Path | None = None,
    fields_paths: Sequence[str | Path] | None = None,
) -> dict[str, Any]:
    """Gather case files into one HDF5 dataset, written atomically.

    Args:
        summary_paths: each case's ``summary.json``.
        point_paths: each case's ``points.h5``, in the same order.
        output: the dataset file to write.
        split: fractions of the train, validation and test parts.
        seed: seed of the random split.
        config: the config sections to record as provenance.
        test_cases: (C1, Φ, θ) of setups the by-case split always holds out as test
            (the clinical cases: a by-case model is then judged on setups it never saw);
            the other converged cases are partitioned by ``split``. A converged case that
            passes through itself (``self_overlap``) is in no split: no surrogate learns it.
            The by-direction and by-C1 splits partition whole directions and whole C1 values
            by the same fractions (:func:`group_partition`).
        mesh: the cases' mesh (XDMF): its tetrahedra are written as ``/points/cells``.
        fields_paths: each case's ``fields.h5``, in the same order: on a quadratic mesh, the
            fields at every node are written as ``/nodes`` (:func:`gather_nodes`).

    Raises:
        DatasetError: naming the case whose files are missing, truncated or whose
            material points differ from the first case's. Nothing is written then.
    """
    if len(summary_paths) != len(point_paths) or not summary_paths:
        raise DatasetError("need one points file per summary, and at least one case")
    summaries: list[dict[str, Any]] = []
    for i, (summary_path, path) in enumerate(zip(summary_paths, point_paths, strict=True)):
        summary, points = read_case(summary_path, path)
        summaries.append(summary)
        if i == 0:
            reference = points
            n_points = len(reference["node_index"])
            displacement = np.full((len(summary_paths), n_points, 3), np.nan)
        case = summary["case"]
        if points["u"].shape != (n_points, 3) or points["X"].shape != (n_points, 3):
            raise DatasetError(
                f"case {case}: {path} has {len(points['u'])} material points, expected {n_points}"
            )
        if not np.array_equal(points["node_index"], reference["node_index"]) or not np.allclose(
            points["X"], reference["X"], rtol=0, atol=1e-12
        ):
            raise DatasetError(
                f"case {case}: {path} lists different material points (another mesh?)"
            )
        if summary["status"] == "converged":
            if not np.all(np.isfinite(points["u"])):
                raise DatasetError(f"case {case}: converged but its displacement has NaN/inf")
            # no tissue moves farther than the body is large: such a field is no solution
            size = float(np.linalg.norm(np.ptp(points["X"], axis=0)))
            farthest = float(np.linalg.norm(points["u"], axis=1).max())
            if farthest > size:
                raise DatasetError(f"case {case}: {path} moves a point {farthest:.3g} m, farther "
                                   f"than the body's own size ({size:.3g} m): not a solution")
            displacement[i] = points["u"]

    converged = np.array([s["status"] == "converged" for s in summaries])
    # A converged state that passes through itself is no breast's: the splits (the data the
    # surrogate learns from and is judged on) leave it out; /cases/self_overlap names it.
    through = np.array([((s.get("self_overlap") or {}).get("overlapping_vertices") or 0) > 0
                        for s in summaries])
    if np.any(converged & through):
        log.warning("dataset: %d converged case(s) pass through themselves and are left out of "
                    "the splits: %s", int(np.sum(converged & through)),
                    ", ".join(s["case"] for s, t in zip(summaries, converged & through,
                                                         strict=True) if t))
    rng = np.random.default_rng(seed)
    good_cases = np.flatnonzero(converged & ~through)
    samples = (good_cases[:, None] * n_points + np.arange(n_points)[None, :]).ravel()
    by_sample = {k: samples[v] for k, v in split.partition(len(samples), rng).items()}
    keys = [(float(s["C1"]), float(s["phi"]), float(s.get("theta", 0.0))) for s in summaries]
    wanted = {tuple(float(v) for v in c) for c in test_cases}
    forced = np.array([keys[i] in wanted for i in good_cases], dtype=bool)
    free = good_cases[~forced]
    by_case = {k: free[v] for k, v in split.partition(len(free), rng).items()}
    by_case["test"] = np.sort(np.concatenate([by_case["test"], good_cases[forced]]))
    c1_all = np.array([k[0] for k in keys])
    phi_all, theta_all = np.array([k[1] for k in keys]), np.array([k[2] for k in keys])
    c1_good = np.round(c1_all[good_cases], 9)
    c1_values = np.unique(c1_good)
    c1_ends = (c1_values[0], c1_values[-1]) if c1_values.size else ()
    groups = {
        "by_direction": (direction_keys(phi_all, theta_all)[good_cases], (), ()),
        "by_c1": (c1_good, c1_ends, softest_held_out_c1(c1_values)),
    }
    held_out = {
        name: group_partition(
            good_cases, key, keep, split, np.random.default_rng([seed, GROUP_SPLITS[name]]),
            always_test=tested,
        )
        for name, (key, keep, tested) in groups.items()
    }

    def column(key: str, default: Any = np.nan) -> np.ndarray:
        return np.array(
            [s.get(key, default) if s.get(key) is not None else default for s in summaries]
        )

    wall = np.array([s.get("wall_s", {}).get("solve", np.nan) for s in summaries], dtype=float)
    cpu = np.array([(s.get("cpu_s") or {}).get("solve", np.nan) for s in summaries], dtype=float)
    start = np.array([(s.get("start") or {}).get("fraction", 0.0) for s in summaries],
                     dtype=float)
    iterations = np.array([sum(s.get("newton_iterations", [])) for s in summaries], dtype=np.int64)
    clocks = np.array(
        [[(s.get("clock") or {}).get(k, np.nan) for k in ("process_start", "finished")]
         for s in summaries], dtype=float).reshape(-1, 2)
    fields = {
        "id": np.array([s["case"] for s in summaries], dtype=object),
        "C1": column("C1").astype(float),
        "phi": column("phi").astype(float),
        "theta": column("theta").astype(float),
        "gravity": np.array([s["gravity_vector"] for s in summaries], dtype=float),
        "status": np.array([s["status"] for s in summaries], dtype=object),
        "reason": np.array([s.get("reason", "") for s in summaries], dtype=object),
        "converged": converged,
        "load_fraction": column("load_fraction").astype(float),
        "first_failure": np.array([s.get("first_failure") or "" for s in summaries], dtype=object),
        "min_detF": column("min_detF").astype(float),
        "self_overlap": np.array(
            [(s.get("self_overlap") or {}).get("overlapping_vertices", -1) for s in summaries],
            dtype=np.int64,
        ),
        "contact_force_N": np.array(
            [(s.get("contact") or {}).get("force_N", np.nan) for s in summaries], dtype=float
        ),
        "self_contact_force_N": np.array(
            [(s.get("self_contact") or {}).get("force_N", np.nan) for s in summaries],
            dtype=float,
        ),
        "load_steps": column("load_steps", 0).astype(np.int64),
        "newton_iterations": iterations,
        "wall_s": wall,
        "cpu_s": cpu,
        "start_fraction": start,
        "process_start_s": clocks[:, 0],
        "finished_s": clocks[:, 1],
        "max_disp_mm": column("max_disp_mm").astype(float),
    }
    units = {
        "C1": "kPa",
        "phi": "deg",
        "theta": "deg",
        "gravity": "m/s^2",
        "wall_s": "s",
        "cpu_s": "s",
        "start_fraction": "1",
        "process_start_s": "s (Unix time)",
        "finished_s": "s (Unix time)",
        "max_disp_mm": "mm",
        "load_fraction": "1",
        "contact_force_N": "N",
        "self_contact_force_N": "N",
    }
    kind = np.where(reference["fixed"], BOUNDARY, DOMAIN).astype(np.int8)
    if mesh is not None:
        reference = {**reference, "cells": mesh_cells(mesh, reference["node_index"],
                                                       reference["X"])}
    nodes = None
    if fields_paths is not None:
        if len(fields_paths) != len(summary_paths):
            raise DatasetError("need one fields file per summary")
        if converged.any():
            nodes = gather_nodes(fields_paths, converged, reference["X"])
    _write_atomically(
        Path(output),
        reference,
        kind,
        fields,
        units,
        displacement,
        {"by_sample": by_sample, "by_case": by_case, **held_out},
        {"seed": seed, "fractions": [split.train, split.validation, split.test]},
        provenance(config),
        nodes,
    )
    failed = [s["case"] for s in summaries if s["status"] != "converged"]
    log.info("dataset: %d cases (%d failed), %d points", len(summaries), len(failed), n_points)
    return {"cases": len(summaries), "failed": failed, "points": n_points}


def _write_atomically(
    output: Path,
    reference: dict[str, np.ndarray],
    kind: np.ndarray,
    fields: dict[str, np.ndarray],
    units: dict[str, str],
    displacement: np.ndarray,
    splits: dict[str, dict[str, np.ndarray]],
    split_info: dict[str, Any],
    prov: dict[str, Any],
    nodes: dict[str, np.ndarray] | None = None,
) -> None:
    import h5py

    output.parent.mkdir(parents=True, exist_ok=True)
    # a build killed before its rename left its temporary file: nothing else writes these
    for stale in output.parent.glob(f".{output.name}.*.tmp"):
        stale.unlink(missing_ok=True)
    fd, tmp = tempfile.mkstemp(dir=output.parent, prefix=f".{output.name}.", suffix=".tmp")
    os.close(fd)
    # mkstemp makes the file private (0600); the dataset gets the mode every other output has
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)
    try:
        with h5py.File(tmp, "w") as h5:
            h5.attrs["title"] = "Breast displacement under rotated gravity (FE sweep)"
            h5.attrs["description"] = __doc__
            h5.attrs["format_version"] = FORMAT_VERSION
            h5.attrs["created"] = datetime.now(UTC).isoformat()
            h5.attrs["provenance"] = json.dumps(prov, default=str)
            pts = h5.create_group("points")
            pts.create_dataset("X", data=reference["X"]).attrs["units"] = "m"
            pts.create_dataset("node_index", data=reference["node_index"])
            if "cells" in reference:
                pts.create_dataset("cells", data=reference["cells"]).attrs["description"] = (
                    "the mesh's tetrahedra as rows of /points (their corner vertices)")
            if nodes is not None:
                group = h5.create_group("nodes")
                group.create_dataset("X", data=nodes["X"]).attrs["units"] = "m"
                group.create_dataset("cells", data=nodes["cells"]).attrs["description"] = (
                    "the mesh's 10-node tetrahedra as rows of /nodes/X, corners first")
                group.create_dataset("vertex", data=nodes["vertex"]).attrs["description"] = (
                    "the row of /nodes/X of each material point")
                d = group.create_dataset(
                    "displacement", data=nodes["displacement"],
                    chunks=(1, *nodes["displacement"].shape[1:]), compression="gzip",
                    compression_opts=4, shuffle=True)
                d.attrs["units"] = "m"
                d.attrs["description"] = "displacement at every node per case; NaN if failed"
            k = pts.create_dataset("kind", data=kind)
            k.attrs["legend"] = json.dumps({"domain": DOMAIN, "boundary": BOUNDARY})
            cases = h5.create_group("cases")
            for name, values in fields.items():
                if values.dtype == object:
                    ds = cases.create_dataset(
                        name, data=values.astype(str).astype(object), dtype=h5py.string_dtype()
                    )
                else:
                    ds = cases.create_dataset(name, data=values)
                if name in units:
                    ds.attrs["units"] = units[name]
            n_points = displacement.shape[1]
            d = h5.create_dataset(
                "displacement",
                data=displacement,
                chunks=(1, n_points, 3),
                compression="gzip",
                compression_opts=4,
                shuffle=True,
            )
            d.attrs["units"] = "m"
            d.attrs["description"] = "displacement of each material point per case; NaN if failed"
            sp = h5.create_group("splits")
            sp.attrs["seed"] = split_info["seed"]
            sp.attrs["fractions"] = split_info["fractions"]
            for kind_name, parts in splits.items():
                g = sp.create_group(kind_name)
                for name, idx in parts.items():
                    g.create_dataset(name, data=idx)
            sp["by_sample"].attrs["description"] = "flat sample index = case * n_points + point"
            sp["by_case"].attrs["description"] = "case indices (whole setups held out)"
            sp["by_direction"].attrs["description"] = "case indices (whole directions held out)"
            sp["by_c1"].attrs["description"] = (
                "case indices (whole C1 values held out; the softest and stiffest train, the "
                "second softest is always tested)"
            )
        os.replace(tmp, output)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def mesh_cells(mesh_xdmf: str | Path, node_index: np.ndarray, X: np.ndarray) -> np.ndarray:
    """The mesh's tetrahedra as rows of the material points ``X`` (C, 4): their corners.

    The material points are the mesh's vertices, listed by ``node_index`` into the mesh file's
    geometry; a quadratic mesh's other nodes are dropped.

    Raises:
        DatasetError: if the mesh cannot be read, or is not the one the points come from.
    """
    import h5py

    from meshes.io import GEOMETRY_DATASET, TOPOLOGY_DATASET

    mesh_h5 = Path(mesh_xdmf).with_suffix(".h5")
    try:
        with h5py.File(mesh_h5, "r") as h5:
            geometry = h5[GEOMETRY_DATASET][...]
            topology = h5[TOPOLOGY_DATASET][...]
    except (OSError, KeyError) as err:
        raise DatasetError(f"cannot read the mesh {mesh_h5}: {err}") from None
    node_index = np.asarray(node_index)
    if node_index.max() >= geometry.shape[0] or not np.allclose(geometry[node_index], X,
                                                                 atol=1e-9):
        raise DatasetError(f"{mesh_xdmf} is not the mesh of these material points")
    lookup = np.full(geometry.shape[0], -1, np.int64)
    lookup[node_index] = np.arange(node_index.size)
    cells = lookup[topology[:, :4]]
    if np.any(cells < 0):
        raise DatasetError(f"{mesh_xdmf}: a tetrahedron's corner is not a material point")
    return cells


# -- reading -----------------------------------------------------------------------------
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
        answer (an unstable equilibrium, :mod:`studies.stability_audit`) is no sample.

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
