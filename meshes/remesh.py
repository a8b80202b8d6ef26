"""Fill a closed surface with tetrahedra, remeshing it where asked, to a quality floor.

A surface is kept (its triangles become the volume mesh's boundary) or remeshed to
``mesh.size.global_size``. Remeshing tries, in order, until one meets the dihedral floor
(:data:`MIN_DIHEDRAL_DEG`):

1. **gmsh's reparametrisation**: the surface is split at sharp edges into patches that gmsh
   parametrises and meshes anew. It is deterministic and gives the best cells on a smooth,
   dense surface (a scan, a marching-cubes surface), but stops on many real files: a low-poly
   surface exported by a modelling tool, an n-gon fill of long thin triangles, a sharp rim
   where the chest-wall cut meets the skin ("Wrong topology of boundary mesh for
   parametrization", "Invalid boundary mesh (overlapping facets)").
2. **fTetWild's envelope** (pytetwild): tetrahedralises any triangle soup within an envelope
   of ``epsilon`` times the bounding box's diagonal of the input, whatever its triangles are;
   its boundary (a clean, closed surface at about ``global_size``) is then filled by gmsh
   keeping those triangles, with gmsh's and Netgen's optimisers. fTetWild is not
   deterministic (its cells differ slightly between runs); the volume kept is recorded.
   A wider envelope is tried when a narrow one leaves a sliver.

Any failure of a mesher becomes a :class:`meshes.exceptions.MeshInputError` that names the
stage and what to try, never a traceback.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from meshes.checks import enclosed_volume
from meshes.exceptions import InvalidElementsError, MeshInputError
from meshes.quality import dihedral_angles, exterior_faces, tet_volumes
from meshes.sizing import MeshSize

log = logging.getLogger(__name__)

#: Smallest dihedral angle (degrees) accepted in a tetrahedron the import makes: below it a
#: cell is a sliver, whose stiffness conditions the tangent badly and whose P2 interpolation
#: errs (a regular tetrahedron has 70.5°).
MIN_DIHEDRAL_DEG = 10.0

#: Envelopes fTetWild is given, in turn (fractions of the input's bounding-box diagonal): the
#: narrowest keeps the shape closest; a wider one lets the mesher move the boundary further
#: to remove a last sliver.
ENVELOPES = (1e-3, 2e-3, 4e-3)

#: Sharp-edge angle at which gmsh splits a surface into patches to reparametrise.
FEATURE_ANGLE_DEG = 40.0


@dataclass(frozen=True)
class FilledSurface:
    """A surface filled with tetrahedra, and how.

    Attributes:
        x: points (N, 3), metres.
        tets: tetrahedra (n, 4).
        method: the method that gave them.
        attempts: every method tried, in order, with its outcome and time.
    """

    x: np.ndarray
    tets: np.ndarray
    method: str
    attempts: list[dict[str, Any]] = field(default_factory=list)

    @property
    def min_dihedral_deg(self) -> float:
        """The smallest dihedral angle of any cell."""
        return worst_dihedral(self.x, self.tets)

    def describe(self) -> dict[str, Any]:
        """For the mesh's quality report."""
        return {"method": self.method, "attempts": self.attempts}


def worst_dihedral(x: np.ndarray, tets: np.ndarray) -> float:
    """The smallest dihedral angle (degrees) of the cells (180 for no cells)."""
    return float(dihedral_angles(x, tets).min()) if len(tets) else 180.0


