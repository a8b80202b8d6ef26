"""The adaptive sweep: FE cases solved where the field is least known, round by round.

With C1 in every term of the potential, a case's equilibrium depends on ρg/C1 alone
(:mod:`fem.chain`): the cases of the sweep are points of one three-dimensional *load space*,
x = ĝ / C1 (1/kPa), and the displacement field is one function u(x), linear in x for small
loads. A softer case lies farther out along its direction, so the soft end, where the field is
largest and changes fastest, takes up most of the space: a design even in x puts its cases
where the error is.

**The estimate** (:class:`LoadSpaceInterpolant`, :func:`committee`): the solved fields are
interpolated in x by a cubic radial basis function with a linear tail (exact for a field linear
in x, the small-deformation limit), as :mod:`benchmarks.direction_spacing_error` does in
direction alone at one C1, and by a linear one (φ(r) = r, the same tail). Both pass through
every solved case; between the cases they part where the field bends faster than the cases are
spaced, and the *committee* estimate is the largest point distance between them. It vanishes at
a solved case and grows in the holes between cases. Two other estimates are kept beside it for
the check: each case's leave-one-out error (the largest point error of the cubic interpolant
built without it, for every case at once from one inverse by Rippa's formula, e_k = c_k /
(A⁻¹)ₖₖ) and the *jackknife* J(x) = maxₖ |L_k(x)|·‖e_k‖ (removing case k changes the interpolant
at x by e_k·L_k(x), its cardinal function). Measured at FE cases left out, the committee ranked
the true error best at the soft end, where the rounds add their cases (docs/sweep.md); the
workflow checks it again at every run against the surrogate's true error
(:mod:`studies.sweep.sweep_estimate`).

**A round** (:func:`plan_round`): the estimate over a pool of candidate directions (a lattice
of the design's part of the sphere and steps along its plane) at every C1 level; the round
adds the candidates of largest estimate, greedily, each counted as solved (its cases join both
interpolants with the cubic one's fields) before the next is chosen, so that a round spreads
over the holes rather than crowding one. A new direction is solved at every C1 level as one
chain (stiffest first), its cases neighbours of each other on one load path. Where the
nearest case already tried at a level failed to converge, that level is not scored: the FE
has no solution there to add. The sweep stops when the estimate's largest value over the pool
is under the target, or when its case budget or its rounds are spent.
"""

from __future__ import annotations

import json
import logging
import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from fem.directions import gravity_angles, gravity_direction
from fem.exceptions import InvalidParameterError
from fem.sweep import Case

log = logging.getLogger(__name__)

SEPARATION_DEG = 5.0
"""A candidate direction closer than this to a direction already tried is not added."""
PLANE_STEP_DEG = 2.5
"""The candidates' step along the design's plane."""
NEIGHBOURHOOD_DEG = 40.0
"""Within a round, a chosen direction's cases count as solved for the estimate within this
angle of it (farther, their effect on the interpolants is left out)."""


@dataclass(frozen=True, slots=True)
class AdaptiveSettings:
    """``sweep.adaptive``: when the rounds stop and how many cases each adds.

    Attributes:
        target_mm: stop when the estimated worst-point error over the range is below this.
        max_cases: the most cases the sweep solves, its start included.
        per_round: the most directions a round adds (each solved at every C1 level).
        max_rounds: the most rounds after the start.
        candidates: directions in the candidate lattice over the design's part of the sphere.
    """

    target_mm: float = 0.5
    max_cases: int = 600
    per_round: int = 12
    max_rounds: int = 8
    candidates: int = 600

    @classmethod
    def from_mapping(cls, section: Mapping[str, Any]) -> AdaptiveSettings:
        """From the config's ``sweep.adaptive`` (defaults filled by the schema).

        Raises:
            InvalidParameterError: for a target that is not positive, or counts below one.
        """
        settings = cls(**{k: section[k] for k in cls.__dataclass_fields__ if k in section})
        if not (math.isfinite(settings.target_mm) and settings.target_mm > 0):
            raise InvalidParameterError(
                f"sweep.adaptive.target_mm must be a positive number of mm, got "
                f"{settings.target_mm!r}")
        for name in ("max_cases", "per_round", "max_rounds", "candidates"):
            if int(getattr(settings, name)) < 1:
                raise InvalidParameterError(f"sweep.adaptive.{name} must be at least 1")
        return settings


