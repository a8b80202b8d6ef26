"""The Siamese MLP: a domain network and a boundary network of identical architecture.

Parameters are a plain pytree ``{"domain": [(W, b), ...], "boundary": [(W, b), ...]}``
so that they save as named arrays (no pickle) and load by rebuilding the
skeleton from the hyperparameters.

How the clamped rib surface (the homogeneous Dirichlet condition) is learnt depends
on ``SurrogateConfig.boundary``:

* ``network`` — the paper's pair: the boundary network predicts the points on the
  rib, trained towards zero with weight α; the domain network predicts all others.
* ``shared`` — one network (``"domain"``) for both point sets; the α-weighted
  boundary term pulls that same function to zero on the rib. This is weight sharing,
  as in the authors' public training code.
* ``exact`` — one network whose output is multiplied by a per-point factor φ that is
  0 on the rib (:func:`surrogate.data.dirichlet_factor`): the condition holds by
  construction and the boundary term of Eq. 2 vanishes.

Every prediction is ``network(x) * gain``, where ``gain`` holds φ (exact mode) and
the compliance scaling (``output_scaling``), both precomputed per sample. A network's output
is the displacement itself (``output_form: vector``) or, in ``gravity_linear`` form, nine
numbers read as a matrix M that multiplies the input's unit gravity direction ĝ:
``network(x) = M(x) ĝ``, linear in ĝ as a linear-elastic body's response to its load is, so
that the network learns from direction to direction only what the nonlinearity changes.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from surrogate.config import SurrogateConfig
from surrogate.data import DIRECTION, N_INPUTS

Layers = list[tuple[jax.Array, jax.Array]]
Params = dict[str, Layers]
NETWORKS = ("domain", "boundary")

ACTIVATIONS: dict[str, Callable[[jax.Array], jax.Array]] = {
    "tanh": jnp.tanh,
    "relu": jax.nn.relu,
    "gelu": jax.nn.gelu,
    "silu": jax.nn.silu,
}


def network_names(config: SurrogateConfig) -> tuple[str, ...]:
    """Networks a config has: both in ``network`` mode, only ``domain`` otherwise."""
    return NETWORKS if config.boundary == "network" else ("domain",)


def boundary_network(config: SurrogateConfig) -> str | None:
    """Network that predicts the clamped points (None: they are exactly zero)."""
    return {"network": "boundary", "shared": "domain", "exact": None}[config.boundary]


def output_width(config: SurrogateConfig) -> int:
    """Outputs of one network: the displacement (3) or the matrix that multiplies ĝ (9)."""
    return 9 if config.output_form == "gravity_linear" else 3


def layer_sizes(config: SurrogateConfig) -> list[int]:
    """Input, hidden and output widths of one network."""
    return [N_INPUTS] + [config.width] * config.hidden_layers + [output_width(config)]


def init_mlp(key: jax.Array, sizes: list[int]) -> Layers:
    """Glorot-uniform weights and zero biases."""
    layers = []
    keys = jax.random.split(key, len(sizes) - 1)
    for k, (n_in, n_out) in zip(keys, zip(sizes[:-1], sizes[1:], strict=False), strict=True):
        limit = np.sqrt(6.0 / (n_in + n_out))
        W = jax.random.uniform(k, (n_in, n_out), jnp.float32, -limit, limit)
        layers.append((W, jnp.zeros((n_out,), jnp.float32)))
    return layers


def init_params(key: jax.Array, config: SurrogateConfig) -> Params:
    """Independent initial weights of the networks (split from one key)."""
    keys = jax.random.split(key, len(NETWORKS))
    sizes = layer_sizes(config)
    names = network_names(config)
    return {net: init_mlp(k, sizes) for net, k in zip(NETWORKS, keys, strict=True) if net in names}


def mlp(layers: Layers, x: jax.Array, activation: str) -> jax.Array:
    """Dense layers with ``activation`` between them and a linear output."""
    act = ACTIVATIONS[activation]
    for W, b in layers[:-1]:
        x = act(x @ W + b)
    W, b = layers[-1]
    return x @ W + b


def network(layers: Layers, x: jax.Array, config: SurrogateConfig) -> jax.Array:
    """One network's displacement (n, 3) before the gain.

    Its outputs, or M ĝ in ``gravity_linear`` form (output ``3 i + j`` is M's entry (i, j)).
    """
    out = mlp(layers, x, config.activation)
    if config.output_form == "gravity_linear":
        out = jnp.einsum("nij,nj->ni", out.reshape(-1, 3, 3), x[:, DIRECTION])
    return out


def apply(
    params: Params, x: jax.Array, boundary: jax.Array, gain: jax.Array, config: SurrogateConfig
) -> jax.Array:
    """Prediction of mixed samples, each through the network its point belongs to.

    Args:
        params: the networks.
        x: inputs (n, 7).
        boundary: clamped flags (n,).
        gain: output multipliers (n,) (see the module docstring).
        config: architecture and boundary mode.
    """
    domain = network(params["domain"], x, config)
    net = boundary_network(config)
    if net is None:
        bound = jnp.zeros_like(domain)
    elif net == "domain":
        bound = domain
    else:
        bound = network(params[net], x, config)
    return jnp.where(boundary[:, None], bound, domain) * gain[:, None]


def pointwise_error(prediction: jax.Array, target: jax.Array) -> jax.Array:
    """Euclidean norm of the error of each sample, smoothed at 0 so its gradient exists."""
    return jnp.sqrt(jnp.sum((prediction - target) ** 2, axis=-1) + 1e-12)


def split_loss(
    params: Params,
    domain: tuple[jax.Array, jax.Array, jax.Array],
    boundary: tuple[jax.Array, jax.Array, jax.Array] | None,
    config: SurrogateConfig,
) -> jax.Array:
    """The paper's Eq. 2 averaged over a batch held as separate domain and boundary parts.

    L = (Σ_domain ‖u − û‖₂ + α Σ_boundary ‖u − û‖₂) / (batch size). Each part is
    ``(x, target, gain)``; only the network a part belongs to is evaluated on it,
    which halves the cost of the paper's pair against evaluating both everywhere.
    """
    x, y, g = domain
    total = jnp.sum(pointwise_error(network(params["domain"], x, config) * g[:, None], y))
    count = x.shape[0]
    net = boundary_network(config)
    if boundary is not None and net is not None:
        xb, yb, gb = boundary
        pred = network(params[net], xb, config) * gb[:, None]
        total = total + config.alpha * jnp.sum(pointwise_error(pred, yb))
        count += xb.shape[0]
    return total / count


def loss(
    params: Params,
    x: jax.Array,
    target: jax.Array,
    boundary: jax.Array,
    gain: jax.Array,
    config: SurrogateConfig,
    weight: jax.Array | None = None,
) -> jax.Array:
    """The paper's Eq. 2 averaged over mixed samples; ``weight`` masks padded samples."""
    err = pointwise_error(apply(params, x, boundary, gain, config), target)
    w = jnp.ones_like(err) if weight is None else weight
    scale = jnp.where(boundary, config.alpha, 1.0) * w
    return jnp.sum(scale * err) / jnp.maximum(jnp.sum(w), 1.0)


def to_arrays(params: Params) -> dict[str, np.ndarray]:
    """Flatten to named numpy arrays, e.g. ``domain/0/W``."""
    out = {}
    for net in NETWORKS:
        for i, (W, b) in enumerate(params.get(net, [])):
            out[f"{net}/{i}/W"] = np.asarray(W)
            out[f"{net}/{i}/b"] = np.asarray(b)
    return out


def from_arrays(arrays: dict[str, Any], config: SurrogateConfig) -> Params:
    """Rebuild parameters from named arrays, checking them against the architecture.

    Raises:
        ValueError: if the arrays belong to another architecture or boundary mode.
    """
    sizes = layer_sizes(config)
    names = network_names(config)
    what = f"a {config.architecture} network ({config.boundary} boundary)"
    params: Params = {}
    for net in names:
        layers = []
        for i, (n_in, n_out) in enumerate(zip(sizes[:-1], sizes[1:], strict=False)):
            try:
                W, b = arrays[f"{net}/{i}/W"], arrays[f"{net}/{i}/b"]
            except KeyError:
                raise ValueError(f"model arrays lack {net} layer {i}: not {what}") from None
            if W.shape != (n_in, n_out) or b.shape != (n_out,):
                raise ValueError(
                    f"{net} layer {i} has shape {W.shape}, expected {(n_in, n_out)} for {what}"
                )
            if not (np.all(np.isfinite(W)) and np.all(np.isfinite(b))):
                raise ValueError(f"{net} layer {i} holds NaN or inf weights")
            layers.append((jnp.asarray(W, jnp.float32), jnp.asarray(b, jnp.float32)))
        params[net] = layers
    expected = 2 * len(names) * (len(sizes) - 1)
    if len(arrays) != expected:
        raise ValueError(f"model has {len(arrays)} weight arrays, {what} has {expected}")
    return params
