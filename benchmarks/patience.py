"""Where early stopping would have stopped finished trainings, and what it would have kept.

    python -m benchmarks.patience RUN [RUN ...] [--patience 20 50 100 200]

Each RUN is a model folder (or its ``history.json``) of a training that ran its whole
``max_epochs``. The epoch loop (:func:`surrogate.epochs.run_epochs`) keeps the epoch of the
lowest validation figure and stops ``patience`` epochs after it; the epochs up to a stop are
the same whether or not the run goes on, so replaying that rule on a whole run's history gives
exactly what a run with that patience would have kept: the epoch it stops at, its best
validation error, and that error over the whole run's best. The figure is the validation
error in mm (what a pod model selects its epoch by), or ``--figure validation_loss``.
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Sequence
from pathlib import Path

import numpy as np


def replay(values: Sequence[float], patience: int) -> tuple[int, int]:
    """The epoch a run stops at under ``patience``, and its best epoch then (1-based)."""
    best, best_epoch, since = np.inf, 0, 0
    for epoch, value in enumerate(values, start=1):
        if value < best:
            best, best_epoch, since = value, epoch, 0
        else:
            since += 1
            if since >= patience:
                return epoch, best_epoch
    return len(values), best_epoch


def history_of(run: Path) -> list[dict]:
    """The per-epoch records of a model folder or of its ``history.json``."""
    path = run / "history.json" if run.is_dir() else run
    data = json.loads(path.read_text())
    return data["history"] if isinstance(data, dict) else data


def main(argv: Sequence[str] | None = None) -> None:
    """Print, for each run and patience, the stop, the error kept and its ratio."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("runs", nargs="+", type=Path)
    parser.add_argument("--patience", nargs="+", type=int, default=[20, 50, 100, 200, 300])
    parser.add_argument("--figure", default="validation_error_mm",
                        choices=["validation_error_mm", "validation_loss"])
    args = parser.parse_args(argv)
    print(f"{'run':<50} {'patience':>8} {'stops at':>8} {'of':>5} {'kept (mm)':>10} "
          f"{'over whole run':>14}")
    for run in args.runs:
        values = [r[args.figure] for r in history_of(run)]
        whole = min(values)
        for patience in args.patience:
            stop, best = replay(values, patience)
            print(f"{str(run)[-50:]:<50} {patience:>8} {stop:>8} {len(values):>5} "
                  f"{values[best - 1]:>10.5f} {values[best - 1] / whole:>14.3f}")


if __name__ == "__main__":
    main()
