"""A parametric breast on the chest wall, built with gmsh's OpenCASCADE kernel.

Coordinates follow the paper (its Fig. 4): ``x`` runs anterior to posterior
(gravity along +x is the supine position, Φ = 0°; along −x prone, Φ = 180°),
``y`` medial to lateral and ``z`` caudal to cranial. Lengths are in metres.

The rib cage is an elliptic cylinder along ``z`` whose most anterior point is
the origin::

    ((x - a) / a)**2 + (y / b)**2 = 1,   a = rib_depth, b = rib_half_width.

A point on it is ``R(ψ) = (a - a cos ψ, b sin ψ)``; ψ = 0 is the sternum and ψ
grows laterally. The soft tissue is a layer over that surface (the region
between it and the confocal-like ellipse with semi-axes ``a + t, b + t``), cut
by the sternal plane (ψ = 0), the axilla plane (ψ = ``axilla_angle``) and the
caudal and cranial planes ``z = z_caudal, z_cranial``, plus a breast mound: an
ellipsoid standing on the layer along the local outward normal at
(``mound_angle``, ``mound_z``). With ``mound_offset > 0`` the ellipsoid's
centre lies outside the skin layer, so the mound is wider than its base: the
pendulous shape of a breast imaged prone.

Where the mound meets the layer the two surfaces would form a sharp re-entrant
crease (the inframammary fold); with ``mound_offset > 0`` the tissue's interior
angle there is about 290°. Linear and nonlinear elasticity are singular at such
an edge (stresses grow without bound, displacement gradients like r^(-1/2)), so
the displacement error near the fold converges slowly under refinement and
pollutes the mound's hinge-like motion. Real skin is smooth there: the crease is
rounded by a fillet of radius ``fold_radius`` (1 cm by default; 0 keeps the crease).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields
from typing import Any

import numpy as np

from meshes.exceptions import GeometryError, reject_unknown

__all__ = [
    "BreastGeometry",
    "GeometryError",
    "add_elliptic_cylinder",
    "add_mound_ellipsoid",
    "build_occ_model",
    "curve_points",
    "fold_curves",
    "rib_cage_surface",
    "round_fold",
]

ANATOMICAL_BREAST_VOLUME_ML = (300.0, 1500.0)
"""Plausible range of the mound (breast) volume, millilitres."""
ANATOMICAL_MAX_PROJECTION_M = 0.15
"""Largest plausible projection of the breast from the chest wall, metres."""


@dataclass(frozen=True, slots=True)
class BreastGeometry:
    """Shape parameters of the parametric breast (metres, degrees).

    Attributes:
        rib_depth: semi-axis ``a`` of the rib-cage ellipse along x.
        rib_half_width: semi-axis ``b`` of the rib-cage ellipse along y.
        layer_thickness: soft-tissue thickness ``t`` over the rib cage.
        axilla_angle: angular extent ψ of the patch, sternum to axilla.
        z_caudal: caudal cut plane.
        z_cranial: cranial cut plane.
        mound_angle: angular position ψ of the mound's axis on the chest wall.
        mound_z: cranio-caudal position of the mound's axis.
        mound_tilt: extra lateral tilt of the mound axis from the local normal.
        mound_length: semi-axis of the mound ellipsoid along its axis.
        mound_radius_lateral: semi-axis across the axis, in the transverse plane.
        mound_radius_cranial: semi-axis across the axis, along z.
        mound_offset: distance of the ellipsoid centre outward from the skin
            layer along the axis (0 gives a dome, > 0 a pendulous mound).
        fold_radius: radius of the fillet that rounds the crease where the mound
            meets the skin layer (0 leaves the crease sharp).
    """

    rib_depth: float = 0.10
    rib_half_width: float = 0.15
    layer_thickness: float = 0.02
    axilla_angle: float = 80.0
    z_caudal: float = -0.10
    z_cranial: float = 0.12
    mound_angle: float = 46.0
    mound_z: float = 0.0
    mound_tilt: float = 0.0
    mound_length: float = 0.075
    mound_radius_lateral: float = 0.065
    mound_radius_cranial: float = 0.06
    mound_offset: float = 0.03
    fold_radius: float = 0.010

    def __post_init__(self) -> None:
        positive = (
            "rib_depth",
            "rib_half_width",
            "layer_thickness",
            "mound_length",
            "mound_radius_lateral",
            "mound_radius_cranial",
        )
        for name in positive:
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise GeometryError(f"geometry.{name} must be a positive length, got {value!r}")
        for f in fields(self):
            if not math.isfinite(getattr(self, f.name)):
                raise GeometryError(f"geometry.{f.name} must be finite")
        if not 10.0 <= self.axilla_angle <= 150.0:
            raise GeometryError(
                f"geometry.axilla_angle must lie in [10, 150] degrees, got {self.axilla_angle}"
            )
        if not self.z_caudal < self.mound_z < self.z_cranial:
            raise GeometryError("geometry.mound_z must lie strictly between z_caudal and z_cranial")
        if not 0.0 < self.mound_angle < self.axilla_angle:
            raise GeometryError(
                "geometry.mound_angle must lie strictly between 0 (sternum) and axilla_angle"
            )
        if self.mound_offset < 0 or self.mound_offset >= self.mound_length:
            raise GeometryError("geometry.mound_offset must lie in [0, mound_length)")
        if self.fold_radius < 0 or self.fold_radius >= 0.5 * min(self.mound_base_radii()):
            raise GeometryError(
                "geometry.fold_radius must lie in [0, half the mound's base radius "
                f"{0.5 * min(self.mound_base_radii()):.4g} m), got {self.fold_radius!r}"
            )
        if self.layer_thickness >= min(self.rib_depth, self.rib_half_width):
            raise GeometryError("geometry.layer_thickness must be smaller than the rib semi-axes")
        # The mound must stand clear of the four cut planes, or it would be sliced.
        base = self.mound_base_radii()
        margin_z = min(self.mound_z - self.z_caudal, self.z_cranial - self.mound_z)
        if max(self.mound_radius_cranial, base[1]) >= margin_z:
            raise GeometryError(
                "the mound reaches the cranial or caudal cut: reduce mound_radius_cranial or "
                "move mound_z / the cut planes"
            )
        arc_to_sternum = self._arc_length(0.0, self.mound_angle)
        arc_to_axilla = self._arc_length(self.mound_angle, self.axilla_angle)
        if max(self.mound_radius_lateral, base[0]) >= min(arc_to_sternum, arc_to_axilla):
            raise GeometryError(
                "the mound reaches the sternal or axilla cut: reduce mound_radius_lateral or "
                "move mound_angle / axilla_angle"
            )

    @classmethod
    def from_mapping(cls, values: dict[str, Any]) -> BreastGeometry:
        """Build from a config mapping, rejecting unknown keys by name."""
        reject_unknown(values, {f.name for f in fields(cls)}, "geometry parameter(s)")
        return cls(**{k: float(v) for k, v in values.items()})

    def as_dict(self) -> dict[str, float]:
        """Parameters as a plain mapping (for JSON metadata)."""
        return asdict(self)

    # -- analytic surfaces used to build the model and to classify its faces ----------------
    @property
    def axis_centre(self) -> np.ndarray:
        """Centre of the rib-cage ellipse in the transverse (x, y) plane."""
        return np.array([self.rib_depth, 0.0])

    def ellipse_point(self, psi_deg: float, offset: float = 0.0) -> np.ndarray:
        """Point ``(x, y)`` at angle ψ on the rib ellipse grown by ``offset``."""
        psi = math.radians(psi_deg)
        a, b = self.rib_depth + offset, self.rib_half_width + offset
        return np.array([self.rib_depth - a * math.cos(psi), b * math.sin(psi)])

    def ellipse_normal(self, psi_deg: float, offset: float = 0.0) -> np.ndarray:
        """Outward unit normal ``(nx, ny)`` of the grown ellipse at angle ψ."""
        psi = math.radians(psi_deg)
        a, b = self.rib_depth + offset, self.rib_half_width + offset
        n = np.array([-math.cos(psi) / a, math.sin(psi) / b])
        return n / np.linalg.norm(n)

    def radial_direction(self, psi_deg: float) -> np.ndarray:
        """Unit direction from the axis to the rib point at ψ (defines the cut planes)."""
        d = self.ellipse_point(psi_deg) - self.axis_centre
        return d / np.linalg.norm(d)

    def rib_level_set(self, x: np.ndarray) -> np.ndarray:
        """Approximate signed distance of points (N×3) to the rib surface (negative inside)."""
        a, b = self.rib_depth, self.rib_half_width
        u = (x[:, 0] - a) / a
        v = x[:, 1] / b
        f = u**2 + v**2 - 1.0
        grad = np.sqrt((2 * u / a) ** 2 + (2 * v / b) ** 2)
        return f / np.maximum(grad, 1e-30)

    def axilla_plane_distance(self, x: np.ndarray) -> np.ndarray:
        """Signed distance of points (N×3) to the axilla cut plane."""
        d = self.radial_direction(self.axilla_angle)
        normal = np.array([-d[1], d[0]])  # in-plane normal of the radial plane
        rel = x[:, :2] - self.axis_centre
        return rel @ normal

    def mound_frame(self) -> tuple[np.ndarray, np.ndarray]:
        """Base point on the skin layer and unit axis (3-vectors) of the mound."""
        p = self.ellipse_point(self.mound_angle, self.layer_thickness)
        n = self.ellipse_normal(self.mound_angle, self.layer_thickness)
        tilt = math.radians(self.mound_tilt)
        # Positive tilt rotates the axis laterally (towards +y) in the transverse plane.
        c, s = math.cos(tilt), math.sin(tilt)
        rot = np.array([[c, s], [-s, c]])
        n = rot @ n
        return np.array([p[0], p[1], self.mound_z]), np.array([n[0], n[1], 0.0])

    def mound_base_radii(self) -> tuple[float, float]:
        """Radii of the ellipsoid's cross-section where it meets the skin layer."""
        shrink = math.sqrt(max(0.0, 1.0 - (self.mound_offset / self.mound_length) ** 2))
        return self.mound_radius_lateral * shrink, self.mound_radius_cranial * shrink

    @property
    def mound_projection(self) -> float:
        """How far the mound tip stands out from the skin layer along its axis."""
        return self.mound_offset + self.mound_length

    @property
    def mound_tip(self) -> np.ndarray:
        """The point of the mound farthest out along its axis (the nipple)."""
        base, axis = self.mound_frame()
        return base + self.mound_projection * axis

    def rib_distance(self, x: np.ndarray) -> np.ndarray:
        """Distance of points (N×3) from the rib-cage cylinder (exact, to round-off).

        Unlike :meth:`rib_level_set` this is a true distance far from the surface,
        which is what a projection from the chest wall needs. The nearest point of
        the ellipse is found by sampling, then polished by Newton's method on
        d/dψ |R(ψ) − p|² = 0.
        """
        a, b = self.rib_depth, self.rib_half_width
        p = np.atleast_2d(np.asarray(x, dtype=float))[:, :2] - np.array([a, 0.0])
        ring = np.linspace(-math.pi, math.pi, 721)
        # (cos, sin) parametrisation about the centre: R(ψ) = (-a cos ψ, b sin ψ)
        d2 = (p[:, None, 0] + a * np.cos(ring)) ** 2 + (p[:, None, 1] - b * np.sin(ring)) ** 2
        psi = ring[np.argmin(d2, axis=1)]
        for _ in range(8):
            c, s = np.cos(psi), np.sin(psi)
            rx, ry = -a * c - p[:, 0], b * s - p[:, 1]
            g = rx * (a * s) + ry * (b * c)
            h = (a * s) ** 2 + (b * c) ** 2 + rx * (a * c) + ry * (-b * s)
            psi = psi - g / np.where(np.abs(h) > 1e-30, h, 1e-30)
        rx, ry = -a * np.cos(psi) - p[:, 0], b * np.sin(psi) - p[:, 1]
        return np.hypot(rx, ry)

    @property
    def projection_from_chest_wall(self) -> float:
        """Distance of the mound tip from the rib-cage (chest-wall) surface, metres."""
        return float(self.rib_distance(self.mound_tip[None, :])[0])

    def _arc_length(self, psi0: float, psi1: float, n: int = 64) -> float:
        psis = np.linspace(psi0, psi1, n)
        pts = np.array([self.ellipse_point(p, self.layer_thickness) for p in psis])
        return float(np.sum(np.linalg.norm(np.diff(pts, axis=0), axis=1)))


