"""What the skin changes: the clinical cases homogeneous and with the skin membrane.

The skin (:class:`fem.materials.SkinLayer`, a membrane on the ``skin`` boundary) is stiffer than
the fat by a ratio and has a thickness, both known only to a range (docs/tissues.md). This
study solves the config's clinical cases on the workflow's mesh with each setting of
:func:`skin_settings`: homogeneous (no membrane) first, then the default skin (the ratio of
``material.tissues.skin``, the thickness and wrinkling of ``material.skin``, else
:data:`fem.materials.DEFAULT_SKIN_THICKNESS`, wrinkling), then each other ratio of
``fe_study.skin.ratios`` at the default thickness and each other thickness of
``fe_study.skin.thicknesses`` at the default ratio. One :class:`fem.case.CaseRunner` serves
each setting's cases (its forms compiled once).

Per setting and case it records the outcome, the load steps, Newton iterations, the solve's
wall time, max |u| and where a tumour point (``fe_study.skin.tumour``, or the mesh's volume
centroid: :func:`tumour_point`) is carried; per setting, the tumour's prone-to-supine path
(:func:`tumour_paths`: the clinical cases paired by C1, Φ 180° against Φ 0°). The workflow's
``fe_skin`` job writes ``results/fe_study/skin.json`` (:class:`SkinStudy`) and the report's
section on the skin draws it (:func:`studies.figures.tissues.plot_skin`).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from fem.case import CaseRunner
from fem.interpolation import evaluate
from fem.materials import DEFAULT_SKIN_THICKNESS, SkinLayer, Tissues
from fem.parameters import SolverSettings
from fem.sweep import Case
from meshes.tags import Tissue
from studies.config_errors import ConfigError
from studies.fe_study.config import SkinStudyConfig
from studies.results import Record, Result

log = logging.getLogger(__name__)

__all__ = ["SkinCase", "SkinSetting", "SkinStudy", "TumourPath", "prone_supine_pairs",
           "skin_settings", "skin_study", "solver_settings", "tumour_paths", "tumour_point"]

#: How far outside the mesh (m) a given tumour point may lie: a point on the skin of a curved
#: mesh may fall a rounding's width outside its cells.
OUTSIDE_TOLERANCE_M = 1e-6

#: What each setting varies: nothing (homogeneous), nothing of the skin (the default skin),
#: its ratio, its thickness.
VARIED = ("none", "default", "ratio", "thickness")


@dataclass(frozen=True, slots=True)
class SkinSetting(Record):
    """One way of carrying the skin.

    Attributes:
        name: ``homogeneous``, ``skin`` (the default skin), ``ratio <r>`` or
            ``thickness <t> mm``.
        varied: which of :data:`VARIED` it is.
        ratio: the skin's C1 over the fat's (None: no skin membrane).
        thickness_m: the skin's thickness, m (None: no skin membrane).
        wrinkles: whether the membrane wrinkles (None: no skin membrane).
    """

    name: str
    varied: str
    ratio: float | None = None
    thickness_m: float | None = None
    wrinkles: bool | None = None

    @property
    def skin(self) -> SkinLayer | None:
        """The membrane (None: homogeneous)."""
        if self.thickness_m is None:
            return None
        return SkinLayer(self.thickness_m, bool(self.wrinkles))


@dataclass(frozen=True, slots=True)
class SkinCase(Record):
    """One clinical case solved with one setting.

    Attributes:
        setting: the setting's name (:attr:`SkinSetting.name`).
        case: the case id (:attr:`fem.sweep.Case.id`).
        C1, phi, theta: the case (kPa, degrees).
        status: ``converged`` or ``failed`` (a failed case keeps the last load it reached).
        load_fraction: the load reached.
        load_steps: accepted load steps.
        newton_iterations: Newton iterations of every attempt.
        wall_s: the solve's wall time.
        max_disp_mm: the largest displacement.
        tumour_mm: where the tumour point is carried, mm (project frame).
    """

    setting: str
    case: str
    C1: float
    phi: float
    theta: float
    status: str
    load_fraction: float
    load_steps: int
    newton_iterations: int
    wall_s: float
    max_disp_mm: float
    tumour_mm: list[float]

    @property
    def converged(self) -> bool:
        """Whether the case converged."""
        return self.status == "converged"


@dataclass(frozen=True, slots=True)
class TumourPath(Record):
    """The tumour's way from the prone to the supine clinical case of one C1, with one setting.

    Attributes:
        setting: the setting's name.
        C1: the cases' C1 (kPa).
        prone, supine: the two cases' ids (Φ 180° and Φ 0°).
        distance_mm: how far the tumour moves (None: either case did not converge).
        vector_mm: supine position minus prone position, mm (None likewise).
    """

    setting: str
    C1: float
    prone: str
    supine: str
    distance_mm: float | None = None
    vector_mm: list[float] | None = None


@dataclass(frozen=True, slots=True)
class SkinStudy(Result):
    """``results/fe_study/skin.json``: the clinical cases with each setting of the skin.

    Attributes:
        mesh: the mesh solved on.
        tumour_mm: the tumour point in the reference configuration, mm (project frame).
        tumour_from: ``fe_study.skin.tumour`` or ``volume centroid`` (:func:`tumour_point`).
        settings: every setting, homogeneous first, in the order solved.
        cases: every case with every setting.
        paths: the tumour's prone-to-supine paths, per setting and C1.
        seconds: the study's wall time.
    """

    mesh: str
    tumour_mm: list[float]
    tumour_from: str
    settings: list[SkinSetting]
    cases: list[SkinCase]
    paths: list[TumourPath]
    seconds: float

    def case(self, setting: str, case: str) -> SkinCase | None:
        """The record of ``case`` solved with ``setting``, or None."""
        return next((c for c in self.cases if c.setting == setting and c.case == case), None)

    def varying(self, varied: str) -> list[SkinSetting]:
        """The settings that vary ``varied`` (one of :data:`VARIED`)."""
        return [s for s in self.settings if s.varied == varied]


def skin_settings(study: SkinStudyConfig, solver: SolverSettings) -> list[SkinSetting]:
    """Homogeneous, the default skin, each other ratio, each other thickness, in that order.

    The default skin is the solver's: its ratio ``material.tissues.skin`` (else the literature
    default), its thickness and wrinkling from ``material.skin`` (else
    :data:`fem.materials.DEFAULT_SKIN_THICKNESS`, wrinkling).
    """
    ratio = solver.tissues.ratio(Tissue.SKIN)
    layer = solver.skin or SkinLayer(DEFAULT_SKIN_THICKNESS)
    thickness, wrinkles = layer.thickness, layer.wrinkles
    out = [SkinSetting("homogeneous", "none"),
           SkinSetting("skin", "default", ratio, thickness, wrinkles)]
    for r in dict.fromkeys(study.ratios):
        if r != ratio:
            out.append(SkinSetting(f"ratio {r:g}", "ratio", r, thickness, wrinkles))
    for t in dict.fromkeys(study.thicknesses):
        if t != thickness:
            out.append(SkinSetting(f"thickness {1e3 * t:g} mm", "thickness", ratio, t,
                                   wrinkles))
    return out


def solver_settings(setting: SkinSetting, solver: SolverSettings) -> SolverSettings:
    """The solver's settings with the setting's skin (its ratio joins the tissue map)."""
    if setting.skin is None:
        return replace(solver, skin=None)
    return replace(solver, skin=setting.skin,
                   tissues=Tissues({**solver.tissues.ratios, Tissue.SKIN: setting.ratio}))


def tumour_point(u: Any, given: tuple[float, float, float] | None,
                 mesh_name: str | Path = "the mesh") -> tuple[np.ndarray, str]:
    """The tumour point in the reference configuration (m) and where it came from.

    ``u`` is any function on the mesh (the point is located in its cells). ``given``
    (``fe_study.skin.tumour``) must lie in the mesh. Without it: the volume centroid of the
    mesh's cells (their straight tetrahedra), or where that lies outside the body (a body bent
    round it) the centre of the cell whose centre is nearest it.

    Raises:
        ConfigError: naming ``fe_study.skin.tumour`` where the given point lies outside.
    """
    if given is not None:
        point = np.asarray(given, dtype=float)
        _, distance = evaluate(u, point[None, :])
        if distance[0] > OUTSIDE_TOLERANCE_M:
            raise ConfigError(
                f"fe_study.skin.tumour: the point {list(given)} m lies {1e3 * distance[0]:.1f} "
                f"mm outside {mesh_name}: give a point inside the breast, in the project's "
                "frame (m), or null for the mesh's volume centroid")
        return point, "fe_study.skin.tumour"
    mesh = u.function_space.mesh
    dofmap = mesh.geometry.dofmap
    cells = dofmap.array.reshape(-1, dofmap.links(0).size)[:, :4]  # the vertices come first
    corners = mesh.geometry.x[cells]  # (cells, 4, 3)
    volume = np.abs(np.linalg.det(corners[:, 1:] - corners[:, :1])) / 6.0
    centres = corners.mean(axis=1)
    point = (volume[:, None] * centres).sum(axis=0) / volume.sum()
    _, distance = evaluate(u, point[None, :])
    if distance[0] > 0.0:
        point = centres[np.argmin(np.linalg.norm(centres - point, axis=1))]
    return point, "volume centroid"


def prone_supine_pairs(cases: list[Case]) -> list[tuple[Case, Case]]:
    """The clinical cases paired by C1: prone (Φ 180°, θ 0) with supine (Φ 0°, θ 0)."""
    def posture(phi: float) -> dict[float, Case]:
        return {c.C1: c for c in cases if c.theta == 0.0 and c.phi % 360.0 == phi}

    prone, supine = posture(180.0), posture(0.0)
    return [(prone[c1], supine[c1]) for c1 in sorted(prone) if c1 in supine]


def tumour_paths(settings: list[SkinSetting], cases: list[SkinCase],
                 clinical: list[Case]) -> list[TumourPath]:
    """Per setting and C1, the tumour's way from prone to supine (where both converged)."""
    solved = {(c.setting, c.case): c for c in cases}
    out = []
    for setting in settings:
        for prone, supine in prone_supine_pairs(clinical):
            a, b = solved.get((setting.name, prone.id)), solved.get((setting.name, supine.id))
            if a is None or b is None:
                continue
            path = TumourPath(setting.name, prone.C1, prone.id, supine.id)
            if a.converged and b.converged:
                vector = np.asarray(b.tumour_mm) - np.asarray(a.tumour_mm)
                path = replace(path, distance_mm=float(np.linalg.norm(vector)),
                               vector_mm=vector.tolist())
            out.append(path)
    return out


