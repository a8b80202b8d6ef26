"""XLA CPU runtime settings that entry points apply before JAX starts its backend.

Measured on this project's machine (Xeon, AVX-512, jax 0.4.38): the CPU "thunk"
runtime that jax 0.4.38 uses by default spends ~0.3 ms of overhead on the eight
small kernels of a 3x32 whole-field prediction (0.53 ms for 2,286 points); the
classic runtime runs the same program in 0.20 ms. Turning Eigen's multi-threading
off costs a further ~30 % on one pinned core, so the one-core timing pins the
process with ``sched_setaffinity`` instead (see :mod:`studies.surrogate_study.timing`).

XLA reads ``XLA_FLAGS`` when the backend is created (at the first computation),
so :func:`configure_cpu` works after ``import jax`` but not after JAX has run.
"""

from __future__ import annotations

import logging
import os
import sys

log = logging.getLogger(__name__)

CLASSIC_RUNTIME_FLAG = "--xla_cpu_use_thunk_runtime=false"
SINGLE_THREAD_FLAGS = "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1"


def _backend_started() -> bool:
    bridge = sys.modules.get("jax._src.xla_bridge")
    return bool(getattr(bridge, "_backends", None))


def configure_cpu(classic_runtime: bool = True, single_thread: bool = False) -> str:
    """Add the XLA CPU flags to ``XLA_FLAGS``; returns the resulting value.

    Args:
        classic_runtime: use the classic (non-thunk) CPU runtime, faster for small kernels.
        single_thread: also stop Eigen from multi-threading (for one-core jobs that run
            beside others; a pinned process is one core either way).
    """
    flags = os.environ.get("XLA_FLAGS", "").split()
    wanted = ([CLASSIC_RUNTIME_FLAG] if classic_runtime else []) + (
        SINGLE_THREAD_FLAGS.split() if single_thread else []
    )
    # Options first: XLA takes a leading token without "--" for a file of flags.
    flags = [f for f in flags if f.startswith("--")] + [f for f in flags if not f.startswith("--")]
    for flag in wanted:
        if flag not in flags:
            flags.insert(0 if flag.startswith("--") else len(flags), flag)
    value = " ".join(flags)
    if _backend_started():
        log.warning(
            "JAX's backend is already running; XLA_FLAGS=%r takes effect only in new processes",
            value,
        )
    os.environ["XLA_FLAGS"] = value
    return value
