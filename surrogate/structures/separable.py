"""A separable structure: point networks give fields of the point alone, a branch weighs them.

The point networks see the point alone (with ``point_features``, its Fourier features too) and
give ``modes`` displacement fields T_k(X); a third network, ``branch``, maps the case (C1, ĝ) to
their weights b_k, and ``network(x) = Σ_k b_k T_k(X) / √modes``: the point networks keep the
paper's domain/boundary pair and Eq. 2 is the loss, but a query no longer passes the points
through a network: a loaded model computes the fields once, and a query costs its branch and one
weighted sum.

Training is on whole cases (:func:`grid_loss`): each step takes ``batch_size`` / N cases on
every point, so that the point networks run once per point and the branch once per case.
"""

from __future__ import annotations

import math
from functools import partial
from typing import TYPE_CHECKING, Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optax

from surrogate.data import Samples, Tables
from surrogate.model import (
    POINT_INPUTS,
    Params,
    Part,
    branch_sizes,
    branch_weights,
    combine,
    mlp,
    pointwise_error,
    weigh_fields,
)
from surrogate.structures.base import EpochPlan, Structure
from surrogate.train import batches

if TYPE_CHECKING:
    from surrogate.predict import Surrogate

_FOURIER_STREAM = 7
"""The stream of the seed that draws a model's Fourier frequencies (:meth:`point_frequencies`)."""


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