def add_elliptic_cylinder(
    model: Any, geometry: BreastGeometry, offset: float, z_from: float, height: float
) -> int:
    """Add the rib-cage ellipse grown by ``offset``, extruded along z; return the volume tag.

    The ellipse has semi-axes a + offset, b + offset; it is extruded from ``z_from`` over
    ``height``.
    """
    occ, g = model.occ, geometry
    a, b = g.rib_depth + offset, g.rib_half_width + offset
    # gmsh's addEllipse needs r1 >= r2; orient the major axis explicitly.
    if b >= a:
        curve = occ.addEllipse(g.rib_depth, 0.0, z_from, b, a, zAxis=[0, 0, 1], xAxis=[0, 1, 0])
    else:
        curve = occ.addEllipse(g.rib_depth, 0.0, z_from, a, b, zAxis=[0, 0, 1], xAxis=[1, 0, 0])
    disk = occ.addPlaneSurface([occ.addCurveLoop([curve])])
    return next(tag for dim, tag in occ.extrude([(2, disk)], 0, 0, height) if dim == 3)


def add_mound_ellipsoid(model: Any, geometry: BreastGeometry, inset: float = 0.0) -> int:
    """Add the mound ellipsoid, aligned with the local normal at the mound base; returns its tag.

    ``inset`` > 0 shrinks its three semi-axes by that much about the same centre (the body
    under a skin layer of that thickness: :func:`build_occ_model`).
    """
    occ, g = model.occ, geometry
    base, axis = g.mound_frame()
    sphere = occ.addSphere(0.0, 0.0, 0.0, 1.0)
    occ.dilate(
        [(3, sphere)], 0, 0, 0, g.mound_length - inset, g.mound_radius_lateral - inset,
        g.mound_radius_cranial - inset,
    )
    # Rotate the ellipsoid's x axis onto the mound axis (rotation about z).
    occ.rotate([(3, sphere)], 0, 0, 0, 0, 0, 1, math.atan2(axis[1], axis[0]))
    occ.translate([(3, sphere)], *(base + g.mound_offset * axis))
    return sphere


