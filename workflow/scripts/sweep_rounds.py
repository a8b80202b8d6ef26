"""Snakemake adapter: every round of the adaptive sweep in one record (sweep.sweep_rounds)."""

from fem.adaptive import RoundPlan
from run.joblog import job_log
from studies.sweep.sweep_rounds import SweepRounds

job_log(snakemake.log[0])

SweepRounds.of([RoundPlan.read(path) for path in snakemake.input],
               snakemake.params.settings).write(snakemake.output[0])
