"""The interface every surrogate structure keeps, and what the networked ones share.

A :class:`Structure` is bound to one :class:`~surrogate.config.SurrogateConfig` (frozen and
hashable as the config is, so that jitted code may take it as a static argument) and answers,
for its models:

* the networks and their parameters: :meth:`~Structure.network_names`,
  :meth:`~Structure.layer_sizes`, :meth:`~Structure.init_params`, and their arrays in the
  checkpoint (:meth:`~Structure.to_arrays`, :meth:`~Structure.from_arrays`,
  :meth:`~Structure.check_saved` for what it saves beside them);
* the forward pass: :meth:`~Structure.network` at raw inputs, :meth:`~Structure.apply` on mixed
  samples; and a loaded model's queries (:meth:`~Structure.query_part`,
  :meth:`~Structure.answer`, :meth:`~Structure.placed` between the points);
* training: :meth:`~Structure.train`, whether it reads the dataset's quadratic nodes
  (:attr:`~Structure.reads_nodes`), the cases it trains on (:meth:`~Structure.trained_cases`)
  and the pieces of the paper's Eq. 2 (:meth:`~Structure.split_loss`, :meth:`~Structure.loss`);
* export for the web page (:meth:`~Structure.web_part`, :meth:`~Structure.web_fields`).

The defaults are those of a structure of point networks (``pointwise``, ``separable``): the
domain network and, by ``boundary`` mode, a rib network of their own or none. How a model of
them is trained, Adam on batches with early stopping on the validation loss, is
:func:`surrogate.train.train_networks`; the structure says how its epoch runs
(:meth:`~Structure.epoch_plan`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from surrogate.config import SurrogateConfig
from surrogate.model import (
    POINT_NETWORKS,
    Params,
    Part,
    init_mlp,
    pointwise_error,
    to_arrays,
)

if TYPE_CHECKING:
    from fem.dataset import Dataset
    from surrogate.checkpoint import Checkpoint
    from surrogate.data import Samples, Tables
    from surrogate.epochs import TrainResult
    from surrogate.predict import Surrogate


class EpochPlan(NamedTuple):
    """How one epoch of a networked structure's training runs (:meth:`Structure.epoch_plan`).

    Attributes:
        epoch: the jitted epoch ``(params, opt_state, key, *data, tables, **static)``.
        data: its training data, after the key.
        per_step: samples (or cases) per step, static.
        steps: steps per epoch.
        what: the epoch in words, for the log.
    """

    epoch: Any
    data: tuple[Any, ...]
    per_step: Any
    steps: int
    what: str


class Placement(NamedTuple):
    """What a model needs to answer at other points (:meth:`Structure.placed`).

    Attributes:
        boundary: which of the points answer exactly zero (on the clamped face).
        basis: a ``pod`` model's modes at the points, else None.
        nodes: for a model that answers at its nodes first, ``(nodes, their modes, the sparse
            (points, nodes) matrix that carries a field from them to the points)``; else None.
    """

    boundary: np.ndarray
    basis: np.ndarray | None = None
    nodes: tuple[np.ndarray, np.ndarray, Any] | None = None


@dataclass(frozen=True)
class Structure:
    """One structure of the surrogate, bound to a config (see the module docstring).

    Attributes:
        config: the model's hyperparameters.
    """

    config: SurrogateConfig
    name: ClassVar[str]
    """Its name in ``surrogate.structure``."""
    weighs_fields: ClassVar[bool] = False
    """Whether a query weighs per-point fields by a branch network's outputs (computed once per
    model), rather than passing the points through the networks."""
    reads_nodes: ClassVar[bool] = False
    """Whether it trains on the fields at every node of a quadratic mesh where the dataset has
    them (``read_dataset(..., nodes=True)``)."""

    # -- networks and their parameters ----------------------------------------------------
    def network_names(self) -> tuple[str, ...]:
        """Networks a model has: both point networks in ``network`` mode, else ``domain``."""
        return POINT_NETWORKS if self.config.boundary == "network" else ("domain",)

    def boundary_network(self) -> str | None:
        """Network that predicts the clamped points (None: they are exactly zero)."""
        return {"network": "boundary", "shared": "domain", "exact": None}[self.config.boundary]

    def layer_sizes(self, net: str = "domain") -> list[int]:
        """Input, hidden and output widths of the network ``net``."""
        raise NotImplementedError

    def init_params(self, key: jax.Array) -> Params:
        """Independent initial weights of the networks (split from one key).

        The point networks' keys are split as they were before the branch existed, so a
        pointwise model's initial weights do not depend on it.
        """
        keys = dict(zip(POINT_NETWORKS, jax.random.split(key, len(POINT_NETWORKS)), strict=True))
        keys["branch"] = jax.random.fold_in(key, len(POINT_NETWORKS))
        return {net: init_mlp(keys[net], self.layer_sizes(net)) for net in self.network_names()}

    def to_arrays(self, params: Params) -> dict[str, np.ndarray]:
        """The weights as named arrays for the checkpoint, e.g. ``domain/0/W``."""
        return to_arrays(params)

    def from_arrays(self, arrays: dict[str, Any]) -> Params:
        """Rebuild parameters from named arrays, checking them against the architecture.

        Raises:
            ValueError: if the arrays belong to another architecture or boundary mode.
        """
        config = self.config
        what = f"a {config.architecture} {self.name} network ({config.boundary} boundary)"
        params: Params = {}
        expected = 0
        for net in self.network_names():
            sizes = self.layer_sizes(net)
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

    def check_saved(self, basis: np.ndarray | None, n_points: int) -> str | None:
        """What is wrong with the arrays a checkpoint holds beside the weights, or None."""
        return None

    # -- the forward pass -------------------------------------------------------------------
    def network(self, params: Params, net: str, x: jax.Array) -> jax.Array:
        """The point network ``net``'s displacement (n, 3) at inputs (n, 7), before the gain."""
        raise NotImplementedError

    def samples_network(self, params: Params, net: str, part: Part,
                        tables: Tables | None) -> jax.Array:
        """:meth:`network` on a part of a batch, ``(x, target, gain, point, case)``."""
        return self.network(params, net, part[0])

    def apply(self, params: Params, x: jax.Array, boundary: jax.Array,
              gain: jax.Array) -> jax.Array:
        """Prediction of mixed samples, each through the network its point belongs to.

        Args:
            params: the networks.
            x: inputs (n, 7).
            boundary: clamped flags (n,).
            gain: output multipliers (n,) (see :mod:`surrogate.model`).
        """
        domain = self.network(params, "domain", x)
        net = self.boundary_network()
        if net is None:
            bound = jnp.zeros_like(domain)
        elif net == "domain":
            bound = domain
        else:
            bound = self.network(params, net, x)
        return jnp.where(boundary[:, None], bound, domain) * gain[:, None]

    # -- training ---------------------------------------------------------------------------
    def train(self, ds: Dataset, progress: bool = True, holdout: np.ndarray | None = None,
              refit_epochs: int | None = None) -> TrainResult:
        """Train a model on ``ds`` (:func:`surrogate.train.train_and_evaluate`'s arguments)."""
        from surrogate.train import train_networks  # the loop builds on the structures

        return train_networks(self, ds, progress, holdout, refit_epochs)

    def epoch_plan(self, train: Samples, n_points: int, boundary: np.ndarray,
                   use_boundary: bool) -> EpochPlan:
        """How an epoch runs on the training samples ``train``.

        ``n_points``: the dataset's points, ``boundary`` their rib flags; ``use_boundary``: the
        rib samples train.
        """
        raise NotImplementedError

    def trained_cases(self, ds: Dataset, held: np.ndarray, refit: bool) -> np.ndarray:
        """The cases of ``ds`` whose fields a model trained on, before the converged filter.

        A by-sample split draws points, so that a model trains on part of every case; a
        case-level split's training cases (and validation cases, ``refit``). Cases in ``held``
        (held out) are not among them.
        """
        if self.config.split == "by_sample":
            return np.setdiff1d(np.arange(len(ds.ids)), held)
        parts = ds.splits[self.config.split]
        return np.setdiff1d(np.union1d(parts["train"], parts["validation"]) if refit
                            else parts["train"], held)

    def split_loss(self, params: Params, domain: Part, boundary: Part | None,
                   tables: Tables | None = None) -> jax.Array:
        """The paper's Eq. 2 averaged over a batch held as separate domain and boundary parts.

        L = (Σ_domain ‖u − û‖₂ + α Σ_boundary ‖u − û‖₂) / (batch size). Each part is
        ``(x, target, gain, point, case)``; only the network a part belongs to is evaluated on
        it, which halves the cost of the paper's pair against evaluating both everywhere.
        ``tables`` holds every point's and case's inputs (:meth:`samples_network`).
        """
        pred = self.samples_network(params, "domain", domain, tables) * domain[2][:, None]
        total = jnp.sum(pointwise_error(pred, domain[1]))
        count = domain[0].shape[0]
        net = self.boundary_network()
        if boundary is not None and net is not None:
            pred = self.samples_network(params, net, boundary, tables) * boundary[2][:, None]
            total = total + self.config.alpha * jnp.sum(pointwise_error(pred, boundary[1]))
            count += boundary[0].shape[0]
        return total / count

    def loss(self, params: Params, x: jax.Array, target: jax.Array, boundary: jax.Array,
             gain: jax.Array, weight: jax.Array | None = None) -> jax.Array:
        """The paper's Eq. 2 averaged over mixed samples; ``weight`` masks padded samples."""
        err = pointwise_error(self.apply(params, x, boundary, gain), target)
        w = jnp.ones_like(err) if weight is None else weight
        scale = jnp.where(boundary, self.config.alpha, 1.0) * w
        return jnp.sum(scale * err) / jnp.maximum(jnp.sum(w), 1.0)

    # -- a loaded model's queries -------------------------------------------------------------
    def query_part(self, layers: Any, points: np.ndarray, gain: np.ndarray,
                   u_scale: np.float32, basis: np.ndarray | None) -> dict[str, Any]:
        """What a query of the points of one part needs, computed once per model.

        Args:
            layers: the part's network.
            points: its standardised points (n, 3), float32.
            gain: their output factor φ (n,).
            u_scale: the displacement unit, mm.
            basis: a ``pod`` model's modes at them, else None.
        """
        raise NotImplementedError

    def answer(self, parts: dict[str, Any], c: jax.Array) -> list[jax.Array]:
        """The displacement (n, 3) of each part for the query features ``c``.

        The parts are ``domain``, then ``boundary`` where it is; ``c`` holds the scaled C1, ĝ
        and the output gain. Traced once per model.
        """
        raise NotImplementedError

    def placed(self, checkpoint: Checkpoint, X: np.ndarray, boundary: np.ndarray,
               points: np.ndarray) -> Placement:
        """What a model of material points ``X`` (rib flags ``boundary``) needs at ``points``.

        The networks answer anywhere, but only the body is trained: where the checkpoint has
        the mesh's cells, a point outside is refused, and one on the chest wall's clamped face
        (a combination of boundary corners alone) answers zero, as FE has it.
        """
        on_face = np.zeros(len(points), dtype=bool)
        if checkpoint.cells is not None:
            from surrogate.interpolation import locate

            rows, weights = locate(X, checkpoint.cells, points)
            on_face = np.where(boundary[rows], 0.0, weights).sum(axis=1) <= 1e-9
        return Placement(on_face)

    # -- export for the web page --------------------------------------------------------------
    def web_part(self, model: Surrogate, index: np.ndarray, net: str) -> dict[str, Any]:
        """What the page's forward pass reads of one part beside its points and gain.

        The layers of its network ``net`` (its points: ``index``).
        """
        from surrogate.export import encode_layers

        return {"layers": encode_layers(model.params[net])}

    def web_fields(self, model: Surrogate) -> dict[str, Any]:
        """The page's model-wide entries: ``modes``, ``branch``, ``point_frequencies``.

        Each null where the structure has none.
        """
        return {"modes": None, "branch": None, "point_frequencies": None}