def curve_points(model: Any, curve: int, n: int) -> np.ndarray:
    """``n`` points of a (synchronised) model curve, evenly spaced in its parameter, (n, 3)."""
    lo, hi = model.getParametrizationBounds(1, abs(curve))
    return np.reshape(model.getValue(1, abs(curve), list(np.linspace(lo[0], hi[0], n))), (-1, 3))


def fold_curves(model: Any, geometry: BreastGeometry, volume: int,
                inset: float = 0.0) -> list[int]:
    """The crease of the inframammary fold: curves of ``volume`` on mound and skin layer.

    The curves of the (synchronised) volume that lie on both the mound ellipsoid and the
    skin layer's outer cylinder (each shrunk by ``inset``: :func:`build_occ_model`).
    """
    g = geometry
    base, axis = g.mound_frame()
    centre = base + g.mound_offset * axis
    across = np.array([-axis[1], axis[0], 0.0])
    offset = g.layer_thickness - inset
    a, b = g.rib_depth + offset, g.rib_half_width + offset
    length, lateral, cranial = (g.mound_length - inset, g.mound_radius_lateral - inset,
                                g.mound_radius_cranial - inset)
    tol = 1e-6
    found = set()
    for _, face in model.getBoundary([(3, volume)], oriented=False):
        for _, curve in model.getBoundary([(2, face)], oriented=False):
            x = curve_points(model, curve, 9)
            rel = x - centre
            q = (rel @ axis / length) ** 2 + (rel @ across / lateral) ** 2
            q += (rel[:, 2] / cranial) ** 2
            layer = ((x[:, 0] - g.rib_depth) / a) ** 2 + (x[:, 1] / b) ** 2
            if np.all(np.abs(q - 1) < tol) and np.all(np.abs(layer - 1) < tol):
                found.add(abs(curve))
    return sorted(found)


