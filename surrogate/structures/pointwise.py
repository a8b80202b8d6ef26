"""The paper's structure: each network maps a material point and the case to its displacement.

A network's seven inputs are the point's standardised coordinates, then the case (C1 encoded and
scaled, ĝ); its output is the displacement (``output_form: vector``) or nine numbers read as a
matrix M that multiplies ĝ (``gravity_linear``). Training draws batches of samples, domain and
boundary in their training proportions, as the authors' code draws one batch from each set per
step; every network is evaluated on its own samples (:meth:`Structure.split_loss`). One epoch
is a single jitted ``lax.scan`` over :func:`train_step`.

A loaded model computes the first layer's point part ``X W_x + b`` once; a query then costs one
rank-one update, the remaining layers and one gather. A ``gravity_linear`` model's last layer is
contracted with the query's ĝ first, so its nine outputs cost what three do.
"""

from __future__ import annotations

from functools import partial
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import optax

from surrogate.data import DIRECTION, N_INPUTS, Samples, Tables
from surrogate.model import ACTIVATIONS, Params, Part, mlp
from surrogate.structures.base import EpochPlan, Structure
from surrogate.train import batches

PART_FIELDS = ("x", "y", "gain", "point", "case")
"""The :class:`Samples` fields of a batch part, in :data:`surrogate.model.Part` order."""


class Pointwise(Structure):
    """Point and case in, displacement out (see the module docstring)."""

    name = "pointwise"

    def layer_sizes(self, net: str = "domain") -> list[int]:
        """Seven inputs (the point, then the case), the hidden layers, :meth:`output_width`."""
        return [N_INPUTS, *[self.config.width] * self.config.hidden_layers, self.output_width()]

    def output_width(self) -> int:
        """The displacement (3) or the matrix that multiplies ĝ (9)."""
        return 9 if self.config.output_form == "gravity_linear" else 3

    def network(self, params: Params, net: str, x: jax.Array) -> jax.Array:
        """Its outputs, or M ĝ in ``gravity_linear`` form.

        Output ``3 i + j`` is M's entry (i, j).
        """
        out = mlp(params[net], x, self.config.activation)
        if self.config.output_form == "gravity_linear":
            out = jnp.einsum("nij,nj->ni", out.reshape(-1, 3, 3), x[:, DIRECTION])
        return out

    def epoch_plan(self, train: Samples, n_points: int, boundary: np.ndarray,
                   use_boundary: bool) -> EpochPlan:
        """Batches of ``batch_size`` samples.

        Each holds domain and rib samples in their training proportions (the rib's left out
        where no network predicts it).
        """
        domain = train.subset(~train.boundary)
        bset = train.subset(train.boundary)
        n_used = len(domain) + (len(bset) if use_boundary else 0)
        batch = min(self.config.batch_size, n_used)
        steps = -(-n_used // batch)
        per_b = max(1, round(batch * len(bset) / n_used)) if use_boundary else 0
        per_step = (batch - per_b, per_b)
        data = (
            tuple(jnp.asarray(getattr(domain, f)) for f in PART_FIELDS),
            tuple(jnp.asarray(getattr(bset, f)) for f in PART_FIELDS) if use_boundary else None,
        )
        return EpochPlan(train_epoch, data, per_step, steps,
                         f"{steps} steps of {per_step} samples")

    def query_part(self, layers: Any, points: np.ndarray, gain: np.ndarray,
                   u_scale: np.float32, basis: np.ndarray | None) -> dict[str, Any]:
        """The first layer's point part, the rest of the layers and the points' gain."""
        W0, b0 = (np.asarray(a, np.float32) for a in layers[0])
        pre = points @ W0[:3] + b0  # point part of the first layer, once per mesh
        return {
            "pre": jnp.asarray(pre),
            "Wc": jnp.asarray(W0[3:]),
            "rest": [(jnp.asarray(W), jnp.asarray(b)) for W, b in layers[1:]],
            "gain": jnp.asarray((gain * u_scale).astype(np.float32)[:, None]),
        }

    def answer(self, parts: dict[str, Any], c: jax.Array) -> list[jax.Array]:
        """Each part through its network, from the first layer's precomputed point part."""
        act = ACTIVATIONS[self.config.activation]
        linear_in_gravity = self.config.output_form == "gravity_linear"

        def forward(part, c):
            h = act(part["pre"] + c[:4] @ part["Wc"])
            for W, b in part["rest"][:-1]:
                h = act(h @ W + b)
            W, b = part["rest"][-1]
            if linear_in_gravity:  # M ĝ: the last layer contracted with ĝ, once per query
                W = W.reshape(W.shape[0], 3, 3) @ c[1:4]
                b = b.reshape(3, 3) @ c[1:4]
            return (h @ W + b) * (part["gain"] * c[4])

        out = [forward(parts["domain"], c)]
        if "boundary" in parts:
            out.append(forward(parts["boundary"], c))
        return out


def train_step(
    params: Params,
    opt_state: Any,
    domain: Part,
    boundary: Part | None,
    tables: Tables,
    *,
    structure: Structure,
    optimizer: optax.GradientTransformation,
) -> tuple[Params, Any, jax.Array]:
    """One Adam step on one batch (domain part and boundary part); returns the loss."""
    value, grads = jax.value_and_grad(structure.split_loss)(params, domain, boundary, tables)
    updates, opt_state = optimizer.update(grads, opt_state, params)
    return optax.apply_updates(params, updates), opt_state, value


@partial(jax.jit, static_argnames=("structure", "optimizer", "per_step", "steps"))
def train_epoch(
    params: Params,
    opt_state: Any,
    key: jax.Array,
    domain: Part,
    boundary: Part | None,
    tables: Tables,
    *,
    structure: Structure,
    optimizer: optax.GradientTransformation,
    per_step: tuple[int, int],
    steps: int,
) -> tuple[Params, Any, jax.Array]:
    """One pass over the training samples: a ``lax.scan`` of :func:`train_step`."""
    k_domain, k_boundary = jax.random.split(key)
    order_d = batches(k_domain, domain[0].shape[0], per_step[0], steps)
    if boundary is None:
        order_b = jnp.zeros((steps, 0), jnp.int32)
    else:
        order_b = batches(k_boundary, boundary[0].shape[0], per_step[1], steps)

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
            structure=structure,
            optimizer=optimizer,
        )
        return (params, opt_state), value

    (params, opt_state), losses = jax.lax.scan(step, (params, opt_state), (order_d, order_b))
    return params, opt_state, jnp.mean(losses)
