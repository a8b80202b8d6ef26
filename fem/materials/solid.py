"""The solid's strain energy: its law, by name, plus the incompressibility of the element.

A solid law is a class of this package built as ``Law(C1, isochoric=...)`` from its stiffness
C1 (a UFL expression: the case's constant, times each cell's ratio where the tissues differ)
and whether its invariants are the isochoric ones, whose ``strain_energy(F)`` is the energy per
unit reference volume (:class:`SolidLaw`). :data:`LAWS` names each one, and
:func:`strain_energy` is the one place that picks a law and adds the volumetric term the
element asks for (:mod:`fem.materials.incompressibility`): what the forward and the inverse
problems' forms, and the tests' hand-derived stresses, all integrate.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Protocol

import ufl

from fem.exceptions import InvalidParameterError
from fem.materials.incompressibility import Incompressible, Penalty
from fem.materials.neo_hookean import NeoHookean

if TYPE_CHECKING:
    from fem.parameters import Discretisation


class SolidLaw(Protocol):
    """What a solid law offers: its strain energy per unit reference volume."""

    def strain_energy(self, F: ufl.core.expr.Expr) -> ufl.core.expr.Expr:
        """ψ(F), without the volumetric constraint."""
        ...


#: The solid laws by name (the name a config would choose one by).
LAWS: dict[str, type] = {"neo-hookean": NeoHookean}
#: The paper's law, every solve's.
DEFAULT_LAW = "neo-hookean"


def solid_law(name: str, C1: ufl.core.expr.Expr, isochoric: bool = True) -> SolidLaw:
    """The law called ``name`` with stiffness ``C1``.

    Raises:
        InvalidParameterError: for a name :data:`LAWS` does not hold, naming those it does.
    """
    if name not in LAWS:
        raise InvalidParameterError(
            f"unknown material law {name!r}; expected one of: {', '.join(sorted(LAWS))}")
    return LAWS[name](C1, isochoric=isochoric)


def strain_energy(
    F: ufl.core.expr.Expr,
    p: ufl.core.expr.Expr | None,
    C1: ufl.core.expr.Expr,
    discretisation: Discretisation,
    kappa_ratio: ufl.core.expr.Expr | float | None = None,
    law: str = DEFAULT_LAW,
) -> ufl.core.expr.Expr:
    """Strain energy density of the chosen law and discretisation (per reference volume).

    Taylor–Hood: ψ = W(F) - p (J - 1); P1-penalty: ψ = W(F) + κ/2 (J - 1)² with
    κ = ``kappa_ratio`` · C1 (default ``discretisation.bulk_ratio``); W is ``law``'s,
    C1 (Ī1 - 3) for the neo-Hookean solid.
    """
    psi = solid_law(law, C1, discretisation.isochoric).strain_energy(F)
    if discretisation.element == "taylor-hood":
        if p is None:
            raise ValueError("the Taylor-Hood strain energy needs the pressure field")
        return psi + Incompressible().strain_energy(F, p)
    ratio = discretisation.bulk_ratio if kappa_ratio is None else kappa_ratio
    return psi + Penalty(ratio * C1).strain_energy(F)


def first_piola_kirchhoff(psi: ufl.core.expr.Expr, F: ufl.core.expr.Expr) -> ufl.core.expr.Expr:
    """P = ∂ψ/∂F for a strain energy ψ written in terms of ``ufl.variable`` F."""
    return ufl.diff(psi, F)
