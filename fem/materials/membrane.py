"""The skin as a membrane: a neo-Hookean sheet bonded to the body's ``skin`` boundary.

The skin is 1–2.5 mm thick and the cells 6–25 mm, so a mesh rarely resolves it; where its
cells carry no skin tag, the skin's law enters the potential per unit area of the skin
boundary instead (:class:`fem.materials.tissues.SkinLayer` holds its settings, docs/tissues.md
says why a membrane).
"""

from __future__ import annotations

from dataclasses import dataclass

import ufl


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
