"""The stiffness from a second observation of the skin: command line, figure and benchmark.

    .venv/bin/python -m studies.reference_state.stiffness SCAN.csv --reference REF.xdmf \
        --model results/surrogate/model --phi 0 [--theta 0] [--config config.yaml] --out DIR

reads the second observation (a ``name,x,y,z`` CSV of points on the skin, in the imported file's
own axes and units when the config's ``mesh.source`` is ``file``, else in the project's frame in
m), estimates C1 (:func:`surrogate.stiffness.estimate_stiffness`: the surrogate searches, FE on
the reference confirms) and writes ``DIR/stiffness.json`` and the misfit curve
``DIR/misfit.png``.

    .venv/bin/python -m studies.reference_state.stiffness --benchmark REF.xdmf --model MODEL [--c1
    1.5 3.5]
        [--noise-mm 0.5] [--phi 0]

is the benchmark: the skin of an FE solve at each true C1 (the skin's vertices) with Gaussian
noise of that size added to every coordinate is the observation; it prints the estimate, its
error, the interval, whether it holds the truth, and the wall time of the whole estimate.
"""

from __future__ import annotations

import argparse
import logging
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from studies.results import Result

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class StiffnessResult(Result):
    """``stiffness.json``: the estimate of C1 from a second observation.

    Attributes:
        observation: the observed points' file.
        phi: the observation's posture Φ, degrees.
        theta: its θ, degrees.
        C1_kPa: the estimate (FE-confirmed).
        interval_kPa: the likelihood-ratio interval.
        confidence: its level.
        surrogate_C1_kPa: the surrogate search's optimum.
        rms_mm: RMS distance of the observed points from the skin predicted at the estimate.
        points: observed points.
        curve_C1_kPa: the surrogate's search grid.
        curve_rms_mm: its RMS misfit at each value.
        fe_C1_kPa: the FE confirmation solves' C1.
        fe_rms_mm: their RMS misfits.
        converged: the FE confirmation settled.
        search_s: the surrogate search's wall time.
        confirm_s: the FE confirmation's wall time.
        wall_s: the whole estimate's wall time (without reading the model and the mesh).
        truth_C1_kPa: the true C1 where it is known (the benchmark).
    """

    observation: str
    phi: float
    theta: float
    C1_kPa: float
    interval_kPa: list[float]
    confidence: float
    surrogate_C1_kPa: float
    rms_mm: float
    points: int
    curve_C1_kPa: list[float]
    curve_rms_mm: list[float]
    fe_C1_kPa: list[float]
    fe_rms_mm: list[float]
    converged: bool
    search_s: float
    confirm_s: float
    wall_s: float
    truth_C1_kPa: float | None = None


