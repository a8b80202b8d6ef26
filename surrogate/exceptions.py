"""The surrogate package's errors (one base, :class:`SurrogateError`) and its warning."""

from __future__ import annotations


class SurrogateError(ValueError):
    """Base of the surrogate's errors: the message names the setting, file or input at fault."""


class SurrogateConfigError(SurrogateError):
    """A surrogate hyperparameter is out of range (the message names it)."""


class ModelFileError(SurrogateError):
    """A model folder is missing, corrupt or of another architecture."""


class ExtrapolationWarning(UserWarning):
    """The query lies outside the parameter range the surrogate was trained on."""
