"""Snakemake adapter: the fold cut with and without self-contact, for the report."""

from fem.dataset import read_case_columns
from fem.parameters import SolverSettings
from fem.sweep import Case
from run.joblog import job_log
from studies.fe_study.fold_section import choose_cases, fold_sections

job_log(snakemake.log[0])

cases = choose_cases(read_case_columns(snakemake.input.dataset),
                     [Case(*c) for c in snakemake.params.cases], snakemake.params.largest)
fold_sections(snakemake.input.mesh, SolverSettings.from_config(snakemake.params.config),
              cases).write(snakemake.output[0])
