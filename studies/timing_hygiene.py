"""The machine a timing was taken on, and how to take it on one core.

Every timed benchmark of the project (the FE clinical benchmark, the speed-accuracy
variants, the surrogate's benchmark) records :func:`machine_state` before and after it,
so that a reader can tell a busy machine from a slow solver, and runs under
:func:`one_core` (every thread pinned) with BLAS capped by :func:`limit_blas_threads`.
"""

from __future__ import annotations

import ctypes
import dataclasses
import functools
import os
import platform
import subprocess
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any, TypeVar

from studies.results import Record

R = TypeVar("R")


def limit_blas_threads(n: int = 1) -> list[str]:
    """Set OpenBLAS (in every copy this process has loaded) and OpenMP to ``n`` threads.

    MUMPS calls BLAS through ``libblas.so.3``, which Debian's ``openblas-pthread``
    provides as a second copy of OpenBLAS beside ``libopenblas.so.0``; each has its own
    thread pool, and the environment variable is read only when a library is loaded.

    Returns:
        The libraries that were set.
    """
    os.environ["OPENBLAS_NUM_THREADS"] = str(n)
    os.environ["OMP_NUM_THREADS"] = str(n)
    done = []
    for name, setter in (
        ("libopenblas.so.0", "openblas_set_num_threads"),
        ("libblas.so.3", "openblas_set_num_threads"),
        ("libgomp.so.1", "omp_set_num_threads"),  # MUMPS' OpenMP regions
    ):
        try:
            lib = ctypes.CDLL(name, mode=os.RTLD_NOLOAD | os.RTLD_GLOBAL)
            getattr(lib, setter)(ctypes.c_int(n))
        except (OSError, AttributeError):
            continue
        done.append(name)
    return done


@contextmanager
def one_core(core: int | None = None) -> Iterator[int]:
    """Run the body on one CPU core: every thread of this process is pinned to ``core``.

    The targets are per core, and some libraries start thread pools of their own (the
    OpenMP build of MUMPS, a second OpenBLAS), so capping thread counts alone does not
    guarantee one core; pinning does. Threads started inside the body inherit the pin.
    The process's previous affinity is restored afterwards.

    Args:
        core: the CPU (default: the lowest this process may use).

    Yields:
        The core pinned to.
    """
    allowed = os.sched_getaffinity(0)
    core = min(allowed) if core is None else core

    def pin(cpus: set[int]) -> None:
        for tid in os.listdir("/proc/self/task"):
            try:
                os.sched_setaffinity(int(tid), cpus)
            except (ProcessLookupError, PermissionError):  # a thread that just ended
                continue

    pin({core})
    try:
        yield core
    finally:
        pin(allowed)


def run_pinned(command: list[str], core: int, log: Path, cwd: Path | None = None
               ) -> tuple[float, float, int]:
    """Run ``command`` pinned to ``core`` with BLAS on one thread, its output into ``log``.

    Returns:
        Its wall seconds, its CPU seconds (the kernel's count for the whole process tree,
        so that another process's load on the machine does not enter it) and its exit status.
    """
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
    start = time.perf_counter()
    with open(log, "w") as out:
        proc = subprocess.Popen(["taskset", "-c", str(core), *command], env=env, cwd=cwd,
                                stdout=out, stderr=subprocess.STDOUT)
        _, status, usage = os.wait4(proc.pid, 0)
    return (time.perf_counter() - start, usage.ru_utime + usage.ru_stime,
            os.waitstatus_to_exitcode(status))


def timed_on_one_core(func: Callable[..., R]) -> Callable[..., R]:
    """Run a benchmark under :func:`one_core`; record the core in its result's ``machine``.

    The benchmark returns a typed result (:mod:`studies.results`) with a ``machine``
    mapping; the core pinned to is added there as ``pinned_core``.
    """

    @functools.wraps(func)
    def wrapper(*args: Any, **kwargs: Any) -> R:
        with one_core() as core:
            record = func(*args, **kwargs)
        return dataclasses.replace(record, machine={**record.machine, "pinned_core": core})

    return wrapper


@dataclasses.dataclass(frozen=True, slots=True)
class MachineState(Record):
    """The machine a timing was taken on, and how busy it was (the one description of it).

    Attributes:
        cpu: the processor's model name.
        cores: CPUs of the machine.
        load_average_1_5_15min: the load averages at the time.
        openblas_num_threads: ``OPENBLAS_NUM_THREADS`` of the process, if set.
        pinned_core: the core a one-core timing was pinned to, if any.
    """

    cpu: str
    cores: int | None
    load_average_1_5_15min: list[float]
    openblas_num_threads: str | None
    pinned_core: int | None = None


def machine_state(pinned_core: int | None = None) -> MachineState:
    """What the timings are taken on: CPU, cores, load average now."""
    try:
        load = os.getloadavg()
    except OSError:
        load = (float("nan"),) * 3
    cpu = platform.processor() or ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return MachineState(
        cpu=cpu,
        cores=os.cpu_count(),
        load_average_1_5_15min=[round(v, 2) for v in load],
        openblas_num_threads=os.environ.get("OPENBLAS_NUM_THREADS"),
        pinned_core=pinned_core,
    )
