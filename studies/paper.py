"""The paper's published figures, to print ours beside them (Babarenda Gamage et al.).

Table 2: validation error (mm) and training time (s, NVIDIA V100) per architecture,
mean and SD over five trainings. Table 3: clinical cases, FE and surrogate mean
displacement and range (mm), surrogate error per Eq. 3 ± SD (mm). Table 4: wall
times (s) of the FE model and the surrogate on an Intel Core i7 (2.3 GHz) CPU.
Fig. 5's caption: the largest surrogate error (mm) of the two soft cases.
"""

from __future__ import annotations

TABLE2: dict[str, dict[str, tuple[float, float]]] = {
    "2x32": {"validation_error_mm": (0.31, 0.06), "train_s": (2663.0, 110.0)},
    "2x64": {"validation_error_mm": (0.21, 0.06), "train_s": (2632.0, 98.0)},
    "2x128": {"validation_error_mm": (0.27, 0.10), "train_s": (2715.0, 105.0)},
    "3x32": {"validation_error_mm": (0.13, 0.03), "train_s": (3155.0, 60.0)},
    "3x64": {"validation_error_mm": (1.27, 0.26), "train_s": (1171.0, 168.0)},
    "3x128": {"validation_error_mm": (1.43, 0.60), "train_s": (1414.0, 982.0)},
    "4x32": {"validation_error_mm": (1.15, 0.56), "train_s": (1842.0, 1051.0)},
    "4x64": {"validation_error_mm": (0.92, 0.77), "train_s": (2420.0, 1175.0)},
    "4x128": {"validation_error_mm": (1.14, 0.19), "train_s": (1390.0, 164.0)},
}

# Keyed by (C1 in kPa, Φ in degrees): Φ = 180° is prone, 0° supine.
TABLE3: dict[tuple[float, float], dict[str, object]] = {
    (1.0, 180.0): {"fe_mean_mm": 3.21, "fe_range_mm": (0.0, 37.2), "surrogate_mean_mm": 3.0,
                   "surrogate_range_mm": (0.01, 35.7), "rmse_mm": 0.70, "sd_mm": 0.68},
    (5.0, 180.0): {"fe_mean_mm": 0.62, "fe_range_mm": (0.0, 7.2), "surrogate_mean_mm": 0.58,
                   "surrogate_range_mm": (0.01, 7.3), "rmse_mm": 0.19, "sd_mm": 0.18},
    (1.0, 0.0): {"fe_mean_mm": 3.16, "fe_range_mm": (0.0, 38.4), "surrogate_mean_mm": 2.6,
                 "surrogate_range_mm": (0.00, 36.2), "rmse_mm": 1.04, "sd_mm": 1.08},
    (5.0, 0.0): {"fe_mean_mm": 0.62, "fe_range_mm": (0.0, 7.3), "surrogate_mean_mm": 0.42,
                 "surrogate_range_mm": (0.01, 6.7), "rmse_mm": 0.30, "sd_mm": 0.29},
}

TABLE4: dict[tuple[float, float], dict[str, tuple[float, float]]] = {
    (1.0, 180.0): {"fe_s": (154.0, 11.0), "surrogate_s": (2.40, 0.02)},
    (5.0, 180.0): {"fe_s": (80.0, 1.7), "surrogate_s": (2.36, 0.02)},
    (1.0, 0.0): {"fe_s": (152.0, 4.0), "surrogate_s": (2.37, 0.02)},
    (5.0, 0.0): {"fe_s": (82.6, 1.6), "surrogate_s": (2.37, 0.02)},
}

# Fig. 5's caption: the largest surrogate error on the material points (mm); the paper
# gives it only for the two soft (1.0 kPa) cases.
FIG5_MAX_ERROR_MM: dict[tuple[float, float], float] = {(1.0, 180.0): 7.73, (1.0, 0.0): 9.50}

BEST_ARCHITECTURE = "3x32"
SPEEDUP_RANGE = (37.0, 82.5)


def _key(C1: float, phi: float) -> tuple[float, float]:
    return round(float(C1), 2), round(float(phi) % 360.0, 1) + 0.0


def table3_row(C1: float, phi: float) -> dict[str, object] | None:
    """The paper's Table 3 column of a clinical case, or None if it is not one of the four."""
    return TABLE3.get(_key(C1, phi))


def table4_row(C1: float, phi: float) -> dict[str, tuple[float, float]] | None:
    """The paper's Table 4 column of a clinical case, or None."""
    return TABLE4.get(_key(C1, phi))


def fig5_max_error_mm(C1: float, phi: float) -> float | None:
    """The largest surrogate error the paper's Fig. 5 caption gives for a case, or None."""
    return FIG5_MAX_ERROR_MM.get(_key(C1, phi))