class Estimator:
    """The reference mesh, its FE runner and the surrogate, loaded once for many estimates."""

    def __init__(self, reference: Path, model_folder: Path, settings: Any) -> None:
        from fem.case import CaseRunner
        from meshes.io import nodes_in_file_order
        from meshes.surface import skin_triangles
        from studies.reference_state.tracking import check_model_on
        from surrogate.predict import Surrogate

        self.model = Surrogate.load(model_folder)
        self.runner = CaseRunner(reference, settings)
        try:
            check_model_on(self.model, self.runner.mesh)
        except Exception:
            self.runner.close()
            raise
        self.X_file = nodes_in_file_order(self.runner.mesh)
        self.triangles = skin_triangles(self.runner.mesh, self.runner.facet_tags)

    def close(self) -> None:
        """Free the FE runner (:meth:`fem.case.CaseRunner.close`)."""
        self.runner.close()

    def __enter__(self) -> Estimator:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def estimate(self, observed: np.ndarray, phi: float, theta: float, name: str,
                 truth: float | None = None, fe: bool = True) -> StiffnessResult:
        """Estimate C1 from ``observed`` (n, 3), project frame, m."""
        from surrogate.stiffness import estimate_stiffness, fe_shape, surrogate_shape

        lo, hi = self.model.training_range.get("C1_kPa", (None, None))
        if lo is None:
            raise ValueError("the model records no trained C1 range")
        found = estimate_stiffness(
            observed, self.triangles, self.X_file,
            surrogate_shape(self.model, self.X_file, phi, theta),
            fe_shape(self.runner, phi, theta) if fe else None, (lo, hi),
        )
        return StiffnessResult(
            observation=name, phi=phi, theta=theta, C1_kPa=found.C1_kPa,
            interval_kPa=list(found.interval_kPa), confidence=found.confidence,
            surrogate_C1_kPa=found.surrogate_C1_kPa, rms_mm=found.rms_mm, points=found.points,
            curve_C1_kPa=found.curve_C1_kPa, curve_rms_mm=found.curve_rms_mm,
            fe_C1_kPa=found.fe_C1_kPa, fe_rms_mm=found.fe_rms_mm, converged=found.converged,
            search_s=found.search_s, confirm_s=found.confirm_s, wall_s=found.wall_s,
            truth_C1_kPa=truth,
        )

    def skin_of_solve(self, c1: float, phi: float, theta: float) -> np.ndarray:
        """The skin's vertices after an FE solve at (C1, Φ, θ), m (the benchmark's truth)."""
        from surrogate.stiffness import fe_shape

        nodes = fe_shape(self.runner, phi, theta)(c1)
        return nodes[np.unique(self.triangles)]


def write_outputs(result: StiffnessResult, folder: Path) -> None:
    """``stiffness.json`` and ``misfit.png`` in ``folder``."""
    from studies.figures.surrogate import plot_stiffness_misfit

    folder.mkdir(parents=True, exist_ok=True)
    plot_stiffness_misfit(result.curve_C1_kPa, result.curve_rms_mm, result.fe_C1_kPa,
                          result.fe_rms_mm, result.C1_kPa, result.interval_kPa,
                          result.truth_C1_kPa, folder / "misfit.png")
    result.write(folder / "stiffness.json")


def benchmark(estimator: Estimator, c1s: list[float], noise_mm: float, phi: float, theta: float,
              seed: int, out: Path | None) -> list[StiffnessResult]:
    """Estimate C1 from noisy FE skins at each true C1; print one row each."""
    from studies.timing_hygiene import machine_state

    rng = np.random.default_rng(seed)
    print(f"machine: {machine_state().to_json()}")
    print(f"{'truth':>6} {'estimate':>8} {'error %':>7} {'interval':>17} {'holds':>5} "
          f"{'surrogate':>9} {'FE solves':>9} {'settled':>7} {'RMS mm':>6} {'search s':>8} "
          f"{'FE s':>6} {'total s':>7}")
    results = []
    for c1 in c1s:
        skin = estimator.skin_of_solve(c1, phi, theta)
        observed = skin + rng.normal(scale=1e-3 * noise_mm, size=skin.shape)
        r = estimator.estimate(observed, phi, theta, f"FE skin at C1 = {c1:g} kPa + "
                               f"{noise_mm:g} mm noise", truth=c1)
        lo, hi = r.interval_kPa
        print(f"{c1:>6g} {r.C1_kPa:>8.4f} {100 * (r.C1_kPa / c1 - 1):>7.2f} "
              f"[{lo:>7.4f}, {hi:>7.4f}] {str(lo <= c1 <= hi):>5} {r.surrogate_C1_kPa:>9.4f} "
              f"{len(r.fe_C1_kPa):>9d} {str(r.converged):>7} {r.rms_mm:>6.3f} "
              f"{r.search_s:>8.2f} {r.confirm_s:>6.2f} {r.wall_s:>7.2f}", flush=True)
        if out is not None:
            write_outputs(r, out / f"c1={c1:g}")
        results.append(r)
    return results


