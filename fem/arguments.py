"""The command line's inputs, checked in one place: angles, stiffness, tolerances, outputs.

Every entry point takes these through argparse's ``type=``, so a bad value stops it before any
work with ``error: argument --phi: ...`` and exit status 2, in the same words everywhere; the
bounds are those of the config's schema (``workflow/schemas/config.schema.yaml``:
``definitions.angle`` and the C1 values), so the command line and the config refuse the same
values. The output paths (a file or folder that can be written, and that is none of the
command's inputs) are checked by :mod:`meshes.arguments`, below every layer, whose commands
write too; they are taken from here.
"""

from __future__ import annotations

import argparse
import math

from meshes.arguments import output_file, output_folder, overwritten, refuse_overwriting

ANGLE_DEG = (-180.0, 360.0)
"""The range of Φ and θ (degrees), as the config's ``definitions.angle``."""
C1_KPA = (0.0, 1000.0)
"""C1 (kPa): above the first, at most the second, as the config's C1 values."""


def _number(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"{text!r} is not a finite number")
    return value


def angle_deg(text: str) -> float:
    """An angle in degrees, from -180 to 360."""
    value = _number(text)
    lo, hi = ANGLE_DEG
    if not lo <= value <= hi:
        raise argparse.ArgumentTypeError(f"{text} is not an angle from {lo:g} to {hi:g} degrees")
    return value


def c1_kpa(text: str) -> float:
    """A stiffness C1 in kPa, above 0 and at most 1000."""
    value = _number(text)
    lo, hi = C1_KPA
    if not lo < value <= hi:
        raise argparse.ArgumentTypeError(f"C1 = {text} kPa is not above {lo:g} and at most "
                                         f"{hi:g} kPa")
    return value


def positive(text: str) -> float:
    """A finite number above zero (a tolerance, a length)."""
    value = _number(text)
    if value <= 0:
        raise argparse.ArgumentTypeError(f"{text} is not above zero")
    return value


__all__ = ["ANGLE_DEG", "C1_KPA", "angle_deg", "c1_kpa", "output_file", "output_folder",
           "overwritten", "positive", "refuse_overwriting"]
