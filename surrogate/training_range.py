"""A surrogate's training range: which queries its sweep's FE solutions back.

A model is trained on a sweep's cases; a query outside them is still answered, but it is an
extrapolation, and :class:`surrogate.predict.Surrogate` warns (``ExtrapolationWarning``):
outside the trained C1 range, in an arc of Φ (or a region of gravity directions) without
training directions, off the trained θ, at or below a C1 at which the sweep's FE solve failed
beside the query's direction, or below the softest C1 solved beside it. :class:`TrainingRange`
holds what decides it, built once per model from ``model.json``'s ``training_range``; the web
page's forward pass receives the same (:meth:`TrainingRange.range_checks`).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from fem.directions import gravity_direction

DIRECTION_REACH = 1.5
"""A query off the plane whose direction is farther than this many of the training directions'
typical spacing (the median angle to each one's nearest) from every one of them is an
extrapolation."""


def _finite(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


def _check_rows(record: dict[str, Any], key: str, width: int) -> None:
    """Refuse ``record[key]`` unless rows of ``width`` finite numbers (a flat list for 0)."""
    value = record[key]
    if not isinstance(value, list):
        raise ValueError(f"training_range.{key} is {value!r}, not a list")
    for i, row in enumerate(value):
        ok = _finite(row) if width == 0 else (
            isinstance(row, list) and len(row) == width and all(map(_finite, row)))
        if not ok:
            what = "a finite number" if width == 0 else f"{width} finite numbers"
            raise ValueError(f"training_range.{key}[{i}] is {row!r}, not {what}")


def check_record(record: Any) -> dict[str, Any]:
    """``model.json``'s ``training_range`` checked: its numbers finite, its C1 ranges ordered.

    Each key may be absent (a model saved before it was recorded is judged without it).

    Raises:
        ValueError: naming the key and its value: a card edited or damaged, whose warnings
            would compare queries against NaN or a reversed range and never warn.
    """
    if not isinstance(record, dict):
        raise ValueError(f"training_range is {record!r}, not a mapping of the trained values")
    if "C1_kPa" in record:
        value = record["C1_kPa"]
        if not (isinstance(value, list) and len(value) == 2 and all(map(_finite, value))
                and 0 < value[0] <= value[1]):
            raise ValueError(f"training_range.C1_kPa is {value!r}, not [low, high] in kPa with "
                             "0 < low <= high")
    for key, width in (("phi_deg", 0), ("theta_deg", 0), ("directions", 2),
                       ("unconverged", 3), ("c1_by_direction", 4)):
        if key in record:
            _check_rows(record, key, width)
    for i, (_, _, low, high) in enumerate(record.get("c1_by_direction", [])):
        if not 0 < low <= high:
            raise ValueError(f"training_range.c1_by_direction[{i}]: its C1 range [{low}, "
                             f"{high}] is not 0 < low <= high")
    tissues = record.get("tissues", {})
    if not isinstance(tissues, dict) or not all(
            _finite(v) and v > 0 for v in tissues.values()):
        raise ValueError(f"training_range.tissues is {tissues!r}, not each tissue's positive "
                         "C1 ratio")
    return record


def _unit_directions(pairs: Any) -> np.ndarray:
    """Unit gravity directions of (Φ, θ) pairs in degrees, shape (n, 3)."""
    angles = np.asarray(pairs, dtype=float).reshape(-1, 2)
    return gravity_direction(angles[:, 0], angles[:, 1])



class TrainingRange:
    """What decides that a query is an extrapolation, from a model's ``training_range``.

    Args:
        training_range: ``model.json``'s record: ``C1_kPa`` (low, high), ``phi_deg``,
            ``theta_deg``, ``directions`` (Φ, θ) pairs, ``unconverged`` (C1, Φ, θ) of the
            sweep's failed cases, ``c1_by_direction`` (Φ, θ, softest C1, stiffest C1); None or
            empty: no limits.
    """

    def __init__(self, training_range: dict[str, Any] | None) -> None:
        rng = training_range or {}
        self._c1_range = tuple(rng.get("C1_kPa", (0.0, math.inf)))
        phis = sorted({float(p) % 360.0 for p in rng.get("phi_deg", [])})
        self._phi_gap: tuple[float, float] | None = None
        if len(phis) > 1:
            gaps = [
                (phis[i], (phis[(i + 1) % len(phis)] - phis[i]) % 360.0 or 360.0)
                for i in range(len(phis))
            ]
            start, widest = max(gaps, key=lambda g: g[1])
            # An arc without training angles more than twice as wide as the typical spacing
            # is outside the training range; elsewhere Φ is interpolated.
            if widest > 2.0 * float(np.median([g[1] for g in gaps])):
                self._phi_gap = (start, widest)
        elif len(phis) == 1:
            self._phi_gap = (phis[0], 360.0)
        self._thetas = [float(t) for t in rng.get("theta_deg", [])]
        # A sweep off the plane (several θ, e.g. sweep.sphere) is judged by direction: its Φ
        # alone has gaps that other θ fill, so the arc test applies to a one-θ sweep only.
        self._directions: np.ndarray | None = None
        self._direction_reach = self._direction_spacing = math.inf
        pairs = rng.get("directions") or []
        if len(self._thetas) > 1 and len(pairs) > 1:
            self._phi_gap = None
            self._directions = _unit_directions(pairs)
            cos = np.clip(self._directions @ self._directions.T, -1.0, 1.0)
            np.fill_diagonal(cos, -1.0)
            spacing = self._direction_spacing = float(
                np.median(np.degrees(np.arccos(cos.max(axis=1))))
            )
            # a query midway between training directions is about 0.6 spacings from the
            # nearest; beyond 1.5 it lies where the sweep has none (e.g. head-down for a
            # sweep of the caudal half)
            self._direction_reach = DIRECTION_REACH * spacing
        self._unconverged = [
            (float(c), float(p), float(t)) for c, p, t in rng.get("unconverged", [])
        ]
        # the angles a query's neighbours are taken from, and the failures' directions: built
        # once, not per prediction
        self._sweep_angles = sorted(set(phis) | {p % 360.0 for _, p, _ in self._unconverged})
        self._unconverged_directions = _unit_directions(
            [(p, t) for _, p, t in self._unconverged] or np.zeros((0, 2)))
        # each training direction's softest FE solution, (C1, Φ, θ)
        self._softest = [
            (float(lo), float(p), float(t)) for p, t, lo, _ in rng.get("c1_by_direction", [])
        ]
        self._softest_directions = _unit_directions(
            [(p, t) for _, p, t in self._softest] or np.zeros((0, 2)))


    def range_checks(self) -> dict[str, Any]:
        """What decides that a query is an extrapolation (for :mod:`surrogate.export`).

        ``c1_kPa``: the trained C1 range; ``phi_gap``: ``[start, width]`` of the arc of Φ without
        training angles (degrees), or None; ``theta_deg``: the trained θ; ``directions``: the
        trained unit gravity directions of a sweep off the plane (else None),
        ``direction_spacing_deg`` their typical spacing and ``direction_reach_deg`` the angle
        from the nearest beyond which a query is outside them; ``unconverged``: the
        sweep's failed cases (C1, Φ, θ); ``softest``: each training direction's softest
        trained C1, as (C1, Φ, θ); ``sweep_phi_deg``: the angles (mod 360°) whose failures and
        softest solutions judge a query between them.
        """
        return {
            "c1_kPa": [v if math.isfinite(v) else None for v in self._c1_range],
            "phi_gap": None if self._phi_gap is None else list(self._phi_gap),
            "theta_deg": list(self._thetas),
            "directions": None if self._directions is None else self._directions.tolist(),
            "direction_spacing_deg": (self._direction_spacing
                                      if math.isfinite(self._direction_spacing) else None),
            "direction_reach_deg": (self._direction_reach
                                    if math.isfinite(self._direction_reach) else None),
            "unconverged": [list(case) for case in self._unconverged],
            "softest": [list(case) for case in self._softest],
            "sweep_phi_deg": list(self._sweep_angles),
        }

    def _beside(self, cases: list[tuple[float, float, float]], units: np.ndarray, phi: float,
                theta: float) -> list[tuple[float, float, float]]:
        """The (C1, Φ, θ) entries of ``cases`` whose direction lies beside the query's.

        A model of the plane judges a query at a sweep angle by that angle's entries, one
        between two angles by both neighbours' (same θ); a model off the plane by the entries
        whose direction (``units``, one row per entry) lies within the training directions'
        typical spacing of the query's.
        """
        if not cases:
            return []
        phi, theta = self.plane_name(phi, theta)
        if self._directions is not None:
            cos = np.clip(units @ _unit_directions([(phi, theta)])[0], -1.0, 1.0)
            angles = np.degrees(np.arccos(cos))
            return [case for case, angle in zip(cases, angles, strict=True)
                    if angle <= self._direction_spacing + 1e-9]
        q = phi % 360.0
        below = min(self._sweep_angles, key=lambda p: (q - p) % 360.0)
        above = min(self._sweep_angles, key=lambda p: (p - q) % 360.0)
        return [
            (c, p, t)
            for c, p, t in cases
            if abs(t - theta) < 1e-6
            and any(abs((p - n + 180.0) % 360.0 - 180.0) < 1e-6 for n in (below, above))
        ]

    def plane_name(self, phi: float, theta: float) -> tuple[float, float]:
        """A query in a one-plane model's plane under the plane's own name, (Φ', θ0).

        Gravity at (Φ, θ0 + 180°) is gravity at (−Φ, θ0), and θ0 ± 360° is θ0: such a query
        is judged as the sweep named that direction (Φ' in (−180°, 180°], to 1e-6°). A query
        off the plane, or a model trained off it, keeps its angles.
        """
        if (self._directions is not None or len(self._thetas) != 1
                or abs(theta - self._thetas[0]) < 1e-6):
            return phi, theta
        t0 = math.radians(self._thetas[0])
        g = _unit_directions([(phi, theta)])[0]
        if abs(g[2] * math.cos(t0) - g[1] * math.sin(t0)) > 1e-9:
            return phi, theta
        along = g[1] * math.cos(t0) + g[2] * math.sin(t0)
        return round(math.degrees(math.atan2(along, g[0])), 6) + 0.0, self._thetas[0]

    def unconverged_beside(
        self, C1: float, phi: float, theta: float
    ) -> tuple[float, float, float] | None:
        """The stiffest failed sweep case beside the query's direction, if C1 is not stiffer.

        The sweep's FE solves fail below some C1 in some directions (the model has no
        equilibrium there, or none on the load path; docs/solver.md). "Beside" as
        :meth:`_beside`.
        """
        beside = self._beside(self._unconverged, self._unconverged_directions, phi, theta)
        if not beside:
            return None
        stiffest = max(beside)
        return stiffest if C1 <= stiffest[0] + 1e-9 else None

    def softest_beside(
        self, C1: float, phi: float, theta: float
    ) -> tuple[float, float, float] | None:
        """The trained direction beside the query's whose softest FE solution is stiffer than C1.

        As (that softest C1, Φ, θ): the one with the stiffest such minimum, or None where every
        direction beside the query (:meth:`_beside`) was trained at C1 or softer. A sweep need
        not solve every direction at every C1 (``sweep.refine``'s bands start at their own
        C1_min, and a direction's softest solves may fail): below a direction's softest
        solution the model extrapolates in C1 there, though C1 lies inside its global range.
        None for a model saved without the per-direction record.
        """
        beside = self._beside(self._softest, self._softest_directions, phi, theta)
        stiffer = [entry for entry in beside if C1 < entry[0] - 1e-9]
        return max(stiffer) if stiffer else None

    def direction_outside(self, phi: float, theta: float) -> float | None:
        """The angle (degrees) from gravity at (Φ, θ) to the nearest training direction.

        Only where it lies outside them (beyond :data:`DIRECTION_REACH` spacings), for a model
        trained off the plane; None otherwise, and for a model of the plane (judged by Φ and θ,
        under the plane's own name: :meth:`plane_name`).
        """
        if self._directions is None:
            return None
        cos = (self._directions @ _unit_directions([(phi, theta)])[0]).max()
        nearest = float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))
        return nearest if nearest > self._direction_reach else None


    def warnings(self, C1: float, phi: float, theta: float) -> list[str]:
        """Why a query (C1 in kPa, Φ and θ in degrees) is an extrapolation: none, or each reason.

        Outside the trained C1 range, in an arc of Φ or a region of directions without
        training directions, off the trained θ, at or below a failed sweep case beside it
        (:meth:`unconverged_beside`), or below the softest solution beside it
        (:meth:`softest_beside`).
        """
        messages = []
        lo, hi = self._c1_range
        given = f"Φ = {phi}°, θ = {theta}°"
        named_as = self.plane_name(phi, theta)
        renamed = named_as != (phi, theta)
        phi, theta = named_as
        if not lo - 1e-9 <= C1 <= hi + 1e-9:
            messages.append(f"C1 = {C1} kPa is outside the training range [{lo}, {hi}] kPa")
        if self._phi_gap is not None:
            start, width = self._phi_gap
            offset = (phi - start) % 360.0
            if 1e-6 < offset < width - 1e-6:
                named = (f"gravity at {given} (Φ = {phi}° in the trained plane)" if renamed
                         else f"Φ = {phi}°")
                messages.append(f"{named} lies in a {width:.0f}° arc without training angles")
        nearest = self.direction_outside(phi, theta)
        if nearest is not None:
            messages.append(
                f"gravity at Φ = {phi}°, θ = {theta}° is {nearest:.0f}° from the nearest "
                f"training direction (they are {self._direction_spacing:.0f}° apart)"
            )
        if (
            self._thetas
            and abs(math.sin(math.radians(phi))) > 1e-6
            and min(abs(theta - t) for t in self._thetas) > 1e-6
            and len(self._thetas) == 1
        ):
            messages.append(
                f"θ = {theta}° but the surrogate was trained at θ = {self._thetas[0]}° only"
            )

        def at(p: float, t: float) -> str:  # a sweep direction: Φ alone in the plane
            return f"Φ = {p:g}°" if self._directions is None else f"Φ = {p:g}°, θ = {t:g}°"

        query = f"C1 = {C1} kPa, {given}"
        failed = self.unconverged_beside(C1, phi, theta)
        if failed is not None:
            c1, p, t = failed
            messages.append(
                f"the sweep's FE solve did not converge at C1 = {c1:g} kPa, {at(p, t)} (beside "
                f"{query}), so no FE solution backs C1 ≤ {c1:g} kPa there"
            )
        softest = None if failed is not None or C1 < lo - 1e-9 else self.softest_beside(
            C1, phi, theta)
        if softest is not None:
            c1, p, t = softest
            messages.append(
                f"the sweep's softest FE solution at {at(p, t)} (beside {query}) is at C1 = "
                f"{c1:g} kPa, so no FE solution backs C1 < {c1:g} kPa there"
            )
        return messages
