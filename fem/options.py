"""Solver options: Newton settings plus named linear-solver presets, in one mapping.

All solver options live in :func:`default_parameters`: Newton settings shared by
every preset plus the linear-solver options of one named preset; a config
overrides them key by key (PETSc option names without the leading dash).

Presets (``fe.solver`` in the config):

``direct`` (default)
    Newton–Krylov on a reused factorisation. The tangent is assembled at every
    Newton iteration, but factorised only when it has to be: GMRES solves each
    Newton system to ``ksp_rtol`` (1e-5) of the *true* residual (right
    preconditioning: with PETSc's default left preconditioning the test is on the
    preconditioned residual, which a stale factorisation of an ill-conditioned
    tangent makes meaningless, and Newton then stalls where exact Newton converges),
    preconditioned by the last MUMPS LDLᵀ factorisation. The tangent is
    re-factorised at the first iteration of every load step, whenever the previous
    Krylov solve needed more than ``refactor_above_its`` iterations or failed, and
    whenever a Newton iteration close to the solution reduced the residual by less than
    the factor ``refactor_above_ratio`` (a stall). An increment that still fails after getting
    within ``fem.convergence.RETRY_BELOW`` of its first residual, or whose Krylov solves
    failed, is tried again from the same guess with a fresh factorisation at every
    iteration (exact Newton) before the loader cuts the step. Above ``blr_above_dofs``
    unknowns the kept factorisation is block low-rank (:data:`BLR_OPTIONS`). One MUMPS
    solve with the factors costs about 1/40 of a factorisation, so a stale factorisation
    is worth keeping while it preconditions to ~10 iterations. Measured on the default mesh, one
    pinned core (the four clinical cases): 1–2 factorisations instead of 3–6, the
    same Newton iterations, and displacements within 6.4e-9 mm of exact Newton's.
    The factorisation is MUMPS LDLᵀ (``pc_type cholesky`` on a matrix flagged
    symmetric, i.e. MUMPS ``SYM=2``, symmetric indefinite with pivoting). The
    tangent is the second variation of a potential, so it is symmetric; LDLᵀ needs
    about half the flops and memory of LU (measured: 3.2e10 against 5.9e10 flops on
    a 48k-DOF P2/P1 tangent). MUMPS reuses its symbolic analysis across
    factorisations because the sparsity pattern never changes.
``direct-refactor``
    Exact Newton: MUMPS LDLᵀ factorisation and solve (``ksp_type preonly``) at every
    Newton iteration; the previous default, kept for comparison.
``direct-lu``
    As ``direct-refactor`` with MUMPS LU.
``iterative``
    For large meshes and MPI: flexible GMRES preconditioned by a fieldsplit
    Schur-complement factorisation. The displacement block is solved by one
    V-cycle of smoothed-aggregation AMG (GAMG) that knows the six rigid-body
    modes (near-nullspace); the Schur complement is approximated by the pressure
    mass matrix scaled by -1/(2 C1) (the preconditioning matrix's pressure block,
    see :attr:`fem.problem.GravityProblem.preconditioner`), inverted by Jacobi.
    For the P1-penalty element (no pressure field) the same AMG preconditions
    the whole tangent.
"""

from __future__ import annotations

import math
import re
from typing import Any

from fem.exceptions import InvalidParameterError

#: Line searches of PETSc 3.18's ``newtonls`` that the configuration may choose.
LINE_SEARCHES = ("bt", "l2", "cp", "basic")

#: Options read by :class:`fem.solver.NewtonSolver` itself, never handed to PETSc.
#: ``refactor_above_its``: re-factorise the tangent when the previous Krylov solve
#: took more iterations than this (0: factorise at every Newton iteration).
#: ``refactor_above_ratio``: re-factorise when the last Newton iteration, already within
#: ``fem.convergence.RETRY_BELOW`` of its first residual, left more than this fraction of the
#: residual (a stalling inexact solve; 1 never).
#: ``load_atol``: Newton's absolute residual tolerance as a fraction of the norm of the
#: full gravity load, so that the test means the same on every mesh, unit and size
#: (PETSc's ``snes_atol``, an absolute force, is applied as well where it is larger).
#: ``blr_above_dofs``: above this many unknowns a kept factorisation is block low-rank
#: (:data:`BLR_OPTIONS`); 0 always, a huge number never.
#: ``lag_below_ratio``: in a solve from a guess near the last solve (the next case of a chain,
#: :mod:`fem.chain`), keep the last tangent and its factorisation (a chord iteration) while
#: each iteration leaves at most this fraction of the residual; after a slower iteration or
#: Krylov solve, the tangent is assembled and factorised afresh and Newton goes on (0: never).
SOLVER_KEYS = (
    "refactor_above_its", "refactor_above_ratio", "load_atol", "blr_above_dofs", "lag_below_ratio"
)

