"""Name the boundary of an imported mesh by rules: a group of the file, or nearness to a surface.

The rib surface (the fixed chest wall) must be selected; other named surfaces may be; every
boundary facet no rule selects is skin.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from meshes.checks import UNITS, point_surface_distance
from meshes.exceptions import GeometryError, NoRibFacetsError, SurfaceRuleError, reject_unknown
from meshes.quality import triangle_areas
from meshes.reading import InputMesh, read_surface
from meshes.tags import Boundary

KINDS = ("group", "plane", "surface", "posterior")
"""The ways a rule can select facets."""

POSTERIOR = np.array([1.0, 0.0, 0.0])
"""The patient's posterior in the project's frame (x runs anterior to posterior)."""


@dataclass(frozen=True, slots=True)
class BoundaryRule:
    """How to find one named boundary among the boundary facets of an imported mesh.

    Exactly one of ``group``, ``plane``, ``surface`` or ``posterior`` is set.

    Attributes:
        group: a physical-group name (gmsh ``.msh``) or an integer tag of the file's
            triangle cell data.
        plane: ``(point, normal)`` of a plane, metres after unit conversion.
        surface: path of a triangulated surface (STL/OBJ/PLY, same units as the model).
        posterior: ``(angle, band)``: the facets that face posterior, their outward normal
            within ``angle`` degrees of the patient's posterior, and lie within ``band``
            (metres) of the model's most posterior point: a chest wall that is not a plane.
        distance: facets whose every vertex lies within this distance of the plane or
            surface are selected, metres.
    """

    group: str | int | None = None
    plane: tuple[tuple[float, float, float], tuple[float, float, float]] | None = None
    surface: str | None = None
    posterior: tuple[float, float] | None = None
    distance: float = 0.001

    def __post_init__(self) -> None:
        given = [k for k in KINDS if getattr(self, k) is not None]
        if len(given) != 1:
            raise GeometryError(
                "a boundary rule needs exactly one of group, plane, surface or posterior, "
                f"got {given or 'none'}"
            )
        if self.posterior is not None:
            angle, band = self.posterior
            if not (0 < angle <= 90 and math.isfinite(band) and band > 0):
                raise GeometryError(
                    "a posterior rule needs an angle in (0, 90] degrees and a positive band, "
                    f"got angle {angle!r}°, band {1e3 * band:g} mm"
                )
        if not (math.isfinite(self.distance) and self.distance > 0):
            raise GeometryError(
                f"a boundary rule's distance must be positive, got {self.distance!r}"
            )
        if self.plane is not None:
            point, normal = self.plane
            if len(point) != 3 or len(normal) != 3 or np.linalg.norm(normal) == 0:
                raise GeometryError(
                    "a plane rule needs a 3-vector point and a non-zero 3-vector normal"
                )

    @classmethod
    def from_mapping(cls, values: dict[str, Any], units: str = "m") -> BoundaryRule:
        """Build from a config mapping; lengths in the file's ``units`` become metres.

        Forms: ``{group: rib}``, ``{plane: {point: [x, y, z], normal: [nx, ny, nz]},
        distance: d}``, ``{surface: path.stl, distance: d}``.
        """
        reject_unknown(values, {"group", "plane", "surface", "posterior", "distance"},
                       "boundary-rule key(s)")
        scale = UNITS[units]
        plane = None
        if values.get("plane") is not None:
            p = values["plane"]
            if set(p) != {"point", "normal"}:
                raise GeometryError("a plane rule is {point: [x, y, z], normal: [nx, ny, nz]}")
            plane = (
                tuple(scale * float(v) for v in p["point"]),
                tuple(float(v) for v in p["normal"]),
            )
        posterior = None
        if values.get("posterior") is not None:
            q = values["posterior"]
            if set(q) - {"angle", "band"}:
                raise GeometryError("a posterior rule is {angle: degrees, band: length}")
            # the band is in the file's units; 10 mm by default
            band = scale * float(q["band"]) if "band" in q else 0.01
            posterior = (float(q.get("angle", 30.0)), band)
        # like the plane's point, the distance is in the file's units; 1 mm by default
        distance = scale * float(values["distance"]) if "distance" in values else 0.001
        return cls(
            group=values.get("group"),
            plane=plane,
            surface=str(values["surface"]) if values.get("surface") is not None else None,
            posterior=posterior,
            distance=distance,
        )

    def describe(self) -> str:
        """The rule in words, for messages."""
        if self.group is not None:
            return f"group {self.group!r}"
        if self.plane is not None:
            point, normal = self.plane
            through = ", ".join(f"{1e3 * v:g}" for v in point)
            return (f"within {1e3 * self.distance:g} mm of the plane through ({through}) mm, "
                    f"normal {tuple(float(v) for v in normal)}")
        if self.posterior is not None:
            angle, band = self.posterior
            return (f"facing posterior within {angle:g}° and within {1e3 * band:g} mm of the most "
                    "posterior point")
        return f"within {1e3 * self.distance:g} mm of the surface {self.surface}"


def _posterior_facets(
    x: np.ndarray, faces: np.ndarray, rule: BoundaryRule, posterior: np.ndarray
) -> np.ndarray:
    """Facets facing ``posterior`` within the rule's angle, in its band of the back (mask)."""
    angle, band = rule.posterior
    direction = np.asarray(posterior, dtype=float) / np.linalg.norm(posterior)
    a, b, c = (x[faces[:, i]] for i in range(3))
    normal = np.cross(b - a, c - a)
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-300)
    depth = x @ direction
    back = depth[faces].min(axis=1) >= depth.max() - band
    return (normal @ direction >= math.cos(math.radians(angle))) & back


