"""``results/sweep/rounds.json``: every round of the adaptive sweep in one typed record.

Each round of :mod:`fem.adaptive` writes its plan (:class:`fem.adaptive.RoundPlan`,
``results/sweep/round_<k>.json``); the rule ``sweep_rounds`` gathers them here, with the
settings the rounds stopped by, for the report's section on how the sweep chose its cases.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from fem.adaptive import AdaptiveSettings, RoundPlan
from fem.directions import direction_keys
from studies.results import Record, Result

START_ROUND = 0
"""The round number of the start design's directions (the rounds count from 1)."""


@dataclass(frozen=True, slots=True)
class SweepRound(Record):
    """One round: the fields of :class:`fem.adaptive.RoundPlan` (see there)."""

    round: int
    cases_before: int
    converged_before: int
    estimate_mm: float
    worst: tuple[float, float, float]
    median_loo_mm: float
    max_loo_mm: float
    directions: list[tuple[float, float]]
    cases: list[str]
    done: bool
    reason: str

    @classmethod
    def of(cls, plan: RoundPlan) -> SweepRound:
        """The round of a plan."""
        return cls(**{name: getattr(plan, name) for name in cls.__dataclass_fields__})


@dataclass(frozen=True, slots=True)
class SweepRounds(Result):
    """Every round of a sweep, in order, and the settings it stopped by (the module).

    Attributes:
        target_mm: ``sweep.adaptive.target_mm``: the rounds stop once the estimate is under it.
        max_cases: ``sweep.adaptive.max_cases``: the case budget, the start included.
        rounds: the rounds, the first (round 1) first; the last ends the sweep if ``done``.
    """

    target_mm: float
    max_cases: int
    rounds: list[SweepRound]

    def __post_init__(self) -> None:
        if not self.rounds:
            raise ValueError("a sweep's rounds record needs at least one round")

    @classmethod
    def of(cls, plans: Sequence[RoundPlan], settings: AdaptiveSettings) -> SweepRounds:
        """The record of a sweep's plans, in order, and its ``sweep.adaptive`` settings."""
        return cls(float(settings.target_mm), int(settings.max_cases),
                   [SweepRound.of(p) for p in sorted(plans, key=lambda p: p.round)])

    @property
    def last(self) -> SweepRound:
        """The latest round."""
        return self.rounds[-1]

    @property
    def cases(self) -> int:
        """The sweep's cases: those before the last round and what it adds."""
        return self.last.cases_before + len(self.last.cases)

    @property
    def added_directions(self) -> int:
        """The directions the rounds added to the start design."""
        return sum(len(r.directions) for r in self.rounds)

    @property
    def estimate_mm(self) -> float:
        """The estimated worst-point error before the last round (mm)."""
        return self.last.estimate_mm

    @property
    def done(self) -> bool:
        """Whether the sweep has ended."""
        return self.last.done

    @property
    def reason(self) -> str:
        """Why it ended (``target met``, ``budget spent``, ...), or ``adding``."""
        return self.last.reason

    def rounds_of(self, phi: Sequence[float], theta: Sequence[float]) -> np.ndarray:
        """The round that added each direction (Φ, θ) (degrees); :data:`START_ROUND` if none.

        The directions are compared as unit vectors (:func:`fem.directions.direction_keys`),
        so that a pole named under two θ is one direction.
        """
        added = {key: r.round for r in self.rounds if r.directions
                 for key in direction_keys(*np.array(r.directions, dtype=float).T)}
        keys = direction_keys(np.asarray(phi, dtype=float), np.asarray(theta, dtype=float))
        return np.array([added.get(k, START_ROUND) for k in keys], dtype=int)