#: Preconditioners whose set-up is a factorisation that a Krylov method can reuse.
_FACTORISATIONS = ("lu", "cholesky")

_NEWTON: dict[str, Any] = {
    "snes_type": "newtonls",
    "snes_linesearch_type": "bt",
    # Relative to the residual at the start of each load step. At 1e-7 the algebraic
    # error is ~1e-6 of the displacement, four orders below the discretisation error
    # (measured on the default mesh, supine C1 = 1.0 kPa: 8e-8 mm from a solve to
    # 1e-12), and Newton stops one quadratic iteration earlier than at 1e-9.
    "snes_rtol": 1e-7,
    # One part in 1e9 of the full weight's norm (0.36 N on the default mesh: 3.6e-10 N, about
    # the absolute 1e-10 N this replaced), so that the test scales with the mesh's size,
    # resolution and density instead of being an absolute force.
    "load_atol": 1e-9,
    "snes_atol": 0.0,
    "snes_stol": 0.0,
    # Past ~15 iterations a step is better cut back than continued: the adaptive
    # loader retries from the last converged state with a smaller increment.
    "snes_max_it": 15,
    "snes_divergence_tolerance": 1e8,
}

_MUMPS: dict[str, Any] = {
    "pc_factor_mat_solver_type": "mumps",
    # Extra workspace (percent) for delayed pivots of the indefinite LDLᵀ: MUMPS'
    # 20 % default fails (INFOG(1) = -9) on strongly deformed states.
    "mat_mumps_icntl_14": 100,
}

#: Newton settings of the adaptive loader's last resort (:class:`fem.parameters.Loading`
#: ``rescue``): when the step has been cut below ``min_step``, the loader starts again
#: from rest with these in place of the defaults' ``bt`` and 15 iterations. On the
#: default mesh with contact, C1 = 0.9 kPa at Φ = −90° converged from rest in one load
#: step of 22 Newton iterations (32 s) with these, where the defaults stalled at 97 % of
#: the load after 12 cut-backs (183 s); from that stalled state these failed too. Only
#: the keys below may be set here.
RESCUE_OPTIONS: dict[str, Any] = {"snes_linesearch_type": "l2", "snes_max_it": 60}

# A factorisation at every Newton iteration: exact Newton.
_FACTORISE_EVERY_ITERATION: dict[str, Any] = {
    "ksp_type": "preonly", "refactor_above_its": 0, "refactor_above_ratio": 1.0,
}

# GMRES on the current tangent, preconditioned by the last factorisation.
_REUSE_FACTORISATION: dict[str, Any] = {
    "ksp_type": "gmres",
    "ksp_rtol": 1e-5,
    "ksp_max_it": 100,
    "ksp_gmres_restart": 100,
    # Measured on the default mesh (clinical cases, one pinned core): 10 gave median
    # 5.1 s and at most 2 factorisations; 25 let supine C1 = 1 kPa take 89 Krylov
    # iterations on one factorisation, 10.4 s against 7.4 s.
    "refactor_above_its": 10,
    "refactor_above_ratio": 0.5,
    "lag_below_ratio": 0.3,
    "ksp_pc_side": "right",
    # Below it the full-rank factorisation is as fast (measured on the default mesh's 50k
    # unknowns: 4 % apart); above it BLR saves most of the time and memory.
    "blr_above_dofs": 200_000,
    # A Krylov failure on stale factors is not fatal: the next iteration re-factorises.
    "snes_max_linear_solve_fail": 3,
}

