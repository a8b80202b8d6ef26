"""Training: Adam with the paper's settings, early stopping, best weights kept.

The paper's protocol is the default: Adam (learning rate 0.01, β1 = 0.5, β2 = 0.9),
batches of 8000 samples, at most 200 epochs, early stopping with patience 20 on the
validation loss (Eq. 2), best weights kept. A learning-rate schedule is an option.

Each batch holds domain and boundary samples in their training proportions, as the
authors' code draws one batch from each set per step; every network is then
evaluated only on its own samples (:meth:`surrogate.structures.base.Structure.split_loss`). One
epoch is a single jitted ``lax.scan``, the structure's (its ``epoch_plan``), so Python runs once
per epoch. A ``pod`` model trains its own way
(:mod:`surrogate.structures.pod`).
All randomness (initial weights, shuffling) is split from ``config.seed``.
"""

from __future__ import annotations

import logging
import time
from functools import partial
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import optax

from fem.dataset import Dataset
from surrogate.config import SurrogateConfig
from surrogate.data import Normalisation, Samples, Tables, dirichlet_factor, sample_arrays, tables
from surrogate.epochs import (
    EpochFigures,
    TrainResult,
    learning_rate_schedule,
    make_optimizer,
    run_epochs,
)
from surrogate.model import Params, pointwise_error
from surrogate.structures import structure_for

log = logging.getLogger(__name__)

EVAL_CHUNK = 32768


def init(
    config: SurrogateConfig, steps_per_epoch: int
) -> tuple[Params, optax.GradientTransformation, Any, jax.Array]:
    """Initial weights, optimiser, its state, and the key of the shuffling.

    Both the weights and the shuffling key are split from ``config.seed``.
    """
    key = jax.random.PRNGKey(config.seed)
    key, init_key = jax.random.split(key)
    params = structure_for(config).init_params(init_key)
    optimizer = make_optimizer(config, steps_per_epoch)
    return params, optimizer, optimizer.init(params), key


