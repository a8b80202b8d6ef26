"""FE benchmarks: clinical-case timings, accuracy against a reference, speed against accuracy.

Everything here is measured, nothing is assumed:

* :func:`solve_reference` solves the clinical cases on a refined discretisation and
  evaluates its displacement at the material points (the default mesh's vertices);
* :func:`clinical_benchmark` times the clinical cases at the default settings on one
  core, each followed by the same case with a fixed 10-step Newton baseline in the same
  process (so their ratio is free of machine speed), and compares the displacement
  with the reference;
* :func:`run_variant` does the same for one point of the speed-accuracy study (a mesh
  size × element × solver preset); :func:`summarise_variants` marks the Pareto front
  and the cheapest variant meeting the accuracy target.

Timings are wall-clock seconds of the nonlinear solve (set-up, i.e. mesh reading and
form compilation, is reported separately), next to CPU seconds and the load average so
that a reader can tell a busy machine from a slow solver.
"""

from __future__ import annotations

import ctypes
import functools
import logging
import os
import platform
import statistics
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from fem.exceptions import InvalidParameterError
from fem.overlap import self_overlap
from fem.parameters import Discretisation, Loading, SolverSettings
from fem.sweep import Case

log = logging.getLogger(__name__)

#: Issue 4's targets for the default discretisation on the clinical cases.
TARGETS = {
    "median_wall_s": 8.0,  # per case, one core
    "factorization_equivalents": 6.0,  # each case
    "relative_max_error": 0.01,  # max |u - u_ref| / max |u_ref|, each case
}

#: Element names of the study and the discretisation each stands for.
ELEMENTS: dict[str, dict[str, Any]] = {
    "p1-penalty": {"element": "p1-penalty"},
    "p2p1": {"element": "taylor-hood", "degree": 2},
    "p3p2": {"element": "taylor-hood", "degree": 3},
}


# -- environment ------------------------------------------------------------------------------
def limit_blas_threads(n: int = 1) -> list[str]:
    """Set OpenBLAS (in every copy this process has loaded) and OpenMP to ``n`` threads.

    MUMPS calls BLAS through ``libblas.so.3``, which Debian's ``openblas-pthread``
    provides as a second copy of OpenBLAS beside ``libopenblas.so.0``; each has its own
    thread pool, and the environment variable is read only when a library is loaded.

    Returns:
        The libraries that were set.
    """
    os.environ["OPENBLAS_NUM_THREADS"] = str(n)
    os.environ["OMP_NUM_THREADS"] = str(n)
    done = []
    for name, setter in (
        ("libopenblas.so.0", "openblas_set_num_threads"),
        ("libblas.so.3", "openblas_set_num_threads"),
        ("libgomp.so.1", "omp_set_num_threads"),  # MUMPS' OpenMP regions
    ):
        try:
            lib = ctypes.CDLL(name, mode=os.RTLD_NOLOAD | os.RTLD_GLOBAL)
            getattr(lib, setter)(ctypes.c_int(n))
        except (OSError, AttributeError):
            continue
        done.append(name)
    return done


@contextmanager
def one_core(core: int | None = None) -> Iterator[int]:
    """Run the body on one CPU core: every thread of this process is pinned to ``core``.

    The targets are per core, and some libraries start thread pools of their own (the
    OpenMP build of MUMPS, a second OpenBLAS), so capping thread counts alone does not
    guarantee one core; pinning does. Threads started inside the body inherit the pin.
    The process's previous affinity is restored afterwards.

    Args:
        core: the CPU (default: the lowest this process may use).

    Yields:
        The core pinned to.
    """
    allowed = os.sched_getaffinity(0)
    core = min(allowed) if core is None else core

    def pin(cpus: set[int]) -> None:
        for tid in os.listdir("/proc/self/task"):
            try:
                os.sched_setaffinity(int(tid), cpus)
            except (ProcessLookupError, PermissionError):  # a thread that just ended
                continue

    pin({core})
    try:
        yield core
    finally:
        pin(allowed)


