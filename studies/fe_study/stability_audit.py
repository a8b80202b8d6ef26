"""Whether the sweep's converged cases are stable equilibria: the tangent's inertia at each.

A converged Newton solve is an equilibrium, not necessarily one the tissue can rest in. Where
the soft mound rolls over the fold, a case's load path (from rest, or down a chain from its
stiffer neighbours, which is the same path) can end on an unstable equilibrium: a state a body
would leave at the slightest disturbance, which a dataset of postures should not hold as if it
were the answer.

For each converged case of the chosen C1 values this study takes the case's own state from the
dataset (its displacement at every node of a quadratic mesh, ``/nodes``; on a linear mesh at
its vertices, interpolated linearly between them), starts Newton from it at the full load (the
pressure from zero: it enters the equations linearly), which polishes it to the solver's
tolerance on the same branch in a few iterations, and counts the tangent's negative
eigenvalues there (:func:`fem.stability.tangent_inertia`). The state judged is the sweep's own,
not one re-solved along another path: the largest difference between the polished state and
the dataset's at the dataset's points is recorded (``moved_mm``: the float32 round-off where
nothing touches; up to a few tenths of a millimetre where the skin rests on itself, whose
contact a fresh Newton solve shares anew between the candidate triangles), and a state that
Newton carries farther than :data:`SAME_STATE_MM` is not judged.

``python -m studies.fe_study.stability_audit MESH DATASET --c1 0.8 1.0 [--config config.yaml]
[--json OUT]``

In the workflow (``fe_study.stability_audit``, ``results/fe_study/stability_audit.json``, the
report's stability section) it audits the sweep's ``softest`` C1 values.
"""

from __future__ import annotations

import argparse
import logging
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from fem.configfile import read_config_file
from fem.exceptions import DatasetError, InvalidParameterError
from fem.parameters import SolverSettings
from fem.sweep import Case
from studies.results import Record, Result
from studies.timing_hygiene import machine_state

log = logging.getLogger(__name__)

#: A polished state farther than this from the dataset's (mm, at any node) is another state.
#: Between the wander of a fresh Newton solve where the skin rests on itself (its contact
#: shares taken anew: tenths of a millimetre) and the distance between two equilibria of one
#: load (millimetres: the crease's two configurations at 0.8 kPa, Φ = −71.5°, 2.975 mm apart).
SAME_STATE_MM = 0.5


@dataclass(frozen=True, slots=True)
class AuditedCase(Record):
    """One converged case of the sweep, judged.

    Attributes:
        case: its id (folder name).
        C1, phi, theta: its stiffness (kPa) and gravity direction (degrees).
        stable: whether its state is a stable equilibrium; None where the state could not be
            polished (``error`` says why).
        unstable_modes: the tangent's negative eigenvalues beyond one per pressure unknown.
        zero: null pivots (a singular tangent: a bifurcation or a mechanism).
        newton_iterations: Newton's iterations from the dataset's state.
        moved_mm: the largest point difference between the polished state and the dataset's.
        min_detF: the state's smallest det F.
        max_mm: its largest displacement.
        error: why the case was not judged (empty where it was).
    """

    case: str
    C1: float
    phi: float
    theta: float
    stable: bool | None
    unstable_modes: int = 0
    zero: int = 0
    newton_iterations: int = 0
    moved_mm: float = float("nan")
    min_detF: float = float("nan")
    max_mm: float = float("nan")
    error: str = ""


@dataclass(frozen=True, slots=True)
class StabilityAudit(Result):
    """The study's record.

    Attributes:
        C1: the stiffness values audited (kPa).
        cases: every converged case of those values, softest first.
        seconds: the study's wall time.
        settings: the solver settings.
        machine: the machine's state at the start.
    """

    C1: list[float]
    cases: list[AuditedCase]
    seconds: float = 0.0
    settings: dict | None = None
    machine: dict | None = None

    @property
    def unstable(self) -> list[AuditedCase]:
        """The cases whose state is not a stable equilibrium."""
        return [c for c in self.cases if c.stable is False]

    @property
    def not_judged(self) -> list[AuditedCase]:
        """The cases whose state could not be polished."""
        return [c for c in self.cases if c.stable is None]

    @classmethod
    def merge(cls, parts: Sequence[StabilityAudit]) -> StabilityAudit:
        """One audit from its parts (:func:`audit_sweep`'s ``part``), the cases in its order.

        ``seconds`` is the parts' summed time (their cases on one core); the settings are the
        first part's.

        Raises:
            InvalidParameterError: if there are no parts, or they audited other C1 values.
        """
        if not parts:
            raise InvalidParameterError("no audit parts to merge")
        if any(p.C1 != parts[0].C1 for p in parts):
            raise InvalidParameterError(
                f"the audit's parts audited other C1 values: {[p.C1 for p in parts]}")
        cases = sorted((c for p in parts for c in p.cases),
                       key=lambda c: _order(c.C1, c.phi, c.theta))
        return cls(C1=list(parts[0].C1), cases=cases, seconds=sum(p.seconds for p in parts),
                   settings=parts[0].settings, machine=parts[0].machine)

    def at(self, c1: float) -> list[AuditedCase]:
        """The cases audited at C1 = ``c1`` (kPa)."""
        return [c for c in self.cases if abs(c.C1 - c1) < 1e-9]

    def tally(self, c1: float) -> tuple[list[AuditedCase], int, list[AuditedCase]]:
        """C1 = ``c1``'s audited cases, how many of them were judged, and the unstable ones."""
        cases = self.at(c1)
        return (cases, sum(c.stable is not None for c in cases),
                [c for c in cases if c.stable is False])


