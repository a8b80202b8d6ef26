"""Where and when a result came from: the packages and git commit that made it, and its clock."""

from __future__ import annotations

import os
import subprocess
import time
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


#: When this module was imported (Unix time): the process's start where /proc cannot say.
_IMPORTED = time.time()


def process_start_time() -> float:
    """When the running process started, in seconds of Unix time (UTC).

    From the kernel's accounting (``/proc/self/stat``'s start time, in clock ticks after boot,
    against the clock since boot now), so that it includes the interpreter's start and the
    imports that a workflow job pays before any case is solved; where that is not available,
    the time this module was imported.
    """
    try:
        stat = Path("/proc/self/stat").read_text()
        # the fields after the command name, which is in parentheses and may hold spaces
        ticks = int(stat[stat.rindex(")") + 2:].split()[19])
        age = time.clock_gettime(time.CLOCK_BOOTTIME) - ticks / os.sysconf("SC_CLK_TCK")
        return time.time() - age
    except (OSError, ValueError, IndexError, AttributeError):
        return _IMPORTED


def clock() -> dict[str, float]:
    """The running process's start and the time now, in seconds of Unix time (UTC).

    A result's ``clock`` record: over a sweep's cases, the earliest ``process_start`` to the
    latest ``finished`` is the wall time the solves spanned, each job's interpreter start,
    imports and set-up included.
    """
    return {"process_start": process_start_time(), "finished": time.time()}
