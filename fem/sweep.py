"""The sweep: which (C1, Φ, θ) cases exist and how their folders are named.

This is the one place that derives the case list from the config and formats
case identifiers; the workflow, the dataset and the report all call it.

A case folder is ``c1=<C1 kPa, 2 decimals>_phi=<Φ deg, 1 decimal>_theta=<θ deg, 1 decimal>``,
e.g. ``c1=1.00_phi=180.0_theta=0.0``. The identifier *is* the case: its
parameters are parsed back from it, so a rounded angle is the angle solved.
"""

from __future__ import annotations

import copy
import logging
import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from fem.directions import direction_keys
from fem.exceptions import InvalidParameterError
from fem.parameters import STANDARD_GRAVITY, TISSUE_DENSITY, Gravity, Material

log = logging.getLogger(__name__)

C1_PATTERN = r"[0-9]+\.[0-9]{2}"
ANGLE_PATTERN = r"-?[0-9]+\.[0-9]"


def direction_id(phi: str, theta: str) -> str:
    """The gravity direction's part of a case folder's name, from its two angles' text."""
    return f"phi={phi}_theta={theta}"


def case_id(c1: str, direction: str) -> str:
    """A case folder's name from its C1 text and its direction's part (:func:`direction_id`).

    The one place that spells a case folder's name: :attr:`Case.id` fills it with a case's
    values, :data:`CASE_WILDCARDS` with Snakemake wildcards, :data:`CASE_PATTERN` with regular
    expressions.
    """
    return f"c1={c1}_{direction}"


DIRECTION_WILDCARDS = direction_id("{phi}", "{theta}")
"""A direction's part of a case folder's name with its angles as wildcards ``{phi}``,
``{theta}``; filled with :data:`ANGLE_PATTERN`, the expression of any direction."""
CASE_WILDCARDS = case_id("{c1}", DIRECTION_WILDCARDS)
"""A case folder's name with its values as Snakemake wildcards ``{c1}``, ``{phi}``, ``{theta}``
(e.g. the solve rules' outputs, ``results/cases/`` + this): the pattern of :attr:`Case.id`."""
CASE_PATTERN = re.compile(case_id(
    rf"(?P<c1>{C1_PATTERN})",
    direction_id(rf"(?P<phi>{ANGLE_PATTERN})", rf"(?P<theta>{ANGLE_PATTERN})")))


def case_folder(root: str, case: Case | None = None) -> str:
    """The folder of ``case`` under ``root`` (e.g. ``results/cases``).

    Without a case, the pattern of every case folder there (:data:`CASE_WILDCARDS`), as a
    rule's output names it.
    """
    return f"{root}/{CASE_WILDCARDS if case is None else case.id}"


@dataclass(frozen=True, slots=True, order=True)
class Case:
    """One mechanical setup.

    Attributes:
        C1: neo-Hookean parameter in kPa (as the paper quotes it).
        phi: gravity elevation angle Φ in degrees.
        theta: gravity azimuth angle θ in degrees.
    """

    C1: float
    phi: float
    theta: float = 0.0

    def __post_init__(self) -> None:
        for name in ("C1", "phi", "theta"):
            if not math.isfinite(getattr(self, name)):
                raise InvalidParameterError(f"case {name} must be finite")
        if self.C1 <= 0:
            raise InvalidParameterError(f"case C1 must be positive, got {self.C1} kPa")
        # Normalise to the identifier's precision so that Case(id) round-trips.
        object.__setattr__(self, "C1", round(float(self.C1), 2))
        object.__setattr__(self, "phi", round(float(self.phi), 1) + 0.0)
        object.__setattr__(self, "theta", round(float(self.theta), 1) + 0.0)

    @property
    def id(self) -> str:
        """Folder name of the case (:func:`case_id`)."""
        return case_id(f"{self.C1:.2f}", self.direction_id)

    @property
    def direction_id(self) -> str:
        """The gravity direction's part of :attr:`id` (:func:`direction_id`)."""
        return direction_id(f"{self.phi:.1f}", f"{self.theta:.1f}")

    @classmethod
    def from_id(cls, case_id: str) -> Case:
        """Parse a folder name.

        Raises:
            InvalidParameterError: if ``case_id`` is not a case identifier.
        """
        match = CASE_PATTERN.fullmatch(case_id)
        if not match:
            raise InvalidParameterError(
                f"{case_id!r} is not a case identifier like 'c1=1.00_phi=180.0_theta=0.0'"
            )
        return cls(float(match["c1"]), float(match["phi"]), float(match["theta"]))

    @classmethod
    def from_summary(cls, summary: Mapping[str, Any]) -> Case:
        """The case a solved case's ``summary.json`` describes (its numbers, not its folder)."""
        return cls(float(summary["C1"]), float(summary["phi"]), float(summary["theta"]))

    def material(self, density: float = TISSUE_DENSITY) -> Material:
        """The case's material (C1 converted to Pa)."""
        return Material(C1=self.C1 * 1e3, density=density)

    def gravity(self, magnitude: float = STANDARD_GRAVITY) -> Gravity:
        """The case's gravity."""
        return Gravity(phi=self.phi, theta=self.theta, unit="deg", magnitude=magnitude)


