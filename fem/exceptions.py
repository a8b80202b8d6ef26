"""Typed errors of the FE solver."""

from __future__ import annotations


class FEError(Exception):
    """Base class of the solver's errors."""


class InvalidParameterError(FEError, ValueError):
    """A physical or numerical parameter is out of its range (the message names it)."""


class MeshError(FEError, ValueError):
    """The mesh cannot be used: no fixed surface, inverted or degenerate cells, ..."""


class DatasetError(ValueError):
    """A case file or the dataset is missing, truncated or inconsistent (the message names it)."""
