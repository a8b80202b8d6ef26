"""Turn (point, case) pairs of the FE dataset into normalised network inputs.

The dataset file is read by :func:`fem.dataset.read_dataset`, its owner.

Inputs of one sample (7 numbers): the material point's reference coordinates,
standardised; C1, mapped linearly to [-1, 1] over the training range; and the
unit gravity direction [cos Φ, sin Φ cos θ, sin Φ sin θ], which has no jump at
Φ = ±180° and extends unchanged to θ ≠ 0. Targets: displacement in mm divided
by one scalar scale, so the loss's L2 norm stays isotropic.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields
from typing import Any, NamedTuple

import numpy as np

from fem.dataset import Dataset
from fem.exceptions import DatasetError

N_INPUTS = 7
DIRECTION = slice(4, 7)
"""Columns of the inputs that hold the unit gravity direction."""


@dataclass(frozen=True)
class Normalisation:
    """Affine maps of inputs and outputs, fitted on the training data and saved with the model.

    Attributes:
        x_mean: mean of the material points (m).
        x_std: largest per-axis standard deviation of the points (m): one scale keeps
            the geometry's aspect ratio.
        c1_min: smallest encoded C1 of the training cases (maps to -1).
        c1_max: largest encoded C1 of the training cases (maps to +1).
        u_scale: displacement unit of the network (mm): the RMS training displacement,
            after the compliance scaling if any.
        c1_encoding: ``linear``, ``log`` or ``inverse`` (see :class:`SurrogateConfig`).
        output_scaling: ``none`` or ``compliance``.
        c1_ref: reference C1 of the compliance scaling (kPa), the softest training case.
    """

    x_mean: tuple[float, float, float]
    x_std: float
    c1_min: float
    c1_max: float
    u_scale: float
    c1_encoding: str = "linear"
    output_scaling: str = "none"
    c1_ref: float = 1.0

    @classmethod
    def fit(
        cls,
        ds: Dataset,
        cases: np.ndarray,
        c1_encoding: str = "linear",
        output_scaling: str = "none",
    ) -> Normalisation:
        """Fit on the given (training) cases."""
        c1 = ds.C1[cases]
        c1_ref = float(c1.min())
        encoded = _encode_c1(c1, c1_encoding)
        lo, hi = float(encoded.min()), float(encoded.max())
        if hi == lo:  # a single stiffness: map it to 0
            lo, hi = lo - 1.0, hi + 1.0
        u = ds.displacement[cases]
        if output_scaling == "compliance":
            u = u * (c1 / c1_ref)[:, None, None]
        scale = float(np.sqrt(np.nanmean(np.sum(u**2, axis=-1))))
        return cls(
            x_mean=tuple(float(v) for v in ds.X.mean(axis=0)),
            x_std=float(ds.X.std(axis=0).max()),
            c1_min=lo,
            c1_max=hi,
            u_scale=scale if scale > 0 else 1.0,
            c1_encoding=c1_encoding,
            output_scaling=output_scaling,
            c1_ref=c1_ref,
        )

    def as_dict(self) -> dict[str, Any]:
        """JSON-friendly mapping."""
        return asdict(self)

    @classmethod
    def from_dict(cls, values: dict[str, Any]) -> Normalisation:
        """Inverse of :meth:`as_dict`.

        Raises:
            ValueError: naming a value that is not a finite number, or a scale that is not
                positive (a model card edited or damaged: it would answer NaN).
        """
        norm = cls(**{**values, "x_mean": tuple(values["x_mean"])})
        numbers = {"x_std": norm.x_std, "c1_min": norm.c1_min, "c1_max": norm.c1_max,
                   "u_scale": norm.u_scale, "c1_ref": norm.c1_ref,
                   **{f"x_mean[{i}]": v for i, v in enumerate(norm.x_mean)}}
        for name, value in numbers.items():
            if isinstance(value, bool) or not isinstance(value, int | float) \
                    or not math.isfinite(value):
                raise ValueError(f"normalisation.{name} is {value!r}, not a finite number")
        for name in ("x_std", "u_scale", "c1_ref"):
            if numbers[name] <= 0:
                raise ValueError(f"normalisation.{name} is {numbers[name]!r}, not positive")
        if norm.c1_max <= norm.c1_min:
            raise ValueError(f"normalisation.c1_max ({norm.c1_max}) is not above c1_min "
                             f"({norm.c1_min})")
        return norm

    def points(self, X: np.ndarray) -> np.ndarray:
        """Standardised coordinates (N, 3)."""
        return (X - np.asarray(self.x_mean)) / self.x_std

    def case(self, C1: np.ndarray, direction: np.ndarray) -> np.ndarray:
        """Case features (..., 4): encoded and scaled C1, and the gravity direction."""
        encoded = _encode_c1(np.asarray(C1, dtype=float), self.c1_encoding)
        c = 2.0 * (encoded - self.c1_min) / (self.c1_max - self.c1_min) - 1.0
        return np.concatenate([np.asarray(c)[..., None], direction], axis=-1)

    def gain(self, C1: np.ndarray | float) -> np.ndarray:
        """Factor from network output to displacement in units of ``u_scale`` (per case)."""
        C1 = np.asarray(C1, dtype=float)
        if self.output_scaling == "compliance":
            return self.c1_ref / C1
        return np.ones_like(C1)


def _encode_c1(C1: np.ndarray, encoding: str) -> np.ndarray:
    if encoding == "log":
        return np.log(C1)
    if encoding == "inverse":
        return 1.0 / C1
    return C1


def dirichlet_factor(
    X: np.ndarray, boundary: np.ndarray, length: float, at: np.ndarray | None = None
) -> np.ndarray:
    """Smooth factor that vanishes exactly on the clamped points, φ = 1 − exp(−d / (length d_max)).

    ``d`` is each point's distance to the nearest clamped point and ``d_max`` its
    largest value over ``X``, so φ rises linearly off the rib (as the displacement does) and
    levels off at 1 in the bulk of the breast. Multiplying a network's output by φ
    enforces the homogeneous Dirichlet condition exactly.

    Args:
        X: material points (N, 3).
        boundary: clamped flags (N,); at least one must be set.
        length: length scale as a fraction of ``d_max``.
        at: other points (M, 3) to evaluate φ at, with the same ``d_max`` (a model queried
            between its material points); None for ``X`` itself.

    Raises:
        DatasetError: if no point is clamped.
    """
    from scipy.spatial import cKDTree

    if not np.any(boundary):
        raise DatasetError("an exact Dirichlet condition needs clamped (boundary) points")
    tree = cKDTree(X[boundary])
    d, _ = tree.query(X)
    d_max = float(d.max()) if d.max() > 0 else 1.0
    if at is not None:
        d, _ = tree.query(np.asarray(at, dtype=float))
    phi = 1.0 - np.exp(-d / (length * d_max))
    if at is None:
        phi[boundary] = 0.0
    return phi


@dataclass
class Samples:
    """Training or evaluation samples as the network sees them.

    Attributes:
        x: inputs (n, 7), float32.
        y: targets (n, 3), displacement / ``u_scale``, float32.
        gain: per-sample output multiplier (n,), float32: the compliance gain times
            φ (exact Dirichlet mode) or 1.
        boundary: clamped flags (n,).
        point: the sample's material point (n,), int32: its row of :class:`Tables` ``points``.
        case: the sample's case (n,), int32: its row of :class:`Tables` ``cases``.
    """

    x: np.ndarray
    y: np.ndarray
    gain: np.ndarray
    boundary: np.ndarray
    point: np.ndarray
    case: np.ndarray

    def __len__(self) -> int:
        return self.x.shape[0]

    def subset(self, mask: np.ndarray) -> Samples:
        """The samples where ``mask`` holds."""
        return Samples(*(getattr(self, f.name)[mask] for f in fields(self)))


class Tables(NamedTuple):
    """Every point's and every case's inputs, which samples index (a separable model's tables).

    Attributes:
        points: standardised material points (N, 3), float32.
        cases: case features (n_cases, 4), float32: encoded C1 and the gravity direction.
    """

    points: np.ndarray
    cases: np.ndarray


def tables(ds: Dataset, norm: Normalisation) -> Tables:
    """The dataset's points and cases as the networks see them."""
    return Tables(
        norm.points(ds.X).astype(np.float32),
        norm.case(ds.C1, ds.direction).astype(np.float32),
    )


def sample_arrays(
    ds: Dataset, samples: np.ndarray, norm: Normalisation, point_factor: np.ndarray | None = None
) -> Samples:
    """Network inputs, scaled targets, output gains and boundary flags of flat sample indices.

    Args:
        ds: the dataset.
        samples: flat indices ``case * N + point``.
        norm: the fitted normalisation.
        point_factor: per-point output factor (N,), e.g. :func:`dirichlet_factor`; 1 if None.
    """
    case, point = np.divmod(samples, ds.n_points)
    inputs = np.concatenate(
        [norm.points(ds.X)[point], norm.case(ds.C1[case], ds.direction[case])], axis=1
    ).astype(np.float32)
    targets = (ds.displacement[case, point] / norm.u_scale).astype(np.float32)
    gain = norm.gain(ds.C1)[case]
    if point_factor is not None:
        gain = gain * point_factor[point]
    return Samples(
        inputs,
        targets,
        gain.astype(np.float32),
        ds.boundary[point],
        point.astype(np.int32),
        case.astype(np.int32),
    )
