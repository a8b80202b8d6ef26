# One run at a time in a working directory (run.workdir), included first by the Snakefile:
# before the config is read, so that a refused run stops before it has written anything.
from pathlib import Path

from snakemake.exceptions import WorkflowError
from snakemake.logging import logger

from run.workdir import RunLock

# Every run takes the kernel lock, and the run that gets it clears the Snakemake locks a killed
# run left (no --unlock needed). A dry run that finds it taken goes on (it writes nothing). Any
# other run stops here, while the Snakefile is read, before it has touched the working
# directory: stopped later, inside Snakemake's own lock, its exit would remove the lock folder
# wholesale, the running run's locks with it. Snakemake opened this run's log before reading
# the Snakefile: it is closed and removed, for the running run takes the newest log for its own
# (run.run_log: the report's time by stage).
RUN_LOCK = RunLock()


def discard_own_run_log():
    """Close and remove the log Snakemake opened for this run (a refused run logs nothing)."""
    manager = workflow.logger_manager
    for handler, path in list(manager.logfile_handlers.items()):
        manager.logger.removeHandler(handler)
        handler.close()
        del manager.logfile_handlers[handler]
        Path(path).unlink(missing_ok=True)


if workflow.is_main_process:
    if RUN_LOCK.acquire():
        RUN_LOCK.clear_stale_snakemake_locks()
    elif workflow.output_settings.dryrun:
        logger.warning(RUN_LOCK.busy_message())
    else:
        discard_own_run_log()
        raise WorkflowError(RUN_LOCK.busy_message())
