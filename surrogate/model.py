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

In a ``separable`` model (``SurrogateConfig.structure``) the point networks see the point alone
and give ``modes`` displacement fields T_k(X); a third network, ``branch``, maps the case
(C1, ĝ) to their weights b_k, and ``network(x) = Σ_k b_k T_k(X) / √modes``: the point networks
keep the paper's domain/boundary pair and Eq. 2 is the loss, but a query no longer passes the
points through a network (:mod:`surrogate.predict` computes the fields once per model).

A ``pod`` model has the branch alone: its fields are the training data's own POD modes
(:mod:`surrogate.pod`, which fits them and trains the branch), so this module only sizes it.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from surrogate.config import SurrogateConfig
from surrogate.data import DIRECTION, N_INPUTS, Tables

Layers = list[tuple[jax.Array, jax.Array]]
Params = dict[str, Layers]
Part = tuple[jax.Array, jax.Array, jax.Array, jax.Array, jax.Array]
"""Samples of one network in a batch: inputs, targets, gains, point rows, case rows."""
POINT_NETWORKS = ("domain", "boundary")
NETWORKS = (*POINT_NETWORKS, "branch")
POINT_INPUTS = 3
"""Leading columns of the inputs that hold the material point; the rest describe the case."""
_FOURIER_STREAM = 7
"""The stream of the seed that draws a model's Fourier frequencies (:func:`point_frequencies`)."""

ACTIVATIONS: dict[str, Callable[[jax.Array], jax.Array]] = {
    "tanh": jnp.tanh,
    "relu": jax.nn.relu,
    "gelu": jax.nn.gelu,
    "silu": jax.nn.silu,
}


def network_names(config: SurrogateConfig) -> tuple[str, ...]:
    """Networks a config has, point networks first, then a separable model's branch.

    Both point networks in ``network`` mode, only ``domain`` otherwise.
    """
    if config.structure == "pod":
        return ("branch",)
    points = POINT_NETWORKS if config.boundary == "network" else ("domain",)
    return (*points, "branch") if config.structure == "separable" else points


def weighs_fields(config: SurrogateConfig) -> bool:
    """Whether a query weighs per-point fields by the branch's outputs (separable and pod).

    A pointwise model passes the points through its networks instead.
    """
    return config.structure in ("separable", "pod")


def boundary_network(config: SurrogateConfig) -> str | None:
    """Network that predicts the clamped points (None: they are exactly zero).

    A ``pod`` model's rib points are exactly zero: its modes are the FE fields', zero there.
    """
    if config.structure == "pod":
        return None
    return {"network": "boundary", "shared": "domain", "exact": None}[config.boundary]


def output_width(config: SurrogateConfig) -> int:
    """Outputs of one point network.

    Pointwise: the displacement (3) or the matrix that multiplies ĝ (9). Separable: ``modes``
    displacement fields (3 each).
    """
    if config.structure == "separable":
        return 3 * config.modes
    return 9 if config.output_form == "gravity_linear" else 3


def point_frequencies(config: SurrogateConfig) -> np.ndarray | None:
    """A separable model's Fourier frequencies (3, ``point_features``), or None without them.

    Drawn from the model's seed (NumPy's PCG64, the same on every platform), so that a saved
    model rebuilds them from its hyperparameters.
    """
    if not config.point_features:
        return None
    rng = np.random.default_rng([config.seed, _FOURIER_STREAM])
    b = config.point_frequency * rng.standard_normal((POINT_INPUTS, config.point_features))
    return b.astype(np.float32)


def point_inputs(points: jax.Array, config: SurrogateConfig) -> jax.Array:
    """What a separable model's point networks see of standardised points (n, 3).

    The coordinates, and with ``point_features`` their Fourier features sin(2π X·b) and
    cos(2π X·b) (:func:`point_frequencies`).
    """
    b = point_frequencies(config)
    if b is None:
        return points
    z = 2.0 * math.pi * (points @ b)
    return jnp.concatenate([points, jnp.sin(z), jnp.cos(z)], axis=-1)


