"""Constitutive laws: the paper's neo-Hookean solid and how incompressibility is imposed.

The paper's strain energy is ``W = C1 (I1 - 3)``. In the continuum J = 1 and
this equals ``C1 (J^(-2/3) I1 - 3)``; in a mixed discretisation J = 1 holds
only weakly, and the plain-I1 form then leaves a soft volumetric mode (on a
prototype mesh it gave 37 % pointwise differences against an independent code
and diverged on refinement). We therefore write the deviatoric part with the
isochoric invariant, as is standard (Holzapfel 2000, §6.5).
"""

from __future__ import annotations

from dataclasses import dataclass

import ufl

from fem.kinematics import first_invariant, isochoric_first_invariant, jacobian


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


@dataclass(frozen=True, slots=True)
class Membrane:
    """An incompressible neo-Hookean membrane on a surface: the skin as a sheet bonded to it.

    Per unit reference area, W = C1 t (I1_s + 1/J_s² − 3): the solid's law integrated over the
    sheet's thickness t under plane stress (its free faces carry no normal stress), the
    thickness stretch 1/J_s set by incompressibility. I1_s = tr C − N·C N is the in-plane
    stretch invariant and J_s = |cof(F) N| the area stretch (Nanson's formula), with N the
    surface's reference normal and F the solid's deformation gradient on it: the sheet takes
    the in-plane deformation of the surface it is bonded to, and no bending.

    A sheet without bending stiffness cannot carry compression: it wrinkles, at a wavelength
    set by its bending stiffness, far below the cells. ``wrinkles`` replaces W by its relaxed
    (tension-field) energy, the least energy of any fine wrinkling of the same mean stretch
    (Pipkin 1986; Steigmann 1990): with a ≥ b the principal squared in-plane stretches,

    * taut, b ≥ a^(-1/2) (both principal stresses ≥ 0): W as above;
    * wrinkled, a > 1 and b < a^(-1/2): uniaxial tension along the larger stretch,
      W = C1 t (a + 2 a^(-1/2) − 3), the width free to take its natural a^(-1/2);
    * slack, a ≤ 1: W = 0.

    The three agree, with their first derivatives, where they meet. Without it the compressed
    sheet's negative geometric stiffness can exceed the soft fat's (a mesh-scale buckling mode)
    and Newton stalls (results log entry 97).

    Attributes:
        C1: the membrane's material parameter (Pa).
        thickness: t (m).
        wrinkles: relax the energy in compression (tension field); False: the plain membrane,
            which resists compression as the bonded solid would.
    """

    C1: ufl.core.expr.Expr
    thickness: ufl.core.expr.Expr | float
    wrinkles: bool = True

    def strain_energy(self, F: ufl.core.expr.Expr, N: ufl.core.expr.Expr) -> ufl.core.expr.Expr:
        """Strain energy per unit reference area of the surface with normal ``N``."""
        C = F.T * F
        in_plane = ufl.tr(C) - ufl.dot(N, C * N)
        area = ufl.cofac(F) * N
        area2 = ufl.dot(area, area)  # J_s² = a b
        taut = self.C1 * self.thickness * (in_plane + 1.0 / area2 - 3)
        if not self.wrinkles:
            return taut
        # a, b = (I ± √(I² − 4 J_s²)) / 2. The root is taken only where it matters (the wrinkled
        # region, a > 1 > b, where its argument is well above zero); the floor keeps its
        # derivative finite in the branches a conditional does not select.
        root = ufl.sqrt(ufl.max_value(in_plane**2 - 4 * area2, 0.0) + _ROOT_FLOOR)
        a = (in_plane + root) / 2
        b = (in_plane - root) / 2
        wrinkled = self.C1 * self.thickness * (a + 2 / ufl.sqrt(a) - 3)
        # taut first, with room for the floor's shift of b: at rest (a = b = 1, where all three
        # meet) the sheet's tangent is then the taut one, and Newton's first step from rest
        # feels the skin (slack there, it would see none)
        return ufl.conditional(ufl.ge(b * area2, 1.0 - _TAUT_TOLERANCE), taut,
                               ufl.conditional(ufl.le(a, 1.0), 0.0, wrinkled))


#: Floor under the discriminant of the in-plane stretches (squared stretches are O(1)).
_ROOT_FLOOR = 1e-12
#: The taut test's allowance: the floor lowers b by at most √floor / 2.
_TAUT_TOLERANCE = 1e-6


def first_piola_kirchhoff(psi: ufl.core.expr.Expr, F: ufl.core.expr.Expr) -> ufl.core.expr.Expr:
    """P = ∂ψ/∂F for a strain energy ψ written in terms of ``ufl.variable`` F."""
    return ufl.diff(psi, F)
