"""Training: Adam with the paper's settings, early stopping, best weights kept.

The paper's protocol is the default: Adam (learning rate 0.01, β1 = 0.5, β2 = 0.9),
batches of 8000 samples, at most 200 epochs, early stopping with patience 20 on the
validation loss (Eq. 2), best weights kept. A learning-rate schedule is an option.

Each batch holds domain and boundary samples in their training proportions, as the
authors' code draws one batch from each set per step; every network is then
evaluated only on its own samples (:func:`surrogate.model.split_loss`). One epoch is
a single jitted ``lax.scan`` over :func:`train_step`, so Python runs once per epoch.
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
from surrogate.model import (
    Params,
    Part,
    PointOrder,
    boundary_network,
    grid_loss,
    init_params,
    pointwise_error,
    samples_network,
    split_loss,
)

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
    params = init_params(init_key, config)
    optimizer = make_optimizer(config, steps_per_epoch)
    return params, optimizer, optimizer.init(params), key


def train_step(
    params: Params,
    opt_state: Any,
    domain: Part,
    boundary: Part | None,
    tables: Tables,
    *,
    config: SurrogateConfig,
    optimizer: optax.GradientTransformation,
) -> tuple[Params, Any, jax.Array]:
    """One Adam step on one batch (domain part and boundary part); returns the loss."""
    value, grads = jax.value_and_grad(split_loss)(params, domain, boundary, config, tables)
    updates, opt_state = optimizer.update(grads, opt_state, params)
    return optax.apply_updates(params, updates), opt_state, value


def _batches(key: jax.Array, n: int, per_step: int, steps: int) -> jax.Array:
    """Shuffled indices (steps, per_step), wrapping around so that every step has one shape."""
    perm = jax.random.permutation(key, n)
    reps = -(-steps * per_step // n)
    return jnp.tile(perm, reps)[: steps * per_step].reshape(steps, per_step)


@partial(jax.jit, static_argnames=("config", "optimizer", "per_step", "steps"))
def train_epoch(
    params: Params,
    opt_state: Any,
    key: jax.Array,
    domain: Part,
    boundary: Part | None,
    tables: Tables,
    *,
    config: SurrogateConfig,
    optimizer: optax.GradientTransformation,
    per_step: tuple[int, int],
    steps: int,
) -> tuple[Params, Any, jax.Array]:
    """One pass over the training samples: a ``lax.scan`` of :func:`train_step`."""
    k_domain, k_boundary = jax.random.split(key)
    order_d = _batches(k_domain, domain[0].shape[0], per_step[0], steps)
    if boundary is None:
        order_b = jnp.zeros((steps, 0), jnp.int32)
    else:
        order_b = _batches(k_boundary, boundary[0].shape[0], per_step[1], steps)

    def step(carry, idx):
        params, opt_state = carry
        i_d, i_b = idx
        part_b = None if boundary is None else tuple(a[i_b] for a in boundary)
        params, opt_state, value = train_step(
            params,
            opt_state,
            tuple(a[i_d] for a in domain),
            part_b,
            tables,
            config=config,
            optimizer=optimizer,
        )
        return (params, opt_state), value

    (params, opt_state), losses = jax.lax.scan(step, (params, opt_state), (order_d, order_b))
    return params, opt_state, jnp.mean(losses)


PART_FIELDS = ("x", "y", "gain", "point", "case")
"""The :class:`Samples` fields of a batch part, in :data:`surrogate.model.Part` order."""


def case_grid(
    samples: Samples, n_points: int, use_rib: bool
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Training samples laid out as whole cases for a separable model's :func:`grid_loss`.

    Returns ``(case rows (C,), targets (C, N, 3), gains (C, N), member (C, N))``: ``member``
    marks the (case, point) pairs that are training samples; rib samples are left out where
    no network predicts them (``use_rib`` False), as the pointwise path leaves them out.
    """
    cases, row = np.unique(samples.case, return_inverse=True)
    y = np.zeros((len(cases), n_points, 3), np.float32)
    gain = np.zeros((len(cases), n_points), np.float32)
    member = np.zeros((len(cases), n_points), np.float32)
    y[row, samples.point] = samples.y
    gain[row, samples.point] = samples.gain
    member[row, samples.point] = 1.0 if use_rib else (~samples.boundary).astype(np.float32)
    return cases.astype(np.int32), y, gain, member


