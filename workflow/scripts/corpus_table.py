"""Snakemake adapter: gather the corpus's runs into one table."""

from studies.corpus import AnatomyRun, CorpusTable
from studies.joblog import job_log

job_log(snakemake.log[0])

CorpusTable(
    [AnatomyRun.read(path) for path in snakemake.input],
    soft_C1=snakemake.params.soft_C1,
    soft_phi=list(snakemake.params.soft_phi),
).write(snakemake.output[0])
