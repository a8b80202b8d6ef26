"""What every structure's training shares: its result, its optimiser and its epoch loop.

:func:`surrogate.train.train_networks` trains the point networks with it, and
:func:`surrogate.structures.pod.train_pod` the ``pod`` model's weights: both build on this module,
which neither of them is, so that neither imports the other's internals.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import optax

from surrogate.config import SurrogateConfig
from surrogate.data import Normalisation
from surrogate.model import Params

log = logging.getLogger(__name__)


@dataclass
class TrainResult:
    """A trained surrogate and how it got there.

    Attributes:
        params: the best weights (lowest validation loss; a ``pod`` model's lowest validation
            error in mm, :mod:`surrogate.pod`).
        config: hyperparameters.
        normalisation: input/output maps fitted on the training cases.
        point_factor: per-point output factor φ of the exact Dirichlet mode (None otherwise).
        history: per-epoch losses, validation error (mm), learning rate and time.
        best_epoch: epoch of the best weights.
        best_validation_loss: Eq. 2 (batch mean, scaled units) at the best epoch.
        validation_error_mm: mean per-point error norm over the validation samples, mm.
        validation_error_domain_mm: the same over validation points off the rib only.
        train_s: wall time of the whole training, compilation included.
        compile_s: wall time of compiling the epoch.
        train_cases: case indices the normalisation and training range come from.
        held_out_cases: case indices excluded from training and validation.
        basis: a ``pod`` model's modes at the points (N, 3, modes), in units of the
            displacement scale per unit weight (:mod:`surrogate.pod`); None for the others.
        node_basis: a ``pod`` model's modes at every node of its dataset's quadratic mesh
            (K, 3, modes), where it was fitted there; else None.
        refit: whether it trained on its validation data too, for a number of epochs chosen
            before (:func:`train_and_evaluate`'s ``refit_epochs``): its validation error is
            then measured on data it trained on.
    """

    params: Params
    config: SurrogateConfig
    normalisation: Normalisation
    point_factor: np.ndarray | None = None
    history: list[dict[str, float]] = field(default_factory=list)
    best_epoch: int = 0
    best_validation_loss: float = float("inf")
    validation_error_mm: float = float("nan")
    validation_error_domain_mm: float = float("nan")
    train_s: float = 0.0
    compile_s: float = 0.0
    train_cases: np.ndarray | None = None
    held_out_cases: np.ndarray | None = None
    basis: np.ndarray | None = None
    node_basis: np.ndarray | None = None
    refit: bool = False

    def summary(self) -> dict[str, Any]:
        """JSON-friendly metrics."""
        return {
            "architecture": self.config.architecture,
            "boundary": self.config.boundary,
            "split": self.config.split,
            "seed": self.config.seed,
            "epochs": len(self.history),
            "best_epoch": self.best_epoch,
            "best_validation_loss": self.best_validation_loss,
            "validation_error_mm": self.validation_error_mm,
            "validation_error_domain_mm": self.validation_error_domain_mm,
            "train_s": self.train_s,
            "compile_s": self.compile_s,
            "n_train_cases": 0 if self.train_cases is None else int(self.train_cases.size),
            "held_out_cases": [] if self.held_out_cases is None else self.held_out_cases.tolist(),
            "refit": self.refit,
        }


def learning_rate_schedule(config: SurrogateConfig, steps_per_epoch: int) -> optax.Schedule:
    """Learning rate per optimisation step."""
    if config.lr_schedule == "cosine":
        return optax.cosine_decay_schedule(
            config.learning_rate,
            decay_steps=config.max_epochs * steps_per_epoch,
            alpha=config.lr_final,
        )
    if config.lr_schedule == "exponential":
        return optax.exponential_decay(
            config.learning_rate,
            transition_steps=steps_per_epoch,
            decay_rate=config.lr_final ** (1.0 / config.max_epochs),
            staircase=True,
        )
    return optax.constant_schedule(config.learning_rate)


def make_optimizer(
    config: SurrogateConfig, steps_per_epoch: int = 1
) -> optax.GradientTransformation:
    """Adam with the configured step size (or schedule) and moment decay rates."""
    return optax.adam(
        learning_rate_schedule(config, steps_per_epoch), b1=config.beta1, b2=config.beta2
    )


@dataclass(frozen=True)
class EpochFigures:
    """What one epoch of training reports: its training loss and its validation figures."""

    train_loss: float
    validation_loss: float
    validation_error_mm: float


def run_epochs(
    one_epoch: Callable[[], tuple[Any, EpochFigures]], params: Any, config: SurrogateConfig,
    result: TrainResult, *, schedule: optax.Schedule, steps: int, refit_epochs: int | None,
    progress: bool, select: str,
) -> None:
    """The epoch loop every structure trains in: early stopping, or a refit's fixed epochs.

    Each call of ``one_epoch`` trains one epoch and returns the weights and their figures; the
    loop appends them to ``result.history`` (with the learning rate at the epoch's first of
    ``steps`` steps and the epoch's time) and stops when training diverges, after
    ``config.max_epochs``, or ``config.patience`` epochs after the best. The best epoch is the
    one of the lowest ``select`` figure (``"validation_loss"`` or ``"validation_error_mm"``);
    with ``refit_epochs``, the last of that many epochs. Its weights, validation loss and
    epoch go into ``result`` (``params``, ``best_validation_loss``, ``best_epoch``), with
    ``result.refit``. ``params`` are the weights before the first epoch.
    """
    if select not in ("validation_loss", "validation_error_mm"):
        raise ValueError(f"select must be validation_loss or validation_error_mm, got {select!r}")
    best: EpochFigures | None = None  # the best epoch's figures; None before there is one
    best_params, best_epoch, since_best = params, 0, 0
    bar = progress_bar(config.max_epochs, progress, config.architecture)
    for epoch in range(1, config.max_epochs + 1):
        t0 = time.perf_counter()
        params, figures = one_epoch()
        result.history.append({
            "epoch": epoch, "train_loss": figures.train_loss,
            "validation_loss": figures.validation_loss,
            "validation_error_mm": figures.validation_error_mm,
            "learning_rate": float(schedule((epoch - 1) * steps)),
            "epoch_s": time.perf_counter() - t0,
        })
        if bar is not None:
            bar.set_postfix(train=f"{figures.train_loss:.4g}", val=f"{figures.validation_loss:.4g}",
                            err_mm=f"{figures.validation_error_mm:.4f}")
            bar.update(1)
        if not np.isfinite(figures.train_loss):
            log.warning("training diverged at epoch %d (loss %s)", epoch, figures.train_loss)
            break
        if refit_epochs is not None:  # the epochs a validation chose before: the last weights
            best, best_params, best_epoch = figures, params, epoch
            if epoch >= refit_epochs:
                break
        elif getattr(figures, select) < (float("inf") if best is None else getattr(best, select)):
            best, best_params, best_epoch, since_best = figures, params, epoch, 0
        else:
            since_best += 1
            if since_best >= config.patience:
                log.info("early stop at epoch %d (best %d)", epoch, best_epoch)
                break
    if bar is not None:
        bar.close()
    result.refit = refit_epochs is not None
    result.params, result.best_epoch = best_params, best_epoch
    result.best_validation_loss = float("inf") if best is None else best.validation_loss


def progress_bar(total: int, enabled: bool, label: str) -> Any:
    """A tqdm bar over the epochs, or None when not ``enabled``."""
    if not enabled:
        return None
    from tqdm import tqdm

    return tqdm(total=total, desc=f"{label} epochs", unit="epoch", mininterval=1.0)
