"""Frictionless self-contact of the skin: the body's own surface may touch but not pass itself.

Where a large, soft mound rolls over the inframammary fold, its underside comes to rest on
the skin below the fold, and the two sides of a closing crease press together. Both are the
same skin. Without self-contact the model lets them pass through each other (the cases
``self_overlap`` flags), or its Newton solve stalls at the crease.

The skin is a triangulation of the displacement's nodes on it: a facet of degree k is split
into k² flat triangles through its nodes (four for P2).
Every skin node is a slave, every triangle a master (two-pass node-to-surface). A node and a
triangle form a pair when, in the *deformed* configuration,

* the node's projection falls on the triangle, or within ``edge_taper`` (in barycentric
  coordinates) past its edge,
* the node lies within ``band`` of the triangle's plane,
* their normals face each other (n_node · n_triangle ≤ −``facing``): a smooth skin never
  contacts itself, since neighbouring facets face the same way, and
* the node is not a corner of the triangle (the rest of a smooth neighbourhood is left out by
  the facing test; FEBio's contact potential excludes neighbours likewise);

a node's contact is shared between its candidate triangles by a partition of unity that
fades out past their edges and as their normals turn away from facing, so that the force is
continuous as the node slides across a seam or off the surface's edge. The pairs are looked
for on the deformed skin at every residual evaluation, among candidates from a k-d tree
(scipy) over the triangles' centroids that serve until the skin has moved or turned by more
than they allow for. A pair whose signed distance g from the triangle's plane is below
``offset`` (the node near, or behind, the master's outer side) adds the penalty energy

    Π_sc = Σ_pairs κ/2 w_s ω ⟨offset − g⟩²,      κ = stiffness · C1,

with w_s the node's tributary reference area and ω the pair's share. Its gradient (the shares
held fixed) enters the residual and its exact Hessian in g (:mod:`fem.point_triangle`,
including the master normal's rotation) the tangent, which stays symmetric, so the solver
keeps MUMPS's LDLᵀ; what the shares' own derivatives would add vanishes on a flat master and
is small on a smooth one. At equilibrium facing skin stands (contact pressure)/κ closer than
``offset``: at the defaults it never passes itself below 5 kPa of contact pressure at
C1 = 1 kPa (κ as the chest contact's, :mod:`fem.contact`).

Serial only: the pairs couple nodes that no cell shares, which a distributed mesh would hold
on different processes.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import sparse
from scipy.spatial import cKDTree

from fem.exceptions import InvalidParameterError
from fem.point_triangle import barycentric, signed_distance_derivatives
from fem.rest_pairs import RestPairs, rest_treatment, surface_normals
from fem.skin_surface import SkinSurface, triangle_radii

log = logging.getLogger(__name__)

__all__ = ["AT_REST", "RestPairs", "SelfContact", "SelfContactAssembler", "SelfContactState",
           "self_contact_from_mapping"]

AT_REST = ("by_side", "exclude", "rest_gap", "none")
"""What :class:`SelfContact` does with the pairs that face each other within reach at rest."""


@dataclass(frozen=True, slots=True)
class SelfContact:
    """Settings of the skin's self-contact (``fe.self_contact``).

    Attributes:
        stiffness: penalty κ as a multiple of C1, per metre (κ = stiffness · C1, Pa/m), as
            :class:`fem.contact.Contact`'s: the penetration scales like the sag, 1/C1.
        offset: the distance (m) at which facing skin starts to push back: the penalty acts
            on ⟨offset − g⟩, so the skin stays intersection-free while the contact pressure
            is below κ · offset (at the defaults, 5 kPa at C1 = 1 kPa); the gap it leaves
            at lighter contact is at most this.
        band: how far (m) a node may lie behind a facing triangle and still be pushed out of
            it; beyond it the triangle is another part of the body. Larger than any
            penetration an iterate reaches, smaller than the tissue's thickness at the fold.
        facing: the cosine by which a node's and a triangle's normals must face each other
            (0.5: more than 120° apart).
        edge_taper: over how much of a triangle's barycentric coordinate, past its edge, a
            node's share in it fades out (so that the force is continuous across seams and
            at the surface's edge).
        at_rest: what becomes of the pairs that already face each other within reach in the
            reference configuration (:data:`AT_REST`): the two sides of a thin region or of a
            sharp rim, whose nodes lie behind each other's skin, and the sides of a crease the
            surface was made with, nearer than ``offset``. ``by_side`` (the default) leaves out
            those behind and measures those in front from their rest gap; ``exclude`` leaves
            out both; ``rest_gap`` measures both from their rest gap. Each way, nothing
            touches at rest. ``none`` treats them as any other pair: they push from the start,
            as two bodies pressed together in the reference configuration do.
    """

    stiffness: float = 1.0e4
    offset: float = 5.0e-4
    band: float = 0.01
    facing: float = 0.5
    edge_taper: float = 0.1
    at_rest: str = "by_side"

    def __post_init__(self) -> None:
        checks = {
            "stiffness": (self.stiffness, 0.0, math.inf),
            "offset": (self.offset, 0.0, 0.01),
            "band": (self.band, 0.0, 1.0),
            "facing": (self.facing, -1.0, 1.0),
            "edge_taper": (self.edge_taper, 0.0, 1.0),
        }
        if self.at_rest not in AT_REST:
            raise InvalidParameterError(
                f"fe.self_contact.at_rest must be one of {', '.join(AT_REST)}, "
                f"got {self.at_rest!r}"
            )
        for name, (value, low, high) in checks.items():
            closed = name == "offset"  # no offset is allowed: contact at touching
            if not (isinstance(value, (int, float)) and math.isfinite(value)
                    and (low <= value if closed else low < value) and value <= high):
                bracket = "[" if closed else "("
                raise InvalidParameterError(
                    f"fe.self_contact.{name} must be a number in {bracket}{low:g}, {high:g}], "
                    f"got {value!r}"
                )

    def as_mapping(self) -> dict[str, float | str]:
        """The ``fe.self_contact`` config entry (JSON-friendly)."""
        return {"stiffness": self.stiffness, "offset": self.offset, "band": self.band,
                "facing": self.facing, "edge_taper": self.edge_taper, "at_rest": self.at_rest}


def self_contact_from_mapping(values: dict[str, Any]) -> SelfContact:
    """A :class:`SelfContact` from the ``fe.self_contact`` mapping, naming unknown keys."""
    if not isinstance(values, dict):
        raise InvalidParameterError(f"fe.self_contact must be a mapping, got {values!r}")
    known = set(SelfContact.__slots__)
    unknown = sorted(set(values) - known)
    if unknown:
        raise InvalidParameterError(
            f"unknown fe.self_contact parameter(s): {', '.join(unknown)}; "
            f"known: {', '.join(sorted(known))}"
        )
    numbers = {k: v for k, v in values.items() if k != "at_rest"}
    try:
        numbers = {k: float(v) for k, v in numbers.items()}
    except (TypeError, ValueError):
        raise InvalidParameterError(f"fe.self_contact values must be numbers, got {values}") \
            from None
    if "at_rest" in values:
        numbers["at_rest"] = values["at_rest"]
    return SelfContact(**numbers)


#: How much farther apart (m) than a touching pair the search's pairs may be, and how much
#: less than ``facing`` their normals may face each other: what the kept candidate list
#: allows the skin to move and turn before it is searched again.
_MARGIN = 0.004
_SLACK = 0.3
#: A skin triangle stretched past this many times its reference size takes no part.
_STRETCH = 2.0


def _largest_turn(now: np.ndarray, before: np.ndarray) -> float:
    """The largest change |n − n₀| of unit normals (rows)."""
    return float(np.sqrt(np.max(np.sum((now - before) ** 2, axis=1), initial=0.0)))


def _smoothstep(s: np.ndarray) -> np.ndarray:
    """0 below 0, 1 above 1, and 3s² − 2s³ (C¹) between."""
    s = np.clip(s, 0.0, 1.0)
    return s * s * (3.0 - 2.0 * s)


@dataclass
class SelfContactState:
    """The active pairs at one configuration and what they add.

    Attributes:
        slaves, masters: node and triangle of each pair in contact (g below the offset).
        share: the pair's part of its node's contact (a partition of unity over the
            triangles the node projects onto, fading out past their edges).
        gap: each pair's signed distance less the offset (m, negative).
        grad, hess: its first and second derivatives with respect to the pair's 12
            coordinates (:func:`fem.point_triangle.signed_distance_derivatives`).
        offset: the distance from the triangle's plane (m) at which each pair starts to push:
            ``settings.offset``, or a pair's rest gap (:meth:`SelfContactAssembler.pairs`).
    """

    slaves: np.ndarray
    masters: np.ndarray
    share: np.ndarray
    gap: np.ndarray
    grad: np.ndarray
    hess: np.ndarray
    offset: np.ndarray


@dataclass
class SelfContactAssembler:
    """Adds the self-contact penalty to a problem's residual and tangent.

    Args:
        settings: the self-contact settings.
        surface: the skin as triangles of displacement nodes.
    """

    settings: SelfContact
    surface: SkinSurface
    #: Accumulated seconds of search, kernel and assembly (the per-case cost).
    seconds: float = 0.0
    evaluations: int = 0
    _last: SelfContactState | None = field(default=None, repr=False)
    _last_x: np.ndarray | None = field(default=None, repr=False)
    _verlet: dict[str, Any] | None = field(default=None, repr=False)
    #: Full k-d tree searches, and their seconds (part of :attr:`seconds`).
    searches: int = 0
    search_seconds: float = 0.0
    _held_codes: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64),
                                    repr=False)
    _held_shares: np.ndarray = field(default_factory=lambda: np.zeros(0), repr=False)

    def __post_init__(self) -> None:
        self._radii = self.surface.radii
        self._rest_normal, self._rest_node_normal = surface_normals(self.surface.X,
                                                             self.surface.triangles)
        # triangles in classes of reference size, up to 1.5, 3 and more times the median, so
        # that the many small triangles of the fold are searched with their own short reach
        median = float(np.median(self._radii)) if len(self._radii) else 0.0
        size_class = np.searchsorted([1.5 * median, 3.0 * median], self._radii)
        self._size_classes = []
        for k in range(3):
            members = np.flatnonzero(size_class == k)
            if len(members):
                self._size_classes.append((members, float(self._radii[members].max())))
        #: The skin's pairs at rest, as found and as left by the treatment (none).
        self.rest = self._find_rest_pairs()

    def positions(self, state: np.ndarray) -> np.ndarray:
        """Deformed node positions for the state's local array."""
        return self.surface.X + state[self.surface.dofs]

    def pairs(self, state: np.ndarray) -> SelfContactState:
        """Search the deformed skin for nodes behind a facing triangle; the active pairs."""
        s, surf = self.settings, self.surface
        x = self.positions(state)
        if self._last is not None and np.array_equal(x, self._last_x):
            return self._last  # the tangent at the residual's state
        start = time.perf_counter()
        tri = surf.triangles
        node, triangle, plane_gap, beta, facing = self._facing(x)
        # the pairs that faced each other within reach at rest: left out, or measured from
        # their rest gap (settings.at_rest)
        kept, offset = self._rest_treatment(node, triangle)
        node, triangle, plane_gap, beta, facing, offset = (
            a[kept] for a in (node, triangle, plane_gap, beta, facing, offset))
        # A node's candidates share it by a partition of unity over the triangles its
        # projection falls on, fading out over edge_taper past a triangle's edge and as the
        # normals turn from facing each other to the facing limit: the force is continuous
        # as the node slides across a seam or off the edge of the surface, and as the skin
        # turns.
        share = _smoothstep(1.0 + beta / s.edge_taper) \
            * _smoothstep((facing - s.facing) / (0.5 * (1.0 - s.facing)))
        total = np.bincount(node, share, minlength=len(x))
        share = share / np.maximum(total[node], 1.0)
        # the kernel for the active pairs only (at rest, a pair measured from its rest gap has
        # plane_gap equal to it, bit for bit: the same arithmetic on the same coordinates)
        active = plane_gap < offset
        node, triangle, offset = node[active], triangle[active], offset[active]
        share = self._hold(node * len(tri) + triangle, share[active])
        g, grad, hess = signed_distance_derivatives(
            x[node], *(x[tri[triangle, k]] for k in range(3))
        )
        result = SelfContactState(node, triangle, share, g - offset, grad, hess, offset)
        self.seconds += time.perf_counter() - start
        self.evaluations += 1
        self._last, self._last_x = result, x
        return result

    def _facing(self, x: np.ndarray) -> tuple[np.ndarray, ...]:
        """The node–triangle pairs of the skin at ``x`` that may touch, and how.

        A node within ``band`` of a facing triangle's plane, its projection on the triangle or
        within ``edge_taper`` past its edge. Returns ``(node, triangle, gap, beta, facing)``:
        gap the node's signed distance from the triangle's plane, beta the projection's
        smallest barycentric coordinate, facing −n_node · n_triangle.
        """
        s, surf = self.settings, self.surface
        tri = surf.triangles
        corners = x[tri]  # (t, 3, 3)
        normal, node_normal = surface_normals(x, tri)
        # a triangle stretched past _STRETCH times its reference size belongs to an iterate
        # no breast takes: it takes no part, and the search's reach stays the reference's
        usable = triangle_radii(corners) <= _STRETCH * self._radii
        node, triangle = self._candidates(x, node_normal, normal)
        facing = -np.einsum("ij,ij->i", node_normal[node], normal[triangle])
        keep = (facing > s.facing) & usable[triangle]
        node, triangle, facing = node[keep], triangle[keep], facing[keep]
        gap = np.einsum("ij,ij->i", normal[triangle], x[node] - corners[triangle, 0])
        near = np.abs(gap) <= s.band  # the cheap test first
        node, triangle, gap, facing = node[near], triangle[near], gap[near], facing[near]
        beta = barycentric(x[node], *(corners[triangle, k] for k in range(3))).min(axis=1)
        near = beta > -s.edge_taper
        return node[near], triangle[near], gap[near], beta[near], facing[near]

    def _rest_treatment(self, node: np.ndarray,
                        triangle: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Which pairs take part, and the offset each is measured from (m).

        :func:`fem.rest_pairs.rest_treatment` of the reference skin: the pairs at rest left
        out, or measured from their rest gap (``settings.at_rest``).
        """
        s, surf = self.settings, self.surface
        return rest_treatment(s.at_rest, s.offset, s.band, surf.X, surf.triangles,
                              self._rest_normal, self._rest_node_normal, node, triangle)

    def _find_rest_pairs(self) -> RestPairs:
        """The pairs that would push at rest (the reference skin), and those left (none).

        Those left are what :meth:`pairs` finds at zero displacement after
        :meth:`_rest_treatment`; the search's counters start afresh afterwards.
        """
        s, surf = self.settings, self.surface
        X = surf.X
        node, _, g0, _, _ = self._facing(X)
        pushing = g0 < s.offset
        node, g0 = node[pushing], g0[pushing]
        left = self.pairs(np.zeros(int(surf.dofs.max()) + 1 if surf.dofs.size else 0))
        self._last = self._last_x = self._verlet = None
        self.begin_solve()
        self.reset_counters()
        return RestPairs.found(s.at_rest, s.offset, X, node, g0, int(len(left.slaves)))

    def _candidates(self, x: np.ndarray, node_normal: np.ndarray,
                    normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Node–triangle pairs that may touch: a k-d tree search, kept while it is valid.

        The search (scipy's cKDTree over the triangles' centroids) takes the pairs within a
        margin more than a touching pair can be apart, whose normals face each other to
        within a slack, less the triangles of which the node is a corner. The list serves
        the following evaluations (Newton's iterates, the line search's trials) while no
        node has moved by half the margin and no normal has turned by half the slack; then
        it is redone. Its reach is fixed by the reference triangles' size (a triangle
        stretched past :data:`_STRETCH` times it takes no part), so that no iterate, however
        crumpled, makes the list grow past what the reference skin's density gives.
        """
        s, surf, cache = self.settings, self.surface, self._verlet
        if cache is not None:
            moved = np.sqrt(np.max(np.sum((x - cache["x"]) ** 2, axis=1), initial=0.0))
            turned = max(_largest_turn(node_normal, cache["node_normal"]),
                          _largest_turn(normal, cache["normal"]))
            if moved <= 0.5 * _MARGIN and turned <= 0.5 * _SLACK:
                return cache["node"], cache["triangle"]
        start = time.perf_counter()
        nodes = cKDTree(x)
        centroids = x[surf.triangles].mean(axis=1)
        node, triangle = [], []
        for members, size in self._size_classes:  # each class of triangles with its own reach
            reach = s.band + (1.0 + 2.0 * s.edge_taper) * _STRETCH * size + _MARGIN
            found = nodes.sparse_distance_matrix(cKDTree(centroids[members]), reach,
                                                 output_type="ndarray")
            node.append(found["i"].astype(np.int64))
            triangle.append(members[found["j"]])
        node, triangle = np.concatenate(node), np.concatenate(triangle)
        facing = -np.einsum("ij,ij->i", node_normal[node], normal[triangle])
        keep = facing > s.facing - _SLACK
        node, triangle = node[keep], triangle[keep]
        code = node * len(surf.triangles) + triangle
        pos = np.minimum(np.searchsorted(surf.excluded, code), len(surf.excluded) - 1)
        keep = surf.excluded[pos] != code if len(surf.excluded) else np.ones(len(code), bool)
        self._verlet = {"x": x, "node_normal": node_normal, "normal": normal,
                        "node": node[keep], "triangle": triangle[keep]}
        self.searches += 1
        self.search_seconds += time.perf_counter() - start
        return self._verlet["node"], self._verlet["triangle"]

    def reset_counters(self) -> None:
        """Start the cost figures afresh (a new case)."""
        self.seconds = self.search_seconds = 0.0
        self.evaluations = self.searches = 0

    def begin_solve(self) -> None:
        """Forget the held shares: a new Newton solve (load increment) starts."""
        self._last = self._last_x = None
        self._held_codes = np.zeros(0, dtype=np.int64)
        self._held_shares = np.zeros(0)

    def _hold(self, codes: np.ndarray, shares: np.ndarray) -> np.ndarray:
        """The shares of these pairs as first seen in the running solve.

        A share depends on the skin's normals around the node, whose derivatives the tangent
        leaves out; held fixed through a Newton solve, the residual is the derivative of an
        energy whose Hessian the tangent is, and Newton converges quadratically once the
        pairs settle. Each load increment starts afresh, so the shares follow the load path.
        """
        pos = np.minimum(np.searchsorted(self._held_codes, codes), len(self._held_codes) - 1)
        known = (self._held_codes[pos] == codes) if len(self._held_codes) else \
            np.zeros(len(codes), dtype=bool)
        shares = shares.copy()
        shares[known] = self._held_shares[pos[known]]
        if not np.all(known):
            merged = np.concatenate([self._held_codes, codes[~known]])
            order = np.argsort(merged, kind="stable")
            self._held_codes = merged[order]
            self._held_shares = np.concatenate([self._held_shares, shares[~known]])[order]
        return shares

    def _pair_dofs(self, state: SelfContactState) -> np.ndarray:
        """The 12 state entries of each pair: slave's, then the triangle's three nodes'."""
        surf = self.surface
        nodes = np.column_stack([state.slaves, surf.triangles[state.masters]])  # (p, 4)
        return surf.dofs[nodes].reshape(len(nodes), 12)

    def _scale(self, state: SelfContactState, C1: float) -> np.ndarray:
        """κ w_s for each pair."""
        return self.settings.stiffness * C1 * self.surface.weights[state.slaves] * state.share

    def add_residual(self, b: np.ndarray, state_array: np.ndarray, C1: float) -> None:
        """Add ∂Π_sc/∂u at the state to the residual's local array ``b``."""
        state = self.pairs(state_array)
        if not len(state.slaves):
            return
        start = time.perf_counter()
        force = (self._scale(state, C1) * state.gap)[:, None] * state.grad  # κ w g ∇g
        b += np.bincount(self._pair_dofs(state).ravel(), force.ravel(), minlength=len(b))
        self.seconds += time.perf_counter() - start

    def add_tangent(self, A: Any, state_array: np.ndarray, C1: float, fixed: np.ndarray) -> None:
        """Add ∂²Π_sc/∂u² at the state to the matrix ``A`` before its final assembly.

        Clamped rows and columns (``fixed``: a boolean mask of the state's local entries) are
        left out, so that they stay the identity's.
        """
        from petsc4py import PETSc

        state = self.pairs(state_array)
        if not len(state.slaves):
            return
        start = time.perf_counter()
        scale = self._scale(state, C1)
        blocks = scale[:, None, None] * (
            state.grad[:, :, None] * state.grad[:, None, :] + state.gap[:, None, None] * state.hess
        )
        dofs = self._pair_dofs(state)
        free = ~fixed[dofs]
        keep = free[:, :, None] & free[:, None, :]
        rows = np.broadcast_to(dofs[:, :, None], blocks.shape)[keep]
        cols = np.broadcast_to(dofs[:, None, :], blocks.shape)[keep]
        n = A.getLocalSize()[0]
        csr = sparse.coo_matrix((blocks[keep], (rows, cols)), shape=(n, n)).tocsr()
        csr.sum_duplicates()
        counts = np.diff(csr.indptr)
        touched = np.flatnonzero(counts)  # only the rows the pairs reach
        indptr = np.concatenate([[0], np.cumsum(counts[touched])])
        A.assemblyBegin(PETSc.Mat.AssemblyType.FLUSH)  # the diagonal was inserted before
        A.assemblyEnd(PETSc.Mat.AssemblyType.FLUSH)
        A.setValuesIJV(indptr.astype(PETSc.IntType), csr.indices.astype(PETSc.IntType),
                       csr.data, addv=PETSc.InsertMode.ADD_VALUES,
                       rowmap=touched.astype(PETSc.IntType))
        self.seconds += time.perf_counter() - start

    def status(self, state_array: np.ndarray, C1: float) -> dict[str, Any]:
        """The contact at the state and its cost since :meth:`reset_counters`.

        ``force_N``: the pairs' normal forces summed; ``area_cm2``: the skin in contact, both
        sides; ``max_penetration_mm``: how far the deepest node lies behind the skin it faces
        (zero while the offset holds); ``max_pressure_Pa`` and ``max_pressure_at_m``, the
        reference position of the node that carries it (None without contact); ``pairs``;
        ``rest_pairs``, those found at rest and treated by ``settings.at_rest``;
        ``skin_nodes``; ``seconds``: all self-contact work (searches, kernel, assembly) over
        ``evaluations`` states, of which ``searches`` k-d tree searches took ``search_seconds``.
        """
        state = self.pairs(state_array)
        pressure = -self.settings.stiffness * C1 * state.gap
        weights = self.surface.weights[state.slaves] * state.share
        # behind the triangle's plane, or deeper behind it than at rest
        penetration = np.minimum(state.offset, 0.0) - (state.gap + state.offset)
        peak = self.surface.X[state.slaves[np.argmax(pressure)]].tolist() if len(pressure) \
            else None
        return {
            "force_N": float(np.sum(pressure * weights)),
            "area_cm2": 1e4 * float(np.sum(weights)),
            "max_penetration_mm": 1e3 * float(max(penetration.max(initial=0.0), 0.0)),
            "max_pressure_Pa": float(pressure.max(initial=0.0)),
            "max_pressure_at_m": peak,
            "pairs": int(len(state.slaves)),
            "rest_pairs": self.rest.pairs,
            "skin_nodes": int(len(self.surface.X)),
            "seconds": self.seconds,
            "evaluations": self.evaluations,
            "searches": self.searches,
            "search_seconds": self.search_seconds,
        }
