"""The stiffness C1 from a second observation of the skin: surrogate search, FE confirmation.

A second shape of the same breast in another posture (a surface scan supine, a point cloud) fixes
C1: the reference is loaded in that posture at trial values of C1, and the misfit is the
observed points' distance from the predicted skin. The misfit is

    S(C1) = Σᵢ dᵢ(C1)²,   dᵢ = distance of point i from the predicted skin surface,

the least-squares objective of points scattered about the skin with independent normal noise.

1. **Search** (the surrogate, milliseconds per trial): S over a log-spaced grid of the model's
   trained C1 range, then refined by a bounded scalar minimisation about the grid's best.
2. **Confirm** (FE): the posture is solved at the surrogate's optimum; about it the displacement
   scales as 1/C1 (linear in the compliance), so S is minimised over u_FE(c) · c/C1, and the FE
   solve repeated at that minimiser (warm-started from the last) until it moves less than
   ``tolerance``. The estimate is then FE's, not the surrogate's.
3. **Interval**: the likelihood-ratio interval of the least-squares fit, the C1 where
   S(C1) − S_min ≤ χ²₁(confidence) · σ̂², with σ̂² = S_min / (n − 1) the noise estimated from
   the residual; on the confirmed (FE-based) curve.

The search and confirmation take callables that give node positions in the mesh file's order,
so that the same code runs with any model; :func:`surrogate_shape` and :func:`fe_shape` build
them from a model and from an FE runner.
"""

from __future__ import annotations

import logging
import math
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from meshes.surface import distance_to_surface

log = logging.getLogger(__name__)

#: The largest RMS distance (mm) of the observed points from the best predicted skin for the
#: observation to count as this breast's skin (an observation in other units or axes is far off).
MAX_RMS_MM = 5.0
#: The observed points' extent over the skin's must lie within these factors.
EXTENT_RATIO = (0.3, 2.0)

#: Shapes: C1 (kPa) → (N, 3) node positions in the mesh file's order, m.
Shape = Callable[[float], np.ndarray]


class StiffnessError(ValueError):
    """An observation or a setting from which no stiffness can be estimated."""


@dataclass(frozen=True)
class StiffnessEstimate:
    """C1 from a second observation.

    Attributes:
        C1_kPa: the estimate (FE-confirmed).
        interval_kPa: the likelihood-ratio interval at ``confidence``.
        confidence: its level.
        surrogate_C1_kPa: the surrogate search's optimum.
        rms_mm: the observed points' RMS distance from the skin predicted at the estimate.
        points: observed points used.
        curve_C1_kPa: the surrogate's search grid.
        curve_rms_mm: the RMS misfit at each grid value (the surrogate's curve).
        fe_C1_kPa: the C1 of each FE confirmation solve.
        fe_rms_mm: the RMS misfit of each FE solve.
        converged: the confirmation settled within its solves.
        search_s: wall time of the surrogate search.
        confirm_s: wall time of the FE confirmation.
    """

    C1_kPa: float
    interval_kPa: tuple[float, float]
    confidence: float
    surrogate_C1_kPa: float
    rms_mm: float
    points: int
    curve_C1_kPa: list[float] = field(default_factory=list)
    curve_rms_mm: list[float] = field(default_factory=list)
    fe_C1_kPa: list[float] = field(default_factory=list)
    fe_rms_mm: list[float] = field(default_factory=list)
    converged: bool = True
    search_s: float = 0.0
    confirm_s: float = 0.0

    @property
    def wall_s(self) -> float:
        """The whole estimate's wall time."""
        return self.search_s + self.confirm_s


def misfit(observed: np.ndarray, nodes: np.ndarray, triangles: np.ndarray) -> float:
    """S: the sum of the observed points' squared distances from the surface (m²)."""
    d = distance_to_surface(observed, nodes, triangles)
    return float(d @ d)


def surrogate_shape(model: Any, X_file: np.ndarray, phi: float, theta: float = 0.0) -> Shape:
    """Node positions predicted by ``model`` for the posture (Φ, θ), as a function of C1.

    Args:
        model: a :class:`surrogate.predict.Surrogate` trained on the mesh whose reference node
            positions, in file order, are ``X_file``.
        X_file: (N, 3) reference positions (m) in the mesh file's order.
        phi: the posture's Φ, degrees.
        theta: the posture's θ, degrees.
    """
    index = np.asarray(model.node_index, dtype=np.int64)

    def shape(c1: float) -> np.ndarray:
        nodes = X_file.copy()
        nodes[index] += 1e-3 * model.predict(c1, phi, theta)
        return nodes

    return shape


