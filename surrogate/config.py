"""Hyperparameters of the Siamese MLP surrogate and its training (one validated object)."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields, replace
from typing import Any

ACTIVATIONS = ("tanh", "relu", "gelu", "silu")
SPLIT_KINDS = ("by_sample", "by_case")


class SurrogateConfigError(ValueError):
    """A surrogate hyperparameter is out of range (the message names it)."""


@dataclass(frozen=True, slots=True)
class SurrogateConfig:
    """Architecture and training protocol; defaults are the paper's (its §2).

    Attributes:
        hidden_layers: hidden layers of each of the two networks.
        width: neurons per hidden layer.
        activation: hidden activation.
        alpha: boundary penalisation α of the loss (paper Eq. 2).
        learning_rate: Adam step size (paper 0.01).
        beta1: Adam β1 (paper 0.5).
        beta2: Adam β2 (paper 0.9).
        batch_size: samples per step (paper 8000).
        max_epochs: epoch cap (paper 200).
        patience: early-stopping patience on the validation loss (paper 20).
        seed: the one seed of all randomness.
        split: ``by_sample`` (the paper's random 80/10/10 of points) or ``by_case``
            (whole setups held out).
    """

    hidden_layers: int = 3
    width: int = 32
    activation: str = "tanh"
    alpha: float = 1.0
    learning_rate: float = 0.01
    beta1: float = 0.5
    beta2: float = 0.9
    batch_size: int = 8000
    max_epochs: int = 200
    patience: int = 20
    seed: int = 0
    split: str = "by_sample"

    def __post_init__(self) -> None:
        for name in ("hidden_layers", "width", "batch_size", "max_epochs", "patience"):
            value = getattr(self, name)
            if not isinstance(value, int) or value < 1:
                raise SurrogateConfigError(f"surrogate.{name} must be a positive integer, got {value!r}")
        if self.activation not in ACTIVATIONS:
            raise SurrogateConfigError(
                f"surrogate.activation must be one of {ACTIVATIONS}, got {self.activation!r}"
            )
        if self.split not in SPLIT_KINDS:
            raise SurrogateConfigError(f"surrogate.split must be one of {SPLIT_KINDS}, got {self.split!r}")
        if not (math.isfinite(self.alpha) and self.alpha >= 0):
            raise SurrogateConfigError(f"surrogate.alpha must be >= 0, got {self.alpha!r}")
        if not (math.isfinite(self.learning_rate) and self.learning_rate > 0):
            raise SurrogateConfigError("surrogate.learning_rate must be positive")
        for name in ("beta1", "beta2"):
            if not 0 <= getattr(self, name) < 1:
                raise SurrogateConfigError(f"surrogate.{name} must lie in [0, 1)")
        if not isinstance(self.seed, int) or self.seed < 0:
            raise SurrogateConfigError("surrogate.seed must be a non-negative integer")

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
