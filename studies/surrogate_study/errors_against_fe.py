"""A surrogate's error on one case, and its spread over a set of cases.

At the material points (:meth:`CaseErrors.of`), or between them at the cells' centroids of a
quadratic mesh (:class:`Centroids`, where the FE field is known by its shape functions); a
case's error is its mean, 95th percentile and maximum over the points, in mm and relative to
the case's largest FE displacement. Shared by every study that judges a model against FE:
the held-out models (:mod:`studies.surrogate_study.held_out`), the postures, the random cases off
the grid,
the direction density and the pod basis.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from fem.dataset import Dataset
from studies.results import Record
from surrogate.exceptions import ExtrapolationWarning

if TYPE_CHECKING:  # JAX is imported by whoever has a model, not by this module's records
    from surrogate.predict import Surrogate


@dataclass(frozen=True, slots=True)
class CaseErrors(Record):
    """One model against FE on one case: point errors (norm of the difference, mm)."""

    case: str
    C1: float
    phi: float
    theta: float
    fe_max_mm: float
    mean_mm: float
    p95_mm: float
    max_mm: float
    relative_mean: float
    relative_p95: float
    relative_max: float

    @classmethod
    def between(
        cls, pred: np.ndarray, fe: np.ndarray, case: str, C1: float, phi: float, theta: float
    ) -> CaseErrors:
        """Errors of ``pred`` against ``fe`` (both (N, 3), mm)."""
        err = np.linalg.norm(pred - fe, axis=1)
        fe_max = float(np.linalg.norm(fe, axis=1).max())
        mean, p95, top = float(err.mean()), float(np.percentile(err, 95)), float(err.max())
        scale = fe_max if fe_max > 0 else float("nan")
        return cls(case, float(C1), float(phi), float(theta), fe_max, mean, p95, top,
                   mean / scale, p95 / scale, top / scale)

    @classmethod
    def of(cls, model: Surrogate, ds: Dataset, case: int,
           centroids: Centroids | None = None) -> CaseErrors:
        """The model's errors on case ``case`` of the dataset.

        At its material points; with ``centroids``, at the quadratic mesh's cell centroids
        instead (``model`` answering there: :meth:`Centroids.model`).
        """
        C1, phi, theta = float(ds.C1[case]), float(ds.phi[case]), float(ds.theta[case])
        with warnings.catch_warnings():  # a sweep case lies in the range by construction;
            warnings.simplefilter("ignore", ExtrapolationWarning)  # near a failed one it warns
            pred = model.predict(C1, phi, theta)
        fe = ds.displacement[case] if centroids is None else centroids.fe(ds, case)
        return cls.between(pred, fe, str(ds.ids[case]), C1, phi, theta)


@dataclass(frozen=True)
class Centroids:
    """The cell centroids of a quadratic mesh: points between the nodes, where a tumour lies.

    The FE field is quadratic in each 10-node cell; at a centroid it is a fixed combination of
    the cell's nodes (:func:`surrogate.interpolation.at_centroids`), exact whatever the model.
    A model's error there is what a user meets between the material points it trained on.

    Attributes:
        X: the centroids (C, 3), m, in the mesh's reference frame.
        cells: the 10-node cells (C, 10), rows of the dataset's ``/nodes``.
    """

    X: np.ndarray
    cells: np.ndarray

    @classmethod
    def of(cls, ds: Dataset) -> Centroids | None:
        """The dataset's centroids.

        None where it has no fields at a quadratic mesh's nodes (a linear mesh, or a dataset
        read without ``nodes=True``).
        """
        from surrogate.interpolation import at_centroids

        if ds.nodes is None or ds.nodes.displacement is None:
            return None
        return cls(at_centroids(ds.nodes.X, ds.nodes.cells), ds.nodes.cells)

    @classmethod
    def of_fields(cls, path: str | Path) -> tuple[Centroids, np.ndarray] | None:
        """A case's ``fields.h5``: its mesh's centroids and its FE displacement there (mm).

        None on a linear mesh, whose fields file lacks the FE field's edge values.

        Raises:
            fem.exceptions.DatasetError: if the file is not a case's fields.
        """
        from fem.case_files import read_node_displacement
        from surrogate.interpolation import at_centroids

        u, cells, nodes = read_node_displacement(path)
        if cells.ndim != 2 or cells.shape[1] != 10:
            return None
        return cls(at_centroids(nodes, cells), cells), at_centroids(1e3 * u, cells)

    def fe(self, ds: Dataset, case: int) -> np.ndarray:
        """Case ``case``'s FE displacement at the centroids (C, 3), mm."""
        from surrogate.interpolation import at_centroids

        return at_centroids(ds.nodes.displacement[case].astype(np.float64), self.cells)

    def model(self, model: Surrogate) -> Surrogate:
        """``model`` answering at the centroids (:meth:`surrogate.predict.Surrogate.at`)."""
        return model.at(self.X)


@dataclass(frozen=True, slots=True)
class ErrorSpread(Record):
    """Per-case errors over a set of cases.

    Attributes:
        cases: how many.
        mean_mm: the mean over the cases of their mean point error.
        p95_mm: the 95th percentile over the cases of their 95th-percentile point error.
        max_mm: the largest point error of any case.
        relative_mean: ``mean_mm``'s relative counterpart (mean of the relative means).
        relative_max: the largest relative point error of any case.
        worst_case: the case with the largest point error.
    """

    cases: int
    mean_mm: float
    p95_mm: float
    max_mm: float
    relative_mean: float
    relative_max: float
    worst_case: str

    @classmethod
    def over(cls, rows: Sequence[CaseErrors]) -> ErrorSpread:
        """The spread of ``rows`` (at least one).

        Raises:
            ValueError: if ``rows`` is empty.
        """
        if not rows:
            raise ValueError("no cases to summarise")
        worst = max(rows, key=lambda r: r.max_mm)
        return cls(
            cases=len(rows),
            mean_mm=float(np.mean([r.mean_mm for r in rows])),
            p95_mm=float(np.percentile([r.p95_mm for r in rows], 95)),
            max_mm=worst.max_mm,
            relative_mean=float(np.mean([r.relative_mean for r in rows])),
            relative_max=float(max(r.relative_max for r in rows)),
            worst_case=worst.case,
        )