def timed_on_one_core(func: Callable[..., dict[str, Any]]) -> Callable[..., dict[str, Any]]:
    """Run a benchmark returning a record with a ``machine`` mapping under :func:`one_core`,
    and record the core there as ``pinned_core``."""

    @functools.wraps(func)
    def wrapper(*args: Any, **kwargs: Any) -> dict[str, Any]:
        with one_core() as core:
            record = func(*args, **kwargs)
        record["machine"]["pinned_core"] = core
        return record

    return wrapper


def machine_state() -> dict[str, Any]:
    """What the timings were taken on: CPU, cores, load average now."""
    try:
        load = os.getloadavg()
    except OSError:
        load = (float("nan"),) * 3
    cpu = platform.processor() or ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return {
        "cpu": cpu,
        "cores": os.cpu_count(),
        "load_average_1_5_15min": [round(v, 2) for v in load],
        "openblas_num_threads": os.environ.get("OPENBLAS_NUM_THREADS"),
    }


# -- the study's variants -----------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class MeshSpec:
    """Element sizes (m) and geometric order of a study mesh; the rest of the mesh
    configuration (geometry, grading) is the workflow's.

    ``fold_size`` is the element size over the inframammary fold (``None``: no
    refinement there, whatever the workflow's own mesh asks for).
    """

    global_size: float
    mound_size: float
    order: int = 1
    fold_size: float | None = None

    def __post_init__(self) -> None:
        if not (0 < self.mound_size <= self.global_size):
            raise InvalidParameterError(f"need 0 < mound_size <= global_size, got {self}")
        if self.order not in (1, 2):
            raise InvalidParameterError(f"mesh order must be 1 or 2, got {self.order}")
        if self.fold_size is not None and not 0 < self.fold_size <= self.global_size:
            raise InvalidParameterError(f"need 0 < fold_size <= global_size, got {self}")

    @property
    def id(self) -> str:
        """Folder name, e.g. ``g=0.0150_m=0.0100_o=1`` or ``g=0.0150_m=0.0100_f=0.0040_o=1``."""
        fold = "" if self.fold_size is None else f"_f={self.fold_size:.4f}"
        return f"g={self.global_size:.4f}_m={self.mound_size:.4f}{fold}_o={self.order}"

    @classmethod
    def from_id(cls, mesh_id: str) -> MeshSpec:
        """Parse :attr:`id`."""
        parts = dict(p.split("=") for p in mesh_id.split("_"))
        fold = float(parts["f"]) if "f" in parts else None
        return cls(float(parts["g"]), float(parts["m"]), int(parts["o"]), fold)

    @classmethod
    def from_mapping(cls, values: dict[str, Any]) -> MeshSpec:
        """From a config mapping ``{global_size, mound_size[, order][, fold_size]}``."""
        fold = values.get("fold_size")
        return cls(
            float(values["global_size"]),
            float(values["mound_size"]),
            int(values.get("order", 1)),
            None if fold is None else float(fold),
        )

    def size_mapping(self) -> dict[str, Any]:
        """The ``mesh.size`` entries this spec sets (``fold_size`` always, even if null)."""
        return {
            "global_size": self.global_size,
            "mound_size": self.mound_size,
            "order": self.order,
            "fold_size": self.fold_size,
        }


MESH_ID_PATTERN = r"g=[0-9]+\.[0-9]{4}_m=[0-9]+\.[0-9]{4}(?:_f=[0-9]+\.[0-9]{4})?_o=[12]"
VARIANT_ID_PATTERN = MESH_ID_PATTERN + r"_el=(p1-penalty|p2p1|p3p2)_solver=[a-z-]+_q=[0-9]+"


