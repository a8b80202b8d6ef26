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

from fem.directions import gravity_direction
from surrogate.checkpoint import Checkpoint, load_checkpoint
from surrogate.exceptions import ExtrapolationWarning, ModelFileError
from surrogate.model import (
    ACTIVATIONS,
    boundary_network,
    branch_weights,
    mlp,
    point_inputs,
    weighs_fields,
)

DIRECTION_REACH = 1.5
"""A query off the plane whose direction is farther than this many of the training directions'
typical spacing (the median angle to each one's nearest) from every one of them is an
extrapolation."""


def _unit_directions(pairs: Any) -> np.ndarray:
    """Unit gravity directions of (Φ, θ) pairs in degrees, shape (n, 3)."""
    angles = np.asarray(pairs, dtype=float).reshape(-1, 2)
    return gravity_direction(angles[:, 0], angles[:, 1])


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
        self._build_range_checks()
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
        act = ACTIVATIONS[config.activation]
        u_scale = np.float32(norm.u_scale)

        def split_first(layers, idx, gain):
            W0, b0 = (np.asarray(a, np.float32) for a in layers[0])
            pre = pts[idx] @ W0[:3] + b0  # point part of the first layer, once per mesh
            return {
                "pre": jnp.asarray(pre),
                "Wc": jnp.asarray(W0[3:]),
                "rest": [(jnp.asarray(W), jnp.asarray(b)) for W, b in layers[1:]],
                "gain": jnp.asarray((gain * u_scale).astype(np.float32)[:, None]),
            }

        def fields_of(layers, idx, gain):
            # a separable model's fields at the points, once per mesh, gain and 1/√modes
            # included, as one (n · 3, modes) matrix: a query is then one matrix-vector product
            # (XLA's CPU backend runs a rank-3 contraction several times slower)
            fields = np.asarray(mlp(layers, point_inputs(jnp.asarray(pts[idx]), config),
                                    config.activation))
            fields = fields.reshape(len(idx), 3, config.modes) / math.sqrt(config.modes)
            fields = fields * (gain * u_scale)[:, None, None]
            return {"fields": jnp.asarray(fields.reshape(-1, config.modes).astype(np.float32))}

        def modes_of(_, idx, gain):
            # a pod model's modes at the points, gain included, as fields_of lays them out
            modes = self.basis[idx] * (gain * u_scale)[:, None, None]
            return {"fields": jnp.asarray(modes.reshape(-1, config.modes).astype(np.float32,
                                                                                copy=False))}

        separable = weighs_fields(config)
        prepare = {"separable": fields_of, "pod": modes_of}.get(config.structure, split_first)
        parts = {"domain": prepare(self.params.get("domain"), domain, factor[domain])}
        net = None if self._clamped_zero else boundary_network(config)
        if net is not None and bound.size:
            parts["boundary"] = prepare(self.params[net], bound, factor[bound])
        if separable:
            parts["branch"] = self.params["branch"]
        n_bound = int(bound.size)
        inverse_j = jnp.asarray(inverse.astype(np.int32))

        linear_in_gravity = config.output_form == "gravity_linear"

        def forward(part, c):
            h = act(part["pre"] + c[:4] @ part["Wc"])
            for W, b in part["rest"][:-1]:
                h = act(h @ W + b)
            W, b = part["rest"][-1]
            if linear_in_gravity:  # M ĝ: the last layer contracted with ĝ, once per query
                W = W.reshape(W.shape[0], 3, 3) @ c[1:4]
                b = b.reshape(3, 3) @ c[1:4]
            return (h @ W + b) * (part["gain"] * c[4])

        def run(parts, c):
            if separable:  # the branch once, then one weighted sum of the fields per part
                weights = branch_weights(parts["branch"], c[None, :4], config)[0] * c[4]
                out = [(parts["domain"]["fields"] @ weights).reshape(-1, 3)]
                if "boundary" in parts:
                    out.append((parts["boundary"]["fields"] @ weights).reshape(-1, 3))
            else:
                out = [forward(parts["domain"], c)]
                if "boundary" in parts:
                    out.append(forward(parts["boundary"], c))
            if "boundary" not in parts and n_bound:
                out.append(jnp.zeros((n_bound, 3), jnp.float32))
            return jnp.take(jnp.concatenate(out), inverse_j, axis=0)

        self._parts = parts
        self._run = jax.jit(run)

    def _build_range_checks(self) -> None:
        rng = self.training_range or {}
        self._c1_range = tuple(rng.get("C1_kPa", (0.0, math.inf)))
        phis = sorted({float(p) % 360.0 for p in rng.get("phi_deg", [])})
        self._phi_gap: tuple[float, float] | None = None
        if len(phis) > 1:
            gaps = [
                (phis[i], (phis[(i + 1) % len(phis)] - phis[i]) % 360.0 or 360.0)
                for i in range(len(phis))
            ]
            start, widest = max(gaps, key=lambda g: g[1])
            # An arc without training angles more than twice as wide as the typical spacing
            # is outside the training range; elsewhere Φ is interpolated.
            if widest > 2.0 * float(np.median([g[1] for g in gaps])):
                self._phi_gap = (start, widest)
        elif len(phis) == 1:
            self._phi_gap = (phis[0], 360.0)
        self._thetas = [float(t) for t in rng.get("theta_deg", [])]
        # A sweep off the plane (several θ, e.g. sweep.sphere) is judged by direction: its Φ
        # alone has gaps that other θ fill, so the arc test applies to a one-θ sweep only.
        self._directions: np.ndarray | None = None
        self._direction_reach = self._direction_spacing = math.inf
        pairs = rng.get("directions") or []
        if len(self._thetas) > 1 and len(pairs) > 1:
            self._phi_gap = None
            self._directions = _unit_directions(pairs)
            cos = np.clip(self._directions @ self._directions.T, -1.0, 1.0)
            np.fill_diagonal(cos, -1.0)
            spacing = self._direction_spacing = float(
                np.median(np.degrees(np.arccos(cos.max(axis=1))))
            )
            # a query midway between training directions is about 0.6 spacings from the
            # nearest; beyond 1.5 it lies where the sweep has none (e.g. head-down for a
            # sweep of the caudal half)
            self._direction_reach = DIRECTION_REACH * spacing
        self._unconverged = [
            (float(c), float(p), float(t)) for c, p, t in rng.get("unconverged", [])
        ]
        # the angles a query's neighbours are taken from, and the failures' directions: built
        # once, not per prediction
        self._sweep_angles = sorted(set(phis) | {p % 360.0 for _, p, _ in self._unconverged})
        self._unconverged_directions = _unit_directions(
            [(p, t) for _, p, t in self._unconverged] or np.zeros((0, 2)))
        # each training direction's softest FE solution, (C1, Φ, θ)
        self._softest = [
            (float(lo), float(p), float(t)) for p, t, lo, _ in rng.get("c1_by_direction", [])
        ]
        self._softest_directions = _unit_directions(
            [(p, t) for _, p, t in self._softest] or np.zeros((0, 2)))

    def range_checks(self) -> dict[str, Any]:
        """What decides that a query is an extrapolation (for :mod:`surrogate.export`).

        ``c1_kPa``: the trained C1 range; ``phi_gap``: ``[start, width]`` of the arc of Φ without
        training angles (degrees), or None; ``theta_deg``: the trained θ; ``directions``: the
        trained unit gravity directions of a sweep off the plane (else None),
        ``direction_spacing_deg`` their typical spacing and ``direction_reach_deg`` the angle
        from the nearest beyond which a query is outside them; ``unconverged``: the
        sweep's failed cases (C1, Φ, θ); ``softest``: each training direction's softest
        trained C1, as (C1, Φ, θ); ``sweep_phi_deg``: the angles (mod 360°) whose failures and
        softest solutions judge a query between them.
        """
        return {
            "c1_kPa": [v if math.isfinite(v) else None for v in self._c1_range],
            "phi_gap": None if self._phi_gap is None else list(self._phi_gap),
            "theta_deg": list(self._thetas),
            "directions": None if self._directions is None else self._directions.tolist(),
            "direction_spacing_deg": (self._direction_spacing
                                      if math.isfinite(self._direction_spacing) else None),
            "direction_reach_deg": (self._direction_reach
                                    if math.isfinite(self._direction_reach) else None),
            "unconverged": [list(case) for case in self._unconverged],
            "softest": [list(case) for case in self._softest],
            "sweep_phi_deg": list(self._sweep_angles),
        }

    def _beside(self, cases: list[tuple[float, float, float]], units: np.ndarray, phi: float,
                theta: float) -> list[tuple[float, float, float]]:
        """The (C1, Φ, θ) entries of ``cases`` whose direction lies beside the query's.

        A model of the plane judges a query at a sweep angle by that angle's entries, one
        between two angles by both neighbours' (same θ); a model off the plane by the entries
        whose direction (``units``, one row per entry) lies within the training directions'
        typical spacing of the query's.
        """
        if not cases:
            return []
        phi, theta = self.plane_name(phi, theta)
        if self._directions is not None:
            cos = np.clip(units @ _unit_directions([(phi, theta)])[0], -1.0, 1.0)
            angles = np.degrees(np.arccos(cos))
            return [case for case, angle in zip(cases, angles, strict=True)
                    if angle <= self._direction_spacing + 1e-9]
        q = phi % 360.0
        below = min(self._sweep_angles, key=lambda p: (q - p) % 360.0)
        above = min(self._sweep_angles, key=lambda p: (p - q) % 360.0)
        return [
            (c, p, t)
            for c, p, t in cases
            if abs(t - theta) < 1e-6
            and any(abs((p - n + 180.0) % 360.0 - 180.0) < 1e-6 for n in (below, above))
        ]

    def plane_name(self, phi: float, theta: float) -> tuple[float, float]:
        """A query in a one-plane model's plane under the plane's own name, (Φ', θ0).

        Gravity at (Φ, θ0 + 180°) is gravity at (−Φ, θ0), and θ0 ± 360° is θ0: such a query
        is judged as the sweep named that direction (Φ' in (−180°, 180°], to 1e-6°). A query
        off the plane, or a model trained off it, keeps its angles.
        """
        if (self._directions is not None or len(self._thetas) != 1
                or abs(theta - self._thetas[0]) < 1e-6):
            return phi, theta
        t0 = math.radians(self._thetas[0])
        g = _unit_directions([(phi, theta)])[0]
        if abs(g[2] * math.cos(t0) - g[1] * math.sin(t0)) > 1e-9:
            return phi, theta
        along = g[1] * math.cos(t0) + g[2] * math.sin(t0)
        return round(math.degrees(math.atan2(along, g[0])), 6) + 0.0, self._thetas[0]

    def unconverged_beside(
        self, C1: float, phi: float, theta: float
    ) -> tuple[float, float, float] | None:
        """The stiffest failed sweep case beside the query's direction, if C1 is not stiffer.

        The sweep's FE solves fail below some C1 in some directions (the model has no
        equilibrium there, or none on the load path; docs/solver.md). "Beside" as
        :meth:`_beside`.
        """
        beside = self._beside(self._unconverged, self._unconverged_directions, phi, theta)
        if not beside:
            return None
        stiffest = max(beside)
        return stiffest if C1 <= stiffest[0] + 1e-9 else None

    def softest_beside(
        self, C1: float, phi: float, theta: float
    ) -> tuple[float, float, float] | None:
        """The trained direction beside the query's whose softest FE solution is stiffer than C1.

        As (that softest C1, Φ, θ): the one with the stiffest such minimum, or None where every
        direction beside the query (:meth:`_beside`) was trained at C1 or softer. A sweep need
        not solve every direction at every C1 (``sweep.refine``'s bands start at their own
        C1_min, and a direction's softest solves may fail): below a direction's softest
        solution the model extrapolates in C1 there, though C1 lies inside its global range.
        None for a model saved without the per-direction record.
        """
        beside = self._beside(self._softest, self._softest_directions, phi, theta)
        stiffer = [entry for entry in beside if C1 < entry[0] - 1e-9]
        return max(stiffer) if stiffer else None

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
        basis = None
        if c.config.structure == "pod":
            from surrogate.interpolation import (
                interpolate,
                interpolation_matrix,
                locate,
                locate_quadratic,
            )

            if c.nodes is not None:
                nodes = c.nodes.X, c.nodes.basis
                where = locate_quadratic(c.nodes.X, c.nodes.cells, points)
            elif c.cells is not None:
                nodes = self.X, c.basis
                where = locate(self.X, c.cells, points)
            else:
                raise ValueError(
                    "this pod model answers at its material points only: its dataset has no "
                    "mesh cells to interpolate its modes in (rebuild the dataset with its mesh, "
                    "snakemake --forcerun aggregate, and train again)")
            if len(points) > len(nodes[0]):
                # more points than nodes: the field at the nodes, then at the points (the same
                # sum by linearity), in memory and time that grow with the points as 3 values
                # each, not as 3 × modes
                return Surrogate(replace(
                    c, X=nodes[0], boundary=np.zeros(len(nodes[0]), dtype=bool),
                    point_factor=None, node_index=None, basis=nodes[1], cells=None, nodes=None,
                ), clamped_zero=True,
                    between=(points, interpolation_matrix(*where, len(nodes[0]))))
            basis = interpolate(nodes[1], *where).astype(np.float32, copy=False)
        boundary = np.zeros(len(points), dtype=bool)
        if c.config.structure != "pod" and c.cells is not None:
            # the networks answer anywhere, but only the body is trained: a point outside is
            # refused, and one on the chest wall's clamped face (a combination of boundary
            # corners alone) answers zero, as FE has it
            from surrogate.interpolation import locate

            rows, weights = locate(self.X, c.cells, points)
            boundary = np.where(self.boundary[rows], 0.0, weights).sum(axis=1) <= 1e-9
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
                the softest C1 trained beside it (:meth:`softest_beside`).
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

    def direction_outside(self, phi: float, theta: float) -> float | None:
        """The angle (degrees) from gravity at (Φ, θ) to the nearest training direction.

        Only where it lies outside them (beyond :data:`DIRECTION_REACH` spacings), for a model
        trained off the plane; None otherwise, and for a model of the plane (judged by Φ and θ,
        under the plane's own name: :meth:`plane_name`).
        """
        if self._directions is None:
            return None
        cos = (self._directions @ _unit_directions([(phi, theta)])[0]).max()
        nearest = float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))
        return nearest if nearest > self._direction_reach else None

    def _warn_if_outside(self, C1: float, phi: float, theta: float) -> None:
        messages = []
        lo, hi = self._c1_range
        given = f"Φ = {phi}°, θ = {theta}°"
        named_as = self.plane_name(phi, theta)
        renamed = named_as != (phi, theta)
        phi, theta = named_as
        if not lo - 1e-9 <= C1 <= hi + 1e-9:
            messages.append(f"C1 = {C1} kPa is outside the training range [{lo}, {hi}] kPa")
        if self._phi_gap is not None:
            start, width = self._phi_gap
            offset = (phi - start) % 360.0
            if 1e-6 < offset < width - 1e-6:
                named = (f"gravity at {given} (Φ = {phi}° in the trained plane)" if renamed
                         else f"Φ = {phi}°")
                messages.append(f"{named} lies in a {width:.0f}° arc without training angles")
        nearest = self.direction_outside(phi, theta)
        if nearest is not None:
            messages.append(
                f"gravity at Φ = {phi}°, θ = {theta}° is {nearest:.0f}° from the nearest "
                f"training direction (they are {self._direction_spacing:.0f}° apart)"
            )
        if (
            self._thetas
            and abs(math.sin(math.radians(phi))) > 1e-6
            and min(abs(theta - t) for t in self._thetas) > 1e-6
            and len(self._thetas) == 1
        ):
            messages.append(
                f"θ = {theta}° but the surrogate was trained at θ = {self._thetas[0]}° only"
            )
        def at(p: float, t: float) -> str:  # a sweep direction: Φ alone in the plane
            return f"Φ = {p:g}°" if self._directions is None else f"Φ = {p:g}°, θ = {t:g}°"

        query = f"C1 = {C1} kPa, {given}"
        failed = self.unconverged_beside(C1, phi, theta)
        if failed is not None:
            c1, p, t = failed
            messages.append(
                f"the sweep's FE solve did not converge at C1 = {c1:g} kPa, {at(p, t)} (beside "
                f"{query}), so no FE solution backs C1 ≤ {c1:g} kPa there"
            )
        softest = None if failed is not None or C1 < lo - 1e-9 else self.softest_beside(
            C1, phi, theta)
        if softest is not None:
            c1, p, t = softest
            messages.append(
                f"the sweep's softest FE solution at {at(p, t)} (beside {query}) is at C1 = "
                f"{c1:g} kPa, so no FE solution backs C1 < {c1:g} kPa there"
            )
        for message in messages:
            warnings.warn(
                message + "; the prediction is an extrapolation", ExtrapolationWarning, stacklevel=4
            )
