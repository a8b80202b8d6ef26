"""Where a trained surrogate answers without a warning, over the range it was trained on.

A model warns (:class:`surrogate.exceptions.ExtrapolationWarning`) where no FE solution backs a
query: outside its C1 range or directions, beside a sweep case whose FE solve failed at that C1
or stiffer, or below the softest C1 solved beside the query's direction. Inside its range the
last two mark where the sweep itself has no answer, at the soft end. This draws queries evenly
over that range, runs each one's checks alone (``Surrogate.features``, which ``predict`` calls;
not the network) and counts the share that warns, by C1 band and by kind: the part of the range
where a user gets an answer without a warning, and where she does not.

The queries: C1 uniform in the model's trained range; gravity directions uniform on the sphere
and kept where they lie among the training directions
(``TrainingRange.direction_outside`` None),
or, for a model of the plane, Φ uniform outside its arc without training angles, at its trained
θ. ``python -m studies.surrogate_study.warning_coverage MODEL [--draws N] [--seed S] [--bands C1
...] [--json
OUT]`` prints the table; the workflow's rule ``warning_coverage`` writes it for the selected model
(``results/surrogate/warning_coverage.json``, :class:`WarningCoverage`) and the report shows it.
"""

from __future__ import annotations

import argparse
import math
import sys
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fem.directions import gravity_angles
from studies.results import Record, Result
from surrogate.exceptions import ExtrapolationWarning
from surrogate.predict import Surrogate

#: The kinds of warning counted inside the trained range. A warned query counts once, under the
#: first that applies, as the model itself checks a failed solve beside it first.
KINDS = ("beside a failed FE solve", "below the softest C1 solved beside", "other")


#: The queries drawn, their seed and the C1 values (kPa) between the table's bands, by default.
DRAWS = 40_000
SEED = 0
BAND_EDGES = (1.0, 1.2, 2.0)


@dataclass(frozen=True, slots=True)
class CoverageBand(Record):
    """How many queries had C1 in ``[c1_low, c1_high)`` kPa, and how many of them warned.

    The last band includes its upper end, the trained range's.
    """

    c1_low: float
    c1_high: float
    queries: int
    warned: int

    @property
    def share(self) -> float:
        """The share of the band's queries that warned (NaN for an empty band)."""
        return self.warned / self.queries if self.queries else math.nan


@dataclass(frozen=True, slots=True)
class WarningCoverage(Result):
    """How much of a model's trained range it answers without a warning.

    ``results/surrogate/warning_coverage.json`` for the selected model.

    Attributes:
        c1_kpa: the trained C1 range the queries were drawn from.
        drawn: directions drawn (on the sphere, or Φ on the plane).
        queries: queries inside the trained directions, each judged.
        warned: queries that warned.
        kinds: per kind of :data:`KINDS`, the queries with such a warning.
        bands: the queries and warnings per C1 band, softest first.
        seed: the random stream's seed.
    """

    c1_kpa: tuple[float, float]
    drawn: int
    queries: int
    warned: int
    kinds: dict[str, int]
    bands: tuple[CoverageBand, ...]
    seed: int

    @property
    def share(self) -> float:
        """The share of all queries that warned."""
        return self.warned / self.queries if self.queries else math.nan


def _directions(
    model: Surrogate, rng: np.random.Generator, n: int
) -> tuple[np.ndarray, np.ndarray]:
    """``n`` query directions (Φ, θ in degrees) drawn evenly, less those outside the trained."""
    checks = model.trained.range_checks()
    if checks["directions"] is None:  # a model of the plane: Φ at its trained θ
        phi = rng.uniform(-180.0, 180.0, n)
        gap = checks["phi_gap"]
        if gap is not None:
            start, width = gap
            offset = (phi - start) % 360.0
            phi = phi[~((offset > 1e-6) & (offset < width - 1e-6))]
        theta = np.full(phi.shape, float(checks["theta_deg"][0]) if checks["theta_deg"] else 0.0)
        return phi, theta
    g = rng.normal(size=(n, 3))
    g /= np.linalg.norm(g, axis=1, keepdims=True)
    phi, theta = np.array([gravity_angles(row) for row in g]).T
    inside = np.array([model.trained.direction_outside(float(p), float(t)) is None
                       for p, t in zip(phi, theta, strict=True)], dtype=bool)
    return phi[inside], theta[inside]