def _order(c1: float, phi: float, theta: float) -> tuple:
    """The audit's order of cases: softest first, each C1's meridian (θ = 0) first, then by Φ, θ."""
    return (float(c1), float(theta) != 0.0, float(phi), float(theta))


def state_from_points(
    problem: Any, points_x: np.ndarray, u_mm: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The problem's state with the displacement ``u_mm`` given at ``points_x``, no pressure.

    Where the points are every node of the displacement (the dataset's ``/nodes`` of a
    quadratic mesh) the values are taken as they are; where they are the mesh's vertices only
    (a linear mesh's material points), the field is interpolated linearly between them, and
    Newton restores the rest.

    Args:
        problem: a :class:`fem.problem.GravityProblem` on the mesh the points belong to.
        points_x: the points (K, 3), m.
        u_mm: the displacement there (K, 3), mm.

    Returns:
        ``(state, rows, points)``: the state vector, and the displacement's nodes that lie at
        given points (rows of :func:`displacement_rows`) with the point each lies at.

    Raises:
        InvalidParameterError: if the points are neither the displacement's nodes nor the
            mesh's vertices (a dataset of another mesh).
    """
    return _state_at(problem, *displacement_rows(problem), points_x, u_mm)


def _state_at(
    problem: Any, V: Any, rows: np.ndarray, points_x: np.ndarray, u_mm: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`state_from_points` given the displacement's space and rows."""
    from dolfinx import fem
    from scipy.spatial import cKDTree

    tree = cKDTree(np.asarray(points_x, dtype=float))
    u = 1e-3 * np.asarray(u_mm, dtype=float)
    distance, point = tree.query(V.tabulate_dof_coordinates()[: len(rows)])
    at = distance <= 1e-9
    if at.all():
        values = u[point]
    else:
        P1 = fem.VectorFunctionSpace(problem.mesh, ("Lagrange", 1))
        d1, p1 = tree.query(P1.tabulate_dof_coordinates())
        if d1.size and d1.max() > 1e-9:
            raise InvalidParameterError(
                f"the dataset's points are not this mesh's (a vertex {d1.max():.3g} m from the "
                "nearest): audit the dataset on the mesh it was solved on")
        linear, field = fem.Function(P1), fem.Function(V)
        linear.x.array[:] = u[p1].ravel()
        field.interpolate(linear)
        values = field.x.array.reshape(-1, 3)[: len(rows)]
    state = np.zeros_like(problem.w.x.array)
    state[rows] = values
    return state, np.flatnonzero(at), point[at]


def displacement_rows(problem: Any) -> tuple[Any, np.ndarray]:
    """The displacement's space and, per node of it, its three entries in the state vector."""
    if problem.mixed:
        V, to_state = problem.W.sub(0).collapse()
    else:
        V, to_state = problem.W, np.arange(problem.w.x.array.size)
    return V, np.asarray(to_state).reshape(-1, 3)


def audit_case(runner: Any, case: Case, points_x: np.ndarray, u_mm: np.ndarray) -> AuditedCase:
    """Judge ``case``'s state given by its displacement ``u_mm`` at ``points_x`` (mm).

    Newton polishes the state on ``runner`` at the full load; a state it cannot polish, or
    carries farther than :data:`SAME_STATE_MM`, is not judged (see the module).
    """
    from fem.stability import tangent_inertia

    problem, solver, settings = runner.problem, runner.solver, runner.settings
    problem.set_case(case.material(settings.density), case.gravity(settings.gravity))
    problem.set_load_fraction(1.0)
    V, rows = displacement_rows(problem)
    state, at, points = _state_at(problem, V, rows, points_x, u_mm)
    problem.w.x.array[:] = state
    solver.scale_to_load()
    outcome = solver.solve()
    base = {"case": case.id, "C1": case.C1, "phi": case.phi, "theta": case.theta,
            "newton_iterations": outcome.iterations}
    if not outcome.converged:
        return AuditedCase(**base, stable=None,
                           error=f"Newton from the dataset's state: {outcome.reason}")
    polished = problem.w.x.array[rows[at]]
    moved_mm = float(np.linalg.norm(1e3 * polished - np.asarray(u_mm)[points], axis=1).max())
    u = problem.w.x.array[rows]
    common = {**base, "moved_mm": moved_mm, "min_detF": problem.min_detF(),
              "max_mm": 1e3 * float(np.linalg.norm(u, axis=1).max())}
    if moved_mm > SAME_STATE_MM:
        return AuditedCase(**common, stable=None,
                           error=f"Newton left the dataset's state by {moved_mm:.3g} mm")
    inertia = tangent_inertia(problem)
    return AuditedCase(**common, stable=inertia.stable, unstable_modes=inertia.unstable_modes,
                       zero=inertia.zero)


def audit_sweep(
    mesh: str | Path, dataset: str | Path, settings: SolverSettings, c1_values: list[float],
    part: int = 0, parts: int = 1,
) -> StabilityAudit:
    """Judge every converged case of ``dataset`` at the C1 values ``c1_values`` (one runner).

    With ``parts`` > 1, only part ``part`` (from 0) of them: every ``parts``-th case in the
    audit's order, so that parts run side by side and :meth:`StabilityAudit.merge` joins them.

    Raises:
        InvalidParameterError: if no C1 value is given, one is not in the dataset, the
            dataset's points are not the mesh's, or ``part`` is not one of ``parts``.
    """
    from fem.case import CaseRunner
    from fem.dataset import read_dataset

    if not c1_values:
        raise InvalidParameterError("name the C1 values to audit (--c1)")
    if not 0 <= part < parts:
        raise InvalidParameterError(f"part {part} of {parts}: parts are numbered 0 to {parts - 1}")
    clock = time.perf_counter()
    ds = read_dataset(dataset, nodes=True)
    c1 = np.asarray(ds.C1, dtype=float)
    missing = [v for v in c1_values if not np.any(np.isclose(c1, v, rtol=0, atol=1e-9))]
    if missing:
        raise InvalidParameterError(
            f"the dataset has no case at C1 = {', '.join(f'{v:g}' for v in missing)} kPa "
            f"(it has {', '.join(f'{v:g}' for v in np.unique(c1))})")
    points_x, fields = (ds.X, ds.displacement) if ds.nodes is None else \
        (ds.nodes.X, ds.nodes.displacement)
    chosen = [i for i in np.flatnonzero(np.asarray(ds.converged, dtype=bool))
              if np.any(np.isclose(c1[i], c1_values, rtol=0, atol=1e-9))]
    chosen.sort(key=lambda i: _order(c1[i], ds.phi[i], ds.theta[i]))
    audited = []
    with CaseRunner(mesh, settings) as runner:
        for i in chosen[part::parts]:
            case = Case(float(c1[i]), float(ds.phi[i]), float(ds.theta[i]))
            audited.append(row := audit_case(runner, case, points_x, fields[i]))
            log.info("%s: %s", row.case, "stable" if row.stable else
                     f"{row.unstable_modes} unstable modes" if row.stable is False else row.error)
    return StabilityAudit(C1=sorted(float(v) for v in c1_values), cases=audited,
                          seconds=time.perf_counter() - clock, settings=settings.describe())


def without_unstable(dataset: Any, audit: str | Path) -> Any:
    """``dataset`` with the cases the audit file ``audit`` found unstable set aside as failed.

    See :meth:`fem.dataset.Dataset.without`: no model trains or is tested on them, and a model
    saved with the dataset warns beside them as beside a failed case.
    """
    unstable = [c.case for c in StabilityAudit.read(audit).unstable]
    if unstable:
        log.info("set aside as failed (an unstable FE state): %s", ", ".join(unstable))
    return dataset.without(unstable)


def softest_c1(c1: np.ndarray, n: int) -> list[float]:
    """The ``n`` softest distinct C1 values of a sweep's cases (kPa), softest first."""
    return [float(v) for v in np.unique(np.round(np.asarray(c1, dtype=float), 9))[:n]]


def main(argv: list[str] | None = None) -> int:
    """Audit a sweep's cases at some C1 values and print what it finds."""
    parser = argparse.ArgumentParser(prog="python -m studies.fe_study.stability_audit",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("mesh", type=Path, help="the mesh (XDMF) the sweep solved on")
    parser.add_argument("dataset", type=Path, help="the sweep's dataset (HDF5)")
    parser.add_argument("--c1", type=float, nargs="+", required=True, help="C1 values (kPa)")
    parser.add_argument("--config", type=Path, default=Path("config.yaml"),
                        help="the config whose fe: section sets the solver (default config.yaml)")
    parser.add_argument("--json", type=Path, help="write the record here")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    machine = machine_state().to_json()
    try:
        settings = SolverSettings.from_config(read_config_file(args.config))
        audit = audit_sweep(args.mesh, args.dataset, settings, args.c1)
    except (InvalidParameterError, DatasetError, OSError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    record = replace(audit, machine=machine)
    for value in record.C1:
        rows, judged, unstable = record.tally(value)
        names = ", ".join(c.case for c in unstable)
        print(f"C1 = {value:g} kPa: {len(rows)} converged cases, {judged} judged, "
              f"{len(unstable)} unstable{': ' + names if unstable else ''}")
    for c in record.not_judged:
        print(f"  not judged: {c.case}: {c.error}")
    print(f"{record.seconds:.0f} s")
    if args.json:
        record.write(args.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())


__all__ = ["AuditedCase", "SAME_STATE_MM", "StabilityAudit", "audit_case", "audit_sweep",
           "displacement_rows", "softest_c1", "state_from_points", "without_unstable"]