def _record(setting: SkinSetting, case: Case, summary: dict[str, Any],
            tumour: np.ndarray) -> SkinCase:
    return SkinCase(setting.name, case.id, case.C1, case.phi, case.theta, summary["status"],
                    summary["load_fraction"], summary["load_steps"],
                    summary["total_newton_iterations"], summary["wall_s"]["solve"],
                    summary["max_disp_mm"], (1e3 * tumour).tolist())


def skin_study(mesh_path: str | Path, solver: SolverSettings, study: SkinStudyConfig,
               clinical: list[Case]) -> SkinStudy:
    """Solve the clinical cases with every setting of :func:`skin_settings`.

    The tumour point is located before any solve, so that a point outside the mesh stops the
    study before it costs anything.
    """
    start = time.perf_counter()
    settings = skin_settings(study, solver)
    records: list[SkinCase] = []
    point, source = None, ""
    for setting in settings:
        with CaseRunner(mesh_path, solver_settings(setting, solver)) as runner:
            if point is None:
                point, source = tumour_point(runner.problem.displacement(), study.tumour,
                                             mesh_path)
                log.info("tumour point (%s): %s mm", source, np.round(1e3 * point, 2))
            for case in clinical:
                result, timings = runner.solve(case)
                summary = runner.summary(case, result, timings, measure_unit=False)
                u, _ = evaluate(runner.problem.displacement(), point[None, :])
                records.append(_record(setting, case, summary, point + u[0]))
                log.info("%s, %s: %s at load %.3f, max |u| %.2f mm, %.1f s", setting.name,
                         case.id, summary["status"], summary["load_fraction"],
                         summary["max_disp_mm"], summary["wall_s"]["solve"])
    return SkinStudy(str(mesh_path), (1e3 * point).tolist(), source, settings, records,
                     tumour_paths(settings, records, clinical), time.perf_counter() - start)
