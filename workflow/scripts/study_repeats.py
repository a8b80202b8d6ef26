"""Snakemake adapter: the architectures that train their repeats, from each one's first run."""

import logging

from run.joblog import job_log
from studies.surrogate_study.architecture import plan_repeats, read_run

job_log(snakemake.log[0])
log = logging.getLogger("study_repeats")

plan = plan_repeats((read_run(path) for path in snakemake.input.runs),
                    snakemake.params.repeats, snakemake.params.within)
plan.write(snakemake.output[0])
for arch, runs in plan.runs.items():
    log.info("%s: first run %.5f mm, %d run(s)", arch, plan.first_error_mm[arch], runs)
