"""Surrogate-versus-FE metrics of the paper (its Eq. 3, Tables 3 and 4), and error fields.

Every comparison is on all material points of a case, in mm. The paper's Eq. 3
"RMS error" is the *mean* over points of the Euclidean error norm; we report it
under ``rmse_mm`` (as the paper names it) with its SD, and the true root mean square
beside it (``true_rmse_mm``). Relative figures divide by the case's largest FE
displacement.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from fem.dataset import Dataset
from fem.sweep import Case, ClinicalCase
from studies import paper
from studies.results import Record, Result
from surrogate.exceptions import ExtrapolationWarning
from surrogate.fields import write_point_fields_xdmf
from surrogate.predict import Surrogate


@dataclass(frozen=True, slots=True)
class NearestCase(Record):
    """The sweep case nearest an extrapolation case, and the model's error there."""

    case: str
    C1: float
    phi: float
    theta: float
    rmse_mm: float
    relative_rmse: float
    fe_range_mm: list[float]


@dataclass(frozen=True, slots=True)
class CaseComparison(Record):
    """Surrogate against FE on one case (the paper's Eq. 3 and Table 3 metrics, mm).

    Clinical rows carry the config's ``label``, the paper's row and the FE time; rows
    outside the sweep carry how they lie outside (``kind``) and the nearest sweep case.
    """

    case: str
    C1: float
    phi: float
    theta: float
    fe_mean_mm: float
    fe_range_mm: list[float]
    surrogate_mean_mm: float
    surrogate_range_mm: list[float]
    rmse_mm: float
    sd_mm: float
    true_rmse_mm: float
    max_error_mm: float
    p95_error_mm: float
    relative_rmse: float
    relative_p95_error: float
    relative_max_error: float
    extrapolation_warnings: list[str]
    label: str | None = None
    paper: dict[str, Any] | None = None
    fe_wall_s: float | None = None
    error_field: str | None = None
    kind: str | None = None
    nearest_sweep_case: NearestCase | None = None
    error_ratio_to_nearest: float | None = None


@dataclass(frozen=True, slots=True)
class ClinicalBlock(Record):
    """One model on the clinical cases."""

    architecture: str
    boundary: str
    split: str
    held_out_of_training: list[str]
    rows: list[CaseComparison]
    worst: dict[str, Any] | None


@dataclass(frozen=True, slots=True)
class ClinicalEvaluation(Result):
    """``results/surrogate/clinical.json``: the paper's Table 3 for both models."""

    by_sample: ClinicalBlock | None = None
    by_case: ClinicalBlock | None = None


@dataclass(frozen=True, slots=True)
class ExtrapolationBlock(Record):
    """One model on the FE cases outside the sweep."""

    rows: list[CaseComparison]
    failed_fe: list[dict[str, Any]]
    by_kind: dict[str, dict[str, Any]]


@dataclass(frozen=True, slots=True)
class Extrapolation(Result):
    """``results/surrogate/extrapolation.json``: both models outside their training data."""

    by_sample: ExtrapolationBlock | None = None
    by_case: ExtrapolationBlock | None = None


def error_metrics(pred: np.ndarray, fe: np.ndarray) -> dict[str, Any]:
    """Table 3 metrics of one case: prediction ``pred`` against ``fe`` (both (N, 3), mm).

    The error at a point is the norm of the difference; a case's error is given as its mean
    over the points (the paper's "RMS"), its 95th percentile and its maximum (a tumour is
    one point), each in mm and relative to the case's largest FE displacement.
    """
    err = np.linalg.norm(pred - fe, axis=1)
    p95 = float(np.percentile(err, 95))
    fe_norm = np.linalg.norm(fe, axis=1)
    pred_norm = np.linalg.norm(pred, axis=1)
    fe_max = float(fe_norm.max())
    return {
        "fe_mean_mm": float(fe_norm.mean()),
        "fe_range_mm": [float(fe_norm.min()), fe_max],
        "surrogate_mean_mm": float(pred_norm.mean()),
        "surrogate_range_mm": [float(pred_norm.min()), float(pred_norm.max())],
        "rmse_mm": float(err.mean()),
        "sd_mm": float(err.std()),
        "true_rmse_mm": float(np.sqrt(np.mean(err**2))),
        "max_error_mm": float(err.max()),
        "p95_error_mm": p95,
        "relative_rmse": float(err.mean() / fe_max) if fe_max > 0 else float("nan"),
        "relative_p95_error": p95 / fe_max if fe_max > 0 else float("nan"),
        "relative_max_error": float(err.max() / fe_max) if fe_max > 0 else float("nan"),
    }


