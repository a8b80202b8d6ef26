"""The networks' shared pieces: MLPs, the branch's weights of fields, the error of Eq. 2.

Parameters are a plain pytree ``{"domain": [(W, b), ...], "boundary": [(W, b), ...]}``
so that they save as named arrays (no pickle) and load by rebuilding the
skeleton from the hyperparameters. Which networks a model has, and how they make its forward
pass, is its structure's (:mod:`surrogate.structures`); this module holds what the structures
build them from.

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

A structure that weighs fields (``separable``, ``pod``) has a network ``branch`` that maps the
case (C1, ĝ) to the weights b_k of its ``modes`` fields T_k(X) (:func:`branch_weights`), and
predicts ``Σ_k b_k T_k(X)`` (:func:`combine`, :func:`weigh_fields`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from surrogate.config import SurrogateConfig
from surrogate.data import N_INPUTS

Layers = list[tuple[jax.Array, jax.Array]]
Params = dict[str, Layers]
Part = tuple[jax.Array, jax.Array, jax.Array, jax.Array, jax.Array]
"""Samples of one network in a batch: inputs, targets, gains, point rows, case rows."""
POINT_NETWORKS = ("domain", "boundary")
NETWORKS = (*POINT_NETWORKS, "branch")
POINT_INPUTS = 3
"""Leading columns of the inputs that hold the material point; the rest describe the case."""

ACTIVATIONS: dict[str, Callable[[jax.Array], jax.Array]] = {
    "tanh": jnp.tanh,
    "relu": jax.nn.relu,
    "gelu": jax.nn.gelu,
    "silu": jax.nn.silu,
}


def init_mlp(key: jax.Array, sizes: list[int]) -> Layers:
    """Glorot-uniform weights and zero biases."""
    layers = []
    keys = jax.random.split(key, len(sizes) - 1)
    for k, (n_in, n_out) in zip(keys, zip(sizes[:-1], sizes[1:], strict=False), strict=True):
        limit = np.sqrt(6.0 / (n_in + n_out))
        W = jax.random.uniform(k, (n_in, n_out), jnp.float32, -limit, limit)
        layers.append((W, jnp.zeros((n_out,), jnp.float32)))
    return layers


def mlp(layers: Layers, x: jax.Array, activation: str) -> jax.Array:
    """Dense layers with ``activation`` between them and a linear output."""
    act = ACTIVATIONS[activation]
    for W, b in layers[:-1]:
        x = act(x @ W + b)
    W, b = layers[-1]
    return x @ W + b


def branch_sizes(config: SurrogateConfig) -> list[int]:
    """Input, hidden and output widths of a branch.

    The case (4) in, the weights of the ``modes`` fields out (a ``modes`` x 3 matrix contracted
    with ĝ in ``gravity_linear`` form).
    """
    per_mode = 3 if config.output_form == "gravity_linear" else 1
    return [N_INPUTS - POINT_INPUTS, *[config.width] * config.hidden_layers,
            per_mode * config.modes]


def branch_weights(layers: Layers, cases: jax.Array, config: SurrogateConfig) -> jax.Array:
    """A separable model's weights of its fields (m, modes) for case features (m, 4).

    In ``gravity_linear`` form each weight is a row of the branch's ``modes`` x 3 matrix times ĝ.
    """
    b = mlp(layers, cases, config.activation)
    if config.output_form == "gravity_linear":
        b = jnp.einsum("mkj,mj->mk", b.reshape(-1, config.modes, 3), cases[:, 1:4])
    return b


def combine(fields: jax.Array, weights: jax.Array, config: SurrogateConfig) -> jax.Array:
    """Σ_k b_k T_k: point networks' fields (n, 3 modes) weighted per sample (n, modes), (n, 3).

    Divided by √modes so that the sum's scale does not grow with the number of fields.
    """
    n = fields.shape[0]
    return jnp.einsum("nik,nk->ni", fields.reshape(n, 3, config.modes), weights) / math.sqrt(
        config.modes
    )


def weigh_fields(parts: dict[str, Any], c: jax.Array, config: SurrogateConfig) -> list[jax.Array]:
    """A loaded model's displacement per part for query features ``c`` (5,).

    The branch once, then one weighted sum of each part's ``fields`` (n · 3, modes), gains
    included.
    """
    weights = branch_weights(parts["branch"], c[None, :4], config)[0] * c[4]
    out = [(parts["domain"]["fields"] @ weights).reshape(-1, 3)]
    if "boundary" in parts:
        out.append((parts["boundary"]["fields"] @ weights).reshape(-1, 3))
    return out


def pointwise_error(prediction: jax.Array, target: jax.Array) -> jax.Array:
    """Euclidean norm of the error of each sample, smoothed at 0 so its gradient exists."""
    return jnp.sqrt(jnp.sum((prediction - target) ** 2, axis=-1) + 1e-12)


def to_arrays(params: Params) -> dict[str, np.ndarray]:
    """Flatten to named numpy arrays, e.g. ``domain/0/W``."""
    out = {}
    for net in NETWORKS:
        for i, (W, b) in enumerate(params.get(net, [])):
            out[f"{net}/{i}/W"] = np.asarray(W)
            out[f"{net}/{i}/b"] = np.asarray(b)
    return out