def load_points(C1: np.ndarray, phi: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """The cases' points x = ĝ / C1 (1/kPa) of the load space, shape (M, 3)."""
    return gravity_direction(np.asarray(phi, float), np.asarray(theta, float)) / np.asarray(
        C1, float)[:, None]


def _tail_axes(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The origin and axes (K, 3) of the affine span of the points ``x``: the linear tail's.

    A design in one plane (the paper's, θ = 0) has its load points in that plane; a tail in
    all three coordinates would make the interpolant's matrix singular.
    """
    origin = x.mean(axis=0)
    _, singular, axes = np.linalg.svd(x - origin, full_matrices=False)
    return origin, axes[singular > 1e-9 * singular[0]]


def _basis(y: np.ndarray, x: np.ndarray, power: int, origin: np.ndarray,
           axes: np.ndarray) -> np.ndarray:
    """Rows [φ(|y − x_j|)_j, 1, y in the tail's axes] at points ``y`` (Q, 3), φ(r) = rᵖ."""
    r = np.linalg.norm(y[:, None, :] - x[None, :, :], axis=2)
    return np.hstack([r**power, np.ones((len(y), 1)), (y - origin) @ axes.T])


class LoadSpaceInterpolant:
    """The solved fields as a cubic RBF with a linear tail in the load space (the module).

    Args:
        x: the cases' load points (M, 3), distinct (in one plane, or on one line, the tail
            is linear within it).
        fields: their displacement fields (M, N, 3), mm.
        loo_mm: each case's leave-one-out error to use instead of computing it (a case counted
            as solved before it is, :func:`plan_round`, has 0).
        power: the radial function rᵖ: 3 (cubic, the default) or 1 (linear, a cruder
            interpolant that a committee sets beside it).
    """

    def __init__(self, x: np.ndarray, fields: np.ndarray | None,
                 loo_mm: np.ndarray | None = None, power: int = 3) -> None:
        if power not in (1, 3):
            raise InvalidParameterError(f"the radial function is r or r³, not r^{power}")
        self.power = power
        self.x = np.asarray(x, dtype=float)
        m = len(self.x)
        if m < 5:
            raise InvalidParameterError(f"the load-space interpolant needs five cases, got {m}")
        self.origin, self.axes = _tail_axes(self.x)
        tail = np.hstack([np.ones((m, 1)), (self.x - self.origin) @ self.axes.T])
        matrix = np.zeros((m + tail.shape[1], m + tail.shape[1]))
        matrix[:m, :m] = np.linalg.norm(self.x[:, None] - self.x[None], axis=2) ** power
        matrix[:m, m:], matrix[m:, :m] = tail, tail.T
        self.inverse = np.linalg.inv(matrix)
        self.fields = fields
        if loo_mm is not None:
            self.loo_mm = np.asarray(loo_mm, dtype=float)
            return
        flat = np.asarray(fields, dtype=float).reshape(m, -1)
        coefficients = self.inverse[:m, :m] @ flat  # the tail's rows of [f; 0] are zero
        errors = coefficients / np.diag(self.inverse)[:m, None]
        self.loo_mm = np.linalg.norm(errors.reshape(m, -1, 3), axis=2).max(axis=1)

    def cardinal(self, y: np.ndarray) -> np.ndarray:
        """Each case's cardinal function at points ``y`` (Q, 3): shape (Q, M)."""
        return _basis(np.atleast_2d(y), self.x, self.power, self.origin,
                      self.axes) @ self.inverse[:, : len(self.x)]

    def predict(self, y: np.ndarray) -> np.ndarray:
        """The interpolated field at points ``y`` (Q, 3): shape (Q, N, 3), mm."""
        if self.fields is None:
            raise InvalidParameterError("this interpolant was built without fields")
        m = len(self.x)
        flat = self.cardinal(y) @ np.asarray(self.fields, dtype=float).reshape(m, -1)
        return flat.reshape(len(flat), -1, 3)

    def jackknife(self, y: np.ndarray, chunk: int = 2048) -> np.ndarray:
        """The estimate J(y) = maxₖ |L_k(y)|·‖e_k‖ at points ``y`` (Q, 3), mm (the module)."""
        y = np.atleast_2d(y)
        return np.concatenate([np.max(np.abs(self.cardinal(y[i:i + chunk])) * self.loo_mm,
                                      axis=1) for i in range(0, len(y), chunk)])

    def nearest(self, y: np.ndarray) -> np.ndarray:
        """The leave-one-out error of the case nearest each point ``y`` in the load space."""
        y = np.atleast_2d(y)
        distance = np.linalg.norm(y[:, None, :] - self.x[None], axis=2)
        return self.loo_mm[np.argmin(distance, axis=1)]


@dataclass(frozen=True, slots=True)
class Domain:
    """The directions a design covers: a stretch of the paper's plane and a part of the sphere.

    Attributes:
        plane: (Φ min, Φ max) of the plane θ = 0 it covers (degrees), or None.
        part: ``whole`` or ``caudal`` (:data:`fem.sweep.SPHERE_PARTS`), or None for the plane
            alone.
    """

    plane: tuple[float, float] | None
    part: str | None

    @classmethod
    def of_sweep(cls, sweep: Mapping[str, Any], start: Sequence[Case]) -> Domain:
        """The domain a ``sweep`` section's start design spans."""
        plane = sorted(c.phi for c in start if c.theta == 0.0) if sweep.get("phi_deg") else []
        sphere = sweep.get("sphere") or {}
        return cls((plane[0], plane[-1]) if plane else None,
                   sphere.get("part", "whole") if sphere else None)

    def candidates(self, n: int) -> np.ndarray:
        """Unit directions (Q, 3) over the domain.

        A lattice of ``n`` over its part of the sphere, and steps of :data:`PLANE_STEP_DEG`
        along its plane.
        """
        from fem.sweep import sphere_directions

        pairs: list[tuple[float, float]] = []
        if self.part is not None:
            pairs += sphere_directions(n, self.part)
        if self.plane is not None:
            lo, hi = self.plane
            count = max(2, int(round((hi - lo) / PLANE_STEP_DEG)) + 1)
            pairs += [(float(p), 0.0) for p in np.linspace(lo, hi, count)]
        angles = np.array(pairs, dtype=float)
        return gravity_direction(angles[:, 0], angles[:, 1])


@dataclass(frozen=True)
class AdaptiveDesign:
    """An adaptive sweep: its start design, its C1 levels, its domain and its settings.

    Attributes:
        start: the start design's cases (:func:`fem.sweep.sweep_cases`).
        levels: the C1 values (kPa) every direction is solved at, stiffest first.
        domain: the directions the start design spans, where the rounds add theirs.
        settings: ``sweep.adaptive``.
    """

    start: tuple[Case, ...]
    levels: tuple[float, ...]
    domain: Domain
    settings: AdaptiveSettings

    @classmethod
    def from_sweep(cls, sweep: Mapping[str, Any]) -> AdaptiveDesign | None:
        """The design of a ``sweep`` section (its preset written out), or None if fixed.

        A fixed design is one without ``adaptive`` (or with it null).

        Raises:
            InvalidParameterError: as :func:`fem.sweep.sweep_cases` and
                :meth:`AdaptiveSettings.from_mapping`.
        """
        from fem.sweep import resolve_sweep, sweep_cases

        sweep = resolve_sweep(dict(sweep))
        if sweep.get("adaptive") is None:
            return None
        start = tuple(sweep_cases(sweep))
        settings = AdaptiveSettings.from_mapping(sweep["adaptive"])
        levels = tuple(sorted({c.C1 for c in start}, reverse=True))
        if len(start) > settings.max_cases:
            raise InvalidParameterError(
                f"sweep.adaptive.max_cases = {settings.max_cases} is fewer than the start "
                f"design's {len(start)} cases: raise it, or start from fewer directions")
        return cls(start, levels, Domain.of_sweep(sweep, start), settings)

    def plan(self, cases: Sequence[Case], converged: np.ndarray, fields: np.ndarray,
             round_number: int, reserved: Sequence[tuple[float, float]] = ()) -> RoundPlan:
        """:func:`plan_round` of this design."""
        return plan_round(self.settings, self.levels, self.domain, cases, converged, fields,
                          round_number, reserved)


def direction_angles(g: np.ndarray) -> tuple[float, float]:
    """(Φ, θ) of the unit direction ``g`` to the case folder's 0.1° (the plane's as (Φ, 0))."""
    phi, theta = (round(a, 1) + 0.0 for a in gravity_angles(g))
    return (180.0 if phi == -180.0 else phi), theta


@dataclass(frozen=True)
class RoundPlan:
    """One round of the adaptive sweep: what the cases so far say, and what it adds.

    Attributes:
        round: 1 for the first round after the start design.
        cases_before: cases tried before the round (converged or not).
        converged_before: of them, converged (those the estimate is built on).
        estimate_mm: the estimate's largest value over the candidates, before the round.
        worst: (C1, Φ, θ) of that candidate.
        median_loo_mm, max_loo_mm: the solved cases' leave-one-out errors.
        directions: the directions the round adds, (Φ, θ) degrees, each at every C1 level.
        cases: their case folders.
        done: whether the sweep ends here (``cases`` is then empty).
        reason: why it ends, or ``adding``.
    """

    round: int
    cases_before: int
    converged_before: int
    estimate_mm: float
    worst: tuple[float, float, float]
    median_loo_mm: float
    max_loo_mm: float
    directions: list[tuple[float, float]] = field(default_factory=list)
    cases: list[str] = field(default_factory=list)
    done: bool = False
    reason: str = "adding"

    def write(self, path: str | Path) -> None:
        """As JSON (written whole, then renamed: a killed planner leaves no half plan)."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        part = path.with_name(path.name + ".part")
        part.write_text(json.dumps(asdict(self), indent=1) + "\n")
        part.replace(path)

    @classmethod
    def read(cls, path: str | Path) -> RoundPlan:
        """A plan written by :meth:`write`."""
        data = json.loads(Path(path).read_text())
        data["worst"] = tuple(data["worst"])
        data["directions"] = [tuple(d) for d in data["directions"]]
        return cls(**data)

    def new_cases(self) -> list[Case]:
        """The cases the round adds."""
        return [Case.from_id(c) for c in self.cases]


def plan_round(settings: AdaptiveSettings, levels: Sequence[float], domain: Domain,
               cases: Sequence[Case], converged: np.ndarray, fields: np.ndarray,
               round_number: int, reserved: Sequence[tuple[float, float]] = ()) -> RoundPlan:
    """The next round of the sweep, from every case tried so far (the module).

    Args:
        settings: the sweep's ``adaptive`` settings.
        levels: the C1 values (kPa) every direction is solved at.
        domain: the directions the sweep covers.
        cases: every case tried so far (the start design and the rounds before).
        converged: whether each converged (and does not pass through itself).
        fields: their displacement fields (M, N, 3), mm (rows of failed cases are ignored).
        round_number: 1 for the first round.
        reserved: directions (Φ, θ) the rounds keep out of the sweep (within
            :data:`SEPARATION_DEG`): those whose FE cases test the surrogate at directions it
            never saw (``surrogate_study.extrapolation``).
    """
    converged = np.asarray(converged, dtype=bool)
    c1 = np.array([c.C1 for c in cases])
    phi, theta = np.array([c.phi for c in cases]), np.array([c.theta for c in cases])
    x_all = load_points(c1, phi, theta)
    fields = np.asarray(fields)[converged]
    interpolant = LoadSpaceInterpolant(x_all[converged], fields)
    linear = LoadSpaceInterpolant(x_all[converged], fields, power=1)
    levels = np.array(sorted(levels, reverse=True), dtype=float)
    pool = domain.candidates(settings.candidates)
    tried = gravity_direction(phi, theta)
    if len(reserved):
        kept = np.array(reserved, dtype=float).reshape(-1, 2)
        tried = np.vstack([tried, gravity_direction(kept[:, 0], kept[:, 1])])
    # a candidate beside a direction already tried adds nothing new
    apart = np.max(pool @ np.unique(np.round(tried, 9), axis=0).T, axis=1) < math.cos(
        math.radians(SEPARATION_DEG))
    y = (pool[:, None, :] / levels[None, :, None]).reshape(-1, 3)
    scored = _scored(y, x_all, converged)
    cubic_at = interpolant.predict(y)
    estimate = np.where(scored, committee(cubic_at, linear, y), 0.0).reshape(len(pool),
                                                                             len(levels))
    worst = np.unravel_index(int(np.argmax(estimate)), estimate.shape)
    plan = dict(round=round_number, cases_before=len(cases),
                converged_before=int(converged.sum()), estimate_mm=float(estimate.max()),
                worst=(float(levels[worst[1]]), *direction_angles(pool[worst[0]])),
                median_loo_mm=float(np.median(interpolant.loo_mm)),
                max_loo_mm=float(interpolant.loo_mm.max()))
    log.info("round %d: %d cases tried, %d converged; leave-one-out error median %.3f, largest "
             "%.3f mm; estimated worst-point error %.3f mm at C1 %.2f kPa, (%.1f, %.1f)",
             round_number, len(cases), plan["converged_before"], plan["median_loo_mm"],
             plan["max_loo_mm"], plan["estimate_mm"], *plan["worst"])
    room = (settings.max_cases - len(cases)) // len(levels)
    reason = ("target met" if plan["estimate_mm"] < settings.target_mm
              else "rounds spent" if round_number > settings.max_rounds
              else "budget spent" if room < 1 else None)
    if reason is not None:
        log.info("round %d: the sweep is done (%s)", round_number, reason)
        return RoundPlan(**plan, done=True, reason=reason)
    chosen = _greedy(interpolant, linear, cubic_at, pool, levels, estimate, apart, scored,
                     min(settings.per_round, room), settings.target_mm)
    if not chosen:
        return RoundPlan(**plan, done=True, reason="no candidate left")
    directions = [direction_angles(pool[i]) for i in chosen]
    log.info("round %d adds %d directions at %d C1 values: %s", round_number, len(directions),
             len(levels), directions)
    new = sorted({Case(level, *d) for level in levels for d in directions})
    return RoundPlan(**plan, directions=directions, cases=[c.id for c in new])


def _scored(y: np.ndarray, x_all: np.ndarray, converged: np.ndarray) -> np.ndarray:
    """Whether each candidate point is scored: its nearest tried case converged.

    Where that case failed, the FE has no solution there to add.
    """
    nearest = np.argmin(np.linalg.norm(y[:, None, :] - x_all[None], axis=2), axis=1)
    return converged[nearest]


def committee(cubic_at: np.ndarray, linear: LoadSpaceInterpolant, y: np.ndarray,
              chunk: int = 1024) -> np.ndarray:
    """The committee estimate at points ``y`` (Q, 3), mm.

    The largest point distance between the cubic interpolant's fields there, ``cubic_at``
    (Q, N, 3), and the linear one's.
    """
    return np.concatenate([
        np.linalg.norm(cubic_at[i:i + chunk] - linear.predict(y[i:i + chunk]), axis=2).max(1)
        for i in range(0, len(y), chunk)])


def _greedy(cubic: LoadSpaceInterpolant, linear: LoadSpaceInterpolant, cubic_at: np.ndarray,
            pool: np.ndarray, levels: np.ndarray, estimate: np.ndarray, apart: np.ndarray,
            scored: np.ndarray, k: int, target_mm: float) -> list[int]:
    """Up to ``k`` candidates, each the largest estimate once those before it count as solved.

    A chosen candidate's cases join both interpolants with the cubic one's fields there: the
    cubic interpolant is unchanged by them, and the linear one comes closer to it around them.
    """
    chosen: list[int] = []
    x, f = linear.x, np.asarray(linear.fields)
    y = (pool[:, None, :] / levels[None, :, None]).reshape(-1, 3)
    flat = estimate.reshape(-1).copy()  # each candidate at each level, taken again near a choice
    score = np.where(apart, estimate.max(axis=1), 0.0)
    while len(chosen) < k and score.max() >= target_mm:
        best = int(np.argmax(score))
        chosen.append(best)
        added = pool[best] / levels[:, None]
        x, f = np.vstack([x, added]), np.concatenate([f, cubic.predict(added)])
        # the new cases move the linear interpolant around them: the estimate is taken again
        # within NEIGHBOURHOOD_DEG of them, and kept farther away
        local = np.repeat(pool @ pool[best] >= math.cos(math.radians(NEIGHBOURHOOD_DEG)),
                          len(levels))
        updated = LoadSpaceInterpolant(x, f, loo_mm=np.zeros(len(x)), power=1)
        flat[local] = np.where(scored[local], committee(cubic_at[local], updated, y[local]), 0.0)
        score = flat.reshape(len(pool), len(levels)).max(axis=1)
        near = pool @ pool[best] >= math.cos(math.radians(SEPARATION_DEG))
        apart = apart & ~near
        score = np.where(apart, score, 0.0)
    return chosen


def read_cases(summary_paths: Sequence[str | Path], point_paths: Sequence[str | Path]
               ) -> tuple[list[Case], np.ndarray, np.ndarray]:
    """The cases of these folders, whether each converged, and their fields (M, N, 3) in mm.

    A case that passes through itself counts as not converged: the dataset's splits leave
    it out.

    Raises:
        DatasetError: as :func:`fem.case_files.read_case`, or for folders of other meshes.
    """
    from fem.case_files import read_case
    from fem.exceptions import DatasetError

    cases, converged, fields = [], [], []
    for summary_path, points_path in zip(summary_paths, point_paths, strict=True):
        summary, points = read_case(summary_path, points_path)
        through = ((summary.get("self_overlap") or {}).get("overlapping_vertices") or 0) > 0
        ok = summary["status"] == "converged" and not through
        if fields and points["u"].shape != fields[0].shape:
            raise DatasetError(f"{points_path}: {len(points['u'])} material points, expected "
                               f"{len(fields[0])} (another mesh?)")
        cases.append(Case.from_summary(summary))  # its numbers (read_case: its folder's)
        converged.append(ok and bool(np.all(np.isfinite(points["u"]))))
        fields.append(1e3 * np.asarray(points["u"], dtype=float))
    return cases, np.array(converged, dtype=bool), np.array(fields)