@dataclass(frozen=True, slots=True)
class Variant:
    """One point of the speed-accuracy study.

    Attributes:
        mesh: mesh sizes.
        element: a key of :data:`ELEMENTS`.
        solver: a linear-solver preset of :func:`fem.options.default_parameters`.
        quadrature_degree: 0 for the element's default.
    """

    mesh: MeshSpec
    element: str = "p2p1"
    solver: str = "direct"
    quadrature_degree: int = 0

    def __post_init__(self) -> None:
        if self.element not in ELEMENTS:
            raise InvalidParameterError(
                f"unknown element {self.element!r}; expected one of {sorted(ELEMENTS)}"
            )

    @property
    def id(self) -> str:
        """File name stem, e.g. ``g=0.0150_m=0.0100_o=1_el=p2p1_solver=direct_q=0``."""
        return f"{self.mesh.id}_el={self.element}_solver={self.solver}_q={self.quadrature_degree}"

    @classmethod
    def from_id(cls, variant_id: str) -> Variant:
        """Parse :attr:`id`."""
        mesh_part, rest = variant_id.split("_el=")
        element, rest = rest.split("_solver=")
        solver, q = rest.split("_q=")
        return cls(MeshSpec.from_id(mesh_part), element, solver, int(q))

    @staticmethod
    def base_config(config: dict[str, Any]) -> dict[str, Any]:
        """The workflow config sections (``fe``, ``material``, ``mesh``) that a variant's
        solve depends on: without the default's element, degree, quadrature and solver
        preset, which :meth:`settings` replaces, so that changing them reruns no study solve."""
        fe = {key: value for key, value in config.get("fe", {}).items() if key != "solver"}
        fe["discretisation"] = {
            key: value
            for key, value in fe.get("discretisation", {}).items()
            if key not in ("element", "degree", "quadrature_degree")
        }
        return {"fe": fe, "material": config["material"], "mesh": config["mesh"]}

    def settings(self, base: SolverSettings) -> SolverSettings:
        """``base`` with this variant's element, quadrature and solver preset."""
        disc = Discretisation(
            **{**ELEMENTS[self.element], "quadrature_degree": self.quadrature_degree,
               "bulk_ratio": base.discretisation.bulk_ratio,
               "isochoric": base.discretisation.isochoric}
        )
        return replace(base, discretisation=disc, solver=self.solver)


def expand_variants(entries: list[dict[str, Any]]) -> list[Variant]:
    """Cross products of the config's ``fe_study.speed_accuracy.variants`` entries.

    Each entry has ``element`` (one name), ``mesh`` (list of ``{global_size,
    mound_size, order, fold_size}``), ``solver`` (list of presets, default ``[direct]``) and
    ``quadrature_degree`` (list, default ``[0]``).
    """
    out: set[Variant] = set()
    for entry in entries:
        for mesh in entry["mesh"]:
            spec = MeshSpec.from_mapping(mesh)
            for solver in entry.get("solver", ["direct"]):
                for q in entry.get("quadrature_degree", [0]):
                    out.add(Variant(spec, entry["element"], solver, int(q)))

    def key(v: Variant) -> tuple:
        m = v.mesh
        return (m.global_size, m.mound_size, m.order, m.fold_size or 0.0, v.element, v.solver,
                v.quadrature_degree)

    return sorted(out, key=key)


def clinical_cases(clinical: list[dict[str, Any]]) -> list[Case]:
    """The config's ``clinical`` list as cases."""
    return [Case(float(c["C1"]), float(c["phi"]), float(c.get("theta", 0.0))) for c in clinical]


# -- material points and references ----------------------------------------------------------
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
    return cases, {case.id: load_displacement(path, mesh_path) for case, path in zip(cases, paths, strict=True)}


