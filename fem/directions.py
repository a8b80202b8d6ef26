"""Gravity's direction: the paper's angles (Eq. 1), back, and one key per direction.

Below both the sweep (:mod:`fem.sweep`, which names and groups its cases' directions) and the
dataset (:mod:`fem.dataset`, whose splits hold out whole directions), so that neither imports
the other for them.
"""

from __future__ import annotations

import numpy as np


def gravity_direction(phi_deg: np.ndarray, theta_deg: np.ndarray) -> np.ndarray:
    """Unit gravity direction of the paper's Eq. 1, shape (..., 3)."""
    phi, theta = np.radians(phi_deg), np.radians(theta_deg)
    return np.stack(
        [np.cos(phi), np.sin(phi) * np.cos(theta), np.sin(phi) * np.sin(theta)], axis=-1
    )


def gravity_angles(g: np.ndarray) -> tuple[float, float]:
    """(Φ, θ) in degrees of the unit gravity direction ``g``, :func:`gravity_direction` inverted.

    A direction in the paper's plane (the poles included) is named as the plane names it,
    (Φ, 0) with Φ in (-180, 180]: not (-Φ, ±180), which is the same direction under another
    name (a sweep refuses a direction listed under two).
    """
    if abs(g[2]) < 1e-9:
        phi = float(np.degrees(np.arctan2(g[1], g[0]))) + 0.0
        return (180.0 if phi == -180.0 else phi), 0.0
    return (float(np.degrees(np.arccos(np.clip(g[0], -1.0, 1.0)))),
            float(np.degrees(np.arctan2(g[2], g[1]))))


def direction_keys(phi_deg: np.ndarray, theta_deg: np.ndarray) -> np.ndarray:
    """One hashable key per gravity direction (its unit vector rounded), shape (M,).

    Cases at Φ = 0 or 180° share a direction whatever their θ, so the key is the vector,
    not the angles.
    """
    g = np.round(gravity_direction(phi_deg, theta_deg), 9) + 0.0  # -0.0 -> 0.0
    return np.array([f"{x:.9f},{y:.9f},{z:.9f}" for x, y, z in g])
