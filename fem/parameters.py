"""Validated, frozen parameter objects of a gravity-loading case and its discretisation."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, fields
from typing import Any

import numpy as np

from fem.contact import Contact, contact_from_mapping, resolve_obstacle
from fem.exceptions import InvalidParameterError
from fem.materials.tissues import SkinLayer, Tissues, skin_from_mapping, tissues_from_mapping
from fem.self_contact import SelfContact, self_contact_from_mapping
from meshes.tags import Boundary

STANDARD_GRAVITY = 9.81  # m/s², the paper's |g|
TISSUE_DENSITY = 900.0  # kg/m³, the paper's breast-tissue density

ANGLE_UNITS = {"deg": math.pi / 180.0, "rad": 1.0}


def _finite(name: str, value: Any) -> float:
    try:
        value = float(value)
    except (TypeError, ValueError):
        raise InvalidParameterError(f"{name} must be a number, got {value!r}") from None
    if not math.isfinite(value):
        raise InvalidParameterError(f"{name} must be finite, got {value!r}")
    return value


@dataclass(frozen=True, slots=True)
class Material:
    """Neo-Hookean tissue.

    Attributes:
        C1: neo-Hookean parameter in Pa (the paper's C1 is quoted in kPa).
        density: reference density in kg/m³.
    """

    C1: float
    density: float = TISSUE_DENSITY

    def __post_init__(self) -> None:
        if _finite("C1", self.C1) <= 0:
            raise InvalidParameterError(f"C1 must be positive, got {self.C1!r} Pa")
        if _finite("density", self.density) <= 0:
            raise InvalidParameterError(f"density must be positive, got {self.density!r}")


@dataclass(frozen=True, slots=True)
class Gravity:
    """Gravity direction in the paper's spherical angles (its Eq. 1).

    g = |g| [cos Φ, sin Φ cos θ, sin Φ sin θ]; Φ = 0° is supine (g along +x),
    Φ = 180° prone.

    Attributes:
        phi: elevation angle Φ.
        theta: azimuth angle θ (the paper fixes θ = 0).
        unit: unit of both angles, ``"deg"`` or ``"rad"``.
        magnitude: |g| in m/s².
    """

    phi: float
    theta: float = 0.0
    unit: str = "deg"
    magnitude: float = STANDARD_GRAVITY

    def __post_init__(self) -> None:
        if self.unit not in ANGLE_UNITS:
            raise InvalidParameterError(
                f"unknown angle unit {self.unit!r}; expected one of {sorted(ANGLE_UNITS)}"
            )
        _finite("phi", self.phi)
        _finite("theta", self.theta)
        if _finite("gravity magnitude", self.magnitude) < 0:
            raise InvalidParameterError("gravity magnitude must be non-negative")

    @property
    def vector(self) -> np.ndarray:
        """Gravitational acceleration (m/s²) as a 3-vector."""
        s = ANGLE_UNITS[self.unit]
        phi, theta = self.phi * s, self.theta * s
        return self.magnitude * np.array(
            [math.cos(phi), math.sin(phi) * math.cos(theta), math.sin(phi) * math.sin(theta)]
        )


ELEMENTS = ("taylor-hood", "p1-penalty")


@dataclass(frozen=True, slots=True)
class Discretisation:
    """Finite-element choice.

    Attributes:
        element: ``"taylor-hood"`` (mixed P_k / P_(k-1), exactly incompressible in
            the weak sense) or ``"p1-penalty"`` (P1 displacement, penalty bulk modulus;
            a cheap, locking-prone baseline).
        degree: displacement degree k of Taylor–Hood (2: P2/P1, 3: P3/P2).
        quadrature_degree: quadrature degree of the nonlinear forms (0: automatic,
            2k for Taylor–Hood and 2 for P1).
        bulk_ratio: κ / C1 of the penalty baseline.
        isochoric: write W with Ī1 = J^(-2/3) I1 (see :mod:`fem.materials.neo_hookean`).
    """

    element: str = "taylor-hood"
    degree: int = 2
    quadrature_degree: int = 0
    bulk_ratio: float = 1000.0
    isochoric: bool = True

    def __post_init__(self) -> None:
        if self.element not in ELEMENTS:
            raise InvalidParameterError(
                f"unknown element {self.element!r}; expected one of {ELEMENTS}"
            )
        if self.element == "taylor-hood" and self.degree not in (2, 3):
            raise InvalidParameterError(f"Taylor-Hood degree must be 2 or 3, got {self.degree}")
        if self.quadrature_degree < 0:
            raise InvalidParameterError("quadrature_degree must be >= 0")
        if _finite("bulk_ratio", self.bulk_ratio) <= 0:
            raise InvalidParameterError("bulk_ratio must be positive")

    @property
    def quadrature(self) -> int:
        """Quadrature degree actually used."""
        if self.quadrature_degree:
            return self.quadrature_degree
        return 2 * self.degree if self.element == "taylor-hood" else 2


@dataclass(frozen=True, slots=True)
class FixedBoundaries:
    """Which named surfaces are clamped, and in which displacement components.

    Attributes:
        components: boundary name -> tuple of fixed components (0: x, 1: y, 2: z).
            The paper fixes all three components on the rib surface only.
    """

    components: dict[str, tuple[int, ...]] = field(default_factory=lambda: {"rib": (0, 1, 2)})

    def __post_init__(self) -> None:
        if not self.components:
            raise InvalidParameterError("at least one boundary must be fixed")
        for name, comps in self.components.items():
            Boundary.from_label(name)
            if not comps or any(c not in (0, 1, 2) for c in comps) or len(set(comps)) != len(comps):
                raise InvalidParameterError(
                    f"fixed components of {name!r} must be distinct values of 0, 1, 2; got {comps}"
                )

    @classmethod
    def from_mapping(cls, values: dict[str, Any]) -> FixedBoundaries:
        """From a config mapping ``{name: "all" | "none" | [x, y, z letters or ints]}``."""
        letters = {"x": 0, "y": 1, "z": 2}
        out: dict[str, tuple[int, ...]] = {}
        for name, spec in values.items():
            if spec in (None, "none", False, []):
                continue
            if spec in ("all", True):
                comps: tuple[int, ...] = (0, 1, 2)
            else:
                try:
                    comps = tuple(letters[c] if isinstance(c, str) else int(c) for c in spec)
                except (KeyError, TypeError, ValueError):
                    raise InvalidParameterError(
                        f"fixed.{name} must be 'all', 'none' or a list of x/y/z, got {spec!r}"
                    ) from None
            out[name] = comps
        return cls(out)

    def items(self) -> list[tuple[Boundary, tuple[int, ...]]]:
        """(boundary, components) pairs, in boundary order."""
        pairs = [(Boundary.from_label(n), c) for n, c in self.components.items()]
        return sorted(pairs, key=lambda pc: int(pc[0]))

    def fully_fixed(self) -> list[Boundary]:
        """Boundaries on which every component is fixed (the 'boundary' material points)."""
        return [b for b, comps in self.items() if len(comps) == 3]


def check_stall_window(value: Any, name: str = "stall_window") -> int:
    """A stall window (:attr:`Loading.stall_window`): a non-negative integer, not a bool.

    Raises:
        InvalidParameterError: naming ``name`` and the value, for anything else.
    """
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        raise InvalidParameterError(f"{name} must be a non-negative integer, got {value!r}")
    return value


@dataclass(frozen=True, slots=True)
class Loading:
    """Adaptive incremental gravity loading.

    Attributes:
        initial_step: first load increment as a fraction of full gravity.
        min_step: smallest increment before the case is declared failed; where halving
            passes it, it is itself tried once (:func:`fem.loading.solve_incrementally`).
            No case of the sweep on the default breast converged with an increment below
            1/8 of the load; a case that needs 1/64 is at its limit point, and cutting on to
            1/1024 only gained it up to 1.5 % of the load at 9-15 min a case (README
            "Stability").
        max_steps: cap on accepted plus rejected increments.
        growth: factor applied to the increment after an easy step.
        easy_iterations: a step converging in at most this many Newton
            iterations counts as easy.
        cutback: factor applied to the increment after a failed step.
        extrapolate: predict each step's initial guess from the previous two (three at the
            start of a path through known states, :func:`fem.loading.solve_incrementally`).
        fixed_steps: if > 0, disable adaptivity and use this many equal steps
            (the baseline the adaptive scheme is compared against).
        rescue: when the step has been cut below ``min_step``, load once more from
            rest with Newton's :data:`fem.options.RESCUE_OPTIONS` (line search ``l2``, 60
            iterations) before declaring the case failed; a failed case keeps whichever
            pass got further. A case that converges without it is solved exactly as
            before.
        stall_window: the last resort gives an attempt up once this many Newton iterations
            sit on a plateau of the residual (``fem.convergence.stalled``) instead of running on
            to its 60th iteration there; 0 turns the test off. The last resort's failing
            attempts on the default mesh sat on such plateaus for up to 50 iterations.
        rescue_min_step: smallest increment of the last resort before the case is declared
            failed (its own floor, in place of ``min_step``). The last resort is there to pass
            the fold in large steps from rest; where its steps shrink below this, it creeps
            along the path that the first pass already failed on (``docs/solver.md``).
        check_branch: accept the last resort's answer only where it continues the load path:
            walked back down the load to where the first pass stopped, it must meet that
            pass's state (``fem.loading.BRANCH_TOLERANCE``). From rest in large steps the last
            resort can reach another equilibrium (a soft mound rolled over its fold another
            way), and the case's answer would then depend on how it was solved; such a case
            fails with the first pass's state, as if the last resort had not converged.
        rescue_after_neighbours: try the last resort also where the load path started from
            known states (a chain's stiffer neighbours, :mod:`fem.chain`), not only from rest.
            Off by default: the path from the neighbours is the case's own load path, and on
            the default sweep none of the last resort's answers after it continued that path
            (``check_branch``), while each cost minutes; a case solved alone starts from rest
            and keeps its last resort.
    """

    initial_step: float = 1.0
    min_step: float = 1.0 / 64
    max_steps: int = 60
    growth: float = 2.0
    easy_iterations: int = 4
    cutback: float = 0.5
    extrapolate: bool = True
    fixed_steps: int = 0
    rescue: bool = True
    stall_window: int = 8
    rescue_min_step: float = 1.0 / 16
    check_branch: bool = True
    rescue_after_neighbours: bool = False

    def __post_init__(self) -> None:
        if not 0 < _finite("initial_step", self.initial_step) <= 1:
            raise InvalidParameterError("loading.initial_step must lie in (0, 1]")
        if not 0 < _finite("min_step", self.min_step) <= self.initial_step:
            raise InvalidParameterError("loading.min_step must lie in (0, initial_step]")
        if self.max_steps < 1:
            raise InvalidParameterError("loading.max_steps must be >= 1")
        if _finite("growth", self.growth) < 1:
            raise InvalidParameterError("loading.growth must be >= 1")
        if not 0 < _finite("cutback", self.cutback) < 1:
            raise InvalidParameterError("loading.cutback must lie in (0, 1)")
        if self.fixed_steps < 0:
            raise InvalidParameterError("loading.fixed_steps must be >= 0")
        check_stall_window(self.stall_window, "loading.stall_window")
        if not 0 < _finite("rescue_min_step", self.rescue_min_step) <= 1:
            raise InvalidParameterError("loading.rescue_min_step must lie in (0, 1]")

    @classmethod
    def from_mapping(cls, values: dict[str, Any]) -> Loading:
        """Build from a config mapping, naming unknown keys."""
        return _from_mapping(cls, values, "loading")


def _from_mapping(cls: type, values: dict[str, Any], section: str) -> Any:
    known = {f.name for f in fields(cls)}
    unknown = sorted(set(values) - known)
    if unknown:
        raise InvalidParameterError(f"unknown {section} parameter(s): {', '.join(unknown)}")
    return cls(**values)


def discretisation_from_mapping(values: dict[str, Any]) -> Discretisation:
    """Build a :class:`Discretisation` from a config mapping, naming unknown keys."""
    return _from_mapping(Discretisation, values, "discretisation")


def as_dict(obj: Any) -> dict[str, Any]:
    """Dataclass as a JSON-friendly mapping."""
    return asdict(obj)


@dataclass(frozen=True, slots=True)
class SolverSettings:
    """Everything about *how* a case is solved (the case itself is a :class:`Case`).

    Attributes:
        discretisation: element choice.
        fixed: clamped boundaries.
        loading: load-stepping parameters.
        petsc_options: overrides of :func:`fem.solver.default_parameters`.
        density: tissue density (kg/m³).
        gravity: |g| (m/s²).
        solver: linear-solver preset of :func:`fem.solver.default_parameters`
            (``direct``, ``direct-lu`` or ``iterative``).
        contact: penalty contact of the skin with a rigid obstacle (None: no contact).
        self_contact: the skin's contact with itself (None: it may pass through itself).
        tissues: each tissue's stiffness over the fat's (``material.tissues``), for meshes
            whose cells carry tissue tags.
        skin: the skin as a membrane on the skin boundary (``material.skin``; None: none),
            where the mesh's cells carry no skin tag.
    """

    discretisation: Discretisation = Discretisation()
    fixed: FixedBoundaries = FixedBoundaries()
    loading: Loading = Loading()
    petsc_options: dict[str, Any] = field(default_factory=dict)
    density: float = TISSUE_DENSITY
    gravity: float = STANDARD_GRAVITY
    solver: str = "direct"
    contact: Contact | None = None
    self_contact: SelfContact | None = None
    tissues: Tissues = Tissues()
    skin: SkinLayer | None = None

    def __post_init__(self) -> None:
        from fem.options import solver_options  # options imports exceptions only

        solver_options(self.solver, self.petsc_options)  # names an unknown preset or line search

    @classmethod
    def from_config(cls, config: dict[str, Any]) -> SolverSettings:
        """Build from the workflow config (sections ``material``, ``fe``, ``mesh``).

        ``fe.contact``, when present, turns contact on; its ``chest`` obstacle (the
        default) is the parametric breast's of ``mesh.geometry``. ``fe.self_contact``, when
        present (and not null), turns the skin's self-contact on.
        """
        fe = config.get("fe", {})
        material = config.get("material", {})
        contact = resolve_obstacle(fe, config.get("mesh", {})).get("contact")
        return cls(
            discretisation=discretisation_from_mapping(fe.get("discretisation", {})),
            fixed=FixedBoundaries.from_mapping(config.get("mesh", {}).get("fixed", {"rib": "all"})),
            loading=Loading.from_mapping(fe.get("loading", {})),
            petsc_options=dict(fe.get("petsc_options", {}) or {}),
            density=_finite("density", material.get("density", TISSUE_DENSITY)),
            gravity=_finite("gravity", material.get("gravity", STANDARD_GRAVITY)),
            solver=str(fe.get("solver", "direct")),
            contact=None if contact is None else contact_from_mapping(contact),
            self_contact=None if fe.get("self_contact") is None
            else self_contact_from_mapping(fe["self_contact"]),
            tissues=tissues_from_mapping(material.get("tissues")),
            skin=skin_from_mapping(material.get("skin")),
        )

    def describe(self, defaults: dict[str, Any] | None = None) -> dict[str, Any]:
        """JSON-friendly description for case metadata.

        Args:
            defaults: the solver's default PETSc options, merged under the overrides.
        """
        return {
            "solver": self.solver,
            "discretisation": as_dict(self.discretisation),
            "fixed": {b.label: list(c) for b, c in self.fixed.items()},
            "loading": as_dict(self.loading),
            "petsc_options": {**(defaults or {}), **self.petsc_options},
            "density": self.density,
            "gravity": self.gravity,
            "contact": None if self.contact is None else self.contact.as_mapping(),
            "self_contact": None if self.self_contact is None else self.self_contact.as_mapping(),
            "tissues": self.tissues.describe(),
            "skin": None if self.skin is None else self.skin.describe(self.tissues),
        }
