"""Snakemake adapter: one part of the audit of the sweep's softest cases (every jobs-th case)."""

from fem.dataset import read_case_columns
from fem.parameters import SolverSettings
from run.joblog import job_log
from studies.fe_study.stability_audit import StabilityAudit, audit_sweep, softest_c1

job_log(snakemake.log[0])

values = softest_c1(read_case_columns(snakemake.input.dataset)["C1"], snakemake.params.softest)
settings = SolverSettings.from_config(snakemake.params.config)
result = (audit_sweep(snakemake.input.mesh, snakemake.input.dataset, settings, values,
                      part=int(snakemake.wildcards.part), parts=snakemake.params.parts)
          if values else StabilityAudit(C1=[], cases=[], settings=settings.describe()))
result.write(snakemake.output[0])
