"""The material laws' package (fem/materials/): the laws by name, and what every law must be.

* a law unknown by name is refused, naming the known ones;
* every law of ``LAWS`` is free of energy and of deviatoric stress at rest (F = I: the
  reference is the unloaded breast), and its isochoric form is blind to a change of volume
  (the volumetric term is the element's, :mod:`fem.materials.incompressibility`);
* the package imports no dolfinx: the config's tissue map is read through it by processes
  that never solve (Snakemake's), which must not start MPI.
"""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from fem.exceptions import InvalidParameterError
from fem.materials import LAWS, solid_law
from tests.conftest import REPO


@pytest.mark.unit
def test_an_unknown_law_is_refused_by_name() -> None:
    with pytest.raises(InvalidParameterError, match=r"unknown material law 'mooney'; expected "
                                                    r"one of: neo-hookean"):
        solid_law("mooney", 1.0)


@pytest.mark.unit
def test_the_package_imports_no_dolfinx() -> None:
    code = ("import sys, fem.materials, fem.parameters; "
            "print(sorted(m for m in ('dolfinx', 'mpi4py', 'petsc4py') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True,
                         check=True)
    assert out.stdout.strip() == "[]"


def _assemble(expr: object) -> float:
    """∫ expr over the unit cube (expr constant in space): its value."""
    import ufl
    from dolfinx import fem
    from dolfinx import mesh as dmesh
    from mpi4py import MPI

    cube = dmesh.create_unit_cube(MPI.COMM_WORLD, 1, 1, 1, dmesh.CellType.tetrahedron)
    return float(fem.assemble_scalar(fem.form(expr * ufl.dx(domain=cube))))


@pytest.mark.solve
@pytest.mark.parametrize("name", sorted(LAWS))
@pytest.mark.parametrize("isochoric", [True, False])
def test_every_law_is_free_of_energy_and_shear_at_rest(name: str, isochoric: bool) -> None:
    import ufl

    from fem.materials import first_piola_kirchhoff

    C1 = 700.0
    F = ufl.variable(ufl.Identity(3))
    law = solid_law(name, C1, isochoric)
    psi = law.strain_energy(F)
    P = first_piola_kirchhoff(psi, F)
    shear = ufl.dev(P)
    assert _assemble(psi) == pytest.approx(0.0, abs=1e-9 * C1)
    assert _assemble(ufl.inner(shear, shear)) == pytest.approx(0.0, abs=1e-18 * C1**2)
    # a stretch that keeps the volume costs energy; in isochoric form a dilation costs none
    stretch = np.diag([1.2, 1.0 / np.sqrt(1.2), 1.0 / np.sqrt(1.2)]).tolist()
    assert _assemble(law.strain_energy(ufl.as_matrix(stretch))) > 1e-3 * C1
    if isochoric:
        dilation = ufl.as_matrix((1.1 * np.eye(3)).tolist())
        assert _assemble(law.strain_energy(dilation)) == pytest.approx(0.0, abs=1e-9 * C1)
