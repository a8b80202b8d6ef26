"""Snakemake adapter: the audit's parts joined into one record (fe_study.stability_audit)."""

from run.joblog import job_log
from studies.fe_study.stability_audit import StabilityAudit

job_log(snakemake.log[0])

StabilityAudit.merge([StabilityAudit.read(path) for path in snakemake.input]).write(
    snakemake.output[0])
