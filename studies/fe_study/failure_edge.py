"""Where the FE solution ends: gravity turned from a converged case towards a failed one.

The sweep's soft cases fail in a patch of directions (lying on the side, medially and
caudally), and a case beside that patch is where the surrogate errs most. This study finds
the patch's edge and says what lies there. From a converged case (reached as a chain from its
stiffer C1 values, as the sweep reaches it), it turns the gravity vector at full load along
the great circle to a target direction, a step at a time, each step a Newton solve from the
last state; a step that fails is halved until it is shorter than the resolution. At every
converged state it records the largest displacement, Newton's iterations and the tangent's
inertia (:func:`fem.stability.tangent_inertia`): whether the state is a stable equilibrium.

The answer: the angle from the start at which the solution was last found (the edge, to the
resolution), the first angle at which it was not, and whether every state up to the edge was
stable. Turning gravity while the body follows is the history of a patient rolling over, so
the edge is where that history has no nearby equilibrium; whether a state exists further on
(a mound rolled over the fold, a crease) is beyond a Newton continuation.

``python -m studies.fe_study.failure_edge MESH --c1 0.8 --from -75 0 --to -90 0 [--via 1.2 1.0]
[--config config.yaml] [--step 1.0] [--resolution 0.05] [--json OUT]``

With ``--meet PHI THETA`` (:func:`meet`) gravity is turned from both ``--from`` and ``--to`` to
that direction, which is also solved as the sweep solves it, and the states are compared: two
stable states at one direction are two equilibria of one load (a fold's hysteresis), and the
answer there depends on the patient's history.

In the workflow, :func:`studies.fe_study.sweep_edges.sweep_edges` traces the sweep's own failed
cases
this way.
"""

from __future__ import annotations

import argparse
import logging
import math
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from fem.arguments import angle_deg, c1_kpa, positive
from fem.configfile import read_config_file
from fem.directions import gravity_angles, gravity_direction
from fem.exceptions import InvalidParameterError
from fem.parameters import Gravity, SolverSettings
from fem.sweep import Case
from studies.results import Record, Result
from studies.timing_hygiene import machine_state

log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True)
class EdgeState(Record):
    """One converged state of the turn.

    Attributes:
        angle_deg: the angle between its gravity and the start's.
        phi, theta: its gravity direction (a direction in the paper's plane as (Φ, 0), Φ
            signed).
        newton_iterations: Newton's iterations from the previous state.
        max_displacement_mm: its largest displacement.
        min_detF: its smallest det F (cells collapsing towards 0 where the skin creases).
        negative, zero, pressure_dofs: the tangent's negative eigenvalues and null pivots, and
            the pressure unknowns (a stable state has as many negatives as these).
        stable: no unstable mode and no null pivot.
        contact_vertices: the skin vertices touching the chest (None without contact).
    """

    angle_deg: float
    phi: float
    theta: float
    newton_iterations: int
    max_displacement_mm: float
    min_detF: float
    negative: int
    zero: int
    pressure_dofs: int
    stable: bool
    contact_vertices: int | None = None


@dataclass(frozen=True, slots=True)
class EdgeFailure(Record):
    """A step of the turn that failed: the angle it aimed at and Newton's reason."""

    angle_deg: float
    reason: str


@dataclass(frozen=True, slots=True)
class FailureEdge(Result):
    """The study's record (``--json``).

    Attributes:
        mesh: the mesh solved on.
        C1: the stiffness (kPa).
        start, target: the directions ``[Φ, θ]`` (degrees) the turn runs between.
        via: the stiffer C1 values (kPa) the start case was reached through.
        start_load_path: the start case's outcome.
        span_deg: the angle between the start and the target.
        edge_deg: the angle from the start of the last converged state.
        first_failure_deg: the angle of the shortest step that still failed beyond it; None
            where the turn reached the target.
        reached_target: whether it did.
        all_stable: whether every converged state was a stable equilibrium.
        states: every converged state, in order.
        failures: the angles of the steps that failed, with Newton's reason.
        resolution_deg: the shortest step tried.
        seconds: the study's wall time.
        settings: the solver settings.
        machine: the machine's state at the start.
    """

    mesh: str
    C1: float
    start: list[float]
    target: list[float]
    via: list[float]
    start_load_path: str
    span_deg: float
    edge_deg: float
    first_failure_deg: float | None
    reached_target: bool
    all_stable: bool
    states: list[EdgeState]
    failures: list[EdgeFailure] = field(default_factory=list)
    resolution_deg: float = 0.05
    seconds: float = 0.0
    settings: dict | None = None
    machine: dict | None = None


