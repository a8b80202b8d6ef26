"""Run a command in a child process and measure it: wall time and peak resident memory."""

from __future__ import annotations

import os
import subprocess
import time
from pathlib import Path


def run_measured(command: list[str], log: Path) -> tuple[float, float]:
    """Run ``command``, its output (stdout and stderr) into ``log``.

    The output goes to a file, not a pipe, so that a chatty child never blocks on a full pipe
    while it is waited for.

    Returns:
        Its wall seconds and its peak resident memory, GB (the kernel's maximum RSS of the
        child).

    Raises:
        RuntimeError: if it fails, with the end of its output.
    """
    start = time.perf_counter()
    with open(log, "w") as out:
        proc = subprocess.Popen(command, stdout=out, stderr=subprocess.STDOUT)
        _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - start
    if os.waitstatus_to_exitcode(status) != 0:
        raise RuntimeError(f"{' '.join(command[:4])} ... failed: "
                           f"{Path(log).read_text(errors='replace')[-2000:]}")
    return wall, usage.ru_maxrss * 1024 / 1e9  # Linux reports kilobytes