class Separable(Structure):
    """Point networks for the fields, a branch for their weights (see the module docstring)."""

    name = "separable"
    weighs_fields = True

    def network_names(self) -> tuple[str, ...]:
        """The point networks, then the branch."""
        return (*super().network_names(), "branch")

    def layer_sizes(self, net: str = "domain") -> list[int]:
        """Input, hidden and output widths of the network ``net``.

        A point network sees the point (3, with its Fourier features) and gives ``modes``
        fields; the branch sees the case (4) and gives their weights: ``modes``, or a ``modes``
        x 3 matrix contracted with ĝ in ``gravity_linear`` form.
        """
        config = self.config
        hidden = [config.width] * config.hidden_layers
        if net == "branch":
            return branch_sizes(config)
        return [POINT_INPUTS + 2 * config.point_features, *hidden, 3 * config.modes]

    def point_frequencies(self) -> np.ndarray | None:
        """The Fourier frequencies (3, ``point_features``), or None without them.

        Drawn from the model's seed (NumPy's PCG64, the same on every platform), so that a saved
        model rebuilds them from its hyperparameters.
        """
        config = self.config
        if not config.point_features:
            return None
        rng = np.random.default_rng([config.seed, _FOURIER_STREAM])
        b = config.point_frequency * rng.standard_normal((POINT_INPUTS, config.point_features))
        return b.astype(np.float32)

    def point_inputs(self, points: jax.Array) -> jax.Array:
        """What the point networks see of standardised points (n, 3).

        The coordinates, and with ``point_features`` their Fourier features sin(2π X·b) and
        cos(2π X·b) (:meth:`point_frequencies`).
        """
        b = self.point_frequencies()
        if b is None:
            return points
        z = 2.0 * math.pi * (points @ b)
        return jnp.concatenate([points, jnp.sin(z), jnp.cos(z)], axis=-1)

    def network(self, params: Params, net: str, x: jax.Array) -> jax.Array:
        """The fields of ``net`` at the points weighted by the branch at the cases."""
        config = self.config
        fields = mlp(params[net], self.point_inputs(x[:, :POINT_INPUTS]), config.activation)
        weights = branch_weights(params["branch"], x[:, POINT_INPUTS:], config)
        return combine(fields, weights, config)

    def samples_network(self, params: Params, net: str, part: Part,
                        tables: Tables | None) -> jax.Array:
        """:meth:`network` on a part of a batch, through ``tables``.

        The point network runs once per point of ``tables`` and the branch once per case,
        gathered per sample: a batch of thousands of samples drawn from a few thousand points
        and a few hundred cases then costs about one pass over the points.
        """
        if tables is None:
            return self.network(params, net, part[0])
        config = self.config
        fields = mlp(params[net], self.point_inputs(tables.points), config.activation)[part[3]]
        weights = branch_weights(params["branch"], tables.cases, config)[part[4]]
        return combine(fields, weights, config)

    def point_fields(self, params: Params, points: jax.Array, order: PointOrder) -> jax.Array:
        """The fields at every point (N, 3 modes), each through its own network.

        Rib points of an exact-Dirichlet model (no network of their own) get the domain
        network's fields, which their zero gain cancels.
        """
        activation = self.config.activation
        points = self.point_inputs(points)
        net = self.boundary_network()
        if net is None or net == "domain":
            return mlp(params["domain"], points, activation)
        parts = [
            mlp(params["domain"], points[order.domain], activation),
            mlp(params[net], points[order.rib], activation),
        ]
        return jnp.concatenate(parts)[order.inverse]

    def epoch_plan(self, train: Samples, n_points: int, boundary: np.ndarray,
                   use_boundary: bool) -> EpochPlan:
        """``batch_size`` / N whole cases a step (:func:`grid_loss`)."""
        grid = case_grid(train, n_points, use_boundary)
        per_step = max(1, min(round(self.config.batch_size / n_points), len(grid[0])))
        steps = -(-len(grid[0]) // per_step)
        data = (tuple(jnp.asarray(a) for a in grid), point_order(boundary))
        return EpochPlan(train_epoch_grid, data, per_step, steps,
                         f"{len(grid[0])} cases on {n_points} points, {steps} steps of "
                         f"{per_step} cases")

    def query_part(self, layers: Any, points: np.ndarray, gain: np.ndarray,
                   u_scale: np.float32, basis: np.ndarray | None) -> dict[str, Any]:
        """The fields at the points, once per mesh, gain and 1/√modes included.

        As one (n · 3, modes) matrix: a query is then one matrix-vector product (XLA's CPU
        backend runs a rank-3 contraction several times slower).
        """
        modes = self.config.modes
        fields = np.asarray(mlp(layers, self.point_inputs(jnp.asarray(points)),
                                self.config.activation))
        fields = fields.reshape(len(points), 3, modes) / math.sqrt(modes)
        fields = fields * (gain * u_scale)[:, None, None]
        return {"fields": jnp.asarray(fields.reshape(-1, modes).astype(np.float32))}

    def answer(self, parts: dict[str, Any], c: jax.Array) -> list[jax.Array]:
        """The branch once, then one weighted sum of the fields per part."""
        return weigh_fields(parts, c, self.config)

    def web_fields(self, model: Surrogate) -> dict[str, Any]:
        """The modes, the branch's layers and the point networks' Fourier frequencies."""
        from surrogate.export import encode_array, encode_layers

        frequencies = self.point_frequencies()
        return {
            "modes": self.config.modes,
            "branch": encode_layers(model.params["branch"]),
            # (3, F) frequencies of the point networks' Fourier features, or null
            "point_frequencies": None if frequencies is None else encode_array(frequencies,
                                                                                "float32"),
        }


def grid_loss(
    params: Params,
    grid: tuple[jax.Array, jax.Array, jax.Array, jax.Array],
    tables: Tables,
    order: PointOrder,
    structure: Separable,
) -> jax.Array:
    """Eq. 2 on whole cases at once: a batch of cases on every point.

    ``grid`` is ``(case rows (B,), targets (B, N, 3), gains (B, N), member (B, N))``, ``member``
    1 for a training sample and 0 for one outside the training split (or on the rib of a model
    without a rib network). Samples on the rib weigh α; the sum is divided by the number of
    training samples, as :meth:`Structure.split_loss` divides by the batch size. The point
    networks run once per point and the branch once per case; nothing is gathered per sample, so
    the gradient needs no scatter.
    """
    config = structure.config
    cases, y, gain, member = grid
    fields = structure.point_fields(params, tables.points, order)
    weights = branch_weights(params["branch"], tables.cases[cases], config)
    pred = jnp.einsum("pik,bk->bpi", fields.reshape(-1, 3, config.modes), weights)
    pred = pred * (gain / math.sqrt(config.modes))[..., None]
    scale = member * jnp.where(order.on_rib, config.alpha, 1.0)[None, :]
    return jnp.sum(scale * pointwise_error(pred, y)) / jnp.maximum(jnp.sum(member), 1.0)


def case_grid(
    samples: Samples, n_points: int, use_rib: bool
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Training samples laid out as whole cases for :func:`grid_loss`.

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
    """The rows each point network takes (:class:`PointOrder`)."""
    domain, rib = np.flatnonzero(~boundary), np.flatnonzero(boundary)
    inverse = np.argsort(np.concatenate([domain, rib]))
    return PointOrder(*(jnp.asarray(a.astype(np.int32)) for a in (domain, rib, inverse)),
                      jnp.asarray(boundary, bool))


@partial(jax.jit, static_argnames=("structure", "optimizer", "per_step", "steps"))
def train_epoch_grid(
    params: Params,
    opt_state: Any,
    key: jax.Array,
    grid: tuple[jax.Array, jax.Array, jax.Array, jax.Array],
    order: PointOrder,
    tables: Tables,
    *,
    structure: Separable,
    optimizer: optax.GradientTransformation,
    per_step: int,
    steps: int,
) -> tuple[Params, Any, jax.Array]:
    """One pass over the training cases, ``per_step`` whole cases a step."""

    def step(carry, idx):
        params, opt_state = carry
        batch = tuple(a[idx] for a in grid)
        value, grads = jax.value_and_grad(grid_loss)(params, batch, tables, order, structure)
        updates, opt_state = optimizer.update(grads, opt_state, params)
        return (optax.apply_updates(params, updates), opt_state), value

    order_c = batches(key, grid[0].shape[0], per_step, steps)
    (params, opt_state), losses = jax.lax.scan(step, (params, opt_state), order_c)
    return params, opt_state, jnp.mean(losses)