def round_fold(model: Any, geometry: BreastGeometry, volume: int, inset: float = 0.0) -> int:
    """Fillet the crease between the mound and the skin layer; return the new volume's tag.

    The fillet radius is ``geometry.fold_radius`` (nothing to do at 0), plus ``inset`` for
    the body shrunk by it (:func:`build_occ_model`): the fold's fillet offset into the body.

    Raises:
        GeometryError: if the crease is not found or OpenCASCADE cannot round it.
    """
    if geometry.fold_radius == 0:
        return volume
    model.occ.synchronize()
    curves = fold_curves(model, geometry, volume, inset)
    if not curves:
        raise GeometryError("the crease between the mound and the skin layer was not found")
    try:
        out = model.occ.fillet([volume], curves, [geometry.fold_radius + inset],
                               removeVolume=True)
    except Exception as err:  # gmsh raises a bare Exception with OpenCASCADE's message
        raise GeometryError(
            f"geometry.fold_radius = {geometry.fold_radius} m cannot round the mound's base: {err}"
        ) from err
    volumes = [tag for dim, tag in out if dim == 3]
    if len(volumes) != 1:
        raise GeometryError(f"rounding the fold produced {len(volumes)} volumes, expected one")
    return volumes[0]


def build_occ_model(model: Any, geometry: BreastGeometry, inset: float = 0.0) -> int:
    """Add the breast volume to a gmsh model with the OpenCASCADE kernel.

    Args:
        model: ``gmsh.model`` (initialised, with a current model).
        geometry: shape parameters.
        inset: > 0: the body under a skin layer of this thickness (m), bounded by the same
            rib and cut planes: the layer's outer cylinder and the mound's semi-axes shrunk
            by it (the mound's centre kept), the fold's fillet radius grown by it. Each
            surface is then the skin's offset into the body, to about 2 % of ``inset`` on
            the default mound (an ellipsoid's offset is not an ellipsoid).
            :mod:`meshes.skin_layer` meshes the layer over it.

    Returns:
        The tag of the single resulting volume.
    """
    occ = model.occ
    g = geometry
    if not 0.0 <= inset < 0.5 * min(g.layer_thickness, g.mound_length - g.mound_offset):
        raise GeometryError(
            f"a skin layer {inset!r} m thick does not fit the breast: it must be under half "
            "of geometry.layer_thickness and of mound_length - mound_offset")
    z0, z1 = g.z_caudal, g.z_cranial
    pad = 0.05 * (z1 - z0)
    inner = add_elliptic_cylinder(model, g, 0.0, z0 - pad, (z1 - z0) + 2 * pad)
    outer = add_elliptic_cylinder(model, g, g.layer_thickness - inset, z0 - pad,
                                  (z1 - z0) + 2 * pad)

    # Wedge between the sternal (ψ = 0) and axilla (ψ = axilla_angle) planes through the axis.
    far = 4.0 * (g.rib_depth + g.rib_half_width + g.layer_thickness + g.mound_projection)
    centre = g.axis_centre
    psis = np.linspace(0.0, g.axilla_angle, 7)
    ring = [centre + far * g.radial_direction(p) for p in psis]
    pts = [occ.addPoint(centre[0], centre[1], z0)]
    pts += [occ.addPoint(p[0], p[1], z0) for p in ring]
    lines = [occ.addLine(pts[i], pts[(i + 1) % len(pts)]) for i in range(len(pts))]
    wedge_face = occ.addPlaneSurface([occ.addCurveLoop(lines)])
    wedge = next(tag for dim, tag in occ.extrude([(2, wedge_face)], 0, 0, z1 - z0) if dim == 3)

    body, _ = occ.fuse([(3, outer)], [(3, add_mound_ellipsoid(model, g, inset))])
    body = [(3, round_fold(model, g, body[0][1], inset))] if len(body) == 1 else body
    body, _ = occ.intersect(body, [(3, wedge)])
    body, _ = occ.cut(body, [(3, inner)])
    occ.synchronize()
    volumes = [tag for dim, tag in body if dim == 3]
    if len(volumes) != 1:
        raise GeometryError(f"the breast geometry produced {len(volumes)} volumes, expected one")
    return volumes[0]