def great_circle(
    start: np.ndarray, target: np.ndarray
) -> tuple[float, Callable[[float], np.ndarray]]:
    """The angle (degrees) between two unit vectors and the unit vector at any angle on the way.

    Raises:
        InvalidParameterError: for opposite directions (no single great circle joins them) or
            equal ones.
    """
    cos = float(np.clip(start @ target, -1.0, 1.0))
    span = math.degrees(math.acos(cos))
    if span < 1e-9 or span > 180.0 - 1e-6:
        raise InvalidParameterError(
            f"the start and the target are {span:.6g}° apart: choose two directions that are "
            "neither the same nor opposite")
    ortho = target - cos * start
    ortho /= np.linalg.norm(ortho)

    def at(angle_deg: float) -> np.ndarray:
        a = math.radians(angle_deg)
        return math.cos(a) * start + math.sin(a) * ortho

    return span, at


def _check_steps(c1: float, via: tuple[float, ...], step_deg: float, resolution_deg: float) -> None:
    if not (step_deg > 0 and resolution_deg > 0 and resolution_deg <= step_deg):
        raise InvalidParameterError(
            f"the step ({step_deg}°) and resolution ({resolution_deg}°) must be positive, the "
            "resolution no longer than the step")
    if any(v <= c1 for v in via):
        raise InvalidParameterError(f"--via takes C1 values stiffer than {c1} kPa, got {via}")


def reach(
    runner: Any, c1: float, direction: tuple[float, float], via: tuple[float, ...] = ()
) -> Any:
    """Solve C1 = ``c1`` at ``direction`` as a chain does: through ``via``, stiffest first.

    The runner's state holds the answer after. Returns the last case's loading result.

    Raises:
        InvalidParameterError: if a case of the chain does not converge.
    """
    from fem.chain import Neighbours

    neighbours = Neighbours(runner.problem.pressure_dofs)
    for value in (*sorted(via, reverse=True), c1):
        case = Case(value, *direction)
        path, _ = neighbours.path(case)
        result, _ = runner.solve(case, path=path)
        if not result.converged:
            raise InvalidParameterError(
                f"the case {case.id} did not converge ({result.reason}): start from a "
                "direction the sweep solves")
        neighbours.add(case, runner.problem.w.x.array)
    return result


def turn_runner(
    runner: Any,
    c1: float,
    start: tuple[float, float],
    target: tuple[float, float],
    via: tuple[float, ...] = (),
    step_deg: float = 1.0,
    resolution_deg: float = 0.05,
    newton: dict | None = None,
) -> FailureEdge:
    """:func:`turn` on an open :class:`fem.case.CaseRunner`; its state holds the last solution."""
    from fem.stability import tangent_inertia

    _check_steps(c1, via, step_deg, resolution_deg)
    g0, g1 = gravity_direction(np.array([start[0], target[0]]), np.array([start[1], target[1]]))
    span, at = great_circle(g0, g1)
    clock = time.perf_counter()
    problem, solver, settings = runner.problem, runner.solver, runner.settings
    result = reach(runner, c1, start, via)
    material = Case(c1, *start).material(settings.density)

    def record(angle: float, g: np.ndarray, iterations: int) -> EdgeState:
        inertia = tangent_inertia(problem)
        u = problem.displacement().x.array.reshape(-1, 3)
        phi, theta = gravity_angles(g)
        contact = problem.contact_status()
        return EdgeState(angle, phi, theta, iterations,
                         1e3 * float(np.linalg.norm(u, axis=1).max(initial=0.0)),
                         problem.min_detF(), inertia.negative, inertia.zero,
                         inertia.pressure_dofs, inertia.stable,
                         None if contact is None else contact["vertices_in_contact"])

    states = [record(0.0, g0, sum(result.newton_iterations))]
    failures: list[EdgeFailure] = []
    angle, step, state = 0.0, min(step_deg, span), problem.w.x.array.copy()
    while angle < span - 1e-12 and step >= resolution_deg:
        goal = min(angle + step, span)
        g = at(goal)
        problem.set_case(material, Gravity(*gravity_angles(g), magnitude=settings.gravity))
        problem.w.x.array[:] = state
        solver.scale_to_load()
        problem.set_load_fraction(1.0)
        outcome = solver.solve(newton)
        if outcome.converged:
            angle, state = goal, problem.w.x.array.copy()
            states.append(record(angle, g, outcome.iterations))
            log.info("%.3f°: converged in %d its, max |u| %.3f mm, %s", angle,
                     outcome.iterations, states[-1].max_displacement_mm,
                     "stable" if states[-1].stable else "unstable")
            step = min(2 * step, step_deg)
        else:
            failures.append(EdgeFailure(goal, outcome.reason))
            log.info("%.3f°: %s", goal, outcome.reason)
            step /= 2
    problem.w.x.array[:] = state  # the last solution, not the last failed iterate
    reached = angle >= span - 1e-12
    return FailureEdge(
        mesh=str(runner.mesh_path), C1=c1, start=list(start), target=list(target), via=list(via),
        start_load_path=result.reason, span_deg=span, edge_deg=angle,
        first_failure_deg=None if reached else min(
            f.angle_deg for f in failures if f.angle_deg > angle),
        reached_target=reached, all_stable=all(s.stable for s in states), states=states,
        failures=failures, resolution_deg=resolution_deg,
        seconds=time.perf_counter() - clock, settings=settings.describe(solver.options),
        machine=machine_state().to_json())