def compare_case(model: Surrogate, ds: Dataset, case: int) -> dict[str, Any]:
    """FE against surrogate on one case of the dataset (displacements in mm)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", ExtrapolationWarning)
        pred = model.predict(float(ds.C1[case]), float(ds.phi[case]), float(ds.theta[case]))
    return {
        "case": str(ds.ids[case]),
        "C1": float(ds.C1[case]),
        "phi": float(ds.phi[case]),
        "theta": float(ds.theta[case]),
        **error_metrics(pred, ds.displacement[case]),
        "extrapolation_warnings": [str(w.message) for w in caught],
    }


def time_prediction(
    model: Surrogate, C1: float, phi: float, repeats: int = 200
) -> dict[str, float]:
    """Wall time of one whole-field prediction after warm-up (seconds), in this process."""
    model.predict(C1, phi)  # compile
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        model.predict(C1, phi)
        times.append(time.perf_counter() - start)
    times_arr = np.asarray(times)
    return {
        "median_s": float(np.median(times_arr)),
        "mean_s": float(times_arr.mean()),
        "std_s": float(times_arr.std()),
        "repeats": repeats,
    }


def clinical_table(
    model: Surrogate,
    ds: Dataset,
    clinical: Sequence[ClinicalCase],
    fe_wall_s: dict[str, float] | None = None,
) -> list[dict[str, Any]]:
    """The paper's Table 3 for the configured clinical cases, ours beside the paper's.

    Args:
        model: the surrogate.
        ds: the dataset holding the clinical cases' FE solutions.
        clinical: the config's clinical cases (:func:`fem.sweep.clinical_list`).
        fe_wall_s: optional FE solve time per case id (Table 4).

    Raises:
        KeyError: if a clinical case is not in the dataset or did not converge.
    """
    rows = []
    for item in clinical:
        case = ds.case_index(item.case.C1, item.case.phi, item.case.theta)
        if not ds.converged[case]:
            raise KeyError(f"clinical case {ds.ids[case]} did not converge in the FE sweep")
        row = {"label": item.label, **compare_case(model, ds, case)}
        row["paper"] = paper.table3_row(item.case.C1, item.case.phi)
        if fe_wall_s is not None:
            row["fe_wall_s"] = fe_wall_s.get(str(ds.ids[case]))
        rows.append(row)
    return rows


def write_error_fields(
    path: str | Path,
    mesh_xdmf: str | Path,
    model: Surrogate,
    fe_mm: np.ndarray,
    pred_mm: np.ndarray,
) -> None:
    """FE and surrogate displacement, error vector and error norm (mm) on the mesh, as XDMF."""
    err = pred_mm - fe_mm
    write_point_fields_xdmf(
        path,
        mesh_xdmf,
        model.node_index,
        model.X,
        {
            "fe_displacement_mm": fe_mm,
            "surrogate_displacement_mm": pred_mm,
            "error_mm": err,
            "error_norm_mm": np.linalg.norm(err, axis=1),
            "fe_displacement_norm_mm": np.linalg.norm(fe_mm, axis=1),
        },
    )


def extrapolation_kind(model: Surrogate, C1: float, phi: float, theta: float) -> str:
    """Which way a case leaves the model's training set, in words (``in range`` if it does not).

    C1 below or above its range, or below the softest C1 trained beside its direction; for a
    model of the plane, an unseen Φ or θ off the plane; for one trained off it, gravity away
    from every training direction.
    """
    training_range = model.training_range
    lo, hi = training_range["C1_kPa"]
    kinds = []
    if C1 < lo - 1e-9:
        kinds.append("C1 below range")
    elif C1 > hi + 1e-9:
        kinds.append("C1 above range")
    elif model.trained.softest_beside(C1, phi, theta) is not None:
        kinds.append("C1 below its direction's range")
    if model.trained.range_checks()["directions"] is not None:
        if model.trained.direction_outside(phi, theta) is not None:
            kinds.append("unseen direction")
        return ", ".join(kinds) or "in range"
    if not any(abs(((phi - p) + 180.0) % 360.0 - 180.0) < 1e-6 for p in training_range["phi_deg"]):
        kinds.append("unseen phi")
    if abs(np.sin(np.radians(phi))) > 1e-9 and not any(
        abs(theta - t) < 1e-6 for t in training_range["theta_deg"]
    ):
        kinds.append("unseen theta")
    return ", ".join(kinds) or "in range"


def compare_extra_case(
    model: Surrogate, C1: float, phi: float, theta: float, fe_mm: np.ndarray, X: np.ndarray
) -> dict[str, Any]:
    """Surrogate against an FE case outside the dataset (same material points required).

    Raises:
        ValueError: if the case's material points are not the model's.
    """
    if X.shape != model.X.shape or not np.allclose(X, model.X, atol=1e-9):
        raise ValueError("the extra case's material points differ from the surrogate's mesh")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", ExtrapolationWarning)
        pred = model.predict(C1, phi, theta)
    return {
        "C1": C1,
        "phi": phi,
        "theta": theta,
        "kind": extrapolation_kind(model, C1, phi, theta),
        **error_metrics(pred, fe_mm),
        "extrapolation_warnings": [str(w.message) for w in caught],
    }


def evaluate_clinical(
    models: dict[str, Surrogate],
    ds: Dataset,
    clinical: Sequence[ClinicalCase],
    fe_wall_s: dict[str, float] | None = None,
    mesh_xdmf: str | Path | None = None,
    field_paths: dict[tuple[str, str], str | Path] | None = None,
) -> dict[str, Any]:
    """Table 3 (and the FE part of Table 4) for each model, with error fields as XDMF.

    Args:
        models: e.g. ``{"by_sample": model, "by_case": model}``.
        ds: the dataset.
        clinical: the config's clinical cases (:func:`fem.sweep.clinical_list`).
        fe_wall_s: FE solve time per case id.
        mesh_xdmf: the mesh, for the error fields.
        field_paths: ``{(model name, case id): path.xdmf}`` of the error fields to write.
    """
    out: dict[str, Any] = {}
    for name, model in models.items():
        rows = clinical_table(model, ds, clinical, fe_wall_s)
        for row in rows:
            path = (field_paths or {}).get((name, row["case"]))
            if path is not None and mesh_xdmf is not None:
                case = ds.case_index(row["C1"], row["phi"], row["theta"])
                pred = model.predict(row["C1"], row["phi"], row["theta"])
                write_error_fields(path, mesh_xdmf, model, ds.displacement[case], pred)
                row["error_field"] = str(path)
        worst = max(rows, key=lambda r: r["rmse_mm"]) if rows else None
        out[name] = {
            "architecture": model.config.architecture,
            "boundary": model.config.boundary,
            "split": model.config.split,
            "held_out_of_training": sorted(set(row["case"] for row in rows) & set(model.held_out)),
            "rows": rows,
            "worst": None
            if worst is None
            else {
                "case": worst["case"],
                "label": worst["label"],
                "rmse_mm": worst["rmse_mm"],
                "sd_mm": worst["sd_mm"],
                "relative_rmse": worst["relative_rmse"],
            },
        }
    return out


def nearest_case(ds: Dataset, C1: float, phi: float, theta: float = 0.0) -> int:
    """The converged dataset case closest in (log C1, gravity direction)."""
    from fem.directions import gravity_direction

    g = gravity_direction(np.asarray(phi, float), np.asarray(theta, float))
    angle = np.degrees(np.arccos(np.clip(ds.direction @ g, -1.0, 1.0)))
    distance = np.abs(np.log(ds.C1 / C1)) / np.log(1.1) + angle / 10.0
    distance[~ds.converged] = np.inf
    return int(np.argmin(distance))


def fe_in_model_order(model: Surrogate, points_path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """An FE case's displacement (mm) and reference coordinates (m) at the model's points.

    Raises:
        ValueError: if the case's file lacks one of the model's material points.
    """
    from fem.case_files import read_points

    points = read_points(points_path)
    row_of = np.full(max(points["node_index"].max(), model.node_index.max()) + 1, -1)
    row_of[points["node_index"]] = np.arange(points["node_index"].size)
    rows = row_of[model.node_index]
    if np.any(rows < 0):
        raise ValueError(f"{points_path}: material points differ from the surrogate's mesh")
    return 1e3 * points["u"][rows], points["X"][rows]


def evaluate_extrapolation(
    models: dict[str, Surrogate],
    ds: Dataset,
    cases: Sequence[tuple[str | Path, str | Path]],
) -> dict[str, Any]:
    """Each model's error on FE cases outside the training set, with the nearest sweep case beside.

    Args:
        models: named surrogates.
        ds: the training dataset (for the nearest in-sweep case).
        cases: ``(summary.json, points.h5)`` of each extra case.
    """
    from fem.case_files import read_summary

    out: dict[str, Any] = {name: {"rows": [], "failed_fe": []} for name in models}
    for summary_path, points_path in cases:
        summary = read_summary(summary_path)
        case = Case.from_summary(summary)
        C1, phi, theta = case.C1, case.phi, case.theta
        for name, model in models.items():
            if summary["status"] != "converged":
                out[name]["failed_fe"].append(
                    {"case": summary["case"], "reason": summary.get("reason", "")}
                )
                continue
            fe, X = fe_in_model_order(model, points_path)
            row = {"case": summary["case"], **compare_extra_case(model, C1, phi, theta, fe, X)}
            near = nearest_case(ds, C1, phi, theta)
            ref = compare_case(model, ds, near)
            row["nearest_sweep_case"] = {
                k: ref[k]
                for k in ("case", "C1", "phi", "theta", "rmse_mm", "relative_rmse", "fe_range_mm")
            }
            row["error_ratio_to_nearest"] = (
                row["rmse_mm"] / ref["rmse_mm"] if ref["rmse_mm"] > 0 else None
            )
            out[name]["rows"].append(row)
    for name in models:
        groups: dict[str, list[float]] = {}
        for row in out[name]["rows"]:
            groups.setdefault(row["kind"], []).append(row["rmse_mm"])
        out[name]["by_kind"] = {
            k: {"cases": len(v), "mean_rmse_mm": float(np.mean(v)), "max_rmse_mm": float(np.max(v))}
            for k, v in groups.items()
        }
    return out
