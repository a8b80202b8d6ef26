"""Load the FE dataset and turn (point, case) pairs into normalised network inputs.

Inputs of one sample (7 numbers): the material point's reference coordinates,
standardised; C1, mapped linearly to [-1, 1] over the training range; and the
unit gravity direction [cos Φ, sin Φ cos θ, sin Φ sin θ], which has no jump at
Φ = ±180° and extends unchanged to θ ≠ 0. Targets: displacement in mm divided
by one scalar scale, so the loss's L2 norm stays isotropic.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from fem.dataset import BOUNDARY, SPLITS

N_INPUTS = 7


class DatasetFormatError(ValueError):
    """The dataset cannot be used for training (the message names the problem)."""


@dataclass
class Dataset:
    """The parts of the HDF5 dataset the surrogate needs, in memory.

    Attributes:
        X: reference coordinates of the material points (N, 3), m.
        boundary: True where the point lies on a clamped surface (N,).
        C1: per case, kPa (M,).
        phi: per case, degrees (M,).
        theta: per case, degrees (M,).
        direction: unit gravity direction per case (M, 3).
        displacement: (M, N, 3) in mm; NaN rows for failed cases.
        converged: (M,) bool.
        splits: ``{"by_sample": {...}, "by_case": {...}}`` index arrays.
        ids: case identifiers (M,).
    """

    X: np.ndarray
    boundary: np.ndarray
    C1: np.ndarray
    phi: np.ndarray
    theta: np.ndarray
    direction: np.ndarray
    displacement: np.ndarray
    converged: np.ndarray
    splits: dict[str, dict[str, np.ndarray]]
    ids: np.ndarray

    @property
    def n_points(self) -> int:
        """Material points per case."""
        return self.X.shape[0]

    def case_index(self, C1: float, phi: float, theta: float = 0.0) -> int:
        """Index of the case with these parameters.

        Raises:
            KeyError: if the dataset has no such case.
        """
        hit = np.flatnonzero(
            np.isclose(self.C1, C1) & np.isclose(self.phi, phi) & np.isclose(self.theta, theta)
        )
        if hit.size == 0:
            raise KeyError(f"no case with C1={C1} kPa, phi={phi} deg, theta={theta} deg")
        return int(hit[0])

    def sample_indices(self, split: str, part: str) -> np.ndarray:
        """Flat sample indices (case * N + point) of a split part."""
        indices = self.splits[split][part]
        if split == "by_case":
            return (indices[:, None] * self.n_points + np.arange(self.n_points)[None, :]).ravel()
        return indices


def gravity_direction(phi_deg: np.ndarray, theta_deg: np.ndarray) -> np.ndarray:
    """Unit gravity direction of the paper's Eq. 1, shape (..., 3)."""
    phi, theta = np.radians(phi_deg), np.radians(theta_deg)
    return np.stack(
        [np.cos(phi), np.sin(phi) * np.cos(theta), np.sin(phi) * np.sin(theta)], axis=-1
    )