def turn(
    mesh: str | Path,
    settings: SolverSettings,
    c1: float,
    start: tuple[float, float],
    target: tuple[float, float],
    via: tuple[float, ...] = (),
    step_deg: float = 1.0,
    resolution_deg: float = 0.05,
    newton: dict | None = None,
) -> FailureEdge:
    """Turn gravity from ``start`` to ``target`` at C1 = ``c1`` kPa (see the module).

    ``newton`` sets each step's Newton solve apart from the start's (the iteration limit or
    line search, :meth:`fem.solver.NewtonSolver.solve`).

    Raises:
        InvalidParameterError: for a step or resolution that is not positive, a ``via`` value
            not stiffer than ``c1``, equal or opposite directions, or a start case that does
            not converge.
    """
    from fem.case import CaseRunner

    _check_steps(c1, via, step_deg, resolution_deg)
    with CaseRunner(mesh, settings) as runner:
        return turn_runner(runner, c1, start, target, via, step_deg, resolution_deg, newton)


@dataclass(frozen=True, slots=True)
class Meeting(Result):
    """One direction reached three ways at one C1: is the equilibrium unique there?

    Attributes:
        C1: the stiffness (kPa).
        at: the direction ``[Φ, θ]`` (degrees) the turns meet at.
        turns: gravity turned to ``at`` from each side (:class:`FailureEdge`, its last state
            the one compared).
        chain_converged: whether the case solved as the sweep solves it (from rest through
            ``via``) converged.
        max_difference_mm: the largest point difference (at the displacement's nodes) between
            each pair of the states that were found, keyed ``"a|b"`` with ``a``, ``b`` among
            ``from <Φ>/<θ>`` and ``chain``.
        mean_difference_mm: the mean point difference of each pair.
        stable: whether each state found is a stable equilibrium, by the same keys.
    """

    C1: float
    at: list[float]
    turns: list[FailureEdge]
    chain_converged: bool
    max_difference_mm: dict[str, float]
    mean_difference_mm: dict[str, float]
    stable: dict[str, bool]


def meet(
    mesh: str | Path,
    settings: SolverSettings,
    c1: float,
    sides: tuple[tuple[float, float], ...],
    at: tuple[float, float],
    via: tuple[float, ...] = (),
    step_deg: float = 1.0,
    resolution_deg: float = 0.05,
) -> Meeting:
    """Reach ``at`` by turning gravity from each of ``sides`` and as the sweep does; compare.

    Two stable states that differ at one direction are two equilibria of one load: the answer
    there depends on the patient's history (a fold's hysteresis), which no single-valued model
    of (C1, direction) can follow. A turn that stops before ``at`` is recorded, not compared.
    """
    from fem.case import CaseRunner
    from fem.stability import tangent_inertia

    _check_steps(c1, via, step_deg, resolution_deg)
    fields: dict[str, np.ndarray] = {}
    stable: dict[str, bool] = {}
    turns = []
    with CaseRunner(mesh, settings) as runner:
        for side in sides:
            edge = turn_runner(runner, c1, side, at, via, step_deg, resolution_deg)
            turns.append(edge)
            if edge.reached_target:
                key = f"from {side[0]:g}/{side[1]:g}"
                fields[key] = runner.problem.displacement().x.array.reshape(-1, 3).copy()
                stable[key] = edge.states[-1].stable
        try:
            reach(runner, c1, at, via)
        except InvalidParameterError as err:
            log.info("%s", err)
            chain = False
        else:
            chain = True
            fields["chain"] = runner.problem.displacement().x.array.reshape(-1, 3).copy()
            stable["chain"] = tangent_inertia(runner.problem).stable
    keys = list(fields)
    largest, mean = {}, {}
    for i, a in enumerate(keys):
        for b in keys[i + 1:]:
            d = 1e3 * np.linalg.norm(fields[a] - fields[b], axis=1)
            largest[f"{a}|{b}"], mean[f"{a}|{b}"] = float(d.max()), float(d.mean())
    return Meeting(C1=c1, at=list(at), turns=turns, chain_converged=chain,
                   max_difference_mm=largest, mean_difference_mm=mean, stable=stable)