def estimate_file(observation: Path, reference: Path, model_folder: Path, phi: float,
                  theta: float, settings: Any, mesh_section: dict[str, Any] | None, out: Path,
                  fe: bool = True) -> StiffnessResult:
    """Estimate C1 from an observation file; write ``stiffness.json`` and ``misfit.png``.

    Args:
        observation: ``name,x,y,z`` of skin points in the posture (Φ, θ), in the file's frame
            and units for an import (``mesh_section``'s ``file``), else the project's frame, m.
        reference: the reference mesh.
        model_folder: a surrogate trained on the sweep from it.
        phi: Φ of the observation.
        theta: θ of the observation.
        settings: the solver settings.
        mesh_section: the config's ``mesh`` section, or None.
        out: the folder to write.
        fe: confirm with FE (else the surrogate's estimate alone).
    """
    from meshes.config import MeshConfig
    from meshes.points import read_points

    spec = MeshConfig.from_mapping(dict(mesh_section or {})).imported
    _, points = read_points(observation)
    if spec is not None:
        points = spec.to_project_frame(points)
    with Estimator(reference, model_folder, settings) as estimator:
        result = estimator.estimate(points, phi, theta, str(observation), fe=fe)
    write_outputs(result, out)
    return result


def main(argv: list[str] | None = None) -> int:
    """The estimate from a points file, or the benchmark."""
    from fem.arguments import angle_deg, c1_kpa, output_folder
    from fem.configfile import read_config_file
    from fem.exceptions import FEError
    from fem.parameters import SolverSettings
    from meshes.exceptions import GeometryError, MeshInputError
    from studies.reference_state.tracking import TrackingInputError
    from surrogate.exceptions import SurrogateError
    from surrogate.stiffness import StiffnessError

    parser = argparse.ArgumentParser(prog="python -m studies.reference_state.stiffness",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("observation", type=Path, nargs="?",
                        help="CSV name,x,y,z of skin points in the second posture")
    parser.add_argument("--benchmark", type=Path, metavar="REFERENCE",
                        help="run the benchmark on this reference mesh")
    parser.add_argument("--reference", type=Path, help="the reference mesh (XDMF)")
    parser.add_argument("--model", type=Path, required=True,
                        help="a surrogate trained on the sweep from the reference")
    parser.add_argument("--phi", type=angle_deg, default=0.0, help="the observation's Φ (deg)")
    parser.add_argument("--theta", type=angle_deg, default=0.0, help="the observation's θ (deg)")
    parser.add_argument("--config", type=Path,
                        help="config: solver settings and mesh.file or mesh.image")
    parser.add_argument("--out", type=output_folder, help="folder to write")
    parser.add_argument("--no-fe", action="store_true", help="the surrogate's estimate alone")
    parser.add_argument("--c1", type=c1_kpa, nargs="+", default=[1.5, 3.5],
                        help="benchmark: the true C1 values (kPa)")
    parser.add_argument("--noise-mm", type=float, default=0.5, help="benchmark: noise (mm)")
    parser.add_argument("--seed", type=int, default=0, help="benchmark: the noise's seed")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.WARNING, format="%(message)s")
    reference = args.benchmark or args.reference
    if reference is None or (args.benchmark is None and
                             (args.observation is None or args.out is None)):
        parser.error("give OBSERVATION --reference REF --out DIR, or --benchmark REF")
    try:
        values = read_config_file(args.config) if args.config else {}
        settings = SolverSettings.from_config(values)
        if args.benchmark is not None:
            with Estimator(reference, args.model, settings) as estimator:
                benchmark(estimator, args.c1, args.noise_mm, args.phi, args.theta, args.seed,
                          args.out)
            return 0
        result = estimate_file(args.observation, reference, args.model, args.phi, args.theta,
                               settings, values.get("mesh"), args.out, fe=not args.no_fe)
    except (FEError, GeometryError, MeshInputError, SurrogateError, StiffnessError,
            TrackingInputError, OSError, ValueError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    lo, hi = result.interval_kPa
    print(f"C1 = {result.C1_kPa:.4g} kPa ({100 * result.confidence:g} % interval "
          f"[{lo:.4g}, {hi:.4g}]), RMS misfit {result.rms_mm:.3f} mm over {result.points} "
          f"points, {result.wall_s:.2f} s; wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
