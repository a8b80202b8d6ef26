"""Save, load and query a trained surrogate; also a command-line interface.

A model folder holds ``model.json`` (hyperparameters, normalisation, training
range, metrics) and ``params.npz`` (weights as named arrays, plus the material
points). Nothing is pickled; loading rebuilds the network skeleton from the JSON
first and checks every array against it.

Example::

    python -m surrogate.predict results/surrogate/model --c1 1.0 --phi 180 --output u.npy
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

from surrogate.config import SurrogateConfig
from surrogate.data import Dataset, Normalisation, gravity_direction, write_json
from surrogate.model import Params, apply, from_arrays, to_arrays
from surrogate.train import TrainResult

log = logging.getLogger(__name__)

FORMAT_VERSION = 1
MODEL_JSON = "model.json"
PARAMS_NPZ = "params.npz"


class ModelFileError(ValueError):
    """A model folder is missing, corrupt or of another architecture."""


class ExtrapolationWarning(UserWarning):
    """The query lies outside the parameter range the surrogate was trained on."""


def save_model(folder: str | Path, result: TrainResult, ds: Dataset) -> Path:
    """Write a trained surrogate to ``folder``; returns the path of ``model.json``."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    cases = result.train_cases if result.train_cases is not None else np.flatnonzero(ds.converged)
    arrays = to_arrays(result.params)
    np.savez(folder / PARAMS_NPZ, points_X=ds.X, points_boundary=ds.boundary, **arrays)
    meta = {
        "format_version": FORMAT_VERSION,
        "config": result.config.as_dict(),
        "normalisation": result.normalisation.as_dict(),
        "n_points": int(ds.n_points),
        "training_range": {
            "C1_kPa": [float(ds.C1[cases].min()), float(ds.C1[cases].max())],
            "phi_deg": sorted({float(v) for v in ds.phi[cases]}),
            "theta_deg": sorted({float(v) for v in ds.theta[cases]}),
        },
        "metrics": result.summary(),
        "inputs": ["x", "y", "z", "C1 (scaled)", "g_x/|g|", "g_y/|g|", "g_z/|g|"],
        "outputs": ["u_x", "u_y", "u_z (mm)"],
    }
    path = folder / MODEL_JSON
    write_json(path, meta)
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
    """

    def __init__(
        self,
        config: SurrogateConfig,
        params: Params,
        normalisation: Normalisation,
        X: np.ndarray,
        boundary: np.ndarray,
        training_range: dict[str, Any],
    ) -> None:
        self.config = config
        self.params = params
        self.normalisation = normalisation
        self.X = X
        self.boundary = boundary
        self.training_range = training_range
        self._points = jnp.asarray(normalisation.points(X), dtype=jnp.float32)
        self._boundary = jnp.asarray(boundary)
        activation, scale = config.activation, normalisation.u_scale
        points, flags = self._points, self._boundary

        @jax.jit
        def _predict(params: Params, case_features: jax.Array) -> jax.Array:
            feats = jnp.broadcast_to(case_features, (points.shape[0], case_features.shape[0]))
            x = jnp.concatenate([points, feats], axis=1)
            return apply(params, x, flags, activation) * scale

        self._predict = _predict

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
            with np.load(folder / PARAMS_NPZ) as npz:
                arrays = {k: npz[k] for k in npz.files}
        except (OSError, json.JSONDecodeError, ValueError) as err:
            raise ModelFileError(f"cannot read a surrogate model from {folder}: {err}") from None
        try:
            config = SurrogateConfig.from_mapping(meta["config"])
            X = arrays.pop("points_X")
            boundary = arrays.pop("points_boundary")
            params = from_arrays(arrays, config)
            norm = Normalisation.from_dict(meta["normalisation"])
        except (KeyError, ValueError) as err:
            raise ModelFileError(f"{folder}: {err}") from None
        return cls(config, params, norm, X, boundary, meta.get("training_range", {}))

    def predict(self, C1: float, phi: float, theta: float = 0.0) -> np.ndarray:
        """Displacement (N, 3) in mm of every material point for one setup.

        Args:
            C1: neo-Hookean parameter, kPa.
            phi: gravity elevation angle Φ, degrees.
            theta: gravity azimuth angle θ, degrees.

        Raises:
            ValueError: if an input is not a finite number or C1 is not positive.
        """
        for name, value in (("C1", C1), ("phi", phi), ("theta", theta)):
            if not isinstance(value, (int, float, np.floating, np.integer)) or not math.isfinite(value):
                raise ValueError(f"{name} must be a finite number, got {value!r}")
        if C1 <= 0:
            raise ValueError(f"C1 must be positive, got {C1} kPa")
        self._warn_if_outside(C1, phi, theta)
        return np.asarray(self._predict(self.params, self.case_features(C1, phi, theta)))

    def case_features(self, C1: float, phi: float, theta: float = 0.0) -> jax.Array:
        """Normalised case inputs (4,) as the network sees them."""
        direction = gravity_direction(np.asarray(phi, dtype=float), np.asarray(theta, dtype=float))
        return jnp.asarray(self.normalisation.case(np.asarray(C1), direction), dtype=jnp.float32)

    def _warn_if_outside(self, C1: float, phi: float, theta: float) -> None:
        rng = self.training_range
        if not rng:
            return
        lo, hi = rng["C1_kPa"]
        messages = []
        if not lo - 1e-9 <= C1 <= hi + 1e-9:
            messages.append(f"C1 = {C1} kPa is outside the training range [{lo}, {hi}] kPa")
        phis = np.asarray(rng["phi_deg"])
        gap = np.min(np.abs((phis - phi + 180.0) % 360.0 - 180.0))
        if len(phis) > 1:
            spacing = np.max(np.diff(np.sort(np.concatenate([phis, phis[:1] + 360.0]))))
            if gap > spacing:
                messages.append(f"Φ = {phi}° is {gap:.0f}° from the nearest training angle")
        if not any(np.isclose(theta, t) for t in rng["theta_deg"]) and len(rng["theta_deg"]) == 1:
            messages.append(f"θ = {theta}° but the surrogate was trained at θ = {rng['theta_deg'][0]}° only")
        for message in messages:
            warnings.warn(message + "; the prediction is an extrapolation", ExtrapolationWarning, stacklevel=3)


def write_prediction_xdmf(path: str | Path, mesh_xdmf: str | Path, X: np.ndarray, u_mm: np.ndarray) -> None:
    """Write a predicted displacement on the mesh's tetrahedra as XDMF (via meshio)."""
    import h5py
    import meshio

    mesh_h5 = Path(mesh_xdmf).with_suffix(".h5")
    with h5py.File(mesh_h5, "r") as h5:
        geometry = h5["Mesh/mesh/geometry"][...]
        topology = h5["Mesh/mesh/topology"][...]
    if geometry.shape[0] != X.shape[0] or not np.allclose(geometry, X, atol=1e-9):
        raise ModelFileError(f"{mesh_xdmf} is not the mesh the surrogate was trained on")
    mesh = meshio.Mesh(geometry, [("tetra", topology[:, :4])], point_data={"displacement_mm": u_mm})
    meshio.write(str(path), mesh)


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("model", help="model folder (or its model.json)")
    parser.add_argument("--c1", type=float, required=True, help="C1 in kPa")
    parser.add_argument("--phi", type=float, required=True, help="gravity elevation angle, degrees")
    parser.add_argument("--theta", type=float, default=0.0, help="gravity azimuth angle, degrees")
    parser.add_argument("--output", help="write the (N, 3) displacement in mm as .npy")
    parser.add_argument("--xdmf", help="write the displacement on the mesh as XDMF")
    parser.add_argument("--mesh", default="results/mesh/mesh.xdmf", help="mesh for --xdmf")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(message)s")
    try:
        model = Surrogate.load(args.model)
        u = model.predict(args.c1, args.phi, args.theta)
    except (ModelFileError, ValueError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    norms = np.linalg.norm(u, axis=1)
    print(f"{u.shape[0]} points: max |u| = {norms.max():.3f} mm, mean |u| = {norms.mean():.3f} mm")
    if args.output:
        np.save(args.output, u)
    if args.xdmf:
        write_prediction_xdmf(args.xdmf, args.mesh, model.X, u)
    return 0


if __name__ == "__main__":
    sys.exit(main())