PAPER_PHI_DEG = (-150.0, -120.0, -90.0, -60.0, -35.0, -15.0, 0.0, 15.0, 35.0, 60.0, 90.0,
                 120.0, 145.0, 160.0, 170.0, 180.0)
"""The paper's 16 gravity angles are not printed; it says they span [-150°, 180°] and cluster
about the poles (0° supine, 180° prone) and thin out about ±90° (its Fig. 4b). These follow
that description: steps of 10–15° next to the poles, 30° next to ±90°, and both clinical
positions (0° and 180°) are sampled exactly."""

PHI_SAMPLINGS = ("paper", "uniform", "equal_area")

CASE_KEYS = ("C1_kPa", "phi_deg", "theta_deg", "sphere", "adaptive")
"""The keys of a ``sweep`` section that choose its cases (a preset sets all of them)."""

SWEEP_PRESETS: dict[str, dict[str, Any]] = {
    "paper": {
        "C1_kPa": {"start": 0.8, "stop": 5.0, "step": 0.1},
        "phi_deg": {"sampling": "paper"},
        "theta_deg": [0.0],
    },
}
"""Named sweeps: ``paper`` is the paper's 688 cases (43 C1 values x its 16 angles in the plane
θ = 0), the preset that reproduces it whatever else the config's ``sweep`` says."""


def resolve_sweep(sweep: dict[str, Any]) -> dict[str, Any]:
    """The ``sweep`` section with its ``preset`` (if any) written out.

    A preset replaces every key of :data:`CASE_KEYS`, so that ``snakemake --config
    sweep={preset: paper}`` (merged into the config file's ``sweep``) is the paper's sweep;
    the other keys (``chains``) are kept.

    Raises:
        InvalidParameterError: for an unknown preset.
    """
    preset = sweep.get("preset")
    if preset is None:
        return dict(sweep)
    if preset not in SWEEP_PRESETS:
        raise InvalidParameterError(
            f"sweep.preset must be one of {tuple(SWEEP_PRESETS)}, got {preset!r}"
        )
    kept = {k: v for k, v in sweep.items() if k not in CASE_KEYS and k != "preset"}
    return {**kept, **copy.deepcopy(SWEEP_PRESETS[preset])}


