r"""Prediction wall time on one CPU core, measured in a pinned subprocess.

The parent process may run JAX with every core (or train on them); a fair "one
core" figure needs a fresh process whose CPU affinity is a single core before JAX
starts its thread pools: every thread it ever starts then runs on that core.
:func:`time_on_one_core` starts ``python -m studies.surrogate_study.timing`` that way (with the
classic XLA CPU runtime, see :mod:`surrogate.runtime`, and optionally Eigen's
multi-threading off as well) and reads its JSON; the child reports the CPUs it was
allowed to run on and its XLA flags, so the result documents its own pinning.

Example (what the benchmark rule runs)::

    XLA_FLAGS=--xla_cpu_use_thunk_runtime=false \
        python -m studies.surrogate_study.timing results/surrogate/model --core 0 --repeats 2000
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import subprocess
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

log = logging.getLogger(__name__)

def one_core_env(single_thread: bool = False, base: dict[str, str] | None = None) -> dict[str, str]:
    """Environment of the timing process: JAX on the CPU, classic runtime, one BLAS thread.

    Args:
        single_thread: also turn Eigen's multi-threading off in XLA.
        base: environment to start from (default: this process's).
    """
    from surrogate.runtime import CLASSIC_RUNTIME_FLAG, SINGLE_THREAD_FLAGS

    env = dict(os.environ if base is None else base)
    flags = CLASSIC_RUNTIME_FLAG + (" " + SINGLE_THREAD_FLAGS if single_thread else "")
    env["XLA_FLAGS"] = flags
    env["JAX_PLATFORMS"] = "cpu"
    for name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        env[name] = "1"
    return env


def _stats_ms(times_s: np.ndarray) -> dict[str, float]:
    ms = 1e3 * np.asarray(times_s)
    return {
        "median_ms": float(np.median(ms)),
        "mean_ms": float(ms.mean()),
        "std_ms": float(ms.std()),
        "min_ms": float(ms.min()),
        "p95_ms": float(np.percentile(ms, 95)),
    }


def time_model(
    model: Any, queries: Sequence[tuple[float, float, float]], repeats: int = 1000, warmup: int = 50
) -> dict[str, Any]:
    """Time whole-field predictions of a loaded :class:`surrogate.predict.Surrogate`.

    Two figures: ``api`` is the public ``predict()`` call (input checks, features, the
    jitted network, the copy to a NumPy array); ``network`` is the jitted call alone,
    waited for. Queries cycle through ``queries``; the first ``warmup`` calls (which
    compile) are not timed.
    """
    feats = [model.features(*q) for q in queries]
    for i in range(warmup):
        model.predict(*queries[i % len(queries)])
    api = np.empty(repeats)
    net = np.empty(repeats)
    for i in range(repeats):
        q = queries[i % len(queries)]
        t0 = time.perf_counter()
        model.predict(*q)
        api[i] = time.perf_counter() - t0
    run, parts = model._run, model._parts
    for i in range(repeats):
        f = feats[i % len(feats)]
        t0 = time.perf_counter()
        run(parts, f).block_until_ready()
        net[i] = time.perf_counter() - t0
    return {
        "points": int(model.X.shape[0]),
        "architecture": model.config.architecture,
        "boundary": model.config.boundary,
        "repeats": repeats,
        "warmup": warmup,
        "api": _stats_ms(api),
        "network": _stats_ms(net),
    }


def time_on_one_core(
    model_dirs: Sequence[str | Path],
    queries: Sequence[tuple[float, float, float]],
    repeats: int = 1000,
    warmup: int = 50,
    core: int | None = None,
    single_thread: bool = False,
) -> dict[str, Any]:
    """Time each model's predictions in a subprocess pinned to one CPU core.

    Args:
        model_dirs: model folders.
        queries: (C1, Φ, θ) triples to cycle through.
        repeats: timed calls per model.
        warmup: untimed calls first.
        core: CPU to pin to (default: the lowest this process may use).
        single_thread: also turn XLA's Eigen multi-threading off (slower on one core).

    Returns:
        ``{"pinned_cpus": [...], "models": {folder: timing}, "loadavg_before": ...}``.

    Raises:
        RuntimeError: if the timing process fails (its stderr is in the message).
    """
    if core is None:
        core = min(os.sched_getaffinity(0))
    cmd = [sys.executable, "-m", "studies.surrogate_study.timing", *map(str, model_dirs), "--core",
        str(core),
           "--repeats", str(repeats), "--warmup", str(warmup),
           "--queries", ";".join(",".join(str(v) for v in q) for q in queries)]
    proc = subprocess.run(cmd, env=one_core_env(single_thread), capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"timing process failed ({proc.returncode}): {proc.stderr[-2000:]}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def main(argv: list[str] | None = None) -> int:
    """Entry point of the pinned timing process: prints one JSON line."""
    parser = argparse.ArgumentParser(description="Time surrogate predictions on one CPU core.")
    parser.add_argument("models", nargs="+", help="model folders")
    parser.add_argument("--core", type=int, default=0, help="CPU to pin this process to")
    parser.add_argument("--repeats", type=int, default=1000)
    parser.add_argument("--warmup", type=int, default=50)
    parser.add_argument("--queries", default="1.0,180.0,0.0;5.0,0.0,0.0",
                        help="C1,phi,theta triples separated by ';'")
    args = parser.parse_args(argv)
    # Pin before JAX starts: its thread pools size themselves on the CPUs they may use.
    os.sched_setaffinity(0, {args.core})
    import warnings

    from surrogate.predict import Surrogate

    queries = [tuple(float(v) for v in q.split(",")) for q in args.queries.split(";")]
    loadavg = os.getloadavg()
    out: dict[str, Any] = {"pinned_cpus": sorted(os.sched_getaffinity(0)),
                           "xla_flags": os.environ.get("XLA_FLAGS", ""),
                           "loadavg_before": loadavg, "models": {}}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for folder in args.models:
            model = Surrogate.load(folder)
            out["models"][folder] = time_model(model, queries, args.repeats, args.warmup)
    out["loadavg_after"] = os.getloadavg()
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
