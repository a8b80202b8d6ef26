"""Pure UFL kinematics of finite deformation.

All functions take the displacement ``u`` (or the deformation gradient) and
return UFL expressions; nothing here depends on a mesh or a function space.
"""

from __future__ import annotations

import ufl


def deformation_gradient(u: ufl.core.expr.Expr) -> ufl.core.expr.Expr:
    """F = I + ∇u."""
    d = len(u)
    return ufl.variable(ufl.Identity(d) + ufl.grad(u))


def jacobian(F: ufl.core.expr.Expr) -> ufl.core.expr.Expr:
    """J = det F, the local volume ratio."""
    return ufl.det(F)


def right_cauchy_green(F: ufl.core.expr.Expr) -> ufl.core.expr.Expr:
    """C = Fᵀ F."""
    return F.T * F


def first_invariant(F: ufl.core.expr.Expr) -> ufl.core.expr.Expr:
    """I1 = tr C."""
    return ufl.tr(right_cauchy_green(F))


def isochoric_first_invariant(F: ufl.core.expr.Expr) -> ufl.core.expr.Expr:
    """Ī1 = J^(-2/3) I1, the first invariant of the volume-preserving part of F."""
    d = F.ufl_shape[0]
    return jacobian(F) ** (-2.0 / d) * first_invariant(F)
