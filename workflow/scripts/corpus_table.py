"""Snakemake adapter: gather the corpus's runs into one table."""

from run.joblog import job_log
from studies.fe_study.corpus import AnatomyRun, CorpusTable

job_log(snakemake.log[0])

CorpusTable(
    [AnatomyRun.read(path) for path in snakemake.input],
    soft_C1=snakemake.params.soft_C1,
    soft_phi=list(snakemake.params.soft_phi),
).write(snakemake.output[0])
