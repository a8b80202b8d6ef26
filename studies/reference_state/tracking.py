"""Track named points from the imaged posture to another, by FE and by the surrogate, side by side.

    .venv/bin/python -m studies.reference_state.tracking POINTS.csv --imaged IMAGED.xdmf
    --reference REF.xdmf
        --model results/surrogate/model --c1 1.0 --phi 0 [--theta 0] [--config config.yaml]
        --out results/tracking/tumour.csv

A point seen in the image (a tumour's centre, its margin: a ``name,x,y,z`` CSV, in the imported
file's own axes and units when the config's ``mesh.source`` is ``file``, in the scanner's LPS
millimetres when it is ``image``, else in the project's frame in m) is carried to the target
posture two ways:

* **FE** (:func:`fem.tracking.track`): located in its cell of the imaged mesh, carried to the
  reference by the same local coordinates, then moved by the target posture's solve on the
  reference;
* **surrogate**: the same material position, queried in the surrogate trained on the sweep
  from that reference (:meth:`surrogate.predict.Surrogate.at`), in well under a millisecond.

The CSV has, per point, the observed position, its material (reference) position, both
predictions (in the points' frame and units) and their distance in mm. The model must have been
trained on this reference mesh: its material points are checked against the reference's nodes.
"""

from __future__ import annotations

import argparse
import csv
import logging
import sys
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from meshes.io import from_file_order, nodes_in_file_order, same_cells
from studies.results import Result
from studies.surrogate_study.timing import time_model
from studies.timing_hygiene import machine_state, one_core

log = logging.getLogger(__name__)

#: The largest distance (m) between a model's material point and the reference node it names
#: for the model to count as trained on that reference.
SAME_MESH_M = 1e-7


class TrackingInputError(ValueError):
    """Inputs that do not belong together (meshes, model) or cannot be tracked."""


@dataclass(frozen=True)
class TrackingResult(Result):
    """Named points carried from the imaged posture to a target posture, by FE and surrogate.

    Positions are (N, 3) lists in the project's frame, m.

    Attributes:
        names: the points' names.
        C1_kPa: the stiffness.
        target_phi: Φ of the target posture, degrees.
        target_theta: θ of the target posture, degrees.
        observed: positions in the imaged (loaded) shape.
        reference: their material positions in the reference.
        fe: positions in the target posture by FE.
        surrogate: positions in the target posture by the surrogate.
        difference_mm: |fe − surrogate| per point, mm.
        max_difference_mm: the largest of them.
        fe_converged: whether the target posture's FE solve converged.
        fe_s: wall time of the FE path (location, solve, evaluation), s.
        surrogate_ms: the surrogate's query for all the points on one core: median, p95 (ms).
        machine: where it was measured.
    """

    names: list[str]
    C1_kPa: float
    target_phi: float
    target_theta: float
    observed: list[list[float]]
    reference: list[list[float]]
    fe: list[list[float]]
    surrogate: list[list[float]]
    difference_mm: list[float]
    max_difference_mm: float
    fe_converged: bool
    fe_s: float
    surrogate_ms: dict[str, Any]
    machine: dict[str, Any]


def reference_positions(imaged: Path, imaged_mesh: Any, reference: Path, reference_mesh: Any
                        ) -> np.ndarray:
    """The reference file's node positions in the imaged mesh's node order.

    A reference file written by :mod:`fem.reference` keeps the imaged file's cells and node
    numbering: node k of one is node k of the other.

    Raises:
        TrackingInputError: if the two files do not have the same cells on the same nodes
            (the reference of another mesh).
    """
    if not same_cells(imaged, reference):
        raise TrackingInputError(
            f"{reference} is not the reference of {imaged} (their cells differ): write it "
            "with python -m fem.reference from that mesh"
        )
    return from_file_order(imaged_mesh, nodes_in_file_order(reference_mesh))


def check_model_on(model: Any, reference: Any) -> None:
    """Refuse a surrogate whose material points are not the reference mesh's nodes.

    Raises:
        TrackingInputError: naming the largest mismatch.
    """
    nodes = nodes_in_file_order(reference)
    index = np.asarray(model.node_index, dtype=np.int64)
    if index.max() >= len(nodes):
        raise TrackingInputError(
            f"the surrogate names node {index.max()}, but the reference mesh has {len(nodes)}: "
            "it was trained on another mesh; train it on the sweep from this reference"
        )
    gap = float(np.linalg.norm(nodes[index] - model.X, axis=1).max())
    if gap > SAME_MESH_M:
        raise TrackingInputError(
            f"the surrogate's material points lie up to {1e3 * gap:.3f} mm from the reference "
            "mesh's nodes: it was trained on another mesh; train it on the sweep from this "
            "reference"
        )