def _facet_distance(x: np.ndarray, faces: np.ndarray, rule: BoundaryRule, units: str) -> np.ndarray:
    """For each face, the largest distance of its vertices from the rule's plane/surface."""
    vertices = np.unique(faces)
    d = np.full(len(x), np.inf)
    if rule.plane is not None:
        point, normal = (np.asarray(v, dtype=float) for v in rule.plane)
        d[vertices] = np.abs((x[vertices] - point) @ (normal / np.linalg.norm(normal)))
    else:
        spts, stris = read_surface(rule.surface, units)
        # exact up to 10x the rule's distance, so a miss can say how far off it was
        d[vertices] = point_surface_distance(x[vertices], spts, stris, 10.0 * rule.distance)
    return d[faces].max(axis=1)


RIB_AREA_SHARE = (0.02, 0.70)
"""The share of the boundary's area the rib rule may select. The clamped chest wall is the
posterior side of a breast model (a third of a hemisphere's surface, for instance): a rule that
clamps nearly all of it leaves nothing to hang under gravity, and one that clamps a sliver holds
the breast by a few facets."""


def _check_rib_share(
    x: np.ndarray, faces: np.ndarray, rib: np.ndarray, rule: BoundaryRule
) -> None:
    """Refuse a rib rule that selects too much or too little of the boundary (by area).

    Raises:
        SurfaceRuleError: with the share, the facet count and what to change.
    """
    areas = triangle_areas(x, faces)
    share = float(areas[rib].sum() / areas.sum())
    lo, hi = RIB_AREA_SHARE
    if lo <= share <= hi:
        return
    what = (
        f"the rib rule ({rule.describe()}) selects {100 * share:.3g} % of the boundary's area "
        f"({int(rib.sum())} of {len(faces)} facets), but the clamped chest wall is "
        f"{100 * lo:g}-{100 * hi:g} % of a breast model's surface"
    )
    remedy = (
        "narrow the rule (a smaller distance, or a plane through the chest wall)"
        if share > hi
        else "widen the rule (a larger distance) or check its position"
    )
    raise SurfaceRuleError(f"{what}: {remedy}")


