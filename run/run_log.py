"""How long a workflow run took, by stage and job, read from Snakemake's own run log.

Every run of the Snakefile writes ``.snakemake/log/<start>.snakemake.log``: the job stats it
planned, then for each job a line ``[<date>]`` before ``rule NAME:`` (or ``localrule``) with its
``jobid``, and ``[<date>]`` before ``Finished jobid: N (Rule: NAME)`` when it ends. This module
reads those lines (to the second, as Snakemake writes them) into each job's start and end,
groups the rules into the study's stages (:data:`STAGES`) and gives each stage's jobs, the sum
of their wall times, when its first job started and when its last ended, counted from the run's
start: the dataset, the selected model, the report and the 3D view are milestones a user waits
for. A job still running (or failed) has no end. While a run goes on, the time left is
estimated from the jobs it planned (its job stats) that have not ended, each at the mean time
of its rule's ended jobs (else its stage's, else every ended job's), on the run's cores.

A run may be several Snakemake runs back to back: ``make reproduce`` asks for the first
report first and for everything else after it (Snakemake does not stop a running job for a more
urgent one, so a long study started on a free core would otherwise hold it while the first
results wait). A log that starts within :data:`CHAIN_GAP_S` of the end of the log before it
continues that log's run (:func:`chained_logs`), and the run's time counts from the first.

``python -m run.run_log [LOG] [--json OUT]`` prints the table for a log (by default the
newest under ``.snakemake/log`` of the working directory).
"""

from __future__ import annotations

import argparse
import re
import sys
from collections.abc import Iterable
from dataclasses import dataclass, field, replace
from datetime import datetime
from pathlib import Path

from studies.results import Record, Result

#: The study's stages, in the order a run reaches them, each with the rules (names, or name
#: prefixes ending in ``*``) that belong to it; a rule of none is ``other``.
STAGES: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("mesh", ("mesh", "reference_state", "self_contact_at_rest")),
    ("sweep", ("solve", "solve_chain", "sweep_round", "sweep_rounds")),
    ("dataset", ("aggregate",)),
    ("surrogate", ("train_study_run", "study_repeats", "architecture_study", "select_model")),
    ("surrogate studies", ("train_ablation_run", "ablations", "train_held_out", "held_out",
                           "clinical", "extrapolation", "postures", "off_grid",
                           "warning_coverage", "surrogate_benchmark", "solve_outside",
                           "sweep_estimate")),
    ("FE study", ("fe_*",)),
    ("reference and tracking", ("reference_roundtrip", "tracking", "stiffness")),
    ("corpus", ("corpus_*",)),
    ("report and 3D view", ("first_report", "report", "viewer")),
)

#: The rules whose end a user waits for, in words.
MILESTONES = {"aggregate": "the dataset", "select_model": "the selected model",
              "first_report": "the first report", "report": "the report",
              "viewer": "the 3D view"}

#: The longest pause (s) between the end of one Snakemake run and the first job of the next for
#: the two to be one run (:func:`chained_logs`).
CHAIN_GAP_S = 60.0

_DATE = re.compile(r"^\[(\w{3} \w{3} +\d+ \d\d:\d\d:\d\d \d{4})\]$")
_START = re.compile(r"^(?:local)?(?:rule|checkpoint) (\w+):$")
_JOBID = re.compile(r"^\s+jobid: (\d+)$")
_FINISHED = re.compile(r"^Finished jobid: (\d+) \(Rule: (\w+)\)$")


def stage_of(rule: str) -> str:
    """The stage of :data:`STAGES` a rule belongs to (``other`` for none)."""
    for stage, rules in STAGES:
        for pattern in rules:
            if rule == pattern or (pattern.endswith("*") and rule.startswith(pattern[:-1])):
                return stage
    return "other"


@dataclass(frozen=True, slots=True)
class JobTime(Record):
    """One job of a run.

    Attributes:
        rule: its rule.
        jobid: Snakemake's number for it in this run.
        start_s: when it started, seconds after the run's first job started.
        end_s: when it ended, the same way; None while it runs, or where it failed.
    """

    rule: str
    jobid: int
    start_s: float
    end_s: float | None = None


@dataclass(frozen=True, slots=True)
class StageTime(Record):
    """One stage of a run: its jobs and when they ran.

    Attributes:
        stage: its name (:data:`STAGES`).
        jobs: jobs started.
        finished: of those, jobs that ended.
        job_s: the sum of the ended jobs' wall times (two at once on two cores count twice).
        first_start_s: when its first job started, after the run's start.
        last_end_s: when its last job ended; None while one runs or where one failed.
    """

    stage: str
    jobs: int
    finished: int
    job_s: float
    first_start_s: float
    last_end_s: float | None