def track_both(runner: Any, X: np.ndarray, model: Any, names: list[str], points: np.ndarray,
               case: Any, density: float = 900.0, gravity: float = 9.81,
               repeats: int = 200) -> TrackingResult:
    """Carry ``points`` (imaged shape, m) to ``case``'s posture by FE and by ``model``.

    Args:
        runner: a :class:`fem.case.CaseRunner` on the imaged mesh.
        X: the reference node positions, in the runner's node order.
        model: a :class:`surrogate.predict.Surrogate` trained on the sweep from ``X``.
        names: the points' names.
        points: (N, 3), the imaged shape's frame (project frame), m.
        case: the target :class:`fem.sweep.Case` (its C1 is the tissue's).
        density: kg/m³.
        gravity: m/s².
        repeats: timed surrogate queries.
    """
    from fem.tracking import track
    from surrogate.exceptions import ExtrapolationWarning

    start = time.perf_counter()
    tracked = track(runner, X, names, points, case.material(density), case.gravity(gravity))
    fe_s = time.perf_counter() - start
    at_points = model.at(tracked.reference)
    query = (case.C1, case.phi, case.theta)
    with warnings.catch_warnings():
        warnings.simplefilter("error", ExtrapolationWarning)  # refused, not timed
        u_mm = at_points.predict(*query)
    with warnings.catch_warnings(), one_core() as core:
        warnings.simplefilter("ignore")
        timing = time_model(at_points, [query], repeats=repeats, warmup=20)
    surrogate = tracked.reference + 1e-3 * np.asarray(u_mm, dtype=float)
    difference = 1e3 * np.linalg.norm(tracked.target - surrogate, axis=1)
    return TrackingResult(
        names=list(names), C1_kPa=case.C1, target_phi=case.phi, target_theta=case.theta,
        observed=tracked.observed.tolist(), reference=tracked.reference.tolist(),
        fe=tracked.target.tolist(), surrogate=surrogate.tolist(),
        difference_mm=difference.tolist(), max_difference_mm=float(difference.max()),
        fe_converged=tracked.converged, fe_s=fe_s,
        surrogate_ms={"points": len(names), **timing["api"]},
        machine={**machine_state().to_json(), "pinned_core": core},
    )


def write_tracking_csv(path: Path, result: TrackingResult,
                       to_frame: Callable[[np.ndarray], np.ndarray] | None = None,
                       unit: str = "m") -> None:
    """Write the tracked points as CSV, positions in the points' own frame and ``unit``.

    Args:
        path: the CSV.
        result: the tracked points.
        to_frame: the map from the project's frame (m) to the points' frame, None for the
            project's frame.
        unit: the points' unit, named in the header.
    """
    columns = ("observed", "reference", "fe", "surrogate")
    arrays = [np.asarray(getattr(result, c), dtype=float) for c in columns]
    if to_frame is not None:
        arrays = [to_frame(a) for a in arrays]
    header = ["name"] + [f"{c}_{axis}_{unit}" for c in columns for axis in "xyz"]
    header.append("difference_mm")
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp")
    with tmp.open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(header)
        for i, name in enumerate(result.names):
            row = [name] + [f"{v:.6g}" for a in arrays for v in a[i]]
            writer.writerow(row + [f"{result.difference_mm[i]:.4f}"])
    tmp.replace(path)


