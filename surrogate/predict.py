"""Save, load and query a trained surrogate; also a command-line interface.

A model folder holds ``model.json`` (hyperparameters, normalisation, training
range, metrics) and ``params.npz`` (weights as named arrays, plus the material
points, their boundary flags, mesh node indices and, in the exact Dirichlet mode,
the factor φ). Nothing is pickled; loading rebuilds the network skeleton from the
JSON first and checks every array against it.

Prediction is built for speed: the first layer's point part ``X W_x + b`` does not
depend on the query, so it is computed once per model; a query then costs one
rank-one update, the remaining layers and one gather, in one jitted float32 call
with static shapes. Points on the rib go through the boundary network (``network``
mode), the shared network (``shared``) or are exactly zero (``exact``).

Example::

    python -m surrogate.predict results/surrogate/model --c1 1.0 --phi 180 --output u.npy \\
        --xdmf u.xdmf --mesh results/mesh/mesh.xdmf
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import sys
import warnings
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from surrogate.config import SurrogateConfig, SurrogateConfigError
from surrogate.data import Dataset, Normalisation, write_json
from surrogate.model import ACTIVATIONS, Params, boundary_network, from_arrays, to_arrays
from surrogate.train import TrainResult

log = logging.getLogger(__name__)

FORMAT_VERSION = 2
MODEL_JSON = "model.json"
PARAMS_NPZ = "params.npz"
HISTORY_JSON = "history.json"


class ModelFileError(ValueError):
    """A model folder is missing, corrupt or of another architecture."""


class ExtrapolationWarning(UserWarning):
    """The query lies outside the parameter range the surrogate was trained on."""


def training_range(ds: Dataset, cases: np.ndarray) -> dict[str, Any]:
    """The C1, Φ and θ values of the given (training) cases.

    ``unconverged`` lists the (C1, Φ, θ) of the dataset's cases whose FE solve failed:
    holes in the range, where no FE solution backs a prediction.
    """
    return {
        "C1_kPa": [float(ds.C1[cases].min()), float(ds.C1[cases].max())],
        "phi_deg": sorted({float(v) for v in ds.phi[cases]}),
        "theta_deg": sorted({float(v) for v in ds.theta[cases]}),
        "unconverged": unconverged_cases(ds),
    }


def unconverged_cases(ds: Dataset) -> list[list[float]]:
    """[C1 (kPa), Φ, θ (degrees)] of every case of ``ds`` whose FE solve failed."""
    return [[float(ds.C1[i]), float(ds.phi[i]), float(ds.theta[i])]
            for i in np.flatnonzero(~ds.converged)]


def save_model(folder: str | Path, result: TrainResult, ds: Dataset) -> Path:
    """Write a trained surrogate (and its training history) to ``folder``.

    Returns:
        The path of ``model.json``.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    cases = result.train_cases if result.train_cases is not None else np.flatnonzero(ds.converged)
    extra = {}
    if result.point_factor is not None:
        extra["points_factor"] = result.point_factor
    node_index = ds.node_index if ds.node_index is not None else np.arange(ds.n_points)
    np.savez(
        folder / PARAMS_NPZ,
        points_X=ds.X,
        points_boundary=ds.boundary,
        points_node_index=node_index,
        **extra,
        **to_arrays(result.params),
    )
    meta = {
        "format_version": FORMAT_VERSION,
        "config": result.config.as_dict(),
        "normalisation": result.normalisation.as_dict(),
        "n_points": int(ds.n_points),
        "training_range": training_range(ds, cases),
        "held_out_cases": [str(ds.ids[c]) for c in (result.held_out_cases if result.held_out_cases is not None else [])],
        "metrics": result.summary(),
        "inputs": ["x", "y", "z", "C1 (encoded, scaled)", "g_x/|g|", "g_y/|g|", "g_z/|g|"],
        "outputs": ["u_x", "u_y", "u_z (mm)"],
    }
    path = folder / MODEL_JSON
    write_json(path, meta)
    write_json(folder / HISTORY_JSON, {"summary": result.summary(), "history": result.history})
    return path


