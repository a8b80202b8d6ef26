"""The material laws, one per module (pure UFL, as fenicsx-pulse's ``material_models``).

* :mod:`~fem.materials.neo_hookean`: the solid's law, W = C1 (Ī1 − 3);
* :mod:`~fem.materials.incompressibility`: J = 1 by a pressure multiplier or a bulk penalty;
* :mod:`~fem.materials.membrane`: the skin as a membrane on the skin boundary;
* :mod:`~fem.materials.solid`: the laws by name and the solid's strain energy, law plus
  incompressibility (the one interface the problems' forms take);
* :mod:`~fem.materials.tissues`: each tissue's stiffness ratio to the fat's, the skin's settings;
* :mod:`~fem.materials.mesh_material`: all of it bound to one mesh (imports dolfinx, so it is
  imported by its own name: the config's tissue map is read where nothing solves).
"""

from fem.materials.incompressibility import Incompressible, Penalty
from fem.materials.membrane import Membrane
from fem.materials.neo_hookean import NeoHookean
from fem.materials.solid import (
    DEFAULT_LAW,
    LAWS,
    SolidLaw,
    first_piola_kirchhoff,
    solid_law,
    strain_energy,
)
from fem.materials.tissues import (
    DEFAULT_RATIOS,
    DEFAULT_SKIN_THICKNESS,
    SkinLayer,
    Tissues,
    skin_from_mapping,
    tissues_from_mapping,
)

__all__ = ["DEFAULT_LAW", "DEFAULT_RATIOS", "DEFAULT_SKIN_THICKNESS", "LAWS", "Incompressible",
           "Membrane", "NeoHookean", "Penalty", "SkinLayer", "SolidLaw", "Tissues",
           "first_piola_kirchhoff", "skin_from_mapping", "solid_law", "strain_energy",
           "tissues_from_mapping"]