# -- timing one case ------------------------------------------------------------------------------
def timed_solve(runner: Any, case: Case, loading: Loading | None = None) -> dict[str, Any]:
    """Solve ``case`` from rest with ``runner`` and return its timing record.

    Args:
        runner: a :class:`fem.case.CaseRunner`.
        case: the case.
        loading: load stepping for this solve (default: the runner's).

    Returns:
        Wall and CPU seconds of the solve, the cost unit (one Jacobian assembly +
        factorisation + solve) and their ratio ``factorization_equivalents``, the load
        path and iteration counts.
    """
    saved = runner.settings
    if loading is not None:
        runner.settings = replace(saved, loading=loading)
    try:
        result, timings = runner.solve(case)
    finally:
        runner.settings = saved
    unit = runner.solver.time_linear_system() if result.converged else float("nan")
    return {
        "case": case.id,
        "converged": bool(result.converged),
        "reason": result.reason,
        "load_fraction": result.fraction,
        "wall_s": timings["solve"],
        "cpu_s": timings["solve_cpu"],
        "assembly_s": timings["assembly"],
        "linear_solve_s": timings["linear_solve"],
        "linear_system_s": unit,
        "factorization_equivalents": timings["solve"] / unit if unit > 0 else float("nan"),
        "load_steps": len(result.accepted),
        "rejected_steps": len(result.attempts) - len(result.accepted),
        "newton_iterations": result.newton_iterations,
        "total_newton_iterations": result.total_iterations,
        "linear_iterations": result.linear_iterations,
        "jacobian_evaluations": timings["jacobian_evaluations"],
        "preconditioner_builds": timings["preconditioner_builds"],
        "residual_evaluations": timings["residual_evaluations"],
        "first_failure": result.first_failure,
    }


