"""Frictionless penalty contact of the breast's skin with the chest wall below the fold.

When a soft mound rolls over the inframammary fold (lying on the side; supine, tilted
laterally), its skin comes to rest on the skin of the chest below it. Without contact
the model lets it pass into the chest, or its solve stalls where the skin over the
fold creases on the way (README "Contact with the chest"). Here the chest's skin is
a rigid obstacle at its reference position, the outer surface of the tissue layer
over the rib cage (an elliptic cylinder along z for the parametric breast), and the
skin points that start at least ``clearance`` from it may touch it (the skin that
starts on it is the chest's own). The penalty energy

    Π_c = ∫_skin κ/2 ⟨−g(X + u)⟩² [g(X) ≥ clearance] dA,   κ = stiffness · C1,

with g the signed distance to the obstacle (negative inside), adds to the total
potential: it is zero while no point penetrates, so the frictionless contact
constraint g ≥ 0 holds to a penetration of about (contact pressure)/κ. The contact
zone is defined point by point on the reference skin, so it is the same surface
on every mesh.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import ufl

from fem.exceptions import InvalidParameterError

log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True)
class EllipticCylinder:
    """A rigid obstacle ((x − cx)/A)² + ((y − cy)/B)² = 1, along z; the body lies outside.

    Attributes:
        centre: (cx, cy) in metres.
        semi_axes: (A, B) in metres.
    """

    centre: tuple[float, float]
    semi_axes: tuple[float, float]

    def __post_init__(self) -> None:
        if len(self.centre) != 2 or len(self.semi_axes) != 2:
            raise InvalidParameterError("an elliptic cylinder needs a 2-d centre and 2 semi-axes")
        if not all(math.isfinite(c) for c in self.centre):
            raise InvalidParameterError(f"obstacle centre must be finite, got {self.centre}")
        if not all(math.isfinite(s) and s > 0 for s in self.semi_axes):
            raise InvalidParameterError(
                f"obstacle semi-axes must be positive, got {self.semi_axes}"
            )

    def _gap(self, x0: Any, x1: Any, sqrt: Callable[[Any], Any]) -> Any:
        (cx, cy), (A, B) = self.centre, self.semi_axes
        u, v = (x0 - cx) / A, (x1 - cy) / B
        # first-order signed distance: f / |∇f|, exact on the surface, accurate near it
        return (u * u + v * v - 1.0) / sqrt((2.0 * u / A) ** 2 + (2.0 * v / B) ** 2)

    def as_mapping(self) -> dict[str, Any]:
        """The config entry of this obstacle."""
        return {
            "elliptic_cylinder": {"centre": list(self.centre), "semi_axes": list(self.semi_axes)}
        }

    def gap(self, x: ufl.core.expr.Expr) -> ufl.core.expr.Expr:
        """Signed distance of the (current) point ``x`` (a UFL 3-vector): < 0 inside."""
        return self._gap(x[0], x[1], ufl.sqrt)

    def gap_values(self, x: np.ndarray) -> np.ndarray:
        """The same for points (N×3) as a numpy array."""
        return self._gap(x[:, 0], x[:, 1], np.sqrt)


@dataclass(frozen=True, slots=True)
class Plane:
    """A rigid plane through ``point`` with unit ``normal`` pointing towards the body.

    Attributes:
        point: a point of the plane (metres).
        normal: its normal (normalised on construction), towards the side the body is on.
    """

    point: tuple[float, float, float]
    normal: tuple[float, float, float]

    def __post_init__(self) -> None:
        if len(self.point) != 3 or not all(math.isfinite(c) for c in self.point):
            raise InvalidParameterError(f"plane point must be 3 finite numbers, got {self.point}")
        n = np.asarray(self.normal, dtype=float)
        if n.shape != (3,) or not np.all(np.isfinite(n)) or np.linalg.norm(n) == 0:
            raise InvalidParameterError(
                f"plane normal must be a non-zero 3-vector, got {self.normal}"
            )
        object.__setattr__(self, "point", tuple(float(c) for c in self.point))
        object.__setattr__(self, "normal", tuple(float(c) for c in n / np.linalg.norm(n)))

    def as_mapping(self) -> dict[str, Any]:
        """The config entry of this obstacle."""
        return {"plane": {"point": list(self.point), "normal": list(self.normal)}}

    def gap(self, x: ufl.core.expr.Expr) -> ufl.core.expr.Expr:
        """Signed distance of the (current) point ``x`` (a UFL 3-vector): < 0 behind the plane."""
        return sum((x[i] - self.point[i]) * self.normal[i] for i in range(3))

    def gap_values(self, x: np.ndarray) -> np.ndarray:
        """The same for points (N×3) as a numpy array."""
        return (x - np.asarray(self.point)) @ np.asarray(self.normal)


Obstacle = EllipticCylinder | Plane


@dataclass(frozen=True, slots=True)
class Contact:
    """Penalty contact of the skin with a rigid obstacle.

    Attributes:
        obstacle: the rigid obstacle (for the parametric breast, :func:`chest_obstacle`).
        stiffness: penalty κ as a multiple of C1, per metre: κ = stiffness · C1 (Pa/m).
            The default 1e4 /m lets a contact pressure of 1 kPa into the obstacle by
            0.1 mm at C1 = 1 kPa (pressure/κ scales as the sag, 1/C1).
        clearance: skin points that start at least this far from the obstacle (metres)
            can touch it; the skin that starts nearer is the chest's own, continuing into
            the obstacle, not a body that comes to rest on it.
    """

    obstacle: Obstacle
    stiffness: float = 1.0e4
    clearance: float = 0.002

    def __post_init__(self) -> None:
        if not (math.isfinite(self.stiffness) and self.stiffness > 0):
            raise InvalidParameterError(f"contact stiffness must be positive, got {self.stiffness}")
        if not (math.isfinite(self.clearance) and self.clearance >= 0):
            raise InvalidParameterError(f"contact clearance must be >= 0, got {self.clearance}")
        if not isinstance(self.obstacle, (EllipticCylinder, Plane)):
            raise InvalidParameterError(f"unknown contact obstacle {self.obstacle!r}")

    def as_mapping(self) -> dict[str, Any]:
        """The ``fe.contact`` config entry of this contact (JSON-friendly)."""
        return {
            "obstacle": self.obstacle.as_mapping(),
            "stiffness": self.stiffness,
            "clearance": self.clearance,
        }

    def pressure(
        self, x: ufl.core.expr.Expr, u: ufl.core.expr.Expr, C1: ufl.core.expr.Expr
    ) -> ufl.core.expr.Expr:
        """Contact pressure κ ⟨−g(x + u)⟩ (Pa) at reference skin point ``x`` (0 off the zone)."""
        return self.stiffness * C1 * self._penetration(x, u) * self.zone(x)

    def energy(
        self, x: ufl.core.expr.Expr, u: ufl.core.expr.Expr, C1: ufl.core.expr.Expr
    ) -> ufl.core.expr.Expr:
        """Penalty energy density per reference area at reference skin point ``x``."""
        return 0.5 * self.stiffness * C1 * self._penetration(x, u) ** 2 * self.zone(x)

    def _penetration(self, x: ufl.core.expr.Expr, u: ufl.core.expr.Expr) -> ufl.core.expr.Expr:
        """⟨−g(x + u)⟩: how far the displaced point lies inside the obstacle (touching counts)."""
        g = self.obstacle.gap(x + u)
        return ufl.conditional(ufl.le(g, 0.0), -g, 0.0)

    def zone(self, x: ufl.core.expr.Expr) -> ufl.core.expr.Expr:
        """1 where the reference skin point ``x`` may touch the obstacle, else 0."""
        return ufl.conditional(ufl.ge(self.obstacle.gap(x), self.clearance), 1.0, 0.0)


def chest_obstacle(geometry: Any) -> EllipticCylinder:
    """The outer surface of the parametric breast's tissue layer (its chest's skin)."""
    t = geometry.layer_thickness
    return EllipticCylinder(
        centre=(geometry.rib_depth, 0.0),
        semi_axes=(geometry.rib_depth + t, geometry.rib_half_width + t),
    )


def obstacle_from_mapping(spec: Any, geometry: dict[str, Any] | None = None) -> Obstacle:
    """The obstacle of a config entry.

    Args:
        spec: ``"chest"`` (the parametric breast's chest skin below the fold),
            ``{"plane": {"point": [...], "normal": [...]}}`` or
            ``{"elliptic_cylinder": {"centre": [cx, cy], "semi_axes": [A, B]}}``.
        geometry: the ``mesh.geometry`` mapping of a parametric breast (needed by ``chest``);
            None when the mesh is imported.
    """
    from meshes.parametric import BreastGeometry

    if spec == "chest":
        if geometry is None:
            raise InvalidParameterError(
                "fe.contact.obstacle 'chest' is the parametric breast's chest skin; an imported "
                "mesh (mesh.source: file) needs an explicit obstacle, e.g. "
                "{plane: {point: [x, y, z], normal: [nx, ny, nz]}}, or no fe.contact"
            )
        return chest_obstacle(BreastGeometry.from_mapping(geometry))
    if isinstance(spec, dict) and len(spec) == 1:
        ((kind, values),) = spec.items()
        try:
            if kind == "plane":
                return Plane(tuple(values["point"]), tuple(values["normal"]))
            if kind == "elliptic_cylinder":
                return EllipticCylinder(tuple(values["centre"]), tuple(values["semi_axes"]))
        except (KeyError, TypeError) as err:
            raise InvalidParameterError(
                f"fe.contact.obstacle.{kind} is incomplete: {err}"
            ) from None
    raise InvalidParameterError(
        "fe.contact.obstacle must be 'chest', {plane: ...} or {elliptic_cylinder: ...}; "
        f"got {spec!r}"
    )


def contact_from_mapping(values: dict[str, Any], geometry: dict[str, Any] | None = None) -> Contact:
    """A :class:`Contact` from the ``fe.contact`` config mapping, naming unknown keys."""
    known = {"obstacle", "stiffness", "clearance"}
    unknown = sorted(set(values) - known)
    if unknown:
        raise InvalidParameterError(f"unknown fe.contact parameter(s): {', '.join(unknown)}")
    options = {k: float(values[k]) for k in ("stiffness", "clearance") if k in values}
    return Contact(obstacle_from_mapping(values.get("obstacle", "chest"), geometry), **options)


def resolve_obstacle(fe: dict[str, Any], mesh: dict[str, Any]) -> dict[str, Any]:
    """``fe`` with a ``chest`` obstacle written out as its elliptic cylinder.

    The solve jobs then need no mesh section to build their contact, and their
    parameters change exactly when the obstacle does. Without contact ``fe`` is
    returned unchanged.

    The default obstacle (``fe.contact`` without an ``obstacle`` key) is the parametric
    breast's chest. An imported mesh has none: there contact is off, said in one line, so that
    switching ``mesh.source`` to ``file`` changes only the ``mesh:`` section. An obstacle
    named ``chest`` explicitly on an imported mesh is refused.
    """
    contact = fe.get("contact")
    if contact is None or contact.get("obstacle", "chest") != "chest":
        return fe
    imported = mesh.get("source", "parametric") != "parametric"
    if imported and "obstacle" not in contact:
        _say_once(
            "fe.contact: off for the imported mesh (its default obstacle is the parametric "
            "breast's chest); name an obstacle, e.g. {plane: {point: [...], normal: [...]}}, "
            "to turn it on"
        )
        return {key: value for key, value in fe.items() if key != "contact"}
    geometry = mesh.get("geometry", {}) if not imported else None
    obstacle = obstacle_from_mapping("chest", geometry)
    return {**fe, "contact": {**contact, "obstacle": obstacle.as_mapping()}}


_SAID: set[str] = set()


def _say_once(message: str) -> None:
    """Log a warning once per process (the config is resolved more than once per parse)."""
    if message not in _SAID:
        _SAID.add(message)
        log.warning(message)
