"""Mesh a label volume with CGAL's labelled-image mesher: one subdomain, one cell tag, per tissue.

``mesh.image.mesher: cgal`` (the other mesher, the default ``ftetwild``, is
:func:`meshes.image.image_volume`: marching cubes and fTetWild). The breast's labels are
cropped to the breast (with a margin of background), each label replaced by its tissue's
:class:`meshes.tags.Tissue` value (the labels outside the breast by 0, the outside) and
meshed by CGAL's ``Mesh_3`` through ``pygalmesh`` (Debian's ``python3-pygalmesh``): the
tissues' interfaces and the skin are
restricted Delaunay surfaces within :data:`FACET_DISTANCE_M` of the labels' boundaries, the
cells bounded by ``size.global_size`` (circumradius), each cell carrying its tissue.

Two runs give the same points and cells: the optimisers that stop on a clock or draw random
moves (CGAL's perturber and Lloyd smoother) are off; the refinement and the exuder (run to
the end, no time limit) are sequential and seeded. The exuder leaves slivers whose four
vertices lie on the tissues' interfaces, which no weight or vertex move inside a tissue can
lift: :func:`lift_slivers` removes them by flips within a tissue (2-3 and 3-2, which keep
every interface) and moves the free vertices of the rest, in a fixed order. The few cells it
leaves below the floor (:data:`meshes.remesh.MIN_DIHEDRAL_DEG`) are counted in the quality
report and named in a warning (:func:`meshes.remesh.check_dihedral_floor`, not strict): the
reason this mesher is not the default. See docs/geometry.md for the measurement.
"""

from __future__ import annotations

import logging
import os
import tempfile
import time
from typing import Any

import numpy as np

from meshes.checks import check_plausible_size, check_plausible_volume, check_tetrahedra
from meshes.exceptions import MeshInputError
from meshes.importing import InputVolume
from meshes.quality import dihedral_angles, exterior_faces, tet_volumes
from meshes.remesh import MIN_DIHEDRAL_DEG, check_dihedral_floor, compact
from meshes.sizing import MeshSize
from meshes.tags import Tissue

log = logging.getLogger(__name__)

#: How far a surface facet may lie from the labels' boundary (CGAL's facet distance), m; at
#: most a tenth of ``global_size``.
FACET_DISTANCE_M = 1e-3
#: CGAL's bound on the surface facets' smallest angle, degrees (its refinement terminates
#: for bounds up to 30°): good surface triangles leave fewer slivers on the interfaces.
FACET_ANGLE_DEG = 25.0
#: CGAL's bound on a cell's circumradius over its shortest edge (it terminates for >= 2).
RADIUS_EDGE_RATIO = 2.0
#: Background voxels kept around the breast's box, so that the outside surrounds it.
MARGIN_VOXELS = 2
#: Rounds of :func:`lift_slivers` (flips, then vertex moves) at most.
LIFT_ROUNDS = 8

#: The faces of a tetrahedron, face i opposite vertex i.
FACES = np.array([[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]])
#: The edges of a tetrahedron.
EDGES = ((0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3))


def cgal_settings(size: MeshSize, spacing_mm: np.ndarray) -> dict[str, Any]:
    """CGAL's criteria (millimetres, the image's units) for ``size`` on voxels of ``spacing_mm``.

    The facet distance is :data:`FACET_DISTANCE_M` (a tenth of ``global_size`` where that is
    finer), never under a third of the finest voxel: the labels' staircase is no finer.
    """
    global_mm = 1e3 * size.global_size
    distance = max(min(1e3 * FACET_DISTANCE_M, global_mm / 10.0), float(np.min(spacing_mm)) / 3.0)
    return {
        "max_cell_circumradius": float(global_mm),
        "max_radius_surface_delaunay_ball": float(global_mm),
        "max_facet_distance": float(distance),
        "min_facet_angle": FACET_ANGLE_DEG,
        "max_circumradius_edge_ratio": RADIUS_EDGE_RATIO,
        # the perturber and Lloyd stop on a clock and move at random: two runs would differ
        "lloyd": False, "odt": False, "perturb": False,
        "exude": True, "exude_time_limit": 0.0, "exude_sliver_bound": 0.0,
        "seed": 0,
    }


