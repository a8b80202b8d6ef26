"""Incompressible neo-Hookean breast under gravity, solved with dolfinx 0.5 and PETSc SNES.

Modules follow concepts: :mod:`fem.kinematics` and the laws of :mod:`fem.materials` (one
module per law) are pure UFL; :mod:`fem.problem` builds spaces, forms and boundary conditions;
:mod:`fem.solver` wraps SNES; :mod:`fem.loading` drives adaptive load steps;
:mod:`fem.io` writes per-case files; :mod:`fem.case` runs one case;
:mod:`fem.sweep` names the cases.
"""