def main(argv: list[str] | None = None) -> int:
    """Run the study and print the turn, the edge and the stability of every state."""
    parser = argparse.ArgumentParser(prog="python -m studies.fe_study.failure_edge",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("mesh", type=Path, help="the mesh (XDMF) to solve on")
    parser.add_argument("--config", type=Path, default=Path("config.yaml"),
                        help="the config whose fe: section sets the solver (default config.yaml)")
    parser.add_argument("--c1", type=c1_kpa, required=True, help="C1 (kPa)")
    parser.add_argument("--from", dest="start", type=angle_deg, nargs=2, required=True,
                        metavar=("PHI", "THETA"), help="a converged direction (degrees)")
    parser.add_argument("--to", dest="target", type=angle_deg, nargs=2, required=True,
                        metavar=("PHI", "THETA"), help="the direction to turn towards")
    parser.add_argument("--via", type=c1_kpa, nargs="*", default=[],
                        help="stiffer C1 values (kPa) to reach the start through, as a chain")
    parser.add_argument("--step", type=positive, default=1.0, help="the longest step (degrees)")
    parser.add_argument("--resolution", type=positive, default=0.05,
                        help="the shortest step tried before stopping (degrees)")
    parser.add_argument("--meet", type=angle_deg, nargs=2, metavar=("PHI", "THETA"),
                        help="instead: turn from --from and from --to to this direction, solve "
                             "it as the sweep does too, and compare the states")
    parser.add_argument("--json", type=Path, help="write the record here")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    try:
        settings = SolverSettings.from_config(read_config_file(args.config))
        if args.meet:
            meeting = meet(args.mesh, settings, args.c1, (tuple(args.start), tuple(args.target)),
                           tuple(args.meet), tuple(args.via), args.step, args.resolution)
        else:
            edge = turn(args.mesh, settings, args.c1, tuple(args.start), tuple(args.target),
                        tuple(args.via), args.step, args.resolution)
    except (InvalidParameterError, OSError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    if args.meet:
        for t in meeting.turns:
            last = t.states[-1]
            print(f"from {t.start}: {'reached' if t.reached_target else 'stopped at'} "
                  f"({last.phi:.3f}, {last.theta:.3f}), max |u| {last.max_displacement_mm:.3f} "
                  f"mm, {'stable' if last.stable else 'UNSTABLE'}")
        print(f"as the sweep solves it: {'converged' if meeting.chain_converged else 'failed'}")
        for pair, largest in meeting.max_difference_mm.items():
            print(f"{pair}: largest point difference {largest:.3f} mm, mean "
                  f"{meeting.mean_difference_mm[pair]:.4f} mm")
        if args.json:
            meeting.write(args.json)
        return 0
    for s in edge.states:
        print(f"{s.angle_deg:8.3f}°  ({s.phi:8.3f}, {s.theta:8.3f})  "
              f"Newton {s.newton_iterations:3d}  max |u| {s.max_displacement_mm:8.3f} mm  "
              f"min det F {s.min_detF:.4f}  in contact {s.contact_vertices}  "
              f"negative {s.negative} (pressure "
              f"{s.pressure_dofs}), null {s.zero}: {'stable' if s.stable else 'UNSTABLE'}")
    where = ("reached the target" if edge.reached_target else
             f"the edge at {edge.edge_deg:.3f}° of {edge.span_deg:.3f}° (a step to "
             f"{edge.first_failure_deg:.3f}° failed)")
    print(f"C1 = {edge.C1:g} kPa from {edge.start} to {edge.target}: {where}; every state "
          f"{'stable' if edge.all_stable else 'NOT stable'}; {edge.seconds:.1f} s")
    if args.json:
        edge.write(args.json)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())


__all__ = ["EdgeFailure", "EdgeState", "FailureEdge", "Meeting", "great_circle", "meet", "reach",
           "turn", "turn_runner"]
