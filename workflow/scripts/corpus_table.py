"""Snakemake adapter: gather the corpus's runs into one table."""

from studies.corpus import AnatomyRun, CorpusTable
from studies.joblog import job_log

job_log(snakemake.log[0])

CorpusTable([AnatomyRun.read(path) for path in snakemake.input]).write(snakemake.output[0])