def sample_phi(spec: Any) -> list[float]:
    """Gravity elevation angles Φ (degrees) from a list or a sampling rule.

    Args:
        spec: a list of angles, or ``{sampling, n, min, max}`` with ``sampling``
            ``paper`` (:data:`PAPER_PHI_DEG`), ``uniform`` (equal steps, both ends
            included) or ``equal_area`` (density ∝ |sin Φ|, the area of the band of
            directions at Φ on the unit sphere: more angles about ±90°, fewer at the
            poles; the paper's suggested future work).
    """
    if not isinstance(spec, dict):
        return grid(spec, "sweep.phi_deg")
    sampling = spec.get("sampling", "paper")
    if sampling not in PHI_SAMPLINGS:
        raise InvalidParameterError(
            f"sweep.phi_deg.sampling must be one of {PHI_SAMPLINGS}, got {sampling!r}"
        )
    if sampling == "paper":
        return list(PAPER_PHI_DEG)
    n = int(spec.get("n", 16))
    lo, hi = float(spec.get("min", -150.0)), float(spec.get("max", 180.0))
    if n < 1 or not lo < hi:
        raise InvalidParameterError("sweep.phi_deg needs n >= 1 and min < max")
    if sampling == "uniform":
        return [float(v) for v in np.linspace(lo, hi, n)] if n > 1 else [lo]
    # equal_area: place angles at the midpoints of n bins of equal probability
    fine = np.linspace(lo, hi, 20001)
    density = np.abs(np.sin(np.radians(fine))) + 1e-12
    cdf = np.concatenate([[0.0], np.cumsum(0.5 * (density[1:] + density[:-1]) * np.diff(fine))])
    cdf /= cdf[-1]
    return [float(v) for v in np.interp((np.arange(n) + 0.5) / n, cdf, fine)]


SPHERE_PARTS = ("whole", "caudal")
"""Which directions ``sweep.sphere`` covers: the whole sphere, or the caudal half (gravity's
cranio-caudal component towards the feet or zero: every posture short of a head-down tilt)."""


def sphere_directions(n: int, part: str = "whole") -> list[tuple[float, float]]:
    """``n`` gravity directions spread evenly over the sphere or its caudal half, as (Φ, θ).

    A Fibonacci lattice (equal area per point, Deserno's 'equidistributed points'): the
    paper's stated future work of leaving the θ = 0 plane. The whole sphere's lattice runs
    along the x axis (Φ is its polar angle); the caudal half's along z, from the paper's plane
    (z = 0, θ = 0 or 180°) to gravity towards the feet (Φ = 90°, θ = −90°), so that its rim
    is the paper's plane.

    Raises:
        InvalidParameterError: if ``n`` < 1 or ``part`` is not one of :data:`SPHERE_PARTS`.
    """
    if n < 1:
        raise InvalidParameterError("sweep.sphere.n must be >= 1")
    if part not in SPHERE_PARTS:
        raise InvalidParameterError(
            f"sweep.sphere.part must be one of {SPHERE_PARTS}, got {part!r}"
        )
    i = np.arange(n)
    azimuth = i * np.pi * (3.0 - np.sqrt(5.0))  # golden angle
    if part == "whole":
        gx = 1.0 - (2.0 * i + 1.0) / n  # cos Φ, uniform: equal area bands
        phi = np.degrees(np.arccos(gx))
        theta = np.degrees(np.arctan2(np.sin(azimuth), np.cos(azimuth)))
    else:
        gz = -(i + 0.5) / n  # uniform in [-1, 0]: equal area bands of the caudal half
        ring = np.sqrt(1.0 - gz**2)
        phi, theta = _angles(ring * np.cos(azimuth), ring * np.sin(azimuth), gz)
    return [(float(p), float(t)) for p, t in zip(phi, theta, strict=True)]


