"""Training: Adam with the paper's settings, early stopping, best weights kept.

One epoch is a single jitted ``lax.scan`` over shuffled mini-batches, so the
Python loop runs once per epoch rather than once per step.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from functools import partial
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import optax

from surrogate.config import SurrogateConfig
from surrogate.data import Dataset, Normalisation, sample_arrays
from surrogate.model import Params, apply, init_params, loss, pointwise_error

log = logging.getLogger(__name__)

EVAL_CHUNK = 65536


@dataclass
class TrainResult:
    """A trained surrogate and how it got there."""

    params: Params
    config: SurrogateConfig
    normalisation: Normalisation
    history: list[dict[str, float]] = field(default_factory=list)
    best_epoch: int = 0
    best_validation_loss: float = float("inf")
    validation_error_mm: float = float("nan")
    train_s: float = 0.0
    compile_s: float = 0.0
    train_cases: np.ndarray | None = None

    def summary(self) -> dict[str, Any]:
        """JSON-friendly metrics."""
        return {
            "architecture": self.config.architecture,
            "epochs": len(self.history),
            "best_epoch": self.best_epoch,
            "best_validation_loss": self.best_validation_loss,
            "validation_error_mm": self.validation_error_mm,
            "train_s": self.train_s,
            "compile_s": self.compile_s,
        }


def make_optimizer(config: SurrogateConfig) -> optax.GradientTransformation:
    """Adam with the configured step size and moment decay rates."""
    return optax.adam(config.learning_rate, b1=config.beta1, b2=config.beta2)


def _pad_to(n: int, multiple: int) -> int:
    return -(-n // multiple) * multiple


@partial(jax.jit, static_argnames=("batch_size", "alpha", "activation", "optimizer"))
def _epoch(
    params: Params,
    opt_state: Any,
    key: jax.Array,
    x: jax.Array,
    y: jax.Array,
    b: jax.Array,
    *,
    batch_size: int,
    alpha: float,
    activation: str,
    optimizer: optax.GradientTransformation,
) -> tuple[Params, Any, jax.Array]:
    n = x.shape[0]
    n_batches = -(-n // batch_size)
    perm = jax.random.permutation(key, n)
    # Fill the last batch by wrapping around the permutation: every step has one shape.
    order = jnp.concatenate([perm, perm[: n_batches * batch_size - n]]).reshape(n_batches, batch_size)

    def step(carry, idx):
        params, opt_state = carry
        value, grads = jax.value_and_grad(loss)(
            params, x[idx], y[idx], b[idx], jnp.ones(batch_size), alpha, activation
        )
        updates, opt_state = optimizer.update(grads, opt_state, params)
        return (optax.apply_updates(params, updates), opt_state), value

    (params, opt_state), losses = jax.lax.scan(step, (params, opt_state), order)
    return params, opt_state, jnp.mean(losses)


@partial(jax.jit, static_argnames=("alpha", "activation"))
def _evaluate_chunk(params, x, y, b, w, u_scale, *, alpha, activation):
    pred = apply(params, x, b, activation)
    err = pointwise_error(pred, y)
    scale = jnp.where(b, alpha, 1.0) * w
    return jnp.sum(scale * err), jnp.sum(w * err * u_scale), jnp.sum(w)


def evaluate(
    params: Params, arrays: tuple[np.ndarray, np.ndarray, np.ndarray], config: SurrogateConfig,
    u_scale: float,
) -> tuple[float, float]:
    """Loss (Eq. 2, batch-mean) and mean per-point L2 error in mm over a sample set."""
    x, y, b = arrays
    n = x.shape[0]
    total_loss = total_err = count = 0.0
    for start in range(0, n, EVAL_CHUNK):
        stop = min(start + EVAL_CHUNK, n)
        pad = EVAL_CHUNK - (stop - start)
        w = np.concatenate([np.ones(stop - start, np.float32), np.zeros(pad, np.float32)])
        chunk = [np.concatenate([a[start:stop], np.repeat(a[:1], pad, axis=0)]) for a in (x, y, b)]
        lsum, esum, c = _evaluate_chunk(
            params, *chunk, w, u_scale, alpha=config.alpha, activation=config.activation
        )
        total_loss += float(lsum)
        total_err += float(esum)
        count += float(c)
    return total_loss / count, total_err / count


def train_and_evaluate(
    ds: Dataset, config: SurrogateConfig, progress: bool = True
) -> TrainResult:
    """Train the Siamese MLP on ``ds`` following ``config``; returns the best weights.

    Raises:
        ValueError: if the chosen split has no training or validation samples.
    """
    train_idx = ds.sample_indices(config.split, "train")
    val_idx = ds.sample_indices(config.split, "validation")
    if train_idx.size == 0 or val_idx.size == 0:
        raise ValueError(f"split {config.split!r} has no training or validation samples")
    train_cases = np.unique(train_idx // ds.n_points)
    norm = Normalisation.fit(ds, train_cases)
    train = sample_arrays(ds, train_idx, norm)
    val = sample_arrays(ds, val_idx, norm)
    batch = min(config.batch_size, train_idx.size)

    key = jax.random.PRNGKey(config.seed)
    key, init_key = jax.random.split(key)
    params = init_params(init_key, config)
    optimizer = make_optimizer(config)
    opt_state = optimizer.init(params)
    x, y, b = (jnp.asarray(a) for a in train)

    result = TrainResult(params=params, config=config, normalisation=norm, train_cases=train_cases)
    best = (float("inf"), params, 0)
    since_best = 0
    bar = _progress(config.max_epochs, progress)
    start = time.perf_counter()
    for epoch in range(1, config.max_epochs + 1):
        t0 = time.perf_counter()
        key, epoch_key = jax.random.split(key)
        params, opt_state, train_loss = _epoch(
            params, opt_state, epoch_key, x, y, b,
            batch_size=batch, alpha=config.alpha, activation=config.activation, optimizer=optimizer,
        )
        train_loss = float(train_loss)
        if epoch == 1:
            result.compile_s = time.perf_counter() - t0
        val_loss, val_err = evaluate(params, val, config, norm.u_scale)
        result.history.append(
            {
                "epoch": epoch,
                "train_loss": train_loss,
                "validation_loss": val_loss,
                "validation_error_mm": val_err,
                "epoch_s": time.perf_counter() - t0,
            }
        )
        if bar is not None:
            bar.set_postfix(train=f"{train_loss:.4g}", val=f"{val_loss:.4g}", err_mm=f"{val_err:.3f}")
            bar.update(1)
        if not np.isfinite(train_loss):
            log.warning("training diverged at epoch %d (loss %s)", epoch, train_loss)
            break
        if val_loss < best[0]:
            best, since_best = (val_loss, params, epoch), 0
        else:
            since_best += 1
            if since_best >= config.patience:
                log.info("early stop at epoch %d (best %d)", epoch, best[2])
                break
    if bar is not None:
        bar.close()
    result.train_s = time.perf_counter() - start
    result.best_validation_loss, result.params, result.best_epoch = best
    result.validation_error_mm = evaluate(result.params, val, config, norm.u_scale)[1]
    log.info(
        "%s: best epoch %d, validation error %.4f mm, %.1f s",
        config.architecture, result.best_epoch, result.validation_error_mm, result.train_s,
    )
    return result


def _progress(total: int, enabled: bool) -> Any:
    if not enabled:
        return None
    from tqdm import tqdm

    return tqdm(total=total, desc="epochs", unit="epoch", mininterval=1.0)
