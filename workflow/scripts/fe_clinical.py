"""Snakemake adapter: the clinical benchmark at the workflow's default discretisation.

Time, factorisation equivalents, the fixed-step baseline, accuracy against the reference.
"""

import logging

from fem.parameters import SolverSettings
from fem.sweep import clinical_list
from run.joblog import job_log
from studies.fe_study.fe_clinical import fe_clinical
from studies.fe_study.fe_reference import load_references
from studies.timing_hygiene import limit_blas_threads

job_log(snakemake.log[0])
logging.info("single-threaded BLAS: %s", limit_blas_threads(1))

cases, references = load_references(
    snakemake.params.clinical, snakemake.input.references, snakemake.input.reference_mesh
)
result = fe_clinical(
    snakemake.input.mesh,
    SolverSettings.from_config(snakemake.params.config),
    cases,
    references,
    baseline_steps=snakemake.params.study["baseline_fixed_steps"],
    repeats=snakemake.params.study["repeats"],
    labels={item.case.id: item.label for item in clinical_list(snakemake.params.clinical)},
)
result.write(snakemake.output[0])
