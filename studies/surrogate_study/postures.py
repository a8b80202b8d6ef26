"""The surrogate in the postures a patient takes: its error against FE in each.

The paper's sweep turns gravity in one plane, the patient rolling from prone through lying on the
side to supine; the clinic adds postures outside it (standing for a mammogram, sitting reclined,
supine tilted under ultrasound). Each posture of ``surrogate_study.postures`` is a direction of
gravity relative to the body (:class:`studies.surrogate_study.config.Posture`), evaluated at a few
stiffnesses; its FE solution comes from the sweep where the sweep has it, else from an extra solve
outside it. The table says, per posture, how far the model's worst point is from FE and whether the
posture lies inside the directions it was trained on, and, from the first posture (prone: the
posture of the MRI), the way the breast takes to each other posture at the same stiffness, with the
model's error in that way: where a tumour seen in the image goes.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from fem.sweep import Case
from studies.results import Record, Result
from studies.surrogate_study.errors_against_fe import CaseErrors, Centroids
from studies.surrogate_study.surrogate_evaluation import extrapolation_kind, fe_in_model_order
from surrogate.exceptions import ExtrapolationWarning
from surrogate.predict import Surrogate


@dataclass(frozen=True, slots=True)
class PostureRow(Record):
    """One posture at one stiffness.

    Attributes:
        posture: its name.
        case: the FE case's id.
        C1: its stiffness (kPa).
        phi: gravity's Φ (degrees).
        theta: gravity's θ (degrees).
        in_sweep: whether the FE case is one of the sweep's (its points trained the model).
        kind: how the case lies relative to the training data (``in range``, ``unseen
            theta``, ...; :func:`studies.surrogate_study.surrogate_evaluation.extrapolation_kind`).
        fe_status: the FE solve's status; the errors are absent unless ``converged``.
        fe_reason: why, where it failed.
        fe_solve_s: the FE solve's wall time.
        errors: the surrogate against FE (mean, 95th percentile and max point error).
        extrapolation_warnings: what the model warned of when asked.
        between: the same at the cell centroids of the case's quadratic mesh, between the
            material points, where a tumour lies
            (:class:`studies.surrogate_study.held_out.Centroids`);
            absent where the case's fields are not on 10-node cells.
        movement: the model's movement from the first posture at the same C1 against FE's
            (its ``fe_max_mm``: FE's largest movement), at the material points; absent for
            the first posture itself, or where either FE solve failed.
    """

    posture: str
    case: str
    C1: float
    phi: float
    theta: float
    in_sweep: bool
    kind: str
    fe_status: str
    fe_reason: str
    fe_solve_s: float | None
    errors: CaseErrors | None
    extrapolation_warnings: list[str]
    between: CaseErrors | None = None
    movement: CaseErrors | None = None


@dataclass(frozen=True, slots=True)
class PostureEvaluation(Result):
    """``results/surrogate/postures.json``: the model's error in every posture."""

    architecture: str
    training_range: dict[str, Any]
    rows: list[PostureRow]


def evaluate_postures(
    model: Surrogate,
    postures: Sequence[tuple[str, bool, str | Path, str | Path, str | Path | None]],
    movement: bool = True,
) -> PostureEvaluation:
    """The model against FE in each posture.

    Args:
        model: the surrogate.
        postures: ``(name, in_sweep, summary.json, points.h5, fields.h5)`` of each posture's
            FE case; with its ``fields.h5`` (None: not compared there) on a quadratic mesh,
            the errors are also taken at the cell centroids.
        movement: also judge each posture's movement from the first posture (the name of the
            first case) at the same C1 (:attr:`PostureRow.movement`).

    Raises:
        ValueError: if a case's material points are not the model's, or a centroid lies
            outside the model's mesh.
    """
    from fem.case_files import read_summary

    rows = []
    fields: list[tuple[np.ndarray, np.ndarray] | None] = []  # each row's (model, FE), mm
    cached: _CentroidModel | None = None  # the model at the centroids, kept between cases
    for name, in_sweep, summary_path, points_path, fields_path in postures:
        summary = read_summary(summary_path)
        case = Case.from_summary(summary)
        C1, phi, theta = case.C1, case.phi, case.theta
        errors = between = None
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", ExtrapolationWarning)
            pred = model.predict(C1, phi, theta)
        if summary["status"] == "converged":
            fe, _ = fe_in_model_order(model, points_path)
            errors = CaseErrors.between(pred, fe, summary["case"], C1, phi, theta)
            if fields_path is not None:
                cached, between = _between(model, cached, fields_path, str(summary["case"]),
                                           C1, phi, theta)
        rows.append(PostureRow(
            posture=name,
            case=str(summary["case"]),
            C1=C1,
            phi=phi,
            theta=theta,
            in_sweep=bool(in_sweep),
            kind=extrapolation_kind(model, C1, phi, theta),
            fe_status=str(summary["status"]),
            fe_reason=str(summary.get("reason", "")),
            fe_solve_s=(summary.get("wall_s") or {}).get("solve"),
            errors=errors,
            extrapolation_warnings=[str(w.message) for w in caught],
            between=between,
        ))
        fields.append(None if errors is None else (pred, fe))
    if movement and rows:
        rows = _movements(rows, fields)
    return PostureEvaluation(
        architecture=model.config.architecture,
        training_range=dict(model.training_range or {}),
        rows=rows,
    )


def _movements(rows: list[PostureRow],
               fields: list[tuple[np.ndarray, np.ndarray] | None]) -> list[PostureRow]:
    """The rows with each one's movement from the first posture at its C1, where both solved."""
    first = rows[0].posture
    start = {row.C1: f for row, f in zip(rows, fields, strict=True)
             if row.posture == first and f is not None}
    out = []
    for row, f in zip(rows, fields, strict=True):
        if row.posture != first and f is not None and row.C1 in start:
            (pred, fe), (pred0, fe0) = f, start[row.C1]
            row = replace(row, movement=CaseErrors.between(
                pred - pred0, fe - fe0, row.case, row.C1, row.phi, row.theta))
        out.append(row)
    return out


@dataclass(frozen=True)
class _CentroidModel:
    """A model answering at one quadratic mesh's cell centroids (the postures share a mesh)."""

    centroids: Centroids
    model: Surrogate


def _between(
    model: Surrogate, cached: _CentroidModel | None, fields_path: str | Path, case: str,
    C1: float, phi: float, theta: float,
) -> tuple[_CentroidModel | None, CaseErrors | None]:
    """The model against the case's FE field at its mesh's cell centroids.

    None on a linear mesh, whose fields file lacks the FE field's edge values. The model
    answering at the centroids is returned too, kept for the next posture on the same mesh.
    """
    read = Centroids.of_fields(fields_path)
    if read is None:
        return cached, None
    centroids, fe = read
    if cached is None or not np.array_equal(cached.centroids.cells, centroids.cells):
        cached = _CentroidModel(centroids, centroids.model(model))
    with warnings.catch_warnings():  # warned of once already, at the material points
        warnings.simplefilter("ignore", ExtrapolationWarning)
        pred = cached.model.predict(C1, phi, theta)
    return cached, CaseErrors.between(pred, fe, case, C1, phi, theta)


__all__ = ["PostureEvaluation", "PostureRow", "evaluate_postures"]
