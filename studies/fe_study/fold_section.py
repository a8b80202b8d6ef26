"""The fold's cross-section with and without the skin's self-contact: what the physics changed.

The cases where the skin rests on itself are those that failed, or passed through themselves,
before :mod:`fem.self_contact`. For each chosen case this study solves it twice on the
sweep's mesh, with the config's self-contact and without any
(:func:`studies.fe_study.self_contact_benchmark.solve_pairs`), and cuts both deformed states, and
the
reference, by one plane through the node that carries the largest self-contact pressure: the
sagittal plane (y fixed: anterior-posterior against inferior-superior) where gravity leans
more towards the feet or the head than to the side, else the transverse plane (z fixed:
anterior-posterior against medial-lateral), so that the plane holds the way the mound rolls
over its fold (:func:`cut_axis`). The cut is a material one:
the boundary's triangles are intersected with the plane in the reference configuration and
the points carried to where each state moves them, so the same skin is drawn in both states.
A state that passes through itself shows the skin below the fold crossing the mound's
underside; with self-contact the two sides rest on each other.

The cases are those named in ``fe_study.fold_section.cases`` and the ``largest`` cases of the
sweep with the largest self-contact force (:func:`choose_cases`); the workflow's
``fe_fold_section`` job writes ``results/fe_study/fold_section.json`` and the report draws it
(:func:`studies.figures.fe.plot_fold_section`).

    python -m studies.fe_study.fold_section results/mesh/mesh.xdmf --config config.yaml
        --case 0.8:-90 -o fold_section.json
"""

from __future__ import annotations

import logging
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from fem.overlap import geometry_displacement
from fem.parameters import SolverSettings
from fem.sweep import Case
from studies.fe_study.self_contact_benchmark import case_arguments, settings_of, solve_pairs
from studies.results import Record, Result

log = logging.getLogger(__name__)

__all__ = ["FoldCase", "FoldSections", "FoldState", "boundary_triangles", "choose_cases",
           "cut_axis", "section_segments", "fold_sections"]


@dataclass(frozen=True, slots=True)
class FoldState(Record):
    """One case solved with one setting, and its cut.

    Attributes:
        setting: ``self-contact`` or ``none``.
        status: ``converged`` or ``failed`` (a failed state is the last load it reached).
        load_fraction: the load reached.
        max_disp_mm: the state's largest displacement.
        self_overlap: boundary vertices inside another cell (:func:`fem.overlap.self_overlap`).
        self_contact_force_N: the self-contact's force (None without self-contact).
        wall_s: the solve's wall time.
        segments_mm: the cut, as segments ``[[x0, a0], [x1, a1]]`` of the deformed boundary
            (mm), ``a`` the plane's other axis (z in a sagittal cut, y in a transverse one).
    """

    setting: str
    status: str
    load_fraction: float
    max_disp_mm: float
    self_overlap: int | None
    self_contact_force_N: float | None
    wall_s: float
    segments_mm: list[list[list[float]]]


@dataclass(frozen=True, slots=True)
class FoldCase(Record):
    """One case's cut: the reference and both states.

    Attributes:
        case: the case id (:attr:`fem.sweep.Case.id`).
        C1, phi, theta: the case (kPa, degrees).
        plane_axis: the axis the plane is normal to: ``y`` (sagittal) or ``z`` (transverse).
        plane_at_mm: where the plane cuts that axis in the reference configuration.
        focus_mm: where the node the plane passes through lies with self-contact ([x, a], mm):
            the node of the largest self-contact pressure, else of the largest difference
            between the two states.
        reference_mm: the cut of the reference configuration (segments, mm).
        states: the case with self-contact and without.
    """

    case: str
    C1: float
    phi: float
    theta: float
    plane_axis: str
    plane_at_mm: float
    focus_mm: list[float]
    reference_mm: list[list[list[float]]]
    states: list[FoldState]


@dataclass(frozen=True, slots=True)
class FoldSections(Result):
    """``results/fe_study/fold_section.json``: the chosen cases cut at the fold.

    Attributes:
        mesh: the mesh solved on.
        cases: one record per chosen case.
        seconds: the study's wall time.
    """

    mesh: str
    cases: list[FoldCase]
    seconds: float


def choose_cases(columns: dict[str, np.ndarray], named: list[Case], largest: int) -> list[Case]:
    """The ``named`` cases, then the ``largest`` converged cases of the sweep by self-contact force.

    ``columns`` are the dataset's per-case columns (:func:`fem.dataset.read_case_columns`); a
    dataset without ``self_contact_force_N`` (solved without self-contact) adds none.
    """
    chosen = list(dict.fromkeys(named))
    limit = len(chosen) + largest
    force = columns.get("self_contact_force_N")
    if largest and force is not None:
        force = np.nan_to_num(np.asarray(force, dtype=float), nan=0.0)
        ok = np.asarray(columns["converged"], dtype=bool) & (force > 0)
        for i in np.flatnonzero(ok)[np.argsort(-force[ok], kind="stable")]:
            if len(chosen) >= limit:
                break
            case = Case(float(columns["C1"][i]), float(columns["phi"][i]),
                        float(columns["theta"][i]))
            if case not in chosen:
                chosen.append(case)
    return chosen


def boundary_triangles(mesh: Any) -> np.ndarray:
    """The boundary's triangles as geometry-node indices of their corners, shape (t, 3)."""
    from dolfinx import mesh as dmesh
    from dolfinx.cpp.mesh import entities_to_geometry

    tdim = mesh.topology.dim
    mesh.topology.create_connectivity(tdim - 1, tdim)
    facets = dmesh.exterior_facet_indices(mesh.topology)
    return entities_to_geometry(mesh._mesh, tdim - 1, facets, False)[:, :3]