@dataclass(frozen=True, slots=True)
class RunTime(Result):
    """A workflow run's time by stage (:func:`run_time`).

    Attributes:
        log: the run log read.
        started: when its first job started (ISO 8601, the log's local time).
        planned: the jobs the run planned (its first job stats, with the jobs a checkpoint
            added).
        finished: the jobs that ended.
        span_s: from the first job's start to the last end read.
        stages: each stage that ran, in :data:`STAGES` order.
        milestones: ``{what: seconds after the start}`` for each of :data:`MILESTONES` done.
        cores: the cores the run was given; None where the log does not say.
        left_s: the estimated time left (see the module docstring); None before any job ended.
        unseen: of the jobs left, those whose rule and stage have no ended job yet (counted at
            the mean of every ended job: the estimate is rough while there are any).
        earlier: the logs of the runs this one continued, oldest first (:func:`chained_logs`).
    """

    log: str
    started: str
    planned: int | None
    finished: int
    span_s: float
    stages: list[StageTime]
    milestones: dict[str, float]
    cores: int | None = None
    left_s: float | None = None
    unseen: int = 0
    earlier: list[str] = field(default_factory=list)


def read_plan(lines: Iterable[str]) -> tuple[dict[str, int], int | None]:
    """A run log's planned jobs by rule (its first job stats) and the cores it was given."""
    plan: dict[str, int] = {}
    cores = None
    in_stats = False
    for line in lines:
        line = line.strip()
        if cores is None and (given := re.match(r"^Provided cores: (\d+)$", line)):
            cores = int(given.group(1))
        if line == "Job stats:":
            in_stats = not plan
        elif in_stats and (row := re.match(r"^(\w+)\s+(\d+)$", line)):
            if row.group(1) == "total":
                in_stats = False
            else:
                plan[row.group(1)] = int(row.group(2))
    return plan, cores


def time_left(jobs: list[JobTime], plan: dict[str, int],
              cores: int | None) -> tuple[float | None, int]:
    """The estimated time left, and how many of the jobs left are of kinds not run yet.

    Each planned job not ended counts its rule's mean so far (else its stage's, else every
    ended job's), and the sum is shared by the cores.
    """
    ended = [job for job in jobs if job.end_s is not None]
    if not ended or not plan:
        return None, 0

    def mean(group: list[JobTime]) -> float | None:
        return sum(j.end_s - j.start_s for j in group) / len(group) if group else None

    overall = mean(ended)
    left, unseen = 0.0, 0
    for rule, count in plan.items():
        done = [job for job in ended if job.rule == rule]
        each = mean(done)
        if each is None:
            each = mean([job for job in ended if stage_of(job.rule) == stage_of(rule)])
        remaining = max(count - len(done), 0)
        if each is None:
            each, unseen = overall, unseen + remaining
        left += remaining * each
    return left / max(cores or 1, 1), unseen


def _date(line: str) -> datetime | None:
    """The time of a run log's date line (``[Sun Nov 29 01:29:51 2026]``), else None."""
    date = _DATE.match(line)
    return datetime.strptime(date.group(1), "%a %b %d %H:%M:%S %Y") if date else None


def read_jobs(lines: Iterable[str]) -> tuple[list[JobTime], datetime | None]:
    """The jobs of a run log's lines, and when its first job started (None: no job)."""
    when: datetime | None = None
    pending: tuple[str, datetime] | None = None
    starts: dict[int, tuple[str, datetime]] = {}
    ends: dict[int, datetime] = {}
    for line in lines:
        line = line.rstrip("\n")
        if date := _date(line):
            when = date
        elif (rule := _START.match(line)) and when is not None:
            pending = (rule.group(1), when)
        elif (job := _JOBID.match(line)) and pending is not None:
            starts.setdefault(int(job.group(1)), pending)
            pending = None
        elif (done := _FINISHED.match(line)) and when is not None:
            ends[int(done.group(1))] = when
    if not starts:
        return [], None
    origin = min(start for _, start in starts.values())
    jobs = [JobTime(rule=rule, jobid=jobid, start_s=(start - origin).total_seconds(),
                    end_s=(ends[jobid] - origin).total_seconds() if jobid in ends else None)
            for jobid, (rule, start) in sorted(starts.items(), key=lambda kv: kv[1][1])]
    return jobs, origin


def _first_date(path: Path) -> datetime | None:
    """When a run log's first job started (its first date line), or None."""
    with path.open(encoding="utf-8", errors="replace") as fh:
        for line in fh:
            if date := _date(line.rstrip("\n")):
                return date
    return None


def chained_logs(log: str | Path) -> list[Path]:
    """``log`` and the logs before it in its folder that it continues, oldest first.

    A log continues the one before it (by name: Snakemake names them by their start) when its
    first job started at most :data:`CHAIN_GAP_S` after that log was last written.
    """
    path = Path(log)
    before = sorted(p for p in path.parent.glob("*.snakemake.log") if p.name < path.name)
    chain = [path]
    while before:
        start = _first_date(chain[0])
        previous = before.pop()
        ended = datetime.fromtimestamp(previous.stat().st_mtime)
        if start is None or (start - ended).total_seconds() > CHAIN_GAP_S:
            break
        chain.insert(0, previous)
    return chain


