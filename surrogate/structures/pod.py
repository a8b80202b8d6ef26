"""A ``pod`` surrogate: the training data's own fields as its basis, a branch for their weights.

A separable model learns its fields T_k(X) with point networks, which cannot resolve the
fields that change over a few millimetres (where the mound rests on the chest, at the soft
caudal end of the sphere; docs/surrogate.md). A ``pod`` model takes them from the data: the
leading right singular vectors (POD modes) of the training cases' displacement fields, each
divided by its case's compliance gain and by the displacement unit, as the other models' outputs
are. One network, the branch, maps the case (C1 encoded, ĝ) to the modes' weights, in the
model's ``output_form`` (in ``gravity_linear`` form each weight is a row of a modes x 3 matrix
times ĝ, :func:`surrogate.model.branch_weights`).

Training is on whole cases: the basis is orthonormal, so a field's squared error is its weights'
squared error plus what the basis cannot hold (a constant of the training). The branch is
trained by Adam on the whole training set at once (the config's learning rate, moments and
schedule), one epoch being :data:`STEPS_PER_EPOCH` steps, with early stopping on the validation
cases' error in mm, the full field's (weights and basis together), the error that the
architecture study compares and the goals are stated in. Its loss, the weights' squared error
in units of each case's compliance gain, weighs a soft case's error less than its millimetres
do; chosen by it, an epoch can be kept whose error in mm is above a later one's
(docs/results-log.md, "fifteen hundred epochs").

The modes are stored scaled by the weights' RMS over the training cases, so that the branch's
outputs are of order one: the displacement of a case is ``gain(C1) · u_scale · (b(C1, ĝ) ·
modes)``.

Where the dataset holds the fields at every node of a quadratic mesh (``/nodes``, read with
``read_dataset(..., nodes=True)``), the modes are taken there: the FE field's own nodes, between
which its quadratic shape functions give it exactly. The material points' modes are their
rows (a query at the points costs the same), and the model answers between the points by the
quadratic shape functions (:func:`surrogate.interpolation.locate_quadratic`) instead of the
vertices' linear ones.
"""

from __future__ import annotations

import logging
import time
from typing import TYPE_CHECKING, Any

import jax
import jax.numpy as jnp
import numpy as np
import optax

from fem.dataset import Dataset
from surrogate.config import SurrogateConfig
from surrogate.data import Normalisation
from surrogate.epochs import (
    EpochFigures,
    TrainResult,
    learning_rate_schedule,
    make_optimizer,
    run_epochs,
)
from surrogate.model import Layers, Params, branch_sizes, branch_weights, weigh_fields
from surrogate.structures.base import Placement, Structure

if TYPE_CHECKING:
    from surrogate.checkpoint import Checkpoint
    from surrogate.predict import Surrogate

log = logging.getLogger(__name__)

STEPS_PER_EPOCH = 100
"""Full-batch Adam steps in one epoch of a ``pod`` model's training."""