def load_dataset(path: str | Path) -> Dataset:
    """Read and check the HDF5 dataset written by :func:`fem.dataset.build_dataset`.

    Raises:
        DatasetFormatError: if the file is missing, empty, has NaN in a converged
            case, or lacks a split.
    """
    import h5py

    path = Path(path)
    if not path.is_file():
        raise DatasetFormatError(f"dataset {path} does not exist")
    try:
        with h5py.File(path, "r") as h5:
            for key in ("points/X", "points/kind", "cases/C1", "cases/phi", "displacement"):
                if key not in h5:
                    raise DatasetFormatError(f"dataset {path} lacks /{key}")
            splits: dict[str, dict[str, np.ndarray]] = {}
            for kind in ("by_sample", "by_case"):
                for part in SPLITS:
                    key = f"splits/{kind}/{part}"
                    if key not in h5:
                        raise DatasetFormatError(f"dataset {path} lacks the split /{key}")
                    splits.setdefault(kind, {})[part] = h5[key][...]
            ds = Dataset(
                X=h5["points/X"][...],
                boundary=h5["points/kind"][...] == BOUNDARY,
                C1=h5["cases/C1"][...],
                phi=h5["cases/phi"][...],
                theta=h5["cases/theta"][...],
                direction=gravity_direction(h5["cases/phi"][...], h5["cases/theta"][...]),
                displacement=1e3 * h5["displacement"][...],
                converged=h5["cases/converged"][...].astype(bool),
                splits=splits,
                ids=h5["cases/id"].asstr()[...],
            )
    except OSError as err:
        raise DatasetFormatError(f"dataset {path} is unreadable ({err})") from None
    if ds.X.shape[0] == 0 or ds.C1.shape[0] == 0:
        raise DatasetFormatError(f"dataset {path} is empty")
    if not ds.converged.any():
        raise DatasetFormatError(f"dataset {path} has no converged case")
    if not np.all(np.isfinite(ds.displacement[ds.converged])):
        raise DatasetFormatError(f"dataset {path} has NaN or inf displacements in converged cases")
    for kind, parts in splits.items():
        if parts["train"].size == 0 or parts["validation"].size == 0:
            raise DatasetFormatError(f"dataset {path}: split {kind} has an empty train or validation part")
    return ds


@dataclass(frozen=True)
class Normalisation:
    """Affine maps of inputs and outputs, fitted on the training data and saved with the model."""

    x_mean: tuple[float, float, float]
    x_std: float
    c1_min: float
    c1_max: float
    u_scale: float

    @classmethod
    def fit(cls, ds: Dataset, cases: np.ndarray) -> Normalisation:
        """Fit on the given (training) cases."""
        u = ds.displacement[cases]
        scale = float(np.sqrt(np.nanmean(np.sum(u**2, axis=-1))))
        c1 = ds.C1[cases]
        lo, hi = float(c1.min()), float(c1.max())
        if hi == lo:  # a single stiffness: map it to 0
            lo, hi = lo - 1.0, hi + 1.0
        return cls(
            x_mean=tuple(float(v) for v in ds.X.mean(axis=0)),
            x_std=float(ds.X.std(axis=0).max()),
            c1_min=lo,
            c1_max=hi,
            u_scale=scale if scale > 0 else 1.0,
        )

    def as_dict(self) -> dict[str, Any]:
        """JSON-friendly mapping."""
        return asdict(self)

    @classmethod
    def from_dict(cls, values: dict[str, Any]) -> Normalisation:
        """Inverse of :meth:`as_dict`."""
        return cls(**{**values, "x_mean": tuple(values["x_mean"])})

    def points(self, X: np.ndarray) -> np.ndarray:
        """Standardised coordinates (N, 3)."""
        return (X - np.asarray(self.x_mean)) / self.x_std

    def case(self, C1: np.ndarray, direction: np.ndarray) -> np.ndarray:
        """Case features (..., 4): scaled C1 and the gravity direction."""
        c = 2.0 * (np.asarray(C1, dtype=float) - self.c1_min) / (self.c1_max - self.c1_min) - 1.0
        return np.concatenate([c[..., None], direction], axis=-1)


def sample_arrays(
    ds: Dataset, samples: np.ndarray, norm: Normalisation
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Inputs (n, 7), scaled targets (n, 3) and boundary flags (n,) of flat sample indices."""
    case, point = np.divmod(samples, ds.n_points)
    inputs = np.concatenate(
        [norm.points(ds.X)[point], norm.case(ds.C1[case], ds.direction[case])], axis=1
    ).astype(np.float32)
    targets = (ds.displacement[case, point] / norm.u_scale).astype(np.float32)
    return inputs, targets, ds.boundary[point]


def write_json(path: str | Path, payload: dict[str, Any]) -> None:
    """Write JSON with a trailing newline."""
    with open(path, "w") as fh:
        json.dump(payload, fh, indent=2)
        fh.write("\n")