def _angles(gx: np.ndarray, gy: np.ndarray, gz: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Φ and θ (degrees) of unit gravity directions g = [cos Φ, sin Φ cos θ, sin Φ sin θ]."""
    return np.degrees(np.arccos(np.clip(gx, -1.0, 1.0))), np.degrees(np.arctan2(gz, gy))


def random_cases(
    n: int, seed: int, c1_range: tuple[float, float], part: str = "caudal"
) -> list[Case]:
    """``n`` cases drawn at random within a sweep's range: a test set off its grid.

    C1 is drawn uniformly in the compliance 1/C1 between the range's ends: the field scales
    nearly as 1/C1, so each stretch of the range is drawn in proportion to the displacement it
    spans, and the soft end, where the field is largest and changes fastest, is not left to
    chance; a range of one value (a sweep of one C1) puts every case at it. Gravity is drawn
    uniformly over the whole sphere or its caudal half (:data:`SPHERE_PARTS`, as
    :func:`sphere_directions`). Each value is rounded to its case folder's precision (0.01
    kPa, 0.1°) by :class:`Case`, so that the case solved is the case drawn.

    Raises:
        InvalidParameterError: if ``n`` < 0, the range is not 0 < low <= high, or ``part`` is
            not one of :data:`SPHERE_PARTS`.
    """
    lo, hi = (float(v) for v in c1_range)
    if n < 0:
        raise InvalidParameterError(f"the number of random cases must be >= 0, got {n}")
    if not (math.isfinite(lo) and math.isfinite(hi) and 0 < lo <= hi):
        raise InvalidParameterError(
            f"random cases need a C1 range 0 < low <= high kPa, got [{lo:g}, {hi:g}]")
    if part not in SPHERE_PARTS:
        raise InvalidParameterError(f"random directions: part must be one of {SPHERE_PARTS}, "
                                    f"got {part!r}")
    rng = np.random.default_rng(seed)
    c1 = 1.0 / rng.uniform(1.0 / hi, 1.0 / lo, n)
    azimuth = rng.uniform(0.0, 2.0 * np.pi, n)
    # uniform in the axial coordinate is uniform in area (Archimedes), as for the lattice
    axial = rng.uniform(-1.0, 1.0, n) if part == "whole" else -rng.uniform(0.0, 1.0, n)
    ring = np.sqrt(1.0 - axial**2)
    if part == "whole":  # polar axis x, as sphere_directions' whole lattice
        phi, theta = _angles(axial, ring * np.cos(azimuth), ring * np.sin(azimuth))
    else:  # polar axis z, the caudal half
        phi, theta = _angles(ring * np.cos(azimuth), ring * np.sin(azimuth), axial)
    return [Case(float(c), float(p), float(t)) for c, p, t in zip(c1, phi, theta, strict=True)]


#: The most values a ``{start, stop, step}`` range may have, and the most cases a sweep may
#: have: a sweep is planned as one job per case, and a plan of millions of jobs does not end.
MAX_GRID_VALUES = 10_000
MAX_CASES = 50_000


def grid(spec: Any, name: str) -> list[float]:
    """Values from a list or from ``{start, stop, step}`` (stop included).

    Raises:
        InvalidParameterError: for an empty list, a range with step <= 0 or stop < start, or
            one of more than :data:`MAX_GRID_VALUES` values.
    """
    if isinstance(spec, dict):
        start, stop, step = (float(spec[k]) for k in ("start", "stop", "step"))
        if step <= 0 or stop < start:
            raise InvalidParameterError(f"{name}: need step > 0 and stop >= start")
        n = int(math.floor((stop - start) / step + 1e-9)) + 1
        if n > MAX_GRID_VALUES:
            raise InvalidParameterError(
                f"{name}: {start:g} to {stop:g} in steps of {step:g} is {n} values, more than "
                f"{MAX_GRID_VALUES}"
            )
        return [float(v) for v in np.round(start + step * np.arange(n), 10)]
    values = [float(v) for v in spec]
    if not values:
        raise InvalidParameterError(f"{name} is empty")
    return values


def sweep_cases(sweep: dict[str, Any]) -> list[Case]:
    """The cases of a sweep config section that are known before any is solved, sorted.

    Args:
        sweep: the ``sweep`` section: ``C1_kPa`` (list or range) and ``phi_deg`` (list or
            sampling rule, see :func:`sample_phi`) × ``theta_deg`` (list, default ``[0]``),
            or ``sphere: {n, part}`` (directions over the whole sphere or its caudal half,
            :func:`sphere_directions`), or both: the plane's directions and the sphere's;
            or a ``preset`` (:func:`resolve_sweep`). Every direction is solved at every C1.
            With ``adaptive`` these are the start design, and the rounds of
            :mod:`fem.adaptive` add directions to it as the workflow solves them.

    Raises:
        InvalidParameterError: if the sweep has more than :data:`MAX_CASES` cases, or two of
            its values are closer than its folder names tell apart (they would share a folder).
    """
    sweep = resolve_sweep(sweep)
    c1s = grid(sweep["C1_kPa"], "sweep.C1_kPa")
    directions: list[tuple[float, float]] = []
    if sweep.get("phi_deg") is not None:
        thetas = grid(sweep.get("theta_deg", [0.0]), "sweep.theta_deg")
        directions = [(p, t) for p in sample_phi(sweep["phi_deg"]) for t in thetas]
    if sweep.get("sphere"):
        sphere = sweep["sphere"]
        directions += sphere_directions(int(sphere["n"]), sphere.get("part", "whole"))
    if not directions:
        raise InvalidParameterError("sweep needs phi_deg or sphere")
    directions = _drop_aliases(directions)
    n_cases = len(c1s) * len(directions)
    if n_cases > MAX_CASES:
        raise InvalidParameterError(
            f"sweep: {len(c1s)} C1 values x {len(directions)} gravity directions is "
            f"{n_cases} cases, more than {MAX_CASES}"
        )
    _distinct_folders("sweep.C1_kPa", c1s, 2, "kPa")
    _distinct_folders("sweep gravity directions (phi, theta)", directions, 1, "deg")
    return sorted({Case(c, p, t) for c in c1s for p, t in directions})


def _distinct_folders(name: str, values: Sequence[Any], digits: int, unit: str) -> None:
    """Refuse two different values that a case folder's name, rounded to ``digits``, merges."""
    seen: dict[Any, Any] = {}
    for value in values:
        key = tuple(round(float(v), digits) + 0.0 for v in np.atleast_1d(value))
        if key in seen and seen[key] != value:
            raise InvalidParameterError(
                f"{name}: {seen[key]} and {value} share one case folder (folder names give "
                f"{digits} decimal(s) of {unit}): drop one or space them further apart"
            )
        seen[key] = value


