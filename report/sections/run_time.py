"""The time of this run: each stage's jobs and when they ran, from Snakemake's own run log."""

from __future__ import annotations

from report.context import Context
from report.html import para, table
from run.run_log import duration


def run_time_section(ctx: Context) -> str:
    """The run that built this page, by stage: jobs, their time, when each stage ran."""
    run = ctx.results.get("run_log")
    if run is None:
        return para("No Snakemake run log was found beside this report: built outside a "
                    "workflow run.", "note")
    out = [para(
        f"The run that built this page (Snakemake's log {run.log}), from its first job's start "
        f"({run.started}) to this report: {run.finished} of {run.planned or '?'} planned jobs "
        "ended. Each stage's jobs, the sum of their wall times (jobs that ran at once count "
        "each), and when the stage's first job started and its last ended, counted from the "
        "run's start. A run resumed from an earlier one counts only its own jobs; "
        "python -m run.run_log prints the same for any run's log.", "caption")]
    rows = [[s.stage, f"{s.finished} of {s.jobs}", duration(s.job_s),
             duration(s.first_start_s), duration(s.last_end_s)] for s in run.stages]
    out.append(table(["stage", "jobs ended", "job time", "started after", "ended after"], rows,
                     table_id="run-time"))
    if run.milestones:
        out.append(para("Written after: " + ", ".join(
            f"{what} {duration(at)}" for what, at in run.milestones.items()) + "."))
    return "".join(out)