def case_split(
    ds: Dataset, config: SurrogateConfig, holdout: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Training and validation cases of a ``pod`` model.

    A case-level split's own parts. For ``by_sample`` (the paper's random points, which would
    leave holes in the fields), the ``by_case`` split's validation cases validate and every other
    case trains, its test cases included: as the paper's by-sample model sees every case, this
    one sees every case but the few that stop its training. Cases in ``holdout`` are left out of
    both.

    Raises:
        ValueError: if no training or validation case is left.
    """
    if config.split == "by_sample":
        parts = ds.splits["by_case"]
        train = np.union1d(parts["train"], parts["test"])
    else:
        parts = ds.splits[config.split]
        train = parts["train"]
    drop = np.asarray([] if holdout is None else holdout, dtype=np.int64)
    train, val = np.setdiff1d(train, drop), np.setdiff1d(parts["validation"], drop)
    if train.size == 0 or val.size == 0:
        raise ValueError(f"split {config.split!r} has no training or validation cases")
    return train, val


def scaled_fields(ds: Dataset, cases: np.ndarray, norm: Normalisation,
                  displacement: np.ndarray | None = None) -> np.ndarray:
    """The cases' fields as the model predicts them, (cases, 3N): u / (gain(C1) · u_scale).

    ``displacement`` (cases of ``ds``, nodes, 3) in mm replaces the material points' fields,
    e.g. the fields at a quadratic mesh's nodes.
    """
    u = ds.displacement if displacement is None else displacement
    u = u[cases] / (norm.gain(ds.C1[cases]) * norm.u_scale)[:, None, None]
    return u.reshape(len(cases), -1)


def fit_basis(fields: np.ndarray, modes: int) -> tuple[np.ndarray, np.ndarray, float]:
    """POD modes of the rows of ``fields``, scaled so that their weights are of order one.

    Returns:
        ``(basis (modes, 3N), singular values (all), scale)``: ``basis`` is the leading right
        singular vectors times ``scale``, the RMS of the fields' weights on them, so that a
        field is approximately ``weights @ basis`` with weights of RMS one.
    """
    _, singular, rows = np.linalg.svd(fields, full_matrices=False)
    basis = rows[:modes]
    scale = float(np.sqrt(np.mean((fields @ basis.T) ** 2)))
    return basis * scale, singular, scale


def _clamped(modes: np.ndarray, rib: np.ndarray) -> np.ndarray:
    """The modes (N, 3, K) as float32, exactly zero on the rib.

    The training fields vanish there, so the modes that hold them do; modes beyond the fields'
    rank (singular values at round-off) need not, and the model answers between the points
    (:meth:`Pod.placed`) by its modes, not by its rib flags.
    """
    modes = modes.astype(np.float32)
    modes[rib] = 0.0
    return modes


def _fit_step(config: SurrogateConfig, optimizer: optax.GradientTransformation):
    """The jitted epoch (``STEPS_PER_EPOCH`` full-batch Adam steps) and the loss it lowers.

    The loss is the weights' mean squared error.
    """

    def loss(layers: Layers, features: jax.Array, target: jax.Array) -> jax.Array:
        return jnp.mean((branch_weights(layers, features, config) - target) ** 2)

    @jax.jit
    def epoch(layers, state, features, target):
        def step(carry, _):
            layers, state = carry
            value, grads = jax.value_and_grad(loss)(layers, features, target)
            updates, state = optimizer.update(grads, state, layers)
            return (optax.apply_updates(layers, updates), state), value

        (layers, state), values = jax.lax.scan(step, (layers, state), None,
                                               length=STEPS_PER_EPOCH)
        return layers, state, jnp.mean(values)

    return epoch, jax.jit(loss)


def train_pod(
    ds: Dataset, config: SurrogateConfig, progress: bool = True,
    holdout: np.ndarray | None = None, refit_epochs: int | None = None,
) -> TrainResult:
    """Fit a ``pod`` model on its split's training cases (see the module docstring).

    With ``refit_epochs`` (:func:`surrogate.train.train_and_evaluate`), on its validation
    cases too.

    Raises:
        ValueError: if the split leaves no training or validation cases, or too few for the
            modes.
    """
    train_cases, val_cases = case_split(ds, config, holdout)
    if refit_epochs is not None:
        train_cases = np.union1d(train_cases, val_cases)
    return fit(ds, config, train_cases, val_cases, progress, holdout, refit_epochs)


def fit(
    ds: Dataset, config: SurrogateConfig, train_cases: np.ndarray, val_cases: np.ndarray,
    progress: bool = False, holdout: np.ndarray | None = None, refit_epochs: int | None = None,
) -> TrainResult:
    """Fit the basis on ``train_cases`` and train the branch, stopping early on ``val_cases``.

    ``holdout`` is recorded as the cases kept out. Where ``ds`` holds the fields at a quadratic
    mesh's nodes, the basis is taken there (the module docstring). With ``refit_epochs``, the
    branch trains for that many epochs and keeps the last weights, without early stopping
    (``val_cases`` then only report an error, on cases it may have trained on).

    Raises:
        ValueError: if a case did not converge, or there are fewer training cases than modes.
    """
    start = time.perf_counter()
    train_cases, val_cases = (np.asarray(c, dtype=np.int64) for c in (train_cases, val_cases))
    if not (np.all(ds.converged[train_cases]) and np.all(ds.converged[val_cases])):
        raise ValueError("a pod model is fitted on converged cases only")
    if len(train_cases) < config.modes or not len(val_cases):
        raise ValueError(f"surrogate.modes = {config.modes} POD modes need at least as many "
                         f"training cases ({len(train_cases)} given) and a validation case")
    norm = Normalisation.fit(ds, train_cases, config.c1_encoding, config.output_scaling)
    nodes = ds.nodes if ds.nodes is not None and ds.nodes.displacement is not None else None
    at_nodes = None if nodes is None else nodes.displacement
    train_fields = scaled_fields(ds, train_cases, norm, at_nodes)
    basis, singular, scale = fit_basis(train_fields, config.modes)
    unit = basis / scale**2  # projects a field onto the scaled basis: weights of RMS one
    node_modes = None
    if nodes is None:
        modes = _clamped(basis.T.reshape(ds.n_points, 3, config.modes), ds.boundary)
    else:
        # the rib's nodes: the points flagged so, and the edge nodes every training field
        # holds at zero (the Dirichlet condition's own nodes)
        rib = ~np.any(train_fields.reshape(len(train_cases), -1, 3) != 0.0, axis=(0, 2))
        rib[nodes.vertex[ds.boundary]] = True
        node_modes = _clamped(basis.T.reshape(len(nodes.X), 3, config.modes), rib)
        modes = node_modes[nodes.vertex]
    basis_j = jnp.asarray(modes.reshape(-1, config.modes).T)

    def data(cases: np.ndarray, basis_fields: np.ndarray) -> tuple[jax.Array, jax.Array]:
        """The cases' features and weights, from their fields where the basis is."""
        features = norm.case(ds.C1[cases], ds.direction[cases])
        return (jnp.asarray(features, jnp.float32),
                jnp.asarray(basis_fields @ unit.T, jnp.float32))

    train_x, train_w = data(train_cases, train_fields)
    val_x, val_w = data(val_cases, scaled_fields(ds, val_cases, norm, at_nodes))
    val_fields = jnp.asarray(scaled_fields(ds, val_cases, norm), jnp.float32)  # at the points
    val_gain = jnp.asarray(norm.gain(ds.C1[val_cases]) * norm.u_scale, jnp.float32)
    off_rib = jnp.asarray(~ds.boundary, jnp.float32)
    n, n_off = ds.n_points, max(int(np.sum(~ds.boundary)), 1)

    @jax.jit
    def field_errors(layers: Layers) -> tuple[jax.Array, jax.Array]:
        pred = branch_weights(layers, val_x, config) @ basis_j
        err = jnp.linalg.norm((pred - val_fields).reshape(len(val_cases), n, 3), axis=-1)
        err = err * val_gain[:, None]  # mm
        return jnp.mean(err), jnp.sum(err * off_rib[None, :]) / (len(val_cases) * n_off)

    key = jax.random.PRNGKey(config.seed)
    _, init_key = jax.random.split(key)
    layers = Pod(config).init_params(init_key)["branch"]
    optimizer = make_optimizer(config, STEPS_PER_EPOCH)
    schedule = learning_rate_schedule(config, STEPS_PER_EPOCH)
    state = optimizer.init(layers)
    epoch_fn, loss_fn = _fit_step(config, optimizer)
    t0 = time.perf_counter()
    epoch_fn = epoch_fn.lower(layers, state, train_x, train_w).compile()
    result = TrainResult(
        params={"branch": layers}, config=config, normalisation=norm,
        train_cases=train_cases, held_out_cases=None if holdout is None else np.asarray(holdout),
        basis=modes, node_basis=node_modes,
    )
    result.compile_s = time.perf_counter() - t0
    left = float(np.sum(singular[config.modes:] ** 2) / np.sum(singular**2))
    log.info("%s pod: %d training cases, %d validation cases, modes at %d %s, %d modes "
             "leaving %.2e of the training fields' energy out, compiled in %.1f s",
             config.architecture, len(train_cases), len(val_cases),
             n if nodes is None else len(nodes.X), "points" if nodes is None else "nodes",
             config.modes, left, result.compile_s)

    def one_epoch() -> tuple[Params, EpochFigures]:
        nonlocal layers, state
        layers, state, train_loss = epoch_fn(layers, state, train_x, train_w)
        figures = EpochFigures(float(train_loss), float(loss_fn(layers, val_x, val_w)),
                               float(field_errors(layers)[0]))
        return {"branch": layers}, figures

    run_epochs(one_epoch, {"branch": layers}, config, result, schedule=schedule,
               steps=STEPS_PER_EPOCH, refit_epochs=refit_epochs, progress=progress,
               select="validation_error_mm")
    error, domain = field_errors(result.params["branch"])
    result.validation_error_mm, result.validation_error_domain_mm = float(error), float(domain)
    result.train_s = time.perf_counter() - start
    log.info("%s pod: best epoch %d of %d, validation error %.4f mm (%.4f mm off the rib), "
             "%.1f s", config.architecture, result.best_epoch, len(result.history),
             result.validation_error_mm, result.validation_error_domain_mm, result.train_s)
    return result


