"""The log of one workflow job: everything the job logs, and the error that ended it.

Every workflow script starts with :func:`job_log` (the libraries only log through
``logging.getLogger(__name__)``). Snakemake points a user at a failed job's log file, so the
traceback that ended the job is written there as well as to the console.
"""

from __future__ import annotations

import logging
import sys
from types import TracebackType

log = logging.getLogger("job")

FORMAT = "%(asctime)s %(levelname)s %(name)s: %(message)s"


def job_log(path: str, level: int = logging.INFO) -> None:
    """Send logging and warnings to ``path``, and log an uncaught exception there too.

    The exception still reaches the console (the original ``sys.excepthook`` runs after) and
    the job still fails.
    """
    logging.basicConfig(filename=path, level=level, format=FORMAT, force=True)
    logging.captureWarnings(True)
    console_hook = sys.excepthook

    def log_then_raise(
        kind: type[BaseException], error: BaseException, trace: TracebackType | None
    ) -> None:
        log.critical("the job failed: %s: %s", kind.__name__, error, exc_info=(kind, error, trace))
        logging.shutdown()
        console_hook(kind, error, trace)

    sys.excepthook = log_then_raise
