"""Aggregation: every case's files into one HDF5 dataset, written atomically.

The layout is :mod:`fem.dataset`'s (its docstring is written into the file as its
description); :func:`build_dataset` reads each case (:mod:`fem.case_files`), draws the splits
(:mod:`fem.splits`) and writes the file under a temporary name, renamed into place when whole.
"""

from __future__ import annotations

import json
import logging
import os
import tempfile
from collections.abc import Sequence
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

import fem.dataset as dataset_format
from fem.case_files import gather_nodes, read_case
from fem.dataset import BOUNDARY, DOMAIN, FORMAT_VERSION
from fem.directions import direction_keys
from fem.exceptions import DatasetError
from fem.provenance import provenance
from fem.splits import GROUP_SPLITS, SplitFractions, group_partition, softest_held_out_c1
from fem.sweep import Case

log = logging.getLogger(__name__)


#: The tissue map of cases solved before tissues existed (all fat).
HOMOGENEOUS = {"fat": 1.0}


def tissue_map(summaries: Sequence[dict[str, Any]]) -> dict[str, float]:
    """The stiffness ratios the cases were solved with (their summaries' settings).

    Raises:
        DatasetError: if the cases were solved with different maps: their C1 would not be
            one stiffness parameter.
    """
    maps = {json.dumps(((s.get("settings") or {}).get("tissues") or HOMOGENEOUS), sort_keys=True)
            for s in summaries}
    if len(maps) > 1:
        raise DatasetError(
            f"the cases were solved with {len(maps)} different tissue maps "
            f"(material.tissues): {'; '.join(sorted(maps))}; solve them again with one")
    return json.loads(maps.pop())


def build_dataset(
    summary_paths: Sequence[str | Path],
    point_paths: Sequence[str | Path],
    output: str | Path,
    split: SplitFractions = SplitFractions(),
    seed: int = 0,
    config: dict[str, Any] | None = None,
    test_cases: Sequence[Case] = (),
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
        test_cases: setups the by-case split always holds out as test
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

    tissues = tissue_map(summaries)
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
    # each case as its summary describes it (read_case checked it is its folder's case)
    keys = [Case.from_summary(s) for s in summaries]
    wanted = set(test_cases)
    forced = np.array([keys[i] in wanted for i in good_cases], dtype=bool)
    free = good_cases[~forced]
    by_case = {k: free[v] for k, v in split.partition(len(free), rng).items()}
    by_case["test"] = np.sort(np.concatenate([by_case["test"], good_cases[forced]]))
    c1_all = np.array([k.C1 for k in keys])
    phi_all, theta_all = np.array([k.phi for k in keys]), np.array([k.theta for k in keys])
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
        tissues,
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
    tissues: dict[str, float] | None = None,
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
            h5.attrs["description"] = dataset_format.__doc__
            h5.attrs["format_version"] = FORMAT_VERSION
            h5.attrs["created"] = datetime.now(UTC).isoformat()
            h5.attrs["provenance"] = json.dumps(prov, default=str)
            h5.attrs["tissues"] = json.dumps(tissues or HOMOGENEOUS)
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