def run_time(log: str | Path) -> RunTime:
    """A run log's time by stage, and when each milestone was written.

    With the logs it continues (:func:`chained_logs`): their jobs count from the first log's
    start, their plans add up, and a job an earlier log left unended (its run was stopped and
    the next redid it) is left out.

    Raises:
        ValueError: if the logs hold no job.
    """
    path = Path(log)
    chain = chained_logs(path)
    jobs: list[JobTime] = []
    plan: dict[str, int] = {}
    origin: datetime | None = None
    cores = None
    for one in chain:
        with one.open(encoding="utf-8", errors="replace") as fh:
            lines = fh.readlines()
        mine, start = read_jobs(lines)
        planned, given = read_plan(lines)
        cores = cores or given
        for rule, count in planned.items():
            plan[rule] = plan.get(rule, 0) + count
        if start is None:
            continue
        origin = origin or start
        shift = (start - origin).total_seconds()
        jobs += [replace(job, start_s=job.start_s + shift,
                         end_s=None if job.end_s is None else job.end_s + shift)
                 for job in mine if job.end_s is not None or one == path]
    if origin is None:
        raise ValueError(f"{path}: no job in this Snakemake log")
    if plan:  # a checkpoint adds jobs its run's plan did not hold (the study's repeats)
        for rule in {job.rule for job in jobs}:
            plan[rule] = max(plan.get(rule, 0), sum(job.rule == rule for job in jobs))
    stages = []
    for stage, _ in (*STAGES, ("other", ())):
        mine = [job for job in jobs if stage_of(job.rule) == stage]
        if not mine:
            continue
        ended = [job for job in mine if job.end_s is not None]
        stages.append(StageTime(
            stage=stage, jobs=len(mine), finished=len(ended),
            job_s=sum(job.end_s - job.start_s for job in ended),
            first_start_s=min(job.start_s for job in mine),
            last_end_s=max(job.end_s for job in ended) if len(ended) == len(mine) else None))
    ends = [job.end_s for job in jobs if job.end_s is not None]
    milestones = {}
    for rule, what in MILESTONES.items():
        ended = [job.end_s for job in jobs if job.rule == rule and job.end_s is not None]
        if ended:
            milestones[what] = max(ended)
    left, unseen = time_left(jobs, plan, cores)
    return RunTime(log=str(path), started=origin.isoformat(), planned=sum(plan.values()) or None,
                   finished=len(ends), span_s=max(ends, default=0.0), stages=stages,
                   milestones=milestones, cores=cores, left_s=left, unseen=unseen,
                   earlier=[str(p) for p in chain[:-1]])


def newest_log(workdir: str | Path = ".") -> Path:
    """The newest run log under ``workdir``'s ``.snakemake/log``.

    Raises:
        FileNotFoundError: if there is none.
    """
    logs = sorted(Path(workdir, ".snakemake", "log").glob("*.snakemake.log"))
    if not logs:
        raise FileNotFoundError(f"no Snakemake run log under {Path(workdir, '.snakemake/log')}")
    return logs[-1]


def duration(seconds: float | None) -> str:
    """A duration of a run in seconds, minutes or hours; ``running`` for a job not ended."""
    if seconds is None:
        return "running"
    if seconds < 90:
        return f"{seconds:.0f} s"
    if seconds < 5400:
        return f"{seconds / 60:.1f} min"
    return f"{seconds / 3600:.2f} h"


def table(run: RunTime) -> str:
    """The run's stages as a text table, then its milestones."""
    after = f" (after {', '.join(Path(p).name for p in run.earlier)})" if run.earlier else ""
    lines = [f"{run.log}{after}: started {run.started}, {run.finished} of {run.planned or '?'} "
             f"jobs ended, {duration(run.span_s)} to the last",
             f"{'stage':<24} {'jobs':>9} {'job time':>10} {'from':>10} {'to':>10}"]
    for s in run.stages:
        lines.append(f"{s.stage:<24} {s.finished:>4} of {s.jobs:<2} {duration(s.job_s):>10} "
                     f"{duration(s.first_start_s):>10} {duration(s.last_end_s):>10}")
    for what, seconds in run.milestones.items():
        lines.append(f"{what} written after {duration(seconds)}")
    if run.left_s is not None and run.finished < (run.planned or 0):
        lines.append(f"about {duration(run.left_s)} left (each job not ended at its rule's mean "
                     f"so far, on {run.cores or 1} cores)")
        if run.unseen:
            lines.append(f"  {run.unseen} of the jobs left are of kinds not run yet, counted at "
                         "the mean of every ended job: a rough estimate until each has run")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Print a run log's time by stage."""
    parser = argparse.ArgumentParser(prog="python -m run.run_log",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("log", nargs="?",
                        help="a Snakemake run log (default: the newest in .snakemake/log)")
    parser.add_argument("--json", help="also write the result here")
    args = parser.parse_args(argv)
    try:
        run = run_time(args.log or newest_log())
    except (OSError, ValueError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    print(table(run))
    if args.json:
        run.write(args.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())
