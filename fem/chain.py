"""Many cases in one process, each solved from its neighbours' solutions.

With C1 in every term of the potential (the neo-Hookean energy, the Taylor–Hood pressure's
work, the penalty and contact energies), the equilibrium of a case depends on ρg/C1 alone:
case C1 at load fraction λ = C1/C1ₖ has exactly the displacement of case C1ₖ at the full load,
and the pressure scaled by λ. The sweep's cases at one gravity direction are therefore points
on one load path. A chain solves them from the stiffest to the softest, and starts each case's
load path (:func:`fem.loading.solve_incrementally`) from its stiffer neighbours' solutions,
which are equilibrium states of the case at λ < 1, instead of from rest: the first step
extrapolates from the last three to the full load, with the kept factorisation, and cuts back
towards them where it fails, as any step does; the last resort still starts from rest. The
answer meets the same stopping test as a case solved alone.

The fixed costs (interpreter, imports, form compilation, mesh read) are paid once per chain,
and the unit of cost (:meth:`fem.case.CaseRunner.summary`'s ``measure_unit``) is measured on
the process's first case only. Every case still gets its own folder, written as
:func:`fem.case.run_case` writes it.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from fem.case import CaseRunner, Start
from fem.exceptions import InvalidParameterError
from fem.parameters import SolverSettings
from fem.sweep import Case

log = logging.getLogger(__name__)

def direction_chains(cases: Iterable[Case]) -> list[list[Case]]:
    """The cases grouped by gravity direction (Φ, θ), each group stiffest first.

    Raises:
        InvalidParameterError: if a case appears twice.
    """
    cases = list(cases)
    if len(set(cases)) != len(cases):
        raise InvalidParameterError("a chain lists a case twice")
    groups: dict[tuple[float, float], list[Case]] = {}
    for case in cases:
        groups.setdefault((case.phi, case.theta), []).append(case)
    return [sorted(group, key=lambda c: -c.C1) for _, group in sorted(groups.items())]


class Neighbours:
    """The last three converged cases of each direction, as states on another case's load path.

    Args:
        pressure_dofs: the pressure's entries in the state's array (scaled by the load
            fraction; none for a displacement-only element).
    """

    def __init__(self, pressure_dofs: np.ndarray) -> None:
        self.pressure_dofs = np.asarray(pressure_dofs)
        self._known: dict[tuple[float, float], list[tuple[Case, np.ndarray]]] = {}

    def add(self, case: Case, state: np.ndarray) -> None:
        """Keep a converged case's state (a copy): the last three of each direction."""
        known = self._known.get(_direction(case), [])
        self._known[_direction(case)] = [*known[-2:], (case, state.copy())]

    def path(self, case: Case) -> tuple[list[tuple[float, np.ndarray]], Start]:
        """The known states of ``case``'s load path, as ``(fraction, state)``, and the start.

        Only stiffer neighbours of the same direction lie on it (λ = C1/C1ₖ < 1); with none,
        the path is empty and the case starts from rest.
        """
        near = [(c, w) for c, w in self._known.get(_direction(case), []) if c.C1 > case.C1]
        near.sort(key=lambda k: -k[0].C1)
        if not near:
            return [], Start()
        path = []
        for c, w in near:
            fraction = case.C1 / c.C1
            state = w.copy()
            state[self.pressure_dofs] *= fraction
            path.append((fraction, state))
        return path, Start("neighbours", tuple(c.id for c, _ in near), path[-1][0])


def _direction(case: Case) -> tuple[float, float]:
    return case.phi, case.theta


@dataclass(frozen=True, slots=True)
class ChainedCase:
    """One solved case of a chain: its summary as written, and whether it converged."""

    case: Case
    summary: dict[str, Any]

    @property
    def converged(self) -> bool:
        """Whether the case reached the full load."""
        return self.summary["status"] == "converged"