class Pod(Structure):
    """The training data's POD modes as the fields, a branch for their weights.

    See the module docstring.
    """

    name = "pod"
    weighs_fields = True
    reads_nodes = True

    def network_names(self) -> tuple[str, ...]:
        """The branch alone."""
        return ("branch",)

    def boundary_network(self) -> str | None:
        """None: the rib points are exactly zero, as its modes (the FE fields') are there."""
        return None

    def layer_sizes(self, net: str = "branch") -> list[int]:
        """The branch's: the case (4) in, the modes' weights out."""
        return branch_sizes(self.config)

    def network(self, params: Params, net: str, x: jax.Array) -> jax.Array:
        """None: a pod model has no point network; its fields are its modes."""
        raise NotImplementedError("a pod model has no point network: its fields are its modes")

    def train(self, ds: Dataset, progress: bool = True, holdout: np.ndarray | None = None,
              refit_epochs: int | None = None) -> TrainResult:
        """:func:`train_pod`."""
        return train_pod(ds, self.config, progress, holdout, refit_epochs)

    def trained_cases(self, ds: Dataset, held: np.ndarray, refit: bool) -> np.ndarray:
        """Whole cases: :func:`case_split`'s training cases (and validation cases, ``refit``)."""
        train, validation = case_split(ds, self.config, held)
        return np.union1d(train, validation) if refit else train

    def check_saved(self, basis: np.ndarray | None, n_points: int) -> str | None:
        """Its modes at the points (``points_basis``) must be there, finite and of its shape."""
        shape = (n_points, 3, self.config.modes)
        if basis is None or basis.shape != shape or not np.all(np.isfinite(basis)):
            return f"a pod model needs its modes as points_basis, finite, of shape {shape}"
        return None

    def query_part(self, layers: Any, points: np.ndarray, gain: np.ndarray,
                   u_scale: np.float32, basis: np.ndarray | None) -> dict[str, Any]:
        """Its modes at the points, gain included, laid out as a separable model's fields."""
        modes = basis * (gain * u_scale)[:, None, None]
        return {"fields": jnp.asarray(modes.reshape(-1, self.config.modes).astype(np.float32,
                                                                                 copy=False))}

    def answer(self, parts: dict[str, Any], c: jax.Array) -> list[jax.Array]:
        """The branch once, then one weighted sum of the modes."""
        return weigh_fields(parts, c, self.config)

    def placed(self, checkpoint: Checkpoint, X: np.ndarray, boundary: np.ndarray,
               points: np.ndarray) -> Placement:
        """Its modes interpolated in the mesh's tetrahedra.

        Quadratic where it has them at every node of a quadratic mesh, linear between the
        vertices otherwise; at more points than
        nodes, the field at the nodes, then at the points (the same sum by linearity), in
        memory and time that grow with the points as 3 values each, not as 3 × modes.

        Raises:
            ValueError: if its dataset had no mesh cells.
        """
        from surrogate.interpolation import (
            interpolate,
            interpolation_matrix,
            locate,
            locate_quadratic,
        )

        c = checkpoint
        if c.nodes is not None:
            nodes = c.nodes.X, c.nodes.basis
            where = locate_quadratic(c.nodes.X, c.nodes.cells, points)
        elif c.cells is not None:
            nodes = X, c.basis
            where = locate(X, c.cells, points)
        else:
            raise ValueError(
                "this pod model answers at its material points only: its dataset has no "
                "mesh cells to interpolate its modes in (rebuild the dataset with its mesh, "
                "snakemake --forcerun aggregate, and train again)")
        on_face = np.zeros(len(points), dtype=bool)
        if len(points) > len(nodes[0]):
            return Placement(on_face, nodes=(*nodes, interpolation_matrix(*where,
                                                                          len(nodes[0]))))
        return Placement(on_face, basis=interpolate(nodes[1], *where).astype(np.float32,
                                                                             copy=False))

    def web_part(self, model: Surrogate, index: np.ndarray, net: str) -> dict[str, Any]:
        """Its modes at the part's points (points, 3, ``modes``) instead of layers.

        Raises:
            ValueError: for a model asked at more points than its nodes
                (:meth:`surrogate.predict.Surrogate.at`), which holds no modes at them.
        """
        from surrogate.export import encode_array

        if model.basis is None:
            raise ValueError(f"a pod model asked at {len(model.X)} points, more than its mesh "
                             "has nodes, holds no modes there to export: ask it at fewer points")
        return {"modes": encode_array(model.basis[index], "float32")}

    def web_fields(self, model: Surrogate) -> dict[str, Any]:
        """The modes and the branch's layers."""
        from surrogate.export import encode_layers

        return {"modes": self.config.modes, "branch": encode_layers(model.params["branch"]),
                "point_frequencies": None}
