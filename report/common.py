"""What several sections share: the needs and ranges they judge by, names, and small measures."""

from __future__ import annotations

import re
from collections.abc import Sequence
from typing import Any

from report.html import finite
from studies.fe_study.fe_timing import TimedSolve
from studies.figures import fe as fem_plots
from studies.surrogate_study.architecture import RunSummary
from studies.surrogate_study.surrogate_benchmark import SurrogateBenchmark

#: Accuracy needs (mm) of the "model no more than a scene needs" section; the paper's
#: clinically accepted error is 5 mm.
NEEDS_MM = (0.5, 1.0, 5.0)


#: The paper's C1 range (kPa).
PAPER_C1_RANGE = (0.8, 5.0)


TARGET_NAMES = {
    "median_wall_s": "median wall time per case (s)",
    "factorization_equivalents": "factorisation equivalents (largest over the cases)",
    "relative_max_error": "max |u − u_ref| / max |u_ref| (%, largest over the cases)",
}


GOAL_NAMES = {
    "validation_error_mm": "best validation error (mm)",
    "worst_clinical_rmse_mm": "worst clinical-case error, Eq. 3 (mm, by-sample)",
    "worst_clinical_relative_rmse": "worst clinical-case error / max |u| (by-sample)",
    "predict_one_core_ms": "one whole-field prediction on one core (ms)",
    "train_3x32_s": "training a 3x32 network (s)",
}


COST_LABELS = {
    "median_cpu_s": "median CPU time per clinical case (s)",
    "median_wall_s": "median wall time per clinical case (s)",
}


_VARIANT_ID = re.compile(
    r"g=(?P<g>[0-9.]+)_m=(?P<m>[0-9.]+)(?:_f=(?P<f>[0-9.]+))?_o=(?P<o>[12])_el=(?P<el>[a-z0-9-]+)"
    r"_solver=(?P<solver>[a-z-]+)_q=(?P<q>[0-9]+)$"
)


def variant_label(variant_id: str) -> str:
    """A short, readable name of an FE study variant, e.g. ``P2/P1, h 15/10 mm, direct``.

    With elements of 4 mm over the fold the sizes read ``h 15/10/4 mm``.
    """
    match = _VARIANT_ID.match(str(variant_id))
    if match is None:
        return str(variant_id)
    g, m = 1e3 * float(match["g"]), 1e3 * float(match["m"])
    sizes = f"{g:.3g}/{m:.3g}" + (f"/{1e3 * float(match['f']):.3g}" if match["f"] else "")
    label = f"{fem_plots.ELEMENT_NAMES.get(match['el'], match['el'])}, h {sizes} mm"
    if match["o"] == "2":
        label += " curved"
    label += f", {match['solver']}"
    if match["q"] != "0":
        label += f", q = {match['q']}"
    return label


def worst_case(cases: Sequence[TimedSolve], key: str) -> float | None:
    """The largest ``accuracy.<key>`` over the cases, or None unless every case has one."""
    values = [getattr(c.accuracy, key) if c.accuracy is not None else None for c in cases]
    if not values or not all(finite(v) for v in values):
        return None
    return float(max(values))


def meets(error: Any, target: Any) -> bool:
    """Whether ``error`` is at most ``target`` (both finite)."""
    return finite(error) and finite(target) and error <= target


def predict_s(timed: RunSummary | SurrogateBenchmark | None) -> float | None:
    """Seconds of one whole-field prediction on one core (the API's median), or None."""
    timing = timed.predict_one_core if timed is not None else None
    ms = ((timing or {}).get("api") or {}).get("median_ms")
    return 1e-3 * ms if finite(ms) else None
