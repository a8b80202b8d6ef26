"""Equilibrium written on the loaded shape: the inverse-motion problem (Govindjee and Mihalic).

The forward problem knows the reference X and seeks the displacement u(X). An imaged breast
gives the opposite: the loaded positions x are known, the reference is not. Writing the same
equilibrium on the known loaded mesh, with the *inverse* displacement U(x) = x − X(x) as the
unknown, finds the reference in one nonlinear solve:

    f = ∂X/∂x = I − ∇ₓU,   F = f⁻¹,   j = det f = dX/dx,

    ∫_ω j [ P(F) : (∇ₓη F) − b · η ] dx + ∫_ω j (∂ψ/∂p) q dx
        + ∫_skin ∂W/∂F(F, N) : (∇ₓη F)  j |Fᵀn| da
        − ∫_skin κ⟨−g(x)⟩ zone(X) ∇g(x) · η  j |Fᵀn| da = 0   for all (η, q),

which is the forward weak form ∫_Ω [P : ∇_X η − b · η] dX (and its pressure, skin membrane
and contact terms) pulled to the loaded configuration: dX = j dx, ∇_X η = ∇ₓη F,
N dA = j Fᵀ n da (Nanson). The solid's law takes each cell's C1 (the tissue field) and the
skin membrane's energy W (:mod:`fem.materials.membrane`, where ``material.skin`` is set) is the
forward problem's, from the same :class:`fem.materials.mesh_material.MeshMaterial`: written on
the reference, it is evaluated with F = f⁻¹ and the reference normal N = Fᵀn / |Fᵀn|, its
derivative taken in F with N held (a reference quantity, as in the forward variation), and
integrated over the loaded skin with dA = j |Fᵀn| da. The contact gap of a skin point is known
(it sits at its loaded position x); its zone is decided at its reference position X = x − U,
as in the forward problem.

On a mesh whose geometry has the displacement's nodes (the curved, order-2 mesh with P2
displacements), the discrete equations are the forward ones exactly: in the element's own
coordinates ξ both give F = (∂x/∂ξ)(∂X/∂ξ)⁻¹ and the same quadrature, so the reference found
here reproduces the observed nodes under a forward solve to the solvers' tolerance. On a
straight mesh the reference's edges stay straight where U bends them, and the forward check
(:func:`fem.reference.estimate_reference`) corrects the vertices.

The tangent is not symmetric (it is not the second variation of a potential in U), so it is
factorised by LU (:attr:`InverseMotionProblem.symmetric`).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from typing import Any

import numpy as np
import ufl
from dolfinx import fem
from mpi4py import MPI

from fem.io import node_displacement
from fem.loading import LoadingResult, solve_incrementally
from fem.parameters import Gravity, Material, SolverSettings
from fem.problem import GravityProblem
from fem.solver import NewtonSolver
from meshes.tags import Boundary

log = logging.getLogger(__name__)


class InverseMotionProblem(GravityProblem):
    """The gravity-loaded breast with its *loaded* mesh known and its reference sought.

    The mesh given is the loaded configuration ω; the state holds the inverse displacement
    U = x − X (and the pressure, a material field: the same values as the forward problem's at
    the same material points). Everything else (the spaces, constants, clamped boundaries,
    load fraction, solver interface) is :class:`fem.problem.GravityProblem`'s, so
    :class:`fem.solver.NewtonSolver` and :func:`fem.loading.solve_incrementally` drive it
    unchanged. ``J`` is det F = 1/det f, for the inversion check.
    """

    #: Not the second variation of a potential: LU, not LDLᵀ.
    symmetric = False

    def _weak_form(self, U: ufl.core.expr.Expr, p: ufl.core.expr.Expr | None) -> ufl.Form:
        mesh, dx, contact = self.mesh, self.dx, self.contact
        f = ufl.Identity(mesh.geometry.dim) - ufl.grad(U)
        F = ufl.variable(ufl.inv(f))
        j = ufl.det(f)
        n = ufl.FacetNormal(mesh)
        reference_area = j * ufl.sqrt(ufl.dot(F.T * n, F.T * n))  # dA/da (Nanson)
        self.J = 1.0 / j
        pressure = None if p is None else ufl.variable(p)
        psi = self.material.strain_energy(F, pressure)
        if self.mixed:
            eta, q = ufl.split(self._test)
        else:
            eta, q = self._test, None
        residual = j * (
            ufl.inner(ufl.diff(psi, F), ufl.grad(eta) * F) - ufl.dot(self.body_force, eta)
        ) * dx
        if q is not None:
            residual += j * ufl.diff(psi, pressure) * q * dx
        membrane = self._skin_residual(F, f, n, eta)
        if membrane is not None:
            residual += membrane * reference_area * self.skin_measure()(int(Boundary.SKIN))
        if contact is not None:
            ds = self.skin_measure()(int(Boundary.SKIN))
            x = ufl.SpatialCoordinate(mesh)
            at = ufl.variable(x)
            gap_gradient = ufl.diff(contact.obstacle.gap(at), at)
            contact_pressure = contact.pressure(x - U, U, self.C1)  # zone at X, gap at x
            residual -= contact_pressure * ufl.dot(gap_gradient, eta) * reference_area * ds
            self._contact_force = fem.form(contact_pressure * reference_area * ds)
        return residual

    def _skin_residual(self, F: ufl.core.expr.Expr, f: ufl.core.expr.Expr,
                       n: ufl.core.expr.Expr, eta: ufl.core.expr.Expr) -> ufl.core.expr.Expr | None:
        """The skin membrane's virtual work per unit *reference* area; None without a membrane.

        ∂W/∂F : ∇_X η with ∇_X η = ∇ₓη F, W the forward problem's membrane energy
        (:meth:`fem.materials.mesh_material.MeshMaterial.skin_energy`) at the reference normal
        N = Fᵀn / |Fᵀn| (Nanson, n the loaded normal). ``F`` is the UFL variable that W is
        differentiated in; N is built from ``f`` (F = f⁻¹ written out again, not the variable),
        so the derivative holds it, as the forward variation holds the reference's normal.
        """
        held = ufl.inv(f).T * n
        normal = held / ufl.sqrt(ufl.dot(held, held))
        energy = self.material.skin_energy(F, normal)
        if energy is None:
            return None
        return ufl.inner(ufl.diff(energy, F), ufl.grad(eta) * F)

    def contact_status(self) -> dict[str, Any] | None:
        """The contact force on the reference skin; the loaded skin's vertices never move here.

        The vertex counts of :meth:`fem.problem.GravityProblem.contact_status` are those of the
        forward solve that checks the reference (:func:`fem.reference.estimate_reference`).
        """
        if self.contact is None:
            return None
        force = self.mesh.comm.allreduce(fem.assemble_scalar(self._contact_force), op=MPI.SUM)
        return {"force_N": float(force)}


@dataclass(frozen=True)
class InverseMotionResult:
    """Outcome of :func:`solve_inverse_motion`.

    Attributes:
        loading: the adaptive load path's record (Newton iterations, steps, reason).
        X: geometry-node positions of the reference (m), in the mesh's node order (the
            loaded nodes where the solve failed).
        state: the inverse problem's mixed-field values (U, p); in the forward problem on the
            reference mesh they are its displacement and pressure, the forward check's guess.
        wall_s: wall time, the form compilation and the solver's set-up included.
    """

    loading: LoadingResult
    X: np.ndarray
    state: np.ndarray
    wall_s: float

    @property
    def converged(self) -> bool:
        """Whether the whole gravity load was carried."""
        return self.loading.converged


def solve_inverse_motion(
    mesh: Any,
    facet_tags: Any,
    settings: SolverSettings,
    material: Material,
    gravity: Gravity,
    cell_tags: Any = None,
) -> InverseMotionResult:
    """Find the reference of the loaded ``mesh`` in one nonlinear solve (adaptive load path).

    Args:
        mesh: the loaded shape (its geometry is read, not moved).
        facet_tags: its boundary tags.
        settings: the forward problem's element, clamped boundaries, contact, tissue ratios
            (``settings.tissues``), skin membrane (``settings.skin``), loading and Newton
            settings: the model of :class:`fem.case.CaseRunner`'s forward problem (its
            self-contact aside).
        material: C1 and density of the observation.
        gravity: the gravity the shape was under.
        cell_tags: its tissues' tags (None: all fat); their ratios are ``settings.tissues``.
    """
    start = time.perf_counter()
    problem = InverseMotionProblem(mesh, facet_tags, settings.discretisation, settings.fixed,
                                   settings.contact, None, cell_tags, settings.tissues,
                                   settings.skin)
    solver = NewtonSolver(problem, settings.petsc_options, settings.solver)
    try:
        problem.set_case(material, gravity)
        problem.w.x.array[:] = 0.0  # at zero load the reference is the loaded shape
        loading = solve_incrementally(problem, solver, settings.loading)
        X = mesh.geometry.x.copy()
        if loading.converged:
            X -= node_displacement(problem)
        log.info("inverse motion: %s, %d Newton its in %d load steps", loading.reason,
                 loading.total_iterations, len(loading.accepted))
        return InverseMotionResult(loading=loading, X=X, state=problem.w.x.array.copy(),
                                   wall_s=time.perf_counter() - start)
    finally:
        solver.destroy()


__all__ = ["InverseMotionProblem", "InverseMotionResult", "solve_inverse_motion"]