def solve_chain(
    mesh_path: str | Path,
    cases: Iterable[Case],
    folder: Callable[[Case], Path],
    settings: SolverSettings = SolverSettings(),
    warm_start: bool = True,
) -> list[ChainedCase]:
    """Solve ``cases`` in one process, direction by direction, and write each case's folder.

    Args:
        mesh_path: the mesh XDMF.
        cases: any cases; they are solved in :func:`direction_chains` order.
        folder: the output folder of a case (written as :func:`fem.case.run_case` does).
        settings: the solver settings of every case.
        warm_start: start each case's load path from its stiffer neighbours (:class:`Neighbours`;
            False: every case from rest, as alone, with the fixed costs still paid once).

    Returns:
        The cases in the order solved. A case that fails is written with ``status: failed``
        like any other and predicts nothing for the next.
    """
    chains = direction_chains(cases)
    with CaseRunner(mesh_path, settings) as runner:
        neighbours = Neighbours(runner.problem.pressure_dofs)
        solved: list[ChainedCase] = []
        for chain in chains:
            for index, case in enumerate(chain):
                path, start = neighbours.path(case) if warm_start else ([], Start())
                result, timings = runner.solve(case, path=path)
                summary = runner.summary(
                    case, result, timings, measure_unit=not solved, start=start
                )
                # the runner's set-up is paid once: by the first case of the process
                summary["wall_s"]["setup"] = runner.setup_s if not solved else 0.0
                summary["chain"] = {"index": index, "length": len(chain), "first": chain[0].id}
                summary = runner.write(folder(case), summary)
                if result.converged:
                    neighbours.add(case, runner.problem.w.x.array)
                log.info(
                    "%s: %s from %s in %d Newton its, %.2f s",
                    case.id,
                    summary["status"],
                    f"λ = {start.fraction:.3f}" if path else "rest",
                    result.total_iterations,
                    timings["solve"],
                )
                solved.append(ChainedCase(case, summary))
    return solved


def main(argv: list[str] | None = None) -> int:
    """``python -m fem.chain MESH --c1 5 4.9 ... --phi P [--theta T] --cases DIR``.

    Solves the cases of one or more directions as chains and writes each to ``DIR/<case id>``,
    the workflow's layout (``results/cases``). Prints one line per case. ``--from-rest`` solves
    every case from rest in the same process (the fixed costs still paid once).
    """
    import argparse
    import json
    import sys

    from fem.arguments import angle_deg, c1_kpa
    from meshes.io import MeshInputError

    parser = argparse.ArgumentParser(prog="python -m fem.chain", description=main.__doc__)
    parser.add_argument("mesh", type=Path, help="mesh XDMF with facet tags")
    parser.add_argument("--c1", type=c1_kpa, nargs="+", required=True, help="C1 values, kPa")
    parser.add_argument("--phi", type=angle_deg, nargs="+", required=True,
                        help="Φ values, degrees")
    parser.add_argument("--theta", type=angle_deg, default=0.0, help="θ, degrees")
    parser.add_argument("--cases", type=Path, required=True, help="folder of the case folders")
    parser.add_argument("--config", type=Path, help="workflow config (fe, material, mesh.fixed)")
    parser.add_argument("--from-rest", action="store_true", help="no guesses: every case cold")
    args = parser.parse_args(argv)
    # force: FFCx (imported with dolfinx) has already given the root logger a handler
    logging.basicConfig(level=logging.INFO, format="%(message)s", force=True)
    from fem.configfile import read_config_file
    from fem.exceptions import FEError

    try:
        settings = SolverSettings.from_config(read_config_file(args.config) if args.config
                                              else {})
        cases = [Case(c1, phi, args.theta) for phi in args.phi for c1 in args.c1]
        solved = solve_chain(args.mesh, cases, lambda case: args.cases / case.id, settings,
                             warm_start=not args.from_rest)
    except (FEError, MeshInputError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    for s in solved:
        print(json.dumps({"case": s.case.id, "status": s.summary["status"],
                          "from": s.summary["start"]["from"],
                          "newton_iterations": s.summary["total_newton_iterations"]}))
    return 0


if __name__ == "__main__":
    import sys

    sys.exit(main())