def layer_sizes(config: SurrogateConfig, net: str = "domain") -> list[int]:
    """Input, hidden and output widths of one network (``net``: a point network or the branch).

    A ``pod`` model has the branch alone. A separable model's point networks see the point alone
    (3 inputs); its branch sees the case (4) and gives the fields' weights: ``modes``, or a
    ``modes`` x 3 matrix contracted with ĝ in ``gravity_linear`` form.
    """
    hidden = [config.width] * config.hidden_layers
    if config.structure == "pointwise":
        return [N_INPUTS, *hidden, output_width(config)]
    if net == "branch":
        per_mode = 3 if config.output_form == "gravity_linear" else 1
        return [N_INPUTS - POINT_INPUTS, *hidden, per_mode * config.modes]
    return [POINT_INPUTS + 2 * config.point_features, *hidden, output_width(config)]


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
    """Independent initial weights of the networks (split from one key).

    The point networks' keys are split as they were before the branch existed, so a pointwise
    model's initial weights do not depend on it.
    """
    keys = dict(zip(POINT_NETWORKS, jax.random.split(key, len(POINT_NETWORKS)), strict=True))
    keys["branch"] = jax.random.fold_in(key, len(POINT_NETWORKS))
    return {net: init_mlp(keys[net], layer_sizes(config, net)) for net in network_names(config)}


def mlp(layers: Layers, x: jax.Array, activation: str) -> jax.Array:
    """Dense layers with ``activation`` between them and a linear output."""
    act = ACTIVATIONS[activation]
    for W, b in layers[:-1]:
        x = act(x @ W + b)
    W, b = layers[-1]
    return x @ W + b


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


def network(params: Params, net: str, x: jax.Array, config: SurrogateConfig) -> jax.Array:
    """The point network ``net``'s displacement (n, 3) at inputs (n, 7), before the gain.

    Pointwise: its outputs, or M ĝ in ``gravity_linear`` form (output ``3 i + j`` is M's entry
    (i, j)). Separable: its fields at the points weighted by the branch at the cases.
    """
    if config.structure == "separable":
        fields = mlp(params[net], point_inputs(x[:, :POINT_INPUTS], config), config.activation)
        weights = branch_weights(params["branch"], x[:, POINT_INPUTS:], config)
        return combine(fields, weights, config)
    out = mlp(params[net], x, config.activation)
    if config.output_form == "gravity_linear":
        out = jnp.einsum("nij,nj->ni", out.reshape(-1, 3, 3), x[:, DIRECTION])
    return out


def samples_network(
    params: Params, net: str, part: Part, tables: Tables | None, config: SurrogateConfig
) -> jax.Array:
    """:func:`network` on a part of a batch, ``(x, target, gain, point, case)``.

    A separable model evaluates its point network once per point of ``tables`` and its branch
    once per case, and gathers them per sample: a batch of thousands of samples drawn from a
    few thousand points and a few hundred cases then costs about one pass over the points.
    """
    if config.structure == "separable" and tables is not None:
        fields = mlp(params[net], point_inputs(tables.points, config),
                     config.activation)[part[3]]
        weights = branch_weights(params["branch"], tables.cases, config)[part[4]]
        return combine(fields, weights, config)
    return network(params, net, part[0], config)


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
    domain = network(params, "domain", x, config)
    net = boundary_network(config)
    if net is None:
        bound = jnp.zeros_like(domain)
    elif net == "domain":
        bound = domain
    else:
        bound = network(params, net, x, config)
    return jnp.where(boundary[:, None], bound, domain) * gain[:, None]


class PointOrder(NamedTuple):
    """Which points each point network of a separable model takes.

    Attributes:
        domain: rows of the points off the rib.
        rib: rows of the points on the rib.
        inverse: the permutation that puts the two networks' outputs back in the points' order.
        on_rib: flags (N,).
    """

    domain: jax.Array
    rib: jax.Array
    inverse: jax.Array
    on_rib: jax.Array