#: MUMPS' block low-rank factorisation (BLR, with the low-rank updates compressed before the
#: factorisation of each front, ``ICNTL(36) = 1``), dropping at ``CNTL(7)``: an approximate
#: factorisation with far less memory and work on large 3D meshes, which GMRES turns into
#: Newton steps as exact as before (its test is on the true residual). The ``direct`` preset
#: uses it above ``blr_above_dofs`` unknowns. Measured on a 447k-unknown P2/P1 import (97k
#: tetrahedra, prone C1 = 1 kPa, 2 cores): docs/results-log.md.
BLR_OPTIONS: dict[str, Any] = {
    "mat_mumps_icntl_35": 2,
    "mat_mumps_icntl_36": 1,
    "mat_mumps_cntl_7": 1e-3,
}

SOLVER_PRESETS: dict[str, dict[str, Any]] = {
    "direct": {**_MUMPS, **_REUSE_FACTORISATION, "pc_type": "cholesky"},
    "direct-refactor": {**_MUMPS, **_FACTORISE_EVERY_ITERATION, "pc_type": "cholesky"},
    "direct-lu": {**_MUMPS, **_FACTORISE_EVERY_ITERATION, "pc_type": "lu"},
    "iterative": {
        "ksp_type": "fgmres",
        "ksp_rtol": 1e-8,
        "ksp_atol": 1e-14,
        "ksp_max_it": 500,
        "ksp_gmres_restart": 200,
        "pc_type": "fieldsplit",
        "pc_fieldsplit_type": "schur",
        "pc_fieldsplit_schur_fact_type": "full",
        # "a11": the pressure block of the preconditioning matrix, -M_p / (2 C1)
        "pc_fieldsplit_schur_precondition": "a11",
        "fieldsplit_u_ksp_type": "preonly",
        "fieldsplit_u_pc_type": "gamg",
        "fieldsplit_u_pc_gamg_threshold": 0.02,
        "fieldsplit_u_mg_levels_ksp_type": "chebyshev",
        "fieldsplit_u_mg_levels_ksp_max_it": 3,
        "fieldsplit_u_mg_levels_pc_type": "jacobi",
        "fieldsplit_p_ksp_type": "preonly",
        "fieldsplit_p_pc_type": "jacobi",
    },
}


def default_parameters(preset: str = "direct") -> dict[str, Any]:
    """Default PETSc options: Newton with backtracking line search plus a linear-solver preset.

    Args:
        preset: ``"direct"`` (GMRES on a reused MUMPS LDLᵀ factorisation),
            ``"direct-refactor"`` (MUMPS LDLᵀ at every iteration), ``"direct-lu"`` (MUMPS
            LU at every iteration) or ``"iterative"`` (FGMRES + fieldsplit Schur + GAMG);
            see the module docstring.

    Raises:
        InvalidParameterError: if ``preset`` is unknown.
    """
    if preset not in SOLVER_PRESETS:
        raise InvalidParameterError(
            f"unknown solver preset {preset!r}; expected one of {sorted(SOLVER_PRESETS)}"
        )
    return {**_NEWTON, **SOLVER_PRESETS[preset]}


#: Every option that a preset, the last resort or the solver itself sets, with its default:
#: the options the solver reads, and so the only ones a config may override.
KNOWN_OPTIONS: dict[str, Any] = {
    key: value
    for options in (*(default_parameters(p) for p in SOLVER_PRESETS), RESCUE_OPTIONS,
                    BLR_OPTIONS)
    for key, value in options.items()
}

#: Parts of an option name that make PETSc write (viewers, monitors, logs, drawing): a
#: config may not set them, since their value can name any file to write.
_WRITES = ("view", "monitor", "log", "draw", "output")

#: A string value: a PETSc type name (no path, no viewer specification).
_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_-]*")