def fill_surface(points: np.ndarray, tris: np.ndarray, size: MeshSize, remesh: bool,
                 envelopes: tuple[float, ...] = ENVELOPES,
                 reparametrise: bool = True) -> FilledSurface:
    """Fill a closed, checked surface with tetrahedra (see the module's docstring).

    Args:
        points: vertices, metres.
        tris: triangles, facing outwards.
        size: ``global_size`` bounds the tetrahedra (and the remeshed triangles).
        remesh: remesh the surface (else keep its triangles).
        envelopes: fTetWild's envelopes to try, in turn.
        reparametrise: try gmsh's reparametrisation first (a dense marching-cubes surface,
            whose every voxel step is a sharp edge, can keep it busy for many minutes).

    Returns:
        The first fill that meets the floor; else the one with the best worst cell (the
        caller's floor check names its slivers).

    Raises:
        MeshInputError: if every method failed, naming each one's error.
    """
    if not remesh:
        try:
            x, tets = _gmsh_fill(points, tris, size, reparametrise=False)
        except Exception as err:  # gmsh raises plain Exception with its own message
            raise MeshInputError(
                f"filling the surface with tetrahedra, keeping its triangles (gmsh), failed: "
                f"{err}; set mesh.file.remesh: true to remesh the surface first"
            ) from None
        return FilledSurface(x, tets, "gmsh, the surface's own triangles",
                             [{"method": "gmsh, kept triangles", "outcome": "done"}])
    attempts: list[dict[str, Any]] = []
    best: FilledSurface | None = None
    methods = [("gmsh reparametrisation", None)] if reparametrise else []
    methods += [(f"fTetWild envelope {eps:.3g}", eps) for eps in envelopes]
    for name, envelope in methods:
        start = time.perf_counter()
        try:
            if envelope is None:
                x, tets = _gmsh_fill(points, tris, size, reparametrise=True)
            else:
                x, tets = _envelope_fill(points, tris, size, envelope)
        except Exception as err:  # both meshers raise plain exceptions with their message
            attempts.append({"method": name, "outcome": f"failed: {err}",
                             "seconds": round(time.perf_counter() - start, 3)})
            log.info("remesh by %s failed: %s", name, err)
            continue
        worst = worst_dihedral(x, tets)
        kept = float(np.abs(tet_volumes(x, tets)).sum() / enclosed_volume(points, tris))
        attempts.append({"method": name, "outcome": "done", "cells": int(len(tets)),
                         "min_dihedral_deg": round(worst, 3), "volume_kept": round(kept, 5),
                         "seconds": round(time.perf_counter() - start, 3)})
        filled = FilledSurface(x, tets, name, attempts)
        if best is None or worst > best.min_dihedral_deg:
            best = filled
        if worst >= MIN_DIHEDRAL_DEG:
            break
        log.info("remesh by %s left a cell of %.2f° (floor %g°)", name, worst, MIN_DIHEDRAL_DEG)
    if best is None:
        raise MeshInputError(
            "remeshing the surface failed with every method: "
            + "; ".join(f"{a['method']}: {a['outcome']}" for a in attempts)
            + ": check the surface (meshes.preview), or import a volume mesh instead"
        )
    return FilledSurface(best.x, best.tets, best.method, attempts)


def _gmsh_fill(points: np.ndarray, tris: np.ndarray, size: MeshSize,
               reparametrise: bool) -> tuple[np.ndarray, np.ndarray]:
    """The Delaunay fill by gmsh of a discrete surface (reparametrised and remeshed, or kept)."""
    import gmsh

    from meshes.build import gmsh_session, mesh_arrays

    with gmsh_session("import") as model:
        surface = model.addDiscreteEntity(2)
        model.mesh.addNodes(2, surface, np.arange(1, len(points) + 1), points.ravel())
        model.mesh.addElementsByType(surface, 2, [], (tris + 1).ravel())
        if reparametrise:
            model.mesh.classifySurfaces(math.radians(FEATURE_ANGLE_DEG), True, True, math.pi)
            model.mesh.createGeometry()
        surfaces = [tag for _, tag in model.getEntities(2)]
        loop = model.geo.addSurfaceLoop(surfaces)
        model.geo.addVolume([loop])
        model.geo.synchronize()
        gmsh.option.setNumber("Mesh.MeshSizeMax", size.global_size)
        gmsh.option.setNumber("Mesh.MeshSizeMin", 0.0)
        gmsh.option.setNumber("Mesh.Algorithm3D", 1)
        gmsh.option.setNumber("Mesh.Optimize", 1)
        # Netgen's optimiser moves and swaps to remove slivers (the tetrahedra of a
        # remeshed noisy surface otherwise reach dihedral angles near 1°)
        gmsh.option.setNumber("Mesh.OptimizeNetgen", 1)
        gmsh.option.setNumber("Mesh.RandomSeed", 1)
        model.mesh.generate(3)
        x, tets, _ = mesh_arrays(model, {})
        if worst_dihedral(x, tets) < MIN_DIHEDRAL_DEG:
            for method in ("Relocate3D", "Netgen"):
                model.mesh.optimize(method)
            x, tets, _ = mesh_arrays(model, {})
    return compact(x, tets)


