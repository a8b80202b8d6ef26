"""Surrogate-versus-FE metrics of the paper (its Eq. 3 and Table 3)."""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from surrogate.data import Dataset
from surrogate.predict import Surrogate


def compare_case(model: Surrogate, ds: Dataset, case: int) -> dict[str, Any]:
    """FE against surrogate on one case of the dataset (displacements in mm).

    ``rmse_mm`` follows the paper's Eq. 3 (the mean over points of the Euclidean
    error norm, which the paper calls RMS error); ``sd_mm`` is that norm's standard
    deviation; ``true_rmse_mm`` is the root of the mean squared norm.
    """
    fe = ds.displacement[case]
    pred = model.predict(float(ds.C1[case]), float(ds.phi[case]), float(ds.theta[case]))
    err = np.linalg.norm(pred - fe, axis=1)
    fe_norm = np.linalg.norm(fe, axis=1)
    pred_norm = np.linalg.norm(pred, axis=1)
    return {
        "case": str(ds.ids[case]),
        "C1": float(ds.C1[case]),
        "phi": float(ds.phi[case]),
        "fe_mean_mm": float(fe_norm.mean()),
        "fe_range_mm": [float(fe_norm.min()), float(fe_norm.max())],
        "surrogate_mean_mm": float(pred_norm.mean()),
        "surrogate_range_mm": [float(pred_norm.min()), float(pred_norm.max())],
        "rmse_mm": float(err.mean()),
        "sd_mm": float(err.std()),
        "true_rmse_mm": float(np.sqrt(np.mean(err**2))),
        "max_error_mm": float(err.max()),
        "relative_rmse": float(err.mean() / fe_norm.max()) if fe_norm.max() > 0 else float("nan"),
    }


def time_prediction(model: Surrogate, C1: float, phi: float, repeats: int = 200) -> dict[str, float]:
    """Wall time of one whole-field prediction after warm-up (seconds)."""
    model.predict(C1, phi)  # compile
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        model.predict(C1, phi)
        times.append(time.perf_counter() - start)
    times_arr = np.asarray(times)
    return {"median_s": float(np.median(times_arr)), "mean_s": float(times_arr.mean()),
            "std_s": float(times_arr.std()), "repeats": repeats}
