"""Where a result came from: the versions of the packages that made it and the git commit."""

from __future__ import annotations

import subprocess
from importlib import metadata
from pathlib import Path
from typing import Any


def provenance(config: dict[str, Any] | None = None) -> dict[str, Any]:
    """Package versions, git commit and (optionally) the config that produced the data."""
    packages = {}
    for name in (
        "fenics-dolfinx",
        "petsc4py",
        "numpy",
        "h5py",
        "gmsh",
        "snakemake",
        "jax",
        "optax",
    ):
        try:
            packages[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            packages[name] = None
    repo = Path(__file__).resolve().parent.parent
    try:
        commit = subprocess.run(
            ["git", "-C", str(repo), "rev-parse", "HEAD"],
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
        dirty = bool(
            subprocess.run(
                ["git", "-C", str(repo), "status", "--porcelain", "--untracked-files=no"],
                capture_output=True,
                text=True,
                check=True,
            ).stdout.strip()
        )
    except (OSError, subprocess.CalledProcessError):
        commit, dirty = None, None
    return {"packages": packages, "git_commit": commit, "git_dirty": dirty, "config": config}
