"""The paper's neo-Hookean solid: W = C1 (Ī1 − 3), the law of every tissue's cells.

The paper's strain energy is ``W = C1 (I1 - 3)``. In the continuum J = 1 and
this equals ``C1 (J^(-2/3) I1 - 3)``; in a mixed discretisation J = 1 holds
only weakly, and the plain-I1 form then leaves a soft volumetric mode (on a
prototype mesh it gave 37 % pointwise differences against an independent code
and diverged on refinement). We therefore write the deviatoric part with the
isochoric invariant, as is standard (Holzapfel 2000, §6.5). How J = 1 is imposed is
:mod:`fem.materials.incompressibility`'s.
"""

from __future__ import annotations

from dataclasses import dataclass

import ufl

from fem.kinematics import first_invariant, isochoric_first_invariant


@dataclass(frozen=True, slots=True)
class NeoHookean:
    """W = C1 (Ī1 - 3) (isochoric) or C1 (I1 - 3) (plain, the paper's literal form).

    Attributes:
        C1: the material parameter (Pa), a UFL constant so that one compiled
            form serves every case of a sweep.
        isochoric: use Ī1 = J^(-2/3) I1 (recommended; see the module docstring).
    """

    C1: ufl.core.expr.Expr
    isochoric: bool = True

    def strain_energy(self, F: ufl.core.expr.Expr) -> ufl.core.expr.Expr:
        """Strain energy density per unit reference volume."""
        I1 = isochoric_first_invariant(F) if self.isochoric else first_invariant(F)
        return self.C1 * (I1 - 3)
