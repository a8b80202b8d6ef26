"""The paper's published figures, transcribed once for side-by-side comparison.

Babarenda Gamage et al., "Rapid prediction of breast biomechanics under gravity loading
using surrogate machine learning models" (../shared/reference/paper.txt). Displacements in
mm, times in s. Keys of the clinical tables are (C1 in kPa, Φ in degrees): Φ = 180° prone,
Φ = 0° supine.
"""

from __future__ import annotations

TABLE2_VALIDATION_MM: dict[str, tuple[float, float]] = {
    "2x32": (0.31, 0.06),
    "2x64": (0.21, 0.06),
    "2x128": (0.27, 0.10),
    "3x32": (0.13, 0.03),
    "3x64": (1.27, 0.26),
    "3x128": (1.43, 0.60),
    "4x32": (1.15, 0.56),
    "4x64": (0.92, 0.77),
    "4x128": (1.14, 0.19),
}
"""Table 2: mean ± SD validation error per architecture (5 repeats, NVIDIA V100)."""

TABLE2_TRAINING_S: dict[str, tuple[float, float]] = {
    "2x32": (2663.0, 110.0),
    "2x64": (2632.0, 98.0),
    "2x128": (2715.0, 105.0),
    "3x32": (3155.0, 60.0),
    "3x64": (1171.0, 168.0),
    "3x128": (1414.0, 982.0),
    "4x32": (1842.0, 1051.0),
    "4x64": (2420.0, 1175.0),
    "4x128": (1390.0, 164.0),
}
"""Table 2: mean ± SD training time per architecture, seconds."""

CLINICAL_CASES: tuple[tuple[float, float], ...] = ((1.0, 180.0), (5.0, 180.0), (1.0, 0.0), (5.0, 0.0))

TABLE3_FE: dict[tuple[float, float], dict[str, float]] = {
    (1.0, 180.0): {"mean_mm": 3.21, "max_mm": 37.2},
    (5.0, 180.0): {"mean_mm": 0.62, "max_mm": 7.2},
    (1.0, 0.0): {"mean_mm": 3.16, "max_mm": 38.4},
    (5.0, 0.0): {"mean_mm": 0.62, "max_mm": 7.3},
}
"""Table 3, FE rows: mean displacement and the top of the displacement range [0, max]."""

TABLE3_SURROGATE: dict[tuple[float, float], dict[str, float]] = {
    (1.0, 180.0): {"mean_mm": 3.0, "rmse_mm": 0.70, "sd_mm": 0.68, "min_mm": 0.01, "max_mm": 35.7},
    (5.0, 180.0): {"mean_mm": 0.58, "rmse_mm": 0.19, "sd_mm": 0.18, "min_mm": 0.01, "max_mm": 7.3},
    (1.0, 0.0): {"mean_mm": 2.6, "rmse_mm": 1.04, "sd_mm": 1.08, "min_mm": 0.00, "max_mm": 36.2},
    (5.0, 0.0): {"mean_mm": 0.42, "rmse_mm": 0.30, "sd_mm": 0.29, "min_mm": 0.01, "max_mm": 6.7},
}
"""Table 3, surrogate rows: mean displacement, 'RMSE' ± SD (their Eq. 3), range."""

TABLE4_S: dict[tuple[float, float], dict[str, tuple[float, float]]] = {
    (1.0, 180.0): {"fe": (154.0, 11.0), "surrogate": (2.40, 0.02)},
    (5.0, 180.0): {"fe": (80.0, 1.7), "surrogate": (2.36, 0.02)},
    (1.0, 0.0): {"fe": (152.0, 4.0), "surrogate": (2.37, 0.02)},
    (5.0, 0.0): {"fe": (82.6, 1.6), "surrogate": (2.37, 0.02)},
}
"""Table 4: mean ± SD wall-clock time of one solve / one prediction (Intel i7, 2.3 GHz)."""

N_CASES = 688
N_POINTS = 3545
CLINICALLY_ACCEPTED_MM = 5.0
"""Error range the paper cites as clinically accepted (its §4)."""
