"""The Siamese MLP: a domain network and a boundary network of identical architecture.

Parameters are a plain pytree ``{"domain": [(W, b), ...], "boundary": [(W, b), ...]}``
so that they save as named arrays (no pickle) and load by rebuilding the
skeleton from the hyperparameters.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from surrogate.config import SurrogateConfig
from surrogate.data import N_INPUTS

Params = dict[str, list[tuple[jax.Array, jax.Array]]]
NETWORKS = ("domain", "boundary")

_ACTIVATIONS: dict[str, Callable[[jax.Array], jax.Array]] = {
    "tanh": jnp.tanh,
    "relu": jax.nn.relu,
    "gelu": jax.nn.gelu,
    "silu": jax.nn.silu,
}


def layer_sizes(config: SurrogateConfig) -> list[int]:
    """Input, hidden and output widths of one network."""
    return [N_INPUTS] + [config.width] * config.hidden_layers + [3]


def init_mlp(key: jax.Array, sizes: list[int]) -> list[tuple[jax.Array, jax.Array]]:
    """Glorot-uniform weights and zero biases."""
    layers = []
    for k, (n_in, n_out) in zip(jax.random.split(key, len(sizes) - 1), zip(sizes[:-1], sizes[1:])):
        limit = np.sqrt(6.0 / (n_in + n_out))
        W = jax.random.uniform(k, (n_in, n_out), jnp.float32, -limit, limit)
        layers.append((W, jnp.zeros((n_out,), jnp.float32)))
    return layers


def init_params(key: jax.Array, config: SurrogateConfig) -> Params:
    """Independent initial weights of the two networks."""
    k_domain, k_boundary = jax.random.split(key)
    sizes = layer_sizes(config)
    return {"domain": init_mlp(k_domain, sizes), "boundary": init_mlp(k_boundary, sizes)}


def mlp(layers: list[tuple[jax.Array, jax.Array]], x: jax.Array, activation: str) -> jax.Array:
    """Dense layers with ``activation`` between them and a linear output."""
    act = _ACTIVATIONS[activation]
    for W, b in layers[:-1]:
        x = act(x @ W + b)
    W, b = layers[-1]
    return x @ W + b


def apply(params: Params, x: jax.Array, boundary: jax.Array, activation: str) -> jax.Array:
    """Each sample through its network: boundary points through the boundary network."""
    domain = mlp(params["domain"], x, activation)
    bound = mlp(params["boundary"], x, activation)
    return jnp.where(boundary[:, None], bound, domain)


def pointwise_error(prediction: jax.Array, target: jax.Array) -> jax.Array:
    """Euclidean norm of the error of each sample, smoothed at 0 so its gradient exists."""
    return jnp.sqrt(jnp.sum((prediction - target) ** 2, axis=-1) + 1e-12)


def loss(
    params: Params,
    x: jax.Array,
    target: jax.Array,
    boundary: jax.Array,
    weight: jax.Array,
    alpha: float,
    activation: str,
) -> jax.Array:
    """The paper's Eq. 2, averaged over the batch.

    L = Σ_domain ‖u − û‖₂ + α Σ_boundary ‖u − û‖₂; ``weight`` masks padded samples.
    """
    err = pointwise_error(apply(params, x, boundary, activation), target)
    scale = jnp.where(boundary, alpha, 1.0) * weight
    return jnp.sum(scale * err) / jnp.maximum(jnp.sum(weight), 1.0)


def to_arrays(params: Params) -> dict[str, np.ndarray]:
    """Flatten to named numpy arrays, e.g. ``domain/0/W``."""
    out = {}
    for net in NETWORKS:
        for i, (W, b) in enumerate(params[net]):
            out[f"{net}/{i}/W"] = np.asarray(W)
            out[f"{net}/{i}/b"] = np.asarray(b)
    return out


def from_arrays(arrays: dict[str, Any], config: SurrogateConfig) -> Params:
    """Rebuild parameters from named arrays, checking them against the architecture.

    Raises:
        ValueError: if the arrays belong to another architecture.
    """
    sizes = layer_sizes(config)
    params: Params = {}
    for net in NETWORKS:
        layers = []
        for i, (n_in, n_out) in enumerate(zip(sizes[:-1], sizes[1:])):
            try:
                W, b = arrays[f"{net}/{i}/W"], arrays[f"{net}/{i}/b"]
            except KeyError:
                raise ValueError(
                    f"model arrays lack {net} layer {i}: not a {config.architecture} network"
                ) from None
            if W.shape != (n_in, n_out) or b.shape != (n_out,):
                raise ValueError(
                    f"{net} layer {i} has shape {W.shape}, expected {(n_in, n_out)} "
                    f"for a {config.architecture} network"
                )
            layers.append((jnp.asarray(W), jnp.asarray(b)))
        params[net] = layers
    expected = 2 * len(NETWORKS) * (len(sizes) - 1)
    if len(arrays) != expected:
        raise ValueError(
            f"model has {len(arrays)} arrays, a {config.architecture} network has {expected}"
        )
    return params