def point_order(boundary: np.ndarray) -> PointOrder:
    """The rows each point network of a separable model takes (:class:`PointOrder`)."""
    domain, rib = np.flatnonzero(~boundary), np.flatnonzero(boundary)
    inverse = np.argsort(np.concatenate([domain, rib]))
    return PointOrder(*(jnp.asarray(a.astype(np.int32)) for a in (domain, rib, inverse)),
                      jnp.asarray(boundary, bool))


@partial(jax.jit, static_argnames=("config", "optimizer", "per_step", "steps"))
def train_epoch_grid(
    params: Params,
    opt_state: Any,
    key: jax.Array,
    grid: tuple[jax.Array, jax.Array, jax.Array, jax.Array],
    order: PointOrder,
    tables: Tables,
    *,
    config: SurrogateConfig,
    optimizer: optax.GradientTransformation,
    per_step: int,
    steps: int,
) -> tuple[Params, Any, jax.Array]:
    """One pass over a separable model's training cases, ``per_step`` whole cases a step."""

    def step(carry, idx):
        params, opt_state = carry
        batch = tuple(a[idx] for a in grid)
        value, grads = jax.value_and_grad(grid_loss)(params, batch, tables, order, config)
        updates, opt_state = optimizer.update(grads, opt_state, params)
        return (optax.apply_updates(params, updates), opt_state), value

    order_c = _batches(key, grid[0].shape[0], per_step, steps)
    (params, opt_state), losses = jax.lax.scan(step, (params, opt_state), order_c)
    return params, opt_state, jnp.mean(losses)


@partial(jax.jit, static_argnames=("net", "config"))
def _error_sum(params, part, w, tables, *, net, config):
    y, g = part[1], part[2]
    pred = (
        jnp.zeros_like(y)
        if net is None
        else samples_network(params, net, part, tables, config) * g[:, None]
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
    for on_boundary, net in ((False, "domain"), (True, boundary_network(config))):
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

    A ``pod`` model is fitted by :func:`surrogate.pod.train_pod`.

    Raises:
        ValueError: if the chosen split has no training or validation samples, or
            ``refit_epochs`` is not a positive integer.
    """
    if refit_epochs is not None and (isinstance(refit_epochs, bool)
                                     or not isinstance(refit_epochs, int) or refit_epochs < 1):
        raise ValueError(f"refit_epochs must be a positive integer, got {refit_epochs!r}")
    if config.structure == "pod":
        from surrogate.pod import train_pod  # it builds on this module

        return train_pod(ds, config, progress, holdout, refit_epochs)
    start = time.perf_counter()
    norm, phi, train, val, train_cases = prepare(ds, config, holdout, refit_epochs is not None)
    inputs = Tables(*(jnp.asarray(a) for a in tables(ds, norm)))
    use_boundary = boundary_network(config) is not None and bool(np.any(train.boundary))
    if config.structure == "separable":
        grid = case_grid(train, ds.n_points, use_boundary)
        per_step = max(1, min(round(config.batch_size / ds.n_points), len(grid[0])))
        steps = -(-len(grid[0]) // per_step)
        data: tuple[Any, ...] = (tuple(jnp.asarray(a) for a in grid), point_order(ds.boundary))
        epoch = train_epoch_grid
        what = f"{len(grid[0])} cases on {ds.n_points} points, {steps} steps of {per_step} cases"
    else:
        domain = train.subset(~train.boundary)
        bset = train.subset(train.boundary)
        n_used = len(domain) + (len(bset) if use_boundary else 0)
        batch = min(config.batch_size, n_used)
        steps = -(-n_used // batch)
        per_b = max(1, round(batch * len(bset) / n_used)) if use_boundary else 0
        per_step = (batch - per_b, per_b)
        data = (
            tuple(jnp.asarray(getattr(domain, f)) for f in PART_FIELDS),
            tuple(jnp.asarray(getattr(bset, f)) for f in PART_FIELDS) if use_boundary else None,
        )
        epoch = train_epoch
        what = f"{steps} steps of {per_step} samples"

    params, optimizer, opt_state, key = init(config, steps)
    schedule = learning_rate_schedule(config, steps)
    kwargs = dict(config=config, optimizer=optimizer, per_step=per_step, steps=steps)

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
        config.structure,
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
