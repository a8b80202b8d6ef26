"""How a dataset's cases are split into training, validation and test parts.

By sample (points of cases), by case, by whole gravity directions and by whole C1 values: the
fractions (:class:`SplitFractions`, the paper's 80/10/10), a partition by whole groups
(:func:`group_partition`) and the C1 value the by-C1 split always tests.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from fem.exceptions import DatasetError

SPLITS = ("train", "validation", "test")
SPLIT_KINDS = ("by_sample", "by_case", "by_direction", "by_c1")
"""The dataset's splits: ``by_sample`` holds flat sample indices, the others case indices."""
GROUP_SPLITS = {"by_direction": 1, "by_c1": 2}
"""Splits that hold out whole groups of cases, with the stream of the seed each draws from
(the by-sample and by-case splits draw from stream 0, as before these were added)."""


@dataclass(frozen=True, slots=True)
class SplitFractions:
    """Fractions of the train / validation / test split (the paper's 80/10/10)."""

    train: float = 0.8
    validation: float = 0.1
    test: float = 0.1

    def __post_init__(self) -> None:
        values = (self.train, self.validation, self.test)
        if any(v < 0 for v in values) or self.train <= 0 or self.validation <= 0:
            raise DatasetError(
                "split fractions must be non-negative, train and validation positive"
            )
        if abs(sum(values) - 1.0) > 1e-9:
            raise DatasetError(f"split fractions must add up to 1, got {sum(values):g}")

    def partition(self, n: int, rng: np.random.Generator) -> dict[str, np.ndarray]:
        """Randomly partition ``range(n)`` into sorted index arrays."""
        order = rng.permutation(n)
        n_train = int(round(self.train * n))
        n_val = int(round(self.validation * n))
        if n >= 3:
            n_train = min(max(n_train, 1), n - 2 if self.test > 0 else n - 1)
            n_val = min(max(n_val, 1), n - n_train - (1 if self.test > 0 else 0))
        parts = np.split(order, [n_train, n_train + n_val])
        return {name: np.sort(p).astype(np.int64) for name, p in zip(SPLITS, parts, strict=True)}


@dataclass(frozen=True, slots=True)
class DatasetSplit:
    """The config's ``dataset`` section: the split's fractions and the seed it is drawn with.

    Attributes:
        fractions: the train / validation / test fractions.
        seed: the seed of the random split.
    """

    fractions: SplitFractions = SplitFractions()
    seed: int = 0

    @classmethod
    def from_mapping(cls, section: dict[str, Any]) -> DatasetSplit:
        """Parse the ``dataset`` section ``{seed?, split?: {train, validation, test}}``.

        Raises:
            DatasetError: for fractions that do not split (:class:`SplitFractions`).
        """
        return cls(SplitFractions(**section.get("split", {})), int(section.get("seed", 0)))


def group_partition(
    cases: np.ndarray,
    key: np.ndarray,
    keep_in_training: Sequence[Any],
    split: SplitFractions,
    rng: np.random.Generator,
    always_test: Sequence[Any] = (),
) -> dict[str, np.ndarray]:
    """Partition ``cases`` by whole groups (cases with equal ``key``) into sorted index arrays.

    Groups whose key is in ``keep_in_training`` always train (the ends of a range, so that
    held-out groups are interpolated, not extrapolated); those in ``always_test`` are always
    tested; the others are partitioned by ``split``'s fractions of their number. With fewer
    than three groups free of both there is nothing to hold out: every case trains and the
    other parts are empty.

    Raises:
        ValueError: if a group of ``always_test`` is not among the keys, or must also train.
    """
    unique = np.unique(key)
    kept = np.isin(unique, np.asarray(keep_in_training, dtype=unique.dtype))
    wanted = np.asarray(always_test, dtype=unique.dtype)
    tested = np.isin(unique, wanted)
    if not np.all(np.isin(wanted, unique[~kept])):
        raise ValueError(f"groups {wanted.tolist()} cannot all be tested: the free groups are "
                         f"{unique[~kept].tolist()}")
    free = unique[~kept & ~tested]
    if free.size < 3:
        parts = {"train": unique, "validation": unique[:0], "test": unique[:0]}
    else:
        drawn = split.partition(free.size, rng)
        parts = {name: free[idx] for name, idx in drawn.items()}
        parts["train"] = np.concatenate([parts["train"], unique[kept]])
        parts["test"] = np.concatenate([parts["test"], unique[tested]])
    return {name: np.sort(cases[np.isin(key, groups)]).astype(np.int64)
            for name, groups in parts.items()}


def softest_held_out_c1(c1_values: np.ndarray) -> tuple[float, ...]:
    """The C1 value that the by-C1 split always tests: the softest one it may hold out.

    The softest and the stiffest train (held-out values are interpolated), so it is the second
    softest, where the field changes fastest with C1. None with fewer than six values: the
    split draws from at least three others (:func:`group_partition`), so that it tests more
    than the soft end.
    """
    values = np.unique(np.asarray(c1_values, dtype=float))
    return (float(values[1]),) if values.size >= 6 else ()