def warning_coverage(
    model: Surrogate, draws: int = DRAWS, seed: int = SEED, edges: Sequence[float] = BAND_EDGES
) -> WarningCoverage:
    """Draw ``draws`` queries over ``model``'s trained range and count where it warns.

    Args:
        model: a trained surrogate.
        draws: directions drawn (those outside the training directions are dropped).
        seed: the random stream's seed.
        edges: C1 values (kPa) between the bands of the table.

    Raises:
        ValueError: if ``draws`` is not positive, or the model records no finite C1 range.
    """
    if draws < 1:
        raise ValueError(f"draws must be positive, got {draws}")
    low, high = model.trained.range_checks()["c1_kPa"]
    if low is None or high is None:
        raise ValueError("the model records no finite trained C1 range")
    rng = np.random.default_rng(seed)
    phi, theta = _directions(model, rng, draws)
    c1 = rng.uniform(low, high, len(phi))
    warned = np.zeros(len(phi), dtype=bool)
    kinds = dict.fromkeys(KINDS, 0)
    for i, (C1, p, t) in enumerate(zip(c1.tolist(), phi.tolist(), theta.tolist(), strict=True)):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", ExtrapolationWarning)
            model.features(C1, p, t)
        if not any(issubclass(w.category, ExtrapolationWarning) for w in caught):
            continue
        warned[i] = True
        failed = model.trained.unconverged_beside(C1, p, t) is not None
        softest = not failed and model.trained.softest_beside(C1, p, t) is not None
        kinds[KINDS[0]] += failed
        kinds[KINDS[1]] += softest
        kinds[KINDS[2]] += not (failed or softest)
    cuts = [low, *sorted(e for e in edges if low < e < high), high]
    bands = []
    for lo, hi in zip(cuts[:-1], cuts[1:], strict=True):
        inside = (c1 >= lo) & ((c1 < hi) if hi < high else (c1 <= hi))
        bands.append(CoverageBand(lo, hi, int(inside.sum()), int(warned[inside].sum())))
    return WarningCoverage((low, high), draws, len(phi), int(warned.sum()), kinds, tuple(bands),
                           seed)


def main(argv: list[str] | None = None) -> int:
    """Print the share of a model's trained range where it warns, by C1 band and by kind."""
    from surrogate.exceptions import SurrogateError

    parser = argparse.ArgumentParser(prog="python -m studies.surrogate_study.warning_coverage",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("model", type=Path, help="a model folder")
    parser.add_argument("--draws", type=int, default=DRAWS,
                        help=f"directions drawn (default {DRAWS})")
    parser.add_argument("--seed", type=int, default=SEED)
    parser.add_argument("--bands", type=float, nargs="*", default=list(BAND_EDGES),
                        help="C1 values (kPa) between the bands (default "
                             f"{' '.join(f'{e:g}' for e in BAND_EDGES)})")
    parser.add_argument("--json", type=Path, help="also write the result here")
    args = parser.parse_args(argv)
    try:
        model = Surrogate.load(args.model)
        coverage = warning_coverage(model, args.draws, args.seed, args.bands)
    except (SurrogateError, OSError, ValueError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    if args.json is not None:
        coverage.write(args.json)
    low, high = coverage.c1_kpa
    print(f"{args.model}: {coverage.queries} queries inside the training directions (of "
          f"{coverage.drawn} drawn, seed {coverage.seed}), C1 uniform in [{low:g}, {high:g}] kPa")
    print(f"  warned: {coverage.warned} ({100 * coverage.share:.2f} %)")
    for band in coverage.bands:
        print(f"  C1 in [{band.c1_low:g}, {band.c1_high:g}) kPa: {band.queries:>6} queries, "
              f"{band.warned:>5} warned ({100 * band.share:.2f} %)")
    for kind, count in coverage.kinds.items():
        print(f"  {kind}: {count}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