#: The axes a cut may be normal to, and the index of each.
_AXES = {"y": 1, "z": 2}


def cut_axis(gravity: np.ndarray) -> str:
    """The axis the fold's cut is normal to: the plane holds gravity's larger component of y, z.

    Gravity along the body (Φ off the plane θ = 0, towards the feet or the head) rolls the
    mound over its caudal or cranial fold, seen in a sagittal cut (y fixed); gravity to the
    side (lying on the side, Φ = ±90° in the plane) rolls it over its lateral or medial fold,
    seen in a transverse cut (z fixed).
    """
    g = np.asarray(gravity, dtype=float)
    sideways = abs(g[1]) - abs(g[2]) > 1e-9 * np.linalg.norm(g)  # not rounding's residue
    return "z" if sideways else "y"


def section_segments(X: np.ndarray, u: np.ndarray, triangles: np.ndarray,
                     at: float, axis: str = "y") -> np.ndarray:
    """The triangles cut by the plane ``X[axis] = at`` of the reference, carried by ``u``.

    Args:
        X: reference coordinates of the nodes (n, 3).
        u: displacement of the nodes (n, 3).
        triangles: corner indices (t, 3).
        at: the plane's position in the reference configuration.
        axis: the axis the plane is normal to, ``y`` or ``z``.

    Returns:
        Segments (k, 2, 3): where each cut triangle's two crossing points are in the
        deformed configuration (a point on an edge moves with the edge's linear interpolation).
    """
    d = X[triangles, _AXES[axis]] - at  # (t, 3)
    d = np.where(d == 0.0, 1e-12, d)  # a corner on the plane counts as above it
    points = []
    for a, b in ((0, 1), (1, 2), (2, 0)):
        da, db = d[:, a], d[:, b]
        crosses = da * db < 0
        t = np.where(crosses, da / np.where(crosses, da - db, 1.0), 0.0)[:, None]
        ia, ib = triangles[:, a], triangles[:, b]
        x = X[ia] + u[ia] + t * (X[ib] + u[ib] - X[ia] - u[ia])
        points.append((crosses, x))
    cut = sum(c.astype(int) for c, _ in points) == 2
    segments = np.empty((int(cut.sum()), 2, 3))
    filled = np.zeros(int(cut.sum()), dtype=int)
    for crosses, x in points:
        take = crosses[cut]
        rows = np.flatnonzero(take)
        segments[rows, filled[rows]] = x[cut][take]
        filled[rows] += 1
    return segments


def _in_plane(axis: str) -> list[int]:
    """The coordinates a cut normal to ``axis`` is drawn in: x and the other of y, z."""
    return [0, 3 - _AXES[axis]]


def _in_plane_mm(segments: np.ndarray, axis: str) -> list[list[list[float]]]:
    """Segments (k, 2, 3) in metres as [[x, a], [x, a]] in mm (a: the plane's other axis)."""
    return np.round(1e3 * segments[:, :, _in_plane(axis)], 3).tolist()


def fold_sections(mesh_path: str | Path, settings: SolverSettings,
                  cases: list[Case]) -> FoldSections:
    """Solve each case with and without self-contact and cut both at the fold."""
    start = time.perf_counter()
    solved: dict[tuple[str, str], tuple[dict[str, Any], np.ndarray]] = {}
    X = triangles = None
    for setting, case, runner, summary in solve_pairs(mesh_path, settings, cases):
        if X is None:
            X, triangles = runner.mesh.geometry.x.copy(), boundary_triangles(runner.mesh)
        solved[(case.id, setting)] = (
            summary, geometry_displacement(runner.mesh, runner.problem.displacement()))
    records = []
    for case in cases:
        (on, u_on), (off, u_off) = solved[(case.id, "self-contact")], solved[(case.id, "none")]
        peak = (on.get("self_contact") or {}).get("max_pressure_at_m")
        node = int(np.argmin(np.linalg.norm(X - np.asarray(peak), axis=1))) if peak is not None \
            else int(np.argmax(np.linalg.norm(u_on - u_off, axis=1)))
        axis = cut_axis(case.gravity().vector)
        at, moved = float(X[node, _AXES[axis]]), X[node] + u_on[node]
        states = []
        for setting, summary, u in (("self-contact", on, u_on), ("none", off, u_off)):
            sc = summary.get("self_contact") or {}
            states.append(FoldState(
                setting, summary["status"], summary["load_fraction"], summary["max_disp_mm"],
                (summary.get("self_overlap") or {}).get("overlapping_vertices"),
                sc.get("force_N"), summary["wall_s"]["solve"],
                _in_plane_mm(section_segments(X, u, triangles, at, axis), axis)))
        records.append(FoldCase(
            case.id, case.C1, case.phi, case.theta, axis, 1e3 * at,
            [1e3 * float(v) for v in moved[_in_plane(axis)]],
            _in_plane_mm(section_segments(X, np.zeros_like(X), triangles, at, axis), axis),
            states))
        log.info("%s: cut at %s = %.1f mm", case.id, axis, 1e3 * at)
    return FoldSections(str(mesh_path), records, time.perf_counter() - start)


def main(argv: list[str] | None = None) -> int:
    """Command line: see the module docstring."""
    parser = case_arguments(__doc__.split("\n\n")[0])
    parser.add_argument("-o", "--output", type=Path, required=True, help="JSON to write")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO)
    settings = settings_of(args)
    if settings is None:
        return 2
    fold_sections(args.mesh, settings, args.case).write(args.output)
    return 0


if __name__ == "__main__":
    sys.exit(main())