class Surrogate:
    """A loaded surrogate that predicts the displacement of every material point.

    Args:
        config: architecture.
        params: network weights.
        normalisation: input/output scaling.
        X: material points (N, 3), m.
        boundary: boundary flags (N,).
        training_range: the C1 / Φ / θ values it was trained on.
        point_factor: per-point output factor φ (exact Dirichlet mode), else None.
        node_index: index of each point in the mesh file (N,), for XDMF output.
        metrics: training metrics as saved (optional).
        held_out: ids of cases kept out of its training and validation.
    """

    def __init__(
        self,
        config: SurrogateConfig,
        params: Params,
        normalisation: Normalisation,
        X: np.ndarray,
        boundary: np.ndarray,
        training_range: dict[str, Any],
        point_factor: np.ndarray | None = None,
        node_index: np.ndarray | None = None,
        metrics: dict[str, Any] | None = None,
        held_out: list[str] | None = None,
    ) -> None:
        if config.boundary == "exact" and point_factor is None:
            raise ModelFileError("an exact-Dirichlet model needs its point factor (points_factor)")
        self.config = config
        self.params = params
        self.normalisation = normalisation
        self.X = np.asarray(X)
        self.boundary = np.asarray(boundary, dtype=bool)
        self.training_range = training_range
        self.point_factor = point_factor
        self.node_index = np.arange(len(X)) if node_index is None else np.asarray(node_index)
        self.metrics = metrics or {}
        self.held_out = list(held_out or [])
        self._build_range_checks()
        self._build_predictor()

    # -- construction -----------------------------------------------------------------
    def _build_predictor(self) -> None:
        """Precompute the query-independent part of the first layer and jit the rest."""
        config, norm = self.config, self.normalisation
        pts = norm.points(self.X).astype(np.float32)
        domain = np.flatnonzero(~self.boundary)
        bound = np.flatnonzero(self.boundary)
        inverse = np.argsort(np.concatenate([domain, bound]))
        factor = np.ones(len(self.X), np.float32) if self.point_factor is None else self.point_factor
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

        parts = {"domain": split_first(self.params["domain"], domain, factor[domain])}
        net = boundary_network(config)
        if net is not None and bound.size:
            parts["boundary"] = split_first(self.params[net], bound, factor[bound])
        n_bound = int(bound.size)
        inverse_j = jnp.asarray(inverse.astype(np.int32))

        def forward(part, c):
            h = act(part["pre"] + c[:4] @ part["Wc"])
            for W, b in part["rest"][:-1]:
                h = act(h @ W + b)
            W, b = part["rest"][-1]
            return (h @ W + b) * (part["gain"] * c[4])

        def run(parts, c):
            out = [forward(parts["domain"], c)]
            if "boundary" in parts:
                out.append(forward(parts["boundary"], c))
            elif n_bound:
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
            gaps = [(phis[i], (phis[(i + 1) % len(phis)] - phis[i]) % 360.0 or 360.0)
                    for i in range(len(phis))]
            start, widest = max(gaps, key=lambda g: g[1])
            # An arc without training angles more than twice as wide as the typical spacing
            # is outside the training range; elsewhere Φ is interpolated.
            if widest > 2.0 * float(np.median([g[1] for g in gaps])):
                self._phi_gap = (start, widest)
        elif len(phis) == 1:
            self._phi_gap = (phis[0], 360.0)
        self._thetas = [float(t) for t in rng.get("theta_deg", [])]
        self._unconverged = [(float(c), float(p), float(t)) for c, p, t in rng.get("unconverged", [])]
        # the angles a query's neighbours are taken from: built once, not per prediction
        self._sweep_angles = sorted(set(phis) | {p % 360.0 for _, p, _ in self._unconverged})

    def _unconverged_beside(self, C1: float, phi: float, theta: float) -> tuple[float, float] | None:
        """The stiffest failed sweep case at a sweep angle next to Φ, if C1 is not stiffer.

        The sweep's FE solves fail below some C1 at some angles (the model has no equilibrium
        there; README "The solver"). A query at a sweep angle is judged by that angle's
        failures, one between two angles by both neighbours' (same θ).
        """
        if not self._unconverged:
            return None
        q = phi % 360.0
        below = min(self._sweep_angles, key=lambda p: (q - p) % 360.0)
        above = min(self._sweep_angles, key=lambda p: (p - q) % 360.0)
        beside = [(c, p) for c, p, t in self._unconverged
                  if abs(t - theta) < 1e-6 and any(
                      abs((p - n + 180.0) % 360.0 - 180.0) < 1e-6 for n in (below, above))]
        if not beside:
            return None
        c, p = max(beside)
        return (c, p) if C1 <= c + 1e-9 else None

    @classmethod
    def load(cls, folder: str | Path) -> Surrogate:
        """Load a model folder written by :func:`save_model`.

        Raises:
            ModelFileError: if files are missing or the weights do not fit the architecture.
        """
        folder = Path(folder)
        if folder.suffix == ".json":
            folder = folder.parent
        try:
            meta = json.loads((folder / MODEL_JSON).read_text())
            with np.load(folder / PARAMS_NPZ, allow_pickle=False) as npz:
                arrays = {k: npz[k] for k in npz.files}
        except (OSError, json.JSONDecodeError, ValueError) as err:
            raise ModelFileError(f"cannot read a surrogate model from {folder}: {err}") from None
        try:
            config = SurrogateConfig.from_mapping(meta["config"])
            points = {k: arrays.pop(k) for k in list(arrays) if k.startswith("points_")}
            params = from_arrays(arrays, config)
            norm = Normalisation.from_dict(meta["normalisation"])
            X, boundary = points["points_X"], points["points_boundary"]
        except (KeyError, TypeError, ValueError, SurrogateConfigError) as err:
            raise ModelFileError(f"{folder}: {err}") from None
        if X.shape != (meta.get("n_points", X.shape[0]), 3) or boundary.shape != (X.shape[0],):
            raise ModelFileError(f"{folder}: material points do not match n_points")
        return cls(
            config, params, norm, X, boundary, meta.get("training_range", {}),
            point_factor=points.get("points_factor"), node_index=points.get("points_node_index"),
            metrics=meta.get("metrics"), held_out=meta.get("held_out_cases"),
        )

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
            ExtrapolationWarning: if (C1, Φ, θ) lies outside the training range, or at or
                below a C1 at which the sweep's FE solve failed at the same or a
                neighbouring angle Φ.
        """
        return np.asarray(self._run(self._parts, self.features(C1, phi, theta)))

    def features(self, C1: float, phi: float, theta: float = 0.0) -> np.ndarray:
        """Checked query features: scaled C1, gravity direction, output gain (5,), float32."""
        for name, value in (("C1", C1), ("phi", phi), ("theta", theta)):
            if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)) \
                    or not math.isfinite(value):
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
        messages = []
        lo, hi = self._c1_range
        if not lo - 1e-9 <= C1 <= hi + 1e-9:
            messages.append(f"C1 = {C1} kPa is outside the training range [{lo}, {hi}] kPa")
        if self._phi_gap is not None:
            start, width = self._phi_gap
            offset = (phi - start) % 360.0
            if 1e-6 < offset < width - 1e-6:
                messages.append(f"Φ = {phi}° lies in a {width:.0f}° arc without training angles")
        if self._thetas and abs(math.sin(math.radians(phi))) > 1e-6 and \
                min(abs(theta - t) for t in self._thetas) > 1e-6 and len(self._thetas) == 1:
            messages.append(f"θ = {theta}° but the surrogate was trained at θ = {self._thetas[0]}° only")
        failed = self._unconverged_beside(C1, phi, theta)
        if failed is not None:
            messages.append(
                f"the sweep's FE solve did not converge at C1 = {failed[0]:g} kPa, Φ = "
                f"{failed[1]:g}° (beside C1 = {C1} kPa, Φ = {phi}°, θ = {theta}°), so no FE "
                f"solution backs C1 ≤ {failed[0]:g} kPa there")
        for message in messages:
            warnings.warn(message + "; the prediction is an extrapolation", ExtrapolationWarning, stacklevel=4)


def read_mesh_vertices(mesh_xdmf: str | Path, node_index: np.ndarray, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Tetrahedra of the mesh on the material points: ``(points (N, 3), cells (C, 4))``.

    The material points are the mesh vertices, listed by ``node_index`` into the mesh
    file's geometry; higher-order nodes are dropped.

    Raises:
        ModelFileError: if the mesh is not the one the points come from.
    """
    import h5py

    from meshes.tags import MESH_NAME

    mesh_h5 = Path(mesh_xdmf).with_suffix(".h5")
    try:
        with h5py.File(mesh_h5, "r") as h5:
            geometry = h5[f"Mesh/{MESH_NAME}/geometry"][...]
            topology = h5[f"Mesh/{MESH_NAME}/topology"][...]
    except (OSError, KeyError) as err:
        raise ModelFileError(f"cannot read the mesh {mesh_h5}: {err}") from None
    if node_index.max() >= geometry.shape[0] or not np.allclose(geometry[node_index], X, atol=1e-9):
        raise ModelFileError(f"{mesh_xdmf} is not the mesh the surrogate was trained on")
    lookup = np.full(geometry.shape[0], -1, np.int64)
    lookup[node_index] = np.arange(node_index.size)
    cells = lookup[topology[:, :4]]
    if np.any(cells < 0):
        raise ModelFileError(f"{mesh_xdmf}: a tetrahedron vertex is not a material point")
    return X, cells


