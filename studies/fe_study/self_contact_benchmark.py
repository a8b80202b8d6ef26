"""Self-contact against none, case by case: does it converge, pass through itself, cost more?

For each case the config's solver settings solve it twice on one mesh, with the skin's
self-contact (``fe.self_contact``, its defaults where the config has none) and without it,
each in its own runner, so that the forms are compiled once per setting and the timings are
the solves' own. Printed per case and setting: the outcome, the load reached, wall seconds,
Newton iterations, max |u|, the boundary vertices inside another cell (``self_overlap``) and
the self-contact's force, area and seconds; then, where both converged, the largest
difference of the displacement at the mesh's vertices and the ratio of the wall times.

    python -m studies.fe_study.self_contact_benchmark results/mesh/mesh.xdmf --config config.yaml
        --case 2.0:180 --case 0.8:-90 [--json out.json]

Run it with nothing else on the machine; the ratio of the two settings' times, measured in
one process, is the figure to compare across machines.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from fem.case import CaseRunner
from fem.configfile import read_config_file
from fem.io import gather_vertex_values
from fem.parameters import SolverSettings
from fem.self_contact import SelfContact
from fem.sweep import Case

log = logging.getLogger(__name__)


def parse_case(text: str) -> Case:
    """``C1:PHI`` or ``C1:PHI:THETA`` (kPa, degrees) as a :class:`fem.sweep.Case`."""
    parts = text.split(":")
    if len(parts) not in (2, 3):
        raise argparse.ArgumentTypeError(f"a case is C1:PHI[:THETA], got {text!r}")
    try:
        return Case(*(float(p) for p in parts))
    except ValueError as err:
        raise argparse.ArgumentTypeError(f"{text!r}: {err}") from None


SETTINGS = ("self-contact", "none")
"""The two settings every case is solved with, in this order."""


def solve_pairs(
    mesh: Path | str, settings: SolverSettings, cases: list[Case]
) -> Iterator[tuple[str, Case, CaseRunner, dict[str, Any]]]:
    """Each case solved with self-contact (the settings' own, else the defaults) and without.

    Yields ``(setting, case, runner, summary)`` right after each solve, while the runner's
    problem holds the state; one runner per setting, so forms are compiled once for each.
    """
    with_contact = settings if settings.self_contact else replace(settings,
                                                                 self_contact=SelfContact())
    for name, current in zip(SETTINGS, (with_contact, replace(settings, self_contact=None)),
                             strict=True):
        with CaseRunner(mesh, current) as runner:
            for case in cases:
                result, timings = runner.solve(case)
                yield name, case, runner, runner.summary(case, result, timings,
                                                         measure_unit=False)


def compare(mesh: Path, settings: SolverSettings, cases: list[Case]) -> list[dict[str, Any]]:
    """Each case with and without self-contact: a row per case and setting."""
    rows: list[dict[str, Any]] = []
    fields: dict[tuple[str, str], np.ndarray] = {}
    for name, case, runner, summary in solve_pairs(mesh, settings, cases):
        _, fields[(case.id, name)] = gather_vertex_values(runner.mesh,
                                                          runner.problem.displacement())
        sc = summary["self_contact"] or {}
        rows.append({
            "case": case.id, "setting": name, "status": summary["status"],
            "load_fraction": summary["load_fraction"],
            "wall_s": summary["wall_s"]["solve"],
            "newton_iterations": summary["total_newton_iterations"],
            "rejected_steps": summary["rejected_steps"],
            "max_disp_mm": summary["max_disp_mm"],
            "self_overlap": (summary["self_overlap"] or {}).get("overlapping_vertices"),
            "self_contact_force_N": sc.get("force_N"),
            "self_contact_area_cm2": sc.get("area_cm2"),
            "self_contact_penetration_mm": sc.get("max_penetration_mm"),
            "self_contact_s": sc.get("seconds"),
        })
    for case in cases:
        on, off = (next(r for r in rows if r["case"] == case.id and r["setting"] == s)
                   for s in SETTINGS)
        if on["status"] == off["status"] == "converged":
            diff = np.abs(fields[(case.id, "self-contact")] - fields[(case.id, "none")]).max()
            on["max_difference_mm"] = 1e3 * float(diff)
            on["time_ratio"] = on["wall_s"] / off["wall_s"]
    return rows


def table(rows: list[dict[str, Any]]) -> str:
    """The rows as a fixed-width table."""
    head = (f"{'case':34} {'setting':12} {'status':9} {'λ':>6} {'wall s':>8} {'its':>5} "
            f"{'max|u| mm':>9} {'overlap':>7} {'force N':>8} {'area cm²':>8} {'contact s':>9} "
            f"{'Δu mm':>8} {'time ×':>6}")
    out = [head]
    def num(r: dict[str, Any], key: str, spec: str) -> str:
        value = r.get(key)
        return "-" if value is None else format(value, spec)

    for r in rows:
        out.append(
            f"{r['case']:34} {r['setting']:12} {r['status']:9} {r['load_fraction']:6.3f} "
            f"{r['wall_s']:8.2f} {r['newton_iterations']:5d} {r['max_disp_mm']:9.3f} "
            f"{num(r, 'self_overlap', 'd'):>7} {num(r, 'self_contact_force_N', '.3g'):>8} "
            f"{num(r, 'self_contact_area_cm2', '.3g'):>8} {num(r, 'self_contact_s', '.2f'):>9} "
            f"{num(r, 'max_difference_mm', '.2e'):>8} {num(r, 'time_ratio', '.3f'):>6}"
        )
    return "\n".join(out)


def case_arguments(description: str) -> argparse.ArgumentParser:
    """A parser of a mesh, ``--config`` and repeated ``--case`` (this study's and its kin's)."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("mesh", type=Path, help="mesh XDMF with facet tags")
    parser.add_argument("--config", type=Path, help="workflow config (fe, material, mesh)")
    parser.add_argument("--case", type=parse_case, action="append", required=True,
                        help="C1:PHI[:THETA] in kPa and degrees; repeat for more")
    return parser


def settings_of(args: argparse.Namespace) -> SolverSettings | None:
    """The config's solver settings (the defaults without one); None, said, if no mesh."""
    if not args.mesh.is_file():
        print(f"error: mesh {args.mesh} does not exist", file=sys.stderr)
        return None
    return SolverSettings.from_config(read_config_file(args.config)) if args.config \
        else SolverSettings()


def main(argv: list[str] | None = None) -> int:
    """Command line: see the module docstring."""
    parser = case_arguments(__doc__.split("\n\n")[0])
    parser.add_argument("--json", type=Path, help="also write the rows here")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.WARNING)
    settings = settings_of(args)
    if settings is None:
        return 2
    rows = compare(args.mesh, settings, args.case)
    print(table(rows))
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