def _drop_aliases(directions: Sequence[tuple[float, float]]) -> list[tuple[float, float]]:
    """The directions with each gravity direction once, under the first of its names.

    A grid of Φ × θ names the poles (Φ = 0 or 180°) once per θ, and Φ = 360° is Φ = 0°: each
    would be solved again in a folder of its own, to the same field. The later names are
    dropped with a warning; a case asked for under one of them is solved alone, outside the
    sweep.
    """
    keys = direction_keys(np.array([p for p, _ in directions], dtype=float),
                          np.array([t for _, t in directions], dtype=float))
    first: dict[str, tuple[float, float]] = {}
    kept = []
    for key, pair in zip(keys, directions, strict=True):
        if str(key) not in first:
            first[str(key)] = pair
            kept.append(pair)
        elif Case(1.0, *first[str(key)]) != Case(1.0, *pair):
            log.warning("sweep: gravity direction (phi, theta) = (%g, %g) is (%g, %g), already "
                        "listed (one direction, several names: at phi = 0 or 180 every theta "
                        "is the same pole, theta = +-180 mirrors phi, phi = 360 is 0): solved "
                        "once, as (%g, %g)", *pair, *first[str(key)], *first[str(key)])
    return kept


@dataclass(frozen=True, slots=True)
class ClinicalCase:
    """One of the config's ``clinical`` cases: the setup and its label in tables and figures.

    Attributes:
        case: the setup (C1, Φ, θ).
        label: the config's ``label``, else the case's folder name.
    """

    case: Case
    label: str

    @classmethod
    def from_mapping(cls, item: Mapping[str, Any]) -> ClinicalCase:
        """Parse one entry ``{C1, phi, theta?, label?}`` of the config's ``clinical`` list."""
        case = Case(float(item["C1"]), float(item["phi"]), float(item.get("theta", 0.0)))
        return cls(case, str(item.get("label", case.id)))


def clinical_list(clinical: Sequence[Mapping[str, Any]]) -> list[ClinicalCase]:
    """The config's ``clinical`` list, parsed (the one place that reads its entries)."""
    return [ClinicalCase.from_mapping(item) for item in clinical]


def clinical_cases(clinical: Sequence[Mapping[str, Any]]) -> list[Case]:
    """The config's ``clinical`` list as cases (:func:`clinical_list` without the labels)."""
    return [item.case for item in clinical_list(clinical)]
