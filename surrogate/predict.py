"""Query a trained surrogate: the displacement of every material point for one setup.

Prediction is built for speed: the first layer's point part ``X W_x + b`` does not
depend on the query, so it is computed once per model; a query then costs one
rank-one update, the remaining layers and one gather, in one jitted float32 call
with static shapes. A ``gravity_linear`` model's last layer is contracted with the query's
gravity direction first, so its nine outputs cost what three do. A ``separable`` model's point
networks are evaluated once per model: a query costs its branch network and one weighted sum of
the fields. A ``pod`` model's fields are its stored modes, weighed the same way. Points on the
rib go through the boundary network (``network`` mode), the shared network (``shared``) or are
exactly zero (``exact``, and every ``pod`` model). A model folder is read by
:mod:`surrogate.checkpoint`; the command line is :mod:`surrogate.cli`.

Example::

    from surrogate.predict import Surrogate

    u = Surrogate.load("results/surrogate/model").predict(1.0, 180.0)  # (N, 3), mm
"""

from __future__ import annotations

import math
import warnings
from dataclasses import replace
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from surrogate.checkpoint import Checkpoint, load_checkpoint
from surrogate.exceptions import ExtrapolationWarning, ModelFileError
from surrogate.structures import structure_for
from surrogate.training_range import TrainingRange


