"""Track material points from the imaged (loaded) posture to any other, through the FE model.

A point seen in the image (a tumour's centre, its margin) lies in the loaded configuration x.
Its material position in the reference X is found in the loaded mesh: the cell that contains
it, and the same local (barycentric) coordinates in that cell at its reference position (the
reference nodes interpolated with the mesh's own geometric order). From there the target
posture's forward solve on the reference carries it: p = X_p + u(X_p).

The reference comes from :func:`fem.reference.estimate_reference`; a point that lies outside
the loaded body (farther than ``tolerance`` from every cell) is refused by name.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from dolfinx import fem

from fem.case import CaseRunner
from fem.exceptions import InvalidParameterError
from fem.interpolation import evaluate
from fem.io import node_dofs
from fem.parameters import Gravity, Material


@dataclass(frozen=True)
class TrackedPoints:
    """Named points carried from the observed posture to a target posture (m, project frame).

    Attributes:
        names: the points' names.
        observed: positions in the observed (loaded) configuration.
        reference: their material positions in the reference configuration.
        target: positions in the target posture.
        converged: whether the target posture's solve converged.
    """

    names: list[str]
    observed: np.ndarray
    reference: np.ndarray
    target: np.ndarray
    converged: bool


def to_reference(
    runner: CaseRunner, X: np.ndarray, names: list[str], points: np.ndarray,
    tolerance: float = 1e-4,
) -> np.ndarray:
    """Material positions in the reference ``X`` of points given in the runner's (loaded) mesh.

    Raises:
        InvalidParameterError: naming every point farther than ``tolerance`` (m) outside the
            loaded body.
    """
    mesh = runner.mesh
    order = 2 if mesh.geometry.dofmap.links(0).size > 4 else 1
    V = fem.VectorFunctionSpace(mesh, ("Lagrange", order))
    positions = fem.Function(V)
    values = positions.x.array.reshape(-1, 3)
    dofs = node_dofs(mesh, V)
    values[dofs[dofs >= 0]] = X[dofs >= 0]
    reference, distance = evaluate(positions, np.asarray(points, dtype=float))
    outside = np.flatnonzero(distance > tolerance)
    if outside.size:
        listed = ", ".join(f"{names[i]} ({1e3 * distance[i]:.1f} mm outside)" for i in outside)
        raise InvalidParameterError(
            f"{outside.size} point(s) lie outside the imaged body: {listed}; check their units "
            "and axes (the points' file is read in the mesh file's frame)"
        )
    return reference


def track(
    runner: CaseRunner, X: np.ndarray, names: list[str], points: np.ndarray,
    material: Material, gravity: Gravity,
) -> TrackedPoints:
    """Carry ``points`` (loaded configuration) to the posture of ``gravity`` via the reference.

    Args:
        runner: a runner on the observed (loaded) mesh, at its observed geometry.
        X: the reference node positions (:func:`fem.reference.estimate_reference`).
        names: the points' names (for errors and the result).
        points: (N, 3) positions in the loaded configuration, m, project frame.
        material: C1 and density.
        gravity: the target posture's gravity.
    """
    problem = runner.problem
    observed = problem.mesh.geometry.x.copy()
    reference = to_reference(runner, X, names, points)
    try:
        problem.set_geometry(X)
        result, _ = runner.solve_material(material, gravity)
        u, _ = evaluate(problem.displacement(), reference)
    finally:
        problem.set_geometry(observed)
    return TrackedPoints(list(names), np.asarray(points, dtype=float), reference, reference + u,
                         result.converged)


__all__ = ["TrackedPoints", "to_reference", "track"]
