"""The surrogate package's errors (one base, :class:`SurrogateError`) and its warning."""

from __future__ import annotations


class SurrogateError(ValueError):
    """Base of the surrogate's errors: the message names the setting, file or input at fault."""


class SurrogateConfigError(SurrogateError):
    """A surrogate hyperparameter is out of range (the message names it)."""


class ModelFileError(SurrogateError):
    """A model folder is missing, corrupt or of another architecture."""


class OutsideMeshError(SurrogateError):
    """Points lie farther outside the mesh than a field can be read there.

    Attributes:
        gaps_m: each such point's index among those asked about, and its distance outside (m).
        limit_m: how far outside a point may lie and still be answered (m).
    """

    def __init__(self, message: str, gaps_m: dict[int, float], limit_m: float) -> None:
        super().__init__(message)
        self.gaps_m = gaps_m
        self.limit_m = limit_m

    def naming(self, names: list[str]) -> str:
        """The message with the points named by ``names`` instead of their indices."""
        listed = ", ".join(f"{names[i]} ({1e3 * gap:.1f} mm outside)"
                           for i, gap in self.gaps_m.items())
        return (f"{len(self.gaps_m)} of {len(names)} points lie outside the mesh by more than "
                f"{1e3 * self.limit_m:g} mm: {listed}; fields are known inside the body only")


class ExtrapolationWarning(UserWarning):
    """The query lies outside the parameter range the surrogate was trained on."""