def mesh_labels(vol: np.ndarray, spacing_mm: np.ndarray,
                settings: dict[str, Any]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """CGAL's mesh of a label volume (uint8, 0 outside).

    ``pygalmesh.generate_from_array`` (0.10.6) passes ``verbose`` and ``seed`` into the
    exuder's time limit and sliver bound (positional arguments one place off), so the volume
    is written as an INR file here and given to ``generate_from_inr`` by keyword.

    Returns:
        ``(points, tets, cell labels)``: points in millimetres of the volume's index frame
        (voxel ``(i, j, k)``'s centre at ``(i, j, k) * spacing``).

    Raises:
        MeshInputError: if pygalmesh is missing or CGAL fails.
    """
    try:
        import pygalmesh
    except ImportError:
        raise MeshInputError("mesh.image.mesher cgal needs pygalmesh (python3-pygalmesh, "
                             "installed by make setup), or set mesh.image.mesher: ftetwild"
                             ) from None
    handle, inr = tempfile.mkstemp(suffix=".inr")
    os.close(handle)
    try:
        pygalmesh.save_inr(np.asfortranarray(vol), tuple(float(s) for s in spacing_mm), inr)
        mesh = pygalmesh.generate_from_inr(inr, verbose=False, **settings)
    except Exception as err:  # CGAL's errors arrive as plain RuntimeErrors
        raise MeshInputError(f"CGAL's labelled-image mesher failed: {err}") from None
    finally:
        os.remove(inr)
    tets = np.asarray(mesh.get_cells_type("tetra"), dtype=np.int64)
    if len(tets) == 0:
        raise MeshInputError("CGAL's labelled-image mesher found no cells: the breast is "
                             "thinner than its facet distance")
    cell_labels = np.asarray(mesh.cell_data_dict["medit:ref"]["tetra"], dtype=np.int64)
    x, tets = compact(np.asarray(mesh.points, dtype=float), tets)
    return x, tets, cell_labels


def _neighbours(tets: np.ndarray) -> np.ndarray:
    """The cell across each face (face i opposite vertex i) of each cell, -1 on the boundary."""
    faces = np.sort(tets[:, FACES].reshape(-1, 3), axis=1)
    n = int(tets.max()) + 1
    key = (faces[:, 0] * n + faces[:, 1]) * n + faces[:, 2]
    order = np.argsort(key, kind="stable")
    same = np.flatnonzero(key[order][1:] == key[order][:-1])
    out = np.full(len(faces), -1, dtype=np.int64)
    a, b = order[same], order[same + 1]
    out[a], out[b] = b // 4, a // 4
    return out.reshape(-1, 4)


def _vertex_cells(tets: np.ndarray, n_points: int) -> tuple[np.ndarray, np.ndarray]:
    """Each vertex's cells as ``cells[start[v]:start[v + 1]]``."""
    order = np.argsort(tets.ravel(), kind="stable")
    start = np.zeros(n_points + 1, dtype=np.int64)
    start[1:] = np.cumsum(np.bincount(tets.ravel(), minlength=n_points))
    return order // 4, start


def _quality(x: np.ndarray, cells: np.ndarray) -> float:
    """The worst dihedral angle of ``cells``, or -1 if one is not positively oriented."""
    cells = np.asarray(cells, dtype=np.int64).reshape(-1, 4)
    volumes = tet_volumes(x, cells)
    scale = np.max(np.abs(x[cells] - x[cells[:, :1]]), axis=(1, 2)) ** 3
    if np.any(volumes <= 1e-9 * scale):
        return -1.0
    return float(dihedral_angles(x, cells).min())


def _positive(x: np.ndarray, cell: list[int]) -> list[int]:
    return cell if tet_volumes(x, np.array([cell]))[0] > 0 else [cell[0], cell[2], cell[1], cell[3]]


def _flip_round(x: np.ndarray, tets: np.ndarray, labels: np.ndarray,
                floor: float) -> tuple[np.ndarray, np.ndarray, int]:
    """One round of flips on the cells below ``floor`` (see :func:`lift_slivers`)."""
    angles = dihedral_angles(x, tets).min(axis=1)
    bad = np.flatnonzero(angles < floor)
    bad = bad[np.argsort(angles[bad], kind="stable")]
    neighbours = _neighbours(tets)
    cells_of, start = _vertex_cells(tets, len(x))
    gone = np.zeros(len(tets), dtype=bool)
    new_cells: list[list[int]] = []
    new_labels: list[int] = []
    for c in bad:
        if gone[c] or np.any(gone[neighbours[c][neighbours[c] >= 0]]):
            continue
        cell = tets[c]
        across = np.where(neighbours[c] >= 0, labels[np.maximum(neighbours[c], 0)], -1)
        others = set(across.tolist()) - {int(labels[c])}
        if len(others) == 1 and np.sum(across == min(others)) >= 2:
            other = min(others)
            if other < 0:  # a flat cell on the boundary, two or three faces outside: drop it
                gone[c] = True
                continue
            # a flat cell lying on an interface, two faces on it: the other tissue's, if a
            # flip on that side lifts it (the interface moves by the sliver's thickness)
            owners = (int(labels[c]), other)
        else:
            owners = (int(labels[c]),)
        best: tuple[float, list[int], list[list[int]], int] | None = None
        for own in owners:
            for i in range(4):  # 2-3: through a face shared with a cell of the tissue
                n = int(neighbours[c, i])
                if n < 0 or gone[n] or labels[n] != own:
                    continue
                a, b, d = cell[FACES[i]]
                top = int(cell[i])
                other_vertex = int(np.setdiff1d(tets[n], cell[FACES[i]])[0])
                trial = [[a, b, top, other_vertex], [b, d, top, other_vertex],
                         [d, a, top, other_vertex]]
                volumes = tet_volumes(x, np.array(trial))
                if not (np.all(volumes > 0) or np.all(volumes < 0)):
                    continue
                trial = [_positive(x, t) for t in trial]
                quality = _quality(x, trial)
                if quality > min(angles[c], angles[n]) + 1e-6 and (
                        best is None or quality > best[0]):
                    best = (quality, [int(c), n], trial, own)
            for p, q in EDGES:  # 3-2: an edge inside the tissue that three cells share
                u, v = int(cell[p]), int(cell[q])
                around = cells_of[start[u]:start[u + 1]]
                around = around[np.any(tets[around] == v, axis=1)]
                if len(around) != 3 or np.any(gone[around]) or np.any(
                        (labels[around] != own) & (around != c)):
                    continue
                ring = sorted({w for k in around for w in tets[k].tolist()} - {u, v})
                if len(ring) != 3 or any(_edge_on_boundary(tets[k], neighbours[k], u, v)
                                         for k in around):
                    continue
                trial = [_positive(x, [*ring, u]), _positive(x, [*ring, v])]
                old_volume = float(np.abs(tet_volumes(x, tets[around])).sum())
                if abs(float(tet_volumes(x, np.array(trial)).sum()) - old_volume) > (
                        1e-9 * old_volume):
                    continue  # the edge does not pierce the ring's triangle
                quality = _quality(x, trial)
                if quality > float(angles[around].min()) + 1e-6 and (
                        best is None or quality > best[0]):
                    best = (quality, around.tolist(), trial, own)
        if best is not None:
            gone[best[1]] = True
            new_cells += best[2]
            new_labels += [best[3]] * len(best[2])
    changed = int(gone.sum())
    if not changed:
        return tets, labels, 0
    tets = np.concatenate([tets[~gone], np.array(new_cells, dtype=np.int64).reshape(-1, 4)])
    labels = np.concatenate([labels[~gone], np.array(new_labels, dtype=np.int64)])
    return tets, labels, changed


def _edge_on_boundary(cell: np.ndarray, neighbours: np.ndarray, u: int, v: int) -> bool:
    """Whether a boundary face of ``cell`` holds the edge (u, v)."""
    return any(neighbours[i] < 0 and u in cell[FACES[i]] and v in cell[FACES[i]]
               for i in range(4))


def _move_round(x: np.ndarray, tets: np.ndarray, labels: np.ndarray, floor: float) -> int:
    """Move the vertices of the cells below ``floor`` (in place; see :func:`lift_slivers`)."""
    angles = dihedral_angles(x, tets).min(axis=1)
    bad = np.flatnonzero(angles < floor)
    if not len(bad):
        return 0
    neighbours = _neighbours(tets)
    across = np.where(neighbours >= 0, labels[np.maximum(neighbours, 0)], -1)
    cells_of, start = _vertex_cells(tets, len(x))
    moved = 0
    for v in np.unique(tets[bad]):
        ring = cells_of[start[v]:start[v + 1]]
        sides = set(labels[ring].tolist()) | set(across[ring].ravel().tolist())
        if len(sides) > 2:
            continue  # on a line where three tissues (or two and the outside) meet: kept
        faces = [tets[k][FACES[i]] for k in ring for i in range(4)
                 if across[k, i] != labels[k] and v in tets[k][FACES[i]]]
        near = np.setdiff1d(np.unique(np.array(faces) if faces else tets[ring]), [v])
        home = x[v].copy()
        step = x[near].mean(axis=0) - home
        if faces:  # on one interface (or the outside): slide along it, not across
            normals = np.cross(x[[f[1] for f in faces]] - x[[f[0] for f in faces]],
                               x[[f[2] for f in faces]] - x[[f[0] for f in faces]])
            normal = np.linalg.eigh(normals.T @ normals)[1][:, -1]
            step -= (step @ normal) * normal
        old = _quality(x, tets[ring])
        below = int(np.sum(dihedral_angles(x, tets[ring]).min(axis=1) < floor))
        best = (old, home)
        for fraction in (1.0, 0.5, 0.25):
            x[v] = home + fraction * step
            quality = _quality(x, tets[ring])
            # the worst cell better, and no other cell newly below the floor
            if quality > best[0] + 1e-6 and np.sum(
                    dihedral_angles(x, tets[ring]).min(axis=1) < floor) <= below:
                best = (quality, x[v].copy())
        x[v] = best[1]
        moved += int(best[0] > old)
    return moved


def lift_slivers(x: np.ndarray, tets: np.ndarray, labels: np.ndarray,
                 floor: float = MIN_DIHEDRAL_DEG) -> tuple[np.ndarray, np.ndarray, np.ndarray,
                                                           dict[str, Any]]:
    """Lift the cells below ``floor``: flips within a tissue, then moves of free vertices.

    A flip replaces cells by others filling the same space (2-3 through a face, 3-2 about an
    edge) among cells of one tissue, so no interface or boundary facet changes; a flat cell
    with two faces on an interface may join the tissue across it to be flipped there, and one
    with two faces outside is dropped (either moves the surface by the sliver's thickness).
    A vertex inside a tissue moves towards its neighbours' centre; one on a single interface
    (or the outside) slides along it, in its plane; one where three sides meet stays. Each
    change is taken only where it raises the worst angle of the cells it touches; cells are
    visited worst first, index breaking ties: the same mesh gives the same result.

    Returns:
        ``(points, tets, labels, record)``: record holds the rounds, flips, moves and the
        cells below the floor before and after.
    """
    x = np.array(x, dtype=float)
    before = int(np.sum(dihedral_angles(x, tets).min(axis=1) < floor))
    record: dict[str, Any] = {"cells_below_floor_before": before, "flips": 0, "moves": 0,
                              "rounds": 0}
    for _ in range(LIFT_ROUNDS):
        if not np.any(dihedral_angles(x, tets).min(axis=1) < floor):
            break
        tets, labels, flips = _flip_round(x, tets, labels, floor)
        moves = _move_round(x, tets, labels, floor)
        record["rounds"] += 1
        record["flips"] += flips
        record["moves"] += moves
        if flips == 0 and moves == 0:
            break
    record["cells_below_floor_after"] = int(np.sum(dihedral_angles(x, tets).min(axis=1) < floor))
    return x, tets, labels, record


def _chest_distance(labels: np.ndarray, lo: np.ndarray, hi: np.ndarray, chest_label: int,
                    spacing_mm: np.ndarray, working_mm: float) -> Any:
    """The distance (mm) from the chest label, in the crop's voxel frame, on a working grid."""
    from scipy import ndimage
    from skimage.measure import block_reduce

    factor = tuple(int(max(1, round(working_mm / s))) for s in spacing_mm)
    crop = tuple(slice(a, b) for a, b in zip(lo, hi, strict=True))
    chest = block_reduce(labels[crop] == chest_label, factor, np.max, cval=False)
    if not chest.any():
        return None
    distance = ndimage.distance_transform_edt(~chest, sampling=spacing_mm * np.array(factor))

    def at(index: np.ndarray) -> np.ndarray:
        """Distances at continuous voxel indices of the crop (n, 3)."""
        grid = (index - (np.array(factor) - 1) / 2.0) / factor
        return ndimage.map_coordinates(distance, grid.T, order=1, mode="nearest")

    return at


def cgal_volume(spec: Any, size: MeshSize, labels: np.ndarray, grid: Any,
                counts: dict[int, int], chest_group: str, working_spacing_m: float,
                read_s: float = 0.0) -> InputVolume:
    """Mesh a label volume's tissues with CGAL (see the module's docstring).

    Args:
        spec: the ``mesh.image`` section (:class:`meshes.image.ImageSpec`).
        size: ``global_size`` bounds the cells.
        labels: the label volume ``[i, j, k]``, its labels checked.
        counts: its voxels per label.
        grid: its header's map to LPS millimetres (:class:`meshes.image.Grid`).
        chest_group: the file group of the facets next to the chest label.
        working_spacing_m: the coarsest grid the chest's distance is taken on.
        read_s: the seconds reading took, for the report.

    Raises:
        MeshInputError: (a subclass naming the problem) for an unreadable image, absent labels,
            a breast CGAL cannot mesh, or cells left below the quality floor.
    """
    from scipy import ndimage

    what = f"the breast of {spec.path} (CGAL)"
    start = time.perf_counter() - read_s
    breast = np.isin(labels, spec.breast_labels)
    spans = [np.flatnonzero(breast.any(axis=tuple(a for a in range(3) if a != axis)))
             for axis in range(3)]
    first, last = np.array([s[0] for s in spans]), np.array([s[-1] for s in spans])
    lo = np.maximum(first - MARGIN_VOXELS, 0)
    hi = np.minimum(last + 1 + MARGIN_VOXELS, labels.shape)
    crop = tuple(slice(a, b) for a, b in zip(lo, hi, strict=True))
    inside = breast[crop]
    del breast
    # the largest connected piece, its inner holes filled with fat (as the fTetWild path)
    pieces, n = ndimage.label(inside)
    sizes = np.bincount(pieces.ravel())[1:]
    kept = pieces == 1 + int(np.argmax(sizes))
    del pieces
    filled = ndimage.binary_fill_holes(kept)
    vol = np.zeros(inside.shape, dtype=np.uint8)
    part = labels[crop]
    for label, tissue in spec.label_tissues().items():
        vol[kept & (part == label)] = int(tissue)
    vol[filled & ~kept] = int(Tissue.FAT)
    voxel_ml = 1e-3 * float(np.prod(grid.spacing))
    info: dict[str, Any] = {
        "path": spec.path, "units": spec.units, "kind": "label volume", "mesher": "cgal",
        "labels": {str(v): c for v, c in counts.items()},
        "breast_labels": list(spec.breast_labels), "chest_label": spec.chest_label,
        "voxel_size_mm": grid.spacing.tolist(), "image_shape": list(grid.shape),
        "labelled_volume_ml": voxel_ml * float(inside.sum()),
        "pieces_dropped": int(n - 1),
        "dropped_volume_ml": voxel_ml * float(sizes.sum() - sizes.max()),
        "holes_filled_ml": voxel_ml * float((filled & ~kept).sum()),
        "labelled_tissue_ml": {t.label: voxel_ml * float(np.sum(vol == t)) for t in Tissue
                               if np.any(vol == t)},
    }
    del inside, kept, filled, part
    prepare_s = time.perf_counter() - start - read_s
    settings = cgal_settings(size, grid.spacing)
    x_mm, tets, cell_labels = mesh_labels(vol, grid.spacing, settings)
    del vol
    cgal_s = time.perf_counter() - start - read_s - prepare_s
    # CGAL's frame: the crop's voxel centres at index * spacing (mm); the header maps indices
    index = x_mm / grid.spacing + lo
    x = 1e-3 * grid.to_physical(index)
    tets = np.where((tet_volumes(x, tets) < 0)[:, None], tets[:, [0, 2, 1, 3]], tets)
    x, tets, cell_labels, info["slivers"] = lift_slivers(x, tets, cell_labels)
    lift_s = time.perf_counter() - start - read_s - prepare_s - cgal_s
    info["extent_m"] = check_plausible_size(x, spec.units, what)
    tets = check_tetrahedra(x, tets, what)
    volumes = np.abs(tet_volumes(x, tets))
    info["volume_ml"] = check_plausible_volume(float(volumes.sum()), spec.units, what)
    info["fill"] = {"method": "CGAL labelled-image mesher (pygalmesh)",
                    "settings_mm": settings, "cells": int(len(tets)),
                    "attempts": [{"method": "cgal", "outcome": "done"}]}
    info["quality_floor"] = check_dihedral_floor(x, tets, what, strict=False)
    info["meshed_volume_ml"] = 1e6 * float(volumes.sum())
    info["volume_kept"] = info["meshed_volume_ml"] / info["labelled_volume_ml"]
    faces = exterior_faces(tets)
    groups = np.full(len(faces), -1, dtype=np.int64)
    names: dict[str, int] = {}
    if spec.chest_label is not None:
        working_mm = 1e3 * min(size.global_size / 6.0, working_spacing_m)
        distance = _chest_distance(labels, lo, hi, spec.chest_label, grid.spacing, working_mm)
        if distance is None:
            raise MeshInputError(f"{spec.path}: the chest label {spec.chest_label} does not "
                                 "touch the breast (none of it lies in the breast's box)")
        centres = grid.to_index(1e3 * x[faces].mean(axis=1)) - lo
        near = distance(centres) <= 1.5 * max(working_mm, float(np.max(grid.spacing)))
        groups[near] = 1
        names[chest_group] = 1
        info["chest_facets"] = int(near.sum())
    del labels
    tissues = cell_labels
    info["tissue_cells"] = {t.label: int(np.sum(tissues == t)) for t in Tissue
                            if np.any(tissues == t)}
    info["tissue_volume_ml"] = {t.label: 1e6 * float(volumes[tissues == t].sum()) for t in Tissue
                                if np.any(tissues == t)}
    info["seconds"] = {"read": round(read_s, 3), "prepare": round(prepare_s, 3),
                       "cgal": round(cgal_s, 3), "lift_slivers": round(lift_s, 3),
                       "total": round(time.perf_counter() - start, 3)}
    log.info("CGAL meshed %s: %d cells, worst dihedral %.2f°, in %.1f s", spec.path, len(tets),
             info["quality_floor"]["min_dihedral_deg"], info["seconds"]["total"])
    all_fat = bool(np.all(tissues == Tissue.FAT))
    return InputVolume(x, tets, faces, groups, names, info, None if all_fat else tissues)
