"""Hyperparameters of the Siamese MLP surrogate and its training (one validated object)."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields, replace
from typing import Any

from fem.splits import SPLIT_KINDS
from surrogate.exceptions import SurrogateConfigError
from surrogate.structures import STRUCTURES as STRUCTURE_ENTRIES

ACTIVATIONS = ("tanh", "relu", "gelu", "silu")
BOUNDARY_MODES = ("network", "shared", "exact")
LR_SCHEDULES = ("constant", "cosine", "exponential")
C1_ENCODINGS = ("linear", "log", "inverse")
OUTPUT_SCALINGS = ("none", "compliance")
OUTPUT_FORMS = ("vector", "gravity_linear")
STRUCTURES = tuple(STRUCTURE_ENTRIES)
"""The structures' names, from their registry (:mod:`surrogate.structures`)."""


@dataclass(frozen=True, slots=True)
class SurrogateConfig:
    """Architecture and training protocol; defaults are the paper's (its §2).

    Attributes:
        hidden_layers: hidden layers of each of the two networks.
        width: neurons per hidden layer.
        activation: hidden activation.
        alpha: boundary penalisation α of the loss (paper Eq. 2).
        boundary: how the clamped (Dirichlet) surface is treated: ``network`` (the
            paper's pair: a separate boundary network trained towards zero with weight
            α), ``shared`` (one network for both point sets, α-weighted boundary term:
            weight sharing as in the authors' public code), or ``exact`` (one network
            whose output is multiplied by a smooth function of the distance to the rib
            points that is exactly 0 on them, so the condition holds by construction).
        bc_length: length scale of that function, as a fraction of the largest
            point-to-rib distance: φ = 1 − exp(−d / (bc_length · d_max)).
        c1_encoding: network input for C1 before scaling to [-1, 1]: ``linear`` (C1),
            ``log`` (ln C1) or ``inverse`` (1 / C1, the compliance).
        output_scaling: ``none`` (the network predicts u) or ``compliance`` (it predicts
            u · C1 / C1_ref and the output is divided by C1 / C1_ref, since gravity sag
            scales roughly as 1 / C1).
        output_form: ``vector`` (the network's three outputs are the displacement, the paper)
            or ``gravity_linear`` (its nine outputs are a 3x3 matrix M and the displacement is
            M ĝ, with ĝ the unit gravity direction: linear in ĝ as linear elasticity's
            superposition is, M's own dependence on ĝ carrying the nonlinearity).
        structure: ``pointwise`` (each network maps a point and the case to its displacement,
            the paper) or ``separable`` (each network maps the point alone to ``modes``
            displacement fields, and a third network, the branch, maps the case to their
            weights: u = Σ_k b_k(C1, ĝ) T_k(X); a query then costs the branch and one
            weighted sum, whatever the networks' size), or ``pod`` (the fields T_k are not learnt
            but taken from the data: the leading POD modes, right singular vectors, of the
            training cases' compliance-scaled fields, and one network, the branch, of
            ``hidden_layers`` x ``width``, maps the case to their weights; the modes vanish on the
            rib as every FE field does, so ``boundary`` and ``alpha`` do not apply. Its unit of
            data is a whole case: with ``split: by_sample`` the ``by_case`` split's validation
            cases validate and every other case trains. It is trained by full-batch Adam on the
            weights' squared error, an epoch being
            :data:`surrogate.structures.pod.STEPS_PER_EPOCH` steps).
        modes: number of fields T_k of a ``separable`` or ``pod`` model.
        point_features: a ``separable`` model's point networks see, besides the point's
            standardised coordinates X, ``sin`` and ``cos`` of 2π X·b for this many random
            frequency vectors b (Fourier features: an MLP of X alone is slow to learn fields
            that change over a few millimetres, such as the fold's where it rests on the
            chest); 0, the coordinates alone.
        point_frequency: standard deviation of the frequencies' components, in cycles per
            unit of the standardised coordinates (about the body's size).
        learning_rate: Adam step size (paper 0.01).
        beta1: Adam β1 (paper 0.5).
        beta2: Adam β2 (paper 0.9).
        batch_size: samples per step (paper 8000).
        max_epochs: epoch cap (paper 200).
        patience: early-stopping patience on the validation loss (a ``pod`` model's on its
            validation error in mm; paper 20).
        lr_schedule: ``constant`` (the paper), ``cosine`` (decay to
            ``lr_final · learning_rate`` at ``max_epochs``) or ``exponential`` (the same
            end point, geometric per epoch, as the authors' public code).
        lr_final: final learning rate as a fraction of ``learning_rate``.
        seed: the one seed of all randomness.
        split: ``by_sample`` (the paper's random 80/10/10 of points), ``by_case`` (whole
            setups held out), ``by_direction`` (whole gravity directions) or ``by_c1``
            (whole C1 values); see :data:`fem.splits.SPLIT_KINDS`.
    """

    hidden_layers: int = 3
    width: int = 32
    activation: str = "tanh"
    alpha: float = 1.0
    boundary: str = "network"
    bc_length: float = 0.25
    c1_encoding: str = "linear"
    output_scaling: str = "none"
    output_form: str = "vector"
    structure: str = "pointwise"
    modes: int = 64
    point_features: int = 0
    point_frequency: float = 1.0
    learning_rate: float = 0.01
    beta1: float = 0.5
    beta2: float = 0.9
    batch_size: int = 8000
    max_epochs: int = 200
    patience: int = 20
    lr_schedule: str = "constant"
    lr_final: float = 0.01
    seed: int = 0
    split: str = "by_sample"

    def __post_init__(self) -> None:
        for name in ("hidden_layers", "width", "modes", "batch_size", "max_epochs", "patience"):
            value = getattr(self, name)
            if not isinstance(value, int) or value < 1:
                raise SurrogateConfigError(
                    f"surrogate.{name} must be a positive integer, got {value!r}"
                )
        if self.activation not in ACTIVATIONS:
            raise SurrogateConfigError(
                f"surrogate.activation must be one of {ACTIVATIONS}, got {self.activation!r}"
            )
        for name, allowed in (
            ("split", SPLIT_KINDS),
            ("boundary", BOUNDARY_MODES),
            ("lr_schedule", LR_SCHEDULES),
            ("c1_encoding", C1_ENCODINGS),
            ("output_scaling", OUTPUT_SCALINGS),
            ("output_form", OUTPUT_FORMS),
            ("structure", STRUCTURES),
        ):
            if getattr(self, name) not in allowed:
                raise SurrogateConfigError(
                    f"surrogate.{name} must be one of {allowed}, got {getattr(self, name)!r}"
                )
        if not (isinstance(self.bc_length, (int, float)) and 0 < self.bc_length <= 100):
            raise SurrogateConfigError(
                f"surrogate.bc_length must lie in (0, 100], got {self.bc_length!r}"
            )
        if not (isinstance(self.lr_final, (int, float)) and 0 < self.lr_final <= 1):
            raise SurrogateConfigError(
                f"surrogate.lr_final must lie in (0, 1], got {self.lr_final!r}"
            )
        if not (math.isfinite(self.alpha) and self.alpha >= 0):
            raise SurrogateConfigError(f"surrogate.alpha must be >= 0, got {self.alpha!r}")
        if not (math.isfinite(self.learning_rate) and self.learning_rate > 0):
            raise SurrogateConfigError("surrogate.learning_rate must be positive")
        for name in ("beta1", "beta2"):
            if not 0 <= getattr(self, name) < 1:
                raise SurrogateConfigError(f"surrogate.{name} must lie in [0, 1)")
        if not isinstance(self.seed, int) or self.seed < 0:
            raise SurrogateConfigError("surrogate.seed must be a non-negative integer")
        if isinstance(self.point_features, bool) or not isinstance(self.point_features, int) \
                or self.point_features < 0:
            raise SurrogateConfigError(
                f"surrogate.point_features must be a non-negative integer, got "
                f"{self.point_features!r}")
        entry = STRUCTURE_ENTRIES[self.structure]
        if self.boundary in entry.refused_boundaries:
            raise SurrogateConfigError(
                f"surrogate.boundary: {self.boundary} does not apply to structure: "
                f"{self.structure} {entry.refusal}")
        if self.point_features and not entry.point_features:
            takes = " or ".join(name for name, e in STRUCTURE_ENTRIES.items() if e.point_features)
            raise SurrogateConfigError(
                f"surrogate.point_features needs structure: {takes} (a {self.structure} model's "
                "networks do not see the point alone)")
        frequency = self.point_frequency
        if isinstance(frequency, bool) or not isinstance(frequency, (int, float)) \
                or not (math.isfinite(frequency) and frequency > 0):
            raise SurrogateConfigError(
                f"surrogate.point_frequency must be positive, got {self.point_frequency!r}")

    @classmethod
    def from_mapping(cls, values: dict[str, Any]) -> SurrogateConfig:
        """Build from a config mapping, naming unknown keys."""
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(values) - known)
        if unknown:
            raise SurrogateConfigError(f"unknown surrogate parameter(s): {', '.join(unknown)}")
        return cls(**values)

    def replace(self, **changes: Any) -> SurrogateConfig:
        """A copy with some fields changed (variants override, they do not copy)."""
        return replace(self, **changes)

    def as_dict(self) -> dict[str, Any]:
        """JSON-friendly mapping."""
        return asdict(self)

    @property
    def architecture(self) -> str:
        """The paper's notation, e.g. ``3x32``."""
        return f"{self.hidden_layers}x{self.width}"

    def with_architecture(self, architecture: str) -> SurrogateConfig:
        """A copy with the architecture given in the paper's notation (``"3x32"``)."""
        layers, width = parse_architecture(architecture)
        return self.replace(hidden_layers=layers, width=width)


def parse_architecture(architecture: str) -> tuple[int, int]:
    """``"3x32"`` -> ``(3, 32)``.

    Raises:
        SurrogateConfigError: if the text is not ``<layers>x<width>`` with positive integers.
    """
    try:
        layers, width = (int(v) for v in str(architecture).lower().split("x"))
    except ValueError:
        raise SurrogateConfigError(
            f"architecture {architecture!r} is not '<hidden layers>x<width>', e.g. '3x32'"
        ) from None
    if layers < 1 or width < 1:
        raise SurrogateConfigError(f"architecture {architecture!r} needs positive layers and width")
    return layers, width
