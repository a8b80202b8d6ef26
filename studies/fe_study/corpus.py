"""The corpus of anatomies (:mod:`meshes.corpus`) solved with the default solver and exact Newton.

For every anatomy of the config's ``corpus`` section: the config's clinical cases and a soft C1
(``corpus.soft_C1``) at several directions (``corpus.soft_phi``), each solved with the config's
solver settings (the default) and again with ``direct-refactor`` (exact Newton, a fresh
factorisation at every iteration), in one process on one mesh. The default must converge every
case exact Newton converges; the table gives each anatomy's volume, cells, unknowns, cases
converged, Newton iterations and time.

An anatomy's soft cases can take many minutes each where they fail, so a job writes every solve
to a progress file as it finishes (:class:`Progress`): a job stopped part-way (a time limit, a
reboot) resumes where it was, keeping the solves of the same mesh with the same settings.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from fem.parameters import SolverSettings, as_dict
from fem.sweep import Case, clinical_cases
from studies.fe_study.mesh_quality import MeshQuality
from studies.results import Record, Result
from studies.timing_hygiene import machine_state

log = logging.getLogger(__name__)

#: The reference path: exact Newton.
EXACT = "direct-refactor"


def corpus_cases(
    clinical: list[dict[str, Any]], soft_C1: float, soft_phi: list[float]
) -> list[Case]:
    """The config's clinical cases, then ``soft_C1`` at every ``soft_phi`` (each once)."""
    cases = clinical_cases(clinical) + [Case(float(soft_C1), float(phi)) for phi in soft_phi]
    return list(dict.fromkeys(cases))


@dataclass(frozen=True, slots=True)
class CorpusSolve(Record):
    """One case solved with one solver path."""

    case: str
    C1: float
    phi: float
    theta: float
    solver: str
    converged: bool
    load_fraction: float
    load_steps: int
    newton_iterations: int
    preconditioner_builds: int
    exact_retries: int
    rescued: bool
    solve_s: float
    max_disp_mm: float
    reason: str


@dataclass(frozen=True, slots=True)
class AnatomyRun(Result):
    """An anatomy's mesh and its cases, with the default solver and with exact Newton."""

    name: str
    description: str
    source: str
    volume_ml: float
    breast_volume_ml: float
    cells: int
    dofs: int
    min_dihedral_deg: float
    solver: str
    solves: list[CorpusSolve]
    machine: dict[str, Any]
    resumed: int = 0
    """Solves taken from the progress file of an earlier, stopped job (timed there)."""

    def by_solver(self, solver: str) -> list[CorpusSolve]:
        """The solves of one path, in case order."""
        return [s for s in self.solves if s.solver == solver]

    @property
    def missed(self) -> list[str]:
        """Cases exact Newton converges and the default does not."""
        default = {s.case: s.converged for s in self.by_solver(self.solver)}
        return [s.case for s in self.by_solver(EXACT) if s.converged and not default.get(s.case)]


@dataclass(frozen=True, slots=True)
class CorpusTable(Result):
    """Every anatomy's run, in the config's order, and the cases each solved."""

    anatomies: list[AnatomyRun]
    soft_C1: float
    soft_phi: list[float]


def fingerprint(mesh_path: str | Path, settings: SolverSettings) -> str:
    """What a solve depends on besides its case: the mesh's files and the solver settings."""
    digest = hashlib.sha256()
    xdmf = Path(mesh_path)
    for path in (xdmf, xdmf.with_suffix(".h5")):
        if path.exists():
            digest.update(path.read_bytes())
    digest.update(json.dumps(as_dict(settings), sort_keys=True, default=str).encode())
    return digest.hexdigest()