def check_overrides(overrides: dict[str, Any]) -> None:
    """Check a config's PETSc options against those the solver reads, before any solve.

    Raises:
        InvalidParameterError: naming the option, for one that writes output (a viewer or
            monitor), one the solver does not read (a typo would be silently ignored), or a
            value of the wrong kind (a number where PETSc reads a number, a type name where it
            reads a string).
    """
    for key, value in overrides.items():
        where = f"petsc_options.{key}"
        if any(part in key for part in _WRITES):
            raise InvalidParameterError(
                f"{where}: options that make PETSc write (viewers, monitors, logs) cannot be "
                "set from the config"
            )
        if key not in KNOWN_OPTIONS:
            raise InvalidParameterError(
                f"{where} is not an option the solver reads (a misspelt option would be "
                f"ignored); expected one of {', '.join(sorted(KNOWN_OPTIONS))}"
            )
        default = KNOWN_OPTIONS[key]
        if key in SOLVER_KEYS:  # the solver's own options: checked by solver_options itself
            continue
        if isinstance(default, bool):
            ok = isinstance(value, bool)
        elif isinstance(default, int):
            ok = isinstance(value, int) and not isinstance(value, bool)
        elif isinstance(default, float):
            ok = (isinstance(value, int | float) and not isinstance(value, bool)
                  and math.isfinite(value))
        else:
            ok = isinstance(value, str) and _NAME.fullmatch(value) is not None
        if not ok:
            kind = {bool: "true or false", int: "an integer", float: "a finite number"}.get(
                type(default), "a PETSc type name")
            raise InvalidParameterError(f"{where} must be {kind}, got {value!r}")


def solver_options(
    preset: str = "direct", overrides: dict[str, Any] | None = None
) -> dict[str, Any]:
    """The preset's defaults with ``overrides`` applied, checked.

    Raises:
        InvalidParameterError: for an unknown preset or line search, or a
            ``refactor_above_its`` that is not a non-negative integer or is set where
            no factorisation can be reused (a ``pc_type`` other than lu/cholesky, or
            ``ksp_type preonly``, which would silently make Newton a chord method).
    """
    check_overrides(overrides or {})
    options = {**default_parameters(preset), **(overrides or {})}
    line_search = options.get("snes_linesearch_type")
    if line_search not in LINE_SEARCHES:
        raise InvalidParameterError(
            f"unknown line search {line_search!r}; expected one of {LINE_SEARCHES}"
        )
    lag = options.get("refactor_above_its", 0)
    if isinstance(lag, bool) or not isinstance(lag, int) or lag < 0:
        raise InvalidParameterError(
            f"refactor_above_its must be a non-negative integer, got {lag!r}"
        )
    ratio = options.get("refactor_above_ratio", 1.0)
    if isinstance(ratio, bool) or not isinstance(ratio, int | float) or not 0 < ratio <= 1:
        raise InvalidParameterError(
            f"refactor_above_ratio must be a number in (0, 1], got {ratio!r}"
        )
    chord = options.get("lag_below_ratio", 0.0)
    if isinstance(chord, bool) or not isinstance(chord, int | float) or not 0 <= chord < 1:
        raise InvalidParameterError(
            f"lag_below_ratio must be a number in [0, 1), got {chord!r}"
        )
    load_atol = options.get("load_atol", 0.0)
    if (isinstance(load_atol, bool) or not isinstance(load_atol, int | float)
            or not math.isfinite(load_atol) or load_atol < 0):
        raise InvalidParameterError(f"load_atol must be a non-negative number, got {load_atol!r}")
    blr = options.get("blr_above_dofs", 0)
    if isinstance(blr, bool) or not isinstance(blr, int) or blr < 0:
        raise InvalidParameterError(f"blr_above_dofs must be a non-negative integer, got {blr!r}")
    if lag and (
        options.get("pc_type") not in _FACTORISATIONS or options.get("ksp_type") == "preonly"
    ):
        raise InvalidParameterError(
            f"refactor_above_its = {lag} reuses a factorisation as a Krylov preconditioner: it "
            f"needs pc_type lu or cholesky and a Krylov ksp_type, not pc_type "
            f"{options.get('pc_type')!r} with ksp_type {options.get('ksp_type')!r} "
            "(set refactor_above_its: 0 to factorise at every Newton iteration)"
        )
    return options


__all__ = [
    "BLR_OPTIONS",
    "KNOWN_OPTIONS",
    "LINE_SEARCHES",
    "RESCUE_OPTIONS",
    "SOLVER_KEYS",
    "SOLVER_PRESETS",
    "check_overrides",
    "default_parameters",
    "solver_options",
]
