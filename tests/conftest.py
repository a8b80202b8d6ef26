"""Shared fixtures: one coarse parametric mesh per test session."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
os.environ.setdefault("JAX_PLATFORMS", "cpu")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

COARSE = {"global_size": 0.03, "mound_size": 0.02, "order": 1}


@pytest.fixture(scope="session")
def coarse_mesh(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The default geometry on a coarse mesh (about 1,000 vertices), as XDMF."""
    from meshes.build import MeshSize, write_parametric_mesh
    from meshes.parametric import BreastGeometry

    folder = tmp_path_factory.mktemp("mesh")
    path = folder / "mesh.xdmf"
    report = write_parametric_mesh(BreastGeometry(), MeshSize(**COARSE), path)
    (folder / "quality.json").write_text(json.dumps(report))
    return path
