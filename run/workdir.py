"""One workflow run at a time in a working directory.

Snakemake's own locks name files, not the directory: two runs whose jobs do not overlap both
go ahead, and the first to finish removes the lock folder wholesale, so a third run (one that
reruns the mesh, say) can pull files from under the second. :class:`RunLock` is a kernel lock
(``flock``) on one file of the working directory, taken by every run of the workflow: the
kernel releases it when the process ends, however it ends (SIGKILL included), so a lock that
nobody holds is never stale, and when we hold it the Snakemake locks left by a killed run
are known to be stale and are cleared.
"""

from __future__ import annotations

import fcntl
import logging
import os
import shutil
import sys
import time
from pathlib import Path
from typing import IO

log = logging.getLogger(__name__)

LOCK_NAME = ".snakemake/run.lock"
"""The lock file, relative to the working directory (Snakemake's own folder, ignored by git)."""


class RunLock:
    """The working directory's run lock (held for the life of this process once taken)."""

    def __init__(self, workdir: str | Path = ".") -> None:
        self.workdir = Path(workdir)
        self.path = self.workdir / LOCK_NAME
        self._file: IO[str] | None = None

    @property
    def held(self) -> bool:
        """Whether this process holds the lock."""
        return self._file is not None

    def acquire(self) -> bool:
        """Take the lock if no other process holds it; never waits.

        Returns:
            True if this process holds the lock now, False if another run holds it.
        """
        if self._file is not None:
            return True
        self.path.parent.mkdir(parents=True, exist_ok=True)
        handle = open(self.path, "a+")  # noqa: SIM115 (kept open: the open file is the lock)
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            handle.close()
            return False
        handle.seek(0)
        handle.truncate()
        handle.write(
            f"pid {os.getpid()}, since {time.strftime('%Y-%m-%d %H:%M:%S')}: "
            f"{' '.join(sys.argv)}\n"
        )
        handle.flush()
        self._file = handle
        return True

    def holder(self) -> str:
        """Who holds the lock, as the holder wrote it (its pid, start time and command)."""
        try:
            return self.path.read_text().strip() or "unknown"
        except OSError:
            return "unknown"

    def clear_stale_snakemake_locks(self) -> bool:
        """Remove Snakemake's lock folder, left by a killed run; returns whether there was one.

        Only a killed run can have left it while this process holds the run lock.
        """
        if not self.held:
            raise RuntimeError("clear Snakemake's locks only while holding the run lock")
        locks = self.workdir / ".snakemake" / "locks"
        if locks.is_dir() and any(locks.iterdir()):
            shutil.rmtree(locks, ignore_errors=True)
            log.info("cleared the locks of a run that was killed: %s", locks)
            return True
        return False

    def busy_message(self) -> str:
        """Why a run cannot start while another holds the lock."""
        return (
            f"another run of the workflow is working in {self.workdir.resolve()} "
            f"({self.holder()}). Wait for it to end (or stop it): two runs in one working "
            "directory can delete each other's files. A dry run (-n) may run beside it."
        )


def refused_marker(output: str | Path) -> Path:
    """Where a job that refused its input says so, beside its output (hidden)."""
    output = Path(output)
    return output.with_name(f".{output.name}.refused")


def mark_refused(output: str | Path, reason: str) -> None:
    """Record that the job making ``output`` refused its input (:func:`age_refused` reads it).

    An ``update()`` output is restored by Snakemake when its job fails, with a new
    modification time: newer than the input that was refused, so the next run would say
    "Nothing to be done" and the error would be gone with the bad file still there.
    """
    marker = refused_marker(output)
    marker.parent.mkdir(parents=True, exist_ok=True)
    marker.write_text(reason + "\n")


def age_refused(output: str | Path) -> bool:
    """After a failed run: make a restored output older than any input if its job refused.

    The output's content is kept; only its time goes back (to the epoch), so that the next
    run makes it again, and fails again until the input is fixed. Returns whether it did.
    """
    output, marker = Path(output), refused_marker(output)
    if not marker.is_file():
        return False
    if output.is_file():
        os.utime(output, (0, 0))
        log.warning("%s was kept but its input was refused: it is marked out of date, so the "
                    "next run makes it again (%s)", output, marker.read_text().strip())
    marker.unlink()
    return True