def rib_cage_surface(
    geometry: BreastGeometry, margin: float = 0.02, spacing: float = 0.004
) -> tuple[np.ndarray, np.ndarray]:
    """Triangulate the rib-cage cylinder over the tissue patch (and ``margin`` beyond it).

    The surface a user would give as the rib rule of an imported model of this
    geometry ("facets within a distance of this surface"); it is also how the
    import is tested against the parametric mesh.

    Args:
        geometry: shape parameters.
        margin: extension beyond the sternal, axilla, cranial and caudal cuts, metres.
        spacing: target edge length of the triangulation, metres (its chordal error
            is about ``spacing**2 / (8 * radius of curvature)``).

    Returns:
        ``(points (N, 3), triangles (M, 3))``.
    """
    g = geometry
    arc = g._arc_length(0.0, g.axilla_angle)  # on the skin ellipse: an upper bound
    dpsi = (margin / max(arc, 1e-9)) * g.axilla_angle
    n_psi = max(8, int(math.ceil((arc + 2 * margin) / spacing)))
    n_z = max(4, int(math.ceil((g.z_cranial - g.z_caudal + 2 * margin) / spacing)))
    psis = np.radians(np.linspace(-dpsi, g.axilla_angle + dpsi, n_psi + 1))
    zs = np.linspace(g.z_caudal - margin, g.z_cranial + margin, n_z + 1)
    ring = np.stack([g.rib_depth - g.rib_depth * np.cos(psis), g.rib_half_width * np.sin(psis)], 1)
    points = np.array([[p[0], p[1], z] for z in zs for p in ring])
    idx = np.arange(len(points)).reshape(len(zs), len(ring))
    a, b = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel()
    c, d = idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    triangles = np.concatenate([np.stack([a, b, d], 1), np.stack([a, d, c], 1)])
    return points, triangles
