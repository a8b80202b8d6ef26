"""Breast geometries on the chest wall: parametric (gmsh/OpenCASCADE) and imported."""

from meshes.tags import TISSUE, Boundary, Tissue

__all__ = ["Boundary", "TISSUE", "Tissue"]