def _envelope_fill(points: np.ndarray, tris: np.ndarray, size: MeshSize,
                   envelope: float) -> tuple[np.ndarray, np.ndarray]:
    """Tetrahedra of fTetWild within ``envelope``, or gmsh's fill of their boundary if better.

    fTetWild's cells are often good already; gmsh's Delaunay fill of the same boundary, with
    Netgen's optimiser, lifts a last sliver more often than it makes one: the better wins.
    """
    import contextlib
    import tempfile

    import pytetwild

    # fTetWild writes a file of its own (__tracked_surface.stl) into the working directory
    with tempfile.TemporaryDirectory(prefix="ftetwild_") as scratch, contextlib.chdir(scratch):
        x, tets = pytetwild.tetrahedralize(
            np.asarray(points, dtype=np.float64), np.asarray(tris, dtype=np.int32),
            edge_length_abs=size.global_size, epsilon=envelope, quiet=True,
        )
    if len(tets) == 0:
        raise MeshInputError("fTetWild found no inside (is the surface closed?)")
    x, tets = compact(np.asarray(x, dtype=float), np.asarray(tets, dtype=np.int64))
    tets = np.where((tet_volumes(x, tets) < 0)[:, None], tets[:, [0, 2, 1, 3]], tets)
    surface_x, surface_tris = compact(x, exterior_faces(tets))
    refilled = _gmsh_fill(surface_x, surface_tris, size, reparametrise=False)
    return max([(x, tets), refilled], key=lambda mesh: worst_dihedral(*mesh))


def compact(x: np.ndarray, cells: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Drop the points no cell uses and renumber the cells."""
    used = np.unique(cells)
    remap = np.full(len(x), -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    return x[used], remap[cells]


def check_dihedral_floor(x: np.ndarray, tets: np.ndarray, what: str, strict: bool) -> dict:
    """Count the cells below :data:`MIN_DIHEDRAL_DEG`; refuse them (``strict``) or warn.

    Returns:
        ``{"min_dihedral_deg", "cells_below_floor", "floor_deg"}`` for the quality report.

    Raises:
        InvalidElementsError: if ``strict`` and a cell is below the floor, naming the worst
            cells (index, smallest angle, centroid).
    """
    angles = dihedral_angles(x, tets).min(axis=1)
    below = np.flatnonzero(angles < MIN_DIHEDRAL_DEG)
    record = {"min_dihedral_deg": float(angles.min()), "cells_below_floor": int(below.size),
              "floor_deg": MIN_DIHEDRAL_DEG}
    if below.size == 0:
        return record
    worst = below[np.argsort(angles[below])][:3]
    named = "; ".join(
        f"cell {i}: {angles[i]:.2f}° at ({', '.join(f'{1e3 * c:.1f}' for c in x[tets[i]].mean(0))})"
        " mm" for i in worst
    )
    message = (f"{what}: {below.size} of {len(tets)} tetrahedra have a dihedral angle below "
               f"{MIN_DIHEDRAL_DEG:g}° (worst {named})")
    if strict:
        raise InvalidElementsError(
            f"{message}, after gmsh's optimisers: remesh with a smaller mesh.size.global_size, "
            "or smooth the surface"
        )
    log.warning("%s; slivers condition the solver badly: remesh them (mesh.file.remesh: true "
                "for a surface) where the solve struggles", message)
    return record