def track_file(points_csv: Path, imaged: Path, reference: Path, model_folder: Path, c1: float,
               phi: float, theta: float, settings: Any, mesh_section: dict[str, Any] | None,
               out: Path) -> TrackingResult:
    """Track a points file to (Φ, θ) at C1 both ways; write the CSV and its JSON beside it.

    Args:
        points_csv: ``name,x,y,z`` in the imaged shape, in the file's frame and units for an
            import (``mesh_section``'s ``file``), in the scanner's LPS mm for an image
            (``mesh_section``'s ``image``), else in the project's frame, m.
        imaged: the imaged mesh.
        reference: its reference (:mod:`fem.reference`).
        model_folder: a surrogate trained on the sweep from ``reference``.
        c1: C1 (kPa).
        phi: Φ of the target posture.
        theta: θ of the target posture.
        settings: the solver settings (:class:`fem.parameters.SolverSettings`).
        mesh_section: the config's ``mesh`` section (its ``file`` frame), or None.
        out: the CSV to write.

    Raises:
        TrackingInputError: for meshes or a model that do not belong together, an FE solve
            that does not converge, or a surrogate query outside its training range.
    """
    from fem.case import CaseRunner
    from fem.sweep import Case
    from meshes.config import MeshConfig
    from meshes.io import read_mesh
    from meshes.points import read_points
    from surrogate.exceptions import ExtrapolationWarning
    from surrogate.predict import Surrogate

    spec = MeshConfig.from_mapping(dict(mesh_section or {})).imported
    names, points = read_points(points_csv)
    if spec is not None:
        points = spec.to_project_frame(points)
    reference_mesh, _, _ = read_mesh(reference)
    model = Surrogate.load(model_folder)
    check_model_on(model, reference_mesh)
    with CaseRunner(imaged, settings) as runner:
        X = reference_positions(imaged, runner.mesh, reference, reference_mesh)
        try:
            result = track_both(runner, X, model, names, points, Case(c1, phi, theta),
                                settings.density, settings.gravity)
        except ExtrapolationWarning as err:
            raise TrackingInputError(f"the surrogate would extrapolate: {err}") from None
    if not result.fe_converged:
        raise TrackingInputError(f"the FE solve of the target posture (C1 = {c1:g} kPa, "
                                 f"Φ = {phi:g}°, θ = {theta:g}°) did not converge")
    if spec is None:
        write_tracking_csv(out, result)
    else:
        write_tracking_csv(out, result, spec.to_file_frame, spec.units)
    result.write(out.with_suffix(".json"))
    return result


def main(argv: list[str] | None = None) -> int:
    """Track the points by both paths, write the CSV (and a JSON beside it), print a summary."""
    from fem.arguments import angle_deg, c1_kpa, output_file, refuse_overwriting
    from fem.configfile import read_config_file
    from fem.exceptions import FEError
    from fem.parameters import SolverSettings
    from meshes.exceptions import GeometryError, MeshInputError
    from surrogate.exceptions import SurrogateError

    parser = argparse.ArgumentParser(prog="python -m studies.reference_state.tracking",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("points", type=Path, help="CSV name,x,y,z in the imaged shape")
    parser.add_argument("--imaged", type=Path, required=True, help="the imaged mesh (XDMF)")
    parser.add_argument("--reference", type=Path, required=True,
                        help="its reference (python -m fem.reference)")
    parser.add_argument("--model", type=Path, required=True,
                        help="a surrogate trained on the sweep from the reference")
    parser.add_argument("--c1", type=c1_kpa, required=True, help="C1 in kPa")
    parser.add_argument("--phi", type=angle_deg, required=True, help="target posture's Φ (deg)")
    parser.add_argument("--theta", type=angle_deg, default=0.0, help="target posture's θ (deg)")
    parser.add_argument("--config", type=Path,
                        help="config: solver settings and mesh.file or mesh.image")
    parser.add_argument("--out", type=output_file, required=True, help="CSV to write")
    args = parser.parse_args(argv)
    refuse_overwriting(parser, "--out", [args.out, args.out.with_suffix(".json")], [
        ("points", args.points), ("--imaged", args.imaged), ("--reference", args.reference),
        ("--model", args.model), ("--config", args.config)])
    logging.basicConfig(level=logging.WARNING, format="%(message)s")
    try:
        values = read_config_file(args.config) if args.config else {}
        result = track_file(args.points, args.imaged, args.reference, args.model, args.c1,
                            args.phi, args.theta, SolverSettings.from_config(values),
                            values.get("mesh"), args.out)
    except (FEError, GeometryError, MeshInputError, SurrogateError, TrackingInputError,
            OSError, ValueError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    t = result.surrogate_ms
    print(f"{len(result.names)} points to Φ = {args.phi:g}°, θ = {args.theta:g}° at C1 = "
          f"{args.c1:g} kPa: FE against surrogate max {result.max_difference_mm:.3f} mm; FE "
          f"{result.fe_s:.2f} s, surrogate median {t['median_ms']:.4f} ms on one core; wrote "
          f"{args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