def batches(key: jax.Array, n: int, per_step: int, steps: int) -> jax.Array:
    """Shuffled indices (steps, per_step), wrapping around so that every step has one shape."""
    perm = jax.random.permutation(key, n)
    reps = -(-steps * per_step // n)
    return jnp.tile(perm, reps)[: steps * per_step].reshape(steps, per_step)


@partial(jax.jit, static_argnames=("net", "config"))
def _error_sum(params, part, w, tables, *, net, config):
    y, g = part[1], part[2]
    pred = (
        jnp.zeros_like(y)
        if net is None
        else structure_for(config).samples_network(params, net, part, tables) * g[:, None]
    )
    return jnp.sum(w * pointwise_error(pred, y))


def error_sums(
    params: Params, samples: Samples, config: SurrogateConfig, tables: Tables
) -> tuple[float, float]:
    """Sums of the error norm (scaled units) over the domain and the boundary samples.

    Evaluated in fixed-size chunks (zero-weight padding) so that one compilation serves
    every set.
    """
    sums = []
    for on_boundary, net in ((False, "domain"), (True, structure_for(config).boundary_network())):
        part = samples.subset(samples.boundary == on_boundary)
        total = 0.0
        for start in range(0, len(part), EVAL_CHUNK):
            stop = min(start + EVAL_CHUNK, len(part))
            pad = EVAL_CHUNK - (stop - start)
            chunk = [
                np.concatenate([a[start:stop], np.zeros((pad, *a.shape[1:]), a.dtype)])
                for a in (part.x, part.y, part.gain, part.point, part.case)
            ]
            w = np.concatenate([np.ones(stop - start, np.float32), np.zeros(pad, np.float32)])
            total += float(_error_sum(params, tuple(chunk), w, tables, net=net, config=config))
        sums.append(total)
    return sums[0], sums[1]


def evaluate(
    params: Params, samples: Samples, config: SurrogateConfig, u_scale: float, tables: Tables
) -> dict[str, float]:
    """Loss (Eq. 2, sample mean, scaled units) and mean per-point error norms in mm."""
    domain, boundary = error_sums(params, samples, config, tables)
    n = max(len(samples), 1)
    n_domain = max(int(np.sum(~samples.boundary)), 1)
    return {
        "loss": (domain + config.alpha * boundary) / n,
        "error_mm": (domain + boundary) * u_scale / n,
        "domain_error_mm": domain * u_scale / n_domain,
    }


def prepare(
    ds: Dataset, config: SurrogateConfig, holdout: np.ndarray | None = None,
    refit: bool = False,
) -> tuple[Normalisation, np.ndarray | None, Samples, Samples, np.ndarray]:
    """Normalisation, point factor φ, training and validation samples, training cases.

    Args:
        ds: the dataset.
        config: hyperparameters (split, boundary mode, encodings).
        holdout: case indices to keep out of training and validation (e.g. the
            clinical cases of a by-case evaluation).
        refit: the validation samples train too (they are still returned, to report on).

    Raises:
        ValueError: if the chosen split has no training or validation samples left.
    """
    train_idx = ds.sample_indices(config.split, "train")
    val_idx = ds.sample_indices(config.split, "validation")
    if holdout is not None and len(holdout):
        keep = lambda idx: idx[~np.isin(idx // ds.n_points, holdout)]  # noqa: E731
        train_idx, val_idx = keep(train_idx), keep(val_idx)
    if train_idx.size == 0 or val_idx.size == 0:
        raise ValueError(f"split {config.split!r} has no training or validation samples")
    if refit:
        train_idx = np.union1d(train_idx, val_idx)
    train_cases = np.unique(train_idx // ds.n_points)
    norm = Normalisation.fit(ds, train_cases, config.c1_encoding, config.output_scaling)
    phi = (
        dirichlet_factor(ds.X, ds.boundary, config.bc_length)
        if config.boundary == "exact"
        else None
    )
    return (
        norm,
        phi,
        sample_arrays(ds, train_idx, norm, phi),
        sample_arrays(ds, val_idx, norm, phi),
        train_cases,
    )


def train_and_evaluate(
    ds: Dataset, config: SurrogateConfig, progress: bool = True, holdout: np.ndarray | None = None,
    refit_epochs: int | None = None,
) -> TrainResult:
    """Train the surrogate on ``ds`` following ``config``; returns the best weights.

    Args:
        ds: the dataset.
        config: hyperparameters and protocol.
        progress: show a progress bar with the epoch losses.
        holdout: case indices kept out of training and validation.
        refit_epochs: train on the split's validation data too, for this many epochs (the best
            epoch a run of the same config chose on that validation data), and keep the last
            weights: the model used downstream, once the validation has done its work of
            choosing the architecture and the epochs. None: train on the training part and
            keep the weights of the lowest validation loss (a ``pod`` model: of the lowest
            validation error in mm).

    The model's structure trains it (:meth:`surrogate.structures.base.Structure.train`): a
    ``pod`` model by :func:`surrogate.structures.pod.train_pod`, the others by
    :func:`train_networks`.

    Raises:
        ValueError: if the chosen split has no training or validation samples, or
            ``refit_epochs`` is not a positive integer.
    """
    if refit_epochs is not None and (isinstance(refit_epochs, bool)
                                     or not isinstance(refit_epochs, int) or refit_epochs < 1):
        raise ValueError(f"refit_epochs must be a positive integer, got {refit_epochs!r}")
    return structure_for(config).train(ds, progress, holdout, refit_epochs)


def train_networks(
    structure: Any, ds: Dataset, progress: bool = True,
    holdout: np.ndarray | None = None, refit_epochs: int | None = None,
) -> TrainResult:
    """Train a structure of point networks (:meth:`Structure.train`'s default).

    ``structure`` is a :class:`surrogate.structures.base.Structure` (not imported: the
    structures build on this loop).

    Adam on its epochs (:meth:`Structure.epoch_plan`), early stopping on the validation loss,
    best weights kept; with ``refit_epochs``, that many epochs on the training and validation
    samples, the last weights kept (:func:`train_and_evaluate`).
    """
    config = structure.config
    start = time.perf_counter()
    norm, phi, train, val, train_cases = prepare(ds, config, holdout, refit_epochs is not None)
    inputs = Tables(*(jnp.asarray(a) for a in tables(ds, norm)))
    use_boundary = structure.boundary_network() is not None and bool(np.any(train.boundary))
    epoch, data, per_step, steps, what = structure.epoch_plan(train, ds.n_points, ds.boundary,
                                                              use_boundary)

    params, optimizer, opt_state, key = init(config, steps)
    schedule = learning_rate_schedule(config, steps)
    kwargs = dict(structure=structure, optimizer=optimizer, per_step=per_step, steps=steps)

    result = TrainResult(
        params=params,
        config=config,
        normalisation=norm,
        point_factor=phi,
        train_cases=train_cases,
        held_out_cases=None if holdout is None else np.asarray(holdout),
    )
    t0 = time.perf_counter()
    epoch_fn = epoch.lower(params, opt_state, key, *data, inputs, **kwargs).compile()
    result.compile_s = time.perf_counter() - t0
    log.info(
        "%s %s (%s boundary): %d training samples (%d on the rib), %s per epoch, "
        "compiled in %.1f s",
        config.architecture,
        structure.name,
        config.boundary,
        len(train),
        int(np.sum(train.boundary)),
        what,
        result.compile_s,
    )

    def one_epoch() -> tuple[Params, EpochFigures]:
        nonlocal params, opt_state, key
        key, epoch_key = jax.random.split(key)
        params, opt_state, train_loss = epoch_fn(params, opt_state, epoch_key, *data, inputs)
        metrics = evaluate(params, val, config, norm.u_scale, inputs)
        return params, EpochFigures(float(train_loss), metrics["loss"], metrics["error_mm"])

    run_epochs(one_epoch, params, config, result, schedule=schedule, steps=steps,
               refit_epochs=refit_epochs, progress=progress, select="validation_loss")
    result.train_s = time.perf_counter() - start
    final = evaluate(result.params, val, config, norm.u_scale, inputs)
    result.validation_error_mm = final["error_mm"]
    result.validation_error_domain_mm = final["domain_error_mm"]
    log.info(
        "%s: best epoch %d of %d, validation error %.4f mm (%.4f mm off the rib), %.1f s",
        config.architecture,
        result.best_epoch,
        len(result.history),
        result.validation_error_mm,
        result.validation_error_domain_mm,
        result.train_s,
    )
    return result
