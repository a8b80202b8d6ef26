"""A run's time by stage, read from Snakemake's run log (run.run_log)."""

from __future__ import annotations

from pathlib import Path

import pytest

from run.run_log import RunTime, main, read_jobs, read_plan, run_time, stage_of, table

pytestmark = pytest.mark.unit

LOG = """Building DAG of jobs...
Provided cores: 2
Job stats:
job           count
----------  -------
mesh              1
solve_chain       2
sweep_round 1
aggregate         1
report            1
total             6

Select jobs to execute...
[Sun Nov 29 01:29:51 2026]
localrule mesh:
    output: results/mesh/mesh.xdmf
    jobid: 4
    reason: Missing output files
[Sun Nov 29 01:29:54 2026]
Finished jobid: 4 (Rule: mesh)
1 of 5 steps (20%) done
[Sun Nov 29 01:29:54 2026]
localrule solve_chain:
    jobid: 7
[Sun Nov 29 01:29:55 2026]
rule sweep_round:
    jobid: 8
[Sun Nov 29 01:31:54 2026]
Finished jobid: 7 (Rule: solve_chain)
[Sun Nov 29 01:32:55 2026]
Finished jobid: 8 (Rule: sweep_round)
[Sun Nov 29 01:33:00 2026]
localrule aggregate:
    jobid: 2
[Sun Nov 29 01:33:30 2026]
Finished jobid: 2 (Rule: aggregate)
[Sun Nov 29 01:33:31 2026]
localrule report:
    jobid: 1
"""


def test_a_run_log_gives_each_stage_its_jobs_and_times(tmp_path: Path) -> None:
    jobs, origin = read_jobs(LOG.splitlines(keepends=True))
    assert sum(read_plan(LOG.splitlines())[0].values()) == 6
    assert origin is not None and origin.minute == 29
    assert [(j.rule, j.jobid, j.start_s, j.end_s) for j in jobs] == [
        ("mesh", 4, 0.0, 3.0), ("solve_chain", 7, 3.0, 123.0),
        ("sweep_round", 8, 4.0, 184.0), ("aggregate", 2, 189.0, 219.0),
        ("report", 1, 220.0, None)]
    path = tmp_path / "run.snakemake.log"
    path.write_text(LOG)
    run = run_time(path)
    by = {s.stage: s for s in run.stages}
    assert list(by) == ["mesh", "sweep", "dataset", "report and 3D view"]
    sweep = by["sweep"]
    assert (sweep.jobs, sweep.finished, sweep.job_s, sweep.first_start_s, sweep.last_end_s) \
        == (2, 2, 300.0, 3.0, 184.0)
    assert by["report and 3D view"].last_end_s is None  # still running
    assert run.milestones == {"the dataset": 219.0} and run.span_s == 219.0
    assert run.finished == 4 and run.planned == 6
    # left: one more solve_chain planned (2 of them, 1 ended: 120 s) and the report (a stage
    # with no ended job: the mean of every ended job, (3 + 120 + 180 + 30) / 4), on 2 cores
    assert run.cores == 2 and run.unseen == 1
    assert run.left_s == pytest.approx((120.0 + 333.0 / 4) / 2)
    run.write(tmp_path / "run.json")
    assert RunTime.read(tmp_path / "run.json") == run
    # a job that a checkpoint added after the plan was printed still counts as planned
    added = tmp_path / "added.snakemake.log"
    added.write_text(LOG.replace("sweep_round 1\n", ""))
    assert run_time(added).planned == 6


def test_the_plan_is_the_first_job_stats_only() -> None:
    plan, cores = read_plan((LOG + "Job stats:\njob count\nreport 9\ntotal 9\n").splitlines())
    assert plan == {"mesh": 1, "solve_chain": 2, "sweep_round": 1, "aggregate": 1,
                    "report": 1} and cores == 2


def test_every_rule_of_the_workflow_has_a_stage() -> None:
    import re

    from tests.conftest import REPO

    rules = {m for path in (REPO / "workflow" / "rules").glob("*.smk")
             for m in re.findall(r"^\s*(?:rule|use rule \w+ as) (\w+)", path.read_text(), re.M)}
    rules -= {"all", "fe_study", "corpus"}  # targets that run nothing themselves
    assert rules and {rule for rule in rules if stage_of(rule) == "other"} == set()


def test_the_command_prints_the_table_or_names_a_log_without_jobs(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "run.snakemake.log"
    path.write_text(LOG)
    assert main([str(path)]) == 0
    said = capsys.readouterr().out
    assert "4 of 6 jobs ended" in said and "the dataset written after 3.6 min" in said
    assert "min left" in said and "1 of the jobs left are of kinds not run yet" in said
    path.write_text("Building DAG of jobs...\n")
    assert main([str(path)]) == 2
    assert "no job in this Snakemake log" in capsys.readouterr().err


def test_the_report_shows_the_runs_time_by_stage(tmp_path: Path) -> None:
    from report.build import build_report

    path = tmp_path / "run.snakemake.log"
    path.write_text(LOG)
    page = build_report({"run_log": path}, tmp_path / "report" / "index.html", []).read_text()
    section = page.split("<h2>The time of this run</h2>")[1].split("<h2>")[0]
    assert "4 of 6 planned jobs" in section and "<td>sweep</td><td>2 of 2</td>" in section
    assert "<td>running</td>" in section  # the report's own job
    assert "the dataset 3.6 min" in section
    page = build_report({}, tmp_path / "other" / "index.html", []).read_text()
    assert "No Snakemake run log was found" in page


def test_runs_back_to_back_are_one_run(tmp_path: Path) -> None:
    """The two Snakemake runs of make reproduce (the first report, then the rest) are one run.

    The second log's jobs count from the first's start; a run started later is a run of its
    own; a job the earlier run left unended is left out.
    """
    import os
    from datetime import datetime

    first = tmp_path / "2026-11-29T012950.000000.snakemake.log"
    first.write_text(LOG.replace("[Sun Nov 29 01:33:31 2026]\nlocalrule report:\n    jobid: 1\n",
                                 "[Sun Nov 29 01:33:31 2026]\nlocalrule select_model:\n"
                                 "    jobid: 9\n"))
    os.utime(first, (0, datetime(2026, 11, 29, 1, 33, 40).timestamp()))
    second = tmp_path / "2026-11-29T013345.000000.snakemake.log"
    second.write_text("""Building DAG of jobs...
Provided cores: 2
Job stats:
job             count
------------  -------
select_model        1
first_report        1
total               2

[Sun Nov 29 01:33:50 2026]
localrule select_model:
    jobid: 3
[Sun Nov 29 01:35:50 2026]
Finished jobid: 3 (Rule: select_model)
[Sun Nov 29 01:35:51 2026]
localrule first_report:
    jobid: 1
[Sun Nov 29 01:36:01 2026]
Finished jobid: 1 (Rule: first_report)
""")
    run = run_time(second)
    assert run.earlier == [str(first)] and run.planned == 8
    assert run.milestones == {"the dataset": 219.0, "the selected model": 359.0,
                              "the first report": 370.0}
    assert [s.stage for s in run.stages] == ["mesh", "sweep", "dataset", "surrogate",
                                             "report and 3D view"]
    assert all(s.last_end_s is not None for s in run.stages)  # the unended job is left out
    assert "(after 2026-11-29T012950.000000.snakemake.log)" in table(run)
    os.utime(first, (0, datetime(2026, 11, 29, 1, 32, 40).timestamp()))  # 70 s before
    alone = run_time(second)
    assert alone.earlier == [] and alone.milestones == {"the selected model": 120.0,
                                                        "the first report": 131.0}
