"""Snakemake adapter: the clinical cases homogeneous and with each skin setting, for the report."""

from fem.parameters import SolverSettings
from fem.sweep import clinical_cases
from run.joblog import job_log
from studies.fe_study.config import SkinStudyConfig
from studies.fe_study.skin import skin_study

job_log(snakemake.log[0])

study = SkinStudyConfig(snakemake.params.ratios, snakemake.params.thicknesses,
                        snakemake.params.tumour)
skin_study(snakemake.input.mesh, SolverSettings.from_config(snakemake.params.config), study,
           clinical_cases(snakemake.params.clinical)).write(snakemake.output[0])