def point_fields(
    params: Params, points: jax.Array, order: PointOrder, config: SurrogateConfig
) -> jax.Array:
    """A separable model's fields at every point (N, 3 modes), each through its own network.

    Rib points of an exact-Dirichlet model (no network of their own) get the domain network's
    fields, which their zero gain cancels.
    """
    points = point_inputs(points, config)
    net = boundary_network(config)
    if net is None or net == "domain":
        return mlp(params["domain"], points, config.activation)
    parts = [
        mlp(params["domain"], points[order.domain], config.activation),
        mlp(params[net], points[order.rib], config.activation),
    ]
    return jnp.concatenate(parts)[order.inverse]


def grid_loss(
    params: Params,
    grid: tuple[jax.Array, jax.Array, jax.Array, jax.Array],
    tables: Tables,
    order: PointOrder,
    config: SurrogateConfig,
) -> jax.Array:
    """Eq. 2 on whole cases at once, for a separable model: a batch of cases on every point.

    ``grid`` is ``(case rows (B,), targets (B, N, 3), gains (B, N), member (B, N))``, ``member``
    1 for a training sample and 0 for one outside the training split (or on the rib of a model
    without a rib network). Samples on the rib weigh α; the sum is divided by the number of
    training samples, as :func:`split_loss` divides by the batch size. The point networks run
    once per point and the branch once per case; nothing is gathered per sample, so the
    gradient needs no scatter.
    """
    cases, y, gain, member = grid
    fields = point_fields(params, tables.points, order, config)
    weights = branch_weights(params["branch"], tables.cases[cases], config)
    pred = jnp.einsum("pik,bk->bpi", fields.reshape(-1, 3, config.modes), weights)
    pred = pred * (gain / math.sqrt(config.modes))[..., None]
    scale = member * jnp.where(order.on_rib, config.alpha, 1.0)[None, :]
    return jnp.sum(scale * pointwise_error(pred, y)) / jnp.maximum(jnp.sum(member), 1.0)


def pointwise_error(prediction: jax.Array, target: jax.Array) -> jax.Array:
    """Euclidean norm of the error of each sample, smoothed at 0 so its gradient exists."""
    return jnp.sqrt(jnp.sum((prediction - target) ** 2, axis=-1) + 1e-12)


def split_loss(
    params: Params,
    domain: Part,
    boundary: Part | None,
    config: SurrogateConfig,
    tables: Tables | None = None,
) -> jax.Array:
    """The paper's Eq. 2 averaged over a batch held as separate domain and boundary parts.

    L = (Σ_domain ‖u − û‖₂ + α Σ_boundary ‖u − û‖₂) / (batch size). Each part is
    ``(x, target, gain, point, case)``; only the network a part belongs to is evaluated on it,
    which halves the cost of the paper's pair against evaluating both everywhere. ``tables``
    holds every point's and case's inputs for a separable model (:func:`samples_network`).
    """
    pred = samples_network(params, "domain", domain, tables, config) * domain[2][:, None]
    total = jnp.sum(pointwise_error(pred, domain[1]))
    count = domain[0].shape[0]
    net = boundary_network(config)
    if boundary is not None and net is not None:
        pred = samples_network(params, net, boundary, tables, config) * boundary[2][:, None]
        total = total + config.alpha * jnp.sum(pointwise_error(pred, boundary[1]))
        count += boundary[0].shape[0]
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
    names = network_names(config)
    what = f"a {config.architecture} {config.structure} network ({config.boundary} boundary)"
    params: Params = {}
    expected = 0
    for net in names:
        sizes = layer_sizes(config, net)
        expected += 2 * (len(sizes) - 1)
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
    if len(arrays) != expected:
        raise ValueError(f"model has {len(arrays)} weight arrays, {what} has {expected}")
    return params
