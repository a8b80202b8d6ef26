"""Snakemake adapter: plan one round of the adaptive sweep (fem.adaptive)."""

from fem.adaptive import AdaptiveDesign, read_cases
from run.joblog import job_log

job_log(snakemake.log[0])

design = AdaptiveDesign.from_sweep(snakemake.params.sweep)
cases, converged, fields = read_cases(snakemake.input.summaries, snakemake.input.points)
plan = design.plan(cases, converged, fields, int(snakemake.wildcards.round),
                   [tuple(d) for d in snakemake.params.reserved])
plan.write(snakemake.output[0])