class Surrogate:
    """A loaded surrogate that predicts the displacement of every material point.

    Args:
        checkpoint: a model folder's content (:func:`surrogate.checkpoint.load_checkpoint`):
            architecture, weights, normalisation, the material points (N, 3) in m with their
            boundary flags and mesh node indices, the training range and metrics.

    Raises:
        ModelFileError: if an exact-Dirichlet model lacks its point factor.
    """

    def __init__(self, checkpoint: Checkpoint, clamped_zero: bool = False,
                 between: tuple[np.ndarray, Any] | None = None) -> None:
        c = checkpoint
        self._checkpoint = c
        #: the boundary points answer exactly zero, as FE has them on the clamped chest wall
        #: (:meth:`at`'s points on its face), whatever the boundary mode
        self._clamped_zero = clamped_zero
        if c.config.boundary == "exact" and c.point_factor is None:
            raise ModelFileError("an exact-Dirichlet model needs its point factor (points_factor)")
        self.config = c.config
        self.params = c.params
        self.normalisation = c.normalisation
        self.X = np.asarray(c.X)
        self.boundary = np.asarray(c.boundary, dtype=bool)
        self.training_range = c.training_range
        self.point_factor = c.point_factor
        self.basis = c.basis
        self.node_index = np.arange(len(c.X)) if c.node_index is None else np.asarray(c.node_index)
        self.metrics = c.metrics
        self.held_out = list(c.held_out)
        #: which queries the sweep's FE solutions back (the warnings of :meth:`predict`)
        self.trained = TrainingRange(self.training_range)
        self._build_predictor()
        #: (:meth:`at` for many points) the field is predicted at the checkpoint's nodes, then
        #: carried to ``points`` by this sparse (M, nodes) matrix of shape functions
        self._between = None
        if between is not None:
            points, self._between = between
            self.X = points
            self.boundary = np.zeros(len(points), dtype=bool)
            self.node_index = np.arange(len(points))
            self.basis = None

    # -- construction -----------------------------------------------------------------
    def _build_predictor(self) -> None:
        """Precompute the query-independent part of the first layer and jit the rest."""
        config, norm = self.config, self.normalisation
        pts = norm.points(self.X).astype(np.float32)
        domain = np.flatnonzero(~self.boundary)
        bound = np.flatnonzero(self.boundary)
        inverse = np.argsort(np.concatenate([domain, bound]))
        factor = (
            np.ones(len(self.X), np.float32) if self.point_factor is None else self.point_factor
        )
        u_scale = np.float32(norm.u_scale)
        structure = structure_for(config)

        def prepare(layers, idx):
            basis = None if self.basis is None else self.basis[idx]
            return structure.query_part(layers, pts[idx], factor[idx], u_scale, basis)

        parts = {"domain": prepare(self.params.get("domain"), domain)}
        net = None if self._clamped_zero else structure.boundary_network()
        if net is not None and bound.size:
            parts["boundary"] = prepare(self.params[net], bound)
        if structure.weighs_fields:
            parts["branch"] = self.params["branch"]
        n_bound = int(bound.size)
        inverse_j = jnp.asarray(inverse.astype(np.int32))

        def run(parts, c):
            out = structure.answer(parts, c)
            if "boundary" not in parts and n_bound:
                out.append(jnp.zeros((n_bound, 3), jnp.float32))
            return jnp.take(jnp.concatenate(out), inverse_j, axis=0)

        self._parts = parts
        self._run = jax.jit(run)

    @classmethod
    def load(cls, folder: str | Path) -> Surrogate:
        """Load a model folder written by :func:`surrogate.checkpoint.save_model`.

        Raises:
            ModelFileError: if files are missing or the weights do not fit the architecture.
        """
        return cls(load_checkpoint(folder))

    def at(self, points: np.ndarray) -> Surrogate:
        """The same model queried at other material points ``points`` (M, 3), in m.

        The network is a function of the reference position, so it answers between the
        material points it was trained on (a ``pod`` model by its modes' interpolation in the
        mesh's tetrahedra, :mod:`surrogate.interpolation`: quadratic where it has its modes at
        every node of a quadratic mesh, linear between the vertices otherwise): a tumour's
        material position, found from the imaged shape (:func:`fem.tracking.to_reference`), is
        predicted directly.
        A point on the chest wall's clamped face (where the mesh has the cells to tell, or by a
        ``pod`` model's modes, zero there) answers exactly zero, as FE has it, every other point
        by the domain network; an exact-Dirichlet model's factor is evaluated at them with the
        model's own length scale.
        Each query of the returned model costs in proportion to M; a ``pod`` model asked at
        more points than its nodes predicts at its nodes and carries the field to the points
        by the same shape functions (no modes held at each point).

        Raises:
            ValueError: if ``points`` is not a finite (M, 3) array; for a ``pod`` model, also
                if its dataset had no mesh cells.
            surrogate.exceptions.OutsideMeshError: if a point lies more than
                :data:`surrogate.interpolation.OUTSIDE_M` outside the mesh (for a model whose
                dataset has the mesh's cells).
        """
        points = np.asarray(points, dtype=float)
        if points.ndim != 2 or points.shape[1] != 3 or not points.size:
            raise ValueError(f"points must be an (M, 3) array, got shape {points.shape}")
        if not np.all(np.isfinite(points)):
            raise ValueError("points must be finite")
        c = self._checkpoint
        factor = None
        if c.config.boundary == "exact":
            from surrogate.data import dirichlet_factor

            factor = dirichlet_factor(self.X, self.boundary, c.config.bc_length, at=points)
        where = structure_for(c.config).placed(c, self.X, self.boundary, points)
        if where.nodes is not None:
            nodes, basis, matrix = where.nodes
            return Surrogate(replace(
                c, X=nodes, boundary=np.zeros(len(nodes), dtype=bool), point_factor=None,
                node_index=None, basis=basis, cells=None, nodes=None,
            ), clamped_zero=True, between=(points, matrix))
        boundary, basis = where.boundary, where.basis
        return Surrogate(replace(
            c, X=points, boundary=boundary,
            point_factor=None if factor is None else factor.astype(np.float32),
            node_index=None, basis=basis, cells=None, nodes=None,
        ), clamped_zero=True)

    # -- queries ----------------------------------------------------------------------
    def predict(self, C1: float, phi: float, theta: float = 0.0) -> np.ndarray:
        """Displacement (N, 3) in mm (float32) of every material point for one setup.

        Args:
            C1: neo-Hookean parameter, kPa.
            phi: gravity elevation angle Φ, degrees.
            theta: gravity azimuth angle θ, degrees.

        Raises:
            ValueError: if an input is not a finite number or C1 is not positive.

        Warns:
            ExtrapolationWarning: if (C1, Φ, θ) lies outside the training range, at or
                below a C1 at which the sweep's FE solve failed beside its direction, or below
                the softest C1 trained beside it
                (:meth:`surrogate.training_range.TrainingRange.softest_beside`).
        """
        u = np.asarray(self._run(self._parts, self.features(C1, phi, theta)))
        if self._between is not None:
            u = (self._between @ u).astype(np.float32)
        return u

    def features(self, C1: float, phi: float, theta: float = 0.0) -> np.ndarray:
        """Checked query features: scaled C1, gravity direction, output gain (5,), float32."""
        for name, value in (("C1", C1), ("phi", phi), ("theta", theta)):
            if (
                isinstance(value, bool)
                or not isinstance(value, (int, float, np.floating, np.integer))
                or not math.isfinite(value)
            ):
                raise ValueError(f"{name} must be a finite number, got {value!r}")
        if C1 <= 0:
            raise ValueError(f"C1 must be positive, got {C1} kPa")
        self._warn_if_outside(C1, phi, theta)
        norm = self.normalisation
        p, t = math.radians(phi), math.radians(theta)
        if norm.c1_encoding == "log":
            enc = math.log(C1)
        elif norm.c1_encoding == "inverse":
            enc = 1.0 / C1
        else:
            enc = float(C1)
        c = 2.0 * (enc - norm.c1_min) / (norm.c1_max - norm.c1_min) - 1.0
        gain = norm.c1_ref / C1 if norm.output_scaling == "compliance" else 1.0
        return np.array(
            [c, math.cos(p), math.sin(p) * math.cos(t), math.sin(p) * math.sin(t), gain], np.float32
        )

    def _warn_if_outside(self, C1: float, phi: float, theta: float) -> None:
        for message in self.trained.warnings(C1, phi, theta):
            warnings.warn(
                message + "; the prediction is an extrapolation", ExtrapolationWarning, stacklevel=4
            )
