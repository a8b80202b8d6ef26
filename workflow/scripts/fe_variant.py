"""Snakemake adapter: one point of the speed-accuracy study on the clinical cases."""

import logging

from fem.parameters import SolverSettings
from run.joblog import job_log
from studies.fe_study.fe_reference import load_references
from studies.fe_study.fe_speed_accuracy import run_variant
from studies.fe_study.fe_variants import FEVariant
from studies.timing_hygiene import limit_blas_threads

job_log(snakemake.log[0])
logging.info("single-threaded BLAS: %s", limit_blas_threads(1))

cases, references = load_references(
    snakemake.params.clinical, snakemake.input.references, snakemake.input.reference_mesh
)
record = run_variant(
    snakemake.input.mesh,
    FEVariant.from_id(snakemake.wildcards.fe_variant),
    SolverSettings.from_config(snakemake.params.config),
    cases,
    references,
    max_dofs=snakemake.params.max_dofs,
)
record.write(snakemake.output[0])