def write_point_fields_xdmf(
    path: str | Path, mesh_xdmf: str | Path, node_index: np.ndarray, X: np.ndarray,
    fields: dict[str, np.ndarray],
) -> None:
    """Write per-point fields on the mesh's tetrahedra as XDMF + HDF5 (meshio), for ParaView."""
    import meshio

    points, cells = read_mesh_vertices(mesh_xdmf, node_index, X)
    mesh = meshio.Mesh(points, [("tetra", cells)], point_data={k: np.asarray(v) for k, v in fields.items()})
    meshio.write(str(path), mesh)


def write_prediction_xdmf(path: str | Path, mesh_xdmf: str | Path, model: Surrogate, u_mm: np.ndarray) -> None:
    """Write a predicted displacement (mm) and its magnitude on the mesh as XDMF."""
    write_point_fields_xdmf(
        path, mesh_xdmf, model.node_index, model.X,
        {"displacement_mm": u_mm, "displacement_magnitude_mm": np.linalg.norm(u_mm, axis=1)},
    )


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("model", help="model folder (or its model.json)")
    parser.add_argument("--c1", type=float, required=True, help="C1 in kPa")
    parser.add_argument("--phi", type=float, required=True, help="gravity elevation angle, degrees")
    parser.add_argument("--theta", type=float, default=0.0, help="gravity azimuth angle, degrees")
    parser.add_argument("--output", help="write the (N, 3) displacement in mm as .npy")
    parser.add_argument("--xdmf", help="write the displacement on the mesh as XDMF (ParaView)")
    parser.add_argument("--mesh", default="results/mesh/mesh.xdmf", help="mesh for --xdmf")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(message)s")
    logging.captureWarnings(True)
    try:
        model = Surrogate.load(args.model)
        u = model.predict(args.c1, args.phi, args.theta)
        if args.xdmf:
            write_prediction_xdmf(args.xdmf, args.mesh, model, u)
    except (ModelFileError, ValueError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    norms = np.linalg.norm(u, axis=1)
    print(f"{u.shape[0]} points: max |u| = {norms.max():.3f} mm, mean |u| = {norms.mean():.3f} mm")
    if args.output:
        np.save(args.output, u)
    return 0


if __name__ == "__main__":
    sys.exit(main())