def fe_shape(runner: Any, phi: float, theta: float = 0.0) -> Shape:
    """Node positions of FE solves of the posture (Φ, θ) on ``runner``'s mesh, by C1.

    Each solve after the first starts from the previous solution scaled by the ratio of the
    stiffnesses (the displacement scales nearly as 1/C1), falling back to the load path.

    Raises:
        StiffnessError: if a solve does not converge.
    """
    from fem.io import node_displacement
    from fem.parameters import Gravity, Material
    from meshes.io import nodes_in_file_order

    problem, settings = runner.problem, runner.settings
    X = runner.mesh.geometry.x.copy()
    gravity = Gravity(phi=phi, theta=theta, unit="deg", magnitude=settings.gravity)
    last: dict[str, Any] = {}

    def shape(c1: float) -> np.ndarray:
        # C1 exactly as asked: a sweep Case rounds it to its folder name's 0.01 kPa, which is
        # coarser than the confirmation's tolerance, and two nearby solves would be one
        guess = None
        if last:
            guess = last["w"] * (last["c1"] / c1)
        ok, _, _ = runner.solve_from(Material(C1=c1 * 1e3, density=settings.density), gravity,
                                     guess)
        if not ok:
            raise StiffnessError(f"the FE solve at C1 = {c1:.4g} kPa, Φ = {phi:g}° did not "
                                 "converge")
        last.update(w=problem.w.x.array.copy(), c1=c1)
        return nodes_in_file_order(runner.mesh, X + node_displacement(problem))

    return shape


def _local_shape(fields: list[tuple[float, np.ndarray]], reference: np.ndarray,
                 observed: np.ndarray, triangles: np.ndarray) -> Callable[[float], float]:
    """The misfit about the FE solves, from their displacements, as a function of C1.

    One solve: its displacement scaled as 1/C1. Two: interpolated linearly in the compliance
    1/C1 between them (a secant in the field), exact at both.
    """
    if len(fields) == 1:
        (c, u), = fields

        def shape(t: float) -> float:
            return misfit(observed, reference + u * (c / t), triangles)
    else:
        (ca, ua), (cb, ub) = fields

        def shape(t: float) -> float:
            w = (1.0 / t - 1.0 / ca) / (1.0 / cb - 1.0 / ca)
            return misfit(observed, reference + ua + w * (ub - ua), triangles)

    return shape


def _check_plausible(observed: np.ndarray, skin: np.ndarray) -> None:
    """Refuse an observation whose size is not the skin's (other units).

    Raises:
        StiffnessError: naming the ratio of the extents.
    """
    size = float(np.linalg.norm(np.ptp(observed, axis=0)))
    expected = float(np.linalg.norm(np.ptp(skin, axis=0)))
    ratio = size / expected
    if not EXTENT_RATIO[0] <= ratio <= EXTENT_RATIO[1]:
        raise StiffnessError(
            f"the observation spans {1e3 * size:.4g} mm, {ratio:.3g} times the skin's "
            f"{1e3 * expected:.4g} mm: are its units those declared?"
        )


def _chi2_1(confidence: float) -> float:
    """The χ² quantile with one degree of freedom: the square of the normal quantile."""
    from scipy.stats import norm

    return float(norm.ppf(0.5 + confidence / 2.0) ** 2)


def _interval(curve: Callable[[float], float], best: float, s_min: float, threshold: float,
              lo: float, hi: float) -> tuple[float, float]:
    """Where curve(c) − s_min ≤ threshold about ``best``, within [lo, hi] (bisection in log C1)."""

    def edge(outer: float) -> float:
        if curve(outer) - s_min <= threshold:
            return outer
        a, b = math.log(best), math.log(outer)
        for _ in range(40):
            m = 0.5 * (a + b)
            if curve(math.exp(m)) - s_min <= threshold:
                a = m
            else:
                b = m
        return math.exp(0.5 * (a + b))

    return edge(lo), edge(hi)


