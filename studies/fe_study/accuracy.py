"""Displacement error measures against a reference, and observed convergence rates.

Discretisations are compared at the *material points* (the vertices of the default
mesh, as in the dataset); :func:`fem.interpolation.evaluate` brings any field there.
"""

from __future__ import annotations

import numpy as np


def displacement_errors(u: np.ndarray, reference: np.ndarray) -> dict[str, float]:
    """Pointwise displacement errors against a reference (both (N, 3), metres).

    Returns:
        ``max_error_mm``, ``rms_error_mm``, ``mean_error_mm`` (the paper's Eq. 3),
        the reference's ``max_disp_mm`` and ``relative_max_error`` = max error /
        max |u_ref| (the accuracy target is 1 %).
    """
    err = np.linalg.norm(np.asarray(u) - np.asarray(reference), axis=1)
    scale = float(np.linalg.norm(reference, axis=1).max())
    return {
        "max_error_mm": 1e3 * float(err.max()),
        "rms_error_mm": 1e3 * float(np.sqrt(np.mean(err**2))),
        "mean_error_mm": 1e3 * float(err.mean()),
        "max_disp_mm": 1e3 * scale,
        "relative_max_error": float(err.max()) / scale if scale > 0 else float("nan"),
    }


def observed_rates(sizes: list[float], errors: list[float]) -> list[float]:
    """Convergence rates log(e_i / e_(i+1)) / log(h_i / h_(i+1)) between successive meshes."""
    rates = []
    pairs = list(zip(sizes, errors, strict=True))
    for (h0, e0), (h1, e1) in zip(pairs, pairs[1:], strict=False):
        rate = np.log(e0 / e1) / np.log(h0 / h1) if e0 > 0 and e1 > 0 else np.nan
        rates.append(float(rate))
    return rates


def fitted_rate(sizes: list[float], errors: list[float]) -> float:
    """Least-squares slope of log(error) against log(h)."""
    h, e = np.log(np.asarray(sizes)), np.log(np.asarray(errors))
    return float(np.polyfit(h, e, 1)[0])