def vertex_displacement(runner: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A serial runner's displacement at its mesh's vertices (the material points).

    Returns:
        ``(node_index, X, u)`` ordered by the vertices' index in the mesh file; the values
        are read from the coefficients, not interpolated.
    """
    from fem.io import gather_vertex_coordinates, gather_vertex_values

    index, u = gather_vertex_values(runner.mesh, runner.problem.displacement())
    index_x, X = gather_vertex_coordinates(runner.mesh)
    assert np.array_equal(index, index_x)
    return index, X, u


def solve_reference(mesh_path: str | Path, settings: SolverSettings, case: Case, path: str | Path) -> dict[str, Any]:
    """Solve ``case`` on the reference discretisation and store the field (:func:`save_displacement`).

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


# -- the clinical benchmark ------------------------------------------------------------------------
def accuracy_at_vertices(runner: Any, reference: Any | None) -> dict[str, Any] | None:
    """Errors of a solved runner at its own vertices against a reference field.

    Args:
        runner: a solved serial :class:`fem.case.CaseRunner`.
        reference: the reference displacement (a dolfinx Function on its own mesh), or None.

    Returns:
        :func:`fem.evaluation.displacement_errors` plus how far the farthest vertex lay
        outside the reference mesh (``max_outside_m``), or None without a reference.
    """
    from fem.evaluation import displacement_errors, evaluate

    if reference is None:
        return None
    _, X, u = vertex_displacement(runner)
    u_ref, distance = evaluate(reference, X)
    return {**displacement_errors(u, u_ref), "max_outside_m": float(distance.max())}


@timed_on_one_core
def clinical_benchmark(
    mesh_path: str | Path,
    settings: SolverSettings,
    cases: list[Case],
    references: dict[str, tuple[Any, dict[str, Any]]],
    baseline_steps: int = 10,
    repeats: int = 1,
) -> dict[str, Any]:
    """Time and check the clinical cases at the default discretisation.

    Args:
        mesh_path: the default mesh (its vertices are the material points).
        settings: the default solver settings.
        cases: the clinical cases.
        references: case id -> ``(field, meta)`` of :func:`load_displacement`.
        baseline_steps: equal load steps of the fixed-step Newton baseline.
        repeats: solves per case; the median wall time is reported.

    Returns:
        Per-case records (timings, baseline, accuracy, :func:`fem.overlap.self_overlap`) and
        a summary against :data:`TARGETS`,
        all measured on one pinned core (:func:`one_core`).
    """
    from fem.case import CaseRunner

    state_before = machine_state()
    runner = CaseRunner(mesh_path, settings)
    baseline_loading = replace(settings.loading, fixed_steps=baseline_steps)
    rows = []
    for case in cases:
        runs = [timed_solve(runner, case) for _ in range(repeats)]
        record = dict(sorted(runs, key=lambda r: r["wall_s"])[len(runs) // 2])
        record["wall_s_repeats"] = [r["wall_s"] for r in runs]
        node_index, _, u = vertex_displacement(runner)
        record["max_disp_mm"] = 1e3 * float(np.linalg.norm(u, axis=1).max())
        record["mean_disp_mm"] = 1e3 * float(np.linalg.norm(u, axis=1).mean())
        reference = references.get(case.id)
        record["accuracy"] = accuracy_at_vertices(runner, reference[0] if reference else None)
        record["self_overlap"] = self_overlap(runner.mesh, runner.problem.displacement())
        baseline = timed_solve(runner, case, baseline_loading)
        _, _, u_base = vertex_displacement(runner)
        baseline["max_difference_from_adaptive_mm"] = 1e3 * float(np.abs(u_base - u).max())
        record["baseline"] = baseline
        record["baseline_over_adaptive_wall"] = baseline["wall_s"] / record["wall_s"]
        record["baseline_over_adaptive_cpu"] = baseline["cpu_s"] / record["cpu_s"]
        rows.append(record)
        log.info(
            "%s: %.2f s (FE %.2f, %s its), baseline %.2f s, error %s",
            case.id, record["wall_s"], record["factorization_equivalents"],
            record["newton_iterations"], baseline["wall_s"],
            f"{100 * record['accuracy']['relative_max_error']:.2f} %" if record["accuracy"] else "n/a",
        )
    walls = [r["wall_s"] for r in rows]
    fe = [r["factorization_equivalents"] for r in rows]
    errors = [r["accuracy"]["relative_max_error"] for r in rows if r["accuracy"]]
    summary = {
        "median_wall_s": statistics.median(walls),
        "median_cpu_s": statistics.median(r["cpu_s"] for r in rows),
        "max_factorization_equivalents": max(fe),
        "median_baseline_over_adaptive_wall": statistics.median(r["baseline_over_adaptive_wall"] for r in rows),
        "max_relative_error": max(errors) if errors else None,
        "all_converged": all(r["converged"] for r in rows),
    }
    summary["targets"] = {
        "median_wall_s": {"target": TARGETS["median_wall_s"], "value": summary["median_wall_s"],
                          "met": summary["median_wall_s"] <= TARGETS["median_wall_s"]},
        "factorization_equivalents": {"target": TARGETS["factorization_equivalents"],
                                      "value": summary["max_factorization_equivalents"],
                                      "met": summary["max_factorization_equivalents"] <= TARGETS["factorization_equivalents"]},
        "relative_max_error": {"target": TARGETS["relative_max_error"], "value": summary["max_relative_error"],
                               "met": bool(errors) and max(errors) <= TARGETS["relative_max_error"]},
    }
    out = {
        "mesh": str(mesh_path),
        "dofs": runner.problem.num_dofs(),
        "material_points": int(len(node_index)),
        "setup_s": runner.setup_s,
        "settings": settings.describe(runner.solver.options),
        "baseline_steps": baseline_steps,
        "repeats": repeats,
        "cases": rows,
        "summary": summary,
        "machine": {"before": state_before, "after": machine_state()},
        "reference": {cid: meta for cid, (_, meta) in references.items()},
    }
    runner.solver.destroy()
    return out


# -- speed against accuracy ------------------------------------------------------------------
@timed_on_one_core
def run_variant(
    mesh_path: str | Path,
    variant: Variant,
    base: SolverSettings,
    cases: list[Case],
    references: dict[str, tuple[Any, dict[str, Any]]],
    max_dofs: int | None = None,
) -> dict[str, Any]:
    """Time one study variant on the clinical cases and measure its error at its material points.

    The material points of a variant are its own mesh's vertices (as the dataset's are
    the default mesh's); the reference is evaluated there. A variant above ``max_dofs``
    is recorded as skipped (with its DOF count), not solved. Timed on one pinned core.
    """
    from fem.case import CaseRunner

    settings = variant.settings(base)
    runner = CaseRunner(mesh_path, settings)
    dofs = runner.problem.num_dofs()
    record: dict[str, Any] = {
        "variant": variant.id,
        "mesh": variant.mesh.size_mapping(),
        "element": variant.element,
        "solver": variant.solver,
        "quadrature_degree": settings.discretisation.quadrature,
        "dofs": dofs,
        "cells": runner.mesh.topology.index_map(3).size_global,
        "material_points": runner.mesh.topology.index_map(0).size_global,
        "setup_s": runner.setup_s,
        "machine": machine_state(),
    }
    if max_dofs is not None and dofs > max_dofs:
        record["skipped"] = f"{dofs} dofs exceed fe_study.speed_accuracy.max_dofs = {max_dofs}"
        runner.solver.destroy()
        return record
    rows = []
    for case in cases:
        row = timed_solve(runner, case)
        reference = references.get(case.id)
        if row["converged"]:
            row["self_overlap"] = self_overlap(runner.mesh, runner.problem.displacement())
            if reference is not None:
                row["accuracy"] = accuracy_at_vertices(runner, reference[0])
        rows.append(row)
        log.info("%s %s: %.2f s, error %s", variant.id, case.id, row["wall_s"],
                 row.get("accuracy", {}).get("relative_max_error") if row.get("accuracy") else "n/a")
    record["cases"] = rows
    ok = [r for r in rows if r.get("accuracy")]
    record["median_wall_s"] = statistics.median(r["wall_s"] for r in rows)
    record["median_cpu_s"] = statistics.median(r["cpu_s"] for r in rows)
    record["max_factorization_equivalents"] = max(r["factorization_equivalents"] for r in rows)
    record["max_relative_error"] = max(r["accuracy"]["relative_max_error"] for r in ok) if len(ok) == len(rows) else None
    record["max_error_mm"] = max(r["accuracy"]["max_error_mm"] for r in ok) if len(ok) == len(rows) else None
    record["max_overlapping_vertices"] = max(
        (r["self_overlap"]["overlapping_vertices"] for r in rows if "self_overlap" in r), default=None
    )
    runner.solver.destroy()
    return record


def pareto_front(costs: list[float], errors: list[float]) -> list[bool]:
    """Points no other point beats in both cost and error (ties count as beaten only if strictly worse in one)."""
    flags = []
    for i, (c, e) in enumerate(zip(costs, errors)):
        dominated = any(
            (c2 <= c and e2 <= e) and (c2 < c or e2 < e)
            for j, (c2, e2) in enumerate(zip(costs, errors)) if j != i
        )
        flags.append(not dominated)
    return flags


def summarise_variants(
    records: list[dict[str, Any]], target: float = TARGETS["relative_max_error"], cost: str = "median_cpu_s"
) -> dict[str, Any]:
    """Mark the Pareto front (cost against worst-case relative error) and the cheapest
    variant that meets ``target``.

    Args:
        records: :func:`run_variant` records.
        target: accuracy target on the max relative error over the clinical cases.
        cost: the cost measure (CPU seconds are robust to a shared machine; wall
            seconds are what a user waits).
    """
    solved = [r for r in records if not r.get("skipped") and r.get("max_relative_error") is not None]
    flags = pareto_front([r[cost] for r in solved], [r["max_relative_error"] for r in solved])
    for r, flag in zip(solved, flags):
        r["pareto"] = flag
    meeting = sorted((r for r in solved if r["max_relative_error"] <= target), key=lambda r: r[cost])
    return {
        "target_relative_max_error": target,
        "cost": cost,
        "variants": records,
        "pareto_front": [r["variant"] for r in solved if r["pareto"]],
        "cheapest_meeting_target": meeting[0]["variant"] if meeting else None,
    }


__all__ = [
    "ELEMENTS",
    "MESH_ID_PATTERN",
    "TARGETS",
    "VARIANT_ID_PATTERN",
    "MeshSpec",
    "Variant",
    "clinical_benchmark",
    "clinical_cases",
    "expand_variants",
    "limit_blas_threads",
    "machine_state",
    "one_core",
    "pareto_front",
    "load_displacement",
    "load_references",
    "save_displacement",
    "vertex_displacement",
    "accuracy_at_vertices",
    "run_variant",
    "solve_reference",
    "summarise_variants",
    "timed_on_one_core",
    "timed_solve",
]
