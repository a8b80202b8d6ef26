"""Named points as a CSV: a header ``name,x,y,z``, then one point per row.

The form every command that takes or writes points uses: a tumour's centre and margin, points
carried between frames (:mod:`meshes.frame`), tracked (:mod:`studies.reference_state.tracking`) or
predicted
(``python -m surrogate.cli predict --points``).
"""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np

from meshes.exceptions import MeshInputError

HEADER = ["name", "x", "y", "z"]


def read_points(path: Path) -> tuple[list[str], np.ndarray]:
    """Names and coordinates (n, 3) of a ``name,x,y,z`` CSV.

    A regular file (the header, then four fields a row, finite numbers) is read by pandas' C
    parser, in about a second a million points; anything else by Python's ``csv`` module, row
    by row, which names what is wrong.

    Raises:
        MeshInputError: naming the file and the row for a missing header, a short row or a
            coordinate that is not a finite number, and the file for one that is not text.
    """
    regular = _read_regular(path)
    if regular is not None:
        return regular
    try:  # "utf-8-sig": a spreadsheet's "CSV UTF-8" starts with a byte-order mark
        with path.open(newline="", encoding="utf-8-sig") as f:
            rows = list(csv.reader(f))
    except (UnicodeDecodeError, csv.Error) as err:
        raise MeshInputError(f"{path}: not a text CSV of name,x,y,z ({err})") from None
    if not rows or not _is_header(rows[0]):
        raise MeshInputError(f"{path}: the first row must be the header {','.join(HEADER)}")
    names, points = [], []
    for number, row in enumerate(rows[1:], start=2):
        if not row:
            continue
        if len(row) != 4:
            raise MeshInputError(f"{path}, row {number}: expected name,x,y,z, got {row!r}")
        try:
            xyz = [float(v) for v in row[1:]]
        except ValueError:
            xyz = [math.nan]
        if not all(math.isfinite(v) for v in xyz):
            raise MeshInputError(f"{path}, row {number} ({row[0]!r}): coordinates must be "
                                 f"finite numbers, got {row[1:]!r}")
        names.append(row[0])
        points.append(xyz)
    if not names:
        raise MeshInputError(f"{path}: no points below the header")
    return names, np.array(points)


def _is_header(row: list[str]) -> bool:
    """Whether a CSV row is the header ``name,x,y,z`` (any case, spaces around the names)."""
    return [c.strip().lower() for c in row] == HEADER


def _read_regular(path: Path) -> tuple[list[str], np.ndarray] | None:
    """:func:`read_points` by pandas' C parser; None for a file it does not read as regular."""
    import pandas as pd

    try:
        with path.open(newline="", encoding="utf-8-sig") as f:
            if not _is_header(next(csv.reader([f.readline()]), [])):
                return None
            frame = pd.read_csv(f, header=None, names=HEADER, dtype={"name": str},
                                keep_default_na=False, engine="c",
                                float_precision="round_trip")
    except (UnicodeDecodeError, csv.Error, ValueError, pd.errors.ParserError):
        return None
    xyz = frame[HEADER[1:]]
    if frame.empty or not all(np.issubdtype(t, np.floating) or np.issubdtype(t, np.integer)
                              for t in xyz.dtypes):
        return None
    points = xyz.to_numpy(dtype=float)
    if not np.all(np.isfinite(points)):
        return None
    return frame["name"].tolist(), points


def write_points(path: Path, names: list[str], points: np.ndarray) -> None:
    """Write a ``name,x,y,z`` CSV."""
    with path.open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(HEADER)
        writer.writerows([name, *map(repr, p)] for name, p in zip(names, points.tolist(),
                                                                   strict=True))


def moved_table(names: list[str], X: np.ndarray, u_mm: np.ndarray) -> str:
    """What a command prints for points ``X`` (m) moved by ``u_mm`` (mm), one line each.

    Under a header: each point's name, the size of its displacement and the displacement (mm),
    and its position in that posture (m).
    """
    lines = [f"{'name':<12} {'|u| mm':>8} {'u (x, y, z) mm':>26}  position in that posture (m)"]
    for name, x, d in zip(names, np.asarray(X) + 1e-3 * np.asarray(u_mm), u_mm, strict=True):
        size = float(np.linalg.norm(d))
        x, d = np.round(x, 5) + 0.0, np.round(d, 3) + 0.0  # no "-0.000"
        lines.append(f"{name:<12} {size:>8.3f} {d[0]:>8.3f} {d[1]:>8.3f} {d[2]:>8.3f}  "
                     f"{x[0]:.5f} {x[1]:.5f} {x[2]:.5f}")
    return "\n".join(lines)


def movement_table(names: list[str], dx_mm: np.ndarray) -> str:
    """What a command prints for points moved by ``dx_mm`` (mm) between two postures.

    One line each: the name, the distance moved and the movement (mm).
    """
    lines = [f"{'name':<12} {'|Δx| mm':>8} {'Δx (x, y, z) mm':>26}"]
    for name, d in zip(names, dx_mm, strict=True):
        size = float(np.linalg.norm(d))
        d = np.round(d, 3) + 0.0  # no "-0.000"
        lines.append(f"{name:<12} {size:>8.3f} {d[0]:>8.3f} {d[1]:>8.3f} {d[2]:>8.3f}")
    return "\n".join(lines)
