"""The unloaded reference state of an imaged (already loaded) shape.

A breast imaged prone hangs under gravity: its mesh is a *deformed* configuration x. Taken as
stress-free, a supine prediction from it carries the prone sag twice. The reference
configuration X is the one whose forward solve under the imaged posture's gravity reproduces x:

    X + u(X) = x,

with u(X) the displacement of the forward problem on the reference X (same C1, boundary
conditions and contact). By default (``method="inverse"``) this module first solves the
inverse-motion problem (:mod:`fem.inverse_motion`: the same equilibrium written on the loaded
mesh, with the reference as unknown, in one nonlinear solve) and then checks its answer with a
forward solve that starts from it; where the check leaves a misfit above the tolerance (a
straight mesh), or the inverse solve fails, the fixed-point iteration of Sellier (2011) goes on
from there (from the loaded shape after a failure),

    r_k = X_k + u(X_k) − x,    X_{k+1} = X_k − r_k   (the plain step),

accelerated by Anderson's mixing of the last five iterates (the step that the history's
residual differences say cancels the residual best), or, as a check, by Aitken's dynamic
relaxation of the plain step:

    X_{k+1} = X_k − ω_k r_k,   ω_{k+1} = −ω_k (r_k · (r_{k+1} − r_k)) / |r_{k+1} − r_k|²,

starting from the inverse-motion answer, or from X_0 = x (the first iterate is then the naive
"reverse the sag" guess). Each forward
solve starts from the previous iterate's converged state at the full load (a warm start: the
fields of neighbouring iterates differ little), falling back to the adaptive load path from rest
where the warm start fails, and from rest directly after a step large against the displacement
(:data:`WARM_STEP_FRACTION`). The clamped chest wall does not move (u = 0 there), so its nodes
keep their imaged positions. The estimate is returned as geometry-node positions and written
as a tagged mesh (:func:`write_reference_mesh`) that every rule can take as its reference.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from fem.case import CaseRunner
from fem.exceptions import InvalidParameterError
from fem.inverse_motion import InverseMotionResult, solve_inverse_motion
from fem.io import node_displacement
from fem.parameters import Gravity, Material

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class ReferenceEstimate:
    """Outcome of :func:`estimate_reference`.

    Attributes:
        converged: the misfit fell below the tolerance within the iteration budget.
        reason: why it stopped.
        X: geometry-node positions of the reference (m), in the mesh's node order.
        misfit_m: after each forward solve, the largest distance |X + u(X) − x| over the nodes.
        newton_iterations: Newton iterations of each forward solve.
        warm_starts: forward solves that converged from the previous iterate's state.
        relaxation: Aitken's ω at each update (the ``aitken`` method).
        wall_s: wall time of the whole estimate.
        forward_solves: forward solves done.
        method: the acceleration (:data:`METHODS`).
        restarts: Anderson histories dropped after a mixed iterate's solve failed.
        inverse: the inverse-motion solve that started the iteration (``inverse`` method).
        largest_shift_m: the largest node distance between the loaded shape and ``X``.
    """

    converged: bool
    reason: str
    X: np.ndarray
    misfit_m: list[float] = field(default_factory=list)
    newton_iterations: list[int] = field(default_factory=list)
    warm_starts: int = 0
    relaxation: list[float] = field(default_factory=list)
    wall_s: float = 0.0
    forward_solves: int = 0
    method: str = "inverse"
    restarts: int = 0
    inverse: InverseMotionResult | None = None
    largest_shift_m: float = 0.0

    def record(self) -> dict[str, Any]:
        """JSON-able summary, without the positions.

        Its keys are those ``reference.json`` shares with the workflow's record
        (:class:`studies.reference_state.reference_state.ReferenceRecord`).
        """
        inverse = self.inverse
        return {
            "converged": self.converged, "reason": self.reason,
            "forward_solves": self.forward_solves, "misfit_mm": [1e3 * m for m in self.misfit_m],
            "newton_iterations": self.newton_iterations, "warm_starts": self.warm_starts,
            "relaxation": self.relaxation, "wall_s": self.wall_s, "method": self.method,
            "restarts": self.restarts,
            "inverse_newton_iterations": None if inverse is None
            else inverse.loading.total_iterations,
            "inverse_s": None if inverse is None else inverse.wall_s,
            "largest_shift_mm": 1e3 * self.largest_shift_m,
        }


#: How the reference is found: the inverse-motion solve checked (and, where needed, finished) by
#: the fixed point with Anderson's mixing; the fixed point alone from the loaded shape, with
#: Anderson's mixing of the last iterates or Aitken's relaxation.
METHODS = ("inverse", "anderson", "aitken")
#: Iterates Anderson's mixing combines.
ANDERSON_DEPTH = 5
#: A forward solve starts from the previous iterate's state only where the geometry moved by
#: less than this fraction of that state's largest displacement: after a larger step (the
#: first ones, tens of millimetres on a soft breast) Newton from it takes longer than the load
#: path from rest, or fails after its full iteration budget.
WARM_STEP_FRACTION = 0.25


def _anderson_step(Xs: list[np.ndarray], Rs: list[np.ndarray]) -> np.ndarray:
    """Anderson's mixing (type II, full step) of the fixed point X ← X − r over the history.

    With f = −r and G(X) = X − r(X): minimise |f_k − ΔF γ| and step to G(X_k) − ΔG γ, where
    ΔF and ΔG hold the differences of successive f and G. One iterate gives the plain step.
    """
    G = [X - R for X, R in zip(Xs, Rs, strict=True)]
    if len(Xs) == 1:
        return G[-1]
    dF = np.stack([(Rs[i] - Rs[i + 1]).ravel() for i in range(len(Rs) - 1)], axis=1)
    dG = np.stack([(G[i + 1] - G[i]).ravel() for i in range(len(G) - 1)], axis=1)
    gamma, *_ = np.linalg.lstsq(dF, -Rs[-1].ravel(), rcond=None)
    return G[-1] - (dG @ gamma).reshape(G[-1].shape)


def estimate_reference(
    runner: CaseRunner,
    material: Material,
    gravity: Gravity,
    tolerance: float = 1e-5,
    max_iterations: int = 30,
    method: str = "inverse",
) -> ReferenceEstimate:
    """Find the reference geometry whose forward solve reproduces the runner's mesh.

    Args:
        runner: a runner on the *observed* (loaded) mesh; its geometry is moved while the
            estimate runs and put back to the observed shape at the end.
        material: C1 and density of the observation.
        gravity: the gravity the observation was under (its posture).
        tolerance: stop when every node's misfit |X + u(X) − x| is below this (m).
        max_iterations: forward solves allowed (the inverse-motion solve not counted).
        method: ``inverse`` (the inverse-motion solve, :mod:`fem.inverse_motion`, then forward
            solves from its answer, mixed as ``anderson`` until the misfit is below the
            tolerance; after a failed inverse solve, ``anderson`` from the loaded shape),
            ``anderson`` (the last :data:`ANDERSON_DEPTH` iterates mixed; where a mixed
            iterate's forward solve fails, the history is dropped and the plain step from the
            best iterate taken) or ``aitken`` (Aitken's relaxation of the plain step).

    Returns:
        The estimate; ``converged`` False (with the reason) when a forward solve fails or the
        budget runs out, with the best iterate found.

    Raises:
        InvalidParameterError: for an unknown method or a mesh split over processes.
    """
    if method not in METHODS:
        raise InvalidParameterError(f"method must be one of {METHODS}, not {method!r}")
    problem = runner.problem
    mesh = problem.mesh
    if mesh.comm.size != 1:
        raise InvalidParameterError("the reference state is estimated in serial")
    observed = mesh.geometry.x.copy()
    start = time.perf_counter()
    problem.set_case(material, gravity)
    runner.solver.scale_to_load()
    X = observed.copy()
    warm: np.ndarray | None = None
    inverse = None
    if method == "inverse":
        inverse = solve_inverse_motion(mesh, runner.facet_tags, runner.settings, material,
                                       gravity, runner.cell_tags)
        if inverse.converged:
            X, warm = inverse.X.copy(), inverse.state
        else:
            log.info("the inverse-motion solve failed (%s): the fixed point from the loaded "
                     "shape", inverse.loading.reason)
    best: tuple[float, np.ndarray, np.ndarray | None] = (np.inf, X.copy(), None)
    misfits, iterations, relaxations = [], [], []
    history: list[tuple[np.ndarray, np.ndarray]] = []
    warm_starts = restarts = 0
    previous: np.ndarray | None = None
    omega = 1.0
    reason = f"no reference within {max_iterations} forward solves"
    converged = False
    try:
        for _ in range(max_iterations):
            problem.set_geometry(X)
            ok, its, was_warm = runner.solve_from(material, gravity, warm)
            iterations.append(its)
            warm_starts += was_warm
            if not ok and method != "aitken" and len(history) > 1 and best[2] is not None:
                # a mixed iterate out of reach: drop the history, plain step from the best
                log.info("forward solve failed on a mixed iterate: plain step from the best")
                restarts += 1
                history.clear()
                X = best[1] - best[2]
                warm = None
                continue
            if not ok:
                reason = (f"the forward solve on iterate {len(iterations)} failed: no reference "
                          "found (the shape may be out of reach for this C1 and posture)")
                break
            warm = problem.w.x.array.copy()
            u_nodes = node_displacement(problem)
            largest_u = float(np.linalg.norm(u_nodes, axis=1).max())
            residual = X + u_nodes - observed
            misfit = float(np.linalg.norm(residual, axis=1).max())
            misfits.append(misfit)
            if misfit < best[0]:
                best = (misfit, X.copy(), residual.copy())
            log.info("reference iterate %d: misfit %.3g mm, %d Newton its%s", len(misfits),
                     1e3 * misfit, its, " (warm)" if was_warm else "")
            if misfit <= tolerance:
                converged, reason = True, "converged"
                break
            if method != "aitken":
                history = [*history, (X.copy(), residual)][-ANDERSON_DEPTH - 1:]
                step = _anderson_step([h[0] for h in history], [h[1] for h in history]) - X
            else:
                if previous is not None:
                    change = (residual - previous).ravel()
                    denominator = float(change @ change)
                    if denominator > 0:
                        omega = -omega * float(previous.ravel() @ change) / denominator
                relaxations.append(omega)
                previous = residual
                step = -omega * residual
            if float(np.linalg.norm(step, axis=1).max()) > WARM_STEP_FRACTION * largest_u:
                warm = None  # too far for the last state to be a guess: from rest
            X = X + step
    finally:
        problem.set_geometry(observed)
    if not converged and inverse is not None and not inverse.converged:
        reason += f"; the inverse-motion solve failed before it: {inverse.loading.reason}"
    return ReferenceEstimate(
        converged=converged, reason=reason, X=best[1], misfit_m=misfits,
        newton_iterations=iterations, warm_starts=int(warm_starts), relaxation=relaxations,
        wall_s=time.perf_counter() - start, forward_solves=len(iterations), method=method,
        restarts=restarts, inverse=inverse,
        largest_shift_m=float(np.linalg.norm(best[1] - observed, axis=1).max()),
    )


def write_reference_mesh(runner: CaseRunner, X: np.ndarray, xdmf_path: str | Path) -> Path:
    """Write the runner's mesh file with its nodes at the reference positions ``X``.

    The cells, tags and node numbering are the observed file's (:func:`meshes.io.moved_mesh`):
    node k of the reference file is node k of the imaged file, the same material point, which
    is how tracking pairs the two.
    """
    from meshes.io import moved_mesh

    return moved_mesh(runner.mesh_path, runner.mesh, X, xdmf_path)


def main(argv: list[str] | None = None) -> int:
    """``python -m fem.reference OBSERVED --c1 C1 --phi PHI --out DIR [options]``.

    Options: ``--theta``, ``--config``, ``--tolerance-mm``, ``--method`` (:data:`METHODS`).
    Estimates the reference of the observed (loaded) mesh under that case's gravity and writes
    ``DIR/reference.xdmf`` (the same tags: any rule's mesh) and ``DIR/reference.json`` (the
    iterations, misfits and cost). Nothing is written when no reference is found: the exit
    status is 1 and the reason is printed; 2 for bad input.
    """
    import argparse
    import json
    import sys

    from fem.arguments import angle_deg, c1_kpa, output_folder, positive
    from fem.configfile import read_config_file
    from fem.exceptions import FEError
    from fem.parameters import SolverSettings
    from fem.sweep import Case
    from meshes.exceptions import MeshInputError

    parser = argparse.ArgumentParser(prog="python -m fem.reference",
                                     description="the unloaded reference of a loaded shape")
    parser.add_argument("observed", type=Path, help="the loaded shape: a mesh XDMF with tags")
    parser.add_argument("--c1", type=c1_kpa, required=True, help="C1 in kPa")
    parser.add_argument("--phi", type=angle_deg, required=True, help="the observation's Φ (deg)")
    parser.add_argument("--theta", type=angle_deg, default=0.0, help="the observation's θ (deg)")
    parser.add_argument("--out", type=output_folder, required=True, help="folder to write")
    parser.add_argument("--config", type=Path, help="config (sections fe, material, mesh)")
    parser.add_argument("--tolerance-mm", type=positive, default=1e-2,
                        help="largest node misfit accepted, mm")
    parser.add_argument("--method", choices=METHODS, default="inverse",
                        help="the inverse-motion solve checked by forward solves (default), or "
                             "the fixed point alone with Anderson's or Aitken's acceleration")
    args = parser.parse_args(argv)
    # force: FFCx (imported with dolfinx) has already given the root logger a handler
    logging.basicConfig(level=logging.INFO, format="%(message)s", force=True)
    try:
        settings = SolverSettings.from_config(read_config_file(args.config) if args.config
                                              else {})
        case = Case(args.c1, args.phi, args.theta)
        runner = CaseRunner(args.observed, settings)
        estimate = estimate_reference(runner, case.material(settings.density),
                                      case.gravity(settings.gravity),
                                      tolerance=1e-3 * args.tolerance_mm, method=args.method)
    except (FEError, MeshInputError, OSError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    if not estimate.converged:
        runner.close()
        print(f"no reference: {estimate.reason}", file=sys.stderr)
        return 1
    args.out.mkdir(parents=True, exist_ok=True)
    write_reference_mesh(runner, estimate.X, args.out / "reference.xdmf")
    runner.close()
    record = {"imaged": str(args.observed), "case": case.id, **estimate.record()}
    tmp = args.out / ".reference.json.tmp"
    tmp.write_text(json.dumps(record, indent=2))
    tmp.replace(args.out / "reference.json")
    print(json.dumps({k: record[k] for k in ("case", "reason", "forward_solves", "wall_s")}))
    return 0


if __name__ == "__main__":
    import sys

    sys.exit(main())


__all__ = [
    "ReferenceEstimate", "estimate_reference", "main", "write_reference_mesh",
]