def select_facets(
    x: np.ndarray,
    faces: np.ndarray,
    rules: dict[Boundary, BoundaryRule],
    units: str,
    face_groups: np.ndarray | None = None,
    group_names: dict[str, int] | None = None,
    posterior: np.ndarray = POSTERIOR,
    orientation_key: str = "mesh.file.orientation",
) -> dict[Boundary, np.ndarray]:
    """The boundary facets each rule selects, as a mask per boundary.

    Args:
        x: points (N, 3), metres.
        faces: boundary triangles (m, 3), facing outwards.
        rules: a rule per boundary (``rib`` required).
        units: the model's units (surface rules read their file in them).
        face_groups: group integer of each face from the file (-1: none), or None.
        group_names: physical name -> group integer of the file.
        posterior: the patient's posterior in the points' axes (for a ``posterior`` rule).
        orientation_key: the config key that says where posterior is (for the message).

    Raises:
        NoRibFacetsError: if the rib rule selects nothing, with how near the closest facet was.
        SurfaceRuleError: if another rule selects nothing or names an unknown group.
    """
    group_names = group_names or {}
    selected: dict[Boundary, np.ndarray] = {}
    for boundary, rule in rules.items():
        error = NoRibFacetsError if boundary == Boundary.RIB else SurfaceRuleError
        if rule.group is not None:
            if face_groups is None or np.all(face_groups < 0):
                raise SurfaceRuleError(
                    f"the {boundary.label} rule selects {rule.describe()}, but the input has no "
                    "boundary groups (only a volume mesh with tagged triangles, e.g. gmsh "
                    "physical groups, has them); use a plane or surface rule"
                )
            if isinstance(rule.group, str) and not rule.group.lstrip("-").isdigit():
                if rule.group not in group_names:
                    raise SurfaceRuleError(
                        f"the {boundary.label} rule names group {rule.group!r}, but the file's "
                        f"groups are: {', '.join(sorted(group_names)) or 'unnamed'}"
                    )
                value = group_names[rule.group]
            else:
                value = int(rule.group)
            mask = face_groups == value
            if not mask.any():
                present = sorted(set(face_groups[face_groups >= 0].tolist()))
                raise error(
                    f"no boundary facets found for the {boundary.label} surface: {rule.describe()} "
                    f"(tag {value}) holds no boundary triangles; tags on the boundary: {present}"
                )
        elif rule.posterior is not None:
            mask = _posterior_facets(x, faces, rule, posterior)
            if not mask.any():
                raise error(
                    f"no boundary facets found for the {boundary.label} surface: none is "
                    f"{rule.describe()}; widen the angle or the band, or check "
                    f"{orientation_key}"
                )
        else:
            distance = _facet_distance(x, faces, rule, units)
            mask = distance <= rule.distance
            if not mask.any():
                nearest = float(np.min(distance))
                how_far = (
                    f"the closest facet lies {1e3 * nearest:.3g} mm from it"
                    if math.isfinite(nearest)
                    else f"no facet comes within {1e3 * 10 * rule.distance:.3g} mm of it"
                )
                raise error(
                    f"no boundary facets found for the {boundary.label} surface: none lies "
                    f"{rule.describe()}; {how_far}. Check the rule's position, the distance and "
                    f"mesh.file.units ({units})"
                )
        selected[boundary] = mask
    return selected


def check_selection(
    x: np.ndarray,
    faces: np.ndarray,
    selected: dict[Boundary, np.ndarray],
    rules: dict[Boundary, BoundaryRule],
) -> None:
    """Refuse a facet that two rules select, and a rib that is too much or too little.

    Raises:
        SurfaceRuleError: naming the rules, or the rib's share of the boundary.
    """
    names = list(selected)
    for i, first in enumerate(names):
        for second in names[i + 1 :]:
            both = int(np.sum(selected[first] & selected[second]))
            if both:
                raise SurfaceRuleError(
                    f"{both} boundary facet(s) match both the {first.label} and the "
                    f"{second.label} rules; make the rules exclusive (e.g. a smaller distance)"
                )
    _check_rib_share(x, faces, selected[Boundary.RIB], rules[Boundary.RIB])


def selection_summary(
    x: np.ndarray, faces: np.ndarray, selected: dict[Boundary, np.ndarray]
) -> dict[str, dict[str, float]]:
    """What each rule selects: facets, area (m²) and share of the boundary's area."""
    areas = triangle_areas(x, faces)
    total = float(areas.sum())
    return {
        b.label: {"facets": int(mask.sum()), "area_m2": float(areas[mask].sum()),
                  "share": float(areas[mask].sum() / total)}
        for b, mask in selected.items()
    }


def name_facets(
    faces: np.ndarray, selected: dict[Boundary, np.ndarray]
) -> dict[Boundary, np.ndarray]:
    """Boundary -> its faces (every boundary present); the faces no rule selects are skin."""
    taken = np.zeros(len(faces), dtype=bool)
    for mask in selected.values():
        taken |= mask
    out = {
        b: faces[selected[b]] if b in selected else np.empty((0, 3), dtype=np.int64)
        for b in Boundary
    }
    out[Boundary.SKIN] = np.concatenate([out[Boundary.SKIN], faces[~taken]])
    return out


def face_groups(mesh: InputMesh, faces: np.ndarray) -> np.ndarray | None:
    """Group of each boundary face, looked up from the file's tagged triangles."""
    if len(mesh.triangles) == 0 or np.all(mesh.triangle_groups < 0):
        return None
    keys = {
        tuple(t): g
        for t, g in zip(
            np.sort(mesh.triangles, axis=1).tolist(), mesh.triangle_groups.tolist(), strict=True
        )
    }
    return np.array(
        [keys.get(tuple(f), -1) for f in np.sort(faces, axis=1).tolist()], dtype=np.int64
    )
