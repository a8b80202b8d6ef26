"""The refined reference solutions of the FE study, stored so that any process can evaluate them.

:func:`solve_reference` solves a clinical case on the reference discretisation and stores
its field (:func:`save_displacement`, HDF5 with the dof coordinates); :func:`load_references`
rebuilds the fields on their mesh for the benchmarks that compare with them.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from fem.overlap import self_overlap
from fem.parameters import SolverSettings
from fem.sweep import Case, clinical_cases
from studies.fe_study.fe_timing import timed_solve


def save_displacement(path: str | Path, problem: Any, meta: dict[str, Any]) -> None:
    """Store a solved displacement field so that another process can evaluate it anywhere.

    The field's coefficients are written with its space's dof coordinates; rebuilding the
    space on the same mesh file (serially) reproduces the same dof layout, which
    :func:`load_displacement` checks against those coordinates. HDF5, written atomically.
    """
    import json

    import h5py
    from dolfinx import fem

    if problem.mesh.comm.size > 1:
        raise ValueError("save_displacement() is serial only")
    # A fresh space of the same element (a collapsed mixed sub-space orders its dofs
    # differently); interpolation between identical elements only reorders the values.
    V = fem.VectorFunctionSpace(problem.mesh, ("Lagrange", problem.V.ufl_element().degree()))
    u = fem.Function(V)
    u.interpolate(problem.displacement())
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = target.with_name(f".{target.name}.{os.getpid()}.tmp")
    with h5py.File(tmp, "w") as h5:
        h5["dof_coordinates"] = u.function_space.tabulate_dof_coordinates()
        h5["u"] = u.x.array
        h5.attrs["degree"] = problem.V.ufl_element().degree()
        h5.attrs["meta"] = json.dumps(meta, default=float)
    os.replace(tmp, target)


def load_displacement(path: str | Path, mesh_path: str | Path) -> tuple[Any, dict[str, Any]]:
    """Rebuild a field stored by :func:`save_displacement` on its mesh: ``(function, meta)``.

    Raises:
        ValueError: if the rebuilt space's dofs do not sit where the stored ones did
            (another mesh, or another dof layout).
    """
    import json

    import h5py
    from dolfinx import fem
    from mpi4py import MPI

    from meshes.io import read_mesh

    with h5py.File(path, "r") as h5:
        x, values, degree = h5["dof_coordinates"][...], h5["u"][...], int(h5.attrs["degree"])
        meta = json.loads(h5.attrs["meta"])
    mesh, _, _ = read_mesh(mesh_path, MPI.COMM_SELF)
    V = fem.VectorFunctionSpace(mesh, ("Lagrange", degree))
    if V.tabulate_dof_coordinates().shape != x.shape or not np.allclose(
        V.tabulate_dof_coordinates(), x, rtol=0, atol=1e-12
    ):
        raise ValueError(f"{path} was not saved on {mesh_path} (dof coordinates differ)")
    u = fem.Function(V, name="reference_displacement")
    u.x.array[:] = values
    return u, meta


def load_references(
    clinical: list[dict[str, Any]], paths: list[str], mesh_path: str | Path
) -> tuple[list[Case], dict[str, tuple[Any, dict[str, Any]]]]:
    """The clinical cases and their stored reference fields, in the config's order.

    Args:
        clinical: the config's ``clinical`` entries.
        paths: one file of :func:`save_displacement` per entry, in the same order.
        mesh_path: the reference mesh.

    Returns:
        ``(cases, {case id: (function, meta)})``.
    """
    cases = clinical_cases(clinical)
    return cases, {
        case.id: load_displacement(path, mesh_path) for case, path in zip(cases, paths, strict=True)
    }


def solve_reference(
    mesh_path: str | Path, settings: SolverSettings, case: Case, path: str | Path
) -> dict[str, Any]:
    """Solve ``case`` on the reference discretisation and store it (:func:`save_displacement`).

    Returns:
        The solve's record (also stored with the field).

    Raises:
        RuntimeError: if the reference does not converge (there would be nothing to compare with).
    """
    from fem.case import CaseRunner

    runner = CaseRunner(mesh_path, settings)
    record = timed_solve(runner, case)
    if not record["converged"]:
        raise RuntimeError(f"the reference solve of {case.id} failed: {record['reason']}")
    u = runner.problem.displacement().x.array.reshape(-1, 3)
    record.update(
        dofs=runner.problem.num_dofs(),
        setup_s=runner.setup_s,
        max_disp_mm=1e3 * float(np.linalg.norm(u, axis=1).max()),
        self_overlap=self_overlap(runner.mesh, runner.problem.displacement()),
        settings=settings.describe(runner.solver.options),
        mesh=str(mesh_path),
    )
    save_displacement(path, runner.problem, record)
    runner.solver.destroy()
    return record