def estimate_stiffness(
    observed: np.ndarray,
    triangles: np.ndarray,
    reference: np.ndarray,
    search: Shape,
    confirm: Shape | None,
    c1_range: tuple[float, float],
    grid: int = 41,
    confidence: float = 0.95,
    tolerance: float = 0.002,
    max_fe_solves: int = 5,
) -> StiffnessEstimate:
    """Estimate C1 from observed skin points (see the module's description).

    Args:
        observed: (n, 3) points on the skin in the second posture, m, project frame.
        triangles: (T, 3) the skin's triangles, as node indices in file order.
        reference: (N, 3) the reference node positions in file order, m.
        search: the fast shape (the surrogate's).
        confirm: the FE shape, or None to report the surrogate's estimate alone.
        c1_range: the C1 range searched (kPa), the surrogate's trained range.
        grid: grid values of the search.
        confidence: level of the interval.
        tolerance: relative change of C1 below which the FE confirmation stops.
        max_fe_solves: FE solves allowed.

    Raises:
        StiffnessError: for fewer than 10 observed points, non-finite points or a bad range.
    """
    from scipy.optimize import minimize_scalar

    observed = np.asarray(observed, dtype=float)
    if observed.ndim != 2 or observed.shape[1] != 3 or len(observed) < 10:
        raise StiffnessError(f"the observation needs at least 10 points (n, 3), got "
                             f"{observed.shape}")
    if not np.all(np.isfinite(observed)):
        raise StiffnessError("the observation has non-finite coordinates")
    lo, hi = (float(v) for v in c1_range)
    if not 0 < lo < hi:
        raise StiffnessError(f"the C1 range {c1_range} must be increasing and positive")
    n = len(observed)
    _check_plausible(observed, reference[np.unique(triangles)])

    start = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the search stays inside the trained range

        def s_search(c: float) -> float:
            return misfit(observed, search(c), triangles)

        cs = np.geomspace(lo, hi, grid)
        curve = np.array([s_search(c) for c in cs])
        i = int(np.argmin(curve))
        a, b = math.log(cs[max(i - 1, 0)]), math.log(cs[min(i + 1, grid - 1)])
        found = minimize_scalar(lambda t: s_search(math.exp(t)), bounds=(a, b),
                                method="bounded", options={"xatol": 1e-4})
    c_surrogate = float(math.exp(found.x))
    search_s = time.perf_counter() - start
    rms_mm = 1e3 * math.sqrt(found.fun / n)
    if rms_mm > MAX_RMS_MM:
        raise StiffnessError(
            f"the observed points lie {rms_mm:.1f} mm (RMS) from the closest predicted skin "
            f"(C1 = {c_surrogate:.3g} kPa): they are not this breast's skin in this posture; "
            "check their units, axes and the posture (Φ, θ)"
        )
    log.info("surrogate search: C1 = %.4g kPa (%d trials, %.2f s)", c_surrogate,
             grid + found.nfev, search_s)

    start = time.perf_counter()
    fe_c, fe_s = [], []
    estimate, converged, local = c_surrogate, confirm is None, None
    if confirm is not None:
        c = c_surrogate
        fields: list[tuple[float, np.ndarray]] = []
        for _ in range(max_fe_solves):
            nodes = confirm(c)
            fe_c.append(c)
            fe_s.append(misfit(observed, nodes, triangles))
            fields.append((c, nodes - reference))
            local = _local_shape(fields[-2:], reference, observed, triangles)
            step = minimize_scalar(lambda s, f=local: f(math.exp(s)),
                                   bounds=(math.log(c) - 0.3, math.log(c) + 0.3),
                                   method="bounded", options={"xatol": 1e-5})
            estimate = float(math.exp(step.x))
            log.info("FE at C1 = %.4g kPa: RMS %.3f mm; local minimum at %.4g kPa", c,
                     1e3 * math.sqrt(fe_s[-1] / n), estimate)
            if abs(estimate / c - 1.0) <= tolerance:
                converged = True
                break
            c = estimate
    confirm_s = time.perf_counter() - start

    if local is None:
        def local(t: float) -> float:
            return misfit(observed, search(t), triangles)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the surrogate's curve a little beyond its range
        s_min = local(estimate)
        threshold = _chi2_1(confidence) * s_min / (n - 1)
        interval = _interval(local, estimate, s_min, threshold, estimate / 1.5, estimate * 1.5)
    return StiffnessEstimate(
        C1_kPa=estimate, interval_kPa=interval, confidence=confidence,
        surrogate_C1_kPa=c_surrogate, rms_mm=1e3 * math.sqrt(s_min / n), points=n,
        curve_C1_kPa=cs.tolist(), curve_rms_mm=(1e3 * np.sqrt(curve / n)).tolist(),
        fe_C1_kPa=fe_c, fe_rms_mm=[1e3 * math.sqrt(s / n) for s in fe_s],
        converged=converged, search_s=search_s, confirm_s=confirm_s,
    )


__all__ = [
    "Shape", "StiffnessError", "StiffnessEstimate", "estimate_stiffness", "fe_shape", "misfit",
    "surrogate_shape",
]
