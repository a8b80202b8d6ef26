"""How the solid's incompressibility is imposed: a pressure multiplier or a bulk penalty.

The element chooses (:attr:`fem.parameters.Discretisation.element`): Taylor–Hood carries a
pressure field p and adds :class:`Incompressible`'s −p (J − 1), so that J = 1 holds weakly;
the P1 baseline has no pressure and adds :class:`Penalty`'s κ/2 (J − 1)², κ a multiple of C1.
"""

from __future__ import annotations

from dataclasses import dataclass

import ufl

from fem.kinematics import jacobian


@dataclass(frozen=True, slots=True)
class Incompressible:
    """Incompressibility by a pressure multiplier: ψ = -p (J - 1)."""

    def strain_energy(self, F: ufl.core.expr.Expr, p: ufl.core.expr.Expr) -> ufl.core.expr.Expr:
        """Lagrange-multiplier term added to the strain energy."""
        return -p * (jacobian(F) - 1)


@dataclass(frozen=True, slots=True)
class Penalty:
    """Near incompressibility by a penalty: ψ = κ/2 (J - 1)², κ the bulk modulus (Pa)."""

    kappa: ufl.core.expr.Expr

    def strain_energy(self, F: ufl.core.expr.Expr) -> ufl.core.expr.Expr:
        """Volumetric penalty energy."""
        return 0.5 * self.kappa * (jacobian(F) - 1) ** 2