class Progress:
    """The solves an anatomy's job has finished, one JSON line each, so that it can resume.

    Each line holds a solve and the :func:`fingerprint` of its mesh and settings; only the
    lines of the fingerprints asked for count, and a line cut short (the job killed while
    writing it) is ignored.
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)

    def done(self, fingerprints: set[str]) -> dict[tuple[str, str], CorpusSolve]:
        """The finished solves by (case, solver), of these fingerprints only.

        The file is rewritten without the other lines (another mesh or settings).
        """
        kept: dict[tuple[str, str], CorpusSolve] = {}
        lines = []
        if self.path.exists():
            for line in self.path.read_text().splitlines():
                try:
                    entry = json.loads(line)
                    solve = CorpusSolve.from_json(entry["solve"], where=str(self.path))
                except (ValueError, KeyError, TypeError):
                    continue
                if entry.get("fingerprint") in fingerprints:
                    kept[(solve.case, solve.solver)] = solve
                    lines.append(line)
            self.path.write_text("".join(f"{line}\n" for line in lines))
        return kept

    def add(self, fingerprint: str, solve: CorpusSolve) -> None:
        """Append one finished solve and flush it to disk."""
        self.path.parent.mkdir(parents=True, exist_ok=True)
        with self.path.open("a") as out:
            out.write(json.dumps({"fingerprint": fingerprint, "solve": solve.to_json()}) + "\n")
            out.flush()
            os.fsync(out.fileno())


def solve_anatomy(
    name: str,
    description: str,
    mesh_path: str | Path,
    quality: MeshQuality,
    settings: SolverSettings,
    cases: list[Case],
    progress: str | Path | None = None,
) -> AnatomyRun:
    """Solve ``cases`` on one anatomy's mesh with ``settings`` and with exact Newton.

    The two paths run alternately case by case in one process (one mesh read and form
    compilation each), so their times are comparable under the same load on the machine.
    With ``progress`` (a :class:`Progress` file), each solve is recorded there as it finishes,
    and the solves already recorded for this mesh and these settings are taken from it instead
    of solved again.
    """
    from fem.case import CaseRunner

    exact = replace(settings, solver=EXACT, petsc_options={})
    paths = {settings.solver: CaseRunner(mesh_path, settings)}
    if settings.solver != EXACT:
        paths[EXACT] = CaseRunner(mesh_path, exact)
    keys = {solver: fingerprint(mesh_path, runner.settings) for solver, runner in paths.items()}
    record = None if progress is None else Progress(progress)
    done = {} if record is None else record.done(set(keys.values()))
    before = machine_state().to_json()
    solves = []
    for case in cases:
        for solver, runner in paths.items():
            if (case.id, solver) in done:
                solves.append(done[(case.id, solver)])
                log.info("%s %s %s: taken from %s (%s)", name, case.id, solver, progress,
                         done[(case.id, solver)].reason)
                continue
            start = time.perf_counter()
            result, timings = runner.solve(case)
            elapsed = time.perf_counter() - start
            u = runner.problem.displacement().x.array.reshape(-1, 3)
            solves.append(CorpusSolve(
                case=case.id, C1=case.C1, phi=case.phi, theta=case.theta, solver=solver,
                converged=result.converged, load_fraction=result.fraction,
                load_steps=len(result.accepted), newton_iterations=result.total_iterations,
                preconditioner_builds=int(timings["preconditioner_builds"]),
                exact_retries=result.exact_retries, rescued=result.rescued, solve_s=elapsed,
                max_disp_mm=float(1e3 * np.linalg.norm(u, axis=1).max(initial=0.0)),
                reason=result.reason,
            ))
            if record is not None:
                record.add(keys[solver], solves[-1])
            log.info("%s %s %s: %s, %d Newton its, %.1f s", name, case.id, solver,
                     result.reason, result.total_iterations, elapsed)
    dofs = paths[settings.solver].problem.num_dofs()
    for runner in paths.values():
        runner.solver.destroy()
    return AnatomyRun(
        name=name, description=description, source=quality.source,
        volume_ml=quality.volume_ml, cells=quality.cells, dofs=int(dofs),
        # the parametric model's mound (the rest is the tissue layer over the chest); an
        # import is all breast
        breast_volume_ml=float(quality.anatomy.get("breast_volume_ml") or quality.volume_ml),
        min_dihedral_deg=quality.min_dihedral_deg, solver=settings.solver, solves=solves,
        machine={"before": before, "after": machine_state().to_json()}, resumed=len(done),
    )


def corpus_rows(table: CorpusTable) -> list[list[str]]:
    """The report's rows: one per anatomy, the default beside exact Newton."""
    rows = []
    for run in table.anatomies:
        default, exact = run.by_solver(run.solver), run.by_solver(EXACT)
        row = [run.name, run.description, f"{run.breast_volume_ml:.0f} ({run.volume_ml:.0f})",
               f"{run.cells:d}",
               f"{run.dofs:d}", f"{run.min_dihedral_deg:.1f}"]
        for solves in (default, exact):
            done = [s for s in solves if s.converged]
            its = [s.newton_iterations for s in solves]
            row += [f"{len(done)}/{len(solves)}",
                    f"{np.median(its):.0f} ({max(its)})" if its else "n/a",
                    f"{np.median([s.solve_s for s in solves]):.1f}" if solves else "n/a"]
        row.append(", ".join(run.missed) or "none")
        rows.append(row)
    return rows


def corpus_failures(table: CorpusTable) -> list[list[str]]:
    """The report's rows of the cases some path did not converge: how far each path loaded them.

    One row per anatomy and case, in the config's order: the load fraction λ each path reached
    (the state it kept) and why it stopped, the default's path first.
    """
    rows = []
    for run in table.anatomies:
        for default, exact in zip(run.by_solver(run.solver), run.by_solver(EXACT), strict=True):
            if default.converged and exact.converged:
                continue
            row = [run.name, default.case]
            for solve in (default, exact):
                row += [f"{solve.load_fraction:.3f}" + ("" if solve.converged else " (failed)"),
                        f"{solve.newton_iterations:d}", f"{solve.solve_s:.0f}",
                        "" if solve.converged else solve.reason]
            rows.append(row)
    return rows


FAILURES_HEADER = [
    "anatomy", "case",
    "default: λ reached", "default: Newton its", "default: time (s)", "default: why it stopped",
    "exact Newton: λ reached", "exact: Newton its", "exact: time (s)", "exact: why it stopped",
]


CORPUS_HEADER = [
    "anatomy", "geometry", "breast (model) volume (ml)", "cells", "P2/P1 unknowns",
    "min dihedral (°)",
    "default: converged", "default: Newton its median (max)", "default: median time (s)",
    "exact Newton: converged", "exact: Newton its median (max)", "exact: median time (s)",
    "converged by exact Newton only",
]


__all__ = ["AnatomyRun", "CORPUS_HEADER", "CorpusSolve", "CorpusTable", "EXACT",
           "FAILURES_HEADER", "Progress", "corpus_cases", "corpus_failures", "corpus_rows",
           "fingerprint", "solve_anatomy"]
